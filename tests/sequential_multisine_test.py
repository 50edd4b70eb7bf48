"""The sequential multisine (heliquad sweep --signal multisine --target-sigma S): whole base
periods until every line is known well enough, or the rig-time cap; each line's sigma and
signal-to-disturbance ratio in the manifest."""

import html
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from heliquad.host.acquire.design import line_sdr


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


def multisine(folder, *options, axis="roll"):
    res = heliquad("sweep", "--axis", axis, "--sil", "--signal", "multisine",
                   "--target-sigma", 0.02, *options, "--out", folder)
    assert res.returncode == 0, res.stderr
    manifest = json.loads((folder / "manifest.json").read_text())
    (entry,) = manifest["frequencies"]
    return manifest, entry


def test_in_still_air_it_ends_once_every_line_is_known(tmp_path):
    manifest, entry = multisine(tmp_path / "still")
    assert manifest["design"]["sequential"] == {"target_sigma": 0.02, "min_periods": 3}
    # the least periods (3) and the one under way when the rule was met: 40 s of 180 s
    assert (entry["multisine_end"], entry["periods"]) == ("target", 4)
    assert len(entry["line_sigma"]) == len(entry["line_sdr"]) == len(entry["orders"])
    assert max(entry["line_sigma"]) <= 0.02
    assert min(entry["line_sdr"]) > 100                      # still air: the lines stand out
    # a mixer sweep measures the plant: it has no other response to be told
    res = heliquad("identify", tmp_path / "still", "--response", "loop")
    assert res.returncode == 2 and "--response is for rate or angle injection" in res.stderr


def test_under_severe_turbulence_it_runs_to_its_cap_and_the_model_holds(tmp_path):
    folder = tmp_path / "severe"
    manifest, entry = multisine(folder, "--turbulence", "severe", "--seed", 5)
    assert entry["multisine_end"] == "cap" and entry["status"] == "ok"
    assert entry["periods"] * entry["period_samples"] / 200.0 <= 180.0
    # every line's ratio said, smaller than in still air
    assert all(10 < s < 100 for s in entry["line_sdr"])
    res = heliquad("identify", folder)
    assert res.returncode == 0, res.stderr
    truth = json.loads((folder / "models.json").read_text())["sil_truth"]
    # measured: within 0.12 dB and 2.2 deg of the simulator's truth (roll, seed 5)
    assert truth["model_worst_db"] < 1.0 and truth["model_worst_deg"] < 5.0


def test_yaw_under_severe_turbulence_the_plant_through_the_rate_loop_holds(tmp_path):
    # At the mixer the loop cancels the injection at yaw's low frequencies and severe
    # turbulence swamps what is left (seed 5: the model 3.5 dB and 12.8 deg off the truth
    # at the cap). At the rate setpoint the loop follows the excitation; the plant is the
    # mixer's input over the rate, both against it.
    folder = tmp_path / "yaw"
    manifest, entry = multisine(folder, "--turbulence", "severe", "--seed", 5, "--inject",
                                "rate", "--response", "plant", "--amplitude", 40, axis="yaw")
    assert manifest["response"] == "plant" and entry["multisine_end"] == "cap"
    assert (entry["end_us"] - entry["start_us"]) / 1e6 <= 180.0
    res = heliquad("identify", folder)
    assert res.returncode == 0, res.stderr
    models = json.loads((folder / "models.json").read_text())
    assert models["response"] == "plant" and "broken_loop" not in models
    truth = models["sil_truth"]                 # the mixer-to-rate truth
    # measured: the model within 0.23 dB and 1.0 deg of it, the points 0.85 dB and 2.6 deg
    assert truth["model_worst_db"] < 1.0 and truth["model_worst_deg"] < 5.0
    # the report says what was measured and each line's sigma and signal-to-disturbance
    assert heliquad("report", folder).returncode == 0
    page = html.unescape(re.sub(r"<[^>]+>", " ", (folder / "report.html").read_text()))
    assert "yaw, rate injection; measured: the plant, the mixer's input to the rate" in page
    lines = page[page.index("Multisine lines"):].split("Frequency response")[0]
    assert f"{entry['periods']} base periods; ended by the rig-time cap" in lines
    for h, sdr in zip(entry["orders"], entry["line_sdr"]):
        assert re.search(rf"\s{h}\s+[0-9.]+ %\s+{sdr:.3g}\s", lines)
    # the same record, told to fit the loop: the rate setpoint to the rate, its own truth
    res = heliquad("identify", folder, "--response", "loop")
    assert res.returncode == 0, res.stderr
    loop = json.loads((folder / "models.json").read_text())
    assert loop["response"] == "loop"
    assert loop["sil_truth"]["points_worst_db"] < 1.0
    gain = lambda doc: doc["sil_truth"]["points"][0]["truth_db"]     # noqa: E731
    assert gain(loop) < gain(models) - 6        # the plant's low-frequency gain is larger
    # a loop's response is not a plant: validate and tune refuse it, in one line
    for command in (["validate", folder / "models.json"],
                    ["tune", folder / "models.json", "--out", folder / "tuned"]):
        res = heliquad(*command)
        assert res.returncode == 2 and "--response plant" in res.stderr
        assert len(res.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("options, said", [
    (["--inject", "mixer", "--response", "plant"], "--response is for rate or angle injection"),
    (["--inject", "motors", "--response", "loop"], "--response is for rate or angle injection"),
])
def test_a_response_is_refused_where_there_is_none_to_choose(tmp_path, options, said):
    res = heliquad("sweep", "--axis", "yaw", "--sil", *options, "--out", tmp_path / "x")
    assert res.returncode == 2 and said in res.stderr
    assert not (tmp_path / "x").exists()


def test_the_signal_to_disturbance_ratio_of_a_line():
    # a 2-unit line at harmonic 3 of a 100-sample period with white noise of 0.1 RMS: over
    # 50 periods (the first left out), the line's DFT is 100 in magnitude and the noise's
    # scatter about its mean sqrt(100 / 2) * 0.1 * sqrt(2) = 1 per bin: a ratio near 100
    rng = np.random.default_rng(3)
    k = np.arange(100 * 50)
    y = 2.0 * np.sin(2 * np.pi * 3 * k / 100) + 0.1 * rng.normal(size=k.size)
    (sdr,) = line_sdr(y, 100, [3])
    assert 85 < sdr < 115
    present = np.ones(k.size, bool)
    present[150] = False                                     # a period with a hole is left out
    assert line_sdr(y[:300], 100, [3], present[:300]) == [None]
    assert line_sdr(y[:200], 100, [3]) == [None]             # one period after the first


@pytest.mark.parametrize("options, said", [
    (["--cycles", 3], "--cycles shape a dwell"),
    (["--max-cycles", 20], "--max-cycles shape a dwell"),
])
def test_a_dwells_options_are_refused(tmp_path, options, said):
    res = heliquad("sweep", "--axis", "roll", "--sil", "--signal", "multisine", "--target-sigma",
                   0.02, *options, "--out", tmp_path / "x")
    assert res.returncode == 2 and said in res.stderr
