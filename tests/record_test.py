"""heliquad identify --from-record: a log read as one record, by the composite of windows
(host/campaign/record.py over host/estimate/composite.py), on a simulated rig's log."""

import json
import shutil
import subprocess
import sys

import pytest


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def multisine(tmp_path_factory):
    """A roll multisine on the simulated rig (its transfer-function plant, still air): a
    broadband record with an excitation."""
    out = tmp_path_factory.mktemp("record") / "roll"
    res = heliquad("sweep", "--axis", "roll", "--sil", "--plant", "tf", "--signal", "multisine",
                   "--rig-time", 30, "--out", out)
    assert res.returncode == 0, res.stderr
    return out


def copy_of(folder, tmp_path):
    dest = tmp_path / "roll"
    shutil.copytree(folder, dest)
    return dest


def test_a_record_read_as_one_gives_the_plant_within_a_dB_and_5_degrees(multisine, tmp_path):
    folder = copy_of(multisine, tmp_path)
    res = heliquad("identify", folder, "--from-record")
    assert res.returncode == 0, res.stderr
    assert "record: 30.1 s of axis_cmd and rate at 200 Hz; windows 15, 11.1, 8.18, 6.03, " \
           "4.44 s; 20 of 20 points with coherence >= 0.6" in res.stdout
    # each point says which estimate it came from
    assert res.stdout.count("composite of windows against the excitation") == 20
    doc = json.loads((folder / "models.json").read_text())
    assert doc["estimate"] == "excitation" and doc["cost"] == "j"
    record = doc["record"]
    assert (record["input"], record["output"], record["estimate"]) == ("axis_cmd", "rate",
                                                                       "excitation")
    # the band is the multisine's lines' (base 1/6 Hz, lines up to 4.5 Hz)
    assert record["band_hz"][0] == pytest.approx(0.5, rel=0.01)
    assert record["band_hz"][1] == pytest.approx(4.5, rel=0.05)
    truth = doc["sil_truth"]
    assert truth["model_worst_db"] < 1.0 and truth["model_worst_deg"] < 5.0
    # between a multisine's lines the windows' taper mixes neighbouring lines (a bias the
    # random error does not count): the points are within 1.5 dB and 6 deg, the model closer
    assert truth["points_worst_db"] < 1.5 and truth["points_worst_deg"] < 6.0
    assert "replay" not in doc
    assert (folder / "bode.png").stat().st_size > 10_000
    assert (folder / "responses.png").stat().st_size > 10_000


def test_a_tlog_alone_is_read_with_its_axis_and_the_band_given(multisine, tmp_path):
    log = tmp_path / "flight.tlog"
    shutil.copy(multisine / "sweep.tlog", log)
    res = heliquad("identify", log, "--from-record", "--band", 0.5, 4, "--order", "0/2")
    assert res.returncode == 0, res.stderr
    doc = json.loads((tmp_path / "models.json").read_text())
    assert doc["axis"] == "roll" and doc["record"]["band_hz"] == [0.5, 4.0]
    assert "sil_truth" not in doc               # a log alone says nothing of its simulator
    assert doc["recommended"] == 0


def test_the_input_and_output_are_named(multisine, tmp_path):
    # the rate setpoint's path to the rate: the closed rate loop, a different response
    folder = copy_of(multisine, tmp_path)
    res = heliquad("identify", folder, "--from-record", "--input", "rate_sp", "--output",
                   "rate", "--order", "0/2")
    assert res.returncode == 0, res.stderr
    doc = json.loads((folder / "models.json").read_text())
    assert (doc["record"]["input"], doc["record"]["output"]) == ("rate_sp", "rate")
    assert "broken_loop" not in doc             # that is the injection's pair's alone


@pytest.mark.parametrize("args, said", [
    (["--input", "rate"], "--input and --output go together"),
    (["--band", 4, 1], "--band 4 1: give LO_HZ < HI_HZ, both positive"),
    (["--band", 1, 150], "below the record's Nyquist frequency (100 Hz)"),
    (["--input", "bogus", "--output", "rate"], "invalid choice: 'bogus'"),
])
def test_bad_record_options_are_one_line_exit_2(multisine, tmp_path, args, said):
    folder = copy_of(multisine, tmp_path)
    res = heliquad("identify", folder, "--from-record", *args)
    assert res.returncode == 2 and said in res.stderr and res.stderr.count("\n") == 1, \
        res.stderr


def test_an_axis_the_records_samples_are_not_of_is_refused(multisine, tmp_path):
    # HQ_SYSID_SAMPLE's fields are of the axis it names: --axis cannot relabel them
    log = tmp_path / "flight.tlog"
    shutil.copy(multisine / "sweep.tlog", log)
    res = heliquad("identify", log, "--from-record", "--axis", "pitch")
    assert res.returncode == 2 and "--axis pitch: the record's samples are roll's" in res.stderr
    assert not (tmp_path / "models.json").exists()


def test_record_options_without_from_record_are_refused(multisine, tmp_path):
    res = heliquad("identify", copy_of(multisine, tmp_path), "--axis", "roll")
    assert res.returncode == 2 and "--axis is an option of --from-record" in res.stderr


def test_a_record_too_short_for_its_lowest_window_is_one_line(multisine, tmp_path):
    folder = copy_of(multisine, tmp_path)
    res = heliquad("identify", folder, "--from-record", "--band", 0.05, 4)
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert "the record (30.1 s) is too short for 0.05 Hz: its longest window (0.5 of the " \
           "record) must hold 2 periods, so the record at least 80 s" in res.stderr


def test_a_tlog_without_samples_is_one_line(tmp_path):
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    res = heliquad("identify", empty, "--from-record")
    assert res.returncode == 2 and "no HQ_SYSID_SAMPLE: no record to identify" in res.stderr
