"""The safety rules end to end: the real firmware over its two ptys, driven through the link
contract (docs/link-contract.md, docs/safety.md): the host build, and the Teensy 3.5 image in
the emulated chip (the ``pil`` mark). Every bound is checked in firmware time (the loop times
the telemetry carries), never in wall time."""

import math

import pytest

from fake_dmp import write_fake_dmp
from firmware_rig import DT_US, MAV, FirmwareRig
from firmwares import FIRMWARES, start
from heliquad.sim.rig.lockstep import HostFirmware

IMU_TIMEOUT_US = 25000          # five samples of the 200 Hz sensor
HOST_TIMEOUT_US = 1500000


def reason(name):
    return getattr(MAV, "HQ_REASON_" + name)


@pytest.fixture(params=FIRMWARES)
def rig(request):
    with start(request.param) as fw:
        r = FirmwareRig(fw)
        yield r
        r.close()


@pytest.fixture
def dmp_rig(tmp_path):
    # The emulated chip runs no DMP code; made-up firmware of the right form exercises the
    # MotionApps set-up and the emulator's check of it.
    with HostFirmware(dmp_image=write_fake_dmp(tmp_path / "dmp.bin")) as fw:
        r = FirmwareRig(fw)
        yield r
        r.close()


def texts(rig, since_us=0):
    return [m.text for _, m in rig.of_type("STATUSTEXT", since_us)]


def test_an_excitation_is_refused_while_disarmed_and_says_why(rig):
    rig.step(20)
    rig.ping()
    t, status = rig.excitation_answer()
    assert status.accepted == 0 and status.reason == reason("DISARMED")
    assert status.state == MAV.HQ_EXCITATION_STATE_IDLE
    assert "excitation refused: disarmed" in texts(rig, t)
    rig.hover(40)                                 # arming later does not start it
    samples = [m for _, m in rig.of_type("HQ_SYSID_SAMPLE", t)]
    assert all(m.exc_state == MAV.HQ_EXCITATION_STATE_IDLE and m.excitation == 0.0
               for m in samples)


def test_an_unknown_excitation_action_is_refused_and_a_running_excitation_goes_on(rig):
    # An HQ_EXCITATION whose action is none of STOP, START, FINISH (a newer host, a bit
    # flip) is refused with its reason; it neither starts nor stops anything.
    from heliquad.host.acquire.link import TARGET_SYSTEM

    rig.hover()
    rig.ping()
    _, status = rig.excitation_answer(freq_hz=2.0, cycles=20)
    assert status.accepted
    rig.tel.mav.hq_excitation_send(TARGET_SYSTEM, rig.tel.target, 7, MAV.HQ_AXIS_PITCH,
                                   MAV.HQ_INJECTION_MIXER, 3.0, 0.5, 5, 1)
    t, answer = rig.until(lambda m: m.get_type() == "HQ_EXCITATION_STATUS")
    assert answer.accepted == 0 and answer.reason == reason("BAD_ACTION")
    assert answer.state != MAV.HQ_EXCITATION_STATE_IDLE and answer.axis == MAV.HQ_AXIS_ROLL
    assert "excitation refused: unknown action" in texts(rig, t)
    rig.ping()
    rig.step(20)
    samples = [m for _, m in rig.of_type("HQ_SYSID_SAMPLE", t)]
    assert samples and all(m.exc_state != MAV.HQ_EXCITATION_STATE_IDLE
                           and m.axis == MAV.HQ_AXIS_ROLL for m in samples)
    _, fw_status = rig.until(lambda m: m.get_type() == "HQ_FW_STATUS")
    assert fw_status.exc_refused == 1 and fw_status.last_reason == reason("BAD_ACTION")


@pytest.mark.parametrize("change, why", [
    ({"amplitude": 1e30}, "AMPLITUDE"),
    ({"amplitude": float("nan")}, "AMPLITUDE"),
    ({"freq_hz": 1e-9}, "FREQUENCY"),
    ({"freq_hz": 80.0}, "FREQUENCY"),
    ({"cycles": 65535, "freq_hz": 1.0}, "DURATION"),
    ({"fade_cycles": 0}, "FADE"),
])
def test_absurd_excitations_are_refused(rig, change, why):
    rig.hover()
    rig.ping()
    _, status = rig.excitation_answer(**change)
    assert status.accepted == 0 and status.reason == reason(why)
    _, fw_status = rig.until(lambda m: m.get_type() == "HQ_FW_STATUS")
    assert fw_status.exc_refused == 1 and fw_status.last_reason == reason(why)


def test_an_excitation_stops_within_1_5_s_of_the_hosts_last_heartbeat(rig):
    rig.hover()
    rig.ping()
    _, status = rig.excitation_answer(cycles=60)
    assert status.accepted
    last_heartbeat = rig.ping()                   # the last one the firmware processed
    t_end, end = rig.until(lambda m: m.get_type() == "HQ_EXCITATION_STATUS"
                           and m.state == MAV.HQ_EXCITATION_STATE_IDLE, max_frames=400)
    assert end.reason == reason("HOST_LOST")
    assert HOST_TIMEOUT_US < end.time_us - last_heartbeat <= HOST_TIMEOUT_US + DT_US
    assert rig.reply.armed                        # armed by the switch: it keeps flying


def test_the_rc_switch_disarms_a_vehicle_armed_by_command(rig):
    rig.rc[4] = 2000                              # switch high from the start: no edge
    rig.step(20)
    assert not rig.reply.armed
    rig.tel.heartbeat()
    rig.tel.arm(True)
    _, ack = rig.until(lambda m: m.get_type() == "COMMAND_ACK" and m.command == 400)
    assert ack.result == MAV.MAV_RESULT_ACCEPTED and rig.step().armed
    rig.rc[4] = 1000
    reply = rig.step()
    assert not reply.armed and reply.motor == [0.0] * 5
    assert "disarmed by RC switch" in texts(rig)


def test_our_own_heartbeat_echoed_back_does_not_count_as_the_hosts(rig):
    # A router that echoes the vehicle's HEARTBEAT (system 1) must not keep an excitation
    # alive: only the host's count.
    rig.hover()
    rig.ping()
    _, status = rig.excitation_answer(cycles=60)
    assert status.accepted
    last_heartbeat = rig.ping()
    echo = MAV.MAVLink(None, srcSystem=1, srcComponent=1)
    for _ in range(400):
        rig.tel.write(echo.heartbeat_encode(2, 0, 0, 0, 0).pack(echo))
        rig.step()
        ends = [m for _, m in rig.of_type("HQ_EXCITATION_STATUS", last_heartbeat)
                if m.state == MAV.HQ_EXCITATION_STATE_IDLE]
        if ends:
            break
    assert ends and ends[0].reason == reason("HOST_LOST")
    assert ends[0].time_us - last_heartbeat <= HOST_TIMEOUT_US + DT_US


def test_arming_by_command_is_refused_without_a_live_rc_link(rig):
    rig.rc = [0] * 8
    rig.step(20)
    rig.tel.heartbeat()
    rig.tel.arm(True)
    _, ack = rig.until(lambda m: m.get_type() == "COMMAND_ACK" and m.command == 400)
    assert ack.result == MAV.MAV_RESULT_DENIED and ack.result_param2 == reason("NO_RC")
    assert not rig.step().armed


def test_a_silent_imu_cuts_the_motors_within_its_timeout(rig):
    rig.hover()
    last_sample = rig.time_us
    reply = rig.step(imu_fault=MAV.HQ_IMU_FAULT_SILENT)
    while reply.armed:
        assert max(reply.motor) > 0.0
        reply = rig.step(imu_fault=MAV.HQ_IMU_FAULT_SILENT)
    assert reply.motor == [0.0] * 5
    assert rig.time_us - last_sample <= IMU_TIMEOUT_US + DT_US
    assert "failsafe: IMU stale, motors off" in texts(rig)
    # Disarmed, the firmware probes the chip: it answers, configured, but sends nothing.
    rig.until(lambda m: m.get_type() == "STATUSTEXT"
              and m.text == "IMU delivers no samples; re-initialising",
              imu_fault=MAV.HQ_IMU_FAULT_SILENT, max_frames=250)
    _, status = rig.until(lambda m: m.get_type() == "HQ_FW_STATUS", imu_fault=MAV.HQ_IMU_FAULT_SILENT)
    assert status.imu_stale == 1 and status.armed == 0


def test_a_nacking_imu_cuts_the_motors_and_says_it_does_not_answer(rig):
    rig.hover(200)
    t_nack = rig.last_loop_us() + 1             # from the next loop on
    reply = rig.step(6, imu_fault=MAV.HQ_IMU_FAULT_NACK)
    assert not reply.armed and reply.motor == [0.0] * 5
    rig.step(100, imu_fault=MAV.HQ_IMU_FAULT_NACK)
    assert texts(rig, t_nack)[:2] == ["failsafe: IMU stale, motors off", "IMU does not answer"]
    # The chip answers again: its FIFO overflowed meanwhile; the driver resynchronises.
    rig.until(lambda m: m.get_type() == "STATUSTEXT" and m.text == "IMU recovered")


def test_a_stuck_bus_cuts_the_motors_is_counted_and_the_loop_goes_on(rig):
    # A device holds the I2C clock low. On the emulated Teensy no byte ends: each transfer
    # times out at the next SysTick (the byte waits sleep until then) and ends in a bus
    # recovery; the host build fails each transfer at once, as for a NACK. Either way the
    # IMU goes stale, the failsafe cuts the motors, the failures are counted, and the loop
    # keeps running; when the bus is released the chip is read again.
    stuck = MAV.HQ_IMU_FAULT_STUCK_BUS
    rig.hover(200)
    _, before = rig.until(lambda m: m.get_type() == "HQ_FW_STATUS", max_frames=250)
    first = rig.frame + 1
    reply = rig.step(imu_fault=stuck)
    while reply.armed and rig.frame - first < 50:
        assert max(reply.motor) > 0.0
        reply = rig.step(imu_fault=stuck)
    assert not reply.armed and reply.motor == [0.0] * 5
    # stale after 25 ms of samples, noticed within one more loop (the timeout's tick)
    assert (rig.frame - first) * DT_US <= IMU_TIMEOUT_US + 2 * DT_US
    _, during = rig.until(lambda m: m.get_type() == "HQ_FW_STATUS" and m.loops > before.loops,
                          imu_fault=stuck, max_frames=250)
    assert during.imu_bus_errors > before.imu_bus_errors and during.imu_stale == 1
    assert during.loops >= before.loops + 150                   # a second later: still looping
    rig.until(lambda m: m.get_type() == "STATUSTEXT" and m.text == "IMU recovered",
              max_frames=400)


def test_a_fifo_overflow_is_resynchronised_without_a_failsafe(rig):
    rig.hover()
    reply = rig.step(imu_fault=MAV.HQ_IMU_FAULT_OVERFLOW)
    reply = rig.step(40)
    assert reply.armed
    _, status = rig.until(lambda m: m.get_type() == "HQ_FW_STATUS" and m.time_us > 0)
    assert status.imu_overflows >= 1 and status.imu_resyncs >= 1 and status.imu_stale == 0


def test_a_reset_chip_is_detected_and_the_dmp_path_comes_back_after_disarm(dmp_rig):
    rig = dmp_rig
    reply = rig.hover()
    assert reply.armed and reply.sensor_kind == MAV.HQ_SENSOR_DMP
    t_reset, frame_reset = rig.last_loop_us() + 1, rig.frame + 1
    reply = rig.step(imu_fault=MAV.HQ_IMU_FAULT_RESET)        # a brown-out
    while reply.armed:
        reply = rig.step()
    assert (rig.frame - frame_reset) * DT_US <= IMU_TIMEOUT_US + DT_US
    t_back, _ = rig.until(lambda m: m.get_type() == "STATUSTEXT" and m.text == "IMU recovered",
                          max_frames=400)
    assert "IMU lost its configuration; re-initialising" in texts(rig, t_reset)
    reply = rig.step()
    assert reply.sensor_kind == MAV.HQ_SENSOR_DMP and not reply.armed
    _, status = rig.until(lambda m: m.get_type() == "HQ_FW_STATUS" and m.time_us > t_back)
    assert status.imu_resets == 1 and status.imu_reinits == 1 and status.sensor_kind == MAV.HQ_SENSOR_DMP
    # The emulated chip takes DMP packets only after the whole MotionApps set-up since its
    # reset (image, configuration table, registers, updates): that it flies again shows that
    # recover_imu() did all of it.
    rig.rc[4] = 1000                                            # the pilot re-arms: it flies
    rig.step(5)
    rig.rc[2] = 1000
    rig.rc[4] = 2000
    rig.step(5)
    rig.rc[2] = 1400
    reply = rig.step(40)
    assert reply.armed and max(reply.motor) > 0.0


def test_statustext_carries_only_its_string(rig):
    rig.rc[2] = 1500                               # throttle up: arming is refused
    rig.step(5)
    rig.rc[4] = 2000
    rig.step(5)
    rig.settle_telemetry()
    rig.tel.read_packets()
    # Raw packets: the text field is bytes 1..50 of the payload (severity first), and every
    # byte after the string's end is zero (MAVLink 2 may also trim trailing zeros).
    rig.rc[4] = 1000
    rig.step(2)
    rig.rc[4] = 2000
    found = []
    for _ in range(40):
        rig.frame += 1
        reply = rig.link.step(rig.time_us, rig.plant.fifo(rig.kind), rig.kind, rig.rc)
        rig.kind = reply.sensor_kind
        rig.plant.step_motors(reply.motor)
        found += [payload for msgid, _, payload in rig.tel.read_packets()
                  if msgid == MAV.MAVLINK_MSG_ID_STATUSTEXT]
        if found:
            break
    assert found, "no STATUSTEXT"
    text = found[0][1:51]
    end = text.index(0) if 0 in text else len(text)
    assert text[:end] == b"arming refused: throttle not low"
    assert all(b == 0 for b in text[end:])


def test_heartbeat_and_samples_report_the_three_facts(rig):
    rig.rc[5] = 0                                   # no mode switch signal
    rig.hover()
    rig.ping()
    rig.tel.set_mode("rate")
    _, status = rig.excitation_answer(injection="rate", amplitude=math.radians(30), freq_hz=2.0)
    assert status.accepted
    t_run, _ = rig.until(lambda m: m.get_type() == "HQ_SYSID_SAMPLE"
                         and m.exc_state == MAV.HQ_EXCITATION_STATE_RUNNING)
    rig.tel.heartbeat()
    _, hb = rig.until(lambda m: m.get_type() == "HEARTBEAT", max_frames=250)
    rig.tel.heartbeat()
    rig.step(100)                                   # a whole period of the 2 Hz sine
    assert hb.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED and hb.custom_mode == MAV.HQ_MODE_RATE
    samples = [m for _, m in rig.of_type("HQ_SYSID_SAMPLE", t_run)]
    assert all(m.armed == 1 and m.mode == MAV.HQ_MODE_RATE for m in samples)
    # Rate mode chosen by SET_MODE with channel 6 silent: the rate loop runs, so the roll rate
    # setpoint is the excitation itself (stick centred).
    running = [m for m in samples if m.exc_state == MAV.HQ_EXCITATION_STATE_RUNNING]
    assert running and all(m.rate_sp == pytest.approx(m.excitation, abs=1e-6) for m in running)
    assert max(abs(m.excitation) for m in running) == pytest.approx(math.radians(30), rel=1e-3)
