"""A sweep's time responses, one panel per frequency: the input and the output on their own
y axes and a model's replay over the output (``responses.png`` of ``identify``)."""

from __future__ import annotations

import math

import numpy as np

from ..records.figures import FIGURE_RC, PNG_COMPRESS_LEVEL
from ..records.output import atomic_write
from .figure import fixed_layout_params

#: The responses figure's colours: each signal's and its axis's (labels and ticks).
INPUT_COLOUR, OUTPUT_COLOUR, REPLAY_COLOUR = "tab:blue", "tab:orange", "k"


#: Units of the logged signals of a sweep (tlog HQ_SYSID_SAMPLE fields), for the labels.
SIGNAL_UNITS = {"axis_cmd": "torque cmd", "rate_sp": "rad/s", "angle_sp": "rad",
                "rate": "rad/s", "angle": "rad"}


#: Columns of the per-frequency responses figure.
RESPONSE_COLUMNS = 3


#: The responses figure's fixed layout, inches: each panel's height, the margins left and
#: right (the input's and the output's labels), at the top (the title) and at the bottom
#: (the legend), and the gaps between panels (the output's labels and the next input's
#: across, the title and the time axis down). Fixed rather than constrained: working out a
#: layout for its dozens of axes cost more than drawing them (0.6 s of 1.6 s for 15 panels).
RESPONSE_PANEL_IN = 1.9


RESPONSE_MARGINS_IN = {"left": 0.75, "right": 0.75, "top": 0.85, "bottom": 0.65}


#: The responses figure's title: its top this far below the figure's, inches.
RESPONSE_TITLE_IN = 0.15


RESPONSE_GAPS_IN = (1.4, 0.75)


RESPONSE_DPI = 90


#: The responses figure's y labels: this far beside each panel, a fraction of its width
#: (clear of tick labels seven characters wide, within the margins and gaps above).
RESPONSE_LABEL_AT = 0.18


#: The time axis's label: this far below each panel, a fraction of its height.
RESPONSE_XLABEL_AT = 0.14


#: At most this many intervals between ticks on each of a panel's axes.
RESPONSE_TICKS = 5



def plot_responses(axes, segments, input_name, output_name, replays=None):
    """The measured cycles of each frequency, one frequency per Axes of ``axes`` (any shape,
    taken in row order; Axes left over are hidden): the input on the Axes' own (left) y axis,
    the output on a twin (right) y axis with its own unit, each axis labelled and coloured as
    its signal; and, where given, a model's replay of the output (dashed, on the output's
    axis, its error in the title). Returns their figure; the lines carry labels for a legend
    (:func:`write_responses` puts one under the figure).

    ``segments``: ``(freq_hz, t_s, u, y)`` per frequency; ``input_name``, ``output_name``:
    the logged signals ``u`` and ``y`` are (``axis_cmd``, ``rate_sp``, ``angle_sp``;
    ``rate``, ``angle``), for the labels. ``replays``: beside ``segments``, a
    :class:`~heliquad.host.validate.replay.Replay` or None for each.
    """
    flat = np.asarray(axes, dtype=object).ravel()
    if len(flat) < len(segments):
        raise ValueError(f"{len(segments)} frequencies need as many axes, got {len(flat)}")
    replays = list(replays) if replays is not None else [None] * len(segments)
    if len(replays) != len(segments):
        raise ValueError(f"{len(segments)} frequencies need as many replays, got {len(replays)}")
    for ax, segment, replay in zip(flat, segments, replays):
        _response_panel(ax, segment, input_name, output_name, replay)
    for ax in flat[len(segments):]:
        ax.axis("off")
    return flat[0].figure



def _response_panel(ax, segment, input_name, output_name, replay):
    """One frequency's input on ``ax``, its output (and replay) on a twin y axis."""
    _response_replay(ax, _response_record(ax, segment, input_name, output_name), segment,
                     replay)



def _response_record(ax, segment, input_name, output_name):
    """One frequency's record: its input on ``ax``, its output on a twin y axis (returned),
    each axis labelled and coloured as its signal."""
    f, t, u, y = segment
    t = np.asarray(t) - t[0]
    right = ax.twinx()
    labels = _response_axes(ax, right, input_name, output_name)
    ax.plot(t, u, color=INPUT_COLOUR, lw=1, label=labels[0])
    right.plot(t, y, color=OUTPUT_COLOUR, lw=1, label=labels[1])
    return right



def _response_axes(ax, right, input_name, output_name) -> tuple:
    """Label and colour ``ax`` as the input's axis and its twin ``right`` as the output's;
    the two signals' labels."""
    u_label = f"input: {input_name} ({SIGNAL_UNITS[input_name]})"
    y_label = f"output: {output_name} ({SIGNAL_UNITS[output_name]})"
    for side, label, colour in ((ax, u_label, INPUT_COLOUR), (right, y_label, OUTPUT_COLOUR)):
        side.set_ylabel(label, color=colour, fontsize=7)
        side.tick_params(axis="y", colors=colour, labelsize=7)
    ax.set_xlabel("time (s)", fontsize=8)
    ax.tick_params(axis="x", labelsize=7)
    ax.grid(alpha=0.3)
    return u_label, y_label



def _response_replay(ax, right, segment, replay) -> list:
    """One frequency's title and, when ``replay`` is given, the replay (dashed, on the
    output's axis ``right``, its error in the title); the artists added."""
    f, t, _, _ = segment
    t = np.asarray(t) - t[0]
    title, added = f"{f:.3g} Hz", []
    if replay is not None:
        added += right.plot(t[replay.start:replay.start + replay.y.size], replay.y, "--",
                            color=REPLAY_COLOUR, lw=1, label="replay: the model driven by the input")
        title += f", replay error {100 * replay.nrmse:.1f} %"
    return [ax.set_title(title, fontsize=9), *added]



def _envelope(t, v, columns: int) -> tuple:
    """``(t, v)`` as a line ``columns`` pixels wide draws it: of each run of samples that
    falls into one column, its lowest and highest in the order they came (a 6000-sample
    record on a 260-pixel panel: 520 points instead of 6000, the same picture; the
    rasteriser's time goes with the points). Short records are left as they are."""
    v = np.asarray(v)
    per = v.size // max(columns, 1)
    if per < 4:
        return t, v
    whole = v.size // per * per
    runs = v[:whole].reshape(-1, per)
    lo, hi = runs.argmin(axis=1), runs.argmax(axis=1)
    starts = np.arange(runs.shape[0]) * per
    keep = np.column_stack([starts + np.minimum(lo, hi), starts + np.maximum(lo, hi)]).ravel()
    keep = np.unique(np.concatenate([[0], keep, np.arange(whole, v.size)]))  # in order, once
    return np.asarray(t)[keep], v[keep]



class ResponsesFigure:
    """:func:`plot_responses` in a figure of its own (three frequencies a row, a fixed
    layout), made in two steps for a caller that has the records before the model: making
    it draws the records and renders the picture, which is most of the work;
    :meth:`save` adds the replays, the panels' titles, the legend and the title onto the
    rendered picture and writes it.

    One pair of Axes (the input's, and its twin, the output's) is drawn at each panel's
    place in turn, with that panel's record and scales: the figure's panels cost the ticks
    and labels of two Axes, not of two a panel (for 15 records of 6000 samples, 0.9 s of
    CPU as 30 Axes). Their labels sit at fixed places beside the panel rather than where
    each panel's tick labels would push them. Each panel's place and scales are kept for
    :meth:`save`, which draws a replay on its output's scale as the record set it (a replay
    that ran past the record's range is cut at the panel's edge)."""

    def __init__(self, segments, input_name, output_name):
        # matplotlib (0.3 s) only to draw: identify's main process leaves it to its plot process
        import matplotlib
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        rows = max(1, math.ceil(len(segments) / RESPONSE_COLUMNS))
        height = (RESPONSE_MARGINS_IN["top"] + RESPONSE_MARGINS_IN["bottom"]
                  + rows * RESPONSE_PANEL_IN + (rows - 1) * RESPONSE_GAPS_IN[1])
        self.fig = Figure(figsize=(13, height), dpi=RESPONSE_DPI)
        FigureCanvasAgg(self.fig)
        grid = self.fig.add_gridspec(rows, RESPONSE_COLUMNS, **fixed_layout_params(
            self.fig, rows, RESPONSE_COLUMNS, RESPONSE_MARGINS_IN, RESPONSE_GAPS_IN))
        self.ax = self.fig.add_subplot(grid[0])
        self.right = self.ax.twinx()
        lines = self._style(input_name, output_name)
        self.segments, self.panels = list(segments), []
        places = [spec.get_position(self.fig) for spec, _ in zip(grid, self.segments)]
        with matplotlib.rc_context(FIGURE_RC):
            self._draw_records(places, *lines)

    def _style(self, input_name, output_name) -> tuple:
        """The pair of Axes labelled and coloured, their labels and title at fixed places,
        and their two (empty) lines, the input's and the output's."""
        # matplotlib (0.3 s) only to draw: identify's main process leaves it to its plot process
        from matplotlib.ticker import MaxNLocator

        ax, right = self.ax, self.right
        labels = _response_axes(ax, right, input_name, output_name)
        ax.yaxis.set_label_coords(-RESPONSE_LABEL_AT, 0.5)
        right.yaxis.set_label_coords(1 + RESPONSE_LABEL_AT, 0.5)
        ax.xaxis.set_label_coords(0.5, -RESPONSE_XLABEL_AT)
        ax.set_title("", fontsize=9, y=1.0)           # where it goes: no search for a place
        for axis in (ax.xaxis, ax.yaxis, right.yaxis):
            axis.set_major_locator(MaxNLocator(RESPONSE_TICKS))
        return (ax.plot([], [], color=INPUT_COLOUR, lw=1, label=labels[0])[0],
                right.plot([], [], color=OUTPUT_COLOUR, lw=1, label=labels[1])[0])

    def _draw_records(self, places, u_line, y_line) -> None:
        """Each record drawn by the pair of Axes at its panel's place; the places and
        scales kept."""
        renderer = self.fig.canvas.get_renderer()
        self.fig.patch.draw(renderer)
        columns = int(places[0].width * self.fig.bbox.width) if places else 1
        for place, (_, t, u, y) in zip(places, self.segments):
            self.ax.set_position(place)                         # and its twin's
            t = np.asarray(t) - t[0]
            u_line.set_data(*_envelope(t, u, columns))
            y_line.set_data(*_envelope(t, y, columns))
            for side in (self.ax, self.right):              # both, before either scales:
                side.relim()                                # they share the time axis
            self.ax.autoscale_view()
            self.right.autoscale_view(scalex=False)
            for side, line in ((self.ax, u_line), (self.right, y_line)):
                if not np.isfinite(line.get_ydata()).any():     # nothing to scale to: not
                    side.set_ylim(-1.0, 1.0)                    # the last panel's scale
                    side.set_autoscaley_on(True)
            self.ax.draw(renderer)
            self.right.draw(renderer)
            self.panels.append((place, self.ax.get_xlim(), self.ax.get_ylim(),
                                self.right.get_ylim()))

    def save(self, path, title="", replays=None) -> None:
        """Add ``replays`` (beside the records, a :class:`~heliquad.host.validate.replay.Replay` or
        None each) and ``title``, and write the picture to ``path`` (PNG). Once: what it
        adds stays on the picture."""
        # matplotlib (0.3 s) only to draw: identify's main process leaves it to its plot process
        import matplotlib
        from matplotlib.image import imsave

        replays = list(replays) if replays is not None else [None] * len(self.segments)
        with matplotlib.rc_context(FIGURE_RC):
            self._draw_replays(replays, title)
        with atomic_write(path, "wb") as fh:
            imsave(fh, np.asarray(self.fig.canvas.buffer_rgba()), format="png",
                   dpi=self.fig.dpi, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})

    def _draw_replays(self, replays, title) -> None:
        """The replays and the panels' titles, each at its panel's place and scales; the
        legend and the figure's title."""
        fig, ax, right = self.fig, self.ax, self.right
        for (place, xlim, ylim, right_ylim), segment, replay in zip(self.panels, self.segments,
                                                                   replays):
            ax.set_position(place)
            ax.set_xlim(xlim)
            ax.set_ylim(ylim)
            right.set_ylim(right_ylim)
            for artist in _response_replay(ax, right, segment, replay):
                fig.draw_artist(artist)
        lines = {}                                  # one entry a label, inputs first
        for side in (ax, right):
            for handle, label in zip(*side.get_legend_handles_labels()):
                lines.setdefault(label, handle)
        added = [fig.legend(lines.values(), lines.keys(), loc="lower center", ncols=3,
                            fontsize=8)] if self.panels else []
        if title:
            added.append(fig.suptitle(title, y=1 - RESPONSE_TITLE_IN / fig.get_figheight(),
                                      va="top"))
        for artist in added:
            fig.draw_artist(artist)



def write_responses(path, segments, input_name, output_name, title="", replays=None):
    """:func:`plot_responses` in a figure of its own (three frequencies a row), written to
    ``path`` (PNG; :class:`ResponsesFigure` in one go)."""
    ResponsesFigure(segments, input_name, output_name).save(path, title, replays)
