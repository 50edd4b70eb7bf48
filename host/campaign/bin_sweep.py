"""A board's on-board log (.BIN) as the sweep it flew, for ``heliquad identify FILE.BIN``: the
excitations found in its logged loops, each as a sweep manifest's frequency entry
(docs/file-formats.md, "A sweep folder"), so that identify measures them exactly as it
measures a sweep folder's.

An excitation is a run of loops whose SIDD gives one start (the loop's time less SIDD's time
into the excitation), and one frequency unless it is a chirp (SIDD's F moves, and the SIDS at
its start names its two ends; one whose SIDS is missing is not measured); a loop missing
from the log (an HQGP gap) leaves it whole, the loop a hole. Each loop's place in it is its
loop number less the start's. Its set-up is the SIDS logged at that start: the fades (TFin)
and the planned full-amplitude part (TC), in loops on the log's loop period; the period in
loops is the loop rate over SIDD's F, the frequency the firmware used. The full-amplitude
window runs from the fade-in's end to the loop before the first fade-out loop; its loops the
log misses are lost, as on a link. An excitation is measured when its fade-out is in the log
(the firmware ended it in order, a finished dwell too) or its logged window reaches the
planned end; one stopped at once (the abort limits, the host's heartbeat lost) or cut off by
the log's end or damage is not measured, and the manifest says so as it says a sweep that
was cut (``complete`` false, ``aborted`` naming each such excitation). An excitation of the
same frequency later in the log supersedes an earlier one (a sweep measures a frequency
again at another amplitude).

A multisine's lines are read from its logged excitation: the full-amplitude periods the log
holds whole, averaged and transformed, give one line per harmonic whose amplitude is more
than :data:`LINE_FLOOR` of the largest (the firmware computes the signal in float, so the
harmonics it does not excite stay below 1e-6 of it). SIDS names only the band's edges (FSt,
FSp), and reading the lines from the signal needs no field the log does not have; the edges
SIDS gives tell a multisine from a sine. Each line's phase is read with it; multisines on the
same lines at two peaks, whose phases differ between those of one peak, are a linearity
campaign's realisations (:func:`_linearity`), each used, none superseded. A multisine
followed by one on the same lines at the same declared peak whose lines' relative
amplitudes or phases differ is a redesigned multisine's two passes (:func:`_redesigns`):
both used, identify combines them.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from ...sim.base.dialect import AXES, INJECTIONS, dialect
from ...sim.base.errors import InputError
from ...sim.base.firmware_facts import LOOP_RATE_HZ
from ..acquire.measure import saturation_masks
from ..records.bin_log import read_bin
from ..records.gains import gains_from_params

__all__ = ["bin_sweep", "log_sweep", "LINE_FLOOR"]

#: A multisine's line is a harmonic above this share of the largest line's amplitude.
LINE_FLOOR = 1e-4


@dataclasses.dataclass
class _Excitation:
    """One excitation's logged loops: their rows in the log's samples, their places in it."""
    rows: np.ndarray
    places: np.ndarray
    freq_hz: float
    setup: dict | None
    freqs: np.ndarray = None            # each loop's SIDD.F (a chirp's moves)

    @property
    def moves(self) -> bool:
        """Its SIDD.F moves (a chirp's does)."""
        return np.unique(self.freqs).size > 1

    @property
    def chirp(self) -> bool:
        """A chirp: its SIDD.F moves, and its SIDS names two ends."""
        return self.moves and self.setup is not None and self.setup["FSp"] != self.setup["FSt"]


def bin_sweep(path) -> tuple:
    """``(manifest, samples, damage)`` of the .BIN at ``path``: a manifest's document with the
    log's excitations as its frequencies (module docstring), the logged loops as
    HQ_SYSID_SAMPLE rows and what the reading left out. InputError when the log holds no
    excitation, or excites more than one axis or injection point."""
    return log_sweep(read_bin(path), path)


def log_sweep(log, path) -> tuple:
    """:func:`bin_sweep` of a log already read (a :class:`~heliquad.host.records.bin_log.BinLog`
    of the file ``path``)."""
    s = log.samples
    mav = dialect()
    active = np.flatnonzero(s.exc_state != mav.HQ_EXCITATION_STATE_IDLE)
    if not active.size:
        raise InputError(f"{path}: no excitation in the log ({s.size} loops logged"
                         + (f"; {log.damage.summary()}" if log.damage else "") + ")")
    axis, inject = _axis_injection(path, s[active])
    loop_us = _loop_period_us(s)
    entries = [_entry(e, s, loop_us, mav) for e in _excitations(log, active, loop_us)]
    design = _linearity(entries)
    if design is None:          # a campaign's realisations are each used, not superseded
        _redesigns(entries)
        _supersede(entries)
    unused = [e for e in entries if e["status"] != "ok" and
              not e["status"].startswith("superseded")]
    gains = gains_from_params(axis, log.params)
    manifest = {"axis": axis, "inject": inject, "tlog": os.path.basename(path),
                "source": {"kind": "log", "file": os.path.basename(path)},
                "signal": next((e["signal"] for e in entries if e.get("signal")), "dwell"),
                "frequencies": entries, "params": log.params or None,
                **({"design": design} if design else {}),
                "gains": None if gains is None else dataclasses.asdict(gains),
                "complete": not unused,
                "aborted": "; ".join(f"{e['freq_hz']:.4g} Hz {e['status']}" for e in unused)
                or None}
    return manifest, s, log.damage


def _axis_injection(path, active) -> tuple:
    """The one axis and injection point the log excites, by name."""
    pairs = sorted(set(zip(active.axis.tolist(), active.injection.tolist())))
    names = {v: k for k, v in AXES.items()}, {v: k for k, v in INJECTIONS.items()}
    said = [f"{names[0][a]} with {names[1][i]} injection" for a, i in pairs]
    if len(pairs) > 1:
        raise InputError(f"{path}: the log excites {' and '.join(said)}; identify takes one "
                         "axis and injection point")
    return names[0][pairs[0][0]], names[1][pairs[0][1]]


def _loop_period_us(s) -> float:
    """The loop period the logged loops show (the median of consecutive loops'), or the
    firmware's default when no two consecutive loops are logged."""
    step = np.diff(s.seq.astype(np.int64)) == 1
    if not step.any():
        return 1e6 / LOOP_RATE_HZ
    return float(np.median(np.diff(s.time_us.astype(np.int64))[step]))


def _excitations(log, active, loop_us) -> list:
    """The log's excitations (module docstring), in order."""
    s = log.samples
    starts = s.time_us[active].astype(float) - log.exc_time_s[active] * 1e6
    # a new start (a chirp's SIDD.F moves within one excitation)
    cut = np.flatnonzero(np.abs(np.diff(starts)) > loop_us / 2) + 1
    found, seq = [], s.seq.astype(np.int64)
    for rows in np.split(active, cut):
        first = rows[0]
        lead = int(round(log.exc_time_s[first] * 1e6 / loop_us))   # its place in it
        start_us = int(s.time_us[first]) - log.exc_time_s[first] * 1e6
        setup = next((u for u in log.setups if abs(u["TimeUS"] - start_us) < loop_us / 2),
                     None)
        found.append(_Excitation(rows, seq[rows] - (seq[first] - lead),
                                 float(log.exc_freq_hz[first]), setup,
                                 np.asarray(log.exc_freq_hz[rows], dtype=float)))
    return found


def _entry(e: _Excitation, s, loop_us: float, mav) -> dict:
    """The manifest's frequency entry of the excitation ``e`` (module docstring)."""
    period = max(int(round(1e6 / (loop_us * e.freq_hz))), 1)
    entry = {"requested_hz": e.freq_hz, "freq_hz": e.freq_hz, "period_samples": period,
             "amplitude": float(e.setup["Mag"]) if e.setup else
             float(np.max(np.abs(s.excitation[e.rows]))), "samples": 0, "status": "ok"}
    running = s.exc_state[e.rows] == mav.HQ_EXCITATION_STATE_RUNNING
    if not running.any():
        return {**entry, "status": "never at full amplitude in the log"}
    rows, places = e.rows[running], e.places[running]
    fade = int(min(round(e.setup["TFin"] * 1e6 / loop_us) if e.setup else places[0],
                   places[0]))
    planned = fade + int(round(e.setup["TC"] * 1e6 / loop_us)) - 1 if e.setup else None
    after = e.places[~running & (e.places > places[-1])]
    if after.size:
        last = int(after[0]) - 1
    elif places[-1] == planned:
        last = planned
    else:
        end = "the log ends" if e.rows[-1] == s.size - 1 else "it was stopped"
        return {**entry, "status": f"not whole in the log: {end} before its fade-out"}
    entry.update(start_us=int(s.time_us[rows[0]]), end_us=int(s.time_us[rows[-1]]),
                 samples=int(rows.size), lost=int(last - fade + 1 - rows.size),
                 **{k: int(np.count_nonzero(s.saturation[rows] & mask))
                    for k, mask in saturation_masks().items()})
    if e.chirp:
        return {**entry, **_chirp_entry(e, rows, fade, last, loop_us)}
    if e.moves:
        return {**entry, "status": "its frequency moves (a chirp) but the log has no SIDS "
                                   "naming its two ends"}
    lines = _lines(s.excitation[rows].astype(float), places - fade, last - fade + 1, period,
                   fade)
    if lines is None:
        return {**entry, "status": "no whole period of its excitation in the log"}
    orders, phases, amplitudes = lines
    if orders != [1] or (e.setup and e.setup["FSp"] > e.setup["FSt"]):
        entry.update(signal="multisine", orders=orders, fade_samples=fade, phases_rad=phases,
                     line_amplitudes=amplitudes)
    return entry


def _chirp_entry(e: _Excitation, rows, fade: int, last: int, loop_us: float) -> dict:
    """A chirp's entry fields (as a sweep's manifest has them): its ends from SIDS (FSt,
    FSp), its sweep's length (the window's loops), and its law read from SIDD's F, the
    frequency at the sweep's middle: geometric (log) or arithmetic (linear) of its ends."""
    start, stop = float(e.setup["FSt"]), float(e.setup["FSp"])
    middle = float(np.interp((fade + last) / 2.0, e.places, e.freqs))
    law = "log" if abs(middle - math.sqrt(start * stop)) < abs(middle - (start + stop) / 2) \
        else "linear"
    sweep = last - fade + 1
    return {"signal": "chirp", "freq_hz": start, "requested_hz": start, "stop_hz": stop,
            "sweep_s": sweep * loop_us * 1e-6, "law": law, "sweep_samples": sweep,
            "fade_samples": fade}


def _lines(r, places, length: int, period: int, fade: int) -> tuple | None:
    """``(harmonics, their phases, their amplitudes)``: the harmonics of ``period`` the
    excitation ``r`` (at ``places`` of a window ``length`` long, which starts ``fade``
    samples into the excitation) has, from its periods the log holds whole, each one's
    phase (rad, of its sine, at the excitation's start as the design gives it) and
    amplitude; None without one."""
    grid = np.full(length // period * period, np.nan)
    inside = places < grid.size
    grid[places[inside]] = r[inside]
    periods = grid.reshape(-1, period)
    whole = periods[~np.isnan(periods).any(axis=1)]
    spectrum = np.fft.rfft(whole.mean(axis=0))[1:] if whole.size else np.zeros(1)
    amplitude = np.abs(spectrum)
    if not amplitude.max() > 0:
        return None
    lines = np.flatnonzero(amplitude > LINE_FLOOR * amplitude.max())
    # a sine's phase p: its DFT bin is proportional to exp(j (p - pi / 2)); the window's
    # start is the fade's length after the excitation's, where the design's phase is
    shift = 2 * np.pi * (lines + 1) * fade / period
    return ((lines + 1).tolist(),
            [float(np.angle(spectrum[k] * np.exp(-1j * d)) + np.pi / 2)
             for k, d in zip(lines, shift)],
            [float(2 * amplitude[k] / period) for k in lines])


def _phase_step(a, b):
    """How far apart phases ``a`` and ``b`` are (rad, 0 to pi, elementwise)."""
    return np.abs(np.angle(np.exp(1j * (a - b))))


#: Two realisations of a linearity campaign differ in some line's phase by more than this.
PHASES_DIFFER_RAD = 0.1


def _linearity(entries) -> dict | None:
    """A linearity campaign's design read from its log (sweep --linearity), or None: every
    measured multisine on the same lines of the same period, at two peaks, and at each peak
    at least two whose phases differ (random-phase realisations; the same multisine flown
    again is not one). Its entries get their level (0 the larger peak) and realisation."""
    ok = [e for e in entries if e["status"] == "ok" and e.get("signal") == "multisine"]
    if len(ok) < 4 or len({(e["freq_hz"], tuple(e["orders"])) for e in ok}) != 1 or \
            any(e["status"] == "ok" and e.get("signal") != "multisine" for e in entries):
        return None
    peaks = sorted({e["amplitude"] for e in ok}, reverse=True)
    if len(peaks) != 2:
        return None
    levels = [[e for e in ok if e["amplitude"] == peak] for peak in peaks]
    for level in levels:
        phases = np.array([e["phases_rad"] for e in level])
        step = _phase_step(phases[:, None, :], phases[None, :, :])
        distinct = step.max(axis=2) > PHASES_DIFFER_RAD
        if len(level) < 2 or not distinct[~np.eye(len(level), dtype=bool)].all():
            return None
    for index, level in enumerate(levels):
        for realisation, e in enumerate(level):
            e.update(level=index, realisation=realisation)
    return {"linearity": {"realisations": max(len(level) for level in levels), "peaks": peaks,
                          "design": "read from the log"}}


def _redesigns(entries) -> None:
    """A redesigned multisine's two passes (sweep --redesign): a measured multisine and the
    next measured excitation, a multisine on the same lines of the same period at the same
    declared peak whose lines' amplitudes relative to their median differ from the first's
    by more than :data:`AMPLITUDES_DIFFER`, or whose phases by more than
    :data:`PHASES_DIFFER_RAD`, on some line (the same multisine flown again has the same
    of both; a second pass of equal lines, the first's phases too: read as flown again, its
    first pass superseded). The second gets ``redesign_of``
    (the first's index) and ``weights`` (those relative amplitudes), as the sweep's
    manifest has them."""
    ok = [i for i, e in enumerate(entries) if e["status"] == "ok"]
    for i, j in zip(ok, ok[1:]):
        a, b = entries[i], entries[j]
        if a.get("signal") != "multisine" or b.get("signal") != "multisine" or \
                "redesign_of" in a or (a["freq_hz"], a["orders"], a["amplitude"]) != \
                (b["freq_hz"], b["orders"], b["amplitude"]):
            continue
        wa, wb = (np.asarray(e["line_amplitudes"]) / np.median(e["line_amplitudes"])
                  for e in (a, b))
        step = _phase_step(np.asarray(b["phases_rad"]), np.asarray(a["phases_rad"]))
        if np.max(np.abs(np.log(wb / wa))) > math.log(1 + AMPLITUDES_DIFFER) or \
                np.max(step) > PHASES_DIFFER_RAD:
            b.update(redesign_of=i, weights=[float(w) for w in wb])


#: Two multisines' lines differ in relative amplitude when one line's differs by this share.
AMPLITUDES_DIFFER = 0.1


def _supersede(entries) -> None:
    """An excitation measured again later in the log (the same signal at the same frequency)
    is superseded by the later one, unless the later one is its redesigned pass."""
    for i, e in enumerate(entries):
        again = next((f for f in entries[i + 1:] if f["status"] == "ok" and
                      f["freq_hz"] == e["freq_hz"] and f.get("orders") == e.get("orders") and
                      f.get("redesign_of") != i), None)
        if e["status"] == "ok" and again is not None:
            e["status"] = (f"superseded: measured again later in the log (amplitude "
                           f"{again['amplitude']:.4g})")
