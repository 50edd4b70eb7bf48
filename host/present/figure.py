"""What every plot of the host tool shares: a bare figure, fixed layouts, logarithmic
frequency axes. The plots themselves are in :mod:`.bode`, :mod:`.responses` and
:mod:`.validation` (compute lives elsewhere; these only draw results).

Each ``plot_*`` function draws onto the matplotlib Axes it is given and returns their
figure, so a notebook can place a plot in a figure of its own::

    fig, axes = plt.subplots(2, 1, sharex=True)
    plot_bode(axes, points, models=result.models)

The ``write_*`` functions are what the command line uses: each makes a figure of its own
(:func:`new_figure`, a bare ``matplotlib.figure.Figure``: no pyplot, no backend chosen or
needed), draws the plot into it and saves it to a file. Nothing here selects a matplotlib
backend.
"""

from __future__ import annotations

import math

__all__ = ["new_figure", "fixed_layout", "fixed_layout_params", "log_ticks", "CURVE_POINTS"]

#: Dense grid points per plotted model curve.
CURVE_POINTS = 400

def new_figure(rows=1, cols=1, figsize=(8, 6), layout="constrained", **subplots):
    """A figure of ``rows`` x ``cols`` axes with constrained layout (or ``layout``), made
    without pyplot (so no backend is involved), and its axes (as ``Figure.subplots`` returns
    them)."""
    # matplotlib (0.3 s) only to draw: identify's main process leaves it to its plot process
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(rows, cols, **subplots)


def fixed_layout(fig, rows: int, cols: int, margins: dict, gaps: tuple) -> None:
    """Place the grid of ``fig``'s subplots by margins and gaps in inches."""
    fig.subplots_adjust(**fixed_layout_params(fig, rows, cols, margins, gaps))


def fixed_layout_params(fig, rows: int, cols: int, margins: dict, gaps: tuple) -> dict:
    """A grid's ``left``, ``right``, ``top``, ``bottom``, ``wspace`` and ``hspace`` (as
    ``subplots_adjust`` and ``add_gridspec`` take them) for margins and gaps in inches."""
    width, height = fig.get_size_inches()
    across, down = gaps
    panel_w = (width - margins["left"] - margins["right"] - (cols - 1) * across) / cols
    panel_h = (height - margins["top"] - margins["bottom"] - (rows - 1) * down) / rows
    return {"left": margins["left"] / width, "right": 1 - margins["right"] / width,
            "top": 1 - margins["top"] / height, "bottom": margins["bottom"] / height,
            "wspace": across / panel_w, "hspace": down / panel_h}


def log_ticks(ax) -> None:
    """A logarithmic x axis labelled in plain numbers (0.1, 1, 10), not matplotlib's powers
    of ten, which cost a mathtext parser (a tenth of a second, most of what a Bode figure's
    drawing spent). Between the decades: every tick when the axis spans less than one (a
    narrow band may hold no decade at all), those at 2 and 5 when it spans less than two."""
    # matplotlib (0.3 s) only to draw: identify's main process leaves it to its plot process
    from matplotlib.ticker import FuncFormatter

    def minor(x, _pos=None) -> str:
        lo, hi = ax.get_xlim()
        if not (x > 0 and hi > lo > 0) or hi / lo >= 100:
            return ""
        if hi / lo < 10:
            return f"{x:.3g}"
        lead = x / 10 ** math.floor(math.log10(x) + 1e-9)
        return f"{x:g}" if min(abs(lead - 2), abs(lead - 5)) < 1e-6 else ""

    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos=None: f"{x:g}"))
    ax.xaxis.set_minor_formatter(FuncFormatter(minor))
