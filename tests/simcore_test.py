"""The simulator's C++ core (sim/*/*.cpp, ``heliquad._simcore``): FIFO packets the firmware's
driver reads back, the batch engine against frame-by-frame stepping, and its failures."""

import math
import os
import signal
import struct

import numpy as np
import pytest

from fake_dmp import write_fake_dmp
from heliquad import _firmware as fw
from heliquad import _simcore
from heliquad.host.acquire.session import SilSession
from heliquad.sim.plant.vehicle_plant import VehiclePlant
from heliquad.sim.rig.lockstep import FirmwareError, HostFirmware, SimLink
from heliquad.sim.rig.setup import SilConfig, _rc


def test_dmp_packet_reads_back_through_the_firmware_driver():
    # 30 deg of roll, body rates and a specific force, all FRD: the encoder converts to the
    # chip frame, the driver converts back; what survives is the chip's quantisation.
    half = math.radians(30) / 2
    q = (math.cos(half), math.sin(half), 0.0, 0.0)
    gyro, accel = (0.3, -0.2, 0.1), (0.5, -4.9, -8.5)
    s = fw.Mpu6050.parse_dmp_packet(_simcore.dmp_packet(q, gyro, accel))
    assert s is not None and s.has_attitude
    assert s.attitude.to_list() == pytest.approx(q, abs=1e-7)
    assert s.gyro_rad_s.to_list() == pytest.approx(gyro, abs=math.radians(1 / 16.4))
    assert s.accel_m_s2.to_list() == pytest.approx(accel, abs=9.80665 / 16384)


def test_raw_packet_has_the_chips_layout_and_saturates():
    # accel x y z then gyro x y z, int16 big-endian, chip frame (y and z flipped from FRD)
    packet = _simcore.raw_packet((math.radians(100), 0.0, 0.0), (0.0, 0.0, -9.80665))
    assert struct.unpack(">3h3h", packet) == (0, 0, 16384, 1640, 0, 0)
    huge = _simcore.raw_packet((100.0, -100.0, 0.0), (0.0, 0.0, 0.0))
    assert struct.unpack(">3h3h", huge)[3:5] == (32767, 32767)    # +/-2000 deg/s full scale


def _vehicle_plant():
    return VehiclePlant("roll", "free", 0.005, turbulence="moderate", seed=7)


def test_a_batch_in_the_engine_equals_the_same_frames_stepped_one_by_one(tmp_path):
    # Free flight with turbulence and the noisy IMU: the engine, fed the same random inputs
    # in one block, reaches exactly the state that frame-by-frame stepping reaches.
    image = write_fake_dmp(tmp_path / "dmp.bin")
    frames = 300
    cfg = SilConfig(plant="vehicle", rig="free", collective=0.47)
    rc = [_rc(f, cfg.collective) for f in range(1, frames + 1)]

    one = _vehicle_plant()
    with HostFirmware(dmp_image=str(image)) as fw_host:
        link, kind = SimLink(fw_host), 0
        for f in range(1, frames + 1):
            reply = link.step(f * 5000, one.fifo(kind), kind, rc[f - 1])
            one.step_motors(reply.motor)
            kind = reply.sensor_kind
        link.close()

    batch = _vehicle_plant()
    with HostFirmware(dmp_image=str(image)) as fw_host:
        link = SimLink(fw_host)
        engine = _simcore.RigEngine(link.port, batch.core)
        noise, gust = batch.frame_inputs(frames)
        engine.start(1, frames, 5000, 0, np.array(rc, dtype=np.uint16), noise, gust)
        result = engine.wait()
        link.close()
    assert result.status == _simcore.LinkStatus.OK and result.frames_done == frames
    assert result.last.armed
    np.testing.assert_array_equal(batch.vehicle.x, one.vehicle.x)
    assert np.max(np.abs(one.vehicle.x[10:13])) > 1e-3           # it did move


def test_a_firmware_killed_during_a_batch_is_a_clear_error(tmp_path):
    with SilSession(SilConfig(), str(tmp_path / "k.tlog")) as session:
        session.advance(frames=50)
        os.kill(session.fw.proc.pid, signal.SIGKILL)
        with pytest.raises(FirmwareError, match="died at frame 51"):
            session.advance(frames=50)
        assert session.frame == 50


def test_a_stopped_firmware_times_out_during_a_batch(tmp_path):
    with SilSession(SilConfig(), str(tmp_path / "s.tlog")) as session:
        session.advance(frames=50)
        os.kill(session.fw.proc.pid, signal.SIGSTOP)
        try:
            with pytest.raises(FirmwareError, match="did not answer within 2 s"):
                session.advance(frames=50)
        finally:
            os.kill(session.fw.proc.pid, signal.SIGCONT)


def test_engine_checks_its_inputs(tmp_path):
    with SilSession(SilConfig(), str(tmp_path / "c.tlog")) as session:
        engine = session.rig.engine
        with pytest.raises(ValueError, match="rc must be n x 8"):
            engine.start(1, 10, 5000, 0, np.zeros((9, 8), dtype=np.uint16), None, None)
        with pytest.raises(ValueError, match="noise must have 10 x 6"):
            engine.start(1, 10, 5000, 0, np.zeros((10, 8), dtype=np.uint16),
                         np.zeros((10, 5)), None)


def test_vehicle_model_refuses_impossible_parameters():
    c = _simcore.VehicleConfig()
    c.inertia_kg_m2 = [0.01, 0.01, 0.0]
    with pytest.raises(ValueError, match="inertia"):
        _simcore.VehicleModel(c)


def _sysid(codec, mav, time_us, seq):
    return codec.encode(mav.MAVLINK_MSG_ID_HQ_SYSID_SAMPLE, {
        "time_us": time_us, "seq": seq, "axis": 0, "injection": 2,
        "exc_state": mav.HQ_EXCITATION_STATE_RUNNING, "armed": 1, "mode": mav.HQ_MODE_ANGLE,
        "excitation": 0.1, "angle_sp": 0.0, "rate_sp": 0.0, "rate": 0.2, "angle": 0.0,
        "axis_cmd": 0.1, "motor": [0.4] * 5 + [0.0] * 3, "motor_count": 5, "saturation": 0})


def test_telemetry_tap_logs_every_packet_with_its_loops_time(tmp_path):
    # Two loops' telemetry (ATTITUDE, then the loop's HQ_SYSID_SAMPLE), line noise in
    # between, and the start of a third loop: each packet is logged stamped with the time of
    # the next HQ_SYSID_SAMPLE, the noise is skipped, the third loop waits for its sample.
    from heliquad.host.records.tlog import read_tlog
    from heliquad.sim.base.dialect import dialect
    from heliquad.sim.base.framing import Codec

    mav = dialect()
    codec = Codec(mav, system_id=1, component_id=mav.MAV_COMP_ID_AUTOPILOT1)
    att = [codec.encode(mav.MAVLINK_MSG_ID_ATTITUDE, {
        "time_boot_ms": k, "roll": 0.1 * k, "pitch": 0.0, "yaw": 0.0, "rollspeed": 0.0,
        "pitchspeed": 0.0, "yawspeed": 0.0}) for k in range(3)]
    loops = [att[0], _sysid(codec, mav, 5000, 1), att[1], _sysid(codec, mav, 10000, 2)]
    stream = b"\x00\xfd\x03junk" + b"".join(loops[:2]) + b"\xfd\x02\x00" + b"".join(loops[2:]) + att[2]
    r, w = os.pipe()
    os.set_blocking(r, False)
    path = tmp_path / "tap.tlog"
    with open(path, "wb") as fh:
        tap = _simcore.TelemetryTap(r, fh.fileno(), [mav.MAVLINK_MSG_ID_HQ_SYSID_SAMPLE])
        os.write(w, stream[:37])                 # arrives in two pieces, split mid-packet
        first = tap.read()
        os.write(w, stream[37:])
        got = first + tap.read()
    os.close(r)
    os.close(w)
    assert [msgid for msgid, _ in got] == [mav.MAVLINK_MSG_ID_HQ_SYSID_SAMPLE] * 2
    assert [codec.decode(msgid, p).seq for msgid, p in got] == [1, 2]
    assert tap.last_time_us == 10000 and tap.packets == 5
    stamp = struct.Struct(">Q").pack
    assert path.read_bytes() == b"".join(
        stamp(t) + p for t, p in zip((5000, 5000, 10000, 10000), loops))
    assert [m.get_type() for _, m in read_tlog(str(path), mav)] == [
        "ATTITUDE", "HQ_SYSID_SAMPLE", "ATTITUDE", "HQ_SYSID_SAMPLE"]


def test_the_tap_stamps_the_runs_start_plus_each_loops_time(tmp_path):
    # A SIL log carries the wall clock of its run's start plus simulated time (tools show the
    # date the run was made); the tap's own clock stays simulated. The reader takes the
    # shared offset for a simulated log's and still names a record stamped otherwise.
    from heliquad.host.records.tlog import TlogDamage, read_tlog
    from heliquad.sim.base.dialect import dialect
    from heliquad.sim.base.framing import Codec

    mav = dialect()
    codec = Codec(mav, system_id=1, component_id=mav.MAV_COMP_ID_AUTOPILOT1)
    text = codec.encode(mav.MAVLINK_MSG_ID_STATUSTEXT, {
        "severity": 6, "text": b"hello", "id": 0, "chunk_seq": 0})
    start = 1_790_000_000_123_456                           # 2026-09-21, in us since 1970
    stream = b"".join(text + _sysid(codec, mav, 5000 * k, k) for k in range(1, 4))
    r, w = os.pipe()
    os.set_blocking(r, False)
    path = tmp_path / "tap.tlog"
    with open(path, "wb") as fh:
        tap = _simcore.TelemetryTap(r, fh.fileno(), [], start)
        os.write(w, stream + text)
        tap.read()
        tap.drain()
    os.close(r)
    os.close(w)
    assert tap.last_time_us == 15000 and tap.offset_us == start
    damage = TlogDamage()
    logged = read_tlog(str(path), mav, damage=damage)
    assert [t - start for t, _ in logged] == [5000, 5000, 10000, 10000, 15000, 15000, 15000]
    assert not damage
    data = bytearray(path.read_bytes())
    data[7] ^= 1                                            # the first record's stamp, 1 us off
    path.write_bytes(bytes(data))
    read_tlog(str(path), mav, damage=damage)
    assert damage.off_loop == [0]


def test_the_tap_drained_at_the_end_keeps_a_loop_cut_short(tmp_path):
    # The firmware said why it stopped (STATUSTEXT) and died before the loop's sample: at the
    # session's end the tap logs it with the last loop's time instead of dropping it.
    from heliquad.host.records.tlog import read_tlog
    from heliquad.sim.base.dialect import dialect
    from heliquad.sim.base.framing import Codec

    mav = dialect()
    codec = Codec(mav, system_id=1, component_id=mav.MAV_COMP_ID_AUTOPILOT1)
    text = codec.encode(mav.MAVLINK_MSG_ID_STATUSTEXT, {
        "severity": 2, "text": b"motors off: IMU stale", "id": 0, "chunk_seq": 0})
    r, w = os.pipe()
    os.set_blocking(r, False)
    path = tmp_path / "tap.tlog"
    with open(path, "wb") as fh:
        tap = _simcore.TelemetryTap(r, fh.fileno(), [mav.MAVLINK_MSG_ID_STATUSTEXT])
        os.write(w, _sysid(codec, mav, 5000, 1) + text)
        assert len(tap.read()) == 1                  # handed over; logged with its loop's time
        assert len(list(read_tlog(str(path), mav))) == 1         # which is not known yet
        os.write(w, text)
        got = tap.drain()
    os.close(r)
    os.close(w)
    assert len(got) == 1 and tap.packets == 3
    logged = list(read_tlog(str(path), mav))
    assert [m.get_type() for _, m in logged] == ["HQ_SYSID_SAMPLE", "STATUSTEXT", "STATUSTEXT"]
    assert [t for t, _ in logged] == [5000, 5000, 5000]
