"""Experiment design under disturbance (host/acquire/design.py): the sequential dwell and the
designed amplitudes, on the simulated rig with the firmware in the loop."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from heliquad.host.acquire.design import AmplitudeDesign, Dwell
from heliquad.host.records.tlog import read_tlog
from heliquad.sim.base.dialect import dialect


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=900)


def sweep(out, *options):
    res = heliquad("sweep", "--axis", "roll", "--sil", "--out", out, *options)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr
    return json.loads((out / "manifest.json").read_text())


def samples(out):
    return [m for _, m in read_tlog(str(out / "sweep.tlog"), dialect(), only=("HQ_SYSID_SAMPLE",))]


def test_a_clean_frequency_ends_at_the_least_cycles_and_fades_out_in_order(tmp_path):
    # No disturbance: the point is known at once, so each frequency runs the published dwell's
    # 8 cycles (9 where the finish, sent at the batch's end, lands after the 8th's last
    # sample: a period shorter than the 50-frame batch), then the planned 2-cycle fade-out:
    # the excitation is never cut off at full amplitude.
    out = tmp_path / "clean"
    manifest = sweep(out, "--plant", "tf", "--freqs-hz", 0.8, 4.5, "--amplitude", 0.3)
    assert manifest["design"]["dwell"] == "sequential" and manifest["complete"]
    msgs = samples(out)
    running, fading = dialect().HQ_EXCITATION_STATE_RUNNING, dialect().HQ_EXCITATION_STATE_FADING
    for e, most in zip(manifest["frequencies"], (8, 9)):
        period = e["period_samples"]
        assert e["dwell_end"] == "target" and 8 <= e["cycles"] <= most
        assert e["samples"] == e["cycles"] * period and e["relative_sigma"] < 0.01
        after = [m for m in msgs if m.time_us > e["end_us"]][:2 * period + 1]
        assert all(m.exc_state == fading for m in after[:2 * period])
        assert after[-1].exc_state not in (running, fading)
        envelope = np.abs([m.excitation for m in after[:2 * period]])
        assert np.max(envelope[-period // 4:]) < 0.1 * 0.3      # faded to nearly nothing


def test_turbulence_gets_more_cycles_where_it_hides_the_point(tmp_path):
    # Moderate turbulence on the vehicle's roll rig: at 0.6 Hz the gusts swamp the response
    # and the dwell runs on until the point's sigma is 2 % or the cap; at 4 Hz it is clean.
    out = tmp_path / "gusty"
    manifest = sweep(out, "--turbulence", "moderate", "--seed", 2, "--freqs-hz", 0.6, 4.0,
                     "--amplitude", 1.0)
    low, high = manifest["frequencies"]
    assert low["cycles"] > 2 * high["cycles"]
    for e in (low, high):
        assert e["dwell_end"] == "cap" or e["relative_sigma"] <= Dwell().target_sigma
    assert low["cycles"] <= Dwell().cycles(low["freq_hz"])


def test_a_designed_amplitude_aims_at_the_swing_and_a_small_first_one_is_measured_again(tmp_path):
    # --swing-deg 4 in moderate turbulence: the first frequency starts at a quarter of the
    # bound, which swings the rig by less than half of 4 deg and leaves the point unknown
    # after the least cycles, so it is finished there and measured again at the designed
    # amplitude; the next frequency is designed from that response. (In still air the
    # first record would already be good enough and would be kept.)
    from heliquad.host.estimate.fsf import estimate_fsf

    out = tmp_path / "designed"
    manifest = sweep(out, "--swing-deg", 4, "--freqs-hz", 0.6, 0.7, "--turbulence", "moderate",
                     "--seed", 3)
    entries = manifest["frequencies"]
    assert len(entries) == 3 and entries[0]["status"].startswith("superseded: amplitude 0.25")
    assert entries[0]["dwell_end"] == "amplitude" and entries[0]["cycles"] == 8
    assert [e["status"] for e in entries[1:]] == ["ok", "ok"]
    assert entries[1]["amplitude"] >= 2 * entries[0]["amplitude"]
    msgs = samples(out)
    for e in entries[1:]:
        window = [m for m in msgs if e["start_us"] <= m.time_us <= e["end_us"]]
        r = np.array([m.excitation for m in window])
        angle = np.array([m.angle for m in window])
        fs = e["freq_hz"] * e["period_samples"]
        swing = math.degrees(abs(estimate_fsf(r, angle, fs, e["freq_hz"]).gain)) * e["amplitude"]
        assert 4 * 2 / 3 < swing < 4 * 4 / 3, swing          # the fundamental's swing
        assert e["amplitude"] <= manifest["design"]["amplitude_bound"]
    res = heliquad("identify", out)
    assert res.returncode == 0 and "2 points" in res.stdout   # the superseded record unused


def test_the_design_steps_at_most_4x_and_never_past_the_bound():
    d = AmplitudeDesign(bound=1.0, swing_deg=10.0)
    assert d.first() == 0.25
    assert d.next(1.0, 0.1, 1e-6) == pytest.approx(0.4)         # a tiny response: 4x at most
    assert d.next(1.0, 0.5, 1e-6) == 1.0                         # and never past the bound
    assert d.next(1.0, 0.8, 1e3) == pytest.approx(0.2)           # a huge one: 1/4 at most
    want = math.radians(10.0) * 2 * math.pi * 1.0 / 5.0          # 10 deg at 1 Hz, 5 per unit
    assert d.next(1.0, 0.2, 5.0) == pytest.approx(want)
    assert d.next(1.0, 0.3, float("nan")) == 0.3                 # nothing measured: keep it


def test_the_input_swings_at_most_half_the_bound():
    # Near the crossover the loop amplifies the excitation at the plant input: with 2 units
    # of input per unit of excitation, an amplitude past 0.25 would swing the command past
    # half the bound, however little the rig moves.
    d = AmplitudeDesign(bound=1.0, swing_deg=10.0)
    assert d.next(10.0, 0.5, 1e-3, 2.0) == pytest.approx(0.25)
    assert d.next(10.0, 0.5, 1e-3, 0.5) == 1.0                  # a quiet input: the bound
    assert d.next(10.0, 0.5, 1e-3, 40.0) == pytest.approx(0.0125)  # below 1/4 when it must


def test_the_cap_is_the_most_cycles_within_the_most_time_but_never_below_the_least():
    d = Dwell()
    assert d.cycles(4.0) == 48 and d.cycles(0.5) == 30 and d.cycles(0.1) == 8


def test_the_dwell_options_are_checked(tmp_path):
    res = heliquad("sweep", "--axis", "roll", "--sil", "--cycles", 8, "--target-sigma", 0.05,
                   "--out", tmp_path / "x")
    assert res.returncode == 2 and "give one or the other" in res.stderr
    res = heliquad("sweep", "--axis", "roll", "--sil", "--inject", "rate", "--swing-deg", 5,
                   "--out", tmp_path / "x")
    assert res.returncode == 2 and "--swing-deg designs mixer amplitudes" in res.stderr
    assert not (tmp_path / "x").exists()
