"""Closed-loop validation (host/validate/closed_loop.py, heliquad validate)."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import scipy.optimize

from heliquad.host.present.figure import new_figure
from heliquad.host.present.validation import plot_validation
from heliquad.host.records import paper
from heliquad.host.records.output import document
from heliquad.host.validate.closed_loop import load_gains, validate_model, validation_record
from heliquad.sim.base.firmware_facts import LOOP_PERIOD_S


@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_papers_models_and_gains_give_stable_loops_with_margins(axis):
    num, den = paper.MODELS[axis][paper.CHOSEN_ORDER[axis]]
    report, _ = validate_model(num, den, 0.0, axis, load_gains(axis), turbulence="moderate", seed=1)
    assert report["stable"]
    for loop in report["loops"].values():
        assert loop["closed_loop_stable"] and loop["phase_margin_rad"] > math.radians(30)
    assert set(report["loops"]) == ({"rate"} if axis == "yaw" else {"rate", "angle", "input"})
    assert report["turbulence"]["rate_rms_rad_s"] < report["turbulence"]["gust_rate_rms_rad_s"]


def test_rate_loop_phase_margin_matches_a_hand_computation():
    # The firmware's PID at 200 Hz, written out from its recurrences: P, the trapezoidal
    # integral Kc T/(2 tau_I) (z + 1)/(z - 1) on the error, and the filtered derivative on the
    # measurement -b (z - 1)/(z - a) (a = (2 tau_f - T)/(2 tau_f + T), b = 2 Kc tau_D/(2 tau_f
    # + T), tau_f = tau_D/10). Broken at the plant input: L = (C_PI - D_m) G(jw).
    kc, ti, td = paper.RATE_GAINS["roll"]
    T, tf = LOOP_PERIOD_S, td / 10

    def L(w):
        z, s = np.exp(1j * w * T), 1j * w
        c_pi = kc + kc * T / (2 * ti) * (z + 1) / (z - 1)
        d_m = -2 * kc * td / (2 * tf + T) * (z - 1) / (z - (2 * tf - T) / (2 * tf + T))
        return (c_pi - d_m) * 28.19 / (s * s + 5.13 * s + 22.93)

    wc = scipy.optimize.brentq(lambda w: abs(L(w)) - 1, 1.0, 100.0)
    pm = math.pi + np.angle(L(wc))
    report, _ = validate_model([28.19], [1, 5.13, 22.93], 0.0, "roll", load_gains("roll"), None)
    assert report["loops"]["rate"]["phase_margin_rad"] == pytest.approx(pm, abs=1e-6)
    assert report["loops"]["rate"]["gain_crossover_rad_s"] == pytest.approx(wc, rel=1e-6)


def test_delay_costs_phase_margin():
    base, _ = validate_model([28.19], [1, 5.13, 22.93], 0.0, "roll", load_gains("roll"), None)
    late, _ = validate_model([28.19], [1, 5.13, 22.93], 0.05, "roll", load_gains("roll"), None)
    wc = base["loops"]["rate"]["gain_crossover_rad_s"]
    lost = base["loops"]["rate"]["phase_margin_rad"] - late["loops"]["rate"]["phase_margin_rad"]
    assert lost == pytest.approx(wc * 0.05, rel=0.05)   # w_c tau, crossover unmoved


def _keys(doc):
    if isinstance(doc, dict):
        for key, value in doc.items():
            yield key
            yield from _keys(value)


@pytest.fixture(scope="module")
def roll_validation():
    num, den = paper.MODELS["roll"][paper.CHOSEN_ORDER["roll"]]
    return validate_model(num, den, 0.0, "roll", load_gains("roll"), "moderate", seed=2)


def test_the_report_and_traces_are_in_si_units(roll_validation):
    report, traces = roll_validation
    assert not [k for k in _keys(report) if "deg" in k or k.endswith(("_db", "_hz"))]
    step = report["step"]
    assert step["quantity"] == "angle" and step["size"] == pytest.approx(math.radians(10))
    ref, out = traces["step"]
    assert ref[0] == step["size"] and out[-1] == pytest.approx(step["size"], rel=1e-3)
    assert report["sine"]["omega_rad_s"] == pytest.approx(math.pi)
    assert np.max(traces["sine"][0]) == pytest.approx(math.radians(10), rel=1e-4)
    # the gust rate (rad/s) is the Dryden model's own output: its RMS is of order 1 rad/s
    tb = report["turbulence"]
    assert np.std(traces["turbulence"]["gust"]) == pytest.approx(tb["gust_rate_rms_rad_s"])
    assert 0.1 < tb["gust_rate_rms_rad_s"] < 5 and tb["angle_rms_rad"] < tb["angle_max_rad"] < 1
    loop = report["loops"]["angle"]
    assert loop["gain_margin"] > 1 and 0 < loop["phase_margin_rad"] < math.pi


def test_the_record_is_the_report_in_degrees_db_and_hz(roll_validation):
    report, _ = roll_validation
    record = validation_record(report)
    doc = document(record)
    assert set(doc) == {"axis", "num", "den", "delay_s", "gains", "band_rad_s", "loops", "stable",
                        "step", "sine", "turbulence"}
    for name, loop in report["loops"].items():
        rec = doc["loops"][name]
        assert set(rec) == {"gain_margin_db", "phase_margin_deg", "gain_crossover_rad_s",
                            "phase_crossover_rad_s", "closed_loop_stable", "unstable_pole_rad_s",
                            "gain_crossovers", "phase_crossovers", "not_validated"}
        assert rec["phase_margin_deg"] == pytest.approx(math.degrees(loop["phase_margin_rad"]))
        assert rec["gain_crossover_rad_s"] == loop["gain_crossover_rad_s"]
    rate_gm = report["loops"]["rate"]["gain_margin"]
    assert doc["loops"]["rate"]["gain_margin_db"] == (None if rate_gm is None else
                                                     pytest.approx(20 * math.log10(rate_gm)))
    assert doc["loops"]["angle"]["gain_margin_db"] == pytest.approx(
        20 * math.log10(report["loops"]["angle"]["gain_margin"]))
    assert doc["step"]["size"] == pytest.approx(10) and doc["step"]["unit"] == "deg"
    assert doc["step"]["rise_time_s"] == report["step"]["rise_time_s"]
    assert doc["sine"]["freq_hz"] == pytest.approx(0.5)
    assert doc["sine"]["amplitude"] == pytest.approx(10)
    assert doc["sine"]["tracking_rms"] == pytest.approx(math.degrees(report["sine"]["tracking_rms"]))
    tb, rec = report["turbulence"], doc["turbulence"]
    assert rec["gust_rate_rms_deg_s"] == pytest.approx(math.degrees(tb["gust_rate_rms_rad_s"]))
    assert rec["angle_max_deg"] == pytest.approx(math.degrees(tb["angle_max_rad"]))
    json.dumps(doc)                                   # plain JSON: no numpy types left


def loop_gain_axes(fig):
    """The loop-gain panel's magnitude and phase Axes, by their labels."""
    (mag,) = [ax for ax in fig.axes if ax.get_ylabel() == "magnitude (dB)"]
    (ph,) = [ax for ax in fig.axes if ax.get_ylabel() == "phase (deg)"]
    return mag, ph


def test_the_validation_plot_draws_in_degrees_onto_the_given_axes(roll_validation):
    report, traces = roll_validation
    fig, axes = new_figure(2, 2)
    assert plot_validation(axes, report, traces) is fig
    step_ax = axes[0, 0]
    assert max(step_ax.lines[0].get_ydata()) == pytest.approx(10)
    assert step_ax.get_ylabel() == "roll (deg)" and axes[0, 1].get_title() == "sine tracking, 0.5 Hz"
    # the fourth panel's place is split: magnitude over phase, sharing the frequency axis
    mag, ph = loop_gain_axes(fig)
    assert axes[1, 1] not in fig.axes and len(fig.axes) == 5
    assert mag.get_shared_x_axes().joined(mag, ph) and mag.get_title() == "loop gains"
    assert ph.get_xlabel() == "frequency (rad/s)" and ph.get_xscale() == "log"
    curves = {line.get_label(): line for line in mag.lines if line.get_linestyle() == "-"}
    assert {"rate loop L_r", "angle loop L_a", "input loop L_in"} <= set(curves)
    L = traces["loop_gains"]["input"]
    np.testing.assert_allclose(curves["input loop L_in"].get_ydata(), 20 * np.log10(np.abs(L)))
    assert -180 in [line.get_ydata()[0] for line in ph.lines if len(line.get_xdata()) == 2
                    and line.get_xdata()[0] == 0]


def test_each_loops_phase_is_drawn_on_the_turn_its_phase_margin_reads_off():
    # A slow pole puts the input loop's phase below -180 deg at the grid's first frequency,
    # where the principal angle is +122 deg: unwrapped from there the curve would sit a turn
    # too high, its phase margin read off nothing.
    from heliquad.host.present.validation import plot_loop_gains

    den = list(np.polymul([1, 0.05], [1, 5.13, 22.93]))
    report, traces = validate_model([28.19], den, 0.0, "roll", load_gains("roll"), None)
    gains = traces["loop_gains"]
    assert np.angle(gains["input"][0]) > 0
    fig, axes = new_figure(2, 1, sharex=True)
    assert plot_loop_gains(axes, report, gains) is fig
    w = gains["omega_rad_s"]
    colours = {"tab:blue": "rate", "tab:orange": "angle", "tab:green": "input"}
    curves = {colours[line.get_color()]: line.get_ydata() for line in axes[1].lines
              if line.get_color() in colours and len(line.get_xdata()) == len(w)}
    assert set(curves) == {"rate", "angle", "input"}
    for key, phase in curves.items():
        lp = report["loops"][key]
        at = np.interp(math.log(lp["gain_crossover_rad_s"]), np.log(w), phase)
        assert at == pytest.approx(-180 + math.degrees(lp["phase_margin_rad"]), abs=0.5), key


def margin_marks(ax):
    """The margin markers on ``ax``: ``[(x, y, validated, hollow)]``."""
    return [(line.get_xdata()[0], line.get_ydata()[0], line.get_gid() == "margin",
             line.get_markerfacecolor() == "none")
            for line in ax.lines if (line.get_gid() or "").startswith("margin")]


def mark_at(marks, x):
    (found,) = [m for m in marks if m[0] == pytest.approx(x)]
    return found


def test_each_margin_is_marked_at_its_crossover_hollow_when_not_validated(roll_validation):
    # The paper's band for roll is 3.1-28 rad/s: the rate loop crosses 0 dB inside it, the
    # angle loop below it (1.5 rad/s): margins validated and not, on the same plot.
    report, traces = roll_validation
    fig, axes = new_figure(2, 2)
    plot_validation(axes, report, traces)
    mag, ph = loop_gain_axes(fig)
    pms, gms = margin_marks(ph), margin_marks(mag)
    expected = []
    for lp in report["loops"].values():
        wc = lp["gain_crossover_rad_s"]
        _, y, validated, hollow = mark_at(pms, wc)
        assert y == pytest.approx(-180 + math.degrees(lp["phase_margin_rad"]))
        expected.append(next(c["in_band"] for c in lp["gain_crossovers"] if c["omega_rad_s"] == wc))
        assert validated == expected[-1] != hollow
        if lp["gain_margin"] is not None:
            wp = lp["phase_crossover_rad_s"]
            _, y, validated, hollow = mark_at(gms, wp)
            assert y == pytest.approx(-20 * math.log10(lp["gain_margin"]))
            expected.append(next(c["in_band"] for c in lp["phase_crossovers"]
                                 if c["omega_rad_s"] == wp))
            assert validated == expected[-1] != hollow
    assert len(pms) + len(gms) == len(expected) and True in expected and False in expected
    said = [t.get_text() for ax in (mag, ph) for t in ax.texts]
    not_validated = sum(len(lp["not_validated"]) for lp in report["loops"].values())
    assert sum(t.endswith(" not validated") for t in said) == not_validated == expected.count(False)
    assert f"PM {math.degrees(report['loops']['rate']['phase_margin_rad']):.0f} deg" in said


def test_the_truth_is_dashed_and_the_measured_points_sit_on_their_loop():
    # A simulated sweep's validation: the truth's loops beside the model's, and the points
    # of the input loop measured through the excitation (here the model's own loop at five
    # frequencies where its phase is below -180 deg, recorded wrapped to +-180 deg as
    # identify records them: drawn on the model's turn).
    from heliquad.host.validate.loops import model_responses

    num, den = paper.MODELS["roll"][paper.CHOSEN_ORDER["roll"]]
    truth = model_responses([1.3 * c for c in num], den, 0.01)
    _, plain = validate_model(num, den, 0.02, "roll", load_gains("roll"), None)
    w, L = plain["loop_gains"]["omega_rad_s"], plain["loop_gains"]["input"]
    at = [300, 320, 340, 360, 380]
    measured = {"loop": "input", "injection": "mixer", "unmeasured": [],
                "points": [{"freq_hz": w[i] / (2 * math.pi), "magnitude_db": 20 * math.log10(abs(L[i])),
                            "phase_deg": math.degrees(np.angle(L[i]))} for i in at]}
    report, traces = validate_model(num, den, 0.02, "roll", load_gains("roll"), None,
                                    truth=truth, measured=measured)
    assert set(traces["loop_gains"]["truth"]) == {"rate", "angle", "input"}
    fig, axes = new_figure(2, 2)
    plot_validation(axes, report, traces)
    mag, ph = loop_gain_axes(fig)
    dashed = [line for line in mag.lines if line.get_linestyle() == "--"]
    assert len(dashed) == 3 and dashed[0].get_label() == "simulator's truth"
    np.testing.assert_allclose(dashed[2].get_ydata(),
                               20 * np.log10(np.abs(traces["loop_gains"]["truth"]["input"])))
    (points,) = [line for line in ph.lines if line.get_marker() == "D"]
    (curve,) = [line for line in mag.lines if line.get_label() == "input loop L_in"]
    assert points.get_color() == curve.get_color()
    (model_phase,) = [line for line in ph.lines if line.get_color() == curve.get_color()
                      and line.get_linestyle() == "-" and len(line.get_xdata()) == len(w)]
    np.testing.assert_allclose(points.get_xdata(), w[at])
    np.testing.assert_allclose(points.get_ydata(), model_phase.get_ydata()[at], atol=1e-9)
    assert np.all(points.get_ydata() < -180)
    labels = [t.get_text() for t in mag.get_legend().get_texts()]
    assert "measured through the excitation (input)" in labels


def cli(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "validate", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def models_file(tmp_path, num, den, axis="roll"):
    path = tmp_path / "models.json"
    path.write_text(json.dumps({"models": [{"order": [len(num) - 1, len(den) - 1], "num": num,
                                            "den": den, "delay_s": 0.0}],
                                "recommended": 0, "axis": axis}))
    return path


def test_cli_writes_report_and_plot(tmp_path):
    res = cli(models_file(tmp_path, [28.19], [1, 5.13, 22.93]), "--seed", 3)
    assert res.returncode == 0, res.stderr
    assert "phase margin" in res.stdout
    doc = json.loads((tmp_path / "validation.json").read_text())
    assert doc["stable"] and doc["turbulence"]["seed"] == 3
    pm = doc["loops"]["rate"]["phase_margin_deg"]
    assert 30 < pm < 90 and f"phase margin {pm:.1f} deg" in res.stdout
    assert (tmp_path / "validation.png").stat().st_size > 20_000


@pytest.mark.parametrize("num, den, extra", [
    ([1, 0], [1, 2, 1], []),                        # a zero at the origin: NaN margins inside
    ([3], [1, 0], ["--turbulence", "none"]),        # an integrator, no turbulence panel
    ([1.191], [1, 1.178], ["--axis", "yaw", "--turbulence", "none"]),
    ([0], [1, 1], []),                              # a zero model: no rise or settling time
])
def test_awkward_models_print_no_warning(tmp_path, num, den, extra):
    res = cli(models_file(tmp_path, num, den), *extra)
    assert res.returncode in (0, 1) and res.stderr == "", res.stderr


def test_an_unstable_cascade_is_reported_with_exit_1(tmp_path):
    gains = tmp_path / "gains.json"
    gains.write_text(json.dumps({"rate": {"roll": [400.0, 0.01, 0.2]}, "angle": {"roll": [50.0, 0.0]}}))
    res = cli(models_file(tmp_path, [28.19], [1, 5.13, 22.93]), "--gains", gains)
    assert res.returncode == 1 and "UNSTABLE" in res.stdout
    assert "closed-loop poles at" in res.stdout and "x the identified band's top" in res.stdout


def test_an_instability_far_above_the_band_is_told_apart_from_one_inside_it():
    # The demo's identified yaw model (0/1 with a 21 ms delay) under the paper's yaw gains: the
    # filtered derivative keeps the loop gain above 1 up to ~435 rad/s, and the closed loop is
    # unstable near 123 rad/s, 12x the yaw band's top (1.6 Hz): the model has no data there.
    far, _ = validate_model([6.0652], [1, 0.11048], 0.0213, "yaw", load_gains("yaw"), None)
    assert not far["stable"]
    inst = far["instability"]
    assert inst["outside_band"] and inst["pole_rad_s"] == pytest.approx(123, rel=0.02)
    assert inst["band_top_rad_s"] == pytest.approx(2 * math.pi * 1.6)
    # The paper's roll model with a 0.6 s delay goes unstable near its crossover, in the band.
    near, _ = validate_model([28.19], [1, 5.13, 22.93], 0.6, "roll", load_gains("roll"), None)
    assert not near["stable"] and not near["instability"]["outside_band"]
    assert near["instability"]["pole_rad_s"] < 3 * 2 * math.pi * 4.5


@pytest.mark.parametrize("content, extra, match", [
    ("not json", [], "not a MODELS.json"),
    ('{"models": [{"num": [1], "den": [1, 1]}], "recommended": 0}', [], "--axis"),
    ('{"models": [{"num": [1], "den": [1, 1]}], "recommended": 0, "axis": "roll"}',
     ["--model", "3"], "no model 3"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, content, extra, match):
    path = tmp_path / "m.json"
    path.write_text(content)
    res = cli(path, *extra)
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and match in res.stderr
