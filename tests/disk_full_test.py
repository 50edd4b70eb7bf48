"""A full disk during a run: the run stops with one line on stderr naming the file, exit 1,
the excitation and the firmware stopped, the log readable up to its last whole record and
(for a sweep) the manifest valid with ``aborted`` set. Nothing recorded before is lost.

A full disk is made without root or mounts: the run gets a file-size limit (RLIMIT_FSIZE,
with SIGXFSZ ignored), so a write past it fails with EFBIG, which the tool takes as a full
disk's ENOSPC. The firmware processes inherit the limit; they write no file but their
stderr (a few lines), so they run on unaffected."""

import json
import os
import subprocess
import sys

import pytest

import teensy_image
from heliquad.host.acquire.log_session import summarise_tlog
from heliquad.sim.base.errors import DiskFull
from tool_runs import Tool, assert_nothing_left, one_line, private_tmpdir

#: The file-size limit: a few seconds of telemetry.
LIMIT = 100_000


@pytest.fixture
def tmpdir_(tmp_path):
    with private_tmpdir(tmp_path) as tmp:
        yield tmp


def assert_whole_log(path):
    """Cut back to its last whole record: read without damage, and nothing past the limit."""
    assert 0 < os.path.getsize(path) <= LIMIT
    s = summarise_tlog(str(path))
    assert s["damage"] is None and s["samples"] > 0 and s["lost"] == 0, s
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "tlog", str(path)],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and res.stderr == "", res.stderr


def assert_disk_full(code, err, path):
    line = one_line(err)
    assert code == 1 and f"disk full: {path} (File too large)" in line, err


@pytest.fixture
def board(tmpdir_, tmp_path):
    rig = tmp_path / "rig"
    # All its telemetry kept for the reader (a stalled one would lose some past the default
    # bound): the log's every sample is asserted.
    board = Tool("board", "--telemetry", rig, "--duration-s", 600, "--backlog-bytes", 0,
                 tmpdir=tmpdir_)
    assert "board running" in board.readline()
    yield board, rig
    board.ctrl_c()
    assert board.finish()[0] == 130                  # Ctrl-C: its code, after the stop


def test_log(board, tmpdir_, tmp_path):
    _, rig = board
    out = tmp_path / "flight.tlog"
    code, stdout, err = Tool("log", "--port", rig, "--out", out, tmpdir=tmpdir_,
                             file_limit=LIMIT).finish()
    assert_disk_full(code, err, out)
    assert f"wrote {out}" in stdout                 # the summary of what the log holds
    assert_whole_log(out)
    assert board[0].proc.poll() is None             # the board runs on


def test_sweep_over_a_port(board, tmpdir_, tmp_path):
    _, rig = board
    out = tmp_path / "sweep"
    code, _, err = Tool("sweep", "--axis", "roll", "--port", rig, "--freqs-hz", 0.5,
                        "--out", out, tmpdir=tmpdir_, file_limit=LIMIT).finish()
    assert_disk_full(code, err, out / "sweep.tlog")
    assert f"kept in {out}" in err
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["aborted"] == f"disk full: {out / 'sweep.tlog'} (File too large)"
    assert manifest["in_progress_hz"] == 0.5 and not manifest["complete"]
    assert_whole_log(out / "sweep.tlog")


@pytest.mark.parametrize("firmware", ["host", pytest.param("teensy35", marks=pytest.mark.pil)])
def test_sweep_sil(firmware, tmpdir_, tmp_path):
    # The SIL's log is written by the simulator's telemetry tap (C++), not by Python.
    out = tmp_path / "sweep"
    env = {"HQ_TEENSY35_ELF": str(teensy_image.image().elf)} if firmware == "teensy35" else {}
    code, _, err = Tool("sweep", "--axis", "roll", "--sil", "--firmware", firmware,
                        "--freqs-hz", 0.5, "--cycles", 10, "--out", out, tmpdir=tmpdir_,
                        file_limit=LIMIT, env=env).finish()
    assert_disk_full(code, err, out / "sweep.tlog")
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["aborted"].startswith("disk full: ") and manifest["in_progress_hz"] == 0.5
    assert_whole_log(out / "sweep.tlog")
    assert_nothing_left(tmpdir_)


def test_sil(tmpdir_, tmp_path):
    run = tmp_path / "run"
    code, _, err = Tool("sil", "--freq-hz", 0.5, "--cycles", 10, "--amplitude", 0.05,
                        "--out", run, tmpdir=tmpdir_, file_limit=LIMIT).finish()
    assert_disk_full(code, err, f"{run}.tlog")
    assert not os.path.exists(f"{run}.csv")
    assert_whole_log(f"{run}.tlog")
    assert_nothing_left(tmpdir_)


LIMITED = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
"""


def run_limited(code: str, limit: int) -> subprocess.CompletedProcess:
    """Python ``code`` in a process whose files may not grow past ``limit`` bytes."""
    return subprocess.run([sys.executable, "-c", LIMITED.format(limit=limit) + code],
                          capture_output=True, text=True, timeout=60)


def test_a_manifest_that_does_not_fit_leaves_the_previous_one_whole(tmp_path):
    path = tmp_path / "manifest.json"
    res = run_limited(f"""
from heliquad.sim.base.errors import DiskFull
from heliquad.host.records.output import write_json
write_json({str(path)!r}, {{"aborted": None}})
try:
    write_json({str(path)!r}, {{"aborted": "x" * 1000}})
except DiskFull as exc:
    print(exc)
""", limit=500)
    assert res.stdout.strip() == f"disk full: {path} (File too large)", res.stderr
    assert json.loads(path.read_text()) == {"aborted": None}
    assert [p.name for p in tmp_path.iterdir()] == ["manifest.json"]     # no temporary file


def test_the_tlog_writer_keeps_whole_records_only(tmp_path):
    # Records of every size up to the limit: the file ends with the last one that fitted
    # whole, every later write is refused, and closing writes nothing more.
    path = tmp_path / "w.tlog"
    res = run_limited(f"""
from heliquad.sim.base.errors import DiskFull
from heliquad.host.records.tlog import TlogWriter
from heliquad.sim.base.dialect import dialect
mav = dialect().MAVLink(None, srcSystem=1, srcComponent=1)
w, n = TlogWriter({str(path)!r}), 0
try:
    while True:
        for i in range(7):
            w.write(n, mav.statustext_encode(6, ("m%d " % n * 12)[:50].encode()).pack(mav))
            n += 1
        w.flush()
except DiskFull as exc:
    print(exc, w.messages)
for call in (lambda: w.write(0, b"x"), w.flush):
    try:
        call()
    except DiskFull:
        pass
    else:
        raise SystemExit("a write after the full disk was taken")
w.close()
""", limit=5000)
    assert res.returncode == 0, res.stderr
    text, kept = res.stdout.rsplit(maxsplit=1)
    assert text == f"disk full: {path} (File too large)"
    from heliquad.host.records.tlog import TlogDamage, read_tlog
    from heliquad.sim.base.dialect import dialect

    damage = TlogDamage()
    msgs = read_tlog(str(path), dialect(), damage=damage)
    assert not damage and len(msgs) == int(kept) > 0
    assert [ts for ts, _ in msgs] == list(range(len(msgs)))         # none lost, none twice
    assert damage.size == path.stat().st_size <= 5000


def test_a_flush_interrupted_by_a_signal_writes_every_record_once(tmp_path):
    # Ctrl-C (or SIGTERM) during a flush, after part of it reached the file: the next flush
    # goes on where the file ends.
    from heliquad.host.records.tlog import TlogDamage, TlogWriter, read_tlog
    from heliquad.sim.base.dialect import dialect

    mav = dialect().MAVLink(None, srcSystem=1, srcComponent=1)
    w = TlogWriter(str(tmp_path / "i.tlog"))
    for n in range(50):
        w.write(n, mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav))
    real = w._fh

    class Interrupted:
        """The file, interrupted after the first 100 bytes of a write."""
        closed = False

        def fileno(self):
            return real.fileno()

        def write(self, data):
            real.write(bytes(data[:100]))
            raise KeyboardInterrupt

    w._fh = Interrupted()
    with pytest.raises(KeyboardInterrupt):
        w.flush()
    w._fh = real
    w.write(50, mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav))
    w.close()
    damage = TlogDamage()
    msgs = read_tlog(str(tmp_path / "i.tlog"), dialect(), damage=damage)
    assert not damage and [ts for ts, _ in msgs] == list(range(51)) and w.messages == 51


def test_a_sweep_that_a_full_disk_stops_keeps_its_manifest_and_stops_the_excitation(
        tmp_path, monkeypatch):
    """run_sweep's own path, on a session whose log fills the disk mid-frequency: the
    excitation is stopped, the manifest records why and the frequency in progress; and when
    even that manifest does not fit, the previous one stays and the one line says so."""
    from heliquad.host.acquire import sweep as sweep_module
    from heliquad.host.acquire.sweep import default_plan, run_sweep

    class Link:
        stops = 0

        def start_excitation(self, *args):
            pass

        def stop_excitation(self):
            Link.stops += 1

    class Session:
        tel = Link()
        time_us = 0

        def hover(self, progress=None):
            pass

        def advance(self, handle=None):
            raise DiskFull(tmp_path / "sweep.tlog", "No space left on device")

    # The board's parameters are read before the first frequency, through the same advance:
    # here the disk fills once the frequency runs.
    monkeypatch.setattr(sweep_module, "_record_params", lambda *args: None)
    plan = default_plan("roll", "mixer", [1.0, 2.0])
    with pytest.raises(DiskFull) as raised:
        run_sweep(Session(), plan, str(tmp_path), {"kind": "test"}, progress=lambda *_: None)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["aborted"] == str(raised.value) == \
        f"disk full: {tmp_path / 'sweep.tlog'} (No space left on device)"
    assert manifest["in_progress_hz"] == 1.0 and Link.stops == 1

    out = tmp_path / "full"
    out.mkdir()
    real = sweep_module.write_manifest

    def manifest_fits_only_without_an_abort(path, manifest):
        if manifest.aborted:
            raise DiskFull(path, "No space left on device")
        real(path, manifest)

    monkeypatch.setattr(sweep_module, "write_manifest", manifest_fits_only_without_an_abort)
    with pytest.raises(DiskFull) as raised:
        run_sweep(Session(), plan, str(out), {"kind": "test"}, progress=lambda *_: None)
    assert "manifest.json could not be updated either; its previous version is kept" \
        in str(raised.value)
    assert json.loads((out / "manifest.json").read_text())["aborted"] is None
    assert Link.stops == 2
