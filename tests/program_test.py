"""The on-board identification program (firmware/core/program.hpp, ``heliquad program``, the
rules in docs/safety.md): set, read back and cleared over HQ_PROGRAM while disarmed, whole or
not at all, kept in its own store across a restart, and run by the pilot's channel 7 with no
host heartbeat at all, on the host build and on the Teensy image in the emulated chip."""

import contextlib

import numpy as np
import pytest

from firmware_rig import MAV, FirmwareRig
from heliquad.host.acquire.link import reason_text
from heliquad.host.acquire.program import ProgramClient, ProgramStep
from heliquad.host.acquire.session import SilSession
from heliquad.host.records.tlog import read_tlog
from heliquad.sim.base.errors import BoardRefused
from heliquad.sim.base.dialect import dialect
from heliquad.sim.rig.faults import parse_fault
from heliquad.sim.rig.lockstep import HostFirmware, PilFirmware
from heliquad.sim.rig.rc_script import parse_rc_script
from heliquad.sim.rig.setup import LOOP_RATE_HZ, SilConfig

#: A short dwell: three frequencies, four measured cycles each, one cycle of fade.
STEPS = [ProgramStep("roll", "mixer", f, 0.1, 4, 1) for f in (2.0, 4.0, 8.0)]


class _RigLink:
    """A FirmwareRig's telemetry link as ProgramClient's link: the firmware steps while the
    client waits, and no heartbeat goes out (the program needs none)."""

    def __init__(self, rig):
        self.rig, self.name, self.can_send = rig, "the host build", True
        self.mav_module = rig.tel.mav_module
        self.seen = 0

    def heartbeat(self):
        pass

    def poll(self, only=()):
        self.rig.step(2)
        self.rig.settle_telemetry()
        new, self.seen = self.rig.messages[self.seen:], len(self.rig.messages)
        return [m for m in new if m.get_type() in only]

    def __getattr__(self, name):              # program_step, program_request
        return getattr(self.rig.tel, name)


def _client(rig):
    return ProgramClient(_RigLink(rig), answer_wait_s=0.5)


def _program_texts(rig):
    return [m.text for _, m in rig.of_type("STATUSTEXT")]


@contextlib.contextmanager
def _board(store, firmware=HostFirmware):
    """The host build (or ``firmware``: PilFirmware for the Teensy image) keeping its
    parameters in ``store`` (its program beside them), on the rig: the rig and a
    ProgramClient on its link."""
    with firmware(params_file=str(store)) as fw:
        rig = FirmwareRig(fw)
        try:
            yield rig, _client(rig)
        finally:
            rig.close()


def test_set_show_and_clear_round_trip(tmp_path):
    with _board(tmp_path / "params") as (rig, client):
        assert client.show() == []
        client.set(STEPS)
        shown = client.show()
        assert [s.freq_hz for s in shown] == [2.0, 4.0, 8.0]
        assert all(np.float32(s.amplitude) == np.float32(0.1) and s.cycles == 4
                   and s.fade_cycles == 1 and s.axis == "roll" and s.inject == "mixer"
                   for s in shown)
        assert "program: saved" in _program_texts(rig)
        client.clear()
        assert client.show() == []
    assert (tmp_path / "params.program").exists()


def test_a_multisine_step_keeps_its_harmonics(tmp_path):
    with _board(tmp_path / "params") as (rig, client):
        harmonics = ((1, 0.04, 0.0), (3, 0.03, 1.0), (7, 0.02, -2.0))
        client.set([ProgramStep("pitch", "rate", 0.5, 0.09, 3, 1, harmonics)])
        (got,) = client.show()
        assert (got.axis, got.inject, got.cycles) == ("pitch", "rate", 3)
        assert [h[0] for h in got.harmonics] == [1, 3, 7]
        assert np.allclose([h[1:] for h in got.harmonics], [h[1:] for h in harmonics])


def test_a_step_out_of_bounds_is_refused_with_its_reason_and_the_old_program_kept(tmp_path):
    with _board(tmp_path / "params") as (rig, client):
        client.set(STEPS)
        bad = STEPS[:1] + [ProgramStep("roll", "mixer", 4.0, 1.5, 4, 1)]    # above 1.0
        with pytest.raises(BoardRefused) as refused:
            client.set(bad)
        assert "step 2 of 2" in str(refused.value)
        assert reason_text(MAV.HQ_REASON_AMPLITUDE) in str(refused.value)
        assert "excitation refused: amplitude out of bounds" in _program_texts(rig)
        too_fast = [ProgramStep("roll", "mixer", 80.0, 0.1, 4, 1)]         # past 50 Hz
        with pytest.raises(BoardRefused, match="outside the allowed band"):
            client.set(too_fast)
        assert [s.freq_hz for s in client.show()] == [2.0, 4.0, 8.0]


def test_set_and_clear_are_refused_while_armed(tmp_path):
    with _board(tmp_path / "params") as (rig, client):
        client.set(STEPS)
        rig.hover()
        for act in (lambda: client.set(STEPS[:1]), client.clear):
            with pytest.raises(BoardRefused, match="armed"):
                act()
        assert "refused: armed (disarm first)" in _program_texts(rig)
        assert len(client.show()) == 3


def _set_program(store, steps, firmware=HostFirmware):
    with _board(store, firmware) as (_, client):
        client.set(steps)


def _fly(tmp_path, store, script, seconds, firmware="host"):
    """A SilSession with the pilot's ``script``, the host's link closed before its first
    heartbeat (so no host is ever heard): every message of the run's telemetry, as its log
    (the rig's tap) has it."""
    cfg = SilConfig(rc_script=parse_rc_script(script), param_store=store, firmware=firmware,
                    faults=(parse_fault("link@0.05"),))
    tlog = str(tmp_path / "run.tlog")
    session = SilSession(cfg, tlog)
    try:
        while session.frame < seconds * LOOP_RATE_HZ:
            session.advance()
    finally:
        session.close()
    return [m for _, m in read_tlog(tlog, dialect())]


def _step_windows(messages):
    """Each program step's excitation samples (HQ_SYSID_SAMPLE.excitation while it runs),
    split at the program's HQ_PROGRAM_STATUS reports."""
    windows, current = [], None
    for m in messages:
        if m.get_type() == "HQ_PROGRAM_STATUS":
            current = [] if m.state == MAV.HQ_PROGRAM_STATE_RUNNING else None
            if current is not None:
                windows.append(current)
        elif m.get_type() == "HQ_SYSID_SAMPLE" and current is not None and m.exc_state:
            current.append(m.excitation)
    return windows


def _frequency_hz(samples):
    """The excitation's frequency from its zero crossings (a sine: two a cycle)."""
    x = np.asarray(samples)
    crossings = np.count_nonzero(np.signbit(x[1:]) != np.signbit(x[:-1]))
    return crossings / 2 / (len(x) / LOOP_RATE_HZ)


@pytest.mark.parametrize("firmware", ["host", "teensy35"])
def test_channel_7_runs_the_stored_program_after_a_restart_with_no_host(tmp_path, firmware):
    """The program set in one run of the firmware is loaded by the next (its store: the host
    build's file, the Teensy image's flash sectors kept in theirs); there, with the host's
    link closed before any heartbeat, the pilot arms, raises the throttle and moves channel 7
    (on the Teensy its capture pin) low then high: the three steps run one after another,
    each at its frequency, and the program says it finished."""
    store = str(tmp_path / "params")
    _set_program(store, STEPS, HostFirmware if firmware == "host" else PilFirmware)
    script = "0.2 5=2000 7=1000\n0.4 3=1400\n0.8 7=2000\n"
    messages = _fly(tmp_path, store, script, 6.5, firmware)
    assert not any(m.get_type() == "HEARTBEAT" and m.type == MAV.MAV_TYPE_GCS for m in messages)
    ends = [m for m in messages if m.get_type() == "HQ_EXCITATION_STATUS"]
    assert [m.reason for m in ends] == [MAV.HQ_REASON_FINISHED] * 3
    assert [round(m.freq_hz, 3) for m in ends] == [2.0, 4.0, 8.0]
    windows = _step_windows(messages)
    assert len(windows) == 3
    for samples, f in zip(windows, (2.0, 4.0, 8.0)):
        assert abs(_frequency_hz(samples) - f) < 0.15 * f
    texts = [m.text for m in messages if m.get_type() == "STATUSTEXT"]
    assert "program started by channel 7" in texts
    assert "program finished: every step ran" in texts
    last = [m for m in messages if m.get_type() == "HQ_PROGRAM_STATUS"][-1]
    assert (last.state, last.reason, last.accepted) == (MAV.HQ_PROGRAM_STATE_STORED,
                                                        MAV.HQ_REASON_NONE, 1)


def test_releasing_channel_7_stops_the_program_with_its_reason(tmp_path):
    store = str(tmp_path / "params")
    _set_program(store, STEPS)
    script = "0.2 5=2000 7=1000\n0.4 3=1400\n0.8 7=2000\n2.0 7=1000\n"
    messages = _fly(tmp_path, store, script, 3.0)
    ends = [m for m in messages if m.get_type() == "HQ_EXCITATION_STATUS"]
    assert [m.reason for m in ends][-1] == MAV.HQ_REASON_PROGRAM_SWITCH
    assert "program stopped: channel 7 released" in [m.text for m in messages
                                                      if m.get_type() == "STATUSTEXT"]
    last = [m for m in messages if m.get_type() == "HQ_PROGRAM_STATUS"][-1]
    assert (last.state, last.reason) == (MAV.HQ_PROGRAM_STATE_STORED,
                                         MAV.HQ_REASON_PROGRAM_SWITCH)
    # nothing excites the vehicle after the release's loop
    after = [m for m in messages if m.get_type() == "HQ_SYSID_SAMPLE" and m.time_us > 2_010_000]
    assert after and not any(m.exc_state for m in after)


def test_a_switch_found_high_does_not_start_the_program(tmp_path):
    store = str(tmp_path / "params")
    _set_program(store, STEPS)
    script = "0.0 7=2000\n0.2 5=2000\n0.4 3=1400\n"
    messages = _fly(tmp_path, store, script, 1.5)
    assert not any(m.get_type() == "HQ_SYSID_SAMPLE" and m.exc_state for m in messages)
    assert any(m.get_type() == "HQ_SYSID_SAMPLE" and m.armed for m in messages)


def test_a_damaged_store_is_no_program_and_is_said_at_boot(tmp_path):
    store = tmp_path / "params"
    _set_program(str(store), STEPS)
    program = tmp_path / "params.program"
    data = bytearray(program.read_bytes())
    data[10] ^= 0xFF
    program.write_bytes(bytes(data))
    with _board(store) as (rig, client):
        rig.step(5)
        assert "program: stored record damaged; none loaded" in _program_texts(rig)
        assert client.show() == []


def _flip_channel_7(rig):
    """Channel 7 low, then high; the HQ_PROGRAM_STATUS that answers the move."""
    rig.rc[6] = 1000
    rig.step(5)
    rig.rc[6] = 2000
    return rig.until(lambda m: m.get_type() == "HQ_PROGRAM_STATUS")[1]


def test_a_hosts_start_is_refused_while_the_program_runs_and_a_stop_ends_it(tmp_path):
    with _board(tmp_path / "params") as (rig, client):
        client.set(STEPS)
        rig.hover()
        assert _flip_channel_7(rig).state == MAV.HQ_PROGRAM_STATE_RUNNING
        _, answer = rig.excitation_answer()
        assert (answer.accepted, answer.reason) == (0, MAV.HQ_REASON_PROGRAM_RUNNING)
        assert "refused: the on-board program runs" in _program_texts(rig)
        rig.tel.stop_excitation()
        _, ended = rig.until(lambda m: m.get_type() == "HQ_PROGRAM_STATUS")
        assert (ended.state, ended.reason) == (MAV.HQ_PROGRAM_STATE_STORED,
                                               MAV.HQ_REASON_STOP_COMMAND)
        since = rig.last_loop_us()
        rig.step(20)
        assert not any(m.exc_state for _, m in rig.of_type("HQ_SYSID_SAMPLE", since + 1))


def test_a_program_too_large_for_its_record_is_refused_and_the_old_one_kept(tmp_path):
    """Three multisines of 16 lines need 537 bytes: the third is refused (PROGRAM_ORDER),
    and the board keeps the program it had."""
    lines = tuple((h, 0.01, 0.0) for h in range(1, 17))
    big = [ProgramStep("roll", "mixer", 0.5, 0.2, 2, 1, lines)] * 3
    with _board(tmp_path / "params") as (rig, client):
        client.set(STEPS)
        with pytest.raises(BoardRefused, match="step 3 of 3") as refused:
            client.set(big)
        assert reason_text(MAV.HQ_REASON_PROGRAM_ORDER) in str(refused.value)
        assert [s.freq_hz for s in client.show()] == [2.0, 4.0, 8.0]


def test_channel_7_with_no_program_or_while_disarmed_is_refused_and_said(tmp_path):
    with _board(tmp_path / "params") as (rig, client):
        rig.step(10)
        disarmed = _flip_channel_7(rig)
        assert (disarmed.reason, disarmed.state) == (MAV.HQ_REASON_DISARMED,
                                                     MAV.HQ_PROGRAM_STATE_NONE)
        rig.hover()
        none = _flip_channel_7(rig)
        assert (none.reason, none.accepted) == (MAV.HQ_REASON_NO_PROGRAM, 0)
        assert "program refused: none stored" in _program_texts(rig)
        assert "excitation refused: disarmed" in _program_texts(rig)
