"""Sweeps through links that lose or damage data: a relay between
``heliquad board`` and ``heliquad sweep --port`` that corrupts bytes or drops whole packets,
each with a seeded random pattern (the same damage to the same stream every time; where the
excitation falls in the stream is the only thing timing changes, and no assertion depends on
it), and guard timeouts far beyond what a run takes."""

import json
import os
import subprocess
import sys
import threading
import tty

import numpy as np
import pytest

from tool_runs import excitation_running, running_board

#: A roll sweep short enough for the suite: three of the band's frequencies, six measured
#: cycles each (about 11 s of excitation in real time).
FREQS_HZ = ("2", "3", "4.5")
CYCLES = "6"
#: The damage the sweeps must survive: a byte in 10 000 corrupted, 2 % of the packets lost.
CORRUPT_BYTE_RATE = 1e-4
DROP_PACKET_RATE = 0.02
#: The board keeps all its telemetry for the relay (no bound on what waits): the relay's
#: damage is then the only loss, however a loaded machine stalls the relay.
KEEP_ALL = ("--backlog-bytes", 0)


def heliquad(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout)


class DamagingRelay:
    """A link between the board's pty and a new pty the sweep opens (its ``port``): what the
    host sends reaches the board untouched; what the board sends is damaged on the way.
    ``corrupt``: each byte replaced by another with this probability; ``drop``: each whole
    packet left out with this probability. Both from a generator seeded with ``seed``, drawn
    per byte or per packet, so the damage depends only on the stream."""

    def __init__(self, board_port, corrupt=0.0, drop=0.0, seed=1):
        import serial

        from heliquad.sim.base.dialect import dialect
        from heliquad.sim.base.framing import Codec, Framer

        self.board = serial.Serial(str(board_port), timeout=0)
        self.main, self.side = os.openpty()
        tty.setraw(self.side)
        self.port = os.ttyname(self.side)
        self.corrupt, self.drop = corrupt, drop
        self.rng = np.random.default_rng(seed)
        self.framer = Framer(Codec(dialect()))
        self.corrupted = self.dropped = self.packets = 0
        self.host_gone = False
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _damage(self, data: bytes) -> bytes:
        if self.drop:
            kept = []
            for _, packet, _ in self.framer.feed(data):
                self.packets += 1
                if self.rng.random() < self.drop:
                    self.dropped += 1
                else:
                    kept.append(packet)
            return b"".join(kept)
        hit = self.rng.random(len(data)) < self.corrupt
        if hit.any():
            buf = np.frombuffer(data, dtype=np.uint8).copy()
            buf[hit] ^= self.rng.integers(1, 256, int(hit.sum()), dtype=np.uint8)
            self.corrupted += int(hit.sum())
            data = buf.tobytes()
        return data

    def _run(self):
        import select

        while not self.stopping.is_set():
            ready, _, _ = select.select([self.board.fileno(), self.main], [], [], 0.05)
            if self.board.fileno() in ready:
                data = self._damage(self.board.read(65536))
                if data and not self.host_gone:
                    try:
                        os.write(self.main, data)
                    except BlockingIOError:         # nobody reads: as a radio, dropped
                        pass
            if self.main in ready:
                try:
                    self.board.write(os.read(self.main, 65536))
                except OSError:
                    self.host_gone = True

    def close(self):
        self.stopping.set()
        self.thread.join(timeout=10)
        self.board.close()
        os.close(self.main)
        os.close(self.side)


def sweep_through(board_port, out, **damage):
    """A roll sweep of FREQS_HZ through a relay with ``damage``; (result, relay)."""
    relay = DamagingRelay(board_port, **damage)
    os.set_blocking(relay.main, False)
    try:
        res = heliquad("sweep", "--axis", "roll", "--port", relay.port, "--freqs-hz",
                       *FREQS_HZ, "--cycles", CYCLES, "--out", out)
    finally:
        relay.close()
    return res, relay


def points(folder):
    """(freq_hz, complex gain, sigma, lost_share or 0) of points.csv."""
    from heliquad.host.records.points import known_column, read_points_csv

    p = read_points_csv(str(folder / "points.csv"))
    return tuple(known_column(p, name) for name in ("freq_hz", "gain", "sigma", "lost_share"))


def test_a_sweep_through_a_damaging_link_completes_and_agrees_with_a_clean_one(tmp_path):
    # Item 11's acceptance: the same roll sweep against `heliquad board` over a clean link,
    # one that corrupts 1e-4 of the bytes and one that drops 2 % of the packets. Both damaged
    # sweeps complete, their manifests count the samples lost (and the corrupting link's
    # garbage bytes), and their points are within 0.2 dB and 1 deg of the clean link's, the
    # difference within three of the two points' combined sigmas.
    with running_board(tmp_path, *KEEP_ALL) as board:
        runs = {name: sweep_through(board, tmp_path / name, **damage)
                for name, damage in (("clean", {}),
                                     ("corrupt", {"corrupt": CORRUPT_BYTE_RATE}),
                                     ("drop", {"drop": DROP_PACKET_RATE}))}
    for name, (res, relay) in runs.items():
        assert res.returncode == 0, f"{name}: {res.stdout}{res.stderr}"
        assert heliquad("identify", tmp_path / name, "--order", "0/2").returncode == 0, name
    assert runs["corrupt"][1].corrupted > 0 and runs["drop"][1].dropped > 0
    clean = points(tmp_path / "clean")
    for name in ("corrupt", "drop"):
        manifest = json.loads((tmp_path / name / "manifest.json").read_text())
        entries = [f for f in manifest["frequencies"] if f["status"] == "ok"]
        assert manifest["complete"] and len(entries) == len(FREQS_HZ)
        assert sum(f["lost"] for f in entries) > 0, name
        for f in entries:
            assert f["samples"] + f["lost"] == int(CYCLES) * f["period_samples"]
        if name == "corrupt":
            assert sum(f["garbage_bytes"] for f in entries) > 0
        f, g, sigma, lost = points(tmp_path / name)
        np.testing.assert_allclose(f, clean[0], rtol=1e-9)
        assert (lost > 0).any() and (lost < 0.05).all()
        ratio = g / clean[1]
        assert np.max(np.abs(20 * np.log10(np.abs(ratio)))) < 0.2, name
        assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 1.0, name
        assert np.all(np.abs(g - clean[1]) <= 3 * np.hypot(sigma, clean[2])), name


# --- The watch of one excitation, fed a lossy stream (no firmware: exact and quick) ---------

PERIOD, MEASURED, FADE = 100, 3, 1          # 2 Hz at 200 Hz, 3 measured cycles, 1 of fade


def stream(lose=(), status=True):
    """What a board sends for one excitation of PERIOD x MEASURED full-amplitude samples
    (after 5 idle samples and a cycle of fade in; a cycle of fade out, one idle sample
    after), the samples whose index within the full-amplitude window is in ``lose`` left
    out, and the start's answer (``status``) sent or lost."""
    import math

    from heliquad.sim.base.dialect import dialect
    from heliquad.sim.base.framing import Message

    mav = dialect()
    out = []
    if status:
        out.append(Message("HQ_EXCITATION_STATUS", dict(
            accepted=1, state=mav.HQ_EXCITATION_STATE_FADING, reason=mav.HQ_REASON_NONE,
            freq_hz=200.0 / PERIOD, period_samples=PERIOD, fade_samples=FADE * PERIOD)))
    states = ([mav.HQ_EXCITATION_STATE_IDLE] * 5 + [mav.HQ_EXCITATION_STATE_FADING] * FADE * PERIOD
              + [mav.HQ_EXCITATION_STATE_RUNNING] * MEASURED * PERIOD
              + [mav.HQ_EXCITATION_STATE_FADING] * FADE * PERIOD + [mav.HQ_EXCITATION_STATE_IDLE])
    first_running = 5 + FADE * PERIOD
    for seq, state in enumerate(states):
        if seq - first_running in lose:
            continue
        r = 0.1 * math.sin(2 * math.pi * seq / PERIOD)
        out.append(Message("HQ_SYSID_SAMPLE", dict(
            seq=seq, time_us=5000 * seq, exc_state=state, excitation=r, axis_cmd=r,
            rate=0.5 * r, angle=0.0, saturation=0, armed=1)))
    return out


def watch(messages):
    from heliquad.host.acquire.measure import ExcitationWatch, Limits
    from heliquad.host.acquire.sweep import SweepPlan

    plan = SweepPlan("roll", "mixer", [2.0], [0.1], cycles=MEASURED, fade_cycles=FADE)
    w = ExcitationWatch(plan, 2.0, 0.1, Limits(), 0, progress=lambda *_: None)
    for m in messages:
        w(m)
    assert w.done
    return w


def test_lost_samples_in_and_at_the_edges_of_the_window_are_counted_not_fatal():
    # Before: "incomplete: 293 of 300 measured samples were logged". The window's first and
    # last samples are among those lost: the gaps around it account for them.
    lose = {0, 1, 57, 58, 59, 200, 299}
    w = watch(stream(lose))
    e = w.entry
    assert e["status"] == "ok" and e["samples"] == 300 - len(lose) and e["lost"] == len(lose)
    assert e["lost_run"] == 3
    r, u, y, present = w.columns()
    assert present.size == 297 and np.count_nonzero(~present) == 4    # holes inside


def test_a_lost_answer_to_the_start_leaves_the_period_known():
    # Before: "incomplete: 300 of 0 measured samples were logged". The period is the
    # firmware's own rule applied to the request and the samples' loop period.
    e = watch(stream(status=False)).entry
    assert e["status"] == "ok" and e["period_samples"] == PERIOD and e["period_inferred"]
    assert e["freq_hz"] == pytest.approx(2.0)


@pytest.mark.parametrize("lose, says", [
    (set(range(0, 300, 15)), r"^lost 20 of 300 measured samples on the link \(6.7 %, more "
                             r"than 5 %\)$"),
    (set(range(100, 151)), r"^lost 51 samples in a row on the link \(more than 50\): the link "
                           r"is dropping out$")])
def test_a_window_that_lost_too_much_ends_the_sweep_saying_so(lose, says):
    import re

    e = watch(stream(lose)).entry
    assert re.match(says, e["status"]), e["status"]


def test_a_window_cut_short_without_gaps_is_still_incomplete():
    # The excitation stopped early and its status was lost: no sequence gap accounts for the
    # missing samples, so it is not passed as complete.
    from heliquad.sim.base.dialect import dialect

    idle = dialect().HQ_EXCITATION_STATE_IDLE
    messages = stream()
    cut = next(i for i, m in enumerate(messages) if getattr(m, "seq", -1) == 5 + PERIOD + 150)
    for m in messages[cut:]:
        m.exc_state = idle
    e = watch(messages).entry
    assert e["status"] == "incomplete: 150 of 300 measured samples were logged"


# --- Messages: a board unplugged, a sweep that was cut --------------------------------------

def test_a_board_unplugged_mid_sweep_exits_1_as_a_silent_one_does(tmp_path):
    # The relay closes the sweep's pty once the sweep's log says the excitation runs:
    # the port reads EIO. Before: exit 2, "error: telemetry link lost". Now exit 1, the
    # frequency's status says the board went away, the manifest and log are kept.
    import time

    with running_board(tmp_path, *KEEP_ALL) as board:
        relay = DamagingRelay(board)
        os.set_blocking(relay.main, False)
        out = tmp_path / "sweep"
        sweep = subprocess.Popen([sys.executable, "-m", "heliquad.host.cli.parser", "sweep", "--axis",
                                  "roll", "--port", relay.port, "--freqs-hz", "0.5", "--cycles",
                                  "10", "--out", str(out)],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            tlog, deadline = out / "sweep.tlog", time.monotonic() + 120   # a hang guard
            while not excitation_running(tlog) and time.monotonic() < deadline and \
                    sweep.poll() is None:
                time.sleep(0.05)
            relay.close()                                     # unplugged
            stdout, stderr = sweep.communicate(timeout=120)
        finally:
            if sweep.poll() is None:
                sweep.kill()
                sweep.communicate()
    assert sweep.returncode == 1, stdout + stderr
    assert "the board went away: telemetry link lost" in stderr and "error:" not in stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert not manifest["complete"] and manifest["aborted"].startswith("the board went away")


def test_identify_and_the_report_say_a_sweep_was_cut(tmp_path):
    # Three frequencies measured, the fourth refused (a board flashed with tighter limits would):
    # identify's first line says the sweep was cut and how much of it was measured, and so
    # does the report.
    from heliquad.host.acquire.session import SilSession
    from heliquad.host.acquire.sweep import SweepPlan, run_sweep
    from heliquad.sim.rig.setup import SilConfig

    out = tmp_path / "cut"
    out.mkdir()
    plan = SweepPlan("roll", "mixer", [1.0, 2.0, 3.0, 4.0], [0.05, 0.05, 0.05, 3.0], cycles=3)
    with SilSession(SilConfig(axis="roll", plant="tf", rig="roll"),
                    str(out / "sweep.tlog")) as session:
        manifest = run_sweep(session, plan, str(out), {"kind": "sil"}, progress=lambda *_: None)
    assert not manifest["complete"]
    res = heliquad("identify", out, "--order", "0/1")
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[0].startswith(
        "warning: the sweep was cut: refused by the firmware: amplitude") and \
        "(3 of 4 frequencies measured)" in res.stdout.splitlines()[0]
    assert heliquad("report", out).returncode == 0
    assert "The sweep was cut: refused by the firmware" in (out / "report.html").read_text()
