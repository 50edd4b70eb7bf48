"""Frequency-response points from sine experiments: the frequency sampling filter (FSF).

One experiment excites the system with a sine of one frequency; this module turns its input
``u(k)`` and output ``y(k)`` into one frequency-response point (see docs/method.md, and
docs/paper.md, step 2). The output is modelled by the FSF expansion

    y(k) = sum_l G_l f_l(k) + c + v(k),
    f_l(k) = (1/N) sum_{i=0}^{N-1} exp(j l w_d i) u(k - i),    w_d = 2 pi / N,

for harmonics ``l = -L..L`` of the excitation period of ``N`` samples. ``f_l`` is the
non-recursive (sliding-sum) form of ``(1/N)(1 - q^-N)/(1 - e^{j l w_d} q^-1) u(k)``; it is the
same filter without the marginally stable pole, so round-off cannot accumulate. The constant
``c`` (``offset=True``) absorbs a DC offset of the output that the input does not explain (gyro
bias, trim), which would otherwise inflate the residual and so the uncertainty.

Two solvers give the same estimate:

* :class:`RecursiveFsf`, the paper's complex recursive least squares, sample by sample
  (for online use);
* :func:`estimate_fsf`, a batch solver of the same regularised least-squares problem. RLS
  started from ``Theta(0) = 0, P(0) = p0 I`` minimises ``sum |y - Phi^H Theta|^2 +
  |Theta|^2 / p0`` exactly, so the batch solver adds that ridge and agrees with RLS to
  round-off. It exploits ``f_{-l} = conj(f_l)`` and ``G_{-l} = conj(G_l)`` to solve a real
  problem of half the size.

Harmonics the input does not excite (``f_l`` identically zero) are held at zero by the ridge
and reported as NaN; DC is absorbed by the offset term and ``G(0)`` is not reported.

A period that is not an integer number of samples cannot be expressed by the FSF. The batch
solver then uses the exact non-integer treatment: a least-squares sine fit of both ``u`` and
``y`` at the exact frequency (harmonics ``1..L`` and a constant), ``G_l = Y_l / U_l``, which
equals the FSF estimate whenever the period is an integer. The point records which method
produced it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base.errors import InputError
from ..records.points import FrequencyPoint

__all__ = [
    "DEFAULT_HARMONICS",
    "DEFAULT_DISCARD_PERIODS",
    "DEFAULT_P0_RELATIVE",
    "RecursiveFsf",
    "estimate_fsf",
    "estimate_against_excitation",
    "estimate_multisine",
    "estimate_multisine_against_excitation",
    "period_segments",
    "period_dfts",
    "estimate_frequency",
    "integer_period_consistent",
    "period_coherence",
    "complete_excitation",
]

#: Harmonics kept on each side of DC (the paper's step 2, docs/paper.md: l = 0, +/-1, +/-2, +/-3).
DEFAULT_HARMONICS = 3
#: Whole periods dropped at the start so the system's transient has decayed.
DEFAULT_DISCARD_PERIODS = 1
#: Initial RLS covariance relative to the input's power: ``P(0) = p0 I`` with
#: ``p0 = DEFAULT_P0_RELATIVE / mean(u^2)``; the batch solver's ridge is ``1/p0``. The bias it
#: causes on the fundamental is ``1 / (p0 n |U_1|^2) = 2e-6 / n`` for ``n`` samples, while
#: RLS stays accurate to round-off (a larger ``p0`` costs RLS precision: its first updates
#: subtract numbers of size ``p0``).
DEFAULT_P0_RELATIVE = 1e6
#: A found frequency is moved to the nearest integer-period one when the input is consistent
#: with it: F statistic (1 degree of freedom) below the chi-square 0.1 % point, 10.83.
F_INTEGER_PERIOD = 10.83
#: A harmonic of the input counts as excited when its amplitude is at least this fraction of
#: the fundamental's.
EXCITED_FRACTION = 1e-3
#: The fundamental's regressor below this fraction of the input's norm: round-off, not an
#: excitation (an input that is constant or zero), and the normal equations would be singular.
NO_EXCITATION_RELATIVE = 1e-9


class RecursiveFsf:
    """The paper's FSF with complex recursive least squares, one sample at a time.

    Parameters
    ----------
    period_samples : int
        Excitation period ``N`` in samples.
    harmonics : int
        ``L``: harmonics ``-L..L`` are estimated.
    offset : bool
        Also estimate a constant output offset.
    p0 : float, optional
        Initial covariance ``P(0) = p0 I``; default ``DEFAULT_P0_RELATIVE / (A^2 / 2)`` for
        an input sine of amplitude ``input_amplitude``. Give the batch solver the same ``p0``
        and both return the same estimate.
    input_amplitude : float
        Expected amplitude of the input sine, used only for the default ``p0``.
    discard_periods : int
        Whole periods dropped for settling. The sliding sums need one more period of input
        before they are complete, so RLS updates begin at sample
        ``(discard_periods + 1) * N - 1``; earlier samples only fill the filters.

    Notes
    -----
    The regressor of sample ``k`` is ``Phi(k) = conj([f_0, f_1, f_-1, ..., f_L, f_-L, 1])`` so
    that the model reads ``y(k) = Phi(k)^H Theta`` as in the paper. The sliding sums are kept in
    a ring buffer and recomputed exactly once per period, so round-off stays bounded however
    long the run.
    """

    def __init__(self, period_samples: int, harmonics: int = DEFAULT_HARMONICS,
                 offset: bool = True, p0: float | None = None,
                 discard_periods: int = DEFAULT_DISCARD_PERIODS, input_amplitude: float = 1.0):
        if int(period_samples) != period_samples or period_samples < 2:
            raise InputError(f"period must be an integer number of samples >= 2, got {period_samples}")
        self.period = int(period_samples)
        self.orders = _harmonic_orders(harmonics)
        self.offset = offset
        self.start_sample = fsf_first_row(self.period, discard_periods)
        n_par = len(self.orders) + (1 if offset else 0)
        self.theta = np.zeros(n_par, dtype=complex)
        if p0 is None:
            p0 = DEFAULT_P0_RELATIVE / (0.5 * input_amplitude ** 2)
        self.P = np.eye(n_par, dtype=complex) * p0
        # twiddle[l, i] = exp(-j l w_d i): exact per phase index i = k mod N.
        idx = np.arange(self.period)
        self._twiddle = np.exp(-2j * np.pi * np.outer(self.orders, idx) / self.period)
        self._ring = np.zeros((len(self.orders), self.period), dtype=complex)
        self._sums = np.zeros(len(self.orders), dtype=complex)
        self.k = 0

    def regressor(self, u_k: float) -> np.ndarray:
        """Advance the filters by one input sample and return ``Phi(k)`` (conjugated)."""
        i = self.k % self.period
        prod = self._twiddle[:, i] * u_k
        self._sums += prod - self._ring[:, i]
        self._ring[:, i] = prod
        if i == self.period - 1:
            self._sums = self._ring.sum(axis=1)      # exact refresh once per period
        f = np.conj(self._twiddle[:, i]) * self._sums / self.period
        if self.offset:
            f = np.append(f, 1.0)
        return np.conj(f)

    def update(self, u_k: float, y_k: float) -> None:
        """Process one sample of input and output."""
        phi = self.regressor(u_k)
        if self.k >= self.start_sample:
            P_phi = self.P @ phi
            denom = 1.0 + np.real(np.vdot(phi, P_phi))
            self.P -= np.outer(P_phi, P_phi.conj()) / denom
            self.P = 0.5 * (self.P + self.P.conj().T)
            err = y_k - np.vdot(phi, self.theta)
            self.theta = self.theta + (self.P @ phi) * err
        self.k += 1

    def gain(self, harmonic: int = 1) -> complex:
        """Current estimate of ``G(exp(j l w_d))`` for harmonic ``l``."""
        return complex(self.theta[list(self.orders).index(harmonic)])


def _positive_orders(harmonics) -> tuple:
    """The positive harmonic orders: ``1..L`` for an integer ``L`` (a sine's fundamental and
    its overtones), or the given strictly increasing orders (a multisine's lines)."""
    if isinstance(harmonics, (int, np.integer)) or (
            isinstance(harmonics, float) and harmonics == int(harmonics)):
        if not 1 <= harmonics <= 20:
            raise InputError(f"harmonics must be an integer from 1 to 20, got {harmonics}")
        return tuple(range(1, int(harmonics) + 1))
    try:
        orders = tuple(int(h) for h in harmonics)
    except (TypeError, ValueError):
        raise InputError(f"harmonics must be an integer from 1 to 20 or a list of orders, "
                         f"got {harmonics!r}") from None
    if not orders or orders[0] < 1 or any(b <= a for a, b in zip(orders, orders[1:])):
        raise InputError(f"harmonic orders must be positive and strictly increasing, got {orders}")
    return orders


def _harmonic_orders(harmonics) -> tuple:
    """Parameter order of the paper: 0, 1, -1, 2, -2, ..., L, -L (or the given orders)."""
    orders = [0]
    for l in _positive_orders(harmonics):
        orders += [l, -l]
    return tuple(orders)


def estimate_frequency(u, fs_hz: float) -> float:
    """Frequency of the dominant sine in ``u``, in Hz.

    A Hann-windowed, zero-padded FFT finds the peak; a bounded one-dimensional search then
    maximises the power that a least-squares sine fit at that frequency explains (the
    four-parameter sine fit), which is exact for a noise-free sine.
    """
    # scipy.optimize (0.2 s) here: identify, which knows its frequencies, need not wait
    import scipy.optimize

    u = np.asarray(u, dtype=float) - np.mean(u)
    n = u.size
    if n < 8 or not np.any(u):
        raise InputError("cannot find the excitation frequency: the input is constant or too short")
    nfft = 1 << (4 * n - 1).bit_length()
    spec = np.abs(np.fft.rfft(u * np.hanning(n), nfft))
    spec[0] = 0.0
    peak = int(np.argmax(spec))
    bin_rad = 2 * np.pi / nfft
    lo, hi = max(peak - 2, 0.5) * bin_rad, min(peak + 2, nfft / 2 - 0.5) * bin_rad
    res = scipy.optimize.minimize_scalar(lambda w: _sine_rss(u, w), bounds=(lo, hi),
                                         method="bounded", options={"xatol": 1e-13})
    return float(res.x) * fs_hz / (2 * np.pi)


def _sine_rss(u, w_per_sample: float) -> float:
    """Residual sum of squares of the least-squares fit of a constant and a sine at ``w``."""
    k = np.arange(u.size)
    basis = np.column_stack([np.ones(u.size), np.cos(w_per_sample * k), np.sin(w_per_sample * k)])
    coef, *_ = np.linalg.lstsq(basis, u, rcond=None)
    resid = u - basis @ coef
    return float(resid @ resid)


def integer_period_consistent(u, fs_hz: float, freq_hz: float):
    """The nearest integer period if the input is consistent with it, else None.

    F-test (1 degree of freedom) of the sine fit at the integer-period frequency against the
    fit at ``freq_hz`` (the best fit): consistent when ``F < F_INTEGER_PERIOD``. A clean sine
    whose period is not an integer fails by many orders of magnitude; a record whose estimate
    was pulled slightly off by noise or a settling transient passes.
    """
    whole = round(fs_hz / freq_hz)
    if whole < 2:
        return None
    u = np.asarray(u, dtype=float)
    rss_best = _sine_rss(u, 2 * np.pi * freq_hz / fs_hz)
    rss_whole = _sine_rss(u, 2 * np.pi / whole)
    scale = max(float(u @ u), np.finfo(float).tiny)
    if rss_whole - rss_best <= 1e-20 * scale:          # equal to round-off: the same fit
        return whole
    if rss_best <= 1e-20 * scale:
        return None
    f_stat = (rss_whole - rss_best) / (rss_best / max(u.size - 4, 1))
    return whole if f_stat < F_INTEGER_PERIOD else None


def period_segments(n: int, period: float, discard_periods: int) -> tuple:
    """(starts, length) of the whole excitation periods of an ``n``-sample record after
    ``discard_periods`` settling periods; ``length`` is the period rounded down."""
    start = int(math.ceil(discard_periods * period))
    count = max(int((n - start) // period), 0)
    return np.round(start + period * np.arange(count)).astype(int), int(math.floor(period))


def period_dfts(x, omega_per_sample: float, starts, length: int) -> np.ndarray:
    """The single-bin DFT of ``x`` at ``omega_per_sample`` over each segment, phase referred
    to sample 0 (so the segments of a steady response agree)."""
    starts = np.asarray(starts, dtype=int)
    idx = starts[:, None] + np.arange(length)[None, :]
    # exp(-j w (start_p + i)) = exp(-j w start_p) exp(-j w i): one kernel for every segment.
    kernel = np.exp(-1j * omega_per_sample * np.arange(length))
    return np.exp(-1j * omega_per_sample * starts) * (np.asarray(x)[idx] @ kernel)


def period_coherence(u, y, omega_per_sample: float, starts, length: int) -> float:
    """Magnitude-squared coherence of ``u`` and ``y`` at one frequency over given segments.

    Each segment (one excitation period) gives a single-bin DFT pair ``U_p, Y_p`` with phase
    referred to sample 0; ``gamma^2 = |sum U_p* Y_p|^2 / (sum |U_p|^2 sum |Y_p|^2)``. One
    period per segment means no leakage for an integer period. NaN for fewer than two
    segments, where coherence is 1 by construction and says nothing.
    """
    if len(starts) < 2:
        return float("nan")
    U = period_dfts(u, omega_per_sample, starts, length)
    Y = period_dfts(y, omega_per_sample, starts, length)
    den = np.sum(np.abs(U) ** 2) * np.sum(np.abs(Y) ** 2)
    if den == 0.0:
        return float("nan")
    return float(np.abs(np.sum(np.conj(U) * Y)) ** 2 / den)


def estimate_fsf(u, y, fs_hz: float, freq_hz: float | None = None,
                 harmonics: int = DEFAULT_HARMONICS,
                 discard_periods: int = DEFAULT_DISCARD_PERIODS,
                 offset: bool = True, p0: float | None = None,
                 present=None) -> FrequencyPoint:
    """Estimate one frequency-response point from a sine experiment (batch solver).

    Parameters
    ----------
    u, y : array_like
        Input and output, uniformly sampled at ``fs_hz``.
    fs_hz : float
        Sampling rate.
    freq_hz : float, optional
        Excitation frequency; found from ``u`` with :func:`estimate_frequency` when omitted.
    harmonics : int
        ``L``: harmonics ``-L..L`` are in the model.
    discard_periods : int
        Whole periods dropped at the start (settling).
    offset : bool
        Estimate a constant output offset.
    p0 : float, optional
        Prior covariance as in :class:`RecursiveFsf` (the estimate equals RLS with the same
        ``p0``); default ``DEFAULT_P0_RELATIVE / mean(u^2)``.
    present : array_like of bool, optional
        Which samples of ``y`` arrived; the rows of the others are left out (``u`` complete).

    Returns
    -------
    FrequencyPoint
    """
    u, y = _check_signals(u, y)
    present = _check_present(present, u.size)
    harmonics = len(_harmonic_orders(harmonics)) // 2       # validates
    if not fs_hz > 0:
        raise InputError(f"sampling rate must be positive, got {fs_hz}")
    if int(discard_periods) != discard_periods or discard_periods < 0:
        raise InputError(f"discard periods must be a non-negative integer, got {discard_periods}")
    given = freq_hz is not None
    if not given:
        freq_hz = estimate_frequency(u, fs_hz)
    if not 0 < freq_hz < fs_hz / 2:
        raise InputError(f"excitation frequency {freq_hz:g} Hz is outside (0, {fs_hz / 2:g}) Hz "
                         "(Nyquist)")
    period = fs_hz / freq_hz
    if u.size - discard_periods * period < period:
        raise InputError(f"record of {u.size} samples holds fewer than {discard_periods + 1} "
                         f"periods of {period:.6g} samples; nothing is left to analyse")
    power = float(np.mean(u ** 2))
    if not power > 0.0:
        raise InputError(f"the input is zero: it has no component at {freq_hz:g} Hz")
    if p0 is None:
        p0 = DEFAULT_P0_RELATIVE / power
    if given:      # taken as it is: an integer period only if it is one to round-off
        whole = round(period) if abs(period - round(period)) <= 1e-9 * period else None
    else:          # the firmware's periods are integers: use one if the input allows it
        whole = integer_period_consistent(u, fs_hz, freq_hz)
    if whole is not None and whole >= 2:
        return _solve_fsf(u, y, fs_hz, whole, harmonics, discard_periods, offset, p0, present)
    return _solve_sinefit(u, y, fs_hz, period, harmonics, discard_periods, present)


def _check_present(present, n: int):
    """The mask of the samples that arrived, or None when all did."""
    if present is None:
        return None
    present = np.asarray(present, dtype=bool)
    if present.shape != (n,):
        raise InputError("the mask of arrived samples must have one entry per sample")
    return None if present.all() else present


def complete_excitation(r, present, period: int) -> np.ndarray:
    """The excitation at every sample of a full-amplitude record some of whose samples were
    lost: there it repeats every ``period`` samples exactly (the firmware's generator steps a
    phase index modulo the period), so a lost sample takes the value of one a whole number
    of periods away that arrived. InputError when some phase of the period arrived in no
    period at all."""
    r = np.array(r, dtype=float)
    present = np.asarray(present, dtype=bool)
    period = int(period)
    phase = np.arange(r.size) % period
    known = np.full(period, np.nan)
    known[phase[present][::-1]] = r[present][::-1]          # the first arrival of each phase
    if np.isnan(known[np.unique(phase)]).any():
        raise InputError("samples lost at the same phase in every period: the excitation "
                         "cannot be completed")
    r[~present] = known[phase[~present]]
    return r


def fill_lost(x, present, r, period: int, gains: dict, offset: float) -> np.ndarray:
    """``x`` (fitted against the complete excitation ``r`` with harmonic gains ``{l: G_l}``
    and ``offset``) with each lost sample replaced by the fit's prediction there, so that
    per-period transforms of the record are not biased by the holes. A filled sample
    carries none of the noise, which the callers' sigmas account for (:func:`lost_factor`)."""
    if present is None:
        return x
    lines = {l: g for l, g in gains.items() if np.isfinite(g)}
    Xt = fsf_design_matrix(np.asarray(r, dtype=float), int(period), tuple(sorted(lines)), 0,
                           offset=False)
    coef = [0.0] + [part for l in sorted(lines) for part in (lines[l].real, lines[l].imag)]
    return np.where(present, x, np.asarray(coef) @ Xt + offset)


def lost_factor(present, segments) -> float:
    """How much a sigma from the scatter of per-period transforms understates the truth
    when lost samples were filled by the fit (:func:`fill_lost`): a period with ``n`` of its
    ``N`` samples carries ``n/N`` of the noise a whole one does, while the estimate rests on
    ``n/N`` of the rows, so the scatter's sigma is low by ``N/n`` over the periods used."""
    if present is None:
        return 1.0
    starts, length = segments
    if not len(starts):
        return 1.0
    arrived = sum(int(np.count_nonzero(present[s:s + length])) for s in starts)
    return len(starts) * length / max(arrived, 1)


def _check_signals(u, y):
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.ndim != 1 or y.ndim != 1 or u.size != y.size:
        raise InputError("input and output must be one-dimensional and of equal length")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise InputError("input or output contains NaN or infinity")
    return u, y


def fsf_first_row(period: int, discard_periods: int) -> int:
    """First sample whose FSF regressor is complete after ``discard_periods`` settling periods."""
    return (int(discard_periods) + 1) * int(period) - 1


def fsf_design_matrix(u, period: int, harmonics, first_row: int,
                      offset: bool = False) -> np.ndarray:
    """Real FSF regressors for rows ``first_row..end``, one regressor per row of the result
    (shape ``(2L + 1 [+ 1], rows)``): ``[f_0, 2Re f_l1, -2Im f_l1, ..., (1)]`` for the
    orders ``l1, l2, ...`` of ``harmonics`` (``1..L`` for an integer).

    With ``exp(-j l w_d k) = c - j s`` (``c = cos(l w_d k)``, ``s = sin(l w_d k)``) the
    sliding sum is ``C - j S`` with real sliding sums ``C = sum u c`` and ``S = sum u s`` over
    the last ``period`` samples (from rest), and ``f_l = (c + j s)(C - j S) / N``, so
    ``2 Re f_l = 2 (c C + s S) / N`` and ``-2 Im f_l = -2 (s C - c S) / N``: real arithmetic
    only. The window of row ``first_row`` starts ``period - 1`` samples earlier.
    """
    orders = _positive_orders(harmonics)
    lo = max(first_row - period + 1, 0)
    keep = first_row - lo
    seg = u[lo:]
    reps = -(-(seg.size + lo % period) // period)
    Xt = np.empty((2 * len(orders) + 1 + int(offset), u.size - first_row))
    Xt[0] = _sliding_sum(seg, period)[keep:] / period
    # One harmonic at a time: arrays of one record length stay in cache.
    for j, l in enumerate(orders, 1):
        angle = 2 * np.pi * ((l * np.arange(period)) % period) / period
        c = np.tile(np.cos(angle), reps)[lo % period:][:seg.size]    # c[k] = cos(l w_d k)
        s = np.tile(np.sin(angle), reps)[lo % period:][:seg.size]
        C = _sliding_sum(seg * c, period)[keep:]
        S = _sliding_sum(seg * s, period)[keep:]
        c, s = c[keep:], s[keep:]
        np.multiply(c, C, out=Xt[2 * j - 1])
        Xt[2 * j - 1] += s * S
        Xt[2 * j - 1] *= 2.0 / period
        np.multiply(c, S, out=Xt[2 * j])
        Xt[2 * j] -= s * C
        Xt[2 * j] *= 2.0 / period
    if offset:
        Xt[-1] = 1.0
    return Xt


def _sliding_sum(x, window: int) -> np.ndarray:
    """``sum x[k - window + 1 .. k]`` for every ``k``, counting samples before ``x`` as zero."""
    csum = np.cumsum(x)
    csum[window:] -= csum[:-window].copy()
    return csum


@dataclasses.dataclass
class _FsfSolution:
    """The batch FSF's least-squares solution over given orders."""
    orders: tuple
    gains: dict           # {l: G_l}, NaN where the input does not excite l
    sigmas: dict          # {l: sqrt(E|dG_l|^2)}
    offset: float
    n_periods: int


def _fsf_solution(u, y, fs_hz, period, orders, discard_periods, offset, p0,
                  present=None) -> _FsfSolution:
    """``present``: which samples of ``y`` arrived (None: all); the rows of the others are
    left out of the regression (each row's regressor comes from ``u`` alone, which must be
    complete)."""
    start = fsf_first_row(period, discard_periods)
    n_periods = (u.size - start) // period
    if n_periods < 1:
        raise InputError(f"record of {u.size} samples is too short: the FSF needs "
                         f"{discard_periods + 2} periods of {period} samples (one fills the filter)")
    # Real form: G_0 f_0 + sum_l 2 Re(G_l f_l) = G_0 f_0 + sum_l (a_l 2Re f_l + b_l (-2Im f_l))
    # with G_l = a_l + j b_l. Every complete row is used, as RLS uses them.
    Xt = fsf_design_matrix(u, period, orders, start, offset)
    n_lines = len(orders)
    ridge = np.full(Xt.shape[0], 2.0)          # |G_l|^2 + |G_-l|^2 = 2 (a^2 + b^2)
    ridge[0] = 1.0                            # f_0 and the offset are real
    if offset:
        ridge[-1] = 1.0
    yy = y[start:]
    if present is not None and not np.all(present[start:]):
        Xt, yy = Xt[:, present[start:]], yy[present[start:]]
    gram = Xt @ Xt.T
    # Excitation per harmonic from the Gram diagonal: sum |f_l|^2 = (|2Re f|^2 + |2Im f|^2)/4.
    # Checked before solving: without excitation the system is singular. A sine's reference
    # is its fundamental, a multisine's its strongest line.
    diag = np.diag(gram)
    amp = np.sqrt(np.r_[diag[0], (diag[1:2 * n_lines:2] + diag[2:2 * n_lines + 1:2]) / 4])
    reference = amp[1] if orders[0] == 1 else float(np.max(amp[1:]))
    if not reference > NO_EXCITATION_RELATIVE * float(np.sqrt(u[start:] @ u[start:])):
        raise InputError(f"the input has no component at {fs_hz * orders[0] / period:g} Hz")
    excited = amp >= EXCITED_FRACTION * reference
    A = gram + np.diag(ridge) / p0
    coef = np.linalg.solve(A, Xt @ yy)
    resid = yy - coef @ Xt
    n_free = int(excited[0]) + 2 * int(np.sum(excited[1:])) + int(offset)
    dof = max(yy.size - n_free, 1)
    noise_var = float(resid @ resid) / dof
    A_inv = np.linalg.inv(A)
    cov = noise_var * A_inv @ gram @ A_inv
    nan = complex("nan+nanj")
    gains = {l: complex(coef[2 * j - 1], coef[2 * j]) if excited[j] else nan
             for j, l in enumerate(orders, 1)}
    sigmas = {l: math.sqrt(max(cov[2 * j - 1, 2 * j - 1] + cov[2 * j, 2 * j], 0.0))
              for j, l in enumerate(orders, 1)}
    return _FsfSolution(tuple(orders), gains, sigmas, float(coef[-1]) if offset else 0.0,
                        int(n_periods))


def _solve_fsf(u, y, fs_hz, period, harmonics, discard_periods, offset, p0, present=None):
    sol = _fsf_solution(u, y, fs_hz, period, _positive_orders(harmonics), discard_periods,
                        offset, p0, present)
    y = fill_lost(y, present, u, period, sol.gains, sol.offset)
    w = 2 * np.pi / period
    coh = period_coherence(u, y, w, *period_segments(u.size, period, discard_periods))
    return FrequencyPoint(omega_rad_s=w * fs_hz, gain=sol.gains[1], sigma=sol.sigmas[1],
                          coherence=coh, period_samples=float(period), n_periods=sol.n_periods,
                          method="fsf", harmonics=sol.gains, offset=sol.offset)


def _solve_sinefit(u, y, fs_hz, period, harmonics, discard_periods, present=None):
    start = int(math.ceil(discard_periods * period))
    n_periods = int((u.size - start) // period)
    stop = start + int(round(n_periods * period))
    w = 2 * np.pi / period
    k = np.arange(start, stop)
    if present is not None:          # the samples that arrived: a sine fit needs no others
        k = k[present[start:stop]]
    cols = [np.ones(k.size)]
    for l in range(1, int(harmonics) + 1):
        cols += [np.cos(l * w * k), np.sin(l * w * k)]
    X = np.column_stack(cols)
    coef_u, *_ = np.linalg.lstsq(X, u[k], rcond=None)
    coef_y, *_ = np.linalg.lstsq(X, y[k], rcond=None)
    # a cos + b sin = Re((a - j b) e^{j w k}): complex amplitude of harmonic l is a - j b.
    U = coef_u[1::2] - 1j * coef_u[2::2]
    Y = coef_y[1::2] - 1j * coef_y[2::2]
    excited = np.abs(U) >= EXCITED_FRACTION * abs(U[0])
    if not excited[0]:
        raise InputError(f"the input has no component at {fs_hz / period:g} Hz")
    gains = {l: complex(Y[l - 1] / U[l - 1]) if excited[l - 1] else complex("nan+nanj")
             for l in range(1, int(harmonics) + 1)}
    resid = y[k] - X @ coef_y
    noise_var = float(resid @ resid) / max(k.size - X.shape[1], 1)
    cov = noise_var * np.linalg.inv(X.T @ X)
    sigma = math.sqrt(max(cov[1, 1] + cov[2, 2], 0.0)) / abs(U[0])
    if present is not None:          # the fit's prediction where samples were lost
        every = np.arange(y.size)
        fit = np.column_stack([np.ones(y.size)] + [f(l * w * every) for l in
                                                   range(1, int(harmonics) + 1)
                                                   for f in (np.cos, np.sin)]) @ coef_y
        y = np.where(present, y, fit)
    coh = period_coherence(u, y, w, *period_segments(u.size, period, discard_periods))
    return FrequencyPoint(omega_rad_s=w * fs_hz, gain=gains[1], sigma=sigma, coherence=coh,
                          period_samples=float(period), n_periods=n_periods, method="sinefit",
                          harmonics=gains, offset=float(coef_y[0]))


def estimate_against_excitation(r, u, y, fs_hz: float, freq_hz: float,
                                harmonics: int = DEFAULT_HARMONICS,
                                discard_periods: int = DEFAULT_DISCARD_PERIODS,
                                present=None) -> FrequencyPoint:
    """One point from closed-loop data: ``G = (Y/R) / (U/R)``, the FSF of the output and of
    the input each against the injected excitation ``r``.

    In a closed loop the disturbance reaches the input too (the controller answers it), so
    regressing ``y`` on the measured ``u`` pulls the estimate towards ``-1 / K``; ``r`` is
    not correlated with the disturbance, so both ratios to it are unbiased and so is their
    quotient (to first order). ``sigma`` comes from the scatter of the per-period estimates
    ``(Y_p - G U_p) / (T_u R_p)`` (``T_u = U/R``): what the record itself shows, not a model
    of the noise. ``coherence`` is the smaller of the coherences of ``r`` with ``y`` and
    with ``u``, both kept on the point.

    ``present``: which samples arrived, for a full-amplitude record with samples lost on the
    link (their values in ``r``, ``u`` and ``y`` are ignored). The excitation is completed
    (:func:`complete_excitation`), the rows of lost samples are left out of both fits, the
    per-period transforms use the fits' predictions there (:func:`fill_lost`), and the
    scatter's sigma is raised by :func:`lost_factor`.
    """
    present = _check_present(present, np.asarray(r).size)
    if present is not None:
        period = fs_hz / freq_hz
        if abs(period - round(period)) > 1e-9 * period:
            raise InputError("samples were lost from a record whose period is not a whole "
                             "number of samples")
        r = complete_excitation(r, present, round(period))
        u, y = (np.where(present, x, 0.0) for x in (u, y))
    r, u = _check_signals(r, u)
    _, y = _check_signals(r, y)
    try:
        to_y = estimate_fsf(r, y, fs_hz, freq_hz, harmonics, discard_periods, offset=True,
                            present=present)
        to_u = estimate_fsf(r, u, fs_hz, freq_hz, harmonics, discard_periods, offset=True,
                            present=present)
    except InputError as exc:
        raise InputError(f"the logged excitation: {exc}") from None
    if not _follows(to_u.gain):
        raise InputError(f"the input does not follow the excitation at {freq_hz:g} Hz")
    gains = {l: to_y.harmonics[l] / to_u.harmonics[l] if to_u.harmonics[l] != 0 else
             complex("nan+nanj") for l in to_y.harmonics}
    if present is not None:
        period = int(to_y.period_samples)
        y = fill_lost(y, present, r, period, to_y.harmonics, to_y.offset)
        u = fill_lost(u, present, r, period, to_u.harmonics, to_u.offset)
    return _against_excitation(r, u, y, to_y, to_u, 1,
                               period_segments(r.size, to_y.period_samples, discard_periods),
                               harmonics=gains, present=present)


def _follows(t_u) -> bool:
    """Whether the input follows the excitation: ``U/R`` non-zero and finite."""
    return abs(t_u) > 0 and math.isfinite(abs(t_u))


def _against_excitation(r, u, y, to_y, to_u, order, segments, present=None,
                        **fields) -> FrequencyPoint:
    """The point ``G = (Y/R) / (U/R)`` at harmonic ``order`` of the record's period, from the
    FSF points of ``y`` and of ``u`` against ``r`` (their coherences, of ``r`` with each,
    were taken over ``segments``, the whole periods used here). ``sigma`` from the scatter
    of the per-period estimates ``(Y_p - G U_p) / (T_u R_p)`` with two or more periods,
    else the two fits' sigmas propagated."""
    t_u = to_u.gain
    g = to_y.gain / t_u
    starts, length = segments
    w = 2 * np.pi * order / to_y.period_samples
    R, U, Y = (period_dfts(x, w, starts, length) for x in (r, u, y))
    if len(starts) >= 2 and np.all(np.abs(R) > 0):
        e = (Y - g * U) / (t_u * R)
        sigma = math.sqrt(float(np.sum(np.abs(e - e.mean()) ** 2)) / (e.size - 1) / e.size)
        sigma *= lost_factor(present, segments)
    else:              # one period: the two fits' residual sigmas, propagated
        sigma = math.hypot(to_y.sigma, abs(g) * to_u.sigma) / abs(t_u)
    return dataclasses.replace(
        to_y, gain=g, sigma=sigma, coherence=float(np.fmin(to_y.coherence, to_u.coherence)),
        estimate="excitation", coherence_ry=to_y.coherence, coherence_ru=to_u.coherence,
        input_gain=t_u, input_sigma=to_u.sigma, **fields)


def _multisine_checks(u, y, fs_hz, period, orders):
    u, y = _check_signals(u, y)
    orders = _positive_orders(orders)
    if not fs_hz > 0:
        raise InputError(f"sampling rate must be positive, got {fs_hz}")
    if int(period) != period or period < 4 * orders[-1]:
        raise InputError(f"a multisine's period must be a whole number of samples, at least 4 "
                         f"per cycle of its highest line ({4 * orders[-1]}), got {period}")
    return u, y, int(period), orders


def estimate_multisine(u, y, fs_hz: float, period: int, orders,
                       discard_periods: int = 0, offset: bool = True,
                       p0: float | None = None, present=None) -> list:
    """Every line of a multisine record: one :class:`FrequencyPoint` per excited harmonic
    ``l`` of ``orders`` of the base period of ``period`` samples, from one FSF fit of the
    whole record (the batch form of :class:`RecursiveFsf` with the same orders and ``p0``).

    With ``discard_periods=0`` the regression starts once the filter holds one whole
    period: an impulse response shorter than the period has forgotten what came before (the
    fade-in), so that period is the settling. ``sigma`` per line from the fit's covariance;
    ``coherence`` per line over the whole periods after the first (NaN with fewer than
    two). A line the input does not excite is left out. ``present``: as for
    :func:`estimate_fsf` (``u`` complete, the rows of lost ``y`` left out)."""
    u, y, period, orders = _multisine_checks(u, y, fs_hz, period, orders)
    present = _check_present(present, u.size)
    power = float(np.mean(u ** 2))
    if not power > 0.0:
        raise InputError("the input is zero: it excites none of the multisine's lines")
    p0 = DEFAULT_P0_RELATIVE / power if p0 is None else p0
    sol = _fsf_solution(u, y, fs_hz, period, orders, discard_periods, offset, p0, present)
    y = fill_lost(y, present, u, period, sol.gains, sol.offset)
    segments = _multisine_segments(u.size, period, discard_periods)
    points = []
    for l in orders:
        if not np.isfinite(sol.gains[l]):
            continue
        w = 2 * np.pi * l / period
        points.append(FrequencyPoint(
            omega_rad_s=w * fs_hz, gain=sol.gains[l], sigma=sol.sigmas[l],
            coherence=period_coherence(u, y, w, *segments), period_samples=float(period),
            n_periods=sol.n_periods, method="fsf", harmonics={1: sol.gains[l]},
            offset=sol.offset, order=l))
    return points


def estimate_multisine_against_excitation(r, u, y, fs_hz: float, period: int, orders,
                                          discard_periods: int = 0, present=None) -> list:
    """Every line of a closed-loop multisine record, ``G_l = (Y/R)_l / (U/R)_l``: the FSF of
    the output and of the input against the logged excitation ``r``
    (:func:`estimate_against_excitation` for each line at once). ``sigma`` per line from the
    scatter of the per-period estimates after the first period (the FSF's filter fill),
    with two or more such periods; else the two fits' sigmas propagated. ``present``: as
    for :func:`estimate_against_excitation`."""
    present = _check_present(present, np.asarray(r).size)
    if present is not None:
        r = complete_excitation(r, present, int(period))
        u, y = (np.where(present, x, 0.0) for x in (u, y))
    r, u, period, orders = _multisine_checks(r, u, fs_hz, period, orders)
    _, y = _check_signals(r, y)
    try:
        to_y = {p.order: p for p in estimate_multisine(r, y, fs_hz, period, orders,
                                                       discard_periods, present=present)}
        to_u = {p.order: p for p in estimate_multisine(r, u, fs_hz, period, orders,
                                                       discard_periods, present=present)}
    except InputError as exc:
        raise InputError(f"the logged excitation: {exc}") from None
    segments = _multisine_segments(r.size, period, discard_periods)
    if present is not None:
        y = fill_lost(y, present, r, period, {l: p.gain for l, p in to_y.items()},
                      next(iter(to_y.values())).offset if to_y else 0.0)
        u = fill_lost(u, present, r, period, {l: p.gain for l, p in to_u.items()},
                      next(iter(to_u.values())).offset if to_u else 0.0)
    return [_against_excitation(r, u, y, to_y[l], to_u[l], l, segments, present=present,
                                harmonics={1: to_y[l].gain / to_u[l].gain})
            for l in sorted(to_y) if _follows(to_u[l].gain)]


def _multisine_segments(n: int, period: int, discard_periods: int) -> tuple:
    """The whole periods a multisine's coherence and scatter use: after the first (the FSF's
    filter fill) and any further discarded ones."""
    return period_segments(n, period, max(discard_periods, 1))
