"""Every run ends cleanly, however it ends: normally, on a terminal's Ctrl-C (SIGINT to its
process group), on SIGTERM, on SIGHUP (the terminal or SSH session closed: to its process
group), or with its firmware killed (SIGKILL) under it. Each leaves its
records readable (a sweep's manifest with ``aborted`` set and the frequency in progress),
no process running (this test process adopts any orphan: tool_runs.adopting_orphans) and
nothing in its TMPDIR (the firmware's temporary folder and links).

Signals are sent once the run is observably under way (a line printed, the log growing),
in runs made many times longer than that, and each outcome is checked on what the run
wrote: no test depends on timing."""

import json
import os
import signal

import pytest

import teensy_image
from heliquad.host.acquire.log_session import summarise_tlog
from tool_runs import (Tool, assert_nothing_left, excitation_running, one_line, private_tmpdir,
                       size, wait_for)

ENDINGS = ["normal", "ctrl-c", "sigterm", "sighup", "firmware killed"]
#: How a signal ends every command (host/cli/parser.py): the word said and the exit code, after
#: the same orderly stop.
BY_SIGNAL = {"ctrl-c": ("interrupted", 130), "sigterm": ("terminated", 143),
             "sighup": ("hung up", 129)}
#: Log bytes that show a run under way: about 150 loops of telemetry; a sweep's 100 kB are
#: about 4 s simulated, past its 1.2 s of boot and hover and into its first frequency.
UNDER_WAY, SWEEP_UNDER_WAY = 20_000, 100_000


@pytest.fixture
def tmpdir_(tmp_path):
    with private_tmpdir(tmp_path) as tmp:
        yield tmp


def end_run(tool, ending, log, under_way=UNDER_WAY):
    """End ``tool`` as ``ending`` says once its log shows it under way."""
    if ending == "normal":
        return
    wait_for(lambda: size(log) > under_way, "a log under way", tool.proc)
    send(tool, ending)


def send(tool, ending):
    if ending == "ctrl-c":
        tool.ctrl_c()
    elif ending == "sigterm":
        tool.sigterm()
    elif ending == "sighup":
        tool.sighup()
    else:
        os.kill(tool.firmware_pid(), signal.SIGKILL)


def assert_signal_ending(ending, code, err):
    """One line naming the signal, and its exit code."""
    word, expected = BY_SIGNAL[ending]
    assert code == expected and one_line(err).endswith(f": {word}"), (code, err)


#: The board keeps all its telemetry for its reader (--backlog-bytes 0): a log's every sample
#: is asserted, and a reader a loaded machine stalls would lose some past the default bound.
KEEP_ALL = ("--backlog-bytes", 0)


def assert_log_readable(path):
    s = summarise_tlog(str(path))
    assert s["samples"] > 0 and s["damage"] is None and s["lost"] == 0, s


@pytest.mark.parametrize("ending", ENDINGS)
def test_board(ending, tmpdir_, tmp_path):
    rig = tmp_path / "rig"
    board = Tool("board", "--telemetry", rig, "--duration-s", 1 if ending == "normal" else 600,
                 *KEEP_ALL, tmpdir=tmpdir_)
    assert "board running" in board.readline()
    if ending != "normal":
        send(board, ending)
    code, out, err = board.finish()
    if ending == "firmware killed":             # the board went away: exit 1
        assert code == 1 and "the firmware died" in one_line(err)
    elif ending == "normal":
        assert code == 0 and "stopped after" in out and err == "", err
    else:
        assert_signal_ending(ending, code, err)
        assert "stopped after" in out
    assert not os.path.lexists(rig)             # its telemetry link goes with it
    assert_nothing_left(tmpdir_)


@pytest.mark.parametrize("ending", ENDINGS)
def test_log(ending, tmpdir_, tmp_path):
    rig, out = tmp_path / "rig", tmp_path / "flight.tlog"
    board = Tool("board", "--telemetry", rig, "--duration-s", 600, *KEEP_ALL, tmpdir=tmpdir_)
    assert "board running" in board.readline()
    log = Tool("log", "--port", rig, "--out", out,
               *(["--duration-s", 1] if ending == "normal" else []), tmpdir=tmpdir_)
    if ending == "firmware killed":          # the board's firmware: the log's link goes away
        wait_for(lambda: size(out) > UNDER_WAY, "a log under way", log.proc)
        os.kill(board.firmware_pid(), signal.SIGKILL)
    else:
        end_run(log, ending, out)
    code, stdout, err = log.finish()
    if ending == "firmware killed":
        assert code == 1 and "telemetry link lost" in one_line(err) and "kept" in err
        board_code, _, board_err = board.finish()
        assert board_code == 1 and "the firmware died" in one_line(board_err)
    else:
        if ending == "normal":
            assert code == 0 and err == "", err
        else:
            assert_signal_ending(ending, code, err)
        assert f"wrote {out}" in stdout
        board.ctrl_c()
        assert board.finish()[0] == 130
    assert_log_readable(out)
    assert not os.path.lexists(rig)
    assert_nothing_left(tmpdir_)


@pytest.mark.parametrize("ending", ENDINGS)
def test_sil(ending, tmpdir_, tmp_path):
    run = tmp_path / "run"
    # Normal: a short experiment; the others: 280 s at a 1 kHz loop (many seconds here).
    what = ["--freq-hz", 4, "--cycles", 3] if ending == "normal" else \
        ["--freq-hz", 0.05, "--cycles", 10, "--loop-hz", 1000]
    sil = Tool("sil", *what, "--amplitude", 0.05, "--out", run, tmpdir=tmpdir_)
    end_run(sil, ending, f"{run}.tlog")
    code, out, err = sil.finish()
    # The firmware killed is the board gone: exit 1 (the rule in host/cli/parser.py), not 2.
    expected = {"normal": (0, None), "firmware killed": (1, "the firmware died"),
                **{k: (code, word) for k, (word, code) in BY_SIGNAL.items()}}
    assert code == expected[ending][0], out + err
    if code:
        assert expected[ending][1] in one_line(err)
    else:
        assert os.path.getsize(f"{run}.csv") > 0
    assert_log_readable(f"{run}.tlog")
    assert_nothing_left(tmpdir_)


@pytest.mark.parametrize("firmware", ["host", pytest.param("teensy35", marks=pytest.mark.pil)])
@pytest.mark.parametrize("ending", ENDINGS)
def test_sweep_sil(ending, firmware, tmpdir_, tmp_path):
    out = tmp_path / "sweep"
    env = {"HQ_TEENSY35_ELF": str(teensy_image.image().elf)} if firmware == "teensy35" else {}
    # Normal: one quick frequency; the others: three of the slowest the firmware allows
    # (0.05-0.07 Hz x 10 cycles, 12 min simulated).
    freqs = [4] if ending == "normal" else [0.05, 0.06, 0.07]
    sweep = Tool("sweep", "--axis", "yaw" if ending != "normal" else "roll", "--sil",
                 "--ideal-sensor", "--firmware", firmware, "--freqs-hz", *freqs,
                 "--cycles", 3 if ending == "normal" else 10, "--out", out,
                 tmpdir=tmpdir_, env=env)
    end_run(sweep, ending, out / "sweep.tlog", SWEEP_UNDER_WAY)
    code, stdout, err = sweep.finish()
    manifest = json.loads((out / "manifest.json").read_text())
    if ending == "normal":
        assert code == 0 and manifest["complete"] and manifest["aborted"] is None, err
    else:
        assert not manifest["complete"] and manifest["in_progress_hz"] == 0.05
        if ending == "firmware killed":
            assert code == 1 and "the firmware died" in one_line(err), stdout + err
            assert manifest["aborted"].startswith("the firmware died at frame")
        else:
            how = {"ctrl-c": "interrupted (Ctrl-C)", "sigterm": "terminated (SIGTERM)",
                   "sighup": "hung up (SIGHUP)"}[ending]
            assert code == BY_SIGNAL[ending][1] and manifest["aborted"] == how, stdout + err
            assert f"{how}: the excitation is stopped" in stdout
    assert_log_readable(out / "sweep.tlog")
    assert_nothing_left(tmpdir_)


def test_a_firmware_start_interrupted_leaves_no_process_or_folder(monkeypatch):
    # Ctrl-C (or SIGTERM) while the firmware starts (the emulated Teensy takes seconds):
    # the process it had started is stopped and its folder removed before the
    # interrupt goes on.
    from heliquad.sim.rig.lockstep import HostFirmware

    started = []
    wait_ready = HostFirmware._wait_ready

    def interrupted(self):
        started.append(self)
        wait_ready(self)                       # it is up, its links are there
        raise KeyboardInterrupt

    monkeypatch.setattr(HostFirmware, "_wait_ready", interrupted)
    with pytest.raises(KeyboardInterrupt):
        HostFirmware()
    fw, = started
    assert fw.proc.poll() is not None and not os.path.exists(fw.workdir)


def test_a_firmware_stop_interrupted_still_stops_it_and_removes_its_links(tmp_path):
    # A second Ctrl-C while the firmware is asked to exit: it is killed at once, and the
    # links it had no time to remove (here one outside its folder, as `heliquad board`
    # publishes) are removed for it, with the folder.
    from heliquad.sim.rig.lockstep import HostFirmware

    telemetry = tmp_path / "telemetry"
    fw = HostFirmware(telemetry_path=str(telemetry))
    assert os.path.islink(telemetry)
    os.kill(fw.proc.pid, signal.SIGSTOP)       # it cannot act on the SIGTERM
    wait = fw.proc.wait

    def interrupted(timeout=None):
        fw.proc.wait = wait
        raise KeyboardInterrupt

    fw.proc.wait = interrupted
    with pytest.raises(KeyboardInterrupt):
        fw.stop()
    assert fw.proc.returncode == -signal.SIGKILL
    assert not os.path.lexists(telemetry) and not os.path.exists(fw.workdir)


def test_a_sweep_over_a_port_whose_board_dies(tmpdir_, tmp_path):
    # The board's firmware killed under a sweep over its port: the sweep ends with one
    # line, its manifest says why and at which frequency, its log is kept. The board went
    # away: exit 1, as for one that fell silent (host/cli/parser.py's rule).
    rig, out = tmp_path / "rig", tmp_path / "sweep"
    board = Tool("board", "--telemetry", rig, "--duration-s", 600, *KEEP_ALL, tmpdir=tmpdir_)
    assert "board running" in board.readline()
    sweep = Tool("sweep", "--axis", "roll", "--port", rig, "--freqs-hz", 0.5, "--cycles", 10,
                 "--out", out, tmpdir=tmpdir_)
    wait_for(lambda: excitation_running(out / "sweep.tlog"), "the excitation running",
             sweep.proc)
    os.kill(board.firmware_pid(), signal.SIGKILL)
    code, _, err = sweep.finish()
    assert code == 1 and f"kept in {out}" in one_line(err)
    assert "the board went away: telemetry link lost" in one_line(err)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["aborted"].startswith("the board went away") and not manifest["complete"]
    assert manifest["frequencies"][-1]["requested_hz"] == 0.5
    assert_log_readable(out / "sweep.tlog")
    assert board.finish()[0] == 1
    assert not os.path.lexists(rig)
    assert_nothing_left(tmpdir_)
