"""The host tool's plots (compute lives elsewhere; these only draw results).

Each ``plot_*`` function draws onto the matplotlib Axes it is given and returns their
figure, so a notebook can place a plot in a figure of its own::

    fig, axes = plt.subplots(2, 1, sharex=True)
    plot_bode(axes, omega, F, models=result.models)

The ``write_*`` functions are what the command line uses: each makes a figure of its own
(:func:`new_figure`, a bare ``matplotlib.figure.Figure``: no pyplot, no backend chosen or
needed), draws the plot into it and saves it to a file. Nothing here selects a matplotlib
backend.
"""

from __future__ import annotations

import math

import numpy as np

from ..records.figures import FIGURE_RC, PNG_COMPRESS_LEVEL, save_figure
from ..records.output import atomic_write

__all__ = ["new_figure", "plot_bode", "plot_coherence", "plot_loop_gains", "plot_responses",
           "plot_validation", "write_bode", "write_responses", "write_validation",
           "ResponsesFigure"]

#: Dense grid points per plotted model curve.
CURVE_POINTS = 400
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
#: The Bode figure's fixed layout, inches: margins (the y labels, the title, the frequency
#: axis) and the gap between its panels (constrained layout took 40 % of its drawing).
BODE_MARGINS_IN = {"left": 0.8, "right": 0.25, "top": 0.4, "bottom": 0.6}
BODE_GAP_IN = 0.25
#: The responses figure's colours: each signal's and its axis's (labels and ticks).
INPUT_COLOUR, OUTPUT_COLOUR, REPLAY_COLOUR = "tab:blue", "tab:orange", "k"
#: The coherence panel's series: the coherence of the excitation r with the output and with
#: the input (points estimated against the excitation), as (key, label, marker style); the
#: second hollow and larger, so that equal values show both.
EXCITATION_COHERENCES = (("coherence_ry", "r -> y", {"marker": "o", "ms": 5}),
                         ("coherence_ru", "r -> u", {"marker": "s", "ms": 8, "mfc": "none"}))
#: Every coherence a points table may hold.
COHERENCE_KEYS = ("coherence", *(key for key, _, _ in EXCITATION_COHERENCES))


def new_figure(rows=1, cols=1, figsize=(8, 6), layout="constrained", **subplots):
    """A figure of ``rows`` x ``cols`` axes with constrained layout (or ``layout``), made
    without pyplot (so no backend is involved), and its axes (as ``Figure.subplots`` returns
    them)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(rows, cols, **subplots)


def _fixed_layout(fig, rows: int, cols: int, margins: dict, gaps: tuple) -> None:
    """Place the grid of ``fig``'s subplots by margins and gaps in inches."""
    fig.subplots_adjust(**_fixed_layout_params(fig, rows, cols, margins, gaps))


def _fixed_layout_params(fig, rows: int, cols: int, margins: dict, gaps: tuple) -> dict:
    """A grid's ``left``, ``right``, ``top``, ``bottom``, ``wspace`` and ``hspace`` (as
    ``subplots_adjust`` and ``add_gridspec`` take them) for margins and gaps in inches."""
    width, height = fig.get_size_inches()
    across, down = gaps
    panel_w = (width - margins["left"] - margins["right"] - (cols - 1) * across) / cols
    panel_h = (height - margins["top"] - margins["bottom"] - (rows - 1) * down) / rows
    return {"left": margins["left"] / width, "right": 1 - margins["right"] / width,
            "top": 1 - margins["top"] / height, "bottom": margins["bottom"] / height,
            "wspace": across / panel_w, "hspace": down / panel_h}


def _log_ticks(ax) -> None:
    """A logarithmic x axis labelled in plain numbers (0.1, 1, 10), not matplotlib's powers
    of ten, which cost a mathtext parser (a tenth of a second, most of what a Bode figure's
    drawing spent). Between the decades: every tick when the axis spans less than one (a
    narrow band may hold no decade at all), those at 2 and 5 when it spans less than two."""
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


# -- Bode plot of points and models --------------------------------------------------------

def plot_bode(axes, omega, F, sigma=None, models=(), recommended=None, title="",
              coherence=None, gate=None):
    """Bode plot of frequency-response points and fitted models onto ``axes``: a pair of
    Axes (magnitude, phase), or three with the points' coherence in the third; returns
    their figure.

    Magnitude in dB, phase in degrees, frequency in Hz (log scale). ``omega`` in rad/s,
    ``F`` complex. ``sigma`` is the standard deviation of each complex point; it is drawn as
    the magnitude band ``20 log10(1 +/- sigma/|F|)`` and the phase band ``asin(sigma/|F|)``.
    ``models``: :class:`~heliquad.host.estimate.fit.TfModel`; the one at index ``recommended`` is
    drawn heavier. ``coherence``: a mapping with any of ``coherence``, ``coherence_ry``,
    ``coherence_ru`` (arrays beside ``omega``, NaN where not known; as
    :func:`~heliquad.host.records.points.read_points_csv` returns them), drawn with the quality
    ``gate`` by :func:`plot_coherence`.
    """
    ax_mag, ax_ph, *rest = axes
    omega = np.asarray(omega, float)
    f_hz = omega / (2 * np.pi)
    mag_db = 20 * np.log10(np.abs(F))
    phase_deg = np.degrees(np.unwrap(np.angle(F)))
    _bode_points(ax_mag, ax_ph, f_hz, mag_db, phase_deg, F, sigma)
    dense = np.logspace(np.log10(omega.min() / 1.5), np.log10(omega.max() * 1.5), CURVE_POINTS)
    for i, model in enumerate(models):
        label = _model_label(model, i == recommended)
        resp = model.response(dense)
        ph = np.degrees(np.unwrap(np.angle(resp)))
        ph += 360 * np.round((phase_deg[0] - np.interp(omega[0], dense, ph)) / 360)
        width = 2.5 if i == recommended else 1.3
        with np.errstate(divide="ignore"):              # a zero on the axis: -inf dB, not drawn
            model_db = 20 * np.log10(np.abs(resp))
        ax_mag.semilogx(dense / (2 * np.pi), model_db, lw=width, label=label)
        ax_ph.semilogx(dense / (2 * np.pi), ph, lw=width)
    if rest:
        plot_coherence(rest[0], omega, coherence, gate)
    ax_mag.set_ylabel("magnitude (dB)")
    ax_ph.set_ylabel("phase (deg)")
    for ax in (ax_mag, ax_ph, *rest):
        _log_ticks(ax)
        ax.grid(True, which="both", alpha=0.3)
    (rest or [ax_ph])[0].set_xlabel("frequency (Hz)")
    ax_mag.legend(fontsize=8)
    if title:
        ax_mag.set_title(title, y=1.0)      # where it goes: no search for a place
    return ax_mag.figure


def plot_coherence(ax, omega, coherence, gate=None):
    """Each point's coherence onto ``ax`` against frequency (Hz), and the quality ``gate``
    (the tool's is :data:`heliquad.host.present.report.LOW_COHERENCE`) as a line when given; returns
    its figure.

    ``coherence`` as :func:`plot_bode` takes it: with ``coherence_ry`` and ``coherence_ru``
    (points estimated against the excitation) those two are drawn, else the single
    ``coherence``; with none the panel says so.
    """
    coherence = coherence or {}
    f_hz = np.asarray(omega, float) / (2 * np.pi)
    series = [(coherence[key], label, style) for key, label, style in EXCITATION_COHERENCES
              if _known(coherence.get(key))]
    if not series and _known(coherence.get("coherence")):
        series = [(coherence["coherence"], "coherence", {"marker": "o", "ms": 5})]
    for values, label, style in series:
        ax.plot(f_hz, values, ls="none", label=label, **style)
    if gate is not None:
        ax.axhline(gate, color="tab:red", ls="--", lw=1, label=f"quality gate {gate:g}")
    if not series:
        ax.text(0.5, 0.5, "no coherence in the points", transform=ax.transAxes, ha="center",
                va="center", fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("coherence")
    ax.legend(fontsize=7, loc="lower left", ncol=3)
    return ax.figure


def _known(values) -> bool:
    """An array of coherences with at least one that is known (not NaN)."""
    return values is not None and bool(np.any(np.isfinite(np.asarray(values, float))))


def _bode_points(ax_mag, ax_ph, f_hz, mag_db, phase_deg, F, sigma):
    """The measured points, with their 1-sigma bands when ``sigma`` is given."""
    if sigma is None:
        ax_mag.plot(f_hz, mag_db, "o", color="k", label="measured", zorder=3)
        ax_ph.plot(f_hz, phase_deg, "o", color="k", zorder=3)
        return
    rel = np.minimum(np.asarray(sigma) / np.abs(F), 0.999)
    below_db, above_db = -20 * np.log10(1 - rel), 20 * np.log10(1 + rel)
    err_deg = np.degrees(np.arcsin(rel))
    ax_mag.errorbar(f_hz, mag_db, yerr=[below_db, above_db], fmt="o", color="k",
                    capsize=3, label="measured (1 sigma)", zorder=3)
    ax_ph.errorbar(f_hz, phase_deg, yerr=err_deg, fmt="o", color="k", capsize=3, zorder=3)


def _model_label(model, recommended):
    m, n = model.order
    j = model.metrics.get("J", float("nan"))
    tag = f"{m}/{n}{' + delay' if model.delay_fitted else ''}  J={j:.1f}"
    if not model.stable:
        tag += " UNSTABLE"
    return tag + (" (recommended)" if recommended else "")


def write_bode(path, omega, F, sigma=None, models=(), recommended=None, title="",
               coherence=None, gate=None):
    """:func:`plot_bode` in a figure of its own, with the coherence panel under it when
    ``coherence`` holds any known value, written to ``path`` (format from its extension)."""
    if any(_known((coherence or {}).get(key)) for key in COHERENCE_KEYS):
        fig, axes = new_figure(3, 1, figsize=(8, 8.5), layout=None, sharex=True,
                               gridspec_kw={"height_ratios": [3, 3, 1.6]})
    else:
        fig, axes = new_figure(2, 1, figsize=(8, 7), layout=None, sharex=True)
    _fixed_layout(fig, len(axes), 1, BODE_MARGINS_IN, (0.0, BODE_GAP_IN))
    plot_bode(axes, omega, F, sigma, models, recommended, title, coherence, gate)
    save_figure(fig, path, dpi=110)


# -- a sweep's time responses --------------------------------------------------------------

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
        import matplotlib
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        rows = max(1, math.ceil(len(segments) / RESPONSE_COLUMNS))
        height = (RESPONSE_MARGINS_IN["top"] + RESPONSE_MARGINS_IN["bottom"]
                  + rows * RESPONSE_PANEL_IN + (rows - 1) * RESPONSE_GAPS_IN[1])
        self.fig = Figure(figsize=(13, height), dpi=RESPONSE_DPI)
        FigureCanvasAgg(self.fig)
        grid = self.fig.add_gridspec(rows, RESPONSE_COLUMNS, **_fixed_layout_params(
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


# -- closed-loop validation ----------------------------------------------------------------

#: The loops of a validation report as the loop-gain panel draws them: (key, label, colour).
LOOP_STYLES = (("rate", "rate loop L_r", "tab:blue"), ("angle", "angle loop L_a", "tab:orange"),
               ("input", "input loop L_in", "tab:green"))
#: A margin whose crossover lies outside the identified band: a hollow marker, a grey
#: line to it and its label faded.
NOT_VALIDATED_COLOUR, NOT_VALIDATED_ALPHA = "0.5", 0.6
#: The loop-gain panel's magnitude axis shows at most this far from 0 dB (a loop with
#: integrators runs off to +100 dB at low frequency; the margins live near 0 dB).
LOOP_GAIN_DB_RANGE = 60.0


def plot_validation(axes, report, traces):
    """The paper's figures 12-16 onto the Axes ``axes`` (any shape, in row order): step
    response, sine tracking, Dryden turbulence, and the loop gains with their margins
    (:func:`plot_loop_gains`). Given four Axes, the fourth's place in its grid is split
    into the loop gains' magnitude over their phase (that Axes is removed); given five, the
    last two are those. Returns their figure. ``report`` and ``traces`` as
    :func:`~heliquad.host.validate.closed_loop.validate_model` returns them (SI units); drawn in
    degrees, deg/s and dB."""
    flat = list(np.asarray(axes, dtype=object).ravel())
    ax_step, ax_sine, ax_turb = flat[:3]
    ax_mag, ax_ph = flat[3:5] if len(flat) >= 5 else _split(flat[3])
    t = traces["t"]
    unit = "deg" if report.get("step", {}).get("quantity", "angle") == "angle" else "deg/s"
    sine = report.get("sine")
    sine_title = "sine tracking" + (f", {sine['omega_rad_s'] / (2 * np.pi):g} Hz" if sine else "")
    for ax, key, title in ((ax_step, "step", "step response"), (ax_sine, "sine", sine_title)):
        if key in traces:
            ref, out = traces[key]
            ax.plot(t, np.degrees(ref), "--", color="k", label="reference")
            ax.plot(t, np.degrees(out), label="response")
            ax.set_xlim(0, 10)
        ax.set_title(title)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"{report['axis']} ({unit})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    _turbulence(ax_turb, report, traces)
    plot_loop_gains((ax_mag, ax_ph), report, traces["loop_gains"])
    return ax_step.figure


def _split(ax):
    """Two Axes, magnitude over phase sharing the frequency axis, in ``ax``'s place in its
    grid (``ax`` removed)."""
    spec = ax.get_subplotspec()
    if spec is None:
        raise ValueError("the loop gains need their Axes in a grid (subplots, add_subplot) "
                         "to split it, or a fifth Axes")
    place, fig = spec.subgridspec(2, 1, hspace=0.05), ax.figure
    ax.remove()
    ax_mag = fig.add_subplot(place[0])
    return ax_mag, fig.add_subplot(place[1], sharex=ax_mag)


def _turbulence(ax, report, traces):
    t = traces["t"]
    if "turbulence" in traces:
        tr = traces["turbulence"]
        ax.plot(t, np.degrees(tr["gust"]), color="0.7", label="gust rate (deg/s)")
        ax.plot(t, np.degrees(tr["rate"]), label="rate, closed loop (deg/s)")
        if "angle" in tr:
            ax.plot(t, np.degrees(tr["angle"]), label="angle, closed loop (deg)")
        ax.set_title(f"Dryden turbulence, {report['turbulence']['level']}")
        ax.legend(fontsize=8)
    else:
        ax.set_title("no turbulence")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("deg/s, deg")
    ax.grid(alpha=0.3)


def plot_loop_gains(axes, report, gains):
    """Every loop of ``report`` (:func:`~heliquad.host.validate.closed_loop.validate_model`'s) onto a
    pair of Axes, magnitude (dB) over phase (deg) against rad/s (log scale); returns their
    figure. ``gains``: its traces' ``loop_gains``.

    The identified band shaded, the 0 dB and -180 deg lines; each reported margin marked
    at its crossover and labelled (the phase margin on the phase at the gain crossover, the
    gain margin on the magnitude at the phase crossover), hollow and grey, "not validated",
    when its crossover lies outside the band; the simulator's truth dashed when ``gains``
    has it; the points of the loop measured through the excitation (``measured_loop``) on
    their loop, each phase (known modulo 360 deg) on the turn of the model's curve there.
    """
    ax_mag, ax_ph = axes
    w = np.asarray(gains["omega_rad_s"], float)
    for ax, label in ((ax_mag, "identified band"), (ax_ph, "_band")):
        ax.axvspan(*report["band_rad_s"], color="0.92", zorder=0, label=label)
    levels = {-180.0}
    for n, (key, label, colour) in enumerate(LOOP_STYLES):
        if key not in gains:
            continue
        lp = report["loops"][key]
        phase = _phase_deg(gains[key], w, lp)
        ax_mag.semilogx(w, _db(gains[key]), color=colour, label=label)
        ax_ph.semilogx(w, phase, color=colour)
        truth = gains.get("truth", {}).get(key)
        if truth is not None:
            first = not any(line.get_label() == "simulator's truth" for line in ax_mag.lines)
            ax_mag.semilogx(w, _db(truth), "--", color=colour, lw=1,
                            label="simulator's truth" if first else "_truth")
            ax_ph.semilogx(w, _phase_deg(truth, w, report["truth"][key]), "--", color=colour,
                           lw=1)
        levels |= _mark_margins(ax_mag, ax_ph, w, phase, lp, colour, n)
        _measured_points(ax_mag, ax_ph, w, phase, report.get("measured_loop"), key, colour)
    _loop_axes(ax_mag, ax_ph, w, levels)
    return ax_mag.figure


def _db(L):
    with np.errstate(divide="ignore"):          # a zero on the axis: -inf dB, not drawn
        return 20 * np.log10(np.abs(L))


def _phase_deg(L, w, lp):
    """The unwrapped phase of the loop gain ``L`` (deg) on the turn where its margins
    (``lp``, :func:`~heliquad.host.validate.loops.margins`'s) read off -180 deg: at the gain
    crossover of its phase margin it is ``-180 + PM``; without one, -180 at the phase
    crossover of its gain margin; without either, it starts in (-360, 0]."""
    phase = np.degrees(np.unwrap(np.angle(L)))
    if lp.get("gain_crossover_rad_s") is not None:
        at, want = lp["gain_crossover_rad_s"], -180 + math.degrees(lp["phase_margin_rad"])
    elif lp.get("phase_crossover_rad_s") is not None:
        at, want = lp["phase_crossover_rad_s"], -180.0
    else:
        return phase - 360 * math.ceil(phase[0] / 360)
    there = np.interp(math.log(at), np.log(w), phase)
    return phase + 360 * round((want - there) / 360)


def _mark_margins(ax_mag, ax_ph, w, phase, lp, colour, n):
    """The loop's reported margins at their crossovers, labelled (staggered by the loop's
    index ``n``); returns the -180 + k 360 deg levels its gain margin reads off."""
    marks, levels = [], set()
    if lp.get("gain_crossover_rad_s") is not None:
        wc, pm = lp["gain_crossover_rad_s"], math.degrees(lp["phase_margin_rad"])
        marks.append((ax_ph, wc, -180 + pm, -180.0, f"PM {pm:.0f} deg",
                      _crossover_in_band(lp["gain_crossovers"], wc)))
    if lp.get("phase_crossover_rad_s") is not None:
        wp, gm = lp["phase_crossover_rad_s"], 20 * math.log10(lp["gain_margin"])
        level = -180 + 360 * round((np.interp(math.log(wp), np.log(w), phase) + 180) / 360)
        levels.add(float(level))
        marks.append((ax_mag, wp, -gm, 0.0, f"GM {gm:.1f} dB",
                      _crossover_in_band(lp["phase_crossovers"], wp)))
    for ax, at, value, reference, text, in_band in marks:
        ax.plot([at, at], [reference, value], color=colour if in_band else NOT_VALIDATED_COLOUR,
                lw=1, ls=":")
        ax.plot([at], [value], "o", ms=6, color=colour, mfc=colour if in_band else "none",
                gid="margin" if in_band else "margin not validated", label="_margin")
        right = math.log(at / w[0]) > 0.7 * math.log(w[-1] / w[0])    # label to its left
        ax.annotate(text + ("" if in_band else " not validated"), (at, value),
                    xytext=(-4 if right else 4, 3 + 8 * n), textcoords="offset points",
                    ha="right" if right else "left", fontsize=6, color=colour,
                    alpha=1 if in_band else NOT_VALIDATED_ALPHA, clip_on=True, in_layout=False,
                    bbox={"fc": "white", "ec": "none", "alpha": 0.7, "pad": 0.5})
    return levels


def _crossover_in_band(crossovers, at) -> bool:
    """Whether the crossover at ``at`` rad/s (one of ``crossovers``) lies in the band."""
    return next((c["in_band"] for c in crossovers if c["omega_rad_s"] == at), True)


def _measured_points(ax_mag, ax_ph, w, phase, measured, key, colour):
    """The points of the loop measured through the excitation, when it is loop ``key``:
    each phase on the turn nearest the model's curve ``phase`` at its frequency."""
    if not measured or measured.get("loop") != key or not measured.get("points"):
        return
    pts = measured["points"]
    at = 2 * np.pi * np.array([p["freq_hz"] for p in pts], float)
    db = np.array([p["magnitude_db"] for p in pts], float)
    deg = np.array([p["phase_deg"] for p in pts], float)
    deg += 360 * np.round((np.interp(np.log(at), np.log(w), phase) - deg) / 360)
    style = {"ls": "none", "marker": "D", "ms": 4, "color": colour, "mec": "k", "mew": 0.6}
    ax_mag.plot(at, db, label=f"measured through the excitation ({key})", **style)
    ax_ph.plot(at, deg, **style)


def _loop_axes(ax_mag, ax_ph, w, levels):
    """The loop-gain panel's lines (0 dB; -180 deg and each other turn a gain margin reads
    off), limits, labels and legend."""
    ax_mag.axhline(0, color="k", lw=0.8)
    for level in sorted(levels):
        ax_ph.axhline(level, color="k", lw=0.8)
    low, high = ax_mag.get_ylim()
    ax_mag.set_ylim(max(low, -LOOP_GAIN_DB_RANGE), min(high, LOOP_GAIN_DB_RANGE))
    low, high = ax_ph.get_ylim()
    ax_ph.set_ylim(max(low, min(levels) - 180), high + 20)
    ax_mag.set_xlim(w[0], w[-1])
    ax_mag.set_title("loop gains")
    ax_mag.set_ylabel("magnitude (dB)")
    ax_ph.set_ylabel("phase (deg)")
    ax_ph.set_xlabel("frequency (rad/s)")
    ax_mag.tick_params(labelbottom=False)
    for ax in (ax_mag, ax_ph):
        ax.set_xscale("log")
        ax.grid(alpha=0.3, which="both")
    ax_mag.legend(fontsize=6, loc="lower left", ncol=2)


def write_validation(path, report, traces):
    """:func:`plot_validation` in a figure of its own, titled, written to ``path``."""
    fig, axes = new_figure(2, 2, figsize=(12, 9.5))
    plot_validation(axes, report, traces)
    fig.suptitle(f"{report['axis']}: closed-loop validation of the identified model")
    save_figure(fig, path, dpi=100)
