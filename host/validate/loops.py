"""The firmware's cascade around a plant known by its frequency response.

A point of identification is a sampled-data response: from the command the firmware logged
to the rate it logged, one loop period apart, with the hold, the sensor's latency and any
delay inside it. A model fitted to the points is that response, so the loops are built as
the firmware flies them: the firmware's discrete PID (its Tustin recurrences, evaluated at
``z = exp(j w T)``, :func:`heliquad.sim.plant.pid_model.pid_z_coeffs`) in series with the
model's own response, delay exact, and no hold added (a second hold would count half a
sample twice).

Three loops, each broken at one point with the others closed (``h`` the rate response,
``h_a`` the angle response, for a model ``h`` times the way the firmware's logged angle
follows its logged rate on the IMU path it flew (:func:`angle_over_rate`: its sum of the
rate samples on the raw path, the integral on the DMP path); ``C_PI``, ``D_m`` the rate PID on the error and on the measurement,
``K_o``, ``D_o`` the angle PD's):

* ``rate``: at the plant input, angle loop open: ``L_r = (C_PI - D_m) h``;
* ``angle``: at the rate setpoint, rate loop closed:
  ``L_a = (K_o - D_o) C_PI h_a / (1 + (C_PI - D_m) h)``;
* ``input``: at the plant input, both loops closed (the loop a rig flies in angle mode, and
  the one a broken-loop measurement with mixer injection sees):
  ``L_in = (C_PI - D_m) h + C_PI (K_o - D_o) h_a``.

Yaw flies the rate loop alone. Margins come from every crossover up to the Nyquist
frequency (:func:`margins`); a margin whose crossover lies outside the identified band is
reported as not validated, with where it lies. For time responses the model becomes a
discrete system at the loop rate (:func:`discrete_cascade`): Tustin's map for its rational
part (it adds no hold; its frequency warping is 0.2 % at 30 rad/s and 200 Hz), whole
samples of delay as ``z^-d`` and the fraction by a first-order allpass of that group delay.
"""

from __future__ import annotations

import math

import numpy as np

from ...sim.base.firmware_facts import LOOP_PERIOD_S
from ...sim.plant.pid_model import pid_z_coeffs
from ..records.gains import DERIVATIVE_FILTER_N

__all__ = ["LOOP_DT_S", "RAW_PATH", "angle_over_rate", "loop_functions", "model_responses",
           "margins", "crossover_in_band", "discrete_cascade",
           "LOOP_NAMES", "broken_loop", "measured_loop", "loop_from_closed"]

#: The firmware's control loop period, s (its one definition: the firmware's loop rate).
LOOP_DT_S = LOOP_PERIOD_S
#: The loops of a cascade, in the order they are reported.
LOOP_NAMES = ("rate", "angle", "input")
#: Crossovers are searched on this many log-spaced frequencies, then refined.
SEARCH_POINTS = 4000
#: The search starts this far below the band's bottom (a slow crossover is still found).
SEARCH_BELOW = 100.0
#: A crossover within this fraction of the band's edges is inside it (rounding).
BAND_SLACK = 0.02
#: A crossover is refined to this fraction of its frequency.
ROOT_RTOL = 1e-12


def _controller(gains, dt_s):
    """``((C_PI, D_m) of the rate loop, (K_o, D_o) of the angle loop or None)``, each a
    ``(num, den)`` pair in z."""
    rate = pid_z_coeffs(*gains.rate, DERIVATIVE_FILTER_N, dt_s)
    if gains.angle is None:
        return rate, None
    kc, td = gains.angle
    return rate, pid_z_coeffs(kc, 0.0, td, DERIVATIVE_FILTER_N, dt_s)


def _at(coeffs, z):
    num, den = coeffs
    return np.polyval(num, z) / np.polyval(den, z)


#: The IMU path on which the firmware's logged angle is the sum of its logged rates: its
#: attitude filter (firmware/core/attitude.cpp) integrates each gyro sample as it arrives,
#: ``angle_k = angle_(k-1) + T rate_k``, which is ``T z / (z - 1)``, half a loop period
#: ahead of the continuous integral. On the DMP path the logged angle is the chip's own
#: attitude, which the continuous integral of the rate describes.
RAW_PATH = "raw"


def angle_over_rate(imu_path=None, dt_s=LOOP_DT_S):
    """The logged angle over the logged rate as a function of ``omega`` (rad/s): the
    firmware's sum ``T z / (z - 1)`` on the raw path (:data:`RAW_PATH`), else (the DMP
    path, or a path not known) the continuous integral ``1 / (j omega)``."""
    if imu_path == RAW_PATH:
        return lambda omega: dt_s / (1.0 - np.exp(-1j * np.asarray(omega, dtype=float) * dt_s))
    return lambda omega: 1.0 / (1j * np.asarray(omega, dtype=float))


def model_responses(num, den, delay_s, imu_path=None):
    """``(h, h_a)``: a model's rate response and the angle response it implies on the IMU
    path the firmware flew (:func:`angle_over_rate`), each a function of ``omega`` (rad/s)
    returning complex arrays."""
    def h(omega):
        s = 1j * np.asarray(omega, dtype=float)
        return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * delay_s)

    integral = angle_over_rate(imu_path)
    return h, (lambda omega: h(omega) * integral(omega))


def loop_functions(h, h_a, gains, dt_s=LOOP_DT_S) -> dict:
    """``{name: L(omega)}`` for the loops of the cascade (``rate``; with an angle loop and an
    angle response ``h_a`` also ``angle`` and ``input``), each a function of rad/s."""
    (c_pi, d_m), outer = _controller(gains, dt_s)

    def parts(omega):
        omega = np.asarray(omega, dtype=float)
        z = np.exp(1j * omega * dt_s)
        return omega, _at(c_pi, z), _at(d_m, z), z

    def rate(omega):
        omega, cp, dm, _ = parts(omega)
        return (cp - dm) * h(omega)

    loops = {"rate": rate}
    if outer is None or h_a is None:
        return loops
    k_o, d_o = outer

    def angle(omega):
        omega, cp, dm, z = parts(omega)
        return (_at(k_o, z) - _at(d_o, z)) * cp * h_a(omega) / (1 + (cp - dm) * h(omega))

    def plant_input(omega):
        omega, cp, dm, z = parts(omega)
        return (cp - dm) * h(omega) + cp * (_at(k_o, z) - _at(d_o, z)) * h_a(omega)

    loops.update(angle=angle, input=plant_input)
    return loops


def _roots(f, grid, values) -> list:
    """The roots of the real function ``f`` where ``values`` (``f`` on ``grid``) change
    sign, each refined by bisection to ROOT_RTOL of its frequency (a crossing whose ``f``
    is not finite inside its interval is none)."""
    with np.errstate(invalid="ignore"):
        change = np.nonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)[0]
    out = []
    for i in change:
        root = _bisect(f, float(grid[i]), float(grid[i + 1]), float(values[i]))
        if root is not None:
            out.append(root)
    return out


def _bisect(f, lo: float, hi: float, f_lo: float):
    """The sign change of ``f`` in ``[lo, hi]`` (``f(lo) = f_lo``, of the other sign than
    ``f(hi)``), halved until ROOT_RTOL of it; None where it is no root: ``f`` not finite
    where it is tried, or, at the end, larger than at either end of the interval (a sign
    change across a pole, where ``f`` grows without bound rather than vanishing). (Here
    rather than scipy.optimize.brentq: a few dozen evaluations of an interpolation, and
    importing scipy.optimize cost identify a fifth of a second.)"""
    bound = max(abs(f_lo), abs(f(hi)))
    while hi - lo > ROOT_RTOL * hi:
        mid = 0.5 * (lo + hi)
        f_mid = f(mid)
        if not math.isfinite(f_mid):
            return None
        if f_mid == 0.0:
            return mid
        if (f_mid < 0) == (f_lo < 0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    mid = 0.5 * (lo + hi)
    f_mid = f(mid)
    return mid if math.isfinite(f_mid) and abs(f_mid) <= bound else None


def crossover_in_band(crossovers, at) -> bool:
    """Whether the crossover at ``at`` rad/s, one of ``crossovers`` (:func:`margins`' lists,
    each with its ``in_band``), lies inside the band; True when it is not among them."""
    return next((c["in_band"] for c in crossovers if c["omega_rad_s"] == at), True)


def _in_band(omega, band) -> bool:
    return bool(band[0] * (1 - BAND_SLACK) <= omega <= band[1] * (1 + BAND_SLACK))


def margins(L, band_rad_s, dt_s=LOOP_DT_S) -> dict:
    """Every crossover of the loop gain ``L`` (a function of rad/s) from well below the band
    up to the Nyquist frequency, and the margins that matter.

    ``gain_crossovers``: ``|L| = 1``, each with its phase margin ``angle(-L)`` (rad, in
    (-pi, pi]); ``phase_crossovers``: ``L`` real and negative, each with its gain margin
    ``1 / |L|`` (a ratio; below 1 the loop is stable only with more gain). Each has
    ``in_band``. ``phase_margin_rad`` is the smallest, ``gain_margin`` the one nearest to 1
    (in dB), with their crossovers; None where there is no crossover. ``not_validated``: one
    sentence per reported margin whose crossover lies outside ``band_rad_s``.
    """
    lo, hi = band_rad_s[0] / SEARCH_BELOW, math.pi / dt_s * (1 - 1e-9)
    grid = np.geomspace(lo, hi, SEARCH_POINTS)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        values = np.asarray(L(grid))
        at = lambda w: complex(np.asarray(L(np.array([w])))[0])     # noqa: E731
        gains = _roots(lambda w: math.log(abs(at(w))), grid, np.log(np.abs(values)))
        phases = [w for w in _roots(lambda w: at(w).imag, grid, values.imag)
                  if at(w).real < 0]
    out = {"gain_crossovers": [{"omega_rad_s": w, "phase_margin_rad": float(np.angle(-at(w))),
                                "in_band": _in_band(w, band_rad_s)} for w in gains],
           "phase_crossovers": [{"omega_rad_s": w, "gain_margin": float(1 / abs(at(w))),
                                 "in_band": _in_band(w, band_rad_s)} for w in phases],
           "phase_margin_rad": None, "gain_crossover_rad_s": None, "gain_margin": None,
           "phase_crossover_rad_s": None, "not_validated": []}
    where = f"outside the identified band ({band_rad_s[0]:.3g}-{band_rad_s[1]:.3g} rad/s)"
    if out["gain_crossovers"]:
        pm = min(out["gain_crossovers"], key=lambda c: c["phase_margin_rad"])
        out.update(phase_margin_rad=pm["phase_margin_rad"], gain_crossover_rad_s=pm["omega_rad_s"])
        if not pm["in_band"]:
            out["not_validated"].append(f"phase margin: gain crossover at "
                                        f"{pm['omega_rad_s']:.3g} rad/s {where}")
    if out["phase_crossovers"]:
        gm = min(out["phase_crossovers"], key=lambda c: abs(math.log(c["gain_margin"])))
        out.update(gain_margin=gm["gain_margin"], phase_crossover_rad_s=gm["omega_rad_s"])
        if not gm["in_band"]:
            out["not_validated"].append(f"gain margin: phase crossover at "
                                        f"{gm['omega_rad_s']:.3g} rad/s {where}")
    return out


def discrete_model(num, den, delay_s, dt_s=LOOP_DT_S):
    """The model as a discrete transfer function at the loop rate: Tustin's map of its
    rational part, ``z^-d`` for whole samples of its delay and the allpass
    ``(a z + 1) / (z + a)``, ``a = (1 - e) / (1 + e)``, for the fraction ``e`` (its group
    delay at low frequency is ``e`` samples)."""
    # python-control (1 s) and scipy.linalg only when a loop is built: identify imports this
    import control

    if not np.any(np.asarray(num, dtype=float)):
        return control.tf([0.0], [1.0], dt_s)             # a zero model: nothing gets through
    G = control.sample_system(control.tf(list(num), list(den)), dt_s, method="bilinear")
    samples = delay_s / dt_s
    whole = int(math.floor(samples + 1e-9))
    frac = samples - whole
    if frac > 1e-6:
        a = (1 - frac) / (1 + frac)
        G = G * control.tf([a, 1.0], [1.0, a], dt_s)
    if whole:
        G = G * control.tf([1.0], [1.0] + [0.0] * whole, dt_s)
    return G


def _blocks_closed(blocks, wiring, inputs, outputs, dt_s):
    """Close a discrete block diagram with algebraic (feedthrough) paths solved exactly.

    ``blocks``: ``[(name of its output, SISO state space)]``; ``wiring``: for each block,
    its input as ``{signal: coefficient}`` over block outputs and external ``inputs``.
    Returns the state space from ``inputs`` to the named ``outputs``."""
    # python-control (1 s) and scipy.linalg only when a loop is built: identify imports this
    import control
    import scipy.linalg

    names_out = [name for name, _ in blocks]
    A = scipy.linalg.block_diag(*[np.atleast_2d(b.A) for _, b in blocks])
    B = scipy.linalg.block_diag(*[np.atleast_2d(b.B) for _, b in blocks])
    C = scipy.linalg.block_diag(*[np.atleast_2d(b.C) for _, b in blocks])
    D = np.diag([float(np.squeeze(b.D)) for _, b in blocks])
    n = len(blocks)
    Q, E = np.zeros((n, n)), np.zeros((n, len(inputs)))
    for row, wires in enumerate(wiring):
        for signal, k in wires.items():
            if signal in inputs:
                E[row, inputs.index(signal)] += k
            else:
                Q[row, names_out.index(signal)] += k
    M = np.linalg.inv(np.eye(n) - D @ Q)          # y = M (C x + D E w): the algebraic part
    S = np.array([[1.0 if name == o else 0.0 for name in names_out] for o in outputs])
    A_cl = A + B @ Q @ M @ C
    B_cl = B @ (Q @ M @ D @ E + E)
    return control.ss(A_cl, B_cl, S @ M @ C, S @ M @ D @ E, dt_s)


def discrete_cascade(num, den, delay_s, gains, dt_s=LOOP_DT_S, outer=True, imu_path=None):
    """The closed loop as the firmware flies it, as one discrete state-space system with
    inputs ``ref`` (the angle setpoint with the outer loop, else the rate setpoint) and
    ``d`` (a disturbance added to the command at the plant input), outputs ``rate`` and,
    with the outer loop, ``angle`` (the logged angle from the rate on ``imu_path``:
    :func:`angle_over_rate`, Tustin's integral for the continuous one). ``outer=False`` (or
    no angle gains) closes the rate loop alone. Its poles are the loop's, every
    controller state included."""
    # python-control (1 s) and scipy.linalg only when a loop is built: identify imports this
    import control

    (c_pi, d_m), angle = _controller(gains, dt_s)
    ss = lambda c: control.ss(control.tf(*c, dt_s))                # noqa: E731
    outer = outer and angle is not None
    setpoint = {"a1": 1.0, "a2": 1.0} if outer else {"ref": 1.0}
    blocks = [("rate", control.ss(discrete_model(num, den, delay_s, dt_s))),
              ("up", ss(c_pi)), ("ud", ss(d_m))]
    wiring = [{"up": 1.0, "ud": 1.0, "d": 1.0}, {**setpoint, "rate": -1.0}, {"rate": 1.0}]
    outputs = ["rate"]
    if outer:
        k_o, d_o = angle
        # the logged angle from the logged rate (angle_over_rate): the firmware's sum on the
        # raw path, else Tustin's integral (the continuous one's phase)
        integral = ([dt_s, 0.0], [1.0, -1.0]) if imu_path == RAW_PATH else \
            ([dt_s / 2, dt_s / 2], [1.0, -1.0])
        blocks += [("angle", ss(integral)), ("a1", ss(k_o)),
                   ("a2", ss(d_o))]
        wiring += [{"rate": 1.0}, {"ref": 1.0, "angle": -1.0}, {"angle": 1.0}]
        outputs.append("angle")
    return _blocks_closed(blocks, wiring, ["ref", "d"], outputs, dt_s)


def measured_loop_name(inject: str, axis: str):
    """The loop a broken-loop measurement sees, ``L = -(u - r) / u``, by where ``r`` is
    injected: at the plant input (mixer) the whole loop there (``input``; yaw's ``rate``);
    at the rate setpoint (rate) the angle loop; None where no loop closes around the
    injection (angle injection, or rate injection on yaw)."""
    if inject == "mixer":
        return "rate" if axis == "yaw" else "input"
    if inject == "rate" and axis != "yaw":
        return "angle"
    return None


def interpolated(omega, L):
    """The loop gain between measured points ``L`` at ``omega`` (increasing): log magnitude
    and unwrapped phase linear in log frequency; NaN outside the points."""
    lw = np.log(np.asarray(omega, dtype=float))
    lm, ph = np.log(np.abs(L)), np.unwrap(np.angle(L))

    def at(w):
        x = np.log(np.atleast_1d(np.asarray(w, dtype=float)))
        out = np.exp(np.interp(x, lw, lm) + 1j * np.interp(x, lw, ph))
        out[(x < lw[0] - 1e-12) | (x > lw[-1] + 1e-12)] = complex("nan+nanj")
        return out

    return at


def broken_loop(omega, input_gain, dt_s=LOOP_DT_S) -> dict:
    """Margins of the loop measured through the excitation: ``L = R/U - 1`` at each point
    (``input_gain`` = U/R), between the points (:func:`interpolated`). A margin whose
    crossover the points do not reach is left out, with ``unmeasured`` saying so."""
    return measured_loop(omega, 1.0 / np.asarray(input_gain, dtype=complex) - 1.0, dt_s)


def loop_from_closed(omega, closed, gains, loop: str, dt_s=LOOP_DT_S):
    """The loop gain at ``omega`` of the ``rate`` loop (broken at the plant input, the angle
    loop open) or the ``angle`` loop (broken at the rate setpoint, the rate loop closed),
    from its measured closed-loop response ``closed`` (rate over rate setpoint, or angle over
    angle setpoint) and the firmware's controller of that loop, known exactly: with ``P`` on
    the error and ``D`` on the measurement (``u = P (sp - y) + D y``), ``T = P G / (1 +
    (P - D) G)``, so ``G = T / (P - T (P - D))`` and ``L = (P - D) G``."""
    omega = np.asarray(omega, dtype=float)
    rate, angle = _controller(gains, dt_s)
    if loop == "angle" and angle is None:
        raise ValueError("yaw flies no angle loop")
    p, d = rate if loop == "rate" else angle
    z = np.exp(1j * omega * dt_s)
    pz, dz = _at(p, z), _at(d, z)
    t = np.asarray(closed, dtype=complex)
    return (pz - dz) * t / (pz - t * (pz - dz))


def measured_loop(omega, L, dt_s=LOOP_DT_S) -> dict:
    """Margins of a loop gain ``L`` measured at the points ``omega`` (increasing), between
    them as :func:`interpolated` has it. A margin whose crossover the points do not reach is
    left out, with ``unmeasured`` saying so."""
    omega = np.asarray(omega, dtype=float)
    L = np.asarray(L, dtype=complex)
    out = margins(interpolated(omega, L), (omega[0], omega[-1]), dt_s)
    out["not_validated"] = []
    lo, hi = omega[0], omega[-1]
    db = 20 * np.log10(np.abs(L))
    span = f"between {lo:.3g} and {hi:.3g} rad/s"
    out["unmeasured"] = []
    if not out["gain_crossovers"]:
        out["unmeasured"].append(f"phase margin: |L| does not cross 0 dB {span} (from "
                                 f"{db[0]:.1f} to {db[-1]:.1f} dB)")
    if not out["phase_crossovers"]:
        out["unmeasured"].append(f"gain margin: the phase of L does not cross -180 deg {span}")
    out["omega_rad_s"], out["L"] = omega, L
    return out
