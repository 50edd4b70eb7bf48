"""The report's tuning section (host/present/report_tune.py): a ``heliquad tune`` folder shows
each axis's gains and predicted loops before and after, and once verified, each loop's
predicted, measured and truth margins with its verdict and what the board holds."""

from __future__ import annotations

import html
import json
import re

from heliquad.host.present.report import write_report
from heliquad.host.records.tune import read_tune
from heliquad.host.records.verify import VerifyFile, write_verify_json
from tune_fixture import reduced_gains, write_tune_dir


def _text(path) -> str:
    """The page's words: tags and embedded images gone, entities read."""
    page = open(path, encoding="utf-8").read()
    page = re.sub(r"<img[^>]*>|<style>.*?</style>", "", page, flags=re.S)
    return html.unescape(re.sub(r"<[^>]+>", " ", page))


def _loop_check(predicted, measured, passed, failures):
    return {"sweep": "verify/roll/rate", "predicted": predicted,
            "allowed": {"phase_margin_deg": 5.0, "gain_margin_db": 1.0},
            "measured": measured, "passed": passed, "failures": failures}


def test_a_tune_folder_shows_before_and_after_and_the_verification(tmp_path):
    folder = write_tune_dir(tmp_path / "tuned", {"roll": reduced_gains("roll", 0.6)})
    report = write_report(str(folder))
    words = _text(report)
    tune = read_tune(tmp_path / "tuned" / "tune.json")
    rate = tune.axes["roll"]["tuned"]["loops"]["rate"]
    assert "Tuning: tuned" in words and "not yet flown" in words
    assert f"{rate['phase_margin_deg']:.1f} deg / {rate['gain_margin_db']:.1f} dB" in words
    kc = tune.axes["roll"]["tuned"]["gains"]["rate"][0]
    assert f"rate [{kc:.4g}," in words
    # verified: the rate loop failed its gain margin, the previous gains restored
    predicted = {k: rate[k] for k in ("phase_margin_deg", "gain_margin_db",
                                      "gain_crossover_rad_s", "phase_crossover_rad_s")}
    measured = {**predicted, "gain_margin_db": rate["gain_margin_db"] - 3.0, "unmeasured": []}
    why = f"gain margin {measured['gain_margin_db']:.1f} dB measured"
    write_verify_json(tmp_path / "tuned" / "verify.json", VerifyFile(
        tune="tune.json", spec=dict(tune.spec),
        floor={"phase_margin_deg": 5.0, "gain_margin_db": 1.0},
        axes={"roll": {"board": "sil", "started": "2026-11-28T20:00:00Z", "verdict": "rejected",
                       "board_holds": "previous", "said": [], "loaded": {}, "previous": {},
                       "restored": {}, "sweeps": {"rate": "verify/roll/rate"},
                       "band_rad_s": {"rate": [1.0, 100.0]},
                       "loops": {"rate": _loop_check(predicted, measured, False, [why])}}}))
    json.loads((tmp_path / "tuned" / "verify.json").read_text())
    words = _text(write_report(str(folder)))
    assert "then flown on the rig" in words and "rejected; the board holds its previous gains" in words
    assert f"{measured['gain_margin_db']:.1f} dB" in words and why in words and "failed" in words
