"""The replay (host/validate/replay.py): a sweep's measured input through a model, against the
measured output. Exact for a periodic steady state, blind to what does not repeat with the
excitation; on a noise-free simulated sweep the simulator's own truth replays the output to
a fraction of a percent, the identified model nearly as well, and a model 20 % off in gain
shows it."""

import json
import subprocess
import sys

import numpy as np
import pytest

from heliquad.host.estimate.fit import TfModel, model_response
from heliquad.host.validate.replay import replay_points, replay_record
from heliquad.sim.base.errors import InputError

FS = 200.0
PERIOD = 80                                   # 2.5 Hz at 200 Hz
NUM, DEN, DELAY = [28.19], [1.0, 5.13, 22.93], 0.012


def periodic_record(periods=6, offset=0.0):
    """A periodic input (the fundamental and two harmonics) and the exact steady-state output
    of NUM/DEN with DELAY, harmonic by harmonic."""
    k = np.arange(periods * PERIOD)
    w0 = 2 * np.pi * FS / PERIOD
    u = np.zeros(k.size)
    y = np.full(k.size, offset)
    for l, amp, phase in ((1, 1.0, 0.3), (2, 0.2, -1.0), (3, 0.05, 2.0)):
        g = model_response(NUM, DEN, DELAY, l * w0)
        u += amp * np.cos(l * w0 * k / FS + phase)
        y += abs(g) * amp * np.cos(l * w0 * k / FS + phase + np.angle(g))
    return u, y


def exact(omega):
    return model_response(NUM, DEN, DELAY, omega)


def test_the_replay_of_a_periodic_steady_state_is_exact():
    u, y = periodic_record(offset=0.7)                # a gyro's bias on the output
    r = replay_record(exact, u, y, FS, PERIOD, discard_periods=1)
    assert (r.start, r.periods, r.y.size) == (PERIOD, 5, 5 * PERIOD)
    assert r.freq_hz == pytest.approx(2.5)
    np.testing.assert_allclose(r.y, y[PERIOD:], atol=1e-12)
    assert r.nrmse < 1e-12


def test_a_gain_error_is_the_replay_error():
    u, y = periodic_record()
    r = replay_record(lambda w: 1.2 * exact(w), u, y, FS, PERIOD)
    assert r.nrmse == pytest.approx(0.2, rel=1e-9)
    late = replay_record(lambda w: exact(w) * np.exp(-1j * w * 0.01), u, y, FS, PERIOD)
    assert late.nrmse > 0.1                                     # 10 ms more delay: 9 deg


def test_what_does_not_repeat_with_the_excitation_is_not_replayed():
    # In a closed loop the input also holds the controller's answer to gusts; the output holds
    # the gusts' effect, which the model knows nothing of. Neither repeats with the excitation.
    u, y = periodic_record(periods=6)
    k = np.arange(u.size)
    gust = 0.5 * np.sin(2 * np.pi * 9 * k / u.size)      # 1.5 times the fundamental
    r = replay_record(exact, u + gust, y, FS, PERIOD, discard_periods=0)
    assert r.nrmse < 1e-12
    bumped = replay_record(exact, u, y + 0.1 * gust, FS, PERIOD, discard_periods=0)
    spread = np.std(y + 0.1 * gust)
    assert bumped.nrmse == pytest.approx(np.std(0.1 * gust) / spread, rel=1e-9)


def test_a_replay_needs_whole_periods():
    u, y = periodic_record()
    with pytest.raises(InputError, match="whole period"):
        replay_record(exact, u, y, FS, 80.5)
    with pytest.raises(InputError, match="no whole period"):
        replay_record(exact, u[:150], y[:150], FS, PERIOD, discard_periods=1)


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def noise_free(tmp_path_factory):
    """A simulated sweep of the vehicle's roll rig with an ideal sensor (no noise, bias or
    latency) and no turbulence, identified with a delay."""
    from heliquad.host.campaign.identify import identify_dir

    out = tmp_path_factory.mktemp("replay") / "roll"
    res = heliquad("sweep", "--axis", "roll", "--sil", "--ideal-sensor", "--freqs-hz", 0.5, 1.5,
                   4.5, "--cycles", 4, "--out", out)
    assert res.returncode == 0, res.stdout + res.stderr
    return out, identify_dir(str(out), delay=True, progress=lambda *_: None)


def test_the_simulators_truth_replays_a_noise_free_sweep(noise_free):
    from heliquad.host.validate.truth import sil_truth

    out, identified = noise_free
    truth, why = sil_truth(identified["manifest"], str(out))
    assert truth is not None, why
    for p, (f, _, u, y) in zip(identified["points"], identified["records"]):
        fs = p.omega_rad_s * p.period_samples / (2 * np.pi)
        r = replay_record(truth, u, y, fs, p.period_samples)
        assert r.nrmse < 0.015, f"{f:.3g} Hz: {100 * r.nrmse:.2f} %"


def test_identify_records_the_recommended_models_replay(noise_free):
    out, identified = noise_free
    doc = json.loads((out / "models.json").read_text())
    assert doc["replay"]["model"] == doc["recommended"] is not None
    assert [p["periods"] for p in doc["replay"]["points"]] == [3, 3, 3]
    assert all(p["nrmse"] < 0.02 for p in doc["replay"]["points"])
    # the same records through the model with 20 % more gain: the replay says so
    model = identified["result"].models[doc["recommended"]]
    louder = TfModel(order=model.order, num=1.2 * model.num, den=model.den,
                     delay_s=model.delay_s, stable=True)
    assert all(r.nrmse > 0.15
               for r in replay_points(louder, identified["points"], identified["records"]))
