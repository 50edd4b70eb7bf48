"""The HTML report (heliquad report) and the demo (heliquad demo)."""

import html
import json
import math
import os
import re
import shutil
import subprocess
import sys

import pytest


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=900)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    out = tmp_path_factory.mktemp("rep") / "roll"
    assert heliquad("sweep", "--axis", "roll", "--sil", "--plant", "tf", "--freqs-hz", 0.7, 1.5,
                    3, "--cycles", 4, "--out", out).returncode == 0
    assert heliquad("identify", out, "--order", "0/2").returncode == 0
    assert heliquad("validate", out / "models.json").returncode == 0
    return out


def quality_flags(page):
    """The quality flags of a report page (what a user must act on), unescaped."""
    return [html.unescape(f) for f in re.findall(r'<li class="flag">(.*?)</li>', page)]


def not_validated(page):
    """The page's lines on what the session does not validate, unescaped."""
    return [html.unescape(re.sub(r"<[^>]+>", "", f))
            for f in re.findall(r'<li class="note">(.*?)</li>', page)]


def only_margins_not_validated(page):
    """The page has no quality flag, and one line on the margins read outside the band: this
    session's sweep (0.7-3 Hz) does not reach the loops' phase crossovers nor the angle
    loop's gain crossover."""
    notes = not_validated(page)
    return not quality_flags(page) and len(notes) == 1 and \
        notes[0].startswith("roll: 3 margins not validated")


def summary_rows(page):
    """The summary's rows: {axis: (model, error against the truth, verdict, next step)}, as
    text."""
    table = page[page.index("<h2>Summary</h2>"):].split("</table>")[0]
    rows = {}
    for row in table.split("<tr>")[2:]:
        cells = [html.unescape(re.sub(r"<[^>]+>", " ", c)).split()
                 for c in re.findall(r"<td[^>]*>(.*?)</td>", row)]
        rows[" ".join(cells[0])] = tuple(" ".join(c) for c in cells[1:])
    return rows


def test_report_holds_every_table_and_plot(session):
    res = heliquad("report", session)
    assert res.returncode == 0, res.stderr
    page = (session / "report.html").read_text()
    for needle in ("Quality flags", "Frequencies", "tables 4-6", "Models", "Recommended:",
                   "Closed-loop validation", "phase margin"):
        assert needle in page
    assert page.count("data:image/png;base64,") == 3          # Bode, responses, validation
    assert only_margins_not_validated(page)


def test_report_flags_low_coherence_and_aborts(session, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(session, copy)
    table = (copy / "points_table.csv").read_text().splitlines()
    table[1] = ",".join(table[1].split(",")[:-1] + ["0.31"])
    (copy / "points_table.csv").write_text("\n".join(table) + "\n")
    manifest = json.loads((copy / "manifest.json").read_text())
    manifest["aborted"] = "interrupted (Ctrl-C)"
    (copy / "manifest.json").write_text(json.dumps(manifest))
    assert heliquad("report", copy).returncode == 0
    page = (copy / "report.html").read_text()
    assert "low coherence 0.31" in page and "sweep stopped: interrupted" in page


def test_a_superseded_frequency_is_listed_but_not_flagged(session, tmp_path):
    # The sequential design measures a frequency again when its first amplitude was wrong;
    # the first record stays in the table with its reason, and is not a quality problem.
    copy = tmp_path / "superseded"
    shutil.copytree(session, copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    first = dict(manifest["frequencies"][0], status="superseded: amplitude 0.1 swung the rig "
                 "far less than the target; measured again at 0.4")
    manifest["frequencies"].insert(0, first)
    (copy / "manifest.json").write_text(json.dumps(manifest))
    assert heliquad("report", copy).returncode == 0
    page = (copy / "report.html").read_text()
    flags = page[page.index("Quality flags"):page.index("<h2", page.index("Quality flags"))]
    assert "superseded: amplitude 0.1" in page and "superseded" not in flags


def test_report_shows_each_points_checks_and_how_the_points_were_estimated(session):
    # The points table goes on past the paper's columns: the coherences with the excitation
    # (points.csv), the recommended model's replay error and, for this simulated sweep, each
    # point's error against the simulator's truth (models.json).
    assert heliquad("report", session).returncode == 0
    page = (session / "report.html").read_text()
    header = re.search(r"<tr>(<th>freq_hz</th>.*?)</tr>", page).group(1)
    assert re.findall(r"<th>(.*?)</th>", header)[7:] == [
        "coherence r-&gt;y", "coherence r-&gt;u", "replay error %", "truth error dB",
        "truth error deg", "truth error / sigma"]
    table = page[page.index(header):].split("</table>")[0]
    replay_errors = [float(row.split("<td>")[10].split("<")[0])
                     for row in table.split("<tr>")[1:]]
    recorded = json.loads((session / "models.json").read_text())["replay"]["points"]
    assert replay_errors == [float(f"{100 * p['nrmse']:.3g}") for p in recorded]
    assert "estimated against the logged excitation r" in page
    assert "through the recommended model (0/2 + delay), its periodic steady state" in page
    assert "Against the simulator&#x27;s truth: the points within" in page


def test_identify_draws_the_coherence_panel_under_the_bode_plot(session):
    from matplotlib.image import imread

    # write_bode's figure with the third panel is 8.5 in high at 110 dpi (7 in without)
    assert imread(session / "bode.png").shape[0] == round(8.5 * 110)


def edited_copy(session, tmp_path, edit, name="models.json"):
    """A copy of the session whose ``name`` (models.json, validation.json) ``edit`` changes
    in place; its report."""
    copy = tmp_path / "copy"
    shutil.copytree(session, copy)
    doc = json.loads((copy / name).read_text())
    edit(doc)
    (copy / name).write_text(json.dumps(doc))
    assert heliquad("report", copy).returncode == 0
    return (copy / "report.html").read_text()


def test_a_session_within_the_accuracy_opens_with_a_summary_and_no_flag(session):
    # This simulated sweep's model is within hundredths of a dB and tenths of a degree of the
    # truth, like the demo's: the page opens with its summary (the model, its error against
    # the truth, the verdict, the next step), no quality flag, and the margins it cannot
    # validate in one line with the sweep that would.
    from heliquad.host.estimate.thresholds import ACCURACY_DB, ACCURACY_DEG

    assert heliquad("report", session).returncode == 0
    page = (session / "report.html").read_text()
    assert page.index("<h2>Summary</h2>") < page.index("Quality flags") < page.index("<h3>Sweep")
    truth = json.loads((session / "models.json").read_text())["sil_truth"]
    assert truth["model_worst_db"] < ACCURACY_DB / 10 and truth["model_worst_deg"] < ACCURACY_DEG / 10
    model, error, verdict, step = summary_rows(page)["roll"]
    assert "s 2 +" in model and "0/2 + delay" in model
    assert error == f"{truth['model_worst_db']:.2f} dB, {truth['model_worst_deg']:.1f} deg"
    assert verdict.startswith("usable for design within the 1 dB and 5 deg a design needs")
    assert re.fullmatch(r"sweep [\d.]+-[\d.]+ Hz \([\d.]+-[\d.]+ rad/s\) to measure the margins "
                        r"there(; .* only on the rig)?", step), step
    assert only_margins_not_validated(page)
    assert "No quality flags" in page


def test_points_and_a_model_off_the_truth_are_flagged_against_the_accuracy(session, tmp_path):
    # A point 3 dB off and a model 6 dB and 40 deg off the simulator's truth are what a
    # design cannot take: flagged, and the summary says to check first. A large error/sigma
    # alone (a bias sigma does not show, well within the accuracy) is a statistic, not a flag.
    def far(doc):
        doc["sil_truth"]["points"][1].update(error_db=3.0, error_over_sigma=40.0)
        doc["sil_truth"].update(model_worst_db=6.0, model_worst_deg=40.0)

    page = edited_copy(session, tmp_path, far)
    flags = quality_flags(page)
    assert flags[0].startswith("roll: 1 of 3 points are further than 1 dB or 5 deg from the "
                               "simulator's truth (the worst, ")
    assert flags[1].startswith("roll: the recommended model is up to 6.00 dB and 40.0 deg from "
                               "the simulator's truth")
    _, error, verdict, step = summary_rows(page)["roll"]
    assert (error, verdict, step) == ("6.00 dB, 40.0 deg", "check first 2 quality flags",
                                      "act on the flags below")

    def biased(doc):
        for p in doc["sil_truth"]["points"]:
            p["error_over_sigma"] = 28.5
        doc["sil_truth"]["points_rms_error_over_sigma"] = 28.5

    page = edited_copy(session, tmp_path / "b", biased)
    assert only_margins_not_validated(page)
    text = html.unescape(page)
    assert "RMS error/sigma of the points: 28.50, how many of their own standard errors" in text
    assert "above 1, so the points carry a bias their scatter does not show" in text


def test_the_sigma_statistic_says_what_it_means_or_that_it_means_nothing(session, tmp_path):
    # Honest sigmas give about 1; sigmas that are round-off (a noise-free simulation) make the
    # ratio meaningless, and the page says so rather than reading anything into it.
    assert heliquad("report", session).returncode == 0
    z = json.loads((session / "models.json").read_text())["sil_truth"]["points_rms_error_over_sigma"]
    assert z < 2
    assert "about 1, as it should be" in (session / "report.html").read_text()
    copy = tmp_path / "roundoff"
    shutil.copytree(session, copy)
    lines = (copy / "points.csv").read_text().splitlines()
    header = lines[0].split(",")
    rows = [r.split(",") for r in lines[1:]]
    for r in rows:
        r[header.index("sigma")] = f"{float(r[header.index('magnitude')]) * 1e-12:.6g}"
    (copy / "points.csv").write_text("\n".join([lines[0]] + [",".join(r) for r in rows]) + "\n")
    assert heliquad("report", copy).returncode == 0
    page = html.unescape((copy / "report.html").read_text())
    assert "not meaningful here, as the sigmas are round-off (1e-12 of the magnitude" in page
    assert not quality_flags(page)


def test_the_sweeps_source_is_a_table_not_json(session):
    assert heliquad("report", session).returncode == 0
    page = (session / "report.html").read_text()
    table = page[page.index("<h3>Sweep</h3>"):].split("</table>")[0]
    rows = dict((html.unescape(a), html.unescape(b)) for a, b in
                re.findall(r'<tr><td class="l">(.*?)</td><td class="l">(.*?)</td></tr>', table))
    manifest = json.loads((session / "manifest.json").read_text())
    assert rows["axis, injection"] == "roll, mixer injection"
    assert rows["source"] == "simulation (SIL)" and rows["plant"] == "a transfer function"
    assert rows["numerator"] == ", ".join(f"{v:g}" for v in manifest["source"]["num"])
    assert rows["air"] == "still" and rows["started"] == manifest["started"]
    assert rows["gains flown"].startswith("rate loop Kc ")
    assert '{"kind"' not in page and "&quot;kind&quot;" not in page


def test_a_board_sweep_has_no_truth_to_show_or_flag(session, tmp_path):
    def board(doc):
        del doc["sil_truth"]

    shutil.copytree(session, tmp_path / "board")
    validation = json.loads((session / "validation.json").read_text())
    del validation["truth_loops"]                       # validate found no simulator beside
    (tmp_path / "board" / "validation.json").write_text(json.dumps(validation))
    page = edited_copy(tmp_path / "board", tmp_path, board)
    assert "truth" not in page and only_margins_not_validated(page)


def loop_section(page, name):
    """The part of the page on one loop of the validation: its table and sentences."""
    start = page.index(f"<h4>{name} loop: broken")
    end = min(i for i in (page.find("<h4>", start + 1), page.find("<p>Step", start)) if i > 0)
    return html.unescape(page[start:end])


def test_report_shows_each_loops_margins_with_what_is_not_validated_or_measured(session):
    # The sweep (0.7-3 Hz, mixer injection on the simulated tf plant) measures the input loop
    # through the excitation; the simulator knows the rate loop's truth (a tf plant has no
    # angle of its own); the rate and input loops' phase crossovers and the angle loop's
    # gain crossover lie outside the band.
    assert heliquad("report", session).returncode == 0
    page = (session / "report.html").read_text()
    v = json.loads((session / "validation.json").read_text())
    lo, hi = v["band_rad_s"]
    for name, lp in v["loops"].items():
        part = loop_section(page, name)
        assert "<td class=\"l\">model</td>" in part and lp["not_validated"]
        assert "not validated (read outside the band)" in part
        assert "Not validated:" not in part             # said once for the axis, not per loop
        assert ("simulator's truth" in part) == (name == "rate")
        assert ("measured through the excitation" in part) == (name == "input")
    measured = loop_section(page, "input")
    assert v["measured_loop"]["unmeasured"] and v["measured_loop"]["gain_margin_db"] is None
    assert "<td>not measured</td>" in measured
    assert all(f"Not measured: {why}." in measured for why in v["measured_loop"]["unmeasured"])
    assert f"<td>{v['measured_loop']['phase_margin_deg']:.3g}</td>" in measured
    assert not quality_flags(page)
    (note,) = not_validated(page)
    assert note.startswith(f"roll: 3 margins not validated, read outside the identified band "
                           f"({lo:.3g}-{hi:.3g} rad/s)")
    angle = f"angle loop phase margin at {v['loops']['angle']['gain_crossover_rad_s']:.3g} rad/s"
    assert angle in note and "rate loop phase margin" not in note
    assert "Next: sweep " in note


def test_a_margin_in_band_the_simulators_truth_does_not_confirm_is_flagged(session, tmp_path):
    # The rate loop's phase margin is read in band (8.8 rad/s) and matches the truth: no flag.
    # Told 8 deg more than the truth (beyond the 5 deg accuracy), it is flagged; with every
    # crossover in band, nothing is left not validated. (The gain margins, read far above
    # the band, are set to the truth's: their extrapolation is not what this checks.)
    v = json.loads((session / "validation.json").read_text())
    rate, truth = v["loops"]["rate"], v["truth_loops"]["rate"]
    assert [c["in_band"] for c in rate["gain_crossovers"]] == [True]
    assert abs(rate["phase_margin_deg"] - truth["phase_margin_deg"]) < 3

    def off(doc):
        doc["loops"]["rate"]["phase_margin_deg"] = truth["phase_margin_deg"] + 8
        for name, lp in doc["loops"].items():
            if name in v["truth_loops"]:
                lp["gain_margin_db"] = v["truth_loops"][name]["gain_margin_db"]
            lp["not_validated"] = []
            for c in lp["gain_crossovers"] + lp["phase_crossovers"]:
                c["in_band"] = True

    page = edited_copy(session, tmp_path, off, "validation.json")
    (flag,) = quality_flags(page)
    assert flag == (f"roll: the rate loop's phase margin is {truth['phase_margin_deg'] + 8:.1f} "
                    f"deg on the model and {truth['phase_margin_deg']:.1f} deg on the "
                    "simulator's truth, more than 5 deg apart, inside the identified band")
    assert not not_validated(page)


def test_without_a_recommended_model_nothing_is_replayed(session, tmp_path):
    def none(doc):
        doc["recommended"] = None

    page = edited_copy(session, tmp_path, none)
    assert "No model is recommended, so none is replayed." in page
    assert "replay error" not in page and "no model recommended" in page


def test_report_of_an_empty_folder_is_one_line_exit_2(tmp_path):
    res = heliquad("report", tmp_path)
    assert res.returncode == 2 and "no models.json" in res.stderr


def test_demo_identifies_the_vehicle_within_a_dB_and_5_degrees(tmp_path):
    # Issue 5: the recommended model of each axis matches the simulator's truth within 1 dB and
    # 5 deg across the band (delay fitted). Roll here; pitch and yaw run in the full demo.
    out = tmp_path / "demo"
    res = heliquad("demo", "--axes", "roll", "--out", out)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr
    db, deg = map(float, re.search(r"error ([\d.]+) dB, ([\d.]+) deg", res.stdout).groups())
    assert db < 1.0 and deg < 5.0
    assert (out / "report.html").exists() and (out / "roll" / "validation.png").exists()
    # Its report opens with the axis's summary and raises no quality flag.
    page = (out / "report.html").read_text()
    assert not quality_flags(page), quality_flags(page)
    _, error, verdict, _ = summary_rows(page)["roll"]
    assert error == f"{db:.2f} dB, {deg:.1f} deg" and verdict.startswith("usable for design")
    assert "real time" in res.stdout
    # It ends with the roll gains tuned and proven on the simulated rig, before and after
    # in the report: the in-band margins measured within the verification's bounds.
    assert "roll: accepted" in res.stdout
    # the simulated board flies the raw IMU path, which identify read from the sweep's log
    assert json.loads((out / "roll" / "models.json").read_text())["imu_path"] == "raw"
    verified = json.loads((out / "tune" / "verify.json").read_text())["axes"]["roll"]
    assert verified["verdict"] == "accepted" and verified["board_holds"] == "tuned"
    for loop in verified["loops"].values():
        assert loop["passed"] and loop["measured"]["phase_margin_deg"] >= 45.0
        # every margin predicted inside the band and measured within the floor of it
        assert not loop["predicted"].get("extrapolated")
        for key, floor in loop["allowed"].items():
            assert abs(loop["measured"][key] - loop["predicted"][key]) <= floor
    # tuned on the tuning sweep's models, identified up to 45 Hz (a dwell's top frequency
    # is what whole loop steps make of it): every crossover of the tuned loops inside it
    tuned = json.loads((out / "tune" / "tune.json").read_text())["axes"]["roll"]
    assert tuned["models"].endswith(os.path.join("roll", "tuning", "models.json"))
    assert tuned["band_rad_s"][1] > 2 * math.pi * 44
    assert not any(loop["extrapolated"] for loop in tuned["tuned"]["loops"].values())
    assert "Tuning: tune" in page and "then flown on the rig" in page


def test_a_cascade_unstable_only_outside_the_band_is_not_validated_not_flagged(session, tmp_path):
    # Where the model has no data its prediction is not validated (a line with the next
    # step); unstable inside what was identified, it is a quality flag.
    def unstable(outside):
        def edit(doc):
            doc["stable"] = False
            doc["instability"] = {"pole_rad_s": 118.0 if outside else 10.0,
                                  "band_top_rad_s": 18.8, "outside_band": outside}
        return edit

    page = edited_copy(session, tmp_path / "out", unstable(True), "validation.json")
    assert not quality_flags(page)
    assert any(n.startswith("roll: the cascade is unstable with these gains: closed-loop poles "
                            "at 118 rad/s") and "Next: check with a model that rolls off there"
               in n for n in not_validated(page))
    page = edited_copy(session, tmp_path / "in", unstable(False), "validation.json")
    assert quality_flags(page) == ["roll: the cascade is unstable with these gains: closed-loop "
                                   "poles at 10 rad/s, 0.53x the identified band's top (18.8 "
                                   "rad/s), inside what was identified"]
    assert summary_rows(page)["roll"][2] == "check first 1 quality flag"


def test_a_folder_of_axes_gives_a_summary_row_per_axis(session, tmp_path):
    for axis in ("roll", "pitch"):
        shutil.copytree(session, tmp_path / axis)
        manifest = json.loads((tmp_path / axis / "manifest.json").read_text())
        (tmp_path / axis / "manifest.json").write_text(json.dumps({**manifest, "axis": axis}))
    assert heliquad("report", tmp_path).returncode == 0
    rows = summary_rows((tmp_path / "report.html").read_text())
    assert sorted(rows) == ["pitch", "roll"]
    assert all(verdict.startswith("usable for design") for _, _, verdict, _ in rows.values())


def test_a_model_of_too_low_an_order_is_flagged_off_the_truth(session, tmp_path):
    # The tf plant is second order; identified as first order without delay, the recommended
    # model is about 10 dB and 80 deg off the simulator's truth and fits its points poorly:
    # both are flags, and the summary says to check first. (Fitted to the relative error:
    # CIFER's J puts a first order's pole at the edge of its range, flagged degenerate, and
    # none is recommended.)
    copy = tmp_path / "low"
    shutil.copytree(session, copy)
    (copy / "validation.json").unlink()
    res = heliquad("identify", copy, "--order", "0/1", "--no-delay", "--cost", "relative")
    assert res.returncode == 0, res.stderr
    assert heliquad("report", copy).returncode == 0
    flags = quality_flags((copy / "report.html").read_text())
    assert any(f.startswith("roll: the recommended model is up to ") and "do not design on it"
               in f for f in flags), flags
    assert any(f.startswith("roll: the recommended model fits its points poorly") for f in flags)
    truth = json.loads((copy / "models.json").read_text())["sil_truth"]
    assert truth["model_worst_db"] > 3 and truth["model_worst_deg"] > 30


@pytest.mark.parametrize("n_points", [1, 2, 5, 15, 40])
def test_the_honest_sigma_bound_is_the_99_percent_point_of_its_chi_square(n_points):
    # RMS error/sigma of n complex points whose sigma is honest: sqrt(chi2(2n) / 2n). The
    # bound the report reads "about 1" under is its 99 % point (15 points: 1.30, where a
    # fixed 2 let sigmas understated by half pass).
    from scipy.stats import chi2

    from heliquad.host.estimate.thresholds import honest_sigma_bound

    exact = (chi2.ppf(0.99, 2 * n_points) / (2 * n_points)) ** 0.5
    assert honest_sigma_bound(n_points) == pytest.approx(exact, rel=5e-3)   # the approximation
