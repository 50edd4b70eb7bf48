"""A sequential multisine in two passes, its lines' amplitudes redesigned from the first
(``heliquad sweep --signal multisine --target-sigma S --redesign``).

Under turbulence the disturbance is not white: on the vehicle's rigs it is strongest at the
bottom of the band, so a multisine of equal lines knows its upper lines long before its
lowest ones, and the sequential rule (every line to ``S``) waits for the worst. The first
pass is the multisine as designed, for the least whole periods the rule judges
(:data:`~.design.SequentialMultisine.min_periods`); if it has not met the target, the second
pass flies the same lines (base period, harmonics) with each line's amplitude in proportion
to the first pass's sigma over magnitude at that line, so that the lines need about the same
time, scaled to the same declared peak, for as many whole periods as the rest of the rig
time holds, sequential again. The rule then judges each line's two passes combined, and
identify combines them the same way (:func:`combined_points`): weighted by each line's
amplitude squared times the periods (:func:`pass_weights`), the disturbance being the same
in both passes.

The first pass's per-line sigmas come from two or three periods: each a chi-square of few
degrees of freedom, off by a factor of two either way. The disturbance and the loop vary
smoothly with frequency, so the design uses a quadratic in log frequency fitted to their
logarithms, and keeps every line within :data:`SPREAD` times the median line's amplitude.
Measured (``python benchmarks/severe_turbulence.py --axes yaw --redesign``: rate injection,
the plant, severe turbulence, seeds 1-5, 180 s): the worst line's sigma of the two passes
combined 0.042-0.058 of its magnitude, against 0.065-0.091 with equal lines over the whole
cap. The first pass, on a grid designed for half the rig time, may have fewer lines than a
single pass would (yaw: 14 on a 20 s period against 15 on 26.7 s).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base.errors import InputError
from ..records.manifest import entry_seconds
from .multisine import Multisine, design

__all__ = ["Redesign", "disturbance_sigmas", "line_weights", "pass_weights", "combined_sigmas",
           "passes_sigmas", "combined_points", "SPREAD"]

#: A redesigned line's amplitude stays within this factor of the median line's (either way).
SPREAD = 8.0
#: The smoothing of the first pass's sigmas: a polynomial of this degree in log frequency.
SMOOTHING_DEGREE = 2
#: Twice this many free harmonics nearest a line give the disturbance there.
NEIGHBOURS = 2


def disturbance_sigmas(u, y, period: int, orders, present=None) -> list:
    """Each line's sigma over magnitude as the disturbance predicts it: over the whole
    periods after the first (none with a lost sample), the power of ``u`` and ``y`` at the
    2 x :data:`NEIGHBOURS` harmonics nearest the line that no line excites, against the
    line's own mean in each (``sigma^2 / |G|^2 = P_y / |Y|^2 + P_u / |U|^2``, over the
    periods used: an approximation, which leaves out that a loop correlates the two
    disturbances; measured, within a factor of 1.0-1.3 of the lines' own sigmas over
    many periods). Many more degrees of freedom than the lines' own scatter, which two
    periods leave off by a factor of two; None where fewer than two periods or no free
    harmonic."""
    u, y = np.asarray(u, dtype=float), np.asarray(y, dtype=float)
    n = y.size // period
    keep = np.ones(n, dtype=bool)
    if present is not None:
        keep = np.asarray(present[:n * period], dtype=bool).reshape(n, period).all(axis=1)
    keep[0] = False                                 # the settling after the fade-in
    if keep.sum() < 2:
        return [None] * len(orders)
    spectra = [np.fft.rfft(x[:n * period].reshape(n, period)[keep], axis=1) for x in (u, y)]
    top = min(spectra[0].shape[1] - 1, 2 * max(orders) + NEIGHBOURS)
    free = np.array(sorted(set(range(1, top + 1)) - set(orders)))
    out = []
    for h in orders:
        near = free[np.argsort(np.abs(free - h), kind="stable")[:2 * NEIGHBOURS]]
        v = sum(np.mean(np.abs(X[:, near]) ** 2) / abs(np.mean(X[:, h])) ** 2
                for X in spectra if abs(np.mean(X[:, h])) > 0)
        out.append(float(math.sqrt(v / keep.sum())) if len(near) and v > 0 else None)
    return out


def line_weights(orders, sigmas) -> np.ndarray | None:
    """The second pass's relative line amplitudes from the first pass's sigma over
    magnitude per line (None where a line was not estimated): proportional to the smoothed
    sigmas, within :data:`SPREAD` of their median; None with fewer than three lines
    estimated (nothing to redesign from)."""
    s = np.array([math.nan if v is None else float(v) for v in sigmas])
    ok = np.isfinite(s) & (s > 0)
    if ok.sum() < 3:
        return None
    x = np.log(np.asarray(orders, dtype=float))
    fit = np.polyfit(x[ok], np.log(s[ok]), min(SMOOTHING_DEGREE, int(ok.sum()) - 1))
    smooth = np.exp(np.polyval(fit, x))
    return np.clip(smooth / np.median(smooth), 1 / SPREAD, SPREAD)


@dataclasses.dataclass
class Redesign:
    """The two passes of a redesigned sequential multisine over ``rig_time_s`` (both passes,
    fades included): ``first`` as designed, for ``min_periods``; ``second`` and its
    ``weights`` once the first has ended (:meth:`second_pass`)."""
    band_hz: tuple
    rig_time_s: float
    first: Multisine
    second: Multisine | None = None
    weights: tuple | None = None
    first_index: int | None = None
    prior: tuple | None = None          # the first pass for the rule (SequentialMultisine)
    why_not: str | None = None          # why there is no second pass, once decided
    equal_why: str | None = None        # why the second pass has equal lines, if it has

    @classmethod
    def of(cls, band_hz, grid: Multisine, rig_time_s: float, min_periods: int) -> "Redesign":
        return cls(tuple(band_hz), float(rig_time_s), dataclasses.replace(grid, periods=min_periods))

    def second_pass(self, entry: dict, index: int, min_periods: int,
                    target_sigma: float) -> Multisine | None:
        """After the first pass's measured manifest ``entry`` (at ``index`` among the
        manifest's frequencies): the redesigned multisine, or None (and ``why_not``) when
        every line of the first pass is at ``target_sigma`` already, or the rest of the rig
        time holds too little. Without a disturbance to redesign from (fewer than three
        lines estimated: samples lost on the link), the second pass flies equal lines and
        ``equal_why`` says why."""
        sigmas = [math.inf if v is None else v for v in entry.get("line_sigma") or [math.inf]]
        if max(sigmas) <= target_sigma:
            self.why_not = "the first pass met the target"
            return None
        disturbance = entry.get("line_disturbance") or []
        weights = line_weights(self.first.orders, disturbance if any(
            v is not None for v in disturbance) else entry.get("line_sigma") or [])
        if weights is None:
            weights = np.ones(len(self.first.orders))
            self.equal_why = "the first pass estimated fewer than three lines"
        spent = entry_seconds(entry, self.first.fade_cycles)
        try:
            self.second = design(self.band_hz, self.first.peak, len(self.first.orders),
                                 self.rig_time_s - spent, min_periods, self.first.fade_cycles,
                                 self.first.fs_hz, weights=weights, like=self.first)
        except InputError:
            self.why_not = (f"the rest of the rig time, {self.rig_time_s - spent:.0f} s, holds "
                            f"fewer than {min_periods} periods")
            return None
        self.weights, self.first_index = tuple(float(w) for w in weights), index
        self.prior = (tuple(entry["line_sigma"]), entry["periods"] - 1, self.first.amplitudes,
                      self.second.amplitudes)
        return self.second


def pass_weights(amplitudes, periods) -> np.ndarray:
    """Each line's weight in a pass (lines x passes): its amplitude squared times the pass's
    whole periods used. The disturbance is the same in both passes, so a line's variance in
    a pass is its disturbance over that; weights from the passes' own sigmas would carry
    those sigmas' scatter (two or three periods in a first pass: off by a factor of two)
    into the combined point."""
    a = np.asarray(amplitudes, dtype=float)
    return a ** 2 * np.asarray(periods, dtype=float)


def combined_sigmas(sigmas, amplitudes, periods) -> np.ndarray:
    """Each line's sigma of its passes combined by :func:`pass_weights` (``sigmas`` and
    ``amplitudes`` lines x passes, NaN for a line a pass did not estimate; ``periods`` per
    pass): the disturbance pooled over the passes (each pass's ``sigma^2 w``, weighted by
    its periods), over the lines' summed weights. One pass: its own sigma."""
    s = np.asarray(sigmas, dtype=float)
    w = pass_weights(amplitudes, periods)
    n = np.broadcast_to(np.asarray(periods, dtype=float), s.shape)
    known = np.isfinite(s) & (w > 0)
    estimated = known.any(axis=1)               # a line no pass estimated stays NaN
    out = np.full(s.shape[0], np.nan)
    k, n, w, s = known[estimated], n[estimated], w[estimated], s[estimated]
    pooled = np.where(k, s ** 2 * w * n, 0).sum(axis=1) / np.where(k, n, 0).sum(axis=1)
    out[estimated] = np.sqrt(pooled / np.where(k, w, 0).sum(axis=1))
    return out


def passes_sigmas(entries) -> list:
    """Each line's sigma over magnitude, the passes of these sweep manifest entries (one
    multisine's, on the same lines; ``line_sigma``, ``line_amplitudes``, ``periods``)
    combined as :func:`combined_sigmas`; None where no pass estimated the line."""
    s = np.column_stack([[np.nan if v is None else v for v in e["line_sigma"]]
                         for e in entries])
    a = np.column_stack([e.get("line_amplitudes") or [1.0] * len(e["line_sigma"])
                         for e in entries])
    got = combined_sigmas(s, a, [max(e.get("periods", 2) - 1, 1) for e in entries])
    return [float(v) if np.isfinite(v) else None for v in got]


def combined_points(first: list, second: list, amplitudes) -> list:
    """The lines of two passes on the same grid, each pair combined with
    :func:`pass_weights` (``amplitudes``: by harmonic, the line's amplitude in each pass):
    the gain, the input's gain and the coherences the weighted means, the sigma
    :func:`combined_sigmas`, the periods added. A line in one pass only is kept as it is."""
    by_order = {p.order: p for p in first}
    out = []
    for q in second:
        p = by_order.pop(q.order, None)
        out.append(q if p is None else _combined(p, q, amplitudes[q.order]))
    return sorted(out + list(by_order.values()), key=lambda p: p.omega_rad_s)


def _combined(p, q, amplitudes):
    w = pass_weights(amplitudes, [p.n_periods, q.n_periods])
    share = w / w.sum()
    mean = lambda a, b, s=share: float(s[0] * a + s[1] * b)        # noqa: E731
    sigma = combined_sigmas([[p.sigma, q.sigma]], [amplitudes], [p.n_periods, q.n_periods])
    fields = dict(gain=complex(share[0] * p.gain + share[1] * q.gain), sigma=float(sigma[0]),
                  n_periods=p.n_periods + q.n_periods,
                  coherence=mean(p.coherence, q.coherence),
                  coherence_ry=mean(p.coherence_ry, q.coherence_ry),
                  coherence_ru=mean(p.coherence_ru, q.coherence_ru),
                  lost_share=(p.lost_share * p.n_periods + q.lost_share * q.n_periods) /
                  max(p.n_periods + q.n_periods, 1))
    if np.isfinite([p.input_gain, q.input_gain]).all():
        fields["input_gain"] = complex(share[0] * p.input_gain + share[1] * q.input_gain)
        fields["input_sigma"] = float(combined_sigmas(
            [[p.input_sigma, q.input_sigma]], [amplitudes], [p.n_periods, q.n_periods])[0])
    return dataclasses.replace(q, **fields)
