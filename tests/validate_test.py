"""Closed-loop validation (host/validate.py, heliquad validate)."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import scipy.optimize

from heliquad.host import paper
from heliquad.host.plot import new_figure, plot_validation
from heliquad.host.validate import load_gains, validate_model, validation_record


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
    T, tf = 0.005, td / 10

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
    doc = validation_record(report)
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


def test_the_validation_plot_draws_in_degrees_onto_the_given_axes(roll_validation):
    report, traces = roll_validation
    fig, axes = new_figure(2, 2)
    assert plot_validation(axes, report, traces) is fig
    step_ax, loops_ax = axes[0, 0], axes[1, 1]
    assert max(step_ax.lines[0].get_ydata()) == pytest.approx(10)
    assert step_ax.get_ylabel() == "roll (deg)" and axes[0, 1].get_title() == "sine tracking, 0.5 Hz"
    pm = math.degrees(report["loops"]["rate"]["phase_margin_rad"])
    assert loops_ax.lines[0].get_label() == f"rate loop L_r: PM {pm:.0f} deg"
    assert len(loops_ax.lines) == 3                   # both loops and the 0 dB line


def cli(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli", "validate", *map(str, args)],
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
