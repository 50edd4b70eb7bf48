"""The per-rotor run (``heliquad sweep --inject motors``, host/acquire/rotor_multisine.py):
each rotor on odd harmonics of its own, in the message's order rotor j mod the count, every
rotor's own sum at its peak, the declared peak one the firmware takes (or one rotor alone,
MOTORn, on every line); on the simulated rig
the run is one MOTORS excitation logged as a sweep folder whose manifest says each rotor's
lines and the geometry flown; a board that flies another rotor count, dwell options and
identify on such a folder are refused in one line."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from heliquad.host.acquire.multisine import MAX_LINES, MIN_PERIODS
from heliquad.host.acquire.rotor_multisine import ROTOR_PEAK, rotor_design
from heliquad.host.campaign.identify import load_sweep
from heliquad.host.campaign.sweep_points import sweep_segments
from heliquad.host.records import paper
from heliquad.sim.base.dialect import dialect
from heliquad.sim.base.errors import InputError


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
@pytest.mark.parametrize("rotors", [4, 5, 8])
def test_each_rotor_has_odd_lines_of_its_own_in_the_firmwares_order(axis, rotors):
    ms = rotor_design(paper.BANDS_HZ[axis][1], rotors, rig_time_s=120.0)
    own = ms.rotor_orders
    assert len(ms.orders) <= MAX_LINES and all(len(o) >= 2 for o in own)
    assert all(o % 2 == 1 for o in ms.orders)       # sums and differences land on no line
    assert list(ms.orders) == sorted(set(ms.orders))
    for i, lines in enumerate(own):                 # message entry j goes to rotor j mod R
        assert [ms.orders[j] for j in range(len(ms.orders)) if j % rotors == i] == list(lines)
        assert all((o - 1) // 2 % rotors == i for o in lines)
        alone = np.zeros(ms.period_samples)
        k = np.arange(ms.period_samples)
        for j in range(i, len(ms.orders), rotors):
            alone += ms.amplitudes[j] * np.sin(2 * np.pi * ms.orders[j] * k / ms.period_samples
                                               + ms.phases[j])
        assert np.max(np.abs(alone)) == pytest.approx(ROTOR_PEAK, rel=1e-9)
    assert ms.freqs_hz[-1] <= paper.BANDS_HZ[axis][1] + 1e-9
    assert 4 * ms.orders[-1] <= ms.period_samples and ms.periods >= MIN_PERIODS
    assert ms.peak >= math.sqrt(np.sum(np.square(ms.amplitudes)) / 2)
    assert ms.duration_s <= 120.0


def test_one_rotors_run_gives_it_every_line_odd():
    ms = rotor_design(paper.BANDS_HZ["roll"][1], 5, only=2)
    assert [len(o) for o in ms.rotor_orders] == [0, 0, MAX_LINES, 0, 0]
    assert all(o % 2 == 1 for o in ms.orders) and ms.peak == ROTOR_PEAK
    assert ms.record()["rotor_orders"][2] == list(ms.orders)


def test_a_band_too_low_for_the_rig_time_takes_fewer_lines_then_is_refused():
    yaw = rotor_design(paper.BANDS_HZ["yaw"][1], 5)      # 60 s: two lines each, not three
    assert [len(o) for o in yaw.rotor_orders] == [2] * 5
    with pytest.raises(InputError, match="rig time"):
        rotor_design(0.5, 5)
    with pytest.raises(InputError, match="lines"):
        rotor_design(4.5, 5, lines=9)


def test_a_per_rotor_run_on_the_simulated_rig_is_one_motors_excitation(tmp_path):
    out = tmp_path / "roll"
    r = heliquad("sweep", "--axis", "roll", "--sil", "--inject", "motors", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "next: heliquad effectiveness" in r.stdout
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["inject"] == "motors" and manifest["complete"]
    design = manifest["design"]
    assert design["rotors"] == 5 and design["rotor_peak"] == ROTOR_PEAK
    assert [len(o) for o in design["rotor_orders"]] == [3] * 5
    assert manifest["params"]["CA_ROTOR_COUNT"] == 5
    entry, = manifest["frequencies"]
    assert entry["samples"] == design["periods"] * design["period_samples"]
    _, doc, samples, _ = load_sweep(str(out))
    (_, _, exc, _, _, present), = list(sweep_segments(doc, samples))
    assert present is None and exc.size == entry["samples"]
    assert set(samples.injection[samples.exc_state != 0]) == {dialect().HQ_INJECTION_MOTORS}
    # the logged excitation is the sum of every rotor's lines: nothing between them
    spectrum = np.abs(np.fft.rfft(exc[:entry["period_samples"]]))
    lines = sorted(o for own in design["rotor_orders"] for o in own)
    assert np.max(np.delete(spectrum, lines)) < 1e-4 * np.min(spectrum[lines])
    r = heliquad("identify", out)
    assert r.returncode == 2 and "heliquad effectiveness" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("extra, why", [
    (("--rotors", "4"), "give --rotors 5"),
    (("--cycles", "8"), "--cycles shape"),
    (("--amplitude", "0.3"), "EXC_MAX_MOT"),
    (("--inject", "motor6"), "flies 5 rotors"),
])
def test_what_a_per_rotor_run_cannot_do_is_refused_in_one_line(tmp_path, extra, why):
    r = heliquad("sweep", "--axis", "pitch", "--sil", "--inject", "motors", *extra,
                 "--out", tmp_path / "run")       # a later --inject replaces the first
    assert r.returncode == 2, r.stderr
    assert why in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_rotors_is_only_for_the_per_rotor_run(tmp_path):
    r = heliquad("sweep", "--axis", "roll", "--sil", "--rotors", "5", "--out", tmp_path / "x")
    assert r.returncode == 2 and "--inject motors" in r.stderr
