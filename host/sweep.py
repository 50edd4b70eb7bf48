"""Frequency sweeps (``heliquad sweep``): the paper's sine dwells for one axis, logged.

The same protocol runs on the simulated rig (lockstep, :class:`heliquad.sim.sil.SilSession`)
and on a port (a Teensy, or a ``heliquad board`` pty; :class:`PortSession`): for each
frequency, start the excitation over the telemetry link, wait for the firmware's
HQ_EXCITATION_STATUS (which gives the exact frequency used), watch every HQ_SYSID_SAMPLE
until the excitation ends, and move on. Everything is logged to ``DIR/sweep.tlog``;
``DIR/manifest.json`` (axis, injection, frequencies requested and used, sample windows,
gains, firmware version, start time, aborts) is rewritten after every frequency, so Ctrl-C
or a breach leaves a valid, identifiable session.

Safety: the firmware enforces its own rules (docs/safety.md): it refuses an excitation out
of bounds or while disarmed, and stops one when its axis passes the abort limits, when the
host's heartbeat stops, or on disarm; HQ_EXCITATION_STATUS says why, and the sweep ends with
that reason in the manifest (``aborted``), never as complete. As a second line, a sample whose
angle exceeds ``max_angle_deg`` (roll and pitch, whose rigs swing; the yaw rig's heading is
free) or whose rate exceeds ``max_rate_deg_s`` makes the host stop the excitation and end the
sweep. Both limits default to the firmware's own (one definition, read from its bindings).
"""

from __future__ import annotations

import datetime
import math
import os
import time

import numpy as np

from heliquad import _firmware

from . import __version__, paper
from .errors import InputError, Terminated
from .files import write_json
from .link import DEFAULT_BAUD, HEARTBEAT_PERIOD_S, SESSION_MESSAGES, reason_text
from ..sim.dialect import dialect

__all__ = ["SweepPlan", "default_plan", "run_sweep", "PortSession", "MANIFEST", "SWEEP_TLOG"]

MANIFEST = "manifest.json"
SWEEP_TLOG = "sweep.tlog"
N_FREQUENCIES = 15
MEASURED_CYCLES = 8
FADE_CYCLES = 2
#: The firmware's abort limits (SafetyLimits), checked again on the host (rounded to the
#: millidegree: the firmware holds them in single precision).
MAX_ANGLE_DEG = round(math.degrees(_firmware.SafetyLimits().abort_angle_rad), 3)
MAX_RATE_DEG_S = round(math.degrees(_firmware.SafetyLimits().abort_rate_rad_s), 3)
#: A frequency's excitation must start within this much (simulated or wall) time.
START_TIMEOUT_S = 3.0
#: A running excitation whose samples stop for this long (the session's time: wall clock on a
#: board) has lost its board: the link is gone or the board hung. The telemetry carries a
#: sample every loop (200 Hz), so 2 s is 400 missing in a row.
SAMPLE_TIMEOUT_S = 2.0


def default_amplitude(axis: str, inject: str, freq_hz: float) -> float:
    """Firmware-unit amplitude that keeps the response well above the gyro's quantisation
    without saturating (docs/vehicle-model.md: the closed yaw loop needs more at low
    frequency)."""
    if inject == "mixer":
        return 0.05 if axis != "yaw" else (1.0 if freq_hz < 0.4 else 0.3)
    if inject == "rate":
        return math.radians(10.0)
    return math.radians(5.0)


class SweepPlan:
    """What a sweep does: axis, injection point, frequencies and amplitudes (firmware units)."""

    def __init__(self, axis, inject, freqs_hz, amplitudes, cycles=MEASURED_CYCLES,
                 fade_cycles=FADE_CYCLES):
        if inject == "angle" and axis == "yaw":
            raise InputError("yaw is rate-only: use --inject rate or mixer")
        self.axis, self.inject = axis, inject
        self.freqs_hz = [float(f) for f in freqs_hz]
        self.amplitudes = [float(a) for a in amplitudes]
        self.cycles, self.fade_cycles = int(cycles), int(fade_cycles)


def default_plan(axis, inject="mixer", freqs_hz=None, amplitude=None, cycles=MEASURED_CYCLES):
    """The paper's Table 1 (docs/paper.md): 15 log-spaced frequencies over the axis's band."""
    if freqs_hz is None:
        lo, hi = paper.BANDS_HZ[axis]
        freqs_hz = np.logspace(math.log10(lo), math.log10(hi), N_FREQUENCIES)
    amps = [amplitude if amplitude is not None else default_amplitude(axis, inject, f)
            for f in freqs_hz]
    return SweepPlan(axis, inject, freqs_hz, amps, cycles)


class PortSession:
    """A board (or a ``heliquad board`` pty) as a sweep driver: wall-clock time, the link
    logging every packet with the host's clock."""

    def __init__(self, port: str, tlog_path: str, baud: int = DEFAULT_BAUD, poll_s: float = 0.05):
        from .link import TelemetryLink
        from .tlog import TlogWriter

        self.tel = TelemetryLink(port, baud=baud)   # the port first: a bad one creates nothing
        try:
            self.tlog = self.tel.tlog = TlogWriter(tlog_path)
        except BaseException:
            self.tel.close()
            raise
        self.poll_s = poll_s
        self.t0 = time.monotonic()
        self.tel.heartbeat()                  # the firmware wants one before an excitation
        self.last_hb = self.t0

    @property
    def time_us(self) -> int:
        return int((time.monotonic() - self.t0) * 1e6)

    def hover(self) -> None:
        """On a board the pilot arms and hovers; nothing to do."""

    def advance(self) -> list:
        time.sleep(self.poll_s)
        now = time.monotonic()
        if now - self.last_hb >= HEARTBEAT_PERIOD_S:
            self.tel.heartbeat()
            self.last_hb = now
        msgs = self.tel.poll(only=SESSION_MESSAGES)
        self.tlog.flush()
        return msgs

    def close(self) -> None:
        self.tel.close()
        self.tlog.close()


def _write_manifest(out_dir, manifest) -> None:
    write_json(os.path.join(out_dir, MANIFEST), manifest)


def run_sweep(session, plan: SweepPlan, out_dir: str, source: dict, progress=print,
              max_angle_deg=MAX_ANGLE_DEG, max_rate_deg_s=MAX_RATE_DEG_S) -> dict:
    """Run the plan on ``session``; returns the manifest (also written to ``out_dir``)."""
    axis_i = ("roll", "pitch", "yaw").index(plan.axis)
    gains = {"rate": paper.RATE_GAINS[plan.axis], "angle": paper.ANGLE_GAINS.get(plan.axis)}
    manifest = {"axis": plan.axis, "inject": plan.inject, "source": source,
                "firmware": f"heliquad {__version__}", "gains": gains,
                "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                "tlog": SWEEP_TLOG, "cycles": plan.cycles, "fade_cycles": plan.fade_cycles,
                "limits": {"max_angle_deg": max_angle_deg, "max_rate_deg_s": max_rate_deg_s},
                "frequencies": [], "complete": False, "aborted": None}
    current = None
    try:
        _write_manifest(out_dir, manifest)
        session.hover()
        for i, (f, amp) in enumerate(zip(plan.freqs_hz, plan.amplitudes), 1):
            current = f
            entry = _one_frequency(session, plan, f, amp, axis_i, max_angle_deg, max_rate_deg_s)
            manifest["frequencies"].append(entry)
            _write_manifest(out_dir, manifest)
            bar = "#" * i + "." * (len(plan.freqs_hz) - i)
            progress(f"[{bar}] {i}/{len(plan.freqs_hz)}  {entry.get('freq_hz', f):.4g} Hz  "
                     f"{entry['samples']} samples  {entry['status']}")
            if entry["status"] != "ok":
                manifest["aborted"] = entry["status"]
                break
        else:
            manifest["complete"] = True
    except KeyboardInterrupt as exc:
        session.tel.stop_excitation()
        how = "terminated (SIGTERM)" if isinstance(exc, Terminated) else "interrupted (Ctrl-C)"
        manifest["aborted"] = how
        manifest["in_progress_hz"] = current          # None: during the hover, before any
        progress(f"{how}: the excitation is stopped; the log and manifest are kept")
    finally:
        _write_manifest(out_dir, manifest)
    return manifest


def _one_frequency(session, plan, f, amp, axis_i, max_angle_deg, max_rate_deg_s):
    mav = dialect()
    idle, running = mav.HQ_EXCITATION_STATE_IDLE, mav.HQ_EXCITATION_STATE_RUNNING
    entry = {"requested_hz": f, "amplitude": amp, "samples": 0, "status": "ok"}
    session.tel.start_excitation(plan.axis, plan.inject, f, amp, plan.cycles, plan.fade_cycles)
    started, seen_active = session.time_us, False
    last_sample = started
    while True:
        for m in session.advance():
            kind = m.get_type()
            if kind == "HQ_EXCITATION_STATUS":
                # Read whatever arrives first: the answer to this start, or (if that was lost
                # on a board's link) the status of its end, which carries the same fields.
                if not m.accepted:           # only a start is ever refused
                    entry["status"] = f"refused by the firmware: {reason_text(m.reason)}"
                    return entry
                if "freq_hz" not in entry:
                    entry.update(freq_hz=float(m.freq_hz), period_samples=int(m.period_samples))
                if m.state == idle and m.reason not in (mav.HQ_REASON_NONE, mav.HQ_REASON_FINISHED):
                    entry["status"] = f"stopped by the firmware: {reason_text(m.reason)}"
                    return entry
            elif kind == "HQ_SYSID_SAMPLE":
                last_sample = session.time_us
                if m.exc_state != idle:
                    seen_active = True
                if m.exc_state == running:
                    entry.setdefault("start_us", int(m.time_us))
                    entry["end_us"] = int(m.time_us)
                    entry["samples"] += 1
                # The angle limit is the roll and pitch rigs' swing; on the yaw rig the logged
                # angle is the heading, which is free.
                swing = abs(math.degrees(m.angle)) if plan.axis != "yaw" else 0.0
                if swing > max_angle_deg or abs(math.degrees(m.rate)) > max_rate_deg_s:
                    session.tel.stop_excitation()
                    entry["status"] = (f"aborted: limit breached at {m.time_us * 1e-6:.2f} s "
                                       f"(angle {math.degrees(m.angle):.1f} deg, rate "
                                       f"{math.degrees(m.rate):.1f} deg/s)")
                    return entry
                if seen_active and m.exc_state == idle:
                    return _check_complete(entry, plan)
            elif kind == "STATUSTEXT" and m.severity <= 4:
                entry.setdefault("messages", []).append(m.text)
        if not seen_active and session.time_us - started > START_TIMEOUT_S * 1e6:
            entry["status"] = "the excitation did not start (no answer from the firmware)"
            return entry
        if seen_active and session.time_us - last_sample > SAMPLE_TIMEOUT_S * 1e6:
            session.tel.stop_excitation()          # in case the board is there but deaf
            entry["status"] = (f"no samples for {SAMPLE_TIMEOUT_S:g} s: the board stopped "
                               "sending (link lost or board hung)")
            return entry


def _check_complete(entry, plan):
    """An excitation that ended without a stop message must still have all its measured
    samples (a lost status message must not pass a truncated record as complete)."""
    expected = plan.cycles * entry.get("period_samples", 0)
    if entry["samples"] != expected:
        entry["status"] = (f"incomplete: {entry['samples']} of {expected} measured samples "
                           "were logged")
    return entry
