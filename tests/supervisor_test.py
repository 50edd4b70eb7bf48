"""The controller's state and safety rules (firmware/core/supervisor.cpp), loop by loop
through the bindings: one test per rule of docs/safety.md."""

import math

import pytest

from heliquad import _firmware as fw
from heliquad.sim.base.dialect import dialect
from heliquad.sim.base.firmware_facts import LOOP_RATE_HZ as LOOP_HZ

MAV = dialect()
DT_US = round(1e6 / LOOP_HZ)
LIMITS = fw.SafetyLimits()


def reason(name: str) -> int:
    return getattr(MAV, "HQ_REASON_" + name)


def rc(arm=False, throttle=1000, mode=1000, age_us=0, roll=1500):
    """RC channels: roll, pitch, throttle, yaw, arm switch, mode switch (0 = no signal)."""
    return fw.RcInput([roll, 1500, throttle, 1500, 2000 if arm else 1000, mode, 0, 0], age_us)


def config(axis=fw.Axis.ROLL, inj=fw.Injection.MIXER, freq=1.0, amp=0.1, cycles=4, fade=1):
    c = fw.ExcitationConfig()
    c.axis, c.injection, c.freq_hz, c.amplitude, c.cycles, c.fade_cycles = axis, inj, freq, amp, cycles, fade
    return c


class Bench:
    """A Supervisor and its clock: one update() per 5 ms loop."""

    def __init__(self, limits=None):
        self.sup = fw.Supervisor(limits or fw.SafetyLimits(), LOOP_HZ)
        self.sup.imu_initialised(0, fw.imu_timeout_for(200.0))
        self.t = 0
        self.rc = rc()

    def step(self, n=1, imu=True, attitude=None, rate=None):
        """n loops with the current RC; this loop's excitation values."""
        out = []
        for _ in range(n):
            self.t += DT_US
            out.append(self.sup.update(fw.SupervisorInputs(
                self.t, self.rc, imu, attitude or fw.Euler(), rate or fw.Vec3())))
        return out

    def arm_by_switch(self):
        self.rc = rc(arm=False)
        self.step(2)
        self.rc = rc(arm=True)
        self.step()
        assert self.sup.armed and self.sup.arm_source == fw.ArmSource.RC_SWITCH

    def heartbeat(self):
        self.sup.host_heartbeat(self.t)

    def reasons(self):
        return [e.reason for e in self.sup.events()]


# --- arming ---------------------------------------------------------------------------------

@pytest.mark.parametrize("channels, why", [
    (rc(arm=True, age_us=LIMITS.rc_timeout_us + 1), "NO_RC"),
    (rc(arm=False), "ARM_SWITCH_LOW"),
    (rc(arm=True, throttle=0), "NO_THROTTLE"),
    (rc(arm=True, throttle=1100), "THROTTLE_HIGH"),
])
def test_arming_by_command_needs_a_live_rc_link_the_switch_high_and_the_throttle_low(channels, why):
    b = Bench()
    b.heartbeat()
    b.step(4)
    assert b.sup.arm_command(channels, b.t) == reason(why)
    assert not b.sup.armed and b.sup.counters.arm_refused == 1
    assert b.reasons() == [reason(why)] and b.sup.last_reason == reason(why)


def test_arming_by_command_works_when_every_check_passes():
    b = Bench()
    b.rc = rc(arm=True)
    b.heartbeat()
    b.step(4)
    assert not b.sup.armed                     # the switch was high from the start: no edge
    assert b.sup.arm_command(b.rc, b.t) == reason("NONE")
    assert b.sup.armed and b.sup.arm_source == fw.ArmSource.COMMAND


def test_arming_needs_a_fresh_imu_sample():
    b = Bench()
    b.rc = rc(arm=True)                        # high from the start: only a command can arm
    b.heartbeat()
    b.step(4, imu=False)                       # the IMU never delivered
    assert b.sup.arm_command(b.rc, b.t) == reason("IMU_NOT_READY")
    b.step(1)
    b.step(6, imu=False)                       # 30 ms without a sample: stale
    assert b.sup.arm_command(b.rc, b.t) == reason("IMU_NOT_READY")
    assert not b.sup.armed
    b.step(1)                                  # fresh again
    assert b.sup.arm_command(b.rc, b.t) == reason("NONE") and b.sup.armed


def test_the_arm_switch_arms_only_on_an_edge_the_pilot_made():
    b = Bench()
    b.rc = rc(arm=True)                        # high at boot: never arms by itself
    b.step(20)
    assert not b.sup.armed
    b.rc = rc(arm=False)
    b.step()
    b.rc = rc(arm=True)
    b.step()
    assert b.sup.armed


def test_the_arm_switch_refuses_with_the_throttle_up_and_says_why():
    b = Bench()
    b.rc = rc(arm=False, throttle=1500)
    b.step()
    b.rc = rc(arm=True, throttle=1500)
    b.step()
    assert not b.sup.armed and b.reasons() == [reason("THROTTLE_HIGH")]


@pytest.mark.parametrize("arm_by", ["command", "switch"])
@pytest.mark.parametrize("switch_us", [1000, 1500, 0])
def test_the_arm_switch_not_high_always_disarms_whatever_armed(arm_by, switch_us):
    b = Bench()
    if arm_by == "switch":
        b.arm_by_switch()
    else:
        b.rc = rc(arm=True)
        b.heartbeat()
        b.step(2)
        assert b.sup.arm_command(b.rc, b.t) == reason("NONE")
    b.rc = fw.RcInput([1500, 1500, 1000, 1500, switch_us, 1000, 0, 0], 0)
    b.step()
    assert not b.sup.armed and reason("RC_SWITCH") in b.reasons()


@pytest.mark.parametrize("dropout_us", [0, 1500])
def test_a_dropout_of_the_arm_switch_pulse_disarms_and_does_not_rearm(dropout_us):
    # A loose channel-5 lead: no pulse (or a mid-travel one) for a frame, then high again.
    b = Bench()
    b.arm_by_switch()
    b.rc = fw.RcInput([1500, 1500, 1000, 1500, dropout_us, 1000, 0, 0], 0)
    b.step()
    assert not b.sup.armed
    b.rc = rc(arm=True)
    b.step(10)
    assert not b.sup.armed                     # no low pulse in between: not an edge


def test_a_switch_moved_high_while_the_rc_link_was_lost_does_not_arm():
    b = Bench()
    b.rc = rc(arm=False)
    b.step(3)
    b.rc = rc(arm=True, age_us=LIMITS.rc_timeout_us + 1)     # link lost, switch moved
    b.step(3)
    b.rc = rc(arm=True)                                       # link back
    b.step(10)
    assert not b.sup.armed
    b.rc = rc(arm=False)                                      # a real edge arms
    b.step()
    b.rc = rc(arm=True)
    b.step()
    assert b.sup.armed


def test_disarm_by_command():
    b = Bench()
    b.arm_by_switch()
    b.sup.disarm_command()
    assert not b.sup.armed and b.reasons()[-1] == reason("DISARM_COMMAND")


# --- failsafes ------------------------------------------------------------------------------

def test_rc_lost_disarms_and_the_vehicle_does_not_rearm_when_the_link_returns():
    b = Bench()
    b.arm_by_switch()
    b.rc = rc(arm=True, age_us=LIMITS.rc_timeout_us)          # at the bound: still live
    b.step()
    assert b.sup.armed
    b.rc = rc(arm=True, age_us=LIMITS.rc_timeout_us + 1)
    b.step()
    assert not b.sup.armed and b.sup.counters.rc_failsafes == 1
    assert b.reasons()[-1] == reason("RC_LOST")
    b.rc = rc(arm=True)                                       # back, switch still high
    b.step(10)
    assert not b.sup.armed


def test_host_lost_disarms_a_vehicle_armed_by_command_within_the_timeout():
    b = Bench()
    b.rc = rc(arm=True)
    b.heartbeat()
    last = b.t                          # the last heartbeat: a command is none
    b.step(2)
    assert b.sup.arm_command(b.rc, b.t) == reason("NONE")
    loops = 0
    while b.sup.armed:
        b.step()
        loops += 1
    assert b.t - last > LIMITS.host_timeout_us and b.t - last <= LIMITS.host_timeout_us + DT_US
    assert b.sup.counters.host_failsafes == 1 and reason("HOST_LOST") in b.reasons()


def test_host_silence_does_not_disarm_a_vehicle_armed_by_the_switch():
    b = Bench()
    b.arm_by_switch()
    b.step(int(3 * LIMITS.host_timeout_us / DT_US))
    assert b.sup.armed


def test_imu_timeout_is_five_samples_of_the_sensor_rate_and_at_most_50_ms():
    assert fw.imu_timeout_for(200.0) == 25000
    assert fw.imu_timeout_for(100.0) == 50000
    assert fw.imu_timeout_for(50.0) == 50000
    assert fw.imu_timeout_for(1000.0) == 5000
    assert fw.imu_timeout_for(0.0) == 50000


def test_a_stale_imu_cuts_the_motors_within_its_timeout():
    b = Bench()
    b.arm_by_switch()
    last_sample = b.t
    while b.sup.armed:
        b.step(imu=False)
    assert b.t - last_sample <= fw.imu_timeout_for(200.0) + DT_US
    assert b.reasons()[-1] == reason("IMU_STALE") and b.sup.counters.imu_stale == 1
    b.step()                                                   # samples again
    assert b.reasons() == [reason("IMU_RECOVERED")] and not b.sup.armed


def test_a_non_finite_value_disarms():
    b = Bench()
    b.arm_by_switch()
    b.sup.fault(reason("NON_FINITE"))
    assert not b.sup.armed and b.sup.counters.non_finite == 1
    assert b.reasons()[-1] == reason("NON_FINITE")


def test_a_stale_imu_is_recovered_only_while_disarmed_and_at_the_retry_pace():
    b = Bench()
    b.arm_by_switch()
    b.step(int(LIMITS.imu_retry_us / DT_US))                   # fly for the retry interval
    b.step(4, imu=False)                                       # 20 ms: not yet stale
    assert not b.sup.imu_recovery_due(b.t) and b.sup.armed
    b.step(2, imu=False)                                       # stale: disarmed
    assert not b.sup.armed and b.sup.imu_recovery_due(b.t)     # due at once
    b.sup.imu_recovery_result(reason("IMU_RESET"), True, b.t)
    assert b.sup.counters.imu_resets == 1 and b.sup.counters.imu_reinits == 1
    assert reason("IMU_RESET") in b.reasons()
    b.step(10, imu=False)
    assert not b.sup.imu_recovery_due(b.t)                     # the retry waits
    b.step(int(LIMITS.imu_retry_us / DT_US), imu=False)
    assert b.sup.imu_recovery_due(b.t)
    b.sup.imu_recovery_result(reason("IMU_NO_ANSWER"), False, b.t)
    b.step(int(LIMITS.imu_retry_us / DT_US), imu=False)
    b.sup.imu_recovery_result(reason("IMU_NO_ANSWER"), False, b.t)
    assert b.reasons().count(reason("IMU_NO_ANSWER")) == 1     # said once, not every retry


def test_an_armed_vehicle_is_never_due_for_imu_recovery():
    b = Bench()
    b.arm_by_switch()
    b.step(int(2 * LIMITS.imu_retry_us / DT_US))
    b.step(3, imu=False)                                       # 15 ms: stale is 25 ms
    assert b.sup.armed and not b.sup.imu_recovery_due(b.t)


# --- excitation -----------------------------------------------------------------------------

def armed_bench():
    b = Bench()
    b.arm_by_switch()
    b.heartbeat()
    return b


def test_excitation_refused_while_disarmed_and_never_starts_on_arming():
    b = Bench()
    b.heartbeat()
    assert b.sup.start_excitation(config(), b.t) == reason("DISARMED")
    assert b.reasons() == [reason("DISARMED")] and b.sup.counters.exc_refused == 1
    b.arm_by_switch()
    assert b.step(10) == [0.0] * 10 and b.sup.excitation_state == fw.ExcitationState.IDLE


def test_excitation_refused_without_a_host_heartbeat():
    b = Bench()
    b.arm_by_switch()
    assert b.sup.start_excitation(config(), b.t) == reason("NO_HOST")
    b.heartbeat()
    b.step(int(LIMITS.host_timeout_us / DT_US) + 1)
    assert b.sup.start_excitation(config(), b.t) == reason("NO_HOST")


@pytest.mark.parametrize("inj, amp, ok", [
    (fw.Injection.ANGLE, math.radians(45), True), (fw.Injection.ANGLE, math.radians(46), False),
    (fw.Injection.RATE, math.radians(200), True), (fw.Injection.RATE, math.radians(201), False),
    (fw.Injection.MIXER, 1.0, True), (fw.Injection.MIXER, 1.01, False),
    (fw.Injection.MIXER, 1e30, False), (fw.Injection.MIXER, math.inf, False),
    (fw.Injection.MIXER, math.nan, False), (fw.Injection.MIXER, 0.0, False),
    (fw.Injection.MIXER, -0.1, False),
])
def test_amplitude_bounds_per_injection_point(inj, amp, ok):
    b = armed_bench()
    got = b.sup.start_excitation(config(inj=inj, amp=amp), b.t)
    assert got == (reason("NONE") if ok else reason("AMPLITUDE"))


@pytest.mark.parametrize("freq, ok", [
    (0.05, True), (0.0499, False), (1e-9, False), (0.0, False), (-1.0, False),
    (50.0, True), (50.01, False), (math.nan, False), (math.inf, False),
])
def test_frequency_bounds(freq, ok):
    # 0.05 Hz and 50 Hz (a quarter of the loop rate) with one cycle fit the duration cap.
    b = armed_bench()
    got = b.sup.start_excitation(config(freq=freq, cycles=1), b.t)
    assert got == (reason("NONE") if ok else reason("FREQUENCY"))


def test_duration_cap_counts_the_fades_and_the_integer_period():
    b = armed_bench()
    # 1 Hz: 300 s allows 296 measured cycles with two fade cycles each side.
    assert b.sup.start_excitation(config(freq=1.0, cycles=297, fade=2), b.t) == reason("DURATION")
    assert b.sup.start_excitation(config(freq=1.0, cycles=296, fade=2), b.t) == reason("NONE")
    # The 32-bit sample counter cannot be reached: cycles is at most 65535.
    b.sup.stop_excitation()
    assert b.sup.start_excitation(config(freq=50.0, cycles=65535, fade=1), b.t) == reason("DURATION")


def test_no_cycles_and_no_fade_in_are_refused():
    b = armed_bench()
    assert b.sup.start_excitation(config(cycles=0), b.t) == reason("CYCLES")
    assert b.sup.start_excitation(config(fade=0), b.t) == reason("FADE")


@pytest.mark.parametrize("axis, inj", [(fw.Axis.YAW, fw.Injection.ANGLE)])
def test_angle_injection_on_yaw_is_refused(axis, inj):
    b = armed_bench()
    assert b.sup.start_excitation(config(axis=axis, inj=inj), b.t) == reason("AXIS_INJECTION")


def test_angle_injection_needs_angle_mode_and_a_second_excitation_waits():
    b = armed_bench()
    assert b.sup.set_mode(MAV.HQ_MODE_RATE) == reason("NONE")
    assert b.sup.start_excitation(config(inj=fw.Injection.ANGLE), b.t) == reason("INJECTION_MODE")
    assert b.sup.start_excitation(config(), b.t) == reason("NONE")
    assert b.sup.start_excitation(config(), b.t) == reason("BUSY")


def test_an_excitation_always_starts_with_its_fade_in():
    b = armed_bench()
    b.sup.start_excitation(config(freq=1.0, amp=0.5, cycles=2, fade=1), b.t)
    values = b.step(400)
    period = 200
    assert values[0] == 0.0
    # Within the first period the envelope limits the value well below the amplitude...
    assert max(abs(v) for v in values[:period // 4]) < 0.5 * 0.5
    # ...and the measured cycles reach it.
    assert max(abs(v) for v in values[period:2 * period]) == pytest.approx(0.5, rel=1e-3)


def test_an_excitation_runs_through_its_states_and_finishes():
    b = armed_bench()
    b.sup.start_excitation(config(freq=2.0, cycles=2, fade=1), b.t)
    states = []
    for _ in range(4 * 100 + 2):
        b.heartbeat()
        b.step()
        states.append(b.sup.excitation_state)
    fading, running, idle = fw.ExcitationState.FADING, fw.ExcitationState.RUNNING, fw.ExcitationState.IDLE
    assert states[:100] == [fading] * 100 and states[100:300] == [running] * 200
    assert states[300:400] == [fading] * 100 and states[400:] == [idle] * 2
    assert b.sup.take_excitation_end() == reason("FINISHED")
    assert b.sup.counters.exc_stopped == 0


def test_an_excitation_stops_within_the_host_timeout_of_the_last_heartbeat():
    b = armed_bench()
    b.sup.start_excitation(config(freq=1.0, cycles=100), b.t)
    last = b.t
    b.step()
    while b.sup.excitation_state != fw.ExcitationState.IDLE:
        b.step()
    assert last + LIMITS.host_timeout_us < b.t <= last + LIMITS.host_timeout_us + DT_US
    assert b.sup.take_excitation_end() == reason("HOST_LOST")
    assert b.sup.armed                                  # armed by the switch: still flying
    assert b.sup.counters.exc_stopped == 1


def test_an_excitation_stops_at_once_on_disarm():
    b = armed_bench()
    b.sup.start_excitation(config(), b.t)
    b.step(10)
    b.sup.disarm_command()
    assert b.step() == [0.0] and b.sup.excitation_state == fw.ExcitationState.IDLE
    # The end carries the disarm's reason (said once, by the disarm).
    assert b.sup.take_excitation_end() == reason("DISARM_COMMAND")
    assert b.reasons() == [reason("DISARM_COMMAND")]


@pytest.mark.parametrize("axis, attitude, rate, why", [
    (fw.Axis.ROLL, fw.Euler(math.radians(80.5), 0, 0), None, "ANGLE_LIMIT"),
    (fw.Axis.PITCH, fw.Euler(0, math.radians(-80.5), 0), None, "ANGLE_LIMIT"),
    (fw.Axis.ROLL, None, fw.Vec3(math.radians(401), 0, 0), "RATE_LIMIT"),
    (fw.Axis.YAW, None, fw.Vec3(0, 0, math.radians(-401)), "RATE_LIMIT"),
])
def test_an_excitation_stops_at_the_abort_limits(axis, attitude, rate, why):
    b = armed_bench()
    b.sup.start_excitation(config(axis=axis), b.t)
    b.step(5)
    assert b.step(attitude=attitude, rate=rate) == [0.0]
    assert b.sup.take_excitation_end() == reason(why) and reason(why) in b.reasons()


@pytest.mark.parametrize("attitude, rate, why", [
    (fw.Euler(math.nan, 0, 0), None, "ANGLE_LIMIT"),
    (None, fw.Vec3(math.nan, 0, 0), "RATE_LIMIT"),
    (None, fw.Vec3(math.inf, 0, 0), "RATE_LIMIT"),
])
def test_a_measurement_that_is_not_a_number_is_beyond_the_limits(attitude, rate, why):
    b = armed_bench()
    b.sup.start_excitation(config(), b.t)
    b.step(3)
    assert b.step(attitude=attitude, rate=rate) == [0.0]
    assert b.sup.take_excitation_end() == reason(why)


def test_imu_recovery_pacing_survives_a_clock_that_goes_backwards():
    b = Bench()
    b.step(int(2 * LIMITS.imu_retry_us / DT_US), imu=False)
    assert b.sup.imu_recovery_due(b.t)
    b.sup.imu_recovery_result(reason("IMU_STALLED"), True, b.t)
    earlier = b.t - 100000
    assert not b.sup.imu_recovery_due(earlier)        # not due on every loop


def test_the_yaw_rigs_heading_has_no_angle_limit():
    b = armed_bench()
    b.sup.start_excitation(config(axis=fw.Axis.YAW), b.t)
    b.step(5, attitude=fw.Euler(0, 0, math.radians(170)))
    assert b.sup.excitation_state != fw.ExcitationState.IDLE


def test_a_stop_command_ends_the_excitation_without_a_reported_end():
    b = armed_bench()
    b.sup.start_excitation(config(), b.t)
    b.step(3)
    assert b.sup.stop_excitation() and not b.sup.stop_excitation()
    assert b.step() == [0.0] and b.sup.take_excitation_end() is None


# --- modes ----------------------------------------------------------------------------------

def test_mode_changes_are_refused_while_an_excitation_runs():
    b = armed_bench()
    b.sup.start_excitation(config(), b.t)
    b.step()
    assert b.sup.set_mode(MAV.HQ_MODE_RATE) == reason("MODE_LOCKED")
    assert b.sup.mode == fw.FlightMode.ANGLE
    assert b.sup.set_mode(7) == reason("BAD_MODE")


def test_an_rc_mode_switch_change_waits_for_the_excitation_to_end():
    b = armed_bench()
    b.sup.start_excitation(config(freq=2.0, cycles=1, fade=1), b.t)
    b.rc = rc(arm=True, mode=2000)
    b.step()
    assert b.sup.mode == fw.FlightMode.ANGLE and b.reasons() == [reason("MODE_LOCKED")]
    for _ in range(310):
        b.heartbeat()
        b.step()
    assert b.sup.excitation_state == fw.ExcitationState.IDLE and b.sup.mode == fw.FlightMode.RATE


def test_set_mode_is_not_overridden_by_a_mode_switch_that_stays_put():
    b = Bench()
    b.rc = rc(mode=1000)
    b.step(3)
    assert b.sup.set_mode(MAV.HQ_MODE_RATE) == reason("NONE")
    b.step(50)
    assert b.sup.mode == fw.FlightMode.RATE
    b.rc = rc(mode=2000)
    b.step()
    b.rc = rc(mode=1000)                                    # the pilot moves it: it wins
    b.step()
    assert b.sup.mode == fw.FlightMode.ANGLE


def test_rate_mode_by_set_mode_runs_the_rate_loop_under_a_rate_injection():
    # The defect this class replaced: SET_MODE rate, no signal on channel 6, a rate-injection
    # excitation; the angle loop ran, so the rate setpoint did not follow the excitation.
    b = armed_bench()
    b.rc = rc(arm=True, mode=0)
    b.step()
    assert b.sup.set_mode(MAV.HQ_MODE_RATE) == reason("NONE")
    assert b.sup.start_excitation(config(inj=fw.Injection.RATE, amp=1.0, freq=2.0), b.t) == 0
    cascade = fw.Cascade()
    tilt = fw.Euler(0.2, -0.1, 0.0)             # an angle the angle loop would act on
    for _ in range(150):
        b.heartbeat()
        exc = b.step(attitude=tilt)[0]
        assert b.sup.mode == fw.FlightMode.RATE
        inp = fw.CascadeInput()
        inp.mode, inp.axis, inp.injection, inp.excitation = b.sup.mode, fw.Axis.ROLL, fw.Injection.RATE, exc
        inp.attitude = tilt
        sticks = fw.sticks(b.rc)
        inp.angle_stick, inp.rate_stick = sticks.angle, sticks.rate
        out = cascade.update(inp)
        assert out.rate_sp.x == pytest.approx(exc, abs=1e-7)      # centred stick: 0 + exc
        assert out.rate_sp.y == 0.0
    assert b.sup.excitation_state == fw.ExcitationState.RUNNING


def test_the_three_facts_are_independent():
    b = Bench()
    b.rc = rc(mode=0)                                        # no mode switch signal
    b.step()
    assert (b.sup.armed, b.sup.mode, b.sup.excitation_state) == (
        False, fw.FlightMode.ANGLE, fw.ExcitationState.IDLE)
    b.sup.set_mode(MAV.HQ_MODE_RATE)
    assert not b.sup.armed and b.sup.mode == fw.FlightMode.RATE       # a mode while disarmed
    for arm in (False, True):
        b.rc = rc(arm=arm, mode=0)
        b.step()
    b.heartbeat()
    b.sup.start_excitation(config(), b.t)
    b.step()
    assert (b.sup.armed, b.sup.mode, b.sup.excitation_state) == (
        True, fw.FlightMode.RATE, fw.ExcitationState.FADING)


def test_events_overflow_drops_the_oldest_and_counts():
    b = Bench()
    for _ in range(12):
        b.sup.set_mode(9)
    assert len(b.sup.events()) == 8 and b.sup.counters.events_dropped == 4


def test_every_reason_has_a_text_that_fits_statustext():
    for entry in MAV.enums["HQ_REASON"]:
        if entry >= MAV.HQ_REASON_ENUM_END:
            continue
        text = fw.reason_text(entry)
        assert 0 < len(text) <= 49 and text != "unknown reason"


def test_the_cascade_gains_have_no_yaw_angle_loop():
    gains = fw.CascadeGains.paper_defaults()
    assert gains.angle(fw.Axis.PITCH).kc == pytest.approx(1.501)
    with pytest.raises(ValueError, match="yaw has no angle loop"):
        gains.angle(fw.Axis.YAW)


def multisine(freq=0.5, lines=((3, 0.05, 0.0), (9, 0.05, 1.0)), peak=0.1, cycles=2):
    c = config(freq=freq, amp=peak, cycles=cycles)
    c.signal = fw.Signal.MULTISINE
    c.harmonics = list(lines)
    return c


@pytest.mark.parametrize("freq, lines, why", [
    (0.5, ((3, 0.05, 0.0), (9, 0.05, 1.0)), "NONE"),
    # Every line in the band: the lowest at least 0.05 Hz, the highest at most 50 Hz.
    (0.0125, ((4, 0.05, 0.0), (9, 0.05, 1.0)), "NONE"),
    (0.0125, ((3, 0.05, 0.0), (9, 0.05, 1.0)), "FREQUENCY"),
    (0.5, ((3, 0.05, 0.0), (101, 0.05, 1.0)), "HARMONICS"),   # fewer than 4 samples a cycle
    (1.0, ((3, 0.05, 0.0), (51, 0.05, 1.0)), "HARMONICS"),
    (0.5, ((9, 0.05, 0.0), (3, 0.05, 1.0)), "HARMONICS"),
    (0.5, (), "HARMONICS"),
])
def test_a_multisine_s_lines_must_be_in_the_band_and_well_formed(freq, lines, why):
    b = armed_bench()
    assert b.sup.start_excitation(multisine(freq, lines, cycles=1), b.t) == reason(why)


def test_a_multisine_s_peak_is_bounded_like_a_sine_s_amplitude_and_its_length_capped():
    b = armed_bench()
    assert b.sup.start_excitation(multisine(peak=1.01), b.t) == reason("AMPLITUDE")
    # 0.5 Hz base: 2 s periods, fades of one cycle of line 3 (134 samples) each way.
    assert b.sup.start_excitation(multisine(cycles=150), b.t) == reason("DURATION")
    assert b.sup.start_excitation(multisine(cycles=149), b.t) == reason("NONE")


def test_an_unknown_signal_is_refused():
    b = armed_bench()
    c = multisine()
    c.signal = fw.Signal(7)
    assert b.sup.start_excitation(c, b.t) == reason("HARMONICS")


def test_a_multisine_that_passes_its_declared_peak_stops_with_the_reason_and_says_so():
    b = armed_bench()
    assert b.sup.start_excitation(multisine(peak=0.06), b.t) == reason("NONE")
    values = []
    for _ in range(2000):
        b.heartbeat()
        values += b.step()
        if b.sup.excitation_state == fw.ExcitationState.IDLE:
            break
    assert b.sup.take_excitation_end() == reason("PEAK")
    assert max(abs(v) for v in values) <= 0.06 * (1 + 1e-3)
    assert reason("PEAK") in b.reasons() and b.sup.counters.exc_stopped == 1


# --- who the host is ------------------------------------------------------------------------

GCS, QUAD = MAV.MAV_TYPE_GCS, MAV.MAV_TYPE_QUADROTOR
STATION_A, STATION_B = fw.station_id(255, 190), fw.station_id(254, 190)


def test_only_a_ground_stations_heartbeat_counts_as_the_host():
    """Another vehicle (system 2, a quadrotor) on the same link is no host: it neither lets
    an excitation start nor keeps a command-armed vehicle armed."""
    b = Bench()
    b.arm_by_switch()
    assert not b.sup.heartbeat(2, 1, QUAD, b.t)
    assert b.sup.start_excitation(config(), b.t, fw.station_id(2, 1)) == reason("NO_HOST")
    assert b.sup.heartbeat(255, 190, GCS, b.t)
    assert b.sup.start_excitation(config(), b.t, STATION_A) == reason("NONE")


def test_an_excitation_belongs_to_the_station_that_commanded_it():
    """A second ground station's heartbeat does not keep an excitation alive once the one
    that commanded it went quiet: it stops within the host timeout of that station's last."""
    b = Bench()
    b.arm_by_switch()
    b.sup.heartbeat(255, 190, GCS, b.t)
    b.sup.heartbeat(254, 190, GCS, b.t)
    assert b.sup.start_excitation(config(cycles=200), b.t, STATION_A) == reason("NONE")
    assert b.sup.excitation_owner == STATION_A
    last_a = b.t
    b.step()
    while b.sup.excitation_state != fw.ExcitationState.IDLE:
        b.sup.heartbeat(254, 190, GCS, b.t)           # only B goes on
        b.step()
        assert b.t - last_a <= LIMITS.host_timeout_us + DT_US, "ran on on another's heartbeat"
    assert b.t - last_a > LIMITS.host_timeout_us
    assert reason("HOST_LOST") in b.reasons()


def test_a_station_whose_own_heartbeat_is_stale_cannot_start_an_excitation():
    b = Bench()
    b.arm_by_switch()
    b.sup.heartbeat(254, 190, GCS, b.t)               # B is alive, A never spoke
    assert b.sup.start_excitation(config(), b.t, STATION_A) == reason("NO_HOST")
    assert b.sup.start_excitation(config(), b.t, STATION_B) == reason("NONE")


def test_mav_gcs_sysid_pins_the_host_to_one_system():
    limits = fw.SafetyLimits()
    limits.gcs_sysid = 255
    b = Bench(limits)
    b.arm_by_switch()
    assert not b.sup.heartbeat(254, 190, GCS, b.t)    # another ground station: ignored
    assert b.sup.start_excitation(config(), b.t, STATION_B) == reason("NO_HOST")
    assert b.sup.heartbeat(255, 190, GCS, b.t)
    assert b.sup.start_excitation(config(), b.t, STATION_A) == reason("NONE")


def test_an_arm_command_needs_a_live_ground_station_and_the_rc_switch_does_not():
    """A command arms only for a ground station whose own heartbeat is fresh (and that
    MAV_GCS_SYSID allows): with none alive, with only another station alive, from a vehicle,
    or after the station went quiet, it is refused NO_HOST and says so, and the pre-arm
    check agrees. The pilot's switch arms without any host (the host-lost failsafe is for
    command arming only)."""
    b = Bench()
    b.rc = rc(arm=True)
    b.step(4)
    assert b.sup.arm_check(b.rc, b.t) == reason("NO_HOST")
    assert b.sup.arm_command(b.rc, b.t, fw.station_id(7, 1)) == reason("NO_HOST")
    assert not b.sup.armed and b.reasons() == [reason("NO_HOST")]
    assert b.sup.counters.arm_refused == 1
    assert b.sup.heartbeat(255, 190, GCS, b.t)
    assert b.sup.arm_check(b.rc, b.t) == reason("NONE")
    assert not b.sup.heartbeat(2, 1, QUAD, b.t)                   # another vehicle
    for who in (fw.station_id(2, 1), STATION_B, fw.station_id(255, 191)):
        assert b.sup.arm_command(b.rc, b.t, who) == reason("NO_HOST"), who
        b.step()
        assert not b.sup.armed
    b.step(int(LIMITS.host_timeout_us / DT_US) + 1)              # A went quiet
    assert b.sup.arm_check(b.rc, b.t) == reason("NO_HOST")
    assert b.sup.arm_command(b.rc, b.t, STATION_A) == reason("NO_HOST")
    assert b.sup.heartbeat(255, 190, GCS, b.t)
    assert b.sup.arm_command(b.rc, b.t, STATION_A) == reason("NONE") and b.sup.armed
    b.sup.disarm_command()
    b.reasons()                                                   # taken
    b.step(int(2 * LIMITS.host_timeout_us / DT_US))               # no host at all now
    b.arm_by_switch()
    b.step(int(2 * LIMITS.host_timeout_us / DT_US))
    assert b.sup.armed and reason("NO_HOST") not in b.reasons()


def test_a_station_mav_gcs_sysid_excludes_is_forgotten_and_its_commands_keep_nothing_alive():
    """Station 255 is heard, then MAV_GCS_SYSID is set to 200: 255 is no host any more. Its
    arm commands every 0.5 s neither arm nor keep it alive, and 5 s on (the timeout is
    1.5 s) its excitation is refused; at once after the change too."""
    b = Bench()
    b.rc = rc(arm=True)
    assert b.sup.heartbeat(255, 190, GCS, b.t)
    b.step(2)
    limits = fw.SafetyLimits()
    limits.gcs_sysid = 200
    b.sup.set_limits(limits)
    assert b.sup.arm_check(b.rc, b.t) == reason("NO_HOST")
    assert b.sup.arm_command(b.rc, b.t, STATION_A) == reason("NO_HOST")
    assert not b.sup.heartbeat(255, 190, GCS, b.t)
    b.arm_by_switch()                                               # the pilot flies
    assert b.sup.start_excitation(config(), b.t, STATION_A) == reason("NO_HOST")
    for _ in range(10):                                             # 5 s of arm commands
        b.step(100)
        b.sup.arm_command(b.rc, b.t, STATION_A)
    assert b.sup.start_excitation(config(), b.t, STATION_A) == reason("NO_HOST")
    assert b.sup.excitation_state == fw.ExcitationState.IDLE
    assert b.sup.heartbeat(200, 190, GCS, b.t)                      # the allowed one
    assert b.sup.start_excitation(config(), b.t, fw.station_id(200, 190)) == reason("NONE")


def test_a_fifth_station_never_evicts_the_running_excitations_owner():
    """Four slots: with MAV_GCS_SYSID = 0 a fifth ground-station component takes the slot
    heard from longest ago, but never the one whose excitation runs: the excitation goes on
    while its own station's heartbeats go on."""
    b = Bench()
    b.arm_by_switch()
    assert b.sup.heartbeat(255, 190, GCS, b.t)
    assert b.sup.start_excitation(config(cycles=200), b.t, STATION_A) == reason("NONE")
    for loop in range(300):                                         # 1.5 s
        if loop % 50 == 0:
            assert b.sup.heartbeat(255, 190, GCS, b.t)              # A, every 0.25 s
        b.step()
        for compid in range(1, 6):                                  # five others, each loop
            assert b.sup.heartbeat(250, compid, GCS, b.t)
        assert b.sup.excitation_state != fw.ExcitationState.IDLE, loop
    assert b.sup.take_excitation_end() is None
    assert b.sup.excitation_owner == STATION_A


# --- chirp ----------------------------------------------------------------------------------

def chirp_config(start=0.5, stop=4.5, sweep_s=60.0, amp=0.25, fade=2, cycles=1):
    c = config(freq=start, amp=amp, cycles=cycles, fade=fade)
    c.signal, c.freq_stop_hz, c.sweep_s = fw.Signal.CHIRP, stop, sweep_s
    return c


@pytest.mark.parametrize("change, why", [
    ({}, "NONE"),
    ({"stop": 50.0}, "NONE"), ({"stop": 50.01}, "FREQUENCY"),   # both ends in the band
    ({"start": 0.0499}, "FREQUENCY"), ({"stop": 0.0}, "FREQUENCY"),
    ({"stop": 0.5}, "FREQUENCY"), ({"stop": math.nan}, "FREQUENCY"),
    ({"amp": 1.01}, "AMPLITUDE"), ({"amp": math.inf}, "AMPLITUDE"),
    ({"cycles": 2}, "CYCLES"), ({"fade": 0}, "FADE"),
    ({"sweep_s": 0.0}, "DURATION"), ({"sweep_s": math.nan}, "DURATION"),
    # 300 s with the fades: 292 s of sweep and two fades of 2 cycles at 0.5 Hz (8 s)
    ({"sweep_s": 292.0}, "NONE"), ({"sweep_s": 292.1}, "DURATION"),
    # whole samples, as the generator counts them: a fade cycle at 0.16 Hz (a float) is
    # ceil(1250.00003) = 1251 samples, so 10 of them each way and 175 s of sweep are 300.1 s
    ({"start": 0.16, "stop": 1.0, "fade": 10, "sweep_s": 174.9}, "NONE"),
    ({"start": 0.16, "stop": 1.0, "fade": 10, "sweep_s": 175.0}, "DURATION"),
])
def test_a_chirp_is_held_to_every_bound_a_sine_is(change, why):
    b = armed_bench()
    got = b.sup.start_excitation(chirp_config(**change), b.t)
    assert got == reason(why)
