"""Firmware in the loop: the firmware driven over ptys by the simulator.

Everything here runs a real firmware and talks to it over its two pseudo-terminals, as the
tools do: the host build (heliquad-fw-host) and, where a test is parametrised with
FIRMWARES, also the Teensy 3.5 image in the emulated chip (heliquad.sim.chip.pil; the ``pil``
mark). The two differ where the board does: the image's clock starts at its reset (its
loop times are offset by the boot and jitter by tens of microseconds), and its telemetry
leaves at the UART's line rate.
"""

import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fake_dmp import write_fake_dmp
from firmware_rig import FirmwareRig
from firmwares import FIRMWARES, image_for, start
from heliquad.host.acquire.experiment import run_sil
from heliquad.host.estimate.fsf import estimate_fsf
from heliquad.host.records.run_csv import read_run_csv
from heliquad.host.records.tlog import read_tlog
from heliquad.sim.base.dialect import dialect
from heliquad.sim.plant.tf_plant import TfPlant
from heliquad.sim.rig.lockstep import FirmwareError, HostFirmware, SimLink
from heliquad.sim.rig.setup import SilConfig

ROLL = ((28.19,), (1.0, 5.13, 22.93))
MAV = dialect()


@pytest.fixture(scope="module", params=FIRMWARES)
def mixer_run(request, tmp_path_factory):
    out = str(tmp_path_factory.mktemp("sil") / "roll_mixer")
    cfg = SilConfig(axis="roll", num=ROLL[0], den=ROLL[1], inject="mixer", freq_hz=1.0,
                    amplitude=0.05, cycles=10, **image_for(request.param))
    return cfg, run_sil(cfg, out, progress=lambda *_: None)


def test_sine_experiment_log_has_every_frame(mixer_run):
    cfg, r = mixer_run
    assert r.seq_gaps == 0 and r.saturated_samples == 0
    assert r.actual_freq_hz == pytest.approx(1.0) and r.samples == 10 * 200
    msgs = read_tlog(r.tlog_path, MAV)
    samples = [m for _, m in msgs if m.get_type() == "HQ_SYSID_SAMPLE"]
    assert len(samples) == r.frames
    assert [m.seq for m in samples] == list(range(samples[0].seq, samples[0].seq + r.frames))
    times = np.array([m.time_us for m in samples])
    # Stamped with the run's start (the wall clock) plus the loop's own time.
    stamps = [t for t, m in msgs if m.get_type() == "HQ_SYSID_SAMPLE"]
    assert list(np.array(stamps) - times) == [r.start_us] * r.frames
    if cfg.firmware == "host":
        # every timestamp comes from the simulated clock: 5 ms steps
        assert list(times) == [5000 * k for k in range(1, r.frames + 1)]
    else:
        # the image's own clock, from its reset: one loop per SysTick period of 5 ms, each
        # loop's time taken after its I2C reads, whose length varies (up to 14 bytes at
        # 375 kHz, 0.34 ms), so the steps jitter by less than half a millisecond
        steps = np.diff(times)
        assert np.all(np.abs(steps - 5000) < 500) and abs(steps.mean() - 5000) < 1


def from_start(path, start_us) -> bytes:
    """A log's bytes with the run's start taken off every record's stamp."""
    data, out, pos = open(path, "rb").read(), bytearray(), 0
    while pos < len(data):
        end = pos + 8 + 12 + data[pos + 9] + (13 if data[pos + 10] & 1 else 0)   # MAVLink 2
        out += (int.from_bytes(data[pos:pos + 8], "big") - start_us).to_bytes(8, "big")
        out += data[pos + 8:end]
        pos = end
    return bytes(out)


def test_two_runs_with_the_same_inputs_give_identical_telemetry(mixer_run, tmp_path):
    # The same run later: the same log once each run's start is taken off its stamps, and
    # byte for byte the same when it is given the same start.
    cfg, r = mixer_run
    again = run_sil(cfg, str(tmp_path / "again"), progress=lambda *_: None)
    assert from_start(again.tlog_path, again.start_us) == from_start(r.tlog_path, r.start_us)
    assert open(again.csv_path).read() == open(r.csv_path).read()
    same = run_sil(cfg, str(tmp_path / "same"), progress=lambda *_: None, start_us=r.start_us)
    assert open(same.tlog_path, "rb").read() == open(r.tlog_path, "rb").read()


def test_fsf_recovers_the_roll_model_from_a_mixer_injection_run(mixer_run):
    # Truth: the plant holds each command for one loop (zero-order hold), so the logged
    # (command, rate) pairs follow the ZOH discretisation of G at 5 ms; to first order that
    # is G(jw) e^{-jwT/2} sinc(wT/2), 0.9 deg of lag at 1 Hz.
    cfg, r = mixer_run
    fs, u, y = read_run_csv(r.csv_path)
    point = estimate_fsf(u, y, fs)
    assert point.method == "fsf" and point.period_samples == 200
    truth = TfPlant("roll", *ROLL, 0.005).truth(point.omega_rad_s)
    assert abs(point.magnitude / abs(truth) - 1) < 0.02
    assert abs(math.degrees(np.angle(point.gain / truth))) < 2.0


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_rate_loop_holds_a_rate_setpoint(firmware):
    # Rate mode (channel 6 high), roll stick at 1510 us: 0.02 of 200 deg/s = 0.0698 rad/s.
    plant = TfPlant("roll", *ROLL, 0.005)
    from heliquad import _firmware

    mixer = _firmware.Mixer()
    with start(firmware) as fw:
        link = SimLink(fw)
        kind = MAV.HQ_SENSOR_NONE
        for frame in range(1, 1201):
            rc = [1500, 1500, 1000, 1500, 1000, 2000, 0, 0]
            if frame > 20:
                rc[4] = 2000                                  # arm
            if frame > 40:
                rc[2], rc[0] = 1400, 1510                     # hover throttle, roll stick
            reply = link.step(frame * 5000, plant.fifo(kind), kind, rc)
            kind = reply.sensor_kind
            plant.step(mixer.achieved(reply.motor).roll)
        link.close()
    assert reply.armed and reply.mode == MAV.HQ_MODE_RATE
    assert plant.rate_rad_s == pytest.approx(0.02 * math.radians(200), rel=0.02)


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_repeated_frame_gets_the_same_reply_without_a_step(firmware):
    with start(firmware) as fw:
        link = SimLink(fw)
        first = link.step(5000)
        again = link.step(5000, frame=first.frame)            # the same counter once more
        assert again == first
        nxt = link.step(10000)
        assert nxt.frame == first.frame + 1
        link.close()


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_killing_the_firmware_mid_run_is_a_clear_error(firmware):
    with start(firmware) as fw:
        link = SimLink(fw)
        for k in range(1, 50):
            link.step(5000 * k)
        fw.proc.kill()
        t0 = time.monotonic()
        with pytest.raises(FirmwareError, match="died"):
            link.step(5000 * 50)
        assert time.monotonic() - t0 < 3.0
        link.close()


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_a_firmware_that_stops_answering_is_a_clear_error(firmware):
    with start(firmware, reply_timeout_s=3.0) as fw:
        link = SimLink(fw)
        link.step(5000)
        os.kill(fw.proc.pid, signal.SIGSTOP)
        try:
            with pytest.raises(FirmwareError, match="did not answer"):
                link.step(10000)
        finally:
            os.kill(fw.proc.pid, signal.SIGCONT)
        link.close()


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_firmware_exits_by_itself_when_the_simulator_goes_away(firmware, tmp_path):
    fw = start(firmware, idle_timeout_s=1)
    try:
        fw.proc.wait(timeout=5)
        assert fw.proc.returncode == 3
        assert "no sensor frame" in fw.stderr_tail()
    finally:
        fw.stop()


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args, match", [
    (["--freq-hz", "80", "--amplitude", "0.05"], "excitation band [0.05, 50] Hz"),
    (["--freq-hz", "1", "--amplitude", "5", "--axis", "yaw", "--inject", "angle"], "rate-only"),
    (["--freq-hz", "1", "--amplitude", "0.05", "--den", "0", "1"],
     "leading coefficient of the denominator is 0"),
    (["--freq-hz", "1", "--amplitude", "0.05", "--collective", "2"], "collective"),
])
def test_sil_bad_input_is_one_line_exit_2(args, match, tmp_path):
    res = heliquad("sil", *args, "--out", tmp_path / "run")
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and match in res.stderr


@pytest.mark.parametrize("fault, match", [
    ("bogus@4", "unknown fault 'bogus'"),
    ("silent", "expected KIND@T"),
    ("silent@-1", "non-negative"),
    ("reset@4:1", "takes no duration"),
    ("nack@4:0", "duration must be positive"),
    ("silent@x", "T and D are seconds"),
])
def test_sil_bad_fault_is_one_line_exit_2(fault, match, tmp_path):
    res = heliquad("sil", "--freq-hz", 1, "--amplitude", 0.05, "--fault", fault,
                   "--out", tmp_path / "run")
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and match in res.stderr


def test_sil_with_a_silent_imu_stops_with_the_firmwares_reason_and_keeps_the_log(tmp_path):
    # The IMU goes silent 4 s in, during the excitation: the firmware's IMU failsafe cuts the
    # motors, the run ends at once with that reason (exit 1), and the log and samples so far
    # are written.
    out = tmp_path / "silent"
    res = heliquad("sil", "--freq-hz", 1, "--amplitude", 0.05, "--fault", "silent@4",
                   "--out", out)
    assert res.returncode == 1 and "Traceback" not in res.stderr
    assert "stopped by the firmware: IMU stale" in res.stderr
    assert "firmware: failsafe: IMU stale, motors off" in res.stdout
    samples = [m for _, m in read_tlog(str(out) + ".tlog", MAV, only=("HQ_SYSID_SAMPLE",))]
    cut = next(m for m in samples if m.armed == 0 and m.time_us > 1_000_000)
    assert 4_000_000 < cut.time_us <= 4_000_000 + 25_000 + 5_000    # within the IMU timeout
    fs, u, y = read_run_csv(str(out) + ".csv")
    assert 0 < u.size < 10 * 200


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_free_running_board_streams_telemetry_in_real_time(firmware, tmp_path):
    # `heliquad board` paces the lockstep at real time; a tool connects to the telemetry
    # path like a serial port, sees 200 Hz samples without gaps, and, once the board is armed
    # and has the tool's heartbeat, can start an excitation. Pacing: the simulated clock never
    # runs ahead of the wall clock (it may fall behind on a loaded machine, so no lower bound).
    from heliquad.host.acquire.link import TelemetryLink

    port = tmp_path / "rig"
    # SIGINT back to its default in the child: a shell that ran the tests in the background
    # hands SIGINT down ignored, and then Python would never see the Ctrl-C sent below.
    env = dict(os.environ)
    if firmware != "host":                      # the image the tests built
        env["HQ_TEENSY35_ELF"] = image_for(firmware)["firmware_image"]
    launched = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "heliquad.host.cli.parser", "board", "--telemetry",
                             str(port), "--duration-s", "30", "--firmware", firmware,
                             "--backlog-bytes", "0"],          # every sample: no gap asserted
                            stdout=subprocess.PIPE, text=True, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        assert "board running" in proc.stdout.readline()
        link = TelemetryLink(str(port))
        samples, statuses, started = [], [], None
        deadline = time.monotonic() + 25.0          # a bound on a hang, not a timing check
        while len(samples) < 400 and time.monotonic() < deadline:
            link.heartbeat()
            for m in link.poll(only=("HQ_SYSID_SAMPLE", "HQ_EXCITATION_STATUS")):
                if m.get_type() == "HQ_SYSID_SAMPLE":
                    samples.append((time.monotonic(), m))
                    if m.armed and started is None:
                        link.start_excitation("roll", "mixer", 2.0, 0.05, 2, 1)
                        started = m.time_us
                else:
                    statuses.append(m)
            time.sleep(0.02)
        link.close()
    finally:
        proc.send_signal(signal.SIGINT)             # Ctrl-C: the board stops cleanly
        proc.wait(timeout=120)                      # a bound on a hang: a loaded machine is slow
    assert len(samples) >= 400, "the board did not stream"
    seqs = [m.seq for _, m in samples]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    wall1, last = samples[-1]
    # The board's clock starts at 0 after it was launched, and the last sample was received
    # after it was simulated: the wall time since the launch bounds its simulated time,
    # however slow the machine (a board that did not pace would be many times ahead). The
    # span between two received samples would not: a first sample delivered late shortens
    # the wall span (a loaded machine failed such a bound by 15 ms).
    assert last.time_us * 1e-6 <= wall1 - launched
    assert started is not None and statuses
    assert statuses[0].accepted and statuses[0].freq_hz == pytest.approx(2.0)
    assert not port.exists()


def test_dmp_path_end_to_end(tmp_path):
    # With a DMP image the firmware uploads and verifies it through the emulated chip, the
    # simulator then sends 42-byte DMP packets, and identification works the same. (The
    # image here is a made-up pattern: the emulated chip runs no DMP code, the simulator
    # computes the quaternion.)
    image = write_fake_dmp(tmp_path / "dmp.bin")
    cfg = SilConfig(axis="pitch", num=(33.64,), den=(1.0, 5.374, 23.65), inject="mixer",
                    freq_hz=2.0, amplitude=0.05, cycles=8, dmp_image=str(image))
    r = run_sil(cfg, str(tmp_path / "dmp"), progress=lambda *_: None)
    assert r.imu_mode == "dmp" and r.seq_gaps == 0
    fs, u, y = read_run_csv(r.csv_path)
    point = estimate_fsf(u, y, fs)
    truth = TfPlant("pitch", (33.64,), (1.0, 5.374, 23.65), 0.005).truth(point.omega_rad_s)
    assert abs(point.gain / truth - 1) < 0.02


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_rc_loss_cuts_the_motors(firmware):
    with start(firmware) as fw:
        rig = FirmwareRig(fw)
        reply = rig.hover(100)
        assert reply.armed and max(reply.motor) > 0.0
        rig.rc = [0] * 8                                        # no RC signal
        lost = rig.step()
        if firmware != "host":
            # The board hears no pulses: each channel reads "no signal" 100 ms after its
            # last one, and the link counts as lost 0.5 s after the sticks' last (safety.md).
            frames = 1
            while lost.armed and frames < 200:
                lost, frames = rig.step(), frames + 1
            assert frames * 5000 <= 500_000 + 5000
        assert not lost.armed and lost.motor == [0.0] * 5
        rig.close()


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_arming_is_refused_with_the_throttle_up(firmware):
    with start(firmware) as fw:
        rig = FirmwareRig(fw)
        rig.rc[2] = 1500                                        # throttle up, then the switch
        rig.step(20)
        rig.rc[4] = 2000
        reply = rig.step(40)
        assert not reply.armed and reply.motor == [0.0] * 5
        texts = [m.text for _, m in rig.of_type("STATUSTEXT")]
        assert "arming refused: throttle not low" in texts
        rig.close()


def test_a_full_telemetry_link_drops_and_counts_without_blocking_the_loop():
    with HostFirmware() as fw:
        rig = FirmwareRig(fw)
        rig.hover(20)
        def step():
            rig.frame += 1
            reply = rig.link.step(rig.time_us, rig.plant.fifo(rig.kind), rig.kind, rig.rc)
            rig.plant.step_motors(reply.motor)
            return reply

        for _ in range(4000):           # ~460 kB of telemetry nobody reads: lockstep goes on
            reply = step()
        assert reply.armed
        fw_status, latest = MAV.MAVLINK_MSG_ID_HQ_FW_STATUS, None
        for _ in range(4000):           # now read while stepping, until a fresh status
            step()
            for msgid, _, payload in rig.tel.read_packets():
                if msgid == fw_status:
                    latest = rig.tel.codec.decode(msgid, payload)
            if latest is not None and latest.loops > 4000:
                break
        assert latest is not None and latest.loops > 4000
        assert latest.telemetry_dropped > 0
        rig.close()


def _rig_points():
    """Five log-spaced frequencies over each axis's Table 1 band (docs/paper.md), with an amplitude
    that keeps the response well above the gyro's quantisation: the closed yaw loop holds
    the yaw rate to a few 0.001 rad/s LSBs below 0.4 Hz unless the excitation is large."""
    from heliquad.host.records import paper

    points = []
    for axis in ("roll", "pitch", "yaw"):
        lo, hi = paper.BANDS_HZ[axis]
        for f in np.logspace(math.log10(lo), math.log10(hi), 5):
            amplitude = 0.05 if axis != "yaw" else (1.0 if f < 0.4 else 0.3)
            points.append((axis, round(float(f), 4), amplitude))
    return points


@pytest.mark.parametrize("axis, freq_hz, amplitude", _rig_points())
def test_vehicle_rig_identification_matches_the_simulators_truth(axis, freq_hz, amplitude, tmp_path):
    # Issue 4: the 6-DoF vehicle on its one-axis rig, the firmware flying it in angle mode,
    # noise-free, mixer injection; the FSF point matches the model linearised at the rig's
    # trim (through the firmware's mixer), ZOH-sampled, within 0.5 dB and 3 deg.
    from heliquad.sim.plant.vehicle_plant import VehiclePlant

    cfg = SilConfig(axis=axis, inject="mixer", freq_hz=freq_hz, amplitude=amplitude, cycles=5,
                    plant="vehicle", rig=axis, ideal_sensor=True)
    r = run_sil(cfg, str(tmp_path / axis), progress=lambda *_: None)
    assert r.saturated_samples == 0 and r.seq_gaps == 0
    fs, u, y = read_run_csv(r.csv_path)
    point = estimate_fsf(u, y, fs)
    truth = VehiclePlant(axis, axis, 0.005, ideal_sensor=True).truth(point.omega_rad_s)
    assert abs(20 * math.log10(point.magnitude / abs(truth))) < 0.5
    assert abs(math.degrees(np.angle(point.gain / truth))) < 3.0


def fly_free(dmp_image, frames, step_at=None, roll_stick_us=None):
    """The vehicle in free flight at hover throttle, armed, angle mode, ideal IMU (the
    control behaviour itself); roll and pitch angles (deg)."""
    from heliquad.sim.plant.vehicle import GRAVITY_M_S2
    from heliquad.sim.plant.vehicle_plant import VehiclePlant

    plant = VehiclePlant("roll", "free", 0.005, ideal_sensor=True)
    hover = plant.params.body.mass_kg * GRAVITY_M_S2 / plant.allocation.units[0]
    throttle = int(round(1000 + 1000 * hover))
    roll, pitch = [], []
    with HostFirmware(dmp_image=dmp_image) as fw:
        assert fw.imu_mode == ("dmp" if dmp_image else "raw")
        link = SimLink(fw)
        kind = MAV.HQ_SENSOR_NONE
        for frame in range(1, frames + 1):
            rc = [1500, 1500, 1000 if frame < 30 else throttle, 1500,
                  1000 if frame < 15 else 2000, 1500, 0, 0]
            if step_at is not None and frame > step_at:
                rc[0] = roll_stick_us
            reply = link.step(frame * 5000, plant.fifo(kind), kind, rc)
            kind = reply.sensor_kind
            plant.step_motors(reply.motor)
            w, x, y, z = plant.vehicle.x[6:10]
            roll.append(math.degrees(math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))))
            pitch.append(math.degrees(math.asin(max(-1.0, min(1.0, 2 * (w * y - x * z))))))
        link.close()
    return np.array(roll), np.array(pitch)


def test_free_flight_hover_is_level_and_a_10_degree_roll_step_settles(tmp_path):
    # The paper's gains, angle mode, DMP attitude. Stick 1667 us = 1/3 of 30 deg = 10 deg.
    image = write_fake_dmp(tmp_path / "dmp.bin")
    roll, pitch = fly_free(str(image), 2200, step_at=1000, roll_stick_us=1500 + round(500 / 3))
    hover = slice(200, 1000)                   # 1 s after arming until the step
    assert np.max(np.abs(roll[hover])) < 0.2 and np.max(np.abs(pitch[hover])) < 0.2
    after = roll[1000:]
    assert after.max() < 11.0                  # no more than 1 deg of overshoot
    assert np.all(np.abs(after[600:] - 10.0) < 0.5)   # settled within 3 s of the step
    assert np.max(np.abs(pitch[1000:])) < 1.0


def test_free_flight_10_degree_roll_step_on_the_raw_path_overshoots_by_less_than_a_degree():
    # The raw FIFO path: the firmware's ComplementaryFilter, not the DMP, gives the attitude.
    # While the vehicle banks it accelerates sideways and its accelerometer reads the thrust
    # axis; the filter's tilt weight (docs/mpu6050.md) keeps that from pulling the estimate
    # level. Bound: the DMP path's own (above, 1 deg of overshoot; the DMP path measures
    # 0.01 deg, as the simulator's DMP is exact), against the simulator's true roll. Measured
    # 10.07 deg; the unweighted filter this replaces reached 19.5 deg.
    roll, pitch = fly_free(None, 2200, step_at=1000, roll_stick_us=1500 + round(500 / 3))
    hover = slice(200, 1000)
    assert np.max(np.abs(roll[hover])) < 0.2 and np.max(np.abs(pitch[hover])) < 0.2
    after = roll[1000:]
    assert after.max() < 11.0
    assert np.all(np.abs(after[600:] - 10.0) < 0.5)   # settled within 3 s of the step
    assert np.max(np.abs(pitch[1000:])) < 1.0


def test_free_flight_hover_in_moderate_turbulence_stays_within_a_degree(tmp_path):
    # Stated bound: |roll| and |pitch| below 1 deg over 19 s of hover in moderate Dryden
    # turbulence, with the realistic IMU (noise, residual bias, DMP latency). The model applies gusts as drag
    # through the centre of mass and gust rates through rotational damping; rotor blowback
    # (gust-velocity moments) is not modelled yet, which is why the bound is this tight.
    from heliquad.sim.plant.vehicle import GRAVITY_M_S2
    from heliquad.sim.plant.vehicle_plant import VehiclePlant

    image = write_fake_dmp(tmp_path / "dmp.bin")
    plant = VehiclePlant("roll", "free", 0.005, turbulence="moderate", seed=1)
    throttle = int(round(1000 + 1000 * plant.params.body.mass_kg * GRAVITY_M_S2
                         / plant.allocation.units[0]))
    worst = 0.0
    with HostFirmware(dmp_image=str(image)) as fw:
        link = SimLink(fw)
        kind = MAV.HQ_SENSOR_NONE
        for frame in range(1, 4001):
            rc = [1500, 1500, 1000 if frame < 30 else throttle, 1500,
                  1000 if frame < 15 else 2000, 1500, 0, 0]
            reply = link.step(frame * 5000, plant.fifo(kind), kind, rc)
            kind = reply.sensor_kind
            plant.step_motors(reply.motor)
            if frame > 200:
                w, x, y, z = plant.vehicle.x[6:10]
                roll = math.degrees(math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)))
                pitch = math.degrees(math.asin(max(-1.0, min(1.0, 2 * (w * y - x * z)))))
                worst = max(worst, abs(roll), abs(pitch))
        link.close()
    assert 0.0 < worst < 1.0


def test_identification_with_a_realistic_imu_needs_its_latency_in_the_truth(tmp_path):
    # Gyro and accelerometer noise at the datasheet's densities, a residual gyro bias, and the
    # DMP's one-sample latency: the logged rate is one loop late, so the truth carries z^-1.
    from heliquad.sim.plant.vehicle_plant import VehiclePlant

    cfg = SilConfig(axis="roll", inject="mixer", freq_hz=2.0, amplitude=0.05, cycles=10,
                    plant="vehicle", rig="roll", seed=2)
    r = run_sil(cfg, str(tmp_path / "noisy"), progress=lambda *_: None)
    fs, u, y = read_run_csv(r.csv_path)
    point = estimate_fsf(u, y, fs)
    with_latency = VehiclePlant("roll", "roll", 0.005).truth(point.omega_rad_s)
    assert abs(20 * math.log10(point.magnitude / abs(with_latency))) < 0.5
    assert abs(math.degrees(np.angle(point.gain / with_latency))) < 1.0
    assert 0.9 < point.coherence < 1.0                     # the noise is really there
    ideal = VehiclePlant("roll", "roll", 0.005, ideal_sensor=True).truth(point.omega_rad_s)
    assert math.degrees(np.angle(point.gain / ideal)) < -2.5   # 5 ms at 2 Hz is 3.6 deg


@pytest.mark.parametrize("axis, inject, freq_hz, amplitude_deg", [
    ("roll", "rate", 0.5, 10.0), ("roll", "rate", 4.5, 10.0),
    ("roll", "angle", 0.5, 5.0), ("roll", "angle", 4.5, 5.0),
    ("yaw", "rate", 1.0, 10.0),
])
def test_closed_loop_injection_matches_the_cascade_truth(axis, inject, freq_hz, amplitude_deg, tmp_path):
    # Rate injection: u = rate setpoint, y = rate, the inner loop closed through the firmware's
    # discrete PID; angle injection: u = angle setpoint, y = angle, the whole cascade. The truth
    # transcribes the Pid's Tustin recurrences into z (sim.plant.pid_model.pid_z). DMP path, so the
    # logged angle is the attitude itself.
    from heliquad.sim.plant.vehicle_plant import VehiclePlant

    image = write_fake_dmp(tmp_path / "dmp.bin")
    cfg = SilConfig(axis=axis, inject=inject, freq_hz=freq_hz, amplitude=math.radians(amplitude_deg),
                    cycles=5, plant="vehicle", rig=axis, ideal_sensor=True, dmp_image=str(image))
    r = run_sil(cfg, str(tmp_path / "cl"), progress=lambda *_: None)
    assert r.imu_mode == "dmp" and r.saturated_samples == 0
    fs, u, y = read_run_csv(r.csv_path)
    point = estimate_fsf(u, y, fs)
    truth = VehiclePlant(axis, axis, 0.005, ideal_sensor=True).truth(point.omega_rad_s, inject=inject)
    assert abs(20 * math.log10(point.magnitude / abs(truth))) < 0.5
    assert abs(math.degrees(np.angle(point.gain / truth))) < 3.0


@pytest.mark.parametrize("old, new, match", [
    ("mass_kg = 0.930", "mass_kg = -0.93", "body.mass_kg must be positive"),
    ("mass_kg = 0.930", "mass_g = 930", "unknown key body.mass_g"),
    ("time_constant_s = 0.15", "", "missing key rotors[1].time_constant_s"),
])
def test_sil_with_a_bad_parameter_file_is_one_line_naming_the_key(old, new, match, tmp_path):
    import importlib.resources

    text = importlib.resources.files("heliquad.sim.plant").joinpath("vehicle.toml").read_text()
    bad = tmp_path / "vehicle.toml"
    bad.write_text(text.replace(old, new, 1))
    res = heliquad("sil", "--plant", "vehicle", "--freq-hz", 1, "--amplitude", 0.05,
                   "--params", bad, "--out", tmp_path / "run")
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and match in res.stderr
