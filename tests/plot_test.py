"""The plots (host/plot.py): they draw onto the caller's axes and return the figure, and
nothing in the tool picks a matplotlib backend."""

import math
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.figure import Figure

from heliquad.host import paper
from heliquad.host.fit import TfModel
from heliquad.host.plot import new_figure, plot_bode, plot_responses

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
    got = plot_bode(axes, omega, F, sigma=0.01 * np.abs(F), models=[roll_model()], recommended=0)
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


def test_responses_fill_the_axes_in_row_order_and_hide_the_rest():
    fig, axes = new_figure(2, 3, squeeze=False)
    t = np.arange(0, 2, 0.005)
    segments = [(f, t, np.sin(2 * np.pi * f * t), 0.5 * np.sin(2 * np.pi * f * t - 1))
                for f in (0.5, 1.0, 2.0, 4.0)]
    assert plot_responses(axes, segments, "axis_cmd", "rate") is fig
    flat = axes.ravel()
    assert [ax.get_title() for ax in flat[:4]] == ["0.5 Hz", "1 Hz", "2 Hz", "4 Hz"]
    assert all(len(ax.lines) == 2 for ax in flat[:4])
    assert not flat[4].axison and not flat[5].axison
    assert "rad/s" in flat[0].lines[1].get_label()


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
from heliquad.host.plot import write_bode
omega = np.array([1.0, 2.0, 4.0])
write_bode({str(tmp_path / 'bode.png')!r}, omega, 1 / (1 + 1j * omega))
print(matplotlib.get_backend())
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().lower() == "pdf"
    assert (tmp_path / "bode.png").read_bytes()[:4] == b"\x89PNG"
