"""Nothing already recorded is lost: the commands that record (log, sweep, sil) never write
over a log or into an earlier session's folder, and a bad port creates nothing."""

import dataclasses
import importlib
import os
import subprocess
import sys

import pytest


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def one_line_error(res, *words):
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    for w in words:
        assert w in lines[0], lines[0]


@pytest.fixture
def old_log(tmp_path):
    path = tmp_path / "flight.tlog"
    path.write_bytes(b"recorded flight data \x00\x01\x02" * 100)
    return path


@pytest.fixture
def pty_port():
    """A port that opens (the slave of a pty nobody writes to)."""
    master, slave = os.openpty()
    yield os.ttyname(slave)
    os.close(slave)
    os.close(master)


def test_log_with_a_bad_port_leaves_an_existing_log_untouched(old_log, tmp_path):
    before = old_log.read_bytes()
    res = heliquad("log", "--port", tmp_path / "no-such-port", "--out", old_log)
    one_line_error(res, "no-such-port")
    assert old_log.read_bytes() == before


def test_log_with_a_bad_port_creates_no_file(tmp_path):
    out = tmp_path / "new.tlog"
    one_line_error(heliquad("log", "--port", tmp_path / "no-such-port", "--out", out))
    assert not out.exists()


def test_log_refuses_to_write_over_an_existing_log(old_log, pty_port):
    before = old_log.read_bytes()
    res = heliquad("log", "--port", pty_port, "--out", old_log, "--duration-s", "0.2")
    one_line_error(res, str(old_log), "exists", "another name")
    assert old_log.read_bytes() == before


def test_sweep_refuses_a_folder_that_holds_an_earlier_session(tmp_path):
    folder = tmp_path / "old_sweep"
    folder.mkdir()
    (folder / "sweep.tlog").write_bytes(b"an earlier session")
    (folder / "models.json").write_text("{}")
    for source in (["--port", tmp_path / "nope"], ["--sil"]):
        res = heliquad("sweep", "--axis", "roll", *source, "--out", folder)
        one_line_error(res, "not empty", "--out")
    assert (folder / "sweep.tlog").read_bytes() == b"an earlier session"
    assert sorted(p.name for p in folder.iterdir()) == ["models.json", "sweep.tlog"]


def test_sweep_with_a_bad_port_leaves_no_folder(tmp_path):
    out = tmp_path / "new_sweep"
    one_line_error(heliquad("sweep", "--axis", "roll", "--port", tmp_path / "nope", "--out", out),
                   "nope")
    assert not out.exists()


def test_sweep_into_an_existing_empty_folder_keeps_the_folder(tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    one_line_error(heliquad("sweep", "--axis", "roll", "--port", tmp_path / "nope", "--out", out))
    assert out.is_dir() and not any(out.iterdir())


@pytest.mark.parametrize("existing", ["run.tlog", "run.csv"])
def test_sil_refuses_to_write_over_a_run(tmp_path, existing):
    (tmp_path / existing).write_text("an earlier run")
    res = heliquad("sil", "--axis", "roll", "--freq-hz", "1", "--amplitude", "0.05",
                   "--out", tmp_path / "run")
    one_line_error(res, existing, "exists")
    assert (tmp_path / existing).read_text() == "an earlier run"
    assert sorted(p.name for p in tmp_path.iterdir()) == [existing]


def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path):
    from heliquad.host.records.output import atomic_write, write_json

    path = tmp_path / "models.json"
    write_json(path, {"models": [1, 2, 3]})
    before = path.read_text()
    with pytest.raises(RuntimeError):
        with atomic_write(path) as fh:
            fh.write('{"models": [')
            raise RuntimeError("the disk filled up here")
    assert path.read_text() == before
    assert [p.name for p in tmp_path.iterdir()] == ["models.json"]


def test_an_unwritable_folder_is_one_line(tmp_path):
    from heliquad.host.records.output import write_json
    from heliquad.sim.base.errors import InputError

    with pytest.raises(InputError, match="cannot write .*no-such-folder"):
        write_json(tmp_path / "no-such-folder" / "x.json", {})


def test_fit_into_a_missing_folder_is_one_line_and_writes_nothing(tmp_path):
    points = tmp_path / "points.csv"
    points.write_text("omega_rad_s,magnitude,phase_rad\n1,1,-0.5\n2,0.8,-1\n4,0.5,-1.5\n"
                      "8,0.2,-2\n16,0.05,-2.5\n")
    res = heliquad("fit", points, "--order", "0/2", "--json", tmp_path / "nope" / "m.json")
    one_line_error(res, "nope")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["points.csv"]


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """A SIL sweep of the roll rig (the transfer-function plant, host build)."""
    out = tmp_path_factory.mktemp("sweep") / "roll"
    res = heliquad("sweep", "--sil", "--axis", "roll", "--out", out)
    assert res.returncode == 0, res.stderr
    return out


def _copy(sweep, dest):
    import shutil

    shutil.copytree(sweep, dest)
    return dest


def test_identify_reads_past_a_damaged_byte_and_the_report_flags_it(sweep, tmp_path):
    import json

    folder = _copy(sweep, tmp_path / "damaged")
    log = folder / "sweep.tlog"
    data = bytearray(log.read_bytes())
    pos = 0                                # the first record from byte 1000 on: stamp, packet
    while pos < 1000:
        pos += 8 + 12 + data[pos + 9]                           # stamp, header + CRC, payload
    data[pos + 8 + 10 + 1] ^= 0x10         # a payload bit (its CRC fails): the flip that used
    log.write_bytes(bytes(data))           # to lose every frequency
    res = heliquad("identify", folder)
    assert res.returncode == 0, res.stderr
    assert "15 points" in res.stdout                      # every frequency still measured
    assert "is damaged" in res.stdout and "the first at byte" in res.stdout
    doc = json.loads((folder / "models.json").read_text())
    assert doc["log"]["skipped_bytes"] > 0 and doc["log"]["damaged_regions"] == 1
    assert heliquad("report", folder).returncode == 0
    page = (folder / "report.html").read_text()
    assert "the log is damaged" in page and "No quality flags" not in page


def test_a_flipped_timestamp_bit_in_a_sil_sweep_is_reported(sweep, tmp_path):
    # No CRC covers a timestamp, and flipping its lowest bit keeps time in order; a simulated
    # session stamps each record with its loop's time, so the one record is still named.
    import json

    folder = _copy(sweep, tmp_path / "stamp")
    log = folder / "sweep.tlog"
    data = bytearray(log.read_bytes())
    pos = 0
    while pos < len(data) // 3:
        pos += 8 + 12 + data[pos + 9]                           # stamp, header + CRC, payload
    data[pos + 7] ^= 0x01
    log.write_bytes(bytes(data))
    res = heliquad("identify", folder)
    assert res.returncode == 0, res.stderr
    assert "15 points" in res.stdout
    assert f"1 timestamp not the time of their control loop (the first at byte {pos})" \
        in res.stdout
    doc = json.loads((folder / "models.json").read_text())
    assert doc["log"]["stamps_not_loop_time"] == 1 and doc["log"]["skipped_bytes"] == 0
    assert heliquad("report", folder).returncode == 0
    page = (folder / "report.html").read_text()
    assert "1 not their control loop&#x27;s time" in page          # html.escape'd


@pytest.mark.parametrize("plot", ["bode.png", "responses.png"])
def test_a_plot_identify_cannot_write_is_one_line_and_the_rest_is_written(sweep, tmp_path,
                                                                          plot):
    # The plots are drawn by a process of their own; what fails there is said here, as any
    # file that cannot be written is.
    folder = _copy(sweep, tmp_path / "blocked")
    (folder / plot).mkdir()                         # a folder where the picture would go
    one_line_error(heliquad("identify", folder), "cannot write", plot)
    assert (folder / "models.json").exists() and (folder / plot).is_dir()


def test_a_broken_matplotlib_is_one_line_and_the_points_and_models_are_written(sweep,
                                                                              tmp_path):
    # The plotting process cannot import what it draws with: said in one line, named, and
    # identify's own results are kept.
    import os
    import subprocess
    import sys

    folder = _copy(sweep, tmp_path / "nompl")
    fake = tmp_path / "fake" / "matplotlib"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('matplotlib is broken here')\n")
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "fake")}
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "identify", folder],
                         capture_output=True, text=True, env=env, timeout=300)
    one_line_error(res, "the plots were not drawn", "ImportError", "matplotlib is broken here")
    assert (folder / "models.json").exists() and (folder / "points.csv").exists()
    assert not (folder / "bode.png").exists() and not (folder / "responses.png").exists()


def test_a_plotting_process_that_died_loses_identify_nothing(sweep, tmp_path):
    # Killed before anything reached it: identify still writes its points and models, then
    # says the plots were not drawn.
    from heliquad.host.campaign.identify import identify_dir
    from heliquad.host.present.plot_process import PlotProcess
    from heliquad.sim.base.errors import InputError

    folder = _copy(sweep, tmp_path / "died")
    with PlotProcess() as plots:
        plots.proc.kill()
        plots.proc.wait()
        with pytest.raises(InputError, match=r"their process ended \(exit code -9\)"):
            identify_dir(str(folder), progress=lambda *_: None, plots=plots)
    assert (folder / "models.json").exists() and (folder / "points.csv").exists()


def test_identify_refuses_a_log_of_another_session(sweep, tmp_path):
    import json

    folder = _copy(sweep, tmp_path / "mixed")
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["axis"] = "pitch"
    (folder / "manifest.json").write_text(json.dumps(manifest))
    one_line_error(heliquad("identify", folder), "not of one session", "roll", "pitch")
    assert not (folder / "models.json").exists()


def test_identify_says_which_frequencies_the_log_lost(sweep, tmp_path):
    import json

    folder = _copy(sweep, tmp_path / "short")
    log = folder / "sweep.tlog"
    data = log.read_bytes()
    log.write_bytes(data[:len(data) * 2 // 3])            # the last frequencies are gone
    res = heliquad("identify", folder)
    assert res.returncode == 0, res.stderr
    assert "the log holds none of its samples" in res.stdout
    assert "frequencies not used" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    doc = json.loads((folder / "models.json").read_text())
    assert doc["skipped_frequencies"]
    assert heliquad("report", folder).returncode == 0
    assert "(not used)" in (folder / "report.html").read_text()


def test_the_demo_refuses_a_folder_with_an_earlier_demo(tmp_path):
    out = tmp_path / "heliquad-demo"
    (out / "roll").mkdir(parents=True)
    (out / "roll" / "sweep.tlog").write_bytes(b"an earlier demo")
    one_line_error(heliquad("demo", "--axes", "roll", "--out", out), "not empty", "--out")
    assert (out / "roll" / "sweep.tlog").read_bytes() == b"an earlier demo"


@pytest.mark.parametrize("module, record, schema", [
    ("models", "ModelsFile", "_models_schema"), ("validation", "ValidationFile",
                                                 "_validation_schema")])
def test_each_key_the_reader_checks_is_a_field_of_its_record(module, record, schema):
    # the reader keeps only its record's fields: a key checked but not kept would be lost
    mod = importlib.import_module(f"heliquad.host.records.{module}")
    spec = getattr(mod, schema)()
    fields = {f.name for f in dataclasses.fields(getattr(mod, record))}
    assert {*spec.required, *spec.optional} <= fields
    if module == "models":
        model = spec.required["models"].item
        stored = {f.name for f in dataclasses.fields(mod.StoredModel)}
        assert {*model.required, *model.optional} == stored
