"""Figures as the host tool writes them (docs/file-formats.md, "Bode figure"): the format a
file name asks for, checked before any work is done, and the figure saved atomically
(:func:`.output.atomic_write`) with heliquad's rendering settings.
"""

from __future__ import annotations

import os
import shutil

from ...sim.base.errors import InputError
from .output import atomic_write, check_output
from .reading import short

__all__ = ["PNG_COMPRESS_LEVEL", "FIGURE_RC", "figure_format", "check_figure_output",
           "save_figure"]


#: zlib's level for the PNGs heliquad writes: 1 writes a figure's picture in about a quarter
#: of the default's (6) time, in a file about a fifth larger.
PNG_COMPRESS_LEVEL = 1

#: How heliquad's figures draw their text: without FreeType's hinting (matplotlib's default
#: hints every glyph, most of what a figure's tick labels cost: identify's responses figure
#: drew its 300 labels in 0.22 s instead of 0.30 s), the glyphs a shade softer.
FIGURE_RC = {"text.hinting": "none"}

#: Figure formats matplotlib writes only with a program outside Python: the rcParams entry
#: that names the program. pgf sets its text with TeX (xelatex by default), and without it
#: matplotlib fails after the figure is drawn.
FIGURE_FORMAT_PROGRAMS = {"pgf": "pgf.texsystem"}


def figure_format(path) -> str:
    """The format a figure is written in: its file name's extension (any case), PNG when it
    has none."""
    return os.path.splitext(os.fspath(path))[1].lstrip(".").lower() or "png"


def check_figure_output(path, option: str) -> None:
    """:func:`check_output` for a figure, and refuse, before any work is done, a file name
    whose extension is no format matplotlib can write here (or whose format needs a program
    that is not installed): the error would otherwise come once the work was done."""
    # matplotlib (0.3 s) here: only a command asked for a figure pays
    import matplotlib
    from matplotlib.backend_bases import FigureCanvasBase

    fmt, given = figure_format(path), os.fspath(path)
    formats = FigureCanvasBase.get_supported_filetypes()
    if fmt not in formats:
        raise InputError(f"{option} {given}: .{short(fmt, 20)} is not an image format "
                         f"heliquad can write; end the name with one of "
                         f"{', '.join('.' + f for f in sorted(formats))}")
    program = matplotlib.rcParams[FIGURE_FORMAT_PROGRAMS[fmt]] if fmt in FIGURE_FORMAT_PROGRAMS \
        else None
    if program and shutil.which(program) is None:
        raise InputError(f"{option} {given}: .{fmt} figures need {program}, which is not "
                         "installed; write .pdf or .svg instead")
    check_output(path, option)


def save_figure(fig, path, **kwargs) -> None:
    """A matplotlib figure to ``path`` (format :func:`figure_format`), atomically."""
    # matplotlib (0.3 s) here: only a command asked for a figure pays
    import matplotlib

    fmt = figure_format(path)
    if fmt == "png":
        kwargs.setdefault("pil_kwargs", {"compress_level": PNG_COMPRESS_LEVEL})
    with atomic_write(path, "wb") as fh, matplotlib.rc_context(FIGURE_RC):
        fig.savefig(fh, format=fmt, **kwargs)

