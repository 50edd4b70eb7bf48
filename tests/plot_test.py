"""The plots (host/present/: figure.py, bode.py, responses.py, validation.py): they draw
onto the caller's axes and return the figure, and nothing in the tool picks a matplotlib
backend."""

import math
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure

from heliquad.host.estimate.fit import TfModel
from heliquad.host.estimate.thresholds import LOW_COHERENCE
from heliquad.host.present.bode import plot_bode, write_bode
from heliquad.host.present.figure import new_figure
from heliquad.host.present.responses import plot_responses
from heliquad.host.records import paper
from heliquad.host.records.points import frequency_points
from heliquad.host.validate.replay import replay_record

ROLL = paper.MODELS["roll"][(0, 2)]


def roll_points(n=8):
    omega = 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), n)
    F = np.polyval(ROLL[0], 1j * omega) / np.polyval(ROLL[1], 1j * omega)
    return omega, F


def roll_model():
    return TfModel(order=(0, 2), num=np.array(ROLL[0]), den=np.array(ROLL[1]), delay_s=0.0,
                   stable=True, metrics={"J": 0.5})


def test_bode_draws_onto_the_given_axes_and_returns_their_figure():
    fig = Figure()
    outer = fig.subfigures(1, 2)[1]                  # a place inside a larger figure
    axes = outer.subplots(2, 1, sharex=True)
    omega, F = roll_points()
    got = plot_bode(axes, frequency_points(omega, F, sigma=0.01 * np.abs(F)), models=[roll_model()],
                    recommended=0)
    assert got is axes[0].figure
    ax_mag, ax_ph = axes
    # the points (an errorbar: one line and its caps) and one model curve on each
    assert len(ax_mag.lines) >= 2 and len(ax_ph.lines) >= 2
    curve_db = ax_mag.lines[-1].get_ydata()
    dense = 2 * np.pi * ax_mag.lines[-1].get_xdata()
    expected = 20 * np.log10(np.abs(np.polyval(ROLL[0], 1j * dense) / np.polyval(ROLL[1], 1j * dense)))
    np.testing.assert_allclose(curve_db, expected, rtol=1e-9)
    assert ax_mag.get_xscale() == "log" and ax_ph.get_ylabel() == "phase (deg)"
    labels = [text.get_text() for text in ax_mag.get_legend().get_texts()]
    assert "0/2  J=0.5 (recommended)" in labels and "measured (1 sigma)" in labels


def twin(ax):
    """The output's axis that plot_responses set beside ``ax``."""
    (other,) = [a for a in ax.get_shared_x_axes().get_siblings(ax) if a is not ax]
    return other


def test_responses_fill_the_axes_in_row_order_and_hide_the_rest():
    fig, axes = new_figure(2, 3, squeeze=False)
    t = np.arange(0, 2, 0.005)
    segments = [(f, t, np.sin(2 * np.pi * f * t), 0.5 * np.sin(2 * np.pi * f * t - 1))
                for f in (0.5, 1.0, 2.0, 4.0)]
    assert plot_responses(axes, segments, "axis_cmd", "rate") is fig
    flat = axes.ravel()
    assert [ax.get_title() for ax in flat[:4]] == ["0.5 Hz", "1 Hz", "2 Hz", "4 Hz"]
    assert all(len(ax.lines) == 1 and len(twin(ax).lines) == 1 for ax in flat[:4])
    assert not flat[4].axison and not flat[5].axison
    assert "rad/s" in twin(flat[0]).lines[0].get_label()


def test_input_and_output_each_have_an_axis_of_their_own_coloured_as_their_line():
    # A torque command of order 1 against a rate of order 1e-3: on one axis the rate would
    # be a flat line. Each gets its own scale, labelled with its unit in its line's colour.
    fig, axes = new_figure(1, 1, squeeze=False)
    t = np.arange(0, 2, 0.005)
    u, y = np.sin(2 * np.pi * t), 1e-3 * np.sin(2 * np.pi * t - 1)
    plot_responses(axes, [(1.0, t, u, y)], "axis_cmd", "rate")
    left = axes[0, 0]
    right = twin(left)
    assert right.get_ylim()[1] < 2e-3 < 0.5 < left.get_ylim()[1]
    for ax, unit in ((left, "torque cmd"), (right, "rad/s")):
        label = ax.yaxis.get_label()
        assert unit in label.get_text()
        assert to_rgba(label.get_color()) == to_rgba(ax.lines[0].get_color())
        assert to_rgba(ax.yaxis.get_ticklabels()[0].get_color()) == to_rgba(ax.lines[0].get_color())


def test_a_replay_is_drawn_over_its_analysed_periods_on_the_output_axis():
    fig, axes = new_figure(1, 2, squeeze=False)
    t = np.arange(0, 4, 0.01)                              # 4 periods of 100 samples
    u, y = np.sin(2 * np.pi * t), 0.5 * np.sin(2 * np.pi * t - 1)
    replay = replay_record(lambda w: 0.5 * np.exp(-1j * np.ones_like(w)), u, y, 100.0, 100)
    plot_responses(axes, [(1.0, t, u, y), (1.0, t, u, y)], "rate_sp", "rate", [replay, None])
    drawn = twin(axes[0, 0]).lines[-1]
    assert drawn.get_label().startswith("replay")
    np.testing.assert_allclose(drawn.get_xdata(), t[100:])       # the first period discarded
    np.testing.assert_allclose(drawn.get_ydata(), y[100:], atol=1e-9)
    assert axes[0, 0].get_title() == "1 Hz, replay error 0.0 %"
    assert len(twin(axes[0, 1]).lines) == 1 and axes[0, 1].get_title() == "1 Hz"


def coherence_panel(coherence, n=8):
    fig, axes = new_figure(3, 1, sharex=True)
    omega, F = roll_points(n)
    plot_bode(axes, frequency_points(omega, F, **coherence), models=[roll_model()],
              gate=LOW_COHERENCE)
    return axes[2]


def test_the_coherence_panel_shows_r_to_y_and_r_to_u_and_the_gate():
    ry, ru = np.linspace(0.99, 0.9, 8), np.linspace(0.95, 0.3, 8)
    ax = coherence_panel({"coherence": np.fmin(ry, ru), "coherence_ry": ry, "coherence_ru": ru})
    points = {line.get_label(): line for line in ax.lines if line.get_linestyle() == "None"}
    assert sorted(points) == ["r -> u", "r -> y"]
    np.testing.assert_allclose(points["r -> y"].get_ydata(), ry)
    np.testing.assert_allclose(points["r -> u"].get_ydata(), ru)
    omega, _ = roll_points()
    np.testing.assert_allclose(points["r -> u"].get_xdata(), omega / (2 * np.pi))
    (gate,) = [line for line in ax.lines if line.get_label().startswith("quality gate")]
    assert set(gate.get_ydata()) == {LOW_COHERENCE}
    assert ax.get_xscale() == "log" and ax.get_xlabel() == "frequency (Hz)"


def test_the_coherence_panel_draws_what_the_points_have():
    # points.csv of `heliquad fsf`, or an older identify: one coherence, or none at all
    only = coherence_panel({"coherence": np.full(8, 0.97), "coherence_ry": None})
    assert [line.get_label() for line in only.lines if line.get_linestyle() == "None"] == ["coherence"]
    unknown = coherence_panel({"coherence": np.full(8, np.nan)})
    assert not [line for line in unknown.lines if line.get_linestyle() == "None"]
    assert "no coherence" in unknown.texts[0].get_text()


def test_write_bode_adds_the_coherence_panel_when_the_points_have_coherence(tmp_path):
    from matplotlib.image import imread

    omega, F = roll_points()
    write_bode(tmp_path / "two.png", frequency_points(omega, F))
    write_bode(tmp_path / "three.png", frequency_points(omega, F, coherence=np.ones(8)))
    assert imread(tmp_path / "three.png").shape[0] > 1.15 * imread(tmp_path / "two.png").shape[0]


def test_responses_refuse_too_few_axes():
    fig, axes = new_figure(1, 2)
    t = np.arange(0, 1, 0.01)
    with pytest.raises(ValueError, match="3 frequencies need as many axes"):
        plot_responses(axes, [(1.0, t, t, t)] * 3, "rate_sp", "rate")


def test_writing_a_plot_keeps_the_callers_backend(tmp_path):
    # A notebook or GUI user has chosen a backend; the tool's plots must not switch it.
    code = f"""
import matplotlib
matplotlib.use("pdf")
import numpy as np
from heliquad.host.present.bode import write_bode
from heliquad.host.records.points import frequency_points
omega = np.array([1.0, 2.0, 4.0])
write_bode({str(tmp_path / 'bode.png')!r}, frequency_points(omega, 1 / (1 + 1j * omega)))
print(matplotlib.get_backend())
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().lower() == "pdf"
    assert (tmp_path / "bode.png").read_bytes()[:4] == b"\x89PNG"


def test_the_envelope_keeps_each_column_s_extremes_in_order():
    from heliquad.host.present.responses import _envelope

    t = np.arange(6000) * 0.005
    y = np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 41 * t)
    te, ye = _envelope(t, y, 260)
    assert te.size < 600 and np.all(np.diff(te) > 0)           # in time order, far fewer
    ramp_t, _ = _envelope(t, t, 260)                            # extremes at the runs' ends
    assert np.all(np.diff(ramp_t) > 0)                          # each sample once
    per = y.size // 260
    for k in range(0, 260 * per, per):                          # each column's extremes kept
        assert y[k:k + per].max() in ye and y[k:k + per].min() in ye
    assert (te[0], te[-1]) == (t[0], t[-1])
    short = np.arange(100.0)
    assert _envelope(short, short, 260)[1] is short             # nothing to thin


def test_the_responses_figure_gives_each_record_its_own_scales(tmp_path):
    from matplotlib.image import imread

    from heliquad.host.present.responses import ResponsesFigure

    t = np.arange(0, 4, 0.005)
    slow = (0.5, t, 0.1 * np.sin(np.pi * t), 2e-3 * np.sin(np.pi * t - 1))
    fast = (2.0, t[:400] + 7.0, 3.0 * np.sin(4 * np.pi * t[:400]), 50 * np.sin(4 * np.pi * t[:400]))
    figure = ResponsesFigure([slow, fast, slow, fast], "axis_cmd", "rate")
    (p0, x0, y0, r0), (p1, x1, y1, r1) = figure.panels[:2]
    assert x0[0] <= 0 and 3.99 <= x0[1] < 4.5 and 1.99 <= x1[1] < 2.3    # time from 0, its own
    assert 0.1 <= y0[1] < 0.15 and 3.0 <= y1[1] < 4.0                     # each input's scale
    assert 2e-3 <= r0[1] < 3e-3 and 50 <= r1[1] < 60                      # each output's
    assert p1.x0 > p0.x1 and figure.panels[3][0].y1 < p0.y0             # across, then down
    figure.save(tmp_path / "responses.png", title="two records")
    assert imread(tmp_path / "responses.png").shape[:2] == figure.fig.canvas.get_width_height()[::-1]


@pytest.mark.parametrize("band_hz, some", [((0.62, 0.93), {"0.7", "0.8", "0.9"}),
                                           ((1.1, 1.9), {"1.2", "1.5", "1.8"}),
                                           ((0.15, 1.6), {"0.2", "0.5", "1"})])
def test_the_frequency_axis_is_labelled_however_narrow_the_band(band_hz, some):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig, axes = new_figure(2, 1, layout=None, sharex=True)
    f = np.linspace(*band_hz, 6)
    plot_bode(axes, frequency_points(2 * np.pi * f, 1 / (2j * np.pi * f + 1)))
    FigureCanvasAgg(fig).draw()
    ax = axes[1]
    lo, hi = ax.get_xlim()
    shown = {t.get_text() for t in ax.xaxis.get_ticklabels(which="both")
             if t.get_text() and lo <= t.get_position()[0] <= hi}
    assert some <= shown, shown
    assert not any("$" in text for text in shown)                   # plain numbers


def test_a_figure_name_is_checked_for_its_format_before_any_work(tmp_path, monkeypatch):
    """heliquad fit --plot: the extension picks the format (any case; PNG without one); one
    matplotlib cannot write, or pgf without the TeX it needs, is refused up front."""
    from heliquad.host.records.figures import check_figure_output, figure_format
    from heliquad.sim.base.errors import InputError

    assert [figure_format(n) for n in ("b.PNG", "b.svg", "bode", "a.b/c")] == \
        ["png", "svg", "png", "png"]
    for name in ("b.png", "b.PDF", "bode"):
        check_figure_output(tmp_path / name, "--plot")
    with pytest.raises(InputError, match=r"--plot .*b\.xyz: \.xyz is not an image format.*\.png"):
        check_figure_output(tmp_path / "b.xyz", "--plot")
    monkeypatch.setenv("PATH", str(tmp_path))              # no TeX on it
    with pytest.raises(InputError, match=r"\.pgf figures need \w+latex"):
        check_figure_output(tmp_path / "b.pgf", "--plot")
    assert list(tmp_path.iterdir()) == []                   # nothing written by a check
