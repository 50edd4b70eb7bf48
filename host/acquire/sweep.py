"""Frequency sweeps (``heliquad sweep``): the paper's sine dwells for one axis, logged.

The same protocol runs on any session (:mod:`heliquad.host.acquire.session`: the simulated rig in
lockstep, or a Teensy or ``heliquad board`` pty on a port): for each frequency,
:func:`measure` starts the excitation over the telemetry link, waits for the firmware's
HQ_EXCITATION_STATUS (which gives the exact frequency used), watches every HQ_SYSID_SAMPLE
until the excitation ends (:class:`ExcitationWatch`), and the sweep moves on. ``heliquad sil``
is the same routine for one frequency. Everything is logged to ``DIR/sweep.tlog``;
``DIR/manifest.json`` (axis, injection, frequencies requested and used, sample windows,
the parameters and gains read from the board, firmware version, start time, aborts) is rewritten after every
frequency, so Ctrl-C or a breach leaves a valid, identifiable session.

Safety: the firmware enforces its own rules (docs/safety.md): it refuses an excitation out
of bounds or while disarmed, and stops one when its axis passes the abort limits, when the
host's heartbeat stops, or on disarm; HQ_EXCITATION_STATUS says why, and the sweep ends with
that reason in the manifest (``aborted``), never as complete. As a second line, a sample whose
angle exceeds ``max_angle_deg`` (roll and pitch, whose rigs swing; the yaw rig's heading is
free) or whose rate exceeds ``max_rate_deg_s`` makes the host stop the excitation and end the
sweep. Both limits default to the firmware's own (one definition, read from its bindings).
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import os

import numpy as np

from ...sim.base import firmware_facts
from ...sim.base.dialect import dialect
from ...sim.base.errors import FirmwareError
from .. import __version__
from ..records import paper
from ...sim.base.errors import DiskFull, InputError, LinkLost
from ..process.signals import ABORTED_BY, stopped_by
from ..records.manifest import MANIFEST, SweepManifest, write_manifest
from .excitation import amplitude_bound, default_amplitude, default_peak
from .link import INPUT_OUTPUT, reason_text
from ..records.gains import gains_from_params, single
# Imported here, not when the sweep reads the board: a Ctrl-C that lands in the middle of an
# import leaves Python to end by SIGINT even after the tool has stopped in order.
from .param_protocol import session_params

__all__ = ["SweepPlan", "default_plan", "multisine_plan", "run_sweep", "sil_source", "measure", "ExcitationWatch",
           "Limits", "MANIFEST", "SWEEP_TLOG", "SATURATION", "saturation_summary",
           "saturation_text", "loss_text", "cut_text", "MAX_LOST_SHARE", "MAX_LOST_RUN"]

SWEEP_TLOG = "sweep.tlog"
N_FREQUENCIES = 15
MEASURED_CYCLES = 8
FADE_CYCLES = 2
#: The firmware's abort limits (SafetyLimits), checked again on the host (rounded to the
#: millidegree: the firmware holds them in single precision).
MAX_ANGLE_DEG = round(math.degrees(firmware_facts.ABORT_ANGLE_RAD), 3)
MAX_RATE_DEG_S = round(math.degrees(firmware_facts.ABORT_RATE_RAD_S), 3)
#: A frequency's excitation must start within this much (simulated or wall) time.
START_TIMEOUT_S = 3.0
#: A running excitation whose samples stop for this long (the session's time: wall clock on a
#: board) has lost its board: the link is gone or the board hung. The telemetry carries a
#: sample every loop (200 Hz), so 2 s is 400 missing in a row.
SAMPLE_TIMEOUT_S = 2.0
#: Samples lost on the link (telemetry radios drop packets; a damaged packet fails its CRC)
#: are left out of the estimate (host/estimate/fsf.py: the excitation repeats every period, and least
#: squares needs no sample it did not get). A frequency ends the sweep only when it lost
#: more than this share of its measured samples (its sigma grows by 1/sqrt(1 - share)) ...
MAX_LOST_SHARE = 0.05
#: ... or more than this many in a row (0.25 s at 200 Hz): a link dropping out, not a packet
#: lost now and then (at 2 % independent loss a run of 5 happens once in 3e8 samples).
MAX_LOST_RUN = 50
#: The saturation counts of a frequency's window (manifest keys): the HQ_SATURATION bits that
#: count a sample, and how a person is told.
SATURATION = {"saturated": (("TORQUE",), "saturated the mixer"),
              "collective_limited": (("COLLECTIVE",), "lost collective"),
              "sensor_clipped": (("GYRO", "ACCEL"), "clipped the IMU")}


class SweepPlan:
    """What a sweep does: axis, injection point, frequencies and amplitudes (firmware units).

    ``amplitudes``: one per frequency, or None for a designed amplitude
    (:class:`~heliquad.host.acquire.design.AmplitudeDesign`, given as ``design``). ``dwell``: a
    :class:`~heliquad.host.acquire.design.Dwell` for the sequential dwell; without one every
    frequency runs ``cycles`` measured cycles (the published dwell)."""

    def __init__(self, axis, inject, freqs_hz, amplitudes, cycles=MEASURED_CYCLES,
                 fade_cycles=FADE_CYCLES, dwell=None, design=None):
        if inject == "angle" and axis == "yaw":
            raise InputError("yaw is rate-only: use --inject rate or mixer")
        self.axis, self.inject = axis, inject
        self.freqs_hz = [float(f) for f in freqs_hz]
        self.amplitudes = [None if a is None else float(a) for a in amplitudes]
        self.cycles, self.fade_cycles = int(cycles), int(fade_cycles)
        self.dwell, self.design = dwell, design
        self.multisine = None

    @classmethod
    def of_multisine(cls, axis, inject, multisine) -> "SweepPlan":
        """One excitation: the multisine (:mod:`.multisine`), its base frequency, declared
        peak, whole periods and fade."""
        plan = cls(axis, inject, [multisine.base_hz], [multisine.peak], multisine.periods,
                   multisine.fade_cycles)
        plan.multisine = multisine
        return plan

    @property
    def signal(self) -> str:
        return "dwell" if self.multisine is None else "multisine"

    def cycles_for(self, freq_hz: float) -> int:
        """The measured cycles (a multisine: base periods) an excitation is started with."""
        return self.dwell.cycles(freq_hz) if self.dwell else self.cycles

    def record(self) -> dict:
        """The design, for the manifest."""
        if self.multisine is not None:
            return self.multisine.record()
        out = {"cycles": self.cycles} if self.dwell is None else {
            "dwell": "sequential", "min_cycles": self.dwell.min_cycles,
            "max_cycles": self.dwell.max_cycles, "max_dwell_s": self.dwell.max_dwell_s,
            "target_sigma": self.dwell.target_sigma}
        if self.design is not None:
            out.update(amplitude="designed", swing_deg=self.design.swing_deg,
                       amplitude_bound=self.design.bound)
        return out


def default_plan(axis, inject="mixer", freqs_hz=None, amplitude=None, cycles=None,
                 dwell=None, swing_deg=None):
    """The paper's Table 1 (docs/paper.md): 15 log-spaced frequencies over the axis's band.

    ``cycles``: a fixed dwell of that many measured cycles (the published one: 8); without
    it the dwell is sequential (``dwell``, default :class:`~heliquad.host.acquire.design.Dwell`).
    ``amplitude``: one for every frequency; without it a mixer sweep's amplitudes are
    designed for a swing of ``swing_deg`` (:class:`~heliquad.host.acquire.design.AmplitudeDesign`)
    and angle and rate sweeps use :func:`.excitation.default_amplitude`."""
    from .design import AmplitudeDesign, Dwell

    if freqs_hz is None:
        lo, hi = paper.BANDS_HZ[axis]
        freqs_hz = np.logspace(math.log10(lo), math.log10(hi), N_FREQUENCIES)
    design = None
    if amplitude is not None:
        amps = [amplitude] * len(freqs_hz)
    elif inject == "mixer":
        design = AmplitudeDesign(amplitude_bound(inject))
        if swing_deg is not None:
            design.swing_deg = swing_deg
        amps = [None] * len(freqs_hz)
    else:
        amps = [default_amplitude(inject)] * len(freqs_hz)
    if cycles is not None:
        return SweepPlan(axis, inject, freqs_hz, amps, cycles, design=design)
    return SweepPlan(axis, inject, freqs_hz, amps, MEASURED_CYCLES, dwell=dwell or Dwell(),
                     design=design)


def multisine_plan(axis, inject="mixer", amplitude=None, lines=None, rig_time_s=None,
                   band_hz=None, like=None) -> SweepPlan:
    """A multisine over the axis's Table 1 band (or ``band_hz``) in ``rig_time_s``
    (:func:`heliquad.host.acquire.multisine.design`). ``amplitude`` is its peak; without it, the
    dwell's amplitude for angle and rate injection (the same largest setpoint), and for
    mixer injection the firmware's bound: the designed dwell reaches it on a rig in
    turbulence, and a multisine shares its power among its lines (on the vehicle's rigs in
    still air the roll rig then swings about 5 deg). ``like``: the same lines as that
    :class:`~heliquad.host.acquire.multisine.Multisine`, as many periods as fit ``rig_time_s``."""
    from .multisine import LINES, RIG_TIME_S, design

    if amplitude is None:
        amplitude = default_peak(inject)
    ms = design(band_hz or paper.BANDS_HZ[axis], amplitude, lines or LINES,
                rig_time_s or RIG_TIME_S, like=like)
    return SweepPlan.of_multisine(axis, inject, ms)


def _write_manifest(out_dir, manifest: SweepManifest) -> None:
    path = os.path.join(out_dir, MANIFEST)
    existed = os.path.exists(path)
    try:
        write_manifest(path, manifest)
    except DiskFull as exc:
        if existed:
            exc.also("its previous version is kept")
        raise


def sil_source(cfg) -> dict:
    """The manifest's ``source`` of a simulated sweep, from its SilConfig: what
    :mod:`.truth` needs to rebuild the plant (docs/file-formats.md)."""
    return {"kind": "sil", "plant": cfg.plant, "num": list(cfg.num), "den": list(cfg.den),
            "params": os.path.abspath(cfg.params) if cfg.params else None,
            "turbulence": cfg.turbulence, "seed": cfg.seed, "ideal_sensor": cfg.ideal_sensor,
            "collective": cfg.collective}


def _record_params(session, axis: str, manifest: SweepManifest, progress) -> None:
    """What the board flies: every parameter it has, read from it, and the axis's gains
    among them (host/records/gains.py)."""
    params = session_params(session, progress)
    if params is None:
        return
    manifest.params = {name: single(v) for name, v in params.items()}   # 2.422, not 2.4219999
    gains = gains_from_params(axis, params)
    manifest.gains = None if gains is None else dataclasses.asdict(gains)


def run_sweep(session, plan: SweepPlan, out_dir: str, source: dict, progress=print,
              max_angle_deg=MAX_ANGLE_DEG, max_rate_deg_s=MAX_RATE_DEG_S) -> dict:
    """Run the plan on ``session``; returns the manifest's document (as written to
    ``out_dir``).

    Ctrl-C and SIGTERM end the sweep in order (the manifest says so; the return is normal).
    Any other error that ends it (a full disk, the firmware died, the link lost) stops the
    excitation, records the error in the manifest's ``aborted`` and the frequency that was
    running in ``in_progress_hz``, and is raised again."""
    limits = Limits(max_angle_deg, max_rate_deg_s)
    manifest = SweepManifest(
        axis=plan.axis, inject=plan.inject, source=source, firmware=f"heliquad {__version__}",
        started=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        tlog=SWEEP_TLOG, tlog_start_us=getattr(session, "start_us", None),
        cycles=plan.cycles, fade_cycles=plan.fade_cycles, design=plan.record(),
        limits={"max_angle_deg": max_angle_deg, "max_rate_deg_s": max_rate_deg_s},
        signal=plan.signal, planned_hz=list(plan.freqs_hz))
    current = None
    try:
        _write_manifest(out_dir, manifest)
        session.hover(progress)
        _record_params(session, plan.axis, manifest, progress)
        _write_manifest(out_dir, manifest)
        last = None                              # (amplitude, rate per unit) just measured
        for i, (f, amp) in enumerate(zip(plan.freqs_hz, plan.amplitudes), 1):
            current = f
            entry, last = _measure_designed(session, plan, f, amp, last, limits, manifest,
                                            progress)
            manifest.frequencies.append(entry)
            current = None
            _write_manifest(out_dir, manifest)
            bar = "#" * i + "." * (len(plan.freqs_hz) - i)
            what = f"{entry.get('freq_hz', f):.4g} Hz" if plan.multisine is None else \
                f"multisine, {len(plan.multisine.orders)} lines on {entry.get('freq_hz', f):.4g} Hz"
            progress(f"[{bar}] {i}/{len(plan.freqs_hz)}  {what}  "
                     f"{entry['samples']} samples{loss_text(entry)}{saturation_text(entry)}  "
                     f"{entry['status']}")
            if entry["status"] != "ok":
                manifest.aborted = entry["status"]
                break
        else:
            manifest.complete = True
    except BaseException as exc:
        _stop_excitation(session)
        manifest.in_progress_hz = current             # None: during the hover, or between two
        if isinstance(exc, KeyboardInterrupt):
            how = ABORTED_BY[stopped_by(exc)]            # Ctrl-C, SIGTERM or SIGHUP
            manifest.aborted = how
            _keep_manifest(out_dir, manifest, exc)
            progress(f"{how}: the excitation is stopped; the log and manifest are kept")
            return manifest.document()
        manifest.aborted = _one_line(exc)
        _keep_manifest(out_dir, manifest, exc)
        raise
    _write_manifest(out_dir, manifest)
    return manifest.document()


def _measure_designed(session, plan, f, amp, last, limits, manifest, progress):
    """One frequency of a sweep, its amplitude designed when ``amp`` is None: (its manifest
    entry, (amplitude, rate per unit) for the next). A designed amplitude found less than
    half of what the swing target allows is finished after the least cycles (its entry
    kept as superseded) and the frequency is measured again with the better one; so is one
    whose input, amplified by the loop near its crossover, swings past the linear range."""
    redesign = None
    if amp is None:
        amp = plan.design.first() if last is None else plan.design.next(f, *last)
        redesign = lambda rpu, ipu: plan.design.next(f, amp, rpu, ipu)   # noqa: E731
    watch = measure(session, plan, f, amp, limits, progress, redesign=redesign)
    if watch.again is not None and watch.entry["status"] == "ok":
        why = ("swung the rig far less than the target" if watch.again > amp else
               "swung the axis's command past the linear range")
        watch.entry["status"] = (f"superseded: amplitude {amp:.3g} {why}; measured again at "
                                 f"{watch.again:.3g}")
        manifest.frequencies.append(watch.entry)
        progress(f"  {watch.entry.get('freq_hz', f):.4g} Hz: amplitude {amp:.3g} {why}; "
                 f"measuring again at {watch.again:.3g}")
        amp = watch.again
        watch = measure(session, plan, f, amp, limits, progress)
    return watch.entry, (amp, watch.rate_per_unit(), watch.rate_per_unit(of="input"))


def _stop_excitation(session) -> None:
    """Ask the firmware to stop the excitation, as far as the link still carries it."""
    try:
        session.tel.stop_excitation()
    except Exception:                  # the port went away: nothing more can be sent on it
        pass


def _one_line(exc: BaseException) -> str:
    """An error that ended a sweep, in one line for the manifest."""
    text = " ".join(str(exc).split())
    if isinstance(exc, (DiskFull, FirmwareError, InputError)):
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _keep_manifest(out_dir, manifest, exc: BaseException) -> None:
    """The last manifest of a sweep that ``exc`` ended. If it cannot be written either, the
    one line raised says both (and the previous manifest stays as it was)."""
    try:
        _write_manifest(out_dir, manifest)
    except DiskFull as failed:
        if isinstance(exc, DiskFull):
            exc.also(f"{MANIFEST} could not be updated either")
            exc.clauses.extend(failed.clauses)
            return
        raise failed.also(f"the sweep had stopped: {manifest.aborted}") from exc


def loss_text(entry) -> str:
    """``, N lost (x %)`` for the samples a frequency's window lost on the link (and the
    garbage bytes the link carried meanwhile), or ""."""
    lost, total = entry.get("lost", 0), entry.get("samples", 0) + entry.get("lost", 0)
    said = f", {lost} lost ({100 * lost / total:.1f} %)" if lost and total else ""
    if entry.get("garbage_bytes"):
        said += f", {entry['garbage_bytes']} garbage bytes"
    return said


def cut_text(manifest) -> str | None:
    """``the sweep was cut: WHY (K of N frequencies measured)`` for a sweep that did not
    complete (Ctrl-C, a breach, a board that went away), or None."""
    if manifest.get("complete", True):
        return None
    measured = sum(1 for f in manifest["frequencies"] if f.get("status") == "ok")
    planned = manifest.get("planned_hz")
    of = f" of {len(planned)}" if planned else ""
    return (f"the sweep was cut: {manifest.get('aborted') or 'it did not complete'} "
            f"({measured}{of} frequencies measured)")


def saturation_summary(counts) -> str:
    """``N saturated the mixer, ...`` for the saturation counts of a frequency's window (a
    manifest entry, or any mapping with its keys), or "" when nothing saturated."""
    return ", ".join(f"{counts[key]} {words}" for key, (_, words) in SATURATION.items()
                     if counts.get(key))


def saturation_text(entry) -> str:
    """`` (N saturated the mixer, ...)`` for what saturated in a frequency's window, or ""."""
    said = saturation_summary(entry)
    return f" ({said})" if said else ""


class Limits:
    """The host's second line of safety: a sample beyond either ends the excitation."""

    def __init__(self, max_angle_deg=MAX_ANGLE_DEG, max_rate_deg_s=MAX_RATE_DEG_S):
        self.max_angle_deg, self.max_rate_deg_s = max_angle_deg, max_rate_deg_s

    def breach(self, axis: str, m) -> str | None:
        """Why sample ``m`` breaches the limits, or None. The angle limit is the roll and
        pitch rigs' swing; on the yaw rig the logged angle is the heading, which is free."""
        swing = abs(math.degrees(m.angle)) if axis != "yaw" else 0.0
        if swing > self.max_angle_deg or abs(math.degrees(m.rate)) > self.max_rate_deg_s:
            return (f"aborted: limit breached at {m.time_us * 1e-6:.2f} s (angle "
                    f"{math.degrees(m.angle):.1f} deg, rate {math.degrees(m.rate):.1f} deg/s)")
        return None


class ExcitationWatch:
    """Watches one excitation, message by message (a session's ``handle``): its answer, its
    samples, its end. ``entry`` is what the manifest records of it; ``done`` is set once it
    ended (the messages after that are ignored), ``stop`` when the host must stop it. With
    ``keep_rows``, the full-amplitude samples' (t_s, u, y) are kept in ``rows``.

    Counted per full-amplitude window, from what the firmware reports in each sample
    (HQ_SYSID_SAMPLE.saturation): samples whose torque command the mixer could not meet
    (``saturated``), whose collective gave way (``collective_limited``), whose gyro or
    accelerometer read full scale (``sensor_clipped``); and gaps in the samples' sequence
    numbers (``seq_gaps``, lost telemetry).

    Samples lost inside the full-amplitude window are kept as holes in the record (NaN,
    ``present`` False) so that every sample keeps its place in the period; ``lost`` counts
    them (with those lost at the window's edges, once the window is known) and ``lost_run``
    the longest run. More than :data:`MAX_LOST_RUN` in a row, or more than
    :data:`MAX_LOST_SHARE` of the window, ends the frequency."""

    def __init__(self, plan, f, amp, limits: Limits, now_us: int, progress=print,
                 keep_rows: bool = False):
        mav = dialect()
        self.idle, self.running = mav.HQ_EXCITATION_STATE_IDLE, mav.HQ_EXCITATION_STATE_RUNNING
        self.normal_end = (mav.HQ_REASON_NONE, mav.HQ_REASON_FINISHED)
        self.flags = {key: sum(getattr(mav, f"HQ_SATURATION_{bit}") for bit in bits)
                      for key, (bits, _) in SATURATION.items()}
        self.warning = mav.MAV_SEVERITY_WARNING
        self.plan, self.limits, self.progress = plan, limits, progress
        self.entry = {"requested_hz": f, "amplitude": amp, "samples": 0, "seq_gaps": 0,
                      "lost": 0, "lost_run": 0,
                      **dict.fromkeys(self.flags, 0), "status": "ok"}
        if plan.multisine is not None:
            self.entry.update(signal="multisine", orders=list(plan.multisine.orders))
        self.u_name, self.y_name = INPUT_OUTPUT[plan.inject]
        self.keep_rows = keep_rows
        self.record = ([], [], [], [])          # t, r, u, y of the full-amplitude samples
        self.present = []                       # False where a sample of it was lost
        self.dt_us = None                       # the loop's period, from the samples
        self.first_run_seq = self.last_run_seq = None
        self.edge_room = [0, None]              # samples lost just before / after the window
        self.started_us, self.last_sample_us = now_us, now_us
        self.seen_active, self.last_seq, self.fresh = False, None, False
        self.last_time_us = None
        self.done, self.stop = False, False
        self.finish = False                     # the dwell has its point: finish in order
        self.redesign = None                    # amplitude -> a better one, designed
        self.again = None                       # the amplitude to measure again with

    @property
    def rows(self):
        """(t, u, y) of every full-amplitude sample that arrived, for RUN.csv
        (``keep_rows``)."""
        t, _, u, y = self.record
        return [row for row, ok in zip(zip(t, u, y), self.present) if ok] \
            if self.keep_rows else None

    def columns(self, n=None):
        """(r, u, y, present) of the first ``n`` samples of the window (all by default) as
        arrays, ``present`` None when none was lost."""
        r, u, y = (np.asarray(c[:n], dtype=float) for c in self.record[1:])
        present = np.asarray(self.present[:n], dtype=bool)
        return r, u, y, (None if present.all() else present)

    def __call__(self, m) -> None:
        if self.done:
            return
        kind = m.get_type()
        if kind == "HQ_EXCITATION_STATUS":
            self._status(m)
        elif kind == "HQ_SYSID_SAMPLE":
            self._sample(m)
        elif kind == "STATUSTEXT" and m.severity <= self.warning:
            self.entry.setdefault("messages", []).append(m.text)
            self.progress(f"firmware: {m.text}")

    def _end(self, status: str | None = None, stop: bool = False) -> None:
        if status:
            self.entry["status"] = status
        self.done, self.stop = True, stop

    def _status(self, m) -> None:
        # Whatever arrives first: the answer to this start, or (if that was lost on a
        # board's link) the status of its end, which carries the same fields.
        if not m.accepted:                       # only a start is ever refused
            return self._end(f"refused by the firmware: {reason_text(m.reason)}")
        if "freq_hz" not in self.entry or self.entry.pop("period_inferred", False):
            self.entry.update(freq_hz=float(m.freq_hz), period_samples=int(m.period_samples))
            if self.plan.multisine is not None:
                self.entry["fade_samples"] = int(m.fade_samples)
        if m.state == self.idle and m.reason not in self.normal_end:
            self._end(f"stopped by the firmware: {reason_text(m.reason)}")

    def _infer_period(self) -> None:
        """The start's answer was lost on the link: the period the firmware chose from the
        request (the nearest whole number of loop samples, excitation.cpp), on the loop
        period the samples show; an answer that arrives later overrides it."""
        e = self.entry
        if "freq_hz" in e or not self.dt_us:
            return
        loop_hz = 1e6 / self.dt_us
        period = max(int(round(loop_hz / e["requested_hz"])), 1)
        e.update(freq_hz=loop_hz / period, period_samples=period, period_inferred=True)
        if self.plan.multisine is not None:
            lowest = self.plan.multisine.orders[0]
            e["fade_samples"] = self.plan.fade_cycles * -(-period // lowest)

    def _sample(self, m) -> None:
        e = self.entry
        gap = 0
        if self.last_seq is not None and m.seq > self.last_seq + 1:
            gap = m.seq - self.last_seq - 1
            e["seq_gaps"] += gap
        if self.last_seq is not None and m.seq > self.last_seq:
            self.dt_us = (m.time_us - self.last_time_us) / (m.seq - self.last_seq)
        running_before = self.last_seq is not None and self.last_seq == self.last_run_seq
        self.last_seq, self.last_time_us, self.fresh = m.seq, m.time_us, True
        if m.exc_state != self.idle:
            self.seen_active = True
        if m.exc_state == self.running:
            if self.first_run_seq is None:
                self.first_run_seq, self.edge_room[0] = m.seq, gap
            self._running(m, gap if running_before else 0)
            if self.done:
                return
        elif self.last_run_seq is not None and self.edge_room[1] is None:
            self.edge_room[1] = m.seq - self.last_run_seq - 1
        breach = self.limits.breach(self.plan.axis, m)
        if breach:
            return self._end(breach, stop=True)
        if self.seen_active and m.exc_state == self.idle:
            self._end(_incomplete(e, self.plan, self.finish, self.edge_room) or
                      _too_lossy(e))

    def _running(self, m, holes: int) -> None:
        """A full-amplitude sample, after ``holes`` lost inside the window."""
        e = self.entry
        self._infer_period()
        e.setdefault("start_us", int(m.time_us))
        e["end_us"] = int(m.time_us)
        e["samples"] += 1
        self.last_run_seq = m.seq
        if holes:
            e["lost"] += holes
            e["lost_run"] = max(e["lost_run"], holes)
            t0 = self.record[0][-1]
            for i in range(1, holes + 1):
                for column, value in zip(self.record, (t0 + i * self.dt_us * 1e-6, math.nan,
                                                       math.nan, math.nan)):
                    column.append(value)
                self.present.append(False)
            if holes > MAX_LOST_RUN:
                return self._end(f"lost {holes} samples in a row on the link (more than "
                                 f"{MAX_LOST_RUN}): the link is dropping out", stop=True)
        for key, bits in self.flags.items():
            if m.saturation & bits:
                e[key] += 1
        for column, value in zip(self.record, (m.time_us * 1e-6, m.excitation,
                                               getattr(m, self.u_name),
                                               getattr(m, self.y_name))):
            column.append(value)
        self.present.append(True)
        self._dwell()

    def _dwell(self) -> None:
        """The sequential dwell, halfway through each cycle from the least cycles' last on
        (so that a finish lands in that cycle, which the firmware completes): finish once
        the point of the whole cycles so far, with that cycle added, is known well enough;
        or, at the first such moment, when the amplitude turns out less than half of what
        the swing target allows, finish to measure again."""
        dwell, e = self.plan.dwell, self.entry
        period = e.get("period_samples")
        if dwell is None or self.finish or not period:
            return
        cycles, into = divmod(len(self.present), period)
        if into != period // 2 or cycles < dwell.min_cycles - 1:
            return
        fs = e["freq_hz"] * period
        r, u, y, present = self.columns(cycles * period)
        relative = dwell.relative_sigma(r, u, y, fs, e["freq_hz"], present)
        used = cycles - 1                       # the first measured cycle is discarded
        if cycles == dwell.min_cycles - 1 and self.redesign is not None:
            better = self.redesign(self.rate_per_unit(require_end=False),
                                   self.rate_per_unit(require_end=False, of="input"))
            if better is not None and better <= 0.75 * e["amplitude"]:
                self.finish, self.again = True, better      # past the linear range: too late
                return                                      # for any precision to help
            if better is not None and better >= 2 * e["amplitude"] and not (
                    used >= 1 and relative * math.sqrt(used / (used + 1)) <= dwell.target_sigma):
                self.finish, self.again = True, better
                return
        if used >= 1 and relative * math.sqrt(used / (used + 1)) <= dwell.target_sigma:
            self.finish = True

    def rate_per_unit(self, require_end: bool = True, of: str = "rate") -> float:
        """The measured rate (``of="input"``: input) per unit of excitation at the
        fundamental (NaN if unknown: an excitation that did not end well, or an output
        that is not the rate)."""
        from .design import response_per_unit

        e = self.entry
        if not e.get("period_samples") or self.y_name != "rate" or (
                require_end and e["status"] != "ok"):
            return math.nan
        r, u, y, present = self.columns()
        return response_per_unit(r, u if of == "input" else y, e["freq_hz"] * e["period_samples"],
                                 e["freq_hz"], present)

    def conclude(self) -> None:
        """A sequential dwell's record in the entry: the cycles measured, why the dwell
        ended, and the point's relative sigma then."""
        e, dwell = self.entry, self.plan.dwell
        if dwell is None or e["status"] != "ok" or not e.get("period_samples"):
            return
        e["cycles"] = (e["samples"] + e["lost"]) // e["period_samples"]
        e["dwell_end"] = ("amplitude" if self.again is not None else "target") if self.finish \
            else "cap"
        r, u, y, present = self.columns()
        relative = dwell.relative_sigma(r, u, y, e["freq_hz"] * e["period_samples"],
                                        e["freq_hz"], present)
        e["relative_sigma"] = relative if math.isfinite(relative) else None

    def check_time(self, now_us: int) -> None:
        """The timeouts, on the session's clock: no start, or samples that stopped."""
        if self.fresh:
            self.last_sample_us, self.fresh = now_us, False
        if self.done:
            return
        if not self.seen_active and now_us - self.started_us > START_TIMEOUT_S * 1e6:
            self._end("the excitation did not start (no answer from the firmware)")
        elif self.seen_active and now_us - self.last_sample_us > SAMPLE_TIMEOUT_S * 1e6:
            # stop too, in case the board is there but deaf
            self._end(f"no samples for {SAMPLE_TIMEOUT_S:g} s: the board stopped sending "
                      "(link lost or board hung)", stop=True)


def measure(session, plan, f, amp, limits: Limits | None = None, progress=print,
            keep_rows: bool = False, redesign=None) -> ExcitationWatch:
    """One excitation on ``session``: start it, watch it to its end, stop it if the host
    must. The one routine every experiment (a sweep's frequency, ``heliquad sil``) runs.
    ``redesign``: for a designed amplitude, rate per unit -> the amplitude the design would
    now choose (the sequential dwell may finish early to measure again with it). A link
    that goes away (the board unplugged) ends it as a board that fell silent does: with
    that status, the records kept. The bytes the link's framer skipped meanwhile (damage,
    noise) are counted in the entry's ``garbage_bytes`` where the session counts them."""
    watch = ExcitationWatch(plan, f, amp, limits or Limits(), session.time_us, progress,
                            keep_rows)
    watch.redesign = redesign
    garbage = getattr(session, "garbage_bytes", None)
    try:
        _watch(session, plan, f, amp, watch)
    except LinkLost as exc:
        watch.done = True
        watch.entry["status"] = f"the board went away: {exc}"
    if garbage is not None:
        watch.entry["garbage_bytes"] = session.garbage_bytes - garbage
    watch.conclude()
    return watch


def _watch(session, plan, f, amp, watch) -> None:
    session.tel.start_excitation(plan.axis, plan.inject, f, amp, plan.cycles_for(f),
                                 plan.fade_cycles,
                                 plan.multisine.harmonics() if plan.multisine else None)
    finishing = False
    while not watch.done:
        session.advance(watch)
        watch.check_time(session.time_us)
        if watch.finish and not finishing:
            session.tel.finish_excitation()
            finishing = True
    if watch.stop:
        session.tel.stop_excitation()


def _incomplete(entry, plan, finished: bool, edge_room=(0, 0)) -> str | None:
    """An excitation that ended without a stop message must still have all its measured
    samples (a lost status message must not pass a truncated record as complete), those
    that arrived and those lost on the link: holes inside the window, and at its edges no
    more than the samples lost there (``edge_room``: lost just before its first sample and
    just after its last). One the dwell finished early must hold whole cycles, at least the
    dwell's least. Sets the entry's ``lost`` to every sample of the window not logged."""
    period = entry.get("period_samples", 0)
    span = entry["samples"] + entry["lost"]               # first to last that arrived
    room = edge_room[0] + (edge_room[1] or 0)
    if not period:
        return (f"incomplete: {entry['samples']} measured samples were logged and the "
                "excitation's period is not known (its status and samples were lost)")
    if finished:
        least = plan.dwell.min_cycles * period
        whole = -(-span // period) * period
        if whole - span > room or whole < least:
            return (f"incomplete: {entry['samples']} measured samples were logged"
                    f"{_lost_text(entry)}, not whole cycles of {period} (at least {least})")
        expected = whole
    else:
        expected = plan.cycles_for(entry["requested_hz"]) * period
        if not 0 <= expected - span <= room:
            return (f"incomplete: {entry['samples']} of {expected} measured samples were "
                    f"logged{_lost_text(entry)}")
    entry["lost_run"] = max(entry["lost_run"], expected - span)   # at the edges: at most
    entry["lost"] = expected - entry["samples"]
    return None


def _lost_text(entry) -> str:
    return f" ({entry['lost']} lost on the link)" if entry["lost"] else ""


def _too_lossy(entry) -> str | None:
    """Why a complete window lost too much of itself on the link to be measured, or None."""
    total = entry["samples"] + entry["lost"]
    if total and entry["lost"] > MAX_LOST_SHARE * total:
        return (f"lost {entry['lost']} of {total} measured samples on the link "
                f"({100 * entry['lost'] / total:.1f} %, more than {100 * MAX_LOST_SHARE:g} %)")
    return None
