"""A sweep's shape beyond its signal: --fade-cycles (a dwell's and a multisine's fades) and
--base-period (a multisine's grid kept for another rig time), flown on the simulated rig;
the time the rig flew excited (records.manifest.excited_seconds); and every study spec in
benchmarks/studies still planned by today's commands."""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from heliquad.host.acquire.sweep import multisine_plan
from heliquad.host.campaign.identify import load_sweep
from heliquad.host.records.manifest import excited_seconds
from heliquad.sim.base.dialect import dialect

STUDIES = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "studies"


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


def excited_runs(samples):
    """The lengths, in samples, of the runs of samples whose excitation is not idle."""
    busy = np.asarray(samples.exc_state) != dialect().HQ_EXCITATION_STATE_IDLE
    edges = np.flatnonzero(np.diff(np.concatenate(([0], busy.astype(int), [0]))))
    return list(edges[1::2] - edges[::2])


def test_a_dwell_faded_over_one_cycle_flies_and_is_identified(tmp_path):
    out = tmp_path / "dwell"
    res = heliquad("sweep", "--axis", "roll", "--sil", "--ideal-sensor", "--cycles", 3,
                   "--fade-cycles", 1, "--freqs-hz", 1, 2, "--out", out)
    assert res.returncode == 0, res.stderr
    _, manifest, samples, _ = load_sweep(str(out))
    assert manifest["fade_cycles"] == 1
    periods = [e["period_samples"] for e in manifest["frequencies"]]
    assert periods == [200, 100]
    # each excitation: one cycle in, three measured, one out (the firmware's own states;
    # a sample either side where the state changes between the loop and its report)
    runs = excited_runs(samples)
    assert len(runs) == 2 and all(abs(n - 5 * p) <= 2 for n, p in zip(runs, periods)), runs
    assert excited_seconds(manifest) == pytest.approx(5 * sum(periods) / 200.0)
    res = heliquad("identify", out)
    assert res.returncode == 0, res.stderr
    doc = json.loads((out / "models.json").read_text())
    assert len(doc["sil_truth"]["points"]) == 2
    assert doc["sil_truth"]["points_worst_db"] < 0.1


def test_a_base_period_keeps_the_default_multisines_lines_for_a_longer_record(tmp_path):
    # yaw's default 60 s design: 13.335 s base period, 13 lines, 3 periods; given 144 s
    # the design would choose a finer grid (other lines); with the base period it keeps
    # the same lines and phases, 9 periods.
    default = multisine_plan("yaw").multisine
    assert multisine_plan("yaw", rig_time_s=144.425).multisine.orders != default.orders
    out = tmp_path / "ms"
    res = heliquad("sweep", "--axis", "yaw", "--sil", "--ideal-sensor", "--signal", "multisine",
                   "--base-period", 13.335, "--rig-time", 144.425, "--out", out)
    assert res.returncode == 0, res.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    (entry,) = manifest["frequencies"]
    assert entry["period_samples"] == default.period_samples == 2667
    assert tuple(entry["orders"]) == default.orders
    assert np.allclose(manifest["design"]["phases_rad"], default.phases, atol=1e-12)
    assert entry["samples"] == 9 * 2667 and entry["fade_samples"] == 1334
    assert excited_seconds(manifest) == pytest.approx((9 * 2667 + 2 * 1334) / 200.0)


def test_a_multisine_faded_over_two_cycles_of_its_lowest_line(tmp_path):
    out = tmp_path / "ms"
    res = heliquad("sweep", "--axis", "roll", "--sil", "--ideal-sensor", "--signal", "multisine",
                   "--lines", 5, "--rig-time", 20, "--fade-cycles", 2, "--out", out)
    assert res.returncode == 0, res.stderr
    _, manifest, samples, _ = load_sweep(str(out))
    (entry,) = manifest["frequencies"]
    lowest_cycle = -(-entry["period_samples"] // entry["orders"][0])
    assert entry["fade_samples"] == 2 * lowest_cycle
    (run,) = excited_runs(samples)
    assert abs(run - (entry["samples"] + 2 * entry["fade_samples"])) <= 2


def test_the_excited_time_counts_samples_lost_on_the_link():
    # the window is samples + lost (what the rig flew); the pauses between excitations not
    manifest = {"fade_cycles": 2, "frequencies": [
        {"freq_hz": 1.0, "period_samples": 200, "samples": 590, "lost": 10, "status": "ok"},
        {"freq_hz": 0.1, "period_samples": 2000, "samples": 6000, "fade_samples": 2000,
         "status": "ok"},
        {"requested_hz": 3.0, "samples": 0, "status": "refused by the firmware"}]}
    assert excited_seconds(manifest) == pytest.approx((600 + 800) / 200 + 10000 / 200)


@pytest.mark.parametrize("options, said", [
    (["--base-period", 10], "--lines, --rig-time and --base-period shape a multisine"),
    (["--signal", "chirp", "--fade-cycles", 2], "--fade-cycles do not shape a chirp"),
    (["--signal", "chirp", "--base-period", 10], "--base-period do not shape a chirp"),
    (["--signal", "multisine", "--base-period", 1.5],
     "a base period of 1.5 s puts the first harmonic above the band's lowest frequency, "
     "0.5 Hz: at least 2 s"),
    (["--signal", "multisine", "--base-period", 25],
     "a multisine over 0.5-4.5 Hz needs more than 60 s: 3 whole periods of its base period "
     "of 25 s, and the fades, do not fit"),
    (["--signal", "multisine", "--linearity", "--fade-cycles", 2],
     "--fade-cycles with --linearity"),
    (["--fade-cycles", 0], "argument --fade-cycles: 0 is outside 1.."),
])
def test_a_shape_that_cannot_fly_is_one_line_before_anything_flies(tmp_path, options, said):
    res = heliquad("sweep", "--axis", "roll", "--sil", *options, "--out", tmp_path / "out")
    assert res.returncode == 2 and said in res.stderr and res.stderr.count("\n") == 1, \
        res.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("spec", sorted(p.name for p in STUDIES.glob("*.toml")))
def test_every_study_spec_in_the_repository_is_planned(spec, tmp_path):
    res = heliquad("study", STUDIES / spec, "--out", tmp_path / "study", "--dry-run")
    assert res.returncode == 0, res.stderr
    assert "to make" in res.stdout and not (tmp_path / "study" / "runs").exists()
