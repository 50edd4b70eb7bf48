"""One excitation measured: started over the telemetry link, watched sample by sample to its
end and judged (:func:`measure`, :class:`ExcitationWatch`). The one routine every sweep
frequency and ``heliquad sil`` run, on any session (:mod:`heliquad.host.acquire.session`).

The watch follows the firmware's HQ_EXCITATION_STATUS (which gives the exact frequency
used) and every HQ_SYSID_SAMPLE: it counts what saturated, the samples lost on the link and
the garbage bytes, applies the host's second line of safety (:class:`Limits`: a sample
beyond the rig's swing or rate ends the excitation), times out an excitation that never
starts or whose samples stop, and finishes the sequential dwell early when its cycles
suffice. Its entry (a manifest's per-frequency record) says how it ended.
"""

from __future__ import annotations

import math

import numpy as np

from ...sim.base import firmware_facts
from ...sim.base.dialect import dialect
from ...sim.base.errors import LinkLost
from .chirp import fade_samples
from .design import line_sdr, response_per_unit
from .redesign import disturbance_sigmas
from .link import reason_text, response_fields

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



def loss_text(entry) -> str:
    """``, N lost (x %)`` for the samples a frequency's window lost on the link (and the
    garbage bytes the link carried meanwhile), or ""."""
    lost, total = entry.get("lost", 0), entry.get("samples", 0) + entry.get("lost", 0)
    said = f", {lost} lost ({100 * lost / total:.1f} %)" if lost and total else ""
    if entry.get("garbage_bytes"):
        said += f", {entry['garbage_bytes']} garbage bytes"
    return said



def saturation_masks() -> dict:
    """Each saturation count's HQ_SATURATION bits as one mask, ``{manifest key: mask}``."""
    mav = dialect()
    return {key: sum(getattr(mav, f"HQ_SATURATION_{bit}") for bit in bits)
            for key, (bits, _) in SATURATION.items()}


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
        self.flags = saturation_masks()
        self.warning = mav.MAV_SEVERITY_WARNING
        self.plan, self.limits, self.progress = plan, limits, progress
        self.entry = {"requested_hz": f, "amplitude": amp, "samples": 0, "seq_gaps": 0,
                      "lost": 0, "lost_run": 0,
                      **dict.fromkeys(self.flags, 0), "status": "ok"}
        if plan.multisine is not None:
            self.entry.update(signal="multisine", orders=list(plan.multisine.orders))
        if plan.chirp is not None:
            self.entry.update(signal="chirp", stop_hz=plan.chirp.stop_hz,
                              sweep_s=plan.chirp.sweep_s, law=plan.chirp.law)
        self.u_name, self.y_name = response_fields(plan.inject, plan.response)
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
            if self.plan.multisine is not None or self.plan.chirp is not None:
                self.entry["fade_samples"] = int(m.fade_samples)
            if self.plan.chirp is not None:          # its full-amplitude part: the sweep
                self.entry["sweep_samples"] = int(m.total_samples) - 2 * int(m.fade_samples)
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
        # a chirp's frequency is used as given: it has no period to round to
        used = e["requested_hz"] if self.plan.chirp is not None else loop_hz / period
        e.update(freq_hz=used, period_samples=period, period_inferred=True)
        if self.plan.multisine is not None:
            lowest = self.plan.multisine.orders[0]
            e["fade_samples"] = self.plan.fade_cycles * -(-period // lowest)
        if self.plan.chirp is not None:            # as excitation.cpp counts them
            e["sweep_samples"] = int(round(self.plan.chirp.sweep_s * loop_hz))
            e["fade_samples"] = fade_samples(self.plan.chirp.band_hz[0], self.plan.fade_cycles,
                                             loop_hz)

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
        self._sequential_multisine()

    def _judging(self, least) -> int | None:
        """The whole periods (a dwell's cycles) so far when a sequential rule whose least is
        ``least`` (None: no rule) judges the record: halfway through each period from the
        least's last on; None at any other sample, or once the excitation is finishing."""
        period = self.entry.get("period_samples")
        if least is None or self.finish or not period:
            return None
        periods, into = divmod(len(self.present), period)
        return periods if into == period // 2 and periods >= least - 1 else None

    def _dwell(self) -> None:
        """The sequential dwell, halfway through each cycle from the least cycles' last on
        (so that a finish lands in that cycle, which the firmware completes): finish once
        the point of the whole cycles so far, with that cycle added, is known well enough;
        or, at the first such moment, when the amplitude turns out less than half of what
        the swing target allows, finish to measure again."""
        dwell, e = self.plan.dwell, self.entry
        cycles = self._judging(dwell and dwell.min_cycles)
        if cycles is None:
            return
        period = e["period_samples"]
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

    def _sequential_multisine(self) -> None:
        """The sequential multisine, halfway through each base period from its least
        periods' last on (so that a finish lands in that period, which the firmware
        completes): finish once every line of the whole periods so far, with that period
        added, is known well enough (the dwell's rule, line by line)."""
        rule, e = self.plan.sequential, self.entry
        periods = self._judging(rule and rule.min_periods)
        if periods is None:
            return
        period = e["period_samples"]
        r, u, y, present = self.columns(periods * period)
        sigmas = rule.relative_sigmas(r, u, y, e["freq_hz"] * period, period,
                                      self.plan.multisine.orders, present)
        if rule.met(sigmas, periods - 1):       # the first period fills the FSF's filter
            self.finish = True

    def rate_per_unit(self, require_end: bool = True, of: str = "rate") -> float:
        """The measured rate (``of="input"``: input) per unit of excitation at the
        fundamental (NaN if unknown: an excitation that did not end well, or an output
        that is not the rate)."""
        e = self.entry
        if not e.get("period_samples") or self.y_name != "rate" or (
                require_end and e["status"] != "ok"):
            return math.nan
        r, u, y, present = self.columns()
        return response_per_unit(r, u if of == "input" else y, e["freq_hz"] * e["period_samples"],
                                 e["freq_hz"], present)

    def conclude(self) -> None:
        """A sequential dwell's record in the entry: the cycles measured, why the dwell
        ended, and the point's relative sigma then (a sequential multisine's:
        :meth:`_conclude_multisine`)."""
        if self.plan.sequential is not None:
            return self._conclude_multisine()
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

    def _conclude_multisine(self) -> None:
        """A sequential multisine's record in the entry: the base periods measured, why it
        ended (``target``: every line known well enough; ``cap``: its rig time ran out), and
        per line its sigma over its magnitude and its signal-to-disturbance ratio in the
        output (:func:`.design.line_sdr`)."""
        e, rule = self.entry, self.plan.sequential
        if e["status"] != "ok" or not e.get("period_samples"):
            return
        period, orders = e["period_samples"], self.plan.multisine.orders
        e["periods"] = (e["samples"] + e["lost"]) // period
        e["multisine_end"] = "target" if self.finish else "cap"
        r, u, y, present = self.columns()
        sigmas = rule.relative_sigmas(r, u, y, e["freq_hz"] * period, period, orders, present)
        e["line_sigma"] = [float(s) if math.isfinite(s) else None for s in sigmas]
        e["line_sdr"] = line_sdr(y, period, orders, present)
        e["line_disturbance"] = disturbance_sigmas(u, y, period, orders, present)

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
    chirp = plan.chirp
    session.tel.start_excitation(plan.axis, plan.inject, f, amp, plan.cycles_for(f),
                                 plan.fade_cycles,
                                 plan.multisine.harmonics() if plan.multisine else None,
                                 (chirp.stop_hz, chirp.sweep_s, chirp.law) if chirp else None)
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
        least = (plan.dwell.min_cycles if plan.dwell is not None
                 else plan.sequential.min_periods) * period
        whole = -(-span // period) * period
        if whole - span > room or whole < least:
            return (f"incomplete: {entry['samples']} measured samples were logged"
                    f"{_lost_text(entry)}, not whole cycles of {period} (at least {least})")
        expected = whole
    else:
        expected = entry["sweep_samples"] if plan.chirp is not None else \
            plan.cycles_for(entry["requested_hz"]) * period
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
