"""heliquad verify's parts: a loop measured from its closed-loop response with the firmware's
controller known (exact against the cascade's own loops), the acceptance rule, the sweep's
band, verify.json; and the verification on the simulated rig in one session: accepted when
the predictions are the vehicle's, rejected with the previous gains read back from the board
when they are a plant's with twice its gain."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from heliquad.host.acquire.param_protocol import ParamClient, SessionLink
from heliquad.host.acquire.session import SilSession
from heliquad.host.acquire.sweep import sil_source
from heliquad.host.campaign.verify import VerifyPlan, verify_axis
from heliquad.host.records.gains import firmware_gains
from heliquad.host.records.tune import read_tune
from heliquad.host.records.verify import read_verify
from heliquad.host.validate.loops import LOOP_DT_S, _at, _controller, loop_functions
from heliquad.host.validate.loops import loop_from_closed
from heliquad.host.validate.verification import FLOOR, judge, measured_margins, sweep_band
from heliquad.sim.base.errors import InputError
from heliquad.sim.rig.setup import SilConfig

from tune_fixture import reduced_gains, vehicle_truth, write_tune_dir

OMEGA = np.geomspace(0.5, 300, 60)


def _closed(axis, gains):
    """The rate loop's (rate over rate setpoint) and the angle loop's (angle over angle
    setpoint) closed-loop responses around the vehicle's truth, from the controller's
    z-domain parts directly."""
    h, h_a = vehicle_truth(axis)
    (c, d), outer = _controller(gains, LOOP_DT_S)
    z = np.exp(1j * OMEGA * LOOP_DT_S)
    cz, dz = _at(c, z), _at(d, z)
    t_r = cz * h(OMEGA) / (1 + (cz - dz) * h(OMEGA))
    if outer is None:
        return t_r, None
    g_a = cz * h_a(OMEGA) / (1 + (cz - dz) * h(OMEGA))         # angle over rate setpoint
    kz, oz = _at(outer[0], z), _at(outer[1], z)
    return t_r, kz * g_a / (1 + (kz - oz) * g_a)


@pytest.mark.parametrize("axis", ["roll", "yaw"])
def test_a_loop_from_its_closed_response_is_the_cascades_own(axis):
    gains = reduced_gains(axis, 0.7)
    t_r, t_a = _closed(axis, gains)
    want = loop_functions(*vehicle_truth(axis), gains)
    np.testing.assert_allclose(loop_from_closed(OMEGA, t_r, gains, "rate"),
                               want["rate"](OMEGA), rtol=1e-9)
    if t_a is not None:
        np.testing.assert_allclose(loop_from_closed(OMEGA, t_a, gains, "angle"),
                                   want["angle"](OMEGA), rtol=1e-9)
    else:
        with pytest.raises(ValueError):
            loop_from_closed(OMEGA, t_r, gains, "angle")


PREDICTED = {"phase_margin_deg": 50.0, "gain_margin_db": 8.0,
             "uncertainty": {"phase_margin_deg": 7.0, "gain_margin_db": 0.2}}
SPEC = {"phase_margin_deg": 45.0, "gain_margin_db": 6.0}


def test_a_margin_within_its_uncertainty_and_above_the_spec_passes():
    allowed, failures = judge(PREDICTED, {"phase_margin_deg": 56.0, "gain_margin_db": 7.1}, SPEC)
    assert failures == []
    # the uncertainty where it is wider than the floor, the floor where it is tighter
    assert allowed == {"phase_margin_deg": 7.0, "gain_margin_db": FLOOR["gain_margin_db"]}


def test_a_noisy_measurement_widens_the_band_by_its_own_uncertainty():
    # 2.4 dB from its prediction: outside the prediction's band (the floor, 1 dB), inside the
    # band of a measurement good to +/- 2.5 dB (combined: hypot(0.2, 2.5) = 2.51 dB)
    measured = {"phase_margin_deg": 50.0, "gain_margin_db": 10.4}
    assert judge(PREDICTED, measured, SPEC)[1] == [
        "gain margin 10.4 dB measured, 8.0 +/- 1.0 predicted (1.4 dB outside)"]
    noisy = {**measured, "uncertainty": {"phase_margin_deg": 0.0, "gain_margin_db": 2.5}}
    allowed, failures = judge(PREDICTED, noisy, SPEC)
    assert failures == [] and allowed["gain_margin_db"] == pytest.approx(np.hypot(0.2, 2.5))
    assert allowed["phase_margin_deg"] == 7.0


def test_a_measured_margins_uncertainty_follows_its_points_sigma():
    gains = reduced_gains("roll", 0.7)
    t_r, _ = _closed("roll", gains)
    exact = measured_margins(OMEGA, t_r, gains, "rate", np.zeros(OMEGA.size))
    assert exact["uncertainty"] == {"phase_margin_deg": 0.0, "gain_margin_db": 0.0}
    u = [measured_margins(OMEGA, t_r, gains, "rate", rel * abs(t_r))["uncertainty"]
         for rel in (0.01, 0.04)]
    # a margin's spread grows with its points' noise, about in proportion; repeatable
    for key in ("phase_margin_deg", "gain_margin_db"):
        assert 0 < u[0][key] < u[1][key] and 2.5 < u[1][key] / u[0][key] < 6
    assert measured_margins(OMEGA, t_r, gains, "rate", 0.01 * abs(t_r))["uncertainty"] == u[0]


def test_the_acceptance_rule_says_each_failure_and_by_how_much():
    _, failures = judge(PREDICTED, {"phase_margin_deg": 41.0, "gain_margin_db": 9.5}, SPEC)
    assert failures == ["phase margin 41.0 deg measured, 50.0 +/- 7.0 predicted (2.0 deg "
                        "outside)",
                        "phase margin 41.0 deg below the specification's 45 deg by 4.0 deg",
                        "gain margin 9.5 dB measured, 8.0 +/- 1.0 predicted (0.5 dB outside)"]


def test_a_margin_the_sweep_did_not_reach_fails_and_one_predicted_absent_passes_if_absent():
    measured = {"phase_margin_deg": 50.0, "gain_margin_db": None,
                "unmeasured": ["gain margin: the phase of L does not cross -180 deg between "
                               "1 and 10 rad/s"]}
    _, failures = judge(PREDICTED, measured, SPEC)
    assert failures == ["gain margin not measured (the phase of L does not cross -180 deg "
                        "between 1 and 10 rad/s)"]
    none = {"phase_margin_deg": 50.0, "gain_margin_db": None}
    assert judge(none, none, {})[1] == []
    assert judge(none, {**none, "gain_margin_db": 3.0}, {})[1] == [
        "gain margin 3.0 dB measured, none predicted"]


def test_an_extrapolated_margin_is_held_to_the_spec_alone():
    predicted = {**PREDICTED, "extrapolated": ["gain_margin_db"]}
    # 5 dB from its prediction, but above the spec: the measurement is the evidence
    assert judge(predicted, {"phase_margin_deg": 50.0, "gain_margin_db": 13.0}, SPEC)[1] == []
    assert judge(predicted, {"phase_margin_deg": 50.0, "gain_margin_db": 5.0}, SPEC)[1] == [
        "gain margin 5.0 dB below the specification's 6 dB by 1.0 dB"]
    # the phase margin, read in band, is still held to its prediction
    assert judge(predicted, {"phase_margin_deg": 60.0, "gain_margin_db": 13.0}, SPEC)[1] == [
        "phase margin 60.0 deg measured, 50.0 +/- 7.0 predicted (3.0 deg outside)"]


def test_the_sweep_band_reaches_past_every_crossover_within_the_limits():
    loop = {"gain_crossover_rad_s": 10.0, "phase_crossover_rad_s": 40.0}
    assert sweep_band(loop, 300.0, 0.1) == (5.0, 60.0)
    assert sweep_band(loop, 50.0, 6.0) == (6.0, 50.0)
    assert sweep_band({"gain_crossover_rad_s": 10.0, "phase_crossover_rad_s": None},
                      300.0, 0.1) == (5.0, 15.0)
    # an extrapolated margin's crossover may lie anywhere above: up to the limit
    assert sweep_band({**loop, "extrapolated": ["gain_margin_db"]}, 300.0, 0.1) == (5.0, 300.0)


def test_verify_json_refuses_what_is_not_its_schema(tmp_path):
    path = tmp_path / "verify.json"
    path.write_text(json.dumps({"format": "heliquad verify", "version": 1, "tune": "tune.json",
                                "spec": {}, "floor": dict(FLOOR), "axes": {"rol": {}}}))
    with pytest.raises(InputError, match="verify.json"):
        read_verify(path)


def _verify_in_one_session(tmp_path, wrong_gain):
    """Roll verified on the simulated rig (short sweeps); returns the exit code, the lines,
    verify.json's roll entry and RATE_RLL_KC read back from the board in the same session."""
    folder = write_tune_dir(tmp_path / "tuned", {"roll": reduced_gains("roll", 0.6)},
                            wrong_gain=wrong_gain,
                            spec={"phase_margin_deg": 30.0, "gain_margin_db": 3.0})
    tune = read_tune(folder / "tune.json")
    plan = VerifyPlan(axis="roll", dir=str(folder), tune=tune,
                      entries=list(tune.axes["roll"]["params"].items()), rig_time_s=3.0)
    (folder / "verify" / "roll").mkdir(parents=True)
    cfg = SilConfig(axis="roll", rig="roll", inject="rate", plant="vehicle")
    with SilSession(cfg, str(folder / "verify" / "roll" / "session.tlog")) as session:
        code, lines = verify_axis(session, sil_source(cfg), plan, progress=lambda _: None)
        kc = ParamClient(SessionLink(session)).get("RATE_RLL_KC").value
    return code, lines, read_verify(folder / "verify.json").axes["roll"], kc


def test_tuned_gains_whose_predictions_hold_are_accepted_and_stay_on_the_board(tmp_path):
    code, lines, entry, kc = _verify_in_one_session(tmp_path, wrong_gain=1.0)
    assert (code, lines, entry["verdict"], entry["board_holds"]) == (0, [], "accepted", "tuned")
    assert kc == pytest.approx(reduced_gains("roll", 0.6).rate[0], rel=1e-6)
    for loop in ("rate", "angle"):
        r = entry["loops"][loop]
        assert r["passed"], r
        for key in ("phase_margin_deg", "gain_margin_db"):
            # measured near the truth, and the truth is what was predicted
            assert abs(r["measured"][key] - r["truth"][key]) < FLOOR[key]
            assert r["truth"][key] == pytest.approx(r["predicted"][key], abs=1e-6)


def test_wrong_predictions_are_rejected_and_the_previous_gains_are_back(tmp_path):
    code, lines, entry, kc = _verify_in_one_session(tmp_path, wrong_gain=2.0)
    assert code == 1 and entry["verdict"] == "rejected"
    assert [line.split(":")[0] for line in lines] == ["roll rate loop", "roll angle loop",
                                                      "rejected"]
    assert "outside" in lines[0] and lines[-1].endswith("the board holds its previous gains")
    assert kc == pytest.approx(firmware_gains("roll").rate[0], rel=1e-6)
    assert entry["restored"]["RATE_RLL_KC"] == pytest.approx(kc, rel=1e-6)
    assert entry["board_holds"] == "previous"
    assert math.isclose(entry["previous"]["RATE_RLL_KC"], kc, rel_tol=1e-6)
