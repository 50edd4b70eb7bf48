"""The cascade as the firmware flies it (host/validate/loops.py): loop gains, margins, discrete loops."""

import math

import numpy as np
import pytest

from heliquad import _firmware as fw
from heliquad.host.estimate.fit import fit_tf
from heliquad.host.records import paper
from heliquad.host.records.gains import firmware_gains
from heliquad.host.validate import loops
from heliquad.host.validate.closed_loop import validate_model
from heliquad.sim.rig.setup import SilConfig, make_plant

DT = loops.LOOP_DT_S
ROLL = paper.MODELS["roll"][(0, 2)]


def test_the_loop_period_is_the_firmwares():
    assert DT == pytest.approx(1 / 200) and fw.LOOP_RATE_HZ == 200


@pytest.mark.parametrize("outer", [False, True])
def test_the_discrete_closed_loop_is_the_loop_algebra(outer):
    # The state-space closed loop, evaluated on the unit circle, against the loop formulas
    # of the module docstring with the same discrete plant: d -> rate is h / (1 + L) with L
    # broken at the plant input (L_r alone, or L_in with the angle loop closed).
    num, den = ROLL
    gains = firmware_gains("roll")
    Gd = loops.discrete_model(num, den, 0.0123, DT)
    sys = loops.discrete_cascade(num, den, 0.0123, gains, DT, outer=outer)
    w = np.array([0.7, 5.0, 40.0, 300.0])
    h = lambda x: Gd(np.exp(1j * np.asarray(x) * DT))                  # noqa: E731
    h_a = lambda x: h(x) * DT / 2 * (np.exp(1j * np.asarray(x) * DT) + 1) / (
        np.exp(1j * np.asarray(x) * DT) - 1)                          # Tustin integral
    f = loops.loop_functions(h, h_a if outer else None, gains, DT)
    L = f["input" if outer else "rate"](w)
    got = np.array([sys(np.exp(1j * x * DT))[0, 1] for x in w])
    assert np.allclose(got, h(w) / (1 + L), rtol=1e-9)


def test_on_the_raw_path_the_cascade_sums_the_rate_as_the_firmware_does():
    # The firmware's raw-path attitude filter adds T times each rate sample as it arrives:
    # T z / (z - 1), half a loop period ahead of the integral (the DMP path's, and Tustin's).
    num, den = ROLL
    gains = firmware_gains("roll")
    w = np.array([0.7, 5.0, 40.0, 300.0])
    z = np.exp(1j * w * DT)
    raw = loops.angle_over_rate(loops.RAW_PATH)(w)
    assert np.allclose(raw, DT * z / (z - 1), rtol=1e-12)
    lead = np.angle(raw / loops.angle_over_rate(None)(w))
    assert np.allclose(lead, w * DT / 2, rtol=1e-9)
    Gd = loops.discrete_model(num, den, 0.0123, DT)
    sys = loops.discrete_cascade(num, den, 0.0123, gains, DT, outer=True, imu_path="raw")
    h = lambda x: Gd(np.exp(1j * np.asarray(x) * DT))                  # noqa: E731
    f = loops.loop_functions(h, lambda x: h(x) * loops.angle_over_rate("raw")(x), gains, DT)
    got = np.array([sys(np.exp(1j * x * DT))[0, 1] for x in w])
    assert np.allclose(got, h(w) / (1 + f["input"](w)), rtol=1e-9)


def _truth(axis):
    plant = make_plant(SilConfig(axis=axis, rig=axis, inject="mixer", plant="vehicle"), DT)
    return (lambda w: plant.sampled(w)[0]), (lambda w: plant.sampled(w)[1])


def test_every_crossover_is_found_and_the_worst_margins_reported():
    # An integrator crossing at 2 rad/s and a lightly damped resonance at 10 rad/s that
    # lifts |L| above 1 again: three gain crossovers, and phase crossovers among them.
    def L(w):
        s = 1j * np.asarray(w, dtype=float)
        return 2 / s * (s * s + 10 * s + 100) / (s * s + 0.4 * s + 100) * np.exp(-0.02 * s)

    m = loops.margins(L, (0.5, 100.0), DT)
    assert len(m["gain_crossovers"]) == 3 and len(m["phase_crossovers"]) >= 1
    worst = min(c["phase_margin_rad"] for c in m["gain_crossovers"])
    assert m["phase_margin_rad"] == worst
    for c in m["gain_crossovers"]:
        assert abs(L(c["omega_rad_s"])) == pytest.approx(1, rel=1e-9)
    for c in m["phase_crossovers"]:
        v = L(c["omega_rad_s"])
        assert abs(v.imag) < 1e-9 * abs(v) and v.real < 0
    assert m["not_validated"] == []


def test_margins_outside_the_band_are_not_validated_and_say_where():
    truth = _truth("roll")
    m = loops.margins(loops.loop_functions(*truth, firmware_gains("roll"))["rate"],
                      (2 * math.pi * 0.5, 2 * math.pi * 4.5))
    assert len(m["not_validated"]) == 2
    assert m["not_validated"][0].startswith("phase margin: gain crossover at 69.8 rad/s outside "
                                            "the identified band (3.14-28.3 rad/s)")


def test_a_model_identified_past_the_crossovers_gives_the_truths_margins():
    # Points of the simulator's roll truth from 0.5 to 40 Hz (past every crossover), a
    # 1/3 model with a fitted delay: each margin of each loop within 1 dB and 3 deg of the
    # truth loop's (the firmware's discrete PID around the linearised vehicle).
    truth = _truth("roll")
    w = 2 * math.pi * np.geomspace(0.5, 40, 20)
    model = fit_tf(w, truth[0](w), (1, 3), delay=True)
    report, _ = validate_model(model.num, model.den, model.delay_s, "roll",
                               firmware_gains("roll"), None, band_rad_s=(w[0], w[-1]),
                               truth=truth)
    for name in ("rate", "input"):
        got, want = report["loops"][name], report["truth"][name]
        assert got["not_validated"] == []
        assert 20 * math.log10(got["gain_margin"] / want["gain_margin"]) == pytest.approx(0, abs=1)
        assert math.degrees(got["phase_margin_rad"] - want["phase_margin_rad"]) == \
            pytest.approx(0, abs=3)
    # the truth's own figures: the roll rate loop as flown is close to its limits
    assert 20 * math.log10(report["truth"]["rate"]["gain_margin"]) == pytest.approx(1.63, abs=0.05)
    assert math.degrees(report["truth"]["rate"]["phase_margin_rad"]) == pytest.approx(22.7, abs=0.2)


def test_a_crossing_is_refined_to_its_frequency_s_rounding():
    grid = np.linspace(1.0, 10.0, 10)
    f = lambda w: math.cos(w)                            # noqa: E731
    roots = loops._roots(f, grid, np.cos(grid))
    np.testing.assert_allclose(roots, [math.pi / 2, 3 * math.pi / 2, 5 * math.pi / 2],
                               rtol=2 * loops.ROOT_RTOL)
    # a sign change across a pole is no crossing: on a midpoint, or between them
    for at in (2.5, 2.3):
        pole = lambda w: 1.0 / (w - at) if w != at else math.nan     # noqa: E731
        assert loops._roots(pole, np.array([2.0, 3.0]), np.array([pole(2.0), pole(3.0)])) == []
