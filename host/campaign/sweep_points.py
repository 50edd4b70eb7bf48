"""A sweep's records to frequency-response points: each measured frequency's record cut from
the log (a dwell's full-amplitude window, a multisine's, a chirp's whole excitation with its
fades), samples lost on the link as holes, and its points estimated: the FSF for a sine, one
point per line for a multisine, the composite of windows (:mod:`..estimate.composite`) for a
chirp; against the logged excitation or the measured input.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...sim.base.dialect import dialect
from ...sim.base.errors import InputError
from ..acquire.link import response_fields
from ..acquire.measure import MAX_LOST_RUN, MAX_LOST_SHARE
from ..acquire.redesign import combined_points
from ..estimate.composite import MIN_COHERENCE, composite_response
from ..estimate.fsf import (complete_excitation, estimate_against_excitation, estimate_fsf,
                            estimate_multisine, estimate_multisine_against_excitation,
                            fill_lost)
from .record import RECORD_POINTS, coherent, longest_run

__all__ = ["sweep_segments", "estimate_points"]


def sweep_segments(manifest, samples):
    """Each measured frequency's full-amplitude record: (entry, t, r, u, y, present), the
    samples on their places in the sequence (:func:`_gridded`). A chirp's record is its
    whole excitation, fades included: they hold its two ends' frequencies, which the sweep
    itself only passes through."""
    mav = dialect()
    running, idle = mav.HQ_EXCITATION_STATE_RUNNING, mav.HQ_EXCITATION_STATE_IDLE
    u_name, y_name = response_fields(manifest["inject"], manifest.get("response"))
    t = samples.time_us.astype(np.int64)
    state = samples.exc_state
    u, y = samples[u_name].astype(float), samples[y_name].astype(float)
    r = samples.excitation.astype(float)
    seq = samples.seq.astype(np.int64)
    for entry in manifest["frequencies"]:
        if entry.get("status") != "ok" or "start_us" not in entry:
            continue
        if entry.get("signal") == "chirp":
            fades = (entry.get("fade_samples", 0) + 1) * float(np.median(np.diff(t)))
            sel = (t >= entry["start_us"] - fades) & (t <= entry["end_us"] + fades) & \
                (state != idle)
        else:
            sel = (t >= entry["start_us"]) & (t <= entry["end_us"]) & (state == running)
        yield (entry, *_gridded(seq[sel], t[sel] * 1e-6, r[sel], u[sel], y[sel]))


def _gridded(seq, t, r, u, y):
    """A record on its samples' places: a sample lost on the link (a gap in the sequence
    numbers) is a hole, NaN in ``r``, ``u`` and ``y`` (its time interpolated), and
    ``present`` says which arrived (None when none was lost)."""
    if not seq.size:
        return t, r, u, y, None
    seq, first = np.unique(seq, return_index=True)          # in order, each sample once
    t, r, u, y = (x[first] for x in (t, r, u, y))
    n = int(seq[-1] - seq[0]) + 1
    if n == seq.size:
        return t, r, u, y, None
    idx = seq - seq[0]
    present = np.zeros(n, dtype=bool)
    present[idx] = True
    holes = []
    for x in (r, u, y):
        full = np.full(n, np.nan)
        full[idx] = x
        holes.append(full)
    return (np.interp(np.arange(n), idx, t), *holes, present)


def _lost_share(entry, present) -> float:
    """The share of a frequency's measured samples lost on the link: the sweep's count (it
    knows the edges of the window too), else the holes in the log's record."""
    if "lost" in entry and entry.get("samples", 0) + entry["lost"] > 0:
        return entry["lost"] / (entry["samples"] + entry["lost"])
    return 0.0 if present is None else 1.0 - float(np.mean(present))


def estimate_points(manifest, samples, estimate, progress, by_entry=None) -> tuple:
    """(points, the records they came from, each record's first point, the frequencies
    skipped and why): one point per measured frequency of a dwell, one per line of a
    multisine, against the excitation or the input (``estimate``). A record that lost
    samples on the link is estimated from those that arrived (each point's
    ``lost_share``); one that lost more than the sweep allows is skipped. ``by_entry``: a
    list that gets ``(entry, its points)`` for each record estimated (a linearity campaign
    groups them by realisation)."""
    points, segments, firsts, skipped = [], [], [], []
    kept = {}                                   # a first pass's points, by its index
    index = {id(e): k for k, e in enumerate(manifest["frequencies"])}
    for entry, t, r, u, y, present in sweep_segments(manifest, samples):
        what = _entry_name(entry)
        lost = _lost_share(entry, present)
        if entry.get("signal") == "chirp" and present is not None:   # its fades count too
            lost = max(lost, 1.0 - float(np.mean(present)))
        try:
            if not len(t):
                raise InputError("the log holds none of its samples")
            if lost > MAX_LOST_SHARE:
                raise InputError(f"{100 * lost:.1f} % of its samples were lost on the link "
                                 f"(at most {100 * MAX_LOST_SHARE:g} % is used)")
            found = _chirp_points(entry, t, r, u, y, estimate, present) \
                if entry.get("signal") == "chirp" else \
                _estimate_entry(entry, r, u, y, estimate, present)
        except InputError as exc:
            progress(f"  {what} skipped: {exc}")
            skipped.append(f"{what}: {exc}")
            continue
        found = [dataclasses.replace(p, lost_share=lost) for p in found]
        kept[index[id(entry)]] = found
        points = _with_pass(manifest, entry, points, found, kept, progress)
        if by_entry is not None:
            by_entry.append((entry, found))
        if lost:
            progress(f"  {what}: {100 * lost:.1f} % of its samples were lost on the link; "
                     "estimated from the rest")
        if present is not None:     # the plots and the replay: holes bridged by a line
            u, y = _bridged(present, u, y)
        segments.append((entry["freq_hz"], t, u, y))
        firsts.append(found[0])
    return points, segments, firsts, skipped


def _with_pass(manifest, entry, points, found, kept, progress) -> list:
    """``points`` with ``found`` added: a redesigned multisine's second pass combined line
    by line with its first pass's points (:func:`..acquire.redesign.combined_points`, by
    each line's amplitude in each pass), which it replaces; a first pass not estimated, on
    other lines or without its lines' amplitudes leaves the second alone."""
    first = entry.get("redesign_of")
    if first is None or first not in kept:
        return points + found
    before = manifest["frequencies"][first]
    if (before.get("period_samples"), before.get("orders")) != (entry.get("period_samples"),
                                                              entry.get("orders")) or \
            not before.get("line_amplitudes") or not entry.get("line_amplitudes"):
        progress(f"  {_entry_name(entry)}: its first pass has other lines, or no line "
                 "amplitudes; used alone")
        return points + found
    amplitudes = {h: pair for h, pair in zip(entry["orders"], zip(before["line_amplitudes"],
                                                                   entry["line_amplitudes"]))}
    ids = {id(p) for p in kept[first]}
    return [p for p in points if id(p) not in ids] + combined_points(kept[first], found,
                                                                     amplitudes)


def _chirp_points(entry, t, r, u, y, estimate, present) -> list:
    """A chirp's points (:mod:`..estimate.composite`): its sweep's record, holes lost on the
    link filled by a straight line, at :data:`~.record.RECORD_POINTS` frequencies over its
    band, against the excitation (or the input); those of coherence below
    :data:`~..estimate.composite.MIN_COHERENCE` are left out."""
    if t.size < 2 or not float(np.median(np.diff(t))) > 0:
        raise InputError("its record has fewer than two samples, or no time step")
    if present is not None:
        start, end = longest_run(~present)
        if end - start > MAX_LOST_RUN:
            raise InputError(f"{end - start} of its samples in a row were lost on the link "
                             f"(at most {MAX_LOST_RUN} are bridged)")
        r, u, y = _bridged(present, r, u, y)
    fs = 1.0 / float(np.median(np.diff(t)))
    lo, hi = sorted((entry["freq_hz"], entry["stop_hz"]))
    found = composite_response(y, u, fs, np.geomspace(lo, hi, RECORD_POINTS),
                               r=r if estimate == "excitation" else None)
    points, _ = coherent(found)
    if len(points) < 2:
        raise InputError(f"{len(points)} of its points have coherence {MIN_COHERENCE:g} or "
                         "more")
    return points


def _bridged(present, *signals) -> tuple:
    """The signals with the samples not ``present`` bridged by a straight line."""
    k = np.arange(present.size)
    return tuple(np.interp(k, k[present], x[present]) for x in signals)


def _entry_name(entry) -> str:
    if entry.get("signal") == "chirp":
        return f"the chirp from {entry['freq_hz']:.4g} to {entry['stop_hz']:.4g} Hz"
    if entry.get("signal") == "multisine":
        return f"the multisine of base {entry['freq_hz']:.4g} Hz"
    return f"{entry['freq_hz']:.4g} Hz"


def _estimate_entry(entry, r, u, y, estimate, present=None) -> list:
    """The points of one excitation's full-amplitude record: a sine's one (the first period
    discarded), or every line of a multisine (its first period fills the FSF's filter).
    ``present``: which samples arrived (None: all)."""
    fs = entry["freq_hz"] * entry["period_samples"]
    if estimate != "excitation" and present is not None:
        u, y = _complete_input(entry, r, u, y, present)
    if entry.get("signal") == "multisine":
        args = (fs, entry["period_samples"], entry["orders"])
        found = estimate_multisine_against_excitation(r, u, y, *args, present=present) \
            if estimate == "excitation" else estimate_multisine(u, y, *args, present=present)
        if not found:
            raise InputError("the input follows none of its lines")
        return found
    if estimate == "excitation":
        return [estimate_against_excitation(r, u, y, fs, entry["freq_hz"], discard_periods=1,
                                            present=present)]
    return [estimate_fsf(u, y, fs, freq_hz=entry["freq_hz"], discard_periods=1,
                         present=present)]


def _complete_input(entry, r, u, y, present):
    """For the estimate against the input, whose regressors need every sample of ``u``:
    the lost samples of ``u`` from its fit against the (completed) excitation; ``y``'s
    lost rows are left out of the fit."""
    period = int(entry["period_samples"])
    r = complete_excitation(r, present, period)
    u0, y0 = np.where(present, u, 0.0), np.where(present, y, 0.0)
    fs = entry["freq_hz"] * period
    if entry.get("signal") == "multisine":
        fits = estimate_multisine(r, u0, fs, period, entry["orders"], present=present)
        gains = {p.order: p.gain for p in fits}
        offset = fits[0].offset if fits else 0.0
    else:
        fit = estimate_fsf(r, u0, fs, entry["freq_hz"], discard_periods=1, present=present)
        gains, offset = fit.harmonics, fit.offset
    return fill_lost(u0, present, r, period, gains, offset), y0
