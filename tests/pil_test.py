"""Processor in the loop against the host build: the same experiment on both firmwares.

The Teensy image and the host build compile the same core without fused multiply-adds, so
their single-precision arithmetic is the same bit for bit where no libm function is called
(checked here on the mixer, whose inputs the telemetry carries). What the board adds moves
the rest a little: its loop measures its own dt (the host build gets exactly 5 ms), and its
ESC pulses have one FTM0 count of resolution (1/15 000 of the range). The closed loop then
sometimes lands the plant's rate on the other side of one gyro count (0.061 deg/s); through
the rate loop's derivative gain and the mixer's roll coefficient that moves a motor by 7e-4
of full thrust. Tolerances follow from those figures, stated at each check.
"""

import math

import numpy as np
import pytest

from firmware_rig import FirmwareRig
from firmwares import image_for, start
from heliquad import _firmware
from heliquad.host.acquire.experiment import run_sil
from heliquad.host.estimate.fsf import estimate_fsf
from heliquad.host.records.run_csv import read_run_csv
from heliquad.host.records.tlog import read_tlog
from heliquad.sim.base.dialect import dialect
from heliquad.sim.chip.pil.board import ESC_MAX_US, ESC_MIN_US, FTM0_COUNTS_PER_US
from heliquad.sim.rig.setup import RC_CENTER_US, SilConfig

pytestmark = pytest.mark.pil
MAV = dialect()
ROLL = ((28.19,), (1.0, 5.13, 22.93))
#: Motor telemetry, host build against image, per loop: a gyro count's effect (see above),
#: with half as much again for the dt jitter acting through the same gains.
MOTOR_TOLERANCE = 1e-3


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("pil")
    result = {}
    for fw in ("host", "teensy35"):
        cfg = SilConfig(axis="roll", num=ROLL[0], den=ROLL[1], inject="mixer", freq_hz=1.0,
                        amplitude=0.05, cycles=4, fade_cycles=1, **image_for(fw))
        r = run_sil(cfg, str(out / fw), progress=lambda *_: None)
        samples = [m for _, m in read_tlog(r.tlog_path, MAV, only=("HQ_SYSID_SAMPLE",))]
        result[fw] = (cfg, r, samples)
    return result


def test_both_fly_the_same_loops_in_the_same_states(runs):
    (_, host, hs), (_, pil, ps) = runs["host"], runs["teensy35"]
    assert host.frames == pil.frames and len(hs) == len(ps) == host.frames
    assert host.seq_gaps == pil.seq_gaps == 0 and host.samples == pil.samples == 4 * 200
    for field in ("armed", "mode", "exc_state", "axis", "injection"):
        assert [getattr(m, field) for m in hs] == [getattr(m, field) for m in ps], field


def test_the_images_allocation_is_the_host_builds_bit_for_bit(runs):
    # While the excitation runs the sticks are still (throttle 1400 us) and only roll moves
    # (pitch and yaw see exact zeros: their commands are exactly 0), so each loop's motors
    # are allocate(throttle, axis_cmd, 0, 0): computed here by the host build's allocation
    # (from the same default geometry parameters) from the image's own telemetry, they must
    # be the image's motors to the last bit.
    cfg, _, ps = runs["teensy35"]
    rc = [RC_CENTER_US] * 8
    rc[2] = int(round(1000 + cfg.collective * 1000))
    throttle = _firmware.sticks(_firmware.RcInput(rc)).throttle
    allocation = _firmware.Allocation(_firmware.params_geometry())
    running = [m for m in ps if m.exc_state != MAV.HQ_EXCITATION_STATE_IDLE]
    assert len(running) > 4 * 200
    for m in running:
        command = _firmware.MixerCommand(throttle, m.axis_cmd, 0.0, 0.0)
        want = np.array(allocation.allocate(command).motor[:5], dtype=np.float32)
        assert m.motor_count == 5 and not any(m.motor[5:])
        assert np.array_equal(want, np.array(m.motor[:5], dtype=np.float32)), (m.seq, m.axis_cmd)


def test_motors_and_measurements_agree_within_what_the_board_adds(runs):
    (_, _, hs), (_, _, ps) = runs["host"], runs["teensy35"]
    mh = np.array([m.motor for m in hs], dtype=np.float64)
    mp = np.array([m.motor for m in ps], dtype=np.float64)
    assert np.abs(mh - mp).max() < MOTOR_TOLERANCE
    # The measured rate is the gyro's count times its scale on both: equal, or one count apart.
    gyro_count = math.radians(2000 / 32768)
    rh = np.array([m.rate for m in hs])
    rp = np.array([m.rate for m in ps])
    steps = np.abs(rh - rp) / gyro_count
    assert np.all((steps < 1e-6) | (np.abs(steps - 1) < 1e-3) | (np.abs(steps - 2) < 1e-3))
    assert np.mean(steps < 1e-6) > 0.8


def test_fsf_points_agree_within_a_tenth_of_a_db_and_half_a_degree(runs):
    points = {}
    for fw in ("host", "teensy35"):
        fs, u, y = read_run_csv(runs[fw][1].csv_path)
        points[fw] = estimate_fsf(u, y, fs)
    host, pil = points["host"], points["teensy35"]
    assert abs(20 * math.log10(pil.magnitude / host.magnitude)) < 0.1
    assert abs(math.degrees(np.angle(pil.gain / host.gain))) < 0.5


def test_the_esc_pulses_carry_the_commanded_thrust_to_one_ftm_count():
    # The reply's motors are read back from FTM0's pulse widths; the telemetry's are the
    # floats the image computed. They differ by the rounding to a count, no more.
    with start("teensy35") as fw:
        rig = FirmwareRig(fw)
        rig.hover(40)
        replies = [(rig.frame + 1, rig.step()) for _ in range(20)]
        rig.step(5)                                 # their telemetry is surely out
        samples = [m for _, m in rig.of_type("HQ_SYSID_SAMPLE")]
        rig.close()
    span = (ESC_MAX_US - ESC_MIN_US) * FTM0_COUNTS_PER_US
    for frame, reply in replies:
        sample = samples[frame - 1]                 # one loop per frame, from the first
        assert reply.armed and sample.armed and max(reply.motor) > 0.05
        for f, pulse in zip(sample.motor, reply.motor):
            counts = int(np.float32(f) * np.float32(span) + np.float32(0.5))
            assert round(pulse * span) == counts


def test_a_loop_longer_than_its_period_shows_as_overruns(tmp_path_factory):
    # A test build of the image (HQ_TEST_LOOP_DELAY_US) adds 6 ms of busy time to every
    # loop of its 5 ms period: the loop timer must count the ticks it missed, HQ_FW_STATUS
    # must report them, and the loop's cycles must show the stretch. The image as built
    # reports none, and a fraction of its budget.
    import teensy_image

    slow_dir = teensy_image.BUILD.parent / "teensy35-slow-loop"
    rc, log = teensy_image.build_preset(slow_dir, defines=("HQ_TEST_LOOP_DELAY_US=6000",))
    assert rc == 0, log[-3000:]
    budget = 600_000                                  # cycles of a 5 ms loop at 120 MHz
    for image, slow in ((str(teensy_image.image().elf), False),
                        (str(slow_dir / "heliquad-fw-teensy35.elf"), True)):
        from heliquad.sim.rig.lockstep import PilFirmware

        with PilFirmware(image=image) as fw:
            rig = FirmwareRig(fw)
            rig.hover(20)
            _, status = rig.until(lambda m: m.get_type() == "HQ_FW_STATUS" and m.loops > 100,
                                  max_frames=400)
            rig.close()
        if slow:
            assert status.loop_overruns > 10
            assert status.loop_cycles_max > budget
        else:
            assert status.loop_overruns == 0
            assert 0 < status.loop_cycles_max < budget / 4


def test_a_frame_is_answered_at_its_steps_outputs_and_the_rest_of_the_loop_changes_none():
    # The drop-in answers a frame where the step's outputs are final (hq_step_outputs) and
    # runs the loop's telemetry and USB work after the reply, while the simulator
    # integrates. That is only right if nothing after that point moves an output: through
    # arming, a hover with the gyro moving the rate loop, and disarming, the motors, armed,
    # mode and sensor kind read at that point must be those at the loop's end, every frame.
    import teensy_image
    from heliquad.sim.chip.pil.board import STEP_OUTPUTS_SYMBOL, PilBoard
    from heliquad.sim.sensor.mpu6050_packets import raw_packet

    board = PilBoard(str(teensy_image.image().elf), link="usb")
    board.boot()
    early_at = board.machine.image.symbol(STEP_OUTPUTS_SYMBOL).address
    rc = [1500, 1500, 1000, 1500, 1000, 1000, 0, 0]
    armed_frames, early = 0, 0
    for k in range(160):
        rc[4] = 2000 if 10 <= k < 130 else 1000          # arm, then disarm
        rc[2] = 1400 if 20 <= k < 120 else 1000
        rate = 0.3 * math.sin(k / 7.0)                    # rad/s: the rate loop works
        fifo = raw_packet([rate, -0.5 * rate, 0.1 * rate], [0.0, 0.0, -9.80665])
        answer = board.begin_frame(fifo, False, rc, MAV.HQ_IMU_FAULT_NONE)
        early += board.machine.pc & ~1 == early_at & ~1
        board.end_frame(sync=(k % 50 == 49))
        assert board.outputs() == answer, f"frame {k}"
        armed_frames += answer[1]
    assert early == 160                      # every frame was answered at the step's outputs
    assert 100 <= armed_frames <= 120        # and the outputs moved: armed, then disarmed
