"""The on-board DataFlash log (firmware/core/log/): a flight of the host build's loop run
in-process (heliquad._firmware.LoggedFirmware), its log drained into a RAM card, read back by
pymavlink's DFReader and mavlogdump.py and held against the same run's telemetry."""

import math
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest
from pymavlink import DFReader

from heliquad import _firmware, _mavlink, _simcore

LOOP_HZ = 200
STEP_US = 1_000_000 // LOOP_HZ
GRAVITY = 9.80665
LOW, MID, HIGH = 1000, 1500, 2000
# RC channels: roll, pitch, throttle, yaw, arm switch, mode switch, 7, 8 (docs/link-contract.md).
DISARMED_RC = [MID, MID, LOW, MID, LOW, LOW, 0, 0]
ARMED_RC = [MID, MID, LOW, MID, HIGH, LOW, 0, 0]
RATE_MODE_RC = [MID, MID, LOW, MID, HIGH, HIGH, 0, 0]
# ArduPilot's LogEvent ids (EV.Id).
EV_ARMED, EV_DISARMED = 10, 11
GAIN = "RATE_RLL_KC"


class Flight:
    """The loop stepped frame by frame, the telemetry it sent read after each step."""

    def __init__(self, service=True):
        self.fw = _firmware.LoggedFirmware(LOOP_HZ)
        self.gcs = _mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.reader = _mavlink.MAVLink(None)
        self.frame = 0
        self.service = service
        self.samples = []        # HQ_SYSID_SAMPLE, in order
        self.texts = []          # (loop time, STATUSTEXT text)

    def send(self, msg):
        self.fw.telemetry_in(msg.pack(self.gcs))

    def step(self, rc, gyro=(0.0, 0.0, 0.0)):
        self.frame += 1
        fifo = _simcore.raw_packet(gyro, (0.0, 0.0, -GRAVITY))
        if self.frame % 20 == 1:
            self.send(_mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))   # a GCS, 10 Hz
        frame = _mavlink.MAVLink_hq_sensor_frame_message(
            self.frame * STEP_US, self.frame, _mavlink.HQ_SENSOR_RAW, len(fifo), 1, rc,
            list(fifo) + [0] * (168 - len(fifo)), 0)
        self.fw.sim(frame.pack(self.gcs))
        for msg in self.reader.parse_buffer(self.fw.telemetry_out()) or []:
            if msg.get_type() == "HQ_SYSID_SAMPLE":
                self.samples.append(msg)
            elif msg.get_type() == "STATUSTEXT":
                self.texts.append((self.frame * STEP_US, msg.text))
        if self.service:
            self.fw.service()

    def steps(self, n, rc, gyro=(0.0, 0.0, 0.0)):
        for _ in range(n):
            self.step(rc, gyro)


def set_param(flight, name, value):
    flight.send(_mavlink.MAVLink_param_set_message(1, 1, name.encode(), value,
                                                   _mavlink.MAV_PARAM_TYPE_REAL32))


def start_excitation(flight):
    flight.send(_mavlink.MAVLink_hq_excitation_message(
        1, 1, _mavlink.HQ_EXCITATION_START, _mavlink.HQ_AXIS_ROLL, _mavlink.HQ_INJECTION_MIXER,
        5.0, 0.02, 4, 1, 0, [0] * 16, [0.0] * 16, [0.0] * 16))


def fly(flight):
    """Disarmed, armed, an excitation, a gain change, rate mode, disarmed."""
    flight.steps(40, DISARMED_RC)
    flight.steps(20, ARMED_RC, gyro=(0.01, 0.0, 0.0))
    assert flight.fw.armed
    start_excitation(flight)
    flight.steps(LOOP_HZ // 2, ARMED_RC, gyro=(0.02, -0.01, 0.005))    # 1.2 s of excitation
    set_param(flight, GAIN, 0.5)             # refused while exciting: the link says why
    flight.steps(LOOP_HZ + LOOP_HZ // 2, ARMED_RC, gyro=(0.02, -0.01, 0.005))
    set_param(flight, GAIN, 0.25)
    flight.steps(10, ARMED_RC)
    flight.steps(10, RATE_MODE_RC)
    flight.steps(10, DISARMED_RC)
    assert not flight.fw.armed
    flight.steps(5, DISARMED_RC)


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    flight = Flight()
    fly(flight)
    logs = flight.fw.logs
    assert len(logs) == 1 and not flight.fw.log_open
    path = tmp_path_factory.mktemp("dataflash") / "00000001.BIN"
    path.write_bytes(logs[0])
    return flight, path


def records(path):
    log = DFReader.DFReader_binary(str(path), zero_time_base=True)
    out = []
    while (m := log.recv_msg()) is not None:
        out.append(m)
    return log, out


def of(msgs, kind):
    return [m for m in msgs if m.get_type() == kind]


def test_mavlogdump_lists_every_message_type(flown):
    _, path = flown
    script = Path(sysconfig.get_path("scripts")) / "mavlogdump.py"
    out = subprocess.run([sys.executable, str(script), "--show-types", str(path)],
                         capture_output=True, text=True, check=True).stdout
    assert set(out.split()) >= {"FMT", "UNIT", "MULT", "FMTU", "PARM", "MSG", "MODE", "EV",
                                "SIDD", "SIDS", "HQSD", "HQMT"}


def test_units_and_multipliers(flown):
    _, path = flown
    log, msgs = records(path)
    sidd = log.formats[log.name_to_id["SIDD"]]
    assert sidd.columns == ["TimeUS", "Time", "Targ", "F", "Gx", "Gy", "Gz", "Ax", "Ay", "Az"]
    assert [sidd.get_unit(c) for c in sidd.columns] == [
        "µs", "s", "", "Hz", "deg/s", "deg/s", "deg/s", "m/s/s", "m/s/s", "m/s/s"]
    hqsd = log.formats[log.name_to_id["HQSD"]]
    assert hqsd.get_unit("ASP") == "rad" and hqsd.get_unit("Rate") == "rad/s"
    # TimeUS times its multiplier is the loop's time in s: DFReader's clock agrees.
    first = of(msgs, "HQSD")[0]
    assert first.TimeUS % STEP_US == 0
    mults = {chr(m.Id): m.Mult for m in of(msgs, "MULT")}
    assert mults["F"] == pytest.approx(1e-6)


def test_header_version_and_every_parameter(flown):
    _, path = flown
    _, msgs = records(path)
    assert msgs[0].get_type() == "FMT"
    assert of(msgs, "MSG")[0].Message.startswith("heliquad ")
    names = [row.name for row in _firmware.param_table()]
    start = [m for m in of(msgs, "PARM") if m.Name in names]
    assert [m.Name for m in start[:len(names)]] == names
    defaults = {row.name: row.default for row in _firmware.param_table()}
    assert all(m.Value == pytest.approx(defaults[m.Name]) for m in start[:len(names)])


def test_parameter_change_logged(flown):
    _, path = flown
    _, msgs = records(path)
    changed = [m for m in of(msgs, "PARM") if m.Name == GAIN][1:]
    assert len(changed) == 1 and changed[0].Value == pytest.approx(0.25)
    assert changed[0].TimeUS > of(msgs, "SIDS")[0].TimeUS


def test_events_mode_and_experiment(flown):
    flight, path = flown
    _, msgs = records(path)
    assert [m.Id for m in of(msgs, "EV")] == [EV_ARMED, EV_DISARMED]
    assert [m.ModeNum for m in of(msgs, "MODE")] == [_mavlink.HQ_MODE_ANGLE, _mavlink.HQ_MODE_RATE]
    (sids,) = of(msgs, "SIDS")
    assert sids.Ax == 10                     # ArduPilot's SID_AXIS 10: mixer roll
    assert sids.Mag == pytest.approx(0.02) and sids.FSt == sids.FSp == pytest.approx(5.0)
    assert sids.TR == pytest.approx(sids.TFin + sids.TC + sids.TFout)


def test_samples_equal_the_telemetry(flown):
    flight, path = flown
    _, msgs = records(path)
    armed = [s for s in flight.samples if s.armed]
    hqsd, hqmt, sidd = of(msgs, "HQSD"), of(msgs, "HQMT"), of(msgs, "SIDD")
    assert len(armed) == len(hqsd) == len(hqmt) == len(sidd) > LOOP_HZ
    assert any(s.excitation != 0.0 for s in armed)
    for s, h, m, d in zip(armed, hqsd, hqmt, sidd):
        assert h.TimeUS == m.TimeUS == d.TimeUS == s.time_us
        assert (h.Seq, h.Axis, h.Inj, h.ESt, h.Arm, h.Mode, h.Sat) == (
            s.seq, s.axis, s.injection, s.exc_state, s.armed, s.mode, s.saturation)
        assert (h.Exc, h.ASP, h.RSP, h.Rate, h.Ang, h.Cmd) == (
            s.excitation, s.angle_sp, s.rate_sp, s.rate, s.angle, s.axis_cmd)
        assert [getattr(m, f"M{i}") for i in range(1, 6)] == list(s.motor[:5])
        assert s.motor_count == 5 and not any(s.motor[5:])      # five rotors: no HQMX
        assert d.Targ == s.excitation
        assert d.Gx == pytest.approx(math.degrees(s.rate), rel=1e-6, abs=1e-9)
        assert d.Az == pytest.approx(-GRAVITY, rel=1e-3)


def test_statustext_logged_as_msg(flown):
    flight, path = flown
    _, msgs = records(path)
    start, end = of(msgs, "EV")[0].TimeUS, of(msgs, "EV")[-1].TimeUS
    said = [(t, text) for t, text in flight.texts if start <= t <= end]
    assert any("disarmed" in text for _, text in said)            # the loop's notice
    assert any("not while exciting" in text for _, text in said)  # the link's own
    assert [(m.TimeUS, m.Message) for m in of(msgs, "MSG")[1:]] == said


def test_full_ring_drops_whole_records_and_writes_a_gap(tmp_path):
    flight = Flight(service=False)         # a card that takes nothing for a while
    flight.steps(40, DISARMED_RC)
    flight.steps(LOOP_HZ // 2, ARMED_RC)
    dropped = flight.fw.log_counters.dropped
    assert dropped > 0
    assert flight.fw.log_queued_bytes <= _firmware.LOG_RING_BYTES
    flight.fw.service()                    # the card is back: the ring empties
    flight.service = True
    flight.steps(10, ARMED_RC)
    flight.steps(3, DISARMED_RC)
    path = tmp_path / "00000001.BIN"
    path.write_bytes(flight.fw.logs[0])
    _, msgs = records(path)
    (gap,) = of(msgs, "HQGP")
    assert gap.Dropped == dropped
    assert gap.SinceUS < gap.TimeUS
    # Whole records only: every byte parsed, the samples in threes, none torn.
    assert path.stat().st_size == sum(len(m.get_msgbuf()) for m in msgs)
    hqsd, hqmt, sidd = of(msgs, "HQSD"), of(msgs, "HQMT"), of(msgs, "SIDD")
    assert [m.TimeUS for m in hqsd] == [m.TimeUS for m in hqmt] == [m.TimeUS for m in sidd]
    times = [m.TimeUS for m in hqsd]
    assert max(b - a for a, b in zip(times, times[1:])) > STEP_US      # the gap is there


def test_no_card_flies_and_logs_nothing():
    flight = Flight()
    flight.fw.card_present = False
    flight.steps(40, DISARMED_RC)
    flight.steps(30, ARMED_RC)
    assert flight.fw.armed and flight.fw.logs == []
    assert flight.fw.log_queued_bytes == 0


def test_a_full_card_cuts_the_log_and_the_vehicle_flies_on(tmp_path):
    flight = Flight()
    flight.fw.card_room = 9000               # the header (a PARM per parameter) and a few loops
    flight.steps(40, DISARMED_RC)
    flight.steps(LOOP_HZ, ARMED_RC)
    assert flight.fw.armed and flight.fw.card_room == 0
    (log,) = flight.fw.logs
    assert len(log) == 9000
    assert flight.fw.log_queued_bytes < 200  # the ring still empties: nothing piles up
    assert flight.fw.log_counters.dropped == 0
    flight.steps(5, DISARMED_RC)
    assert not flight.fw.log_open
    path = tmp_path / "00000001.BIN"
    path.write_bytes(log)
    _, msgs = records(path)                  # what was written reads back
    assert of(msgs, "EV")[0].Id == EV_ARMED and of(msgs, "HQSD")


def test_one_log_per_arming_and_a_quick_rearm_continues_the_log(tmp_path):
    flight = Flight()
    flight.steps(40, DISARMED_RC)
    for _ in range(2):                       # two flights, the card served between them
        flight.steps(10, ARMED_RC)
        flight.steps(5, DISARMED_RC)
    assert len(flight.fw.logs) == 2 and not flight.fw.log_open
    flight.service = False                   # disarmed and armed again before the log ended
    for rc in (ARMED_RC, DISARMED_RC, ARMED_RC, DISARMED_RC):
        flight.steps(5, rc)
    flight.fw.service()
    assert len(flight.fw.logs) == 3 and not flight.fw.log_open
    assert flight.fw.log_counters.dropped == 0
    evs = []
    for k, log in enumerate(flight.fw.logs):
        path = tmp_path / f"{k + 1:08d}.BIN"
        path.write_bytes(log)
        evs.append([m.Id for m in of(records(path)[1], "EV")])
    assert evs == [[EV_ARMED, EV_DISARMED]] * 2 + [[EV_ARMED, EV_DISARMED] * 2]
