"""Frequency sweeps (``heliquad sweep``): the paper's sine dwells for one axis, logged.

The same protocol runs on the simulated rig (lockstep, :class:`heliquad.sim.sil.SilSession`)
and on a port (a Teensy, or a ``heliquad board`` pty; :class:`PortSession`): for each
frequency, start the excitation over the telemetry link, wait for the firmware's
HQ_EXCITATION_STATUS (which gives the exact frequency used), watch every HQ_SYSID_SAMPLE
until the excitation ends, and move on. Everything is logged to ``DIR/sweep.tlog``;
``DIR/manifest.json`` (axis, injection, frequencies requested and used, sample windows,
gains, firmware version, start time, aborts) is rewritten after every frequency, so Ctrl-C
or a breach leaves a valid, identifiable session.

Safety: a sample whose angle exceeds ``max_angle_deg`` (80 deg, SPEC.md; roll and pitch,
whose rigs swing; the yaw rig's heading is free) or whose rate exceeds ``max_rate_deg_s``
stops the excitation at once and ends the sweep; the manifest records the breach.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import time

import numpy as np

from . import __version__, paper
from .errors import InputError
from .link import SESSION_MESSAGES

__all__ = ["SweepPlan", "default_plan", "run_sweep", "PortSession", "MANIFEST", "SWEEP_TLOG"]

MANIFEST = "manifest.json"
SWEEP_TLOG = "sweep.tlog"
N_FREQUENCIES = 15
MEASURED_CYCLES = 8
FADE_CYCLES = 2
MAX_ANGLE_DEG = 80.0
MAX_RATE_DEG_S = 400.0
#: A frequency's excitation must start within this much (simulated or wall) time.
START_TIMEOUT_S = 3.0


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
    """SPEC.md Table 1: 15 log-spaced frequencies over the axis's band."""
    if freqs_hz is None:
        lo, hi = paper.BANDS_HZ[axis]
        freqs_hz = np.logspace(math.log10(lo), math.log10(hi), N_FREQUENCIES)
    amps = [amplitude if amplitude is not None else default_amplitude(axis, inject, f)
            for f in freqs_hz]
    return SweepPlan(axis, inject, freqs_hz, amps, cycles)


class PortSession:
    """A board (or a ``heliquad board`` pty) as a sweep driver: wall-clock time, the link
    logging every packet with the host's clock."""

    def __init__(self, port: str, tlog_path: str, baud: int = 115200, poll_s: float = 0.05):
        from .link import TelemetryLink
        from .tlog import TlogWriter

        self.tlog = TlogWriter(tlog_path)
        self.tel = TelemetryLink(port, baud=baud, tlog=self.tlog)
        self.poll_s = poll_s
        self.t0 = time.monotonic()
        self.last_hb = 0.0

    @property
    def time_us(self) -> int:
        return int((time.monotonic() - self.t0) * 1e6)

    def hover(self) -> None:
        """On a board the pilot arms and hovers; nothing to do."""

    def advance(self) -> list:
        time.sleep(self.poll_s)
        now = time.monotonic()
        if now - self.last_hb >= 1.0:
            self.tel.heartbeat()
            self.last_hb = now
        msgs = self.tel.poll(only=SESSION_MESSAGES)
        self.tlog.flush()
        return msgs

    def close(self) -> None:
        self.tel.close()
        self.tlog.close()


def _write_manifest(out_dir, manifest) -> None:
    path = os.path.join(out_dir, MANIFEST)
    with open(path + ".tmp", "w") as fh:
        json.dump(manifest, fh, indent=2)
    os.replace(path + ".tmp", path)


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
    _write_manifest(out_dir, manifest)
    session.hover()
    try:
        for i, (f, amp) in enumerate(zip(plan.freqs_hz, plan.amplitudes), 1):
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
    except KeyboardInterrupt:
        session.tel.stop_excitation()
        manifest["aborted"] = "interrupted (Ctrl-C)"
        progress("interrupted: the excitation is stopped; the log and manifest are kept")
    finally:
        _write_manifest(out_dir, manifest)
    return manifest


def _one_frequency(session, plan, f, amp, axis_i, max_angle_deg, max_rate_deg_s):
    entry = {"requested_hz": f, "amplitude": amp, "samples": 0, "status": "ok"}
    session.tel.start_excitation(plan.axis, plan.inject, f, amp, plan.cycles, plan.fade_cycles)
    started, seen_active = session.time_us, False
    while True:
        for m in session.advance():
            kind = m.get_type()
            if kind == "HQ_EXCITATION_STATUS" and "freq_hz" not in entry:
                if not m.accepted:
                    entry["status"] = "refused by the firmware"
                    return entry
                entry.update(freq_hz=float(m.freq_hz), period_samples=int(m.period_samples))
            elif kind == "HQ_SYSID_SAMPLE":
                if m.exc_state:
                    seen_active = True
                if m.exc_state == 2:
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
                if seen_active and m.exc_state == 0:
                    return entry
            elif kind == "STATUSTEXT" and m.severity <= 4:
                entry.setdefault("messages", []).append(m.text)
        if not seen_active and session.time_us - started > START_TIMEOUT_S * 1e6:
            entry["status"] = "the excitation did not start (no answer from the firmware)"
            return entry
