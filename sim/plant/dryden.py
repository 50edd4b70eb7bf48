"""Dryden turbulence (MIL-F-8785C, low-altitude model), as disturbance forces and moments.

Gust velocities (u, v, w) and gust rates (p, q, r), in body axes, are white noise through
the standard's shaping filters (with the turbulence scales L and intensities sigma of the
low-altitude model, h in feet inside the formulas):

    L_w = h,  L_u = L_v = h / (0.177 + 0.000823 h)^1.2
    sigma_w = 0.1 W20,  sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4
    H_u = sigma_u sqrt(2 L_u / (pi V)) / (1 + L_u/V s)
    H_v = sigma_v sqrt(L_v / (pi V)) (1 + sqrt(3) L_v/V s) / (1 + L_v/V s)^2     (H_w alike)
    H_p = sigma_w sqrt(0.8 / V) (pi / (4 b))^(1/6) / (L_w^(1/3) (1 + 4b/(pi V) s))
    H_q = (s / V) / (1 + 4b/(pi V) s) H_w,   H_r = (s / V) / (1 + 3b/(pi V) s) H_v

W20 (wind at 20 ft): light 15 kt, moderate 30 kt, severe 45 kt. A hovering vehicle has no
airspeed, so V is the mean wind at the flight altitude (the turbulence is carried past the
vehicle by it: frozen turbulence), from the standard's logarithmic profile
``W(h) = W20 ln(h / 0.15 ft) / ln(20 ft / 0.15 ft)``, at least 1 m/s. Altitudes below 10 ft
are taken as 10 ft. The spectra are one-sided, so unit-PSD white noise is generated with
variance pi / dt per sample; each output's variance is then sigma^2 (checked in the tests).

Forces and moments: the gust velocity acts through the airframe's linear drag
(``drag_n_s_m``, F = c_d v_gust), the gust rates through a rotational damping
(``rotational_damping_n_m_s_rad``). Both coefficients are in the vehicle file.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["Dryden", "LEVELS_KT"]

LEVELS_KT = {"light": 15.0, "moderate": 30.0, "severe": 45.0}
KT_TO_M_S = 0.514444
FT = 0.3048
MIN_ALTITUDE_FT = 10.0
Z0_FT = 0.15                 # surface roughness of the standard's wind profile
MIN_CONVECTION_M_S = 1.0


def _discrete(num, den, dt):
    """ZOH discretisation of a continuous filter num/den, as (b, a) for lfilter."""
    # scipy.signal (0.5 s) only for a turbulent run: every sil and sweep imports this module
    import scipy.signal

    b, a, _ = scipy.signal.cont2discrete((num, den), dt, method="zoh")
    return np.atleast_2d(b)[0], np.asarray(a, dtype=float)


class Dryden:
    """Six coloured-noise channels: gust velocities (m/s) and gust rates (rad/s), body axes.

    Parameters
    ----------
    level : str
        ``light``, ``moderate`` or ``severe``.
    altitude_m : float
        Flight altitude above ground.
    span_m : float
        Vehicle span b (rotor tip to rotor tip).
    dt_s : float
        Sample period.
    seed : int
        Random seed: the same seed gives the same turbulence.
    """

    def __init__(self, level: str, altitude_m: float, span_m: float, dt_s: float, seed: int = 0):
        if level not in LEVELS_KT:
            raise ValueError(f"turbulence level must be one of {', '.join(LEVELS_KT)}")
        h = max(altitude_m / FT, MIN_ALTITUDE_FT)
        w20 = LEVELS_KT[level] * KT_TO_M_S
        self.sigma_w = 0.1 * w20
        self.sigma_uv = self.sigma_w / (0.177 + 0.000823 * h) ** 0.4
        lw = h * FT
        luv = h / (0.177 + 0.000823 * h) ** 1.2 * FT
        v = max(w20 * math.log(h / Z0_FT) / math.log(20.0 / Z0_FT), MIN_CONVECTION_M_S)
        self.convection_m_s = v
        b = span_m
        su, sw = self.sigma_uv, self.sigma_w
        hu = ([su * math.sqrt(2 * luv / (math.pi * v))], [luv / v, 1.0])

        def vertical(sig, L):
            k = sig * math.sqrt(L / (math.pi * v))
            return [k * math.sqrt(3) * L / v, k], np.polymul([L / v, 1.0], [L / v, 1.0])

        hv, hw = vertical(su, luv), vertical(sw, lw)
        kp = sw * math.sqrt(0.8 / v) * (math.pi / (4 * b)) ** (1 / 6) / lw ** (1 / 3)
        hp = ([kp], [4 * b / (math.pi * v), 1.0])
        hq = (np.polymul([1 / v, 0.0], hw[0]), np.polymul([4 * b / (math.pi * v), 1.0], hw[1]))
        hr = (np.polymul([1 / v, 0.0], hv[0]), np.polymul([3 * b / (math.pi * v), 1.0], hv[1]))
        # q and r share their noise with w and v (they are derivatives of the same field).
        self.filters = [_discrete(n, d, dt_s) for n, d in (hu, hv, hw, hp, hq, hr)]
        self.states = [np.zeros(max(len(a), len(b)) - 1) for b, a in self.filters]
        self.noise_gain = math.sqrt(math.pi / dt_s)
        self.rng = np.random.default_rng(seed)
        # scipy.signal is imported here, when the turbulence is made (before a run, never
        # inside one): a module that merely imports this one (the vehicle plant, and through
        # it heliquad identify's loop analysis) must not wait about 0.5 s for it.
        import scipy.signal

        self._lfilter = scipy.signal.lfilter

    def step(self) -> np.ndarray:
        """The next sample: [u, v, w] gust velocity (m/s), [p, q, r] gust rates (rad/s)."""
        return self.block(1)[0]

    def block(self, samples: int) -> np.ndarray:
        """The next ``samples`` samples (rows as :meth:`step`); the same stream however it
        is cut into blocks."""
        n_u, n_v, n_w, n_p = (self.rng.standard_normal((samples, 4)) * self.noise_gain).T
        out = np.empty((samples, 6))
        for i, n in enumerate((n_u, n_v, n_w, n_p, n_w, n_v)):
            b, a = self.filters[i]
            out[:, i], self.states[i] = self._lfilter(b, a, n, zi=self.states[i])
        return out
