"""The firmware as ground stations speak to it, with pymavlink's own ``mavutil`` as the
client: the parameter protocol (fetch, set, read back, fly with it, persisted across a
restart, a corrupt store, refusals), the standard messages and commands, broadcast targets,
and the modes' names.

The firmware is stepped frame by frame (lockstep), and the client reads the telemetry pty
between frames, so everything checked is firmware time; a wall-clock bound only stops a hang.
"""

from __future__ import annotations

import math
import os
import struct
import sys
import zlib

import numpy as np
import pytest
from pymavlink import mavutil

from firmware_rig import ARM_HIGH, DT_US, RC_REST, ROLL, THROTTLE_HOVER
from firmwares import FIRMWARES, start
from heliquad import _firmware
from heliquad.host.acquire.param_protocol import decode_value, encode_value
from heliquad.sim.base.dialect import dialect
from heliquad.sim.plant.tf_plant import TfPlant
from heliquad.sim.rig.lockstep import SimLink

MAV = dialect()
# mavutil loads a dialect by module name, MAVLink 2 only with MAVLINK20 set (as MAVProxy
# sets it): the project's generated module, under its own name.
os.environ["MAVLINK20"] = "1"
import pymavlink.dialects.v20 as _v20  # noqa: E402

sys.modules.setdefault("pymavlink.dialects.v20.heliquad", MAV)
_v20.heliquad = MAV
PARAMS = [(p.name, p.minimum, p.maximum, p.default, p.integer) for p in _firmware.param_table()]
NAMES = [p[0] for p in PARAMS]
#: The table's size: every other count here is read from it.
COUNT = len(PARAMS)
REAL32, INT32 = MAV.MAV_PARAM_TYPE_REAL32, MAV.MAV_PARAM_TYPE_INT32


class Client:
    """The firmware on a roll tf plant, stepped in lockstep, with a mavutil client on its
    telemetry port."""

    def __init__(self, fw):
        self.fw = fw
        self.link = SimLink(fw)
        self.plant = TfPlant("roll", *ROLL, DT_US * 1e-6)
        self.rc = list(RC_REST)
        self.frame, self.kind = 0, MAV.HQ_SENSOR_NONE
        self.conn = mavutil.mavlink_connection(fw.telemetry_path, dialect="heliquad",
                                               source_system=255, source_component=190)
        self.mav = self.conn.mav
        self.seen = []
        self.cursor = 0           # until() looks at messages from here on

    def close(self):
        self.conn.close()
        self.link.close()

    def step(self, n=1):
        for _ in range(n):
            self.frame += 1
            reply = self.link.step(self.frame * DT_US, self.plant.fifo(self.kind), self.kind, self.rc)
            self.kind = reply.sensor_kind
            self.plant.step_motors(reply.motor)
            self.read()

    def read(self):
        while True:
            m = self.conn.recv_match(blocking=False)
            if m is None:
                return
            if m.get_type() != "BAD_DATA":
                self.seen.append(m)

    def until(self, pred, frames=400):
        """The first message from the cursor on that satisfies pred, stepping until it
        arrives; the cursor moves past it."""
        for _ in range(frames + 1):
            for i in range(self.cursor, len(self.seen)):
                if pred(self.seen[i]):
                    self.cursor = i + 1
                    return self.seen[i]
            self.cursor = len(self.seen)
            self.step()
        raise AssertionError(f"not seen within {frames} frames")

    def sent(self):
        """Marks a request just sent: its answers are looked for from here on."""
        self.cursor = len(self.seen)

    def of_type(self, name):
        return [m for m in self.seen if m.get_type() == name]

    def text(self, fragment, frames=400):
        return self.until(lambda m: m.get_type() == "STATUSTEXT" and fragment in m.text, frames)

    def fetch(self):
        self.sent()
        self.mav.param_request_list_send(1, 1)
        values = {}
        self.until(lambda m: m.get_type() == "PARAM_VALUE"
                   and values.setdefault(m.param_id, m) and len(values) == m.param_count)
        return values

    def set(self, name, value):
        """PARAM_SET; the PARAM_VALUE that answers it."""
        self.sent()
        start = self.cursor
        self.mav.param_set_send(1, 1, name.encode(), float(value), MAV.MAV_PARAM_TYPE_REAL32)
        m = self.until(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name)
        during, self.cursor = self.seen[start:self.cursor], start   # its STATUSTEXT may follow
        return m, during

    def command(self, command, *params, target=(1, 1)):
        self.sent()
        start = self.cursor
        self.mav.command_long_send(*target, command, 0, *(list(params) + [0] * (7 - len(params))))
        ack = self.until(lambda m: m.get_type() == "COMMAND_ACK" and m.command == command)
        self.cursor = start                 # what the command sent may come before its ACK
        return ack

    def heartbeat(self):
        self.mav.heartbeat_send(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def hover(self):
        self.rc[4] = 1000
        self.step(10)
        self.rc[4] = ARM_HIGH
        self.step(10)
        self.rc[2] = THROTTLE_HOVER
        self.step(100)


@pytest.fixture
def client(tmp_path):
    with start("host", params_file=str(tmp_path / "params.bin")) as fw:
        c = Client(fw)
        yield c
        c.close()


# --- the table ----------------------------------------------------------------------------

def test_every_name_fits_the_protocol_and_every_default_lies_in_its_range():
    assert len(NAMES) == len(set(NAMES)) == COUNT == 118     # the table, pinned
    for name, lo, hi, default, integer in PARAMS:
        assert 0 < len(name) <= 16 and name == name.upper(), name
        assert lo <= default <= hi, name
        assert not integer or default == int(default), name


def test_the_defaults_are_the_flight_values():
    g = _firmware.CascadeGains.paper_defaults()
    table = {p[0]: p[3] for p in PARAMS}
    roll = g.rate(_firmware.Axis.ROLL)
    assert table["RATE_RLL_KC"] == pytest.approx(roll.kc, rel=1e-7)
    assert table["RATE_RLL_TI"] == pytest.approx(roll.tau_i_s, rel=1e-7)
    assert table["ANG_PIT_TD"] == pytest.approx(g.angle(_firmware.Axis.PITCH).tau_d_s, rel=1e-7)
    limits = _firmware.SafetyLimits()
    assert table["EXC_MAX_ANG"] == 45.0                    # reads back as the degrees it is
    assert table["FS_ABORT_ANG"] == pytest.approx(math.degrees(limits.abort_angle_rad), abs=1e-4)
    assert table["FS_HOST_TIMEOUT"] == limits.host_timeout_us * 1e-6
    assert table["ESC1_MIN"] == 1000 and table["ESC5_MAX"] == 2000


# --- the protocol, with mavutil -------------------------------------------------------------

@pytest.mark.parametrize("firmware", FIRMWARES)
def test_fetch_all_set_one_read_it_back_and_find_it_after_a_restart(tmp_path, firmware):
    """On the host build the store is a file; on the Teensy image (emulated) it is the two
    flash sectors, kept in a file across the emulator's runs as the chip keeps them across a
    reset or a power cycle."""
    store = tmp_path / "params.bin"
    with start(firmware, params_file=str(store)) as fw:
        c = Client(fw)
        c.text("params: none stored; defaults")
        values = c.fetch()
        assert sorted(values) == sorted(NAMES)
        assert {m.param_index for m in values.values()} == set(range(COUNT))
        assert values["RATE_RLL_KC"].param_value == pytest.approx(2.422, rel=1e-6)
        assert values["ESC3_MAX"].param_type == MAV.MAV_PARAM_TYPE_INT32
        m, _ = c.set("RATE_RLL_KC", 3.5)
        assert m.param_value == pytest.approx(3.5)
        c.mav.param_request_read_send(1, 1, b"RATE_RLL_KC", -1)
        back = c.until(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "RATE_RLL_KC")
        assert back.param_value == pytest.approx(3.5) and back.param_index == NAMES.index("RATE_RLL_KC")
        c.text("params: saved")                        # half a second after the last change
        c.close()
    with start(firmware, params_file=str(store)) as fw:
        c = Client(fw)
        values = c.fetch()
        c.close()
    assert values["RATE_RLL_KC"].param_value == pytest.approx(3.5)
    assert values["RATE_PIT_KC"].param_value == pytest.approx(2.386, rel=1e-6)


def _stored(tmp_path, **values):
    """A host build's parameter store holding ``values``, set through the protocol and saved
    by the firmware."""
    store = tmp_path / "params.bin"
    with start("host", params_file=str(store)) as fw:
        c = Client(fw)
        for name, value in values.items():
            c.set(name, value)
        c.text("params: saved")
        c.close()
    return store


def _changed_store(tmp_path, change, **values):
    """A store of ``values`` whose bytes ``change`` (given them as a bytearray) then edits."""
    store = _stored(tmp_path, **values)
    data = bytearray(store.read_bytes())
    change(data)
    store.write_bytes(bytes(data))
    return store


def _corrupted(tmp_path):
    """A stored EXC_MAX_DUR of 120 s with one bit of its value flipped."""
    def flip(data):
        data[20] ^= 0x40                               # one bit of one stored value

    return _changed_store(tmp_path, flip, EXC_MAX_DUR=120)


def test_a_corrupt_store_gives_the_defaults_and_says_so(tmp_path):
    store = _corrupted(tmp_path)
    with start("host", params_file=str(store)) as fw:
        c = Client(fw)
        warning = c.text("params: store corrupt; defaults loaded")
        assert warning.severity == MAV.MAV_SEVERITY_WARNING
        values = c.fetch()
        c.close()
    assert values["EXC_MAX_DUR"].param_value == 300.0


def _out_of_range(tmp_path):
    """A store whose RATE_YAW_TD (0..1) holds 7.0, its record's CRC rewritten to match."""
    def seven(data):
        struct.pack_into("<f", data, 8 + 8 * NAMES.index("RATE_YAW_TD") + 4, 7.0)
        struct.pack_into("<I", data, len(data) - 4, zlib.crc32(bytes(data[:-4])))

    return _changed_store(tmp_path, seven, RATE_YAW_TD=0.05)


def _not_a_baud_rate(tmp_path):
    """A store whose SER_TEL1_BAUD holds 100000: inside its range, but no standard rate."""
    def odd_rate(data):
        struct.pack_into("<f", data, 8 + 8 * NAMES.index("SER_TEL1_BAUD") + 4, 100000.0)
        struct.pack_into("<I", data, len(data) - 4, zlib.crc32(bytes(data[:-4])))

    return _changed_store(tmp_path, odd_rate, RATE_YAW_TD=0.05)


def test_a_stored_value_out_of_range_keeps_its_default_and_is_named(tmp_path):
    store = _out_of_range(tmp_path)
    with start("host", params_file=str(store)) as fw:
        c = Client(fw)
        c.text("RATE_YAW_TD out of range 0..1")
        values = c.fetch()
        c.close()
    assert values["RATE_YAW_TD"].param_value == pytest.approx(0.043, rel=1e-6)


@pytest.mark.parametrize("name, value, why", [
    ("RATE_RLL_KC", 80.0, "RATE_RLL_KC out of range 0.01..50"),
    ("RATE_RLL_KC", float("nan"), "RATE_RLL_KC out of range 0.01..50"),
    ("ESC2_MIN", 1050.5, "ESC2_MIN takes whole numbers only"),
    ("ESC2_MIN", 1300, "ESC2_MIN out of range 800..1100"),
    ("RATE_RLL_KC", float("inf"), "RATE_RLL_KC out of range 0.01..50"),
    ("RATE_RLL_IMAX", 1e-40, "RATE_RLL_IMAX out of range 0..1"),         # a denormal
    ("RATE_RLL_TI", 5e-4, "RATE_RLL_TI is 0 (off) or at least 0.001"),
    ("ANG_PIT_TD", 1e-30, "ANG_PIT_TD is 0 (off) or at least 0.001"),
    ("SER_TEL1_BAUD", 100000, "SER_TEL1_BAUD not a standard baud rate"),
    ("SER_TEL1_BAUD", 921601, "SER_TEL1_BAUD not a standard baud rate"),
    ("SER_TEL1_BAUD", 57600.5, "SER_TEL1_BAUD takes whole numbers only"),
    ("SER_TEL1_BAUD", 4800, "SER_TEL1_BAUD out of range 9600..1000000"),
    ("SER_TEL1_BAUD", 2000000, "SER_TEL1_BAUD out of range 9600..1000000"),
    ("CA_ROTOR_COUNT", 3, "CA_ROTOR_COUNT out of range 4..8"),
    ("CA_ROTOR_COUNT", 9, "CA_ROTOR_COUNT out of range 4..8"),
    ("CA_ROTOR_COUNT", 5.5, "CA_ROTOR_COUNT takes whole numbers only"),
    ("CA_ROTOR1_AX", 1.5, "CA_ROTOR1_AX out of range -1..1"),
    ("CA_ROTOR2_PX", math.nan, "CA_ROTOR2_PX out of range -2..2"),
    ("CA_ROTOR7_CT", math.inf, "CA_ROTOR7_CT out of range 0..200"),
    ("CA_ROTOR0_KM", -0.6, "CA_ROTOR0_KM out of range -0.5..0.5"),
    ("CA_HOVER_THRUST", 0, "CA_HOVER_THRUST out of range 0.5..500"),
])
def test_a_refused_set_keeps_the_value_and_says_why(client, name, value, why):
    before = client.fetch()[name]
    m, during = client.set(name, value)
    assert decode_value(m.param_value, m.param_type) == \
        decode_value(before.param_value, before.param_type)
    # The STATUSTEXT goes out in the loop that refuses, before the PARAM_VALUE.
    assert why in [x.text for x in during if x.get_type() == "STATUSTEXT"]


#: The rates SER_TEL1_BAUD takes (params.hpp's kSerialBauds, docs/parameters.md).
STANDARD_BAUDS = (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 921600, 1000000)


def test_the_telemetry_baud_rate_takes_exactly_the_standard_rates_and_says_restart():
    """SER_TEL1_BAUD, the Teensy's UART0: an integer, 921600 by default, disarmed only; the
    firmware's own reading of each value (the table and the check a PARAM_SET meets) takes
    the standard rates and nothing between them."""
    row = next(p for p in _firmware.param_table() if p.name == "SER_TEL1_BAUD")
    assert (row.default, row.integer, row.armed_ok) == (921600, True, False)
    assert (row.minimum, row.maximum) == (min(STANDARD_BAUDS), max(STANDARD_BAUDS))
    index = NAMES.index("SER_TEL1_BAUD")
    for baud in STANDARD_BAUDS:
        assert _firmware.decode_param_value(index, encode_value(baud, INT32), INT32) == baud


def test_a_new_telemetry_baud_rate_is_answered_restart_to_apply_and_kept_across_a_restart(tmp_path):
    store = tmp_path / "params.bin"
    with start("host", params_file=str(store)) as fw:
        c = Client(fw)
        for baud in STANDARD_BAUDS:
            m, _ = c.set("SER_TEL1_BAUD", baud)
            assert m.param_value == baud
            said = c.text("SER_TEL1_BAUD set; restart to apply")
            assert said.severity == MAV.MAV_SEVERITY_NOTICE
        c.set("SER_TEL1_BAUD", 115200)
        c.text("params: saved")
        c.close()
    with start("host", params_file=str(store)) as fw:
        c = Client(fw)
        values = c.fetch()
        c.close()
    assert decode_value(values["SER_TEL1_BAUD"].param_value, INT32) == 115200
    record = store.read_bytes()
    at = record.index(struct.pack("<I", zlib.crc32(b"SER_TEL1_BAUD")))
    assert struct.unpack_from("<f", record, at + 4)[0] == 115200.0, "stored as its float"


def test_a_stored_baud_rate_that_is_no_standard_rate_keeps_the_default(tmp_path):
    """A record (its CRC rewritten) holding 100000, within the range but no standard rate:
    the board starts at 921600."""
    def nonstandard(data):
        struct.pack_into("<f", data, 8 + 8 * NAMES.index("SER_TEL1_BAUD") + 4, 100000.0)
        struct.pack_into("<I", data, len(data) - 4, zlib.crc32(bytes(data[:-4])))

    store = _changed_store(tmp_path, nonstandard, SER_TEL1_BAUD=57600)
    with start("host", params_file=str(store)) as fw:
        c = Client(fw)
        c.text("SER_TEL1_BAUD")
        values = c.fetch()
        c.close()
    assert decode_value(values["SER_TEL1_BAUD"].param_value, INT32) == 921600


def test_an_unknown_name_is_answered_with_a_statustext(client):
    client.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, MAV.MAV_PARAM_TYPE_REAL32)
    client.text("params: no NO_SUCH_PARAM")
    client.mav.param_request_read_send(1, 1, b"", COUNT)
    client.text(f"params: no index {COUNT}")
    client.mav.param_request_read_send(1, 1, b"RATE_RLL_KCX", -1)
    client.text("params: no RATE_RLL_KCX")


def test_while_armed_only_the_gains_change_and_nothing_is_saved_until_disarm(client):
    client.hover()
    m, _ = client.set("FS_ABORT_ANG", 60)
    assert m.param_value == pytest.approx(80.0, abs=1e-4)
    client.text("FS_ABORT_ANG changes only while disarmed")
    m, _ = client.set("SER_TEL1_BAUD", 57600)
    assert decode_value(m.param_value, m.param_type) == 921600
    client.text("SER_TEL1_BAUD changes only while disarmed")
    m, _ = client.set("RATE_PIT_KC", 2.0)
    assert m.param_value == pytest.approx(2.0)
    client.step(200)                                   # a second: armed, so no save
    assert not [x for x in client.of_type("STATUSTEXT") if x.text == "params: saved"]
    client.rc[4] = 1000                                # disarm with the switch
    client.text("params: saved")


def test_nothing_changes_while_an_excitation_runs(client):
    client.hover()
    client.heartbeat()
    client.mav.hq_excitation_send(1, 1, MAV.HQ_EXCITATION_START, MAV.HQ_AXIS_ROLL,
                                  MAV.HQ_INJECTION_MIXER, 2.0, 0.05, 20, 1)
    client.until(lambda m: m.get_type() == "HQ_EXCITATION_STATUS" and m.accepted)
    m, _ = client.set("RATE_RLL_KC", 3.0)
    assert m.param_value == pytest.approx(2.422, rel=1e-6)
    client.text("RATE_RLL_KC: not while exciting")


def _loop_response(client, freq_hz, amplitude=0.1, cycles=24, settle=8):
    """Rate mode, a mixer-injection sine on roll: at the excitation's frequency, the rate
    controller C = -(u - r) / y, the closed loop y / r and the plant y / u, from the whole
    periods of the full-amplitude samples after the first `settle` (the loop's transient).
    The amplitude keeps the rate at about 25 mrad/s, some 25 of the gyro's 1.07 mrad/s
    steps: at 0.03 their rounding alone moved y / u by 2 %."""
    first = len(client.seen)
    client.heartbeat()
    client.mav.hq_excitation_send(1, 1, MAV.HQ_EXCITATION_START, MAV.HQ_AXIS_ROLL,
                                  MAV.HQ_INJECTION_MIXER, freq_hz, amplitude, cycles, 1)
    status = client.until(lambda m: m.get_type() == "HQ_EXCITATION_STATUS" and m.accepted)
    for _ in range(int(status.total_samples) // 100 + 2):
        client.heartbeat()
        client.step(100)
    running = [m for m in client.seen[first:] if m.get_type() == "HQ_SYSID_SAMPLE"
               and m.exc_state == MAV.HQ_EXCITATION_STATE_RUNNING]
    running = running[settle * status.period_samples:]
    n = status.period_samples * (len(running) // status.period_samples)
    r = np.array([m.excitation for m in running[:n]])
    u = np.array([m.axis_cmd for m in running[:n]])
    y = np.array([m.rate for m in running[:n]])
    basis = np.exp(-2j * np.pi * np.arange(n) / status.period_samples)
    R, U, Y = (basis @ x for x in (r, u, y))
    return -(U - R) / Y, Y / R, Y / U


def test_the_firmware_flies_with_a_new_rate_gain_as_the_gain_predicts(client):
    """In rate mode with the sticks centred the rate setpoint is 0, so the rate PID's output
    is C(jw) times the measured rate: doubling Kc doubles C at every frequency (ideal form:
    Kc scales P, I and D), and the closed loop y/r = G / (1 + G C) moves to what the plant G
    measured in the first run predicts for 2 C."""
    client.hover()
    ack = client.command(MAV.MAV_CMD_DO_SET_MODE, MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                         MAV.HQ_MODE_RATE)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED
    c1, t1, g1 = _loop_response(client, 2.0)
    kc = client.fetch()["RATE_RLL_KC"].param_value
    client.set("RATE_RLL_KC", 2 * kc)
    c2, t2, g2 = _loop_response(client, 2.0)
    assert abs(c2 / c1) == pytest.approx(2.0, rel=0.01)
    assert math.degrees(abs(np.angle(c2 / c1))) < 0.5
    predicted = g1 / (1 + g1 * 2 * c1)
    assert abs(t2 / predicted) == pytest.approx(1.0, rel=0.01)
    assert math.degrees(abs(np.angle(t2 / predicted))) < 0.5
    assert abs(t2 - t1) > 0.3 * abs(t1)               # and the change is no small one


# --- the boot report ------------------------------------------------------------------------

#: Every finding of the boot report begins so (what start-up found, not what holds now); the
#: report: the reset, the parameter store, the IMU, the SD card, one a loop.
BOOT = "boot: "
FINDINGS = 4
LATE_S = 30.0                       # a ground station that connects this long after boot
LOOPS_A_SECOND = round(1e6 / DT_US)  # the most often a report starts: once a second


def _is_finding(m):
    return m.get_type() == "STATUSTEXT" and m.text.startswith(BOOT)


def _boot_report(c, frames=20):
    """The boot report's STATUSTEXTs, from the cursor on (each within frames of the last)."""
    report = [c.until(_is_finding, frames) for _ in range(FINDINGS)]
    assert report[0].text.startswith("boot: reset by ")
    assert report[2].text.startswith("boot: IMU: ")
    assert report[3].text.startswith("boot: SD: ")
    return report


def _findings(c, since=0):
    """Every boot report finding seen from index since on."""
    return [m for m in c.seen[since:] if _is_finding(m)]


def _connect_late(c):
    """LATE_S of firmware time with nobody on the link, then a ground station's first
    HEARTBEAT; the boot report it gets."""
    c.step(round(LATE_S * 1e6 / DT_US))
    assert not _findings(c)
    c.sent()
    c.heartbeat()
    return _boot_report(c)


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_a_station_that_connects_late_gets_the_boot_report_once_and_so_does_a_new_one(firmware):
    with start(firmware) as fw:
        c = Client(fw)
        reset, store, imu, card = report = _connect_late(c)
        assert reset.text == "boot: reset by power-on"
        # The host build without --params keeps nothing; the board's flash is blank.
        assert store.text == {"host": "boot: params: no storage; defaults",
                              "teensy35": "boot: params: none stored; defaults"}[firmware]
        assert imu.text.startswith("boot: IMU: MPU6050 found; ")
        # Neither the host build nor the emulated board has a card unless given one: said as
        # a notice (logging is no flight safety item), the rest as information.
        assert card.text == "boot: SD: no card; no on-board log"
        assert [m.severity for m in report] == [MAV.MAV_SEVERITY_INFO] * 3 + [MAV.MAV_SEVERITY_NOTICE]
        for _ in range(5):                             # the same station again: no repeat
            c.heartbeat()
            c.step(20)
        assert len(_findings(c)) == FINDINGS
        c.mav.srcSystem = 254                          # another ground station on the link
        c.sent()
        c.heartbeat()
        again = _boot_report(c, frames=LOOPS_A_SECOND)  # a second after the last began
        c.close()
    assert [(m.text, m.severity) for m in again] == [(m.text, m.severity) for m in report]


def _sysid_samples_between(c, a, b):
    """Loops from message a to message b (each loop ends with its HQ_SYSID_SAMPLE)."""
    at = c.seen.index(a), c.seen.index(b)
    return [m.get_type() for m in c.seen[at[0]:at[1]]].count("HQ_SYSID_SAMPLE")


def test_request_message_for_statustext_sends_the_boot_report_again_with_an_ack(client):
    client.step()
    client.sent()
    client.heartbeat()
    first = _boot_report(client)
    ack = client.command(MAV.MAV_CMD_REQUEST_MESSAGE, MAV.MAVLINK_MSG_ID_STATUSTEXT)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED
    ack_at = client.seen.index(ack)
    again = _boot_report(client, frames=LOOPS_A_SECOND)
    assert client.seen.index(again[0]) > ack_at
    assert [m.text for m in again] == [m.text for m in first]
    assert first[1].text == "boot: params: none stored; defaults"
    # One finding a loop: each loop's telemetry (its HQ_SYSID_SAMPLE) between two findings.
    for a, b in zip(again, again[1:]):
        assert _sysid_samples_between(client, a, b) == 1
    # The second began a second (of loops) after the first.
    assert _sysid_samples_between(client, first[0], again[0]) == LOOPS_A_SECOND


def test_a_request_during_the_boot_report_gets_one_more_whole_report_after_it(client):
    client.step()
    client.sent()
    start_at = client.cursor
    client.heartbeat()
    under_way = client.until(_is_finding, 20)          # the report's first finding is out
    ack = client.command(MAV.MAV_CMD_REQUEST_MESSAGE, MAV.MAVLINK_MSG_ID_STATUSTEXT)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED
    client.step(3 * LOOPS_A_SECOND)
    found = _findings(client, start_at)
    # The request came while the report ran; that report was not restarted but ran to its
    # end, and exactly one whole report more followed, a second after it began.
    at = [client.seen.index(m) for m in found]
    assert at[0] < client.seen.index(ack) < at[FINDINGS - 1]
    assert found[0] is under_way and len(found) == 2 * FINDINGS
    assert [m.text for m in found[FINDINGS:]] == [m.text for m in found[:FINDINGS]]
    assert found[0].text.startswith("boot: reset by ")
    assert _sysid_samples_between(client, found[0], found[FINDINGS]) == LOOPS_A_SECOND


@pytest.mark.parametrize("store, text", [
    (_corrupted, "boot: params: store corrupt; defaults loaded"),
    (_out_of_range, "boot: RATE_YAW_TD out of range 0..1"),
    (_not_a_baud_rate, "boot: SER_TEL1_BAUD not a standard baud rate"),
], ids=["corrupt", "out_of_range", "not_a_baud_rate"])
def test_the_boot_report_names_a_bad_store_as_a_warning(tmp_path, store, text):
    """A corrupt store, and a stored value a set would refuse (which keeps its default), in
    the words a set of that value gets."""
    with start("host", params_file=str(store(tmp_path))) as fw:
        c = Client(fw)
        _, found, _, _ = _connect_late(c)
        c.close()
    assert found.text == text
    assert found.severity == MAV.MAV_SEVERITY_WARNING


def _heartbeat_from(c, sysid, compid):
    c.mav.srcSystem, c.mav.srcComponent = sysid, compid
    c.heartbeat()
    c.mav.srcSystem, c.mav.srcComponent = 255, 190


def test_a_ninth_station_does_not_evict_one_still_heard(client):
    """The heard list keeps the stations heard most recently: the first station heartbeats
    every second while eight others each send one; it is never forgotten, so its own
    heartbeats never ask for the report again."""
    client.step()
    for k in range(8):
        client.heartbeat()
        client.step(LOOPS_A_SECOND // 2)
        _heartbeat_from(client, 200 + k, 190)          # a new station: its report
        client.step(LOOPS_A_SECOND // 2 + 10)
    client.heartbeat()
    client.step(2 * LOOPS_A_SECOND)
    reports_before = len(_findings(client))
    for _ in range(5):                                 # the first station, still heard
        client.heartbeat()
        client.step(LOOPS_A_SECOND)
    assert reports_before == 9 * FINDINGS
    assert len(_findings(client)) == reports_before


def test_a_flood_of_new_stations_costs_one_whole_report_a_second(client):
    """A new ground station id every loop for 5 s of loop time (spoofed heartbeats): the
    report still goes out whole, every finding in order, and starts at most once a second."""
    client.step()
    since = len(client.seen)
    loops = 5 * LOOPS_A_SECOND
    for i in range(loops):
        _heartbeat_from(client, 10 + i // 100, 100 + i % 100)
        client.step()
    found = _findings(client, since)
    texts = [m.text for m in found]
    whole = texts[:FINDINGS]
    assert whole[0].startswith("boot: reset by ") and whole[2].startswith("boot: IMU: ")
    starts = len(found) // FINDINGS
    assert texts == whole * starts                     # whole reports, each in order
    assert 5 <= starts <= 6
    for a, b in zip(found[::FINDINGS], found[FINDINGS::FINDINGS]):
        assert _sysid_samples_between(client, a, b) == LOOPS_A_SECOND


# --- standard telemetry ---------------------------------------------------------------------

@pytest.fixture(params=FIRMWARES)
def any_client(request):
    with start(request.param) as fw:
        c = Client(fw)
        yield c
        c.close()


def test_standard_messages_describe_the_vehicle(any_client):
    client = any_client
    client.hover()
    client.step(420)
    status = client.of_type("SYS_STATUS")[-1]
    gyro, rc = MAV.MAV_SYS_STATUS_SENSOR_3D_GYRO, MAV.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
    assert status.onboard_control_sensors_health & gyro and status.onboard_control_sensors_health & rc
    assert status.onboard_control_sensors_enabled & MAV.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    # Load: the median loop's cycles (HQ_FW_STATUS, sent just before) over the 600 000 a
    # 200 Hz loop has at 120 MHz, in 0.1 %; the host build has no cycle counter.
    median = client.of_type("HQ_FW_STATUS")[-1].loop_cycles_median
    if client.fw.name == "host":
        assert status.load == 0 and median == 0
    else:
        assert 0 < status.load == int(1000 * median / 600000) < 1000
    channels = client.of_type("RC_CHANNELS")[-1]
    assert channels.chancount == 6
    assert [channels.chan1_raw, channels.chan3_raw, channels.chan5_raw] == [1500, THROTTLE_HOVER, ARM_HIGH]
    sample = [m for m in client.seen if m.get_type() == "HQ_SYSID_SAMPLE"][-1]
    servo = client.of_type("SERVO_OUTPUT_RAW")[-1]
    assert servo.servo1_raw == pytest.approx(1000 + 1000 * sample.motor[0], abs=15)
    assert 1000 < servo.servo2_raw < 2000
    # Past the five rotors flown, the ESC outputs carry their stop pulse (ESCn_MIN).
    assert [servo.servo6_raw, servo.servo7_raw, servo.servo8_raw] == [1000] * 3
    imu = client.of_type("SCALED_IMU")[-1]
    assert math.hypot(imu.xacc, imu.yacc, imu.zacc) == pytest.approx(1000, rel=0.05)
    hr = client.of_type("HIGHRES_IMU")[-1]            # SI units: MAVSDK's imu()
    assert math.hypot(hr.xacc, hr.yacc, hr.zacc) == pytest.approx(9.81, rel=0.05)
    assert hr.fields_updated == 0x3F
    prearm = MAV.MAV_SYS_STATUS_PREARM_CHECK           # armed: healthy (MAVSDK's is_armable)
    assert status.onboard_control_sensors_present & prearm
    assert status.onboard_control_sensors_health & prearm
    # The default rates: 10 Hz servo and IMU, 5 Hz RC, 1 Hz status, over the last 2 s.
    window = client.seen[-3 * 400:]
    counts = {k: sum(m.get_type() == k for m in window) for k in
              ("SERVO_OUTPUT_RAW", "SCALED_IMU", "HIGHRES_IMU", "RC_CHANNELS", "SYS_STATUS",
               "HQ_SYSID_SAMPLE")}
    per_s = {k: v / (counts["HQ_SYSID_SAMPLE"] / 200) for k, v in counts.items()}
    assert per_s["SERVO_OUTPUT_RAW"] == pytest.approx(10, rel=0.15)
    assert per_s["HIGHRES_IMU"] == pytest.approx(10, rel=0.15)
    assert per_s["RC_CHANNELS"] == pytest.approx(5, rel=0.25)


def test_the_pre_arm_bit_says_whether_an_arm_command_would_arm(client):
    """Disarmed with the arm switch low, a command would be refused: not healthy."""
    client.step(420)
    status = client.of_type("SYS_STATUS")[-1]
    prearm = MAV.MAV_SYS_STATUS_PREARM_CHECK
    assert status.onboard_control_sensors_present & prearm
    assert not status.onboard_control_sensors_health & prearm


@pytest.mark.parametrize("firmware, uid, uid2", [
    ("host", 0x48512D484F535401, bytes(18)),
    pytest.param("teensy35", 0x4D4B363400000001,
                 bytes.fromhex("00004851" "00454D55" "4D4B3634" "00000001") + bytes(2),
                 marks=pytest.mark.pil)])
def test_autopilot_version_carries_the_boards_unique_id(tmp_path, firmware, uid, uid2):
    """The Teensy's is the chip's (SIM_UIDH..UIDL, the emulated chip's fixed id); the host
    build's a fixed stand-in."""
    with start(firmware) as fw:
        c = Client(fw)
        c.command(MAV.MAV_CMD_REQUEST_MESSAGE, MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        v = c.until(lambda m: m.get_type() == "AUTOPILOT_VERSION")
        c.close()
    assert v.uid == uid and bytes(v.uid2) == uid2


def test_autopilot_version_on_request_and_the_capabilities_a_ground_station_reads(client):
    ack = client.command(MAV.MAV_CMD_REQUEST_MESSAGE, MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED
    v = client.until(lambda m: m.get_type() == "AUTOPILOT_VERSION")
    caps = v.capabilities
    assert caps & MAV.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert caps & MAV.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    assert not caps & MAV.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
    from importlib.metadata import version

    major, minor, patch = (int(x) for x in version("heliquad").split(".")[:3])
    assert v.flight_sw_version >> 8 == (major << 16) | (minor << 8) | patch
    ack = client.command(MAV.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED


def test_set_message_interval_within_what_the_link_carries(client):
    ack = client.command(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, MAV.MAVLINK_MSG_ID_SCALED_IMU, 20000)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED
    first = len(client.seen)
    client.step(200)
    got = sum(m.get_type() == "SCALED_IMU" for m in client.seen[first:])
    assert got == pytest.approx(50, abs=2)            # 50 Hz over a second
    ack = client.command(MAV.MAV_CMD_GET_MESSAGE_INTERVAL, MAV.MAVLINK_MSG_ID_SCALED_IMU)
    interval = client.until(lambda m: m.get_type() == "MESSAGE_INTERVAL")
    assert interval.interval_us == 20000
    # Every stream at the loop rate is more than the 921600-baud link carries.
    results = [client.command(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, msgid, 1).result
               for msgid in (MAV.MAVLINK_MSG_ID_SYS_STATUS, MAV.MAVLINK_MSG_ID_RC_CHANNELS,
                             MAV.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, MAV.MAVLINK_MSG_ID_HQ_FW_STATUS)]
    assert MAV.MAV_RESULT_DENIED in results
    client.text("interval refused: more than the link carries")
    # The link contract's messages keep their rates; -1 turns a stream off.
    assert client.command(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, MAV.MAVLINK_MSG_ID_HEARTBEAT, 5e5).result \
        == MAV.MAV_RESULT_DENIED
    assert client.command(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, MAV.MAVLINK_MSG_ID_HQ_SYSID_SAMPLE, 1e5).result \
        == MAV.MAV_RESULT_DENIED
    assert client.command(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, MAV.MAVLINK_MSG_ID_SCALED_IMU, -1).result \
        == MAV.MAV_RESULT_ACCEPTED
    first = len(client.seen)
    client.step(100)
    assert not [m for m in client.seen[first:] if m.get_type() == "SCALED_IMU"]


def test_every_command_is_acknowledged_and_broadcast_targets_are_ours(client):
    # Unknown commands: UNSUPPORTED; broadcast (0, 0) and our own address both answered.
    assert client.command(MAV.MAV_CMD_NAV_TAKEOFF).result == MAV.MAV_RESULT_UNSUPPORTED
    assert client.command(MAV.MAV_CMD_NAV_TAKEOFF, target=(0, 0)).result == MAV.MAV_RESULT_UNSUPPORTED
    ack = client.command(MAV.MAV_CMD_REQUEST_MESSAGE, MAV.MAVLINK_MSG_ID_SYS_STATUS, target=(0, 0))
    assert ack.result == MAV.MAV_RESULT_ACCEPTED and ack.target_system == 255
    # COMMAND_INT is answered as COMMAND_LONG is.
    client.mav.command_int_send(0, 0, 0, MAV.MAV_CMD_DO_SET_MODE, 0, 0,
                                MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MAV.HQ_MODE_RATE, 0, 0, 0, 0, 0)
    ack = client.until(lambda m: m.get_type() == "COMMAND_ACK" and m.command == MAV.MAV_CMD_DO_SET_MODE)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED
    # Another vehicle's commands are not ours: no answer.
    first = len(client.seen)
    client.mav.command_long_send(7, 1, MAV.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 0)
    client.step(100)
    assert not [m for m in client.seen[first:] if m.get_type() == "COMMAND_ACK"]


def test_more_requests_than_a_loop_takes_are_each_answered_from_their_own_fields(any_client):
    """A loop takes 24 messages (LoopInbox::kCapacity). A burst of 39 sent between two
    frames (the host build's pty gives the loop all of it at once, so the 25th waits whole
    in the link's framer for the next loop and the rest in the port), a parameter read by
    name and two REQUEST_MESSAGE commands (one streamed message, one not) in turn, is
    answered every one: each command's ACK in the order sent with the result its own
    parameter gives, and each name read once."""
    client = any_client
    client.step(5)
    names = [p[0] for p in PARAMS[:13]]
    asked = [(MAV.MAVLINK_MSG_ID_SYS_STATUS, MAV.MAV_RESULT_ACCEPTED),
             (MAV.MAVLINK_MSG_ID_GPS_RAW_INT, MAV.MAV_RESULT_DENIED)]
    client.sent()
    start = client.cursor
    for name in names:
        client.mav.param_request_read_send(1, 1, name.encode(), -1)
        for msgid, _ in asked:
            client.mav.command_long_send(1, 1, MAV.MAV_CMD_REQUEST_MESSAGE, 0, msgid,
                                         0, 0, 0, 0, 0, 0)
    client.step(20)
    answers = client.seen[start:]
    acks = [(m.command, m.result) for m in answers if m.get_type() == "COMMAND_ACK"]
    assert acks == [(MAV.MAV_CMD_REQUEST_MESSAGE, result) for _ in names for _, result in asked]
    values = [m.param_id for m in answers if m.get_type() == "PARAM_VALUE"]
    assert sorted(values) == sorted(names)


def test_modes_by_their_usual_names(client):
    """mavutil names a multirotor's custom modes as ArduCopter's: STABILIZE for angle mode,
    ACRO for rate mode; arming and an excitation leave the mode as it is."""
    hb = client.until(lambda m: m.get_type() == "HEARTBEAT")
    assert mavutil.mode_string_v10(hb) == "STABILIZE"
    client.hover()
    client.heartbeat()
    client.mav.hq_excitation_send(1, 1, MAV.HQ_EXCITATION_START, MAV.HQ_AXIS_ROLL,
                                  MAV.HQ_INJECTION_MIXER, 2.0, 0.05, 20, 1)
    client.step(5)
    hb = client.until(lambda m: m.get_type() == "HEARTBEAT")
    assert hb.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED and mavutil.mode_string_v10(hb) == "STABILIZE"
    client.mav.hq_excitation_send(1, 1, MAV.HQ_EXCITATION_STOP, 0, 0, 0, 0, 0, 0)
    client.step(50)
    client.conn.set_mode("ACRO")                       # mavutil's own mode change
    client.heartbeat()
    hb = client.until(lambda m: m.get_type() == "HEARTBEAT" and m.custom_mode == MAV.HQ_MODE_RATE)
    assert mavutil.mode_string_v10(hb) == "ACRO"
    assert client.conn.flightmode == "ACRO"


def test_preflight_storage_resets_to_the_defaults_and_saves(client):
    client.set("STK_ANG_MAX", 20)
    ack = client.command(MAV.MAV_CMD_PREFLIGHT_STORAGE, MAV.PARAM_RESET_FACTORY_DEFAULT)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED
    assert client.fetch()["STK_ANG_MAX"].param_value == pytest.approx(30.0, abs=1e-4)
    ack = client.command(MAV.MAV_CMD_PREFLIGHT_STORAGE, MAV.PARAM_WRITE_PERSISTENT)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED
    client.text("params: saved")


def test_the_parameters_page_lists_the_table_as_the_firmware_has_it():
    import pathlib
    import re

    page = (pathlib.Path(__file__).resolve().parent.parent / "docs" / "parameters.md").read_text()
    rows = re.findall(r"^\| `(\w+)` \| (\S+) \| (\S+) \.\. (\S+) \| (\S+) \| (int|real) \|", page, re.M)
    assert [r[0] for r in rows] == NAMES
    for (name, units, lo, hi, default, kind), p in zip(rows, _firmware.param_table()):
        assert units == (p.units or "-"), name
        assert (float(lo), float(hi)) == (pytest.approx(p.minimum), pytest.approx(p.maximum)), name
        assert float(default) == pytest.approx(p.default, rel=1e-6), name
        assert (kind == "int") == p.integer, name


def _documented_defaults():
    import pathlib
    import re

    page = (pathlib.Path(__file__).resolve().parent.parent / "docs" / "parameters.md").read_text()
    rows = re.findall(r"^\| `(\w+)` \| \S+ \| \S+ \.\. \S+ \| (\S+) \| (int|real) \|", page, re.M)
    return {name: float(default) for name, default, _ in rows}


def test_every_default_reads_over_the_protocol_exactly_as_documented(client):
    """STK_YAW_MAX read 89.99999237 where the page says 90: every value, as a client decodes
    it, is the float32 of the documented number, not merely close to it."""
    documented = _documented_defaults()
    values = client.fetch()
    got = {n: decode_value(m.param_value, m.param_type) for n, m in values.items()}
    assert {n: got[n] for n in documented} == \
        {n: float(np.float32(v)) for n, v in documented.items()}


def test_integer_parameters_travel_bytewise_and_a_set_in_either_form_is_taken(client):
    """INT32 values are byte-wise (MAVSDK's and QGroundControl's reading for a generic
    autopilot); a PARAM_SET typed INT32 is read byte-wise (MAVSDK, QGroundControl), one typed
    REAL32 as the number (MAVProxy, pymavlink) and answered in that form, and a C-cast INT32
    (ArduPilot's convention) as the number it carries."""
    esc = client.fetch()["ESC1_MAX"]
    assert esc.param_type == INT32 and esc.param_value == encode_value(2000, INT32)
    assert np.float32(esc.param_value).view(np.int32) == 2000
    for raw, kind, want in [(encode_value(1900, INT32), INT32, 1900), (1950.0, REAL32, 1950),
                            (1850.0, INT32, 1850)]:
        client.sent()
        client.mav.param_set_send(1, 1, b"ESC1_MAX", raw, kind)
        m = client.until(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "ESC1_MAX")
        assert decode_value(m.param_value, m.param_type) == want
        assert m.param_type == (REAL32 if kind == REAL32 else INT32)
    assert decode_value(client.fetch()["ESC1_MAX"].param_value, INT32) == 1850


def test_every_integer_range_keeps_the_two_encodings_apart():
    """A byte-wise value is a denormal float below 2^23, never a whole number but 0: so a
    C-cast set is told from a byte-wise one without doubt (firmware decode_param_value)."""
    assert all(p[2] < 2 ** 23 and p[1] >= 0 for p in PARAMS if p[4])


@pytest.mark.skipif(not hasattr(MAV, "MAVLINK_MSG_ID_PARAM_ERROR"),
                    reason="pymavlink's common.xml has no PARAM_ERROR (2.4.50 has)")
@pytest.mark.parametrize("name, value, error", [
    ("RATE_RLL_KC", 80.0, "VALUE_OUT_OF_RANGE"), ("ESC2_MIN", 1050.5, "VALUE_OUT_OF_RANGE"),
    ("NO_SUCH_PARAM", 1.0, "DOES_NOT_EXIST")])
def test_a_refused_set_is_answered_with_param_error_to_the_asker(client, name, value, error):
    client.sent()
    client.mav.param_set_send(1, 1, name.encode(), value, REAL32)
    m = client.until(lambda m: m.get_type() == "PARAM_ERROR")
    assert m.param_id == name and m.error == getattr(MAV, "MAV_PARAM_ERROR_" + error)
    assert (m.target_system, m.target_component) == (255, 190)      # the mavutil client


def test_while_armed_a_set_of_a_bound_is_denied_with_param_error(client):
    if not hasattr(MAV, "MAVLINK_MSG_ID_PARAM_ERROR"):
        pytest.skip("pymavlink's common.xml has no PARAM_ERROR (2.4.50 has)")
    client.heartbeat()
    client.hover()
    client.sent()
    client.mav.param_set_send(1, 1, b"ESC1_MIN", encode_value(1050, INT32), INT32)
    m = client.until(lambda m: m.get_type() == "PARAM_ERROR")
    assert m.error == MAV.MAV_PARAM_ERROR_PERMISSION_DENIED


def _set_raw(client, name, raw, kind, frames=20):
    """PARAM_SET in the given form; its PARAM_VALUE, and everything that came within `frames`
    loops after it (a refusal's PARAM_ERROR and STATUSTEXT would be there)."""
    client.sent()
    start = client.cursor
    client.mav.param_set_send(1, 1, name.encode(), raw, kind)
    m = client.until(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name)
    client.step(frames)
    return m, client.seen[start:]


def _refusals(messages, name):
    return [m for m in messages if (m.get_type() == "PARAM_ERROR" and m.param_id == name)
            or (m.get_type() == "STATUSTEXT" and name in m.text)]


def test_a_set_to_the_value_it_has_is_answered_with_it_even_while_armed_or_exciting(client):
    """A PARAM_SET whose value equals the parameter's (after rounding to its type: a whole
    number for an integer parameter) changes nothing, so the rules about changes (armed,
    exciting) do not apply: it is answered with that value, in the form it came in, and never
    refused (docs/parameters.md). MAVProxy's `param load` of an unchanged file re-sends every
    integer parameter it misreads. Another value is still refused, and nothing is saved."""
    current = client.fetch()
    abort = current["FS_ABORT_ANG"].param_value
    esc = decode_value(current["ESC1_MIN"].param_value, INT32)
    kc = current["RATE_RLL_KC"].param_value
    client.heartbeat()
    client.hover()
    for name, raw, kind, want in [("FS_ABORT_ANG", abort, REAL32, abort),
                                  ("ESC1_MIN", float(esc), REAL32, esc),        # MAVProxy's form
                                  ("ESC1_MIN", esc + 0.3, REAL32, esc),         # rounds to it
                                  ("ESC1_MIN", encode_value(esc, INT32), INT32, esc)]:
        m, after = _set_raw(client, name, raw, kind)
        assert decode_value(m.param_value, m.param_type) == pytest.approx(want, abs=0)
        assert m.param_type == (INT32 if kind == INT32 else REAL32)
        assert not _refusals(after, name), (name, raw)
    m, after = _set_raw(client, "FS_ABORT_ANG", 60.0, REAL32)             # a change: refused
    assert m.param_value == abort
    assert any("changes only while disarmed" in x.text for x in _refusals(after, "FS_ABORT_ANG")
               if x.get_type() == "STATUSTEXT")
    client.heartbeat()
    client.mav.hq_excitation_send(1, 1, MAV.HQ_EXCITATION_START, MAV.HQ_AXIS_ROLL,
                                  MAV.HQ_INJECTION_MIXER, 2.0, 0.05, 20, 1)
    client.until(lambda m: m.get_type() == "HQ_EXCITATION_STATUS" and m.accepted)
    m, after = _set_raw(client, "RATE_RLL_KC", kc, REAL32)
    assert m.param_value == kc and not _refusals(after, "RATE_RLL_KC")
    m, after = _set_raw(client, "RATE_RLL_KC", 3.0, REAL32)
    assert m.param_value == kc and _refusals(after, "RATE_RLL_KC")
    client.rc[4] = 1000                                  # disarm: nothing changed, no save
    client.step(300)
    assert not [x for x in client.of_type("STATUSTEXT") if x.text == "params: saved"]


def _heliquad(*args):
    import subprocess

    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)


def test_a_sweep_records_the_gains_the_board_flies_and_identify_and_validate_use_them(tmp_path):
    """The board's rate gain changed through the protocol: the sweep reads it back from the
    board, identify carries it into models.json, validate says it validates with it."""
    import json

    store = _stored(tmp_path, RATE_RLL_KC=3.1, ANG_RLL_TD=0.09)
    out = tmp_path / "sweep"
    res = _heliquad("sweep", "--axis", "roll", "--sil", "--plant", "tf", "--freqs-hz", 1, 2, 4,
                    "--param-store", store, "--out", out)
    assert res.returncode == 0, res.stderr
    assert f"read {COUNT} parameters from the board" in res.stdout
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["params"]["RATE_RLL_KC"] == 3.1 and manifest["params"]["ESC1_MIN"] == 1000
    assert manifest["gains"] == {"rate": [3.1, 0.439, 0.051], "angle": [1.488, 0.09]}
    res = _heliquad("identify", out, "--order", "0/2", "--no-delay")
    assert res.returncode == 0, res.stderr
    models = json.loads((out / "models.json").read_text())
    assert models["gains"] == manifest["gains"]
    res = _heliquad("validate", out / "models.json", "--turbulence", "none")
    assert "gains: the board's, as its sweep read them: rate [3.1, 0.439, 0.051], angle [1.488, 0.09]" \
        in res.stdout, res.stdout + res.stderr
    validation = json.loads((out / "validation.json").read_text())
    assert validation["gains"] == {"rate": [3.1, 0.439, 0.051], "angle": [1.488, 0.09]}


def test_heliquad_params_against_the_simulated_board(tmp_path):
    """heliquad params against the firmware itself (heliquad board, real time): a set read
    back with get, a refusal quoting the firmware, and a file saved in MAVProxy's layout
    loaded back."""
    import signal

    from tool_runs import cli

    port = tmp_path / "rig"
    board = cli("board", "--telemetry", port, "--param-store", tmp_path / "store.bin")
    try:
        assert "board running" in board.stdout.readline()
        res = _heliquad("params", "--port", port, "set", "RATE_YAW_KC", 6.5)
        assert res.returncode == 0 and "RATE_YAW_KC: 7.393 -> 6.5" in res.stdout, res.stderr
        assert "the board is armed: it saves the change when it disarms" in res.stdout
        assert _heliquad("params", "--port", port, "get", "RATE_YAW_KC").stdout.split() == \
            ["RATE_YAW_KC", "6.5"]
        res = _heliquad("params", "--port", port, "set", "ESC1_MIN", 1050)   # armed: refused
        # The board refused: exit 1, as a refused load (2 is for wrong arguments or files).
        assert res.returncode == 1 and 'it says "ESC1_MIN changes only while disarmed"' in res.stderr
        saved = tmp_path / "rig.parm"
        assert _heliquad("params", "--port", port, "save", "--mavproxy", saved).returncode == 0
        lines = [ln.split() for ln in saved.read_text().splitlines() if not ln.startswith("#")]
        assert len(lines) == COUNT and ["RATE_YAW_KC", "6.5"] in lines
        assert _heliquad("params", "--port", port, "set", "RATE_YAW_KC", 7).returncode == 0
        res = _heliquad("params", "--port", port, "load", saved)
        assert res.returncode == 0 and f"1 set, {COUNT - 1} already so, 0 refused" in res.stdout, res.stdout
    finally:
        board.send_signal(signal.SIGINT)
        board.communicate(timeout=60)


# --- the type a set names, and the time constants' floor ----------------------------------

INTEGER_TYPES = {  # MAV_PARAM_TYPE: struct format, range
    "UINT8": ("<B", 0, 2 ** 8 - 1), "INT8": ("<b", -2 ** 7, 2 ** 7 - 1),
    "UINT16": ("<H", 0, 2 ** 16 - 1), "INT16": ("<h", -2 ** 15, 2 ** 15 - 1),
    "UINT32": ("<I", 0, 2 ** 32 - 1), "INT32": ("<i", -2 ** 31, 2 ** 31 - 1)}


def _bytewise(value, fmt, size, sign_extend):
    """The float a byte-wise encoder sends: the narrow value's bytes, the rest zero (a
    zeroed union) or, for a signed type, its sign extension."""
    import struct
    low = struct.pack(fmt, value)
    pad = b"\xff" if sign_extend and value < 0 else b"\x00"
    return struct.unpack("<f", low + pad * (4 - size))[0]


def test_every_integer_type_in_either_encoding_reads_every_value_of_every_integer_parameter():
    """The firmware's decoder, for every integer parameter, every value of its range, every
    integer type that holds it, byte-wise (zero- or sign-extended) and C-cast: the value.
    Truncating a C-cast float's bits to 8 or 16 bits read 1.0 as UINT8 and 255.0 as INT16
    as 0, which is in range (IMU_PATH, MAV_GCS_SYSID's pin silently removed)."""
    import struct
    checked = 0
    for index, (name, lo, hi, _, integer) in enumerate(PARAMS):
        if not integer:
            continue
        for tname, (fmt, tlo, thi) in INTEGER_TYPES.items():
            kind = getattr(MAV, "MAV_PARAM_TYPE_" + tname)
            size = struct.calcsize(fmt)
            for v in range(max(int(lo), tlo), min(int(hi), thi) + 1):
                for raw in {_bytewise(v, fmt, size, False), _bytewise(v, fmt, size, True),
                            float(v)}:
                    got = _firmware.decode_param_value(index, raw, kind)
                    assert got == v, (name, tname, v, raw, got)
                    checked += 1
    assert checked > 5000


def test_a_set_of_a_real_parameter_typed_as_an_integer_is_refused_and_the_motors_run_on(client):
    """An INT32-typed set of RATE_RLL_TI = 1 carried the float whose bits are 1 (1.4e-45):
    taken, the PID went NaN and the failsafe cut the motors in flight. Now the type is
    refused (PARAM_ERROR, STATUSTEXT, the unchanged value) and the vehicle flies on."""
    for name in ("RATE_RLL_TI", "RATE_RLL_KC"):
        assert _firmware.decode_param_value(NAMES.index(name), encode_value(1, INT32), INT32) \
            is None
        assert _firmware.decode_param_value(NAMES.index(name), 1.0, REAL32) == 1.0
    before = client.fetch()["RATE_RLL_TI"].param_value
    client.heartbeat()
    client.hover()
    m, after = _set_raw(client, "RATE_RLL_TI", encode_value(1, INT32), INT32, frames=100)
    assert m.param_value == before and m.param_type == REAL32
    assert any(x.get_type() == "STATUSTEXT" and x.text == "RATE_RLL_TI sent with the wrong type"
               for x in after)
    if hasattr(MAV, "MAVLINK_MSG_ID_PARAM_ERROR"):
        errors = [x for x in after if x.get_type() == "PARAM_ERROR"]
        assert errors and errors[0].param_id == "RATE_RLL_TI"
        assert errors[0].error == getattr(MAV, "MAV_PARAM_ERROR_TYPE_MISMATCH",
                                          MAV.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE)
    assert not [x for x in after if x.get_type() == "STATUSTEXT" and "non-finite" in x.text]
    samples = [x for x in after if x.get_type() == "HQ_SYSID_SAMPLE"]
    assert samples and all(s.armed for s in samples)
    m, _ = client.set("RATE_RLL_TI", 0.0)                            # 0: off, taken armed
    assert m.param_value == 0.0


@pytest.mark.parametrize("name, raw, kind, want", [
    ("IMU_PATH", 1.0, "UINT8", 1), ("MAV_GCS_SYSID", 255.0, "INT16", 255),
    ("MAV_GCS_SYSID", 200.0, "UINT8", 200)])
def test_a_c_cast_set_of_a_narrow_type_is_read_as_the_number(client, name, raw, kind, want):
    m, after = _set_raw(client, name, raw, getattr(MAV, "MAV_PARAM_TYPE_" + kind))
    assert decode_value(m.param_value, m.param_type) == want
    assert not _refusals(after, name)


def test_a_station_mav_gcs_sysid_excludes_can_neither_stay_alive_nor_excite(client):
    """The mavutil client is system 255. It heartbeats, MAV_GCS_SYSID becomes 200, the pilot
    arms, and 255 sends an arm command every 0.5 s for 5 s (the host timeout is 1.5 s): each
    is refused, and so is its excitation (it was accepted: a command kept the slot alive)."""
    client.heartbeat()
    client.step(2)
    m, _ = client.set("MAV_GCS_SYSID", 200)
    assert m.param_value == encode_value(200, INT32) or m.param_value == 200.0
    client.hover()
    for _ in range(10):
        ack = client.command(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        assert ack.result == MAV.MAV_RESULT_DENIED and ack.result_param2 == MAV.HQ_REASON_NO_HOST
        client.step(100)
    client.sent()
    client.mav.hq_excitation_send(1, 1, MAV.HQ_EXCITATION_START, MAV.HQ_AXIS_ROLL,
                                  MAV.HQ_INJECTION_MIXER, 2.0, 0.05, 20, 1)
    status = client.until(lambda m: m.get_type() == "HQ_EXCITATION_STATUS")
    assert not status.accepted and status.reason == MAV.HQ_REASON_NO_HOST


def test_the_pre_arm_bit_says_not_armable_without_a_live_ground_station(client):
    """Switch high (no edge), throttle low, IMU fresh: only the host is missing, and a
    command would be refused NO_HOST, so the pre-arm bit is not healthy; with the station's
    heartbeat it is."""
    prearm = MAV.MAV_SYS_STATUS_PREARM_CHECK
    client.rc[4] = ARM_HIGH
    client.step(420)
    assert not client.of_type("SYS_STATUS")[-1].onboard_control_sensors_health & prearm
    for _ in range(5):
        client.heartbeat()
        client.step(50)
    assert client.of_type("SYS_STATUS")[-1].onboard_control_sensors_health & prearm
    assert not client.of_type("HQ_SYSID_SAMPLE")[-1].armed
