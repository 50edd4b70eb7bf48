"""The linearity campaign: odd random-phase multisines (sweep --signal multisine
--linearity), the best linear approximation with the noise and the nonlinear distortion
told apart per line (host/estimate/linearity.py), and identify's verdict on the simulated
roll rig with and without hinge friction."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy import signal

from heliquad.host.acquire.linearity import linearity_design, odd_lines
from heliquad.host.estimate.fsf import estimate_multisine
from heliquad.host.estimate.linearity import best_linear_approximation, level_verdict


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=900)


def test_the_design_is_odd_lines_with_random_phases_the_same_for_the_same_seed():
    n, orders = odd_lines((0.5, 4.5), 200.0)
    assert all(h % 2 == 1 for h in orders) and orders == sorted(set(orders))
    assert 200.0 / n * orders[0] == pytest.approx(0.5) and 200.0 / n * orders[-1] <= 4.5 + 1e-9
    runs = linearity_design((0.5, 4.5), 1.0, seed=7, realisations=3)
    assert [(level, i) for _, level, i in runs] == [(0, 0), (1, 0), (0, 1), (1, 1), (0, 2),
                                                   (1, 2)]
    for ms, level, _ in runs:                      # every period's peak is the one declared
        assert np.max(np.abs(ms.period())) == pytest.approx(ms.peak)
        assert ms.peak == (1.0 if level == 0 else 0.25)
    phases = [ms.phases for ms, level, _ in runs if level == 0]
    assert len({p for p in phases}) == 3           # each realisation's own phases
    again = linearity_design((0.5, 4.5), 1.0, seed=7, realisations=3)
    assert [ms.phases for ms, _, _ in again] == [ms.phases for ms, _, _ in runs]
    other = linearity_design((0.5, 4.5), 1.0, seed=8, realisations=3)
    assert other[0][0].phases != runs[0][0].phases


def _campaign(rng, seed, nonlinear, realisations=6, periods=3, noise=0.02):
    """Realisations of an odd random-phase multisine through a linear filter (and, if
    ``nonlinear``, a cubic term after it), white noise on the output; each realisation's
    points against its input."""
    b, a = signal.butter(2, 0.15)
    found = []
    for ms, level, _ in linearity_design((2.0, 25.0), 1.0, seed, realisations, fs_hz=200.0):
        if level:
            continue
        u = np.tile(ms.period(), periods)
        x = signal.lfilter(b, a, u)
        y = x + nonlinear * x ** 3 + noise * rng.standard_normal(u.size)
        found.append(estimate_multisine(u, y, 200.0, ms.period_samples, list(ms.orders)))
    return found


def test_a_linear_system_is_flagged_about_as_often_as_the_false_alarm_rate():
    rng = np.random.default_rng(1)
    flags, ratios = 0, []
    for seed in range(200):
        lines = best_linear_approximation(_campaign(rng, seed, nonlinear=0.0))
        flags += level_verdict(lines)["flagged"]
        ratios += [line.ratio for line in lines]
    # the verdict's false alarms: at most 1 in 100 by design; 200 linear campaigns give at
    # most 6 (the binomial's 99.9 % bound at 1 %)
    assert flags <= 6
    # the ratio of total to noise variance is F-distributed: its mean d2 / (d2 - 2)
    assert 0.8 < np.mean(ratios) < 1.6


def test_a_cubic_nonlinearity_is_flagged_and_its_distortion_measured():
    rng = np.random.default_rng(2)
    verdicts = [level_verdict(best_linear_approximation(_campaign(rng, seed, nonlinear=1.0)))
                for seed in range(10)]
    assert all(v["flagged"] for v in verdicts)
    assert all(v["distortion_db"] > v["noise_db"] + 6 for v in verdicts)   # measured 9-11 dB


@pytest.fixture(scope="module")
def rigs(tmp_path_factory):
    """The roll rig (6-DoF vehicle, the IMU's noise, still air): the linearity campaign
    without friction and with 0.002 N m at the hinge (about 1 % of the full mixer command's
    torque), identified."""
    base = tmp_path_factory.mktemp("linearity")
    out = {}
    for name, friction in (("free", 0.0), ("friction", 0.002)):
        folder = base / name
        res = heliquad("sweep", "--axis", "roll", "--sil", "--signal", "multisine",
                       "--linearity", "--hinge-friction", friction, "--seed", 3, "--out", folder)
        assert res.returncode == 0, res.stderr
        res = heliquad("identify", folder)
        assert res.returncode == 0, res.stderr
        out[name] = (json.loads((folder / "models.json").read_text()), res, folder)
    return out


def test_the_frictionless_rig_is_not_flagged_at_either_amplitude(rigs):
    doc, res, folder = rigs["free"]
    large, small = doc["linearity"]["levels"]
    assert (large["peak"], small["peak"]) == (1.0, 0.25)
    assert not large["flagged"] and not small["flagged"] and not doc["linearity"]["flagged"]
    assert "a linear model holds" in res.stdout and "warning" not in res.stdout
    # no amplitude dependence beyond the scatter; the models agree with the simulator
    assert not doc["linearity"]["amplitude_dependence"]["significant"]
    assert doc["linearity"]["amplitude_dependence"]["max_db"] < 0.2
    assert doc["sil_truth"]["model_worst_db"] < 0.5
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["design"]["linearity"]["realisations"] == 6
    assert len(manifest["frequencies"]) == 12


def test_hinge_friction_is_flagged_at_the_small_amplitude_and_not_at_the_large(rigs):
    doc, res, _ = rigs["friction"]
    large, small = doc["linearity"]["levels"]
    # measured (seed 3): distortion -23.5 and -16.3 dB of the response, noise about -57 and
    # -48 dB: above the noise at both, above -20 dB only at the small amplitude
    assert small["flagged"] and small["distortion_db"] > -20
    assert not large["flagged"] and large["distortion_db"] < -20
    assert large["above_noise"] == large["count"]          # seen, but small enough
    assert doc["linearity"]["amplitude_dependence"]["significant"]
    assert not doc["linearity"]["flagged"]                 # the models are the large one's
    assert "flagged: a linear model does not hold here" in res.stdout
    points = [p for p in doc["linearity"]["levels"][0]["lines"]]
    assert len(points) == 10


def test_linearity_needs_a_multisine_and_its_own_length(tmp_path):
    for extra, says in ((["--linearity"], "--linearity is a campaign of multisines: add "
                                          "--signal multisine"),
                        (["--signal", "multisine", "--linearity", "--rig-time", 60],
                         "--rig-time with --linearity")):
        res = heliquad("sweep", "--axis", "roll", "--sil", *extra, "--out", tmp_path / "x")
        assert res.returncode == 2
        assert says in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_the_report_shows_each_amplitudes_verdict(rigs, tmp_path):
    _, _, folder = rigs["friction"]
    res = heliquad("report", folder, "--out", tmp_path / "report.html")
    assert res.returncode == 0, res.stderr
    page = (tmp_path / "report.html").read_text()
    section = page[page.index("Linearity (best linear approximation"):]
    assert section.count("FLAGGED") == 1 and "Amplitude dependence: up to" in section
    assert "significant" in section
    # the models are the large amplitude's, which is not flagged: no quality flag for it
    assert "a linear model does not hold at this amplitude" not in page


def test_a_models_file_whose_linearity_is_incomplete_is_refused_by_the_report(rigs, tmp_path):
    _, _, folder = rigs["free"]
    broken = tmp_path / "broken"
    broken.mkdir()
    doc = json.loads((folder / "models.json").read_text())
    del doc["linearity"]["levels"][0]["count"]
    (broken / "models.json").write_text(json.dumps(doc))
    res = heliquad("report", broken, "--out", tmp_path / "r.html")
    assert res.returncode == 2
    assert res.stderr.strip().endswith("linearity.levels[0].count is missing")
