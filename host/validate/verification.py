"""Tuned gains judged on the board (``heliquad verify``, docs/verification.md): the band a
verification sweep covers, each loop measured from its sweep's points, and the acceptance
rule.

Each loop is measured from a sweep injected at its own setpoint, against the excitation:
the rate loop (broken at the plant input, the angle loop open) from the rate setpoint's
sweep, the angle loop (broken at the rate setpoint, the rate loop closed) from the angle
setpoint's, each from its closed-loop response and the firmware's controller of that loop,
known exactly (:func:`heliquad.host.validate.loops.loop_from_closed`). Each measured margin
carries its own uncertainty: its spread over draws of the points within their sigma,
times :data:`COVERAGE`. A measured margin is accepted when it lies within the predicted
one's uncertainty and the measurement's, combined (root sum of squares, never tighter than
:data:`FLOOR`), and is not below the specification; one predicted by extrapolation (its
crossover outside the band the model was identified over) when it is not below the
specification.
"""

from __future__ import annotations

import numpy as np

from .closed_loop import margins_record
from .loops import LOOP_DT_S, loop_from_closed, loop_functions, margins, measured_loop
from .tuning import Spec

__all__ = ["FLOOR", "COVERAGE", "MARGINS", "CROSSOVERS", "SWEEP_OF_LOOP", "sweep_band", "measured_margins",
           "truth_margins", "judge", "margins_only", "sorted_points"]

#: The least a measured margin may differ from its prediction by: a sweep's points carry
#: their own noise, and the interpolation between them moves a crossover a little.
FLOOR = {"gain_margin_db": 1.0, "phase_margin_deg": 5.0}
#: A measured margin's uncertainty is this many standard deviations of its spread over
#: :data:`DRAWS` draws of the points (each point's complex response with its sigma, normal,
#: independent; a fixed seed, so a verdict is repeatable): tune's default coverage of the
#: points' sigma, so that both uncertainties are read alike.
COVERAGE = Spec.coverage_k
DRAWS = 200
#: The margins judged, each with its unit as said.
MARGINS = {"phase_margin_deg": "deg", "gain_margin_db": "dB"}
#: The injection whose sweep measures each loop.
SWEEP_OF_LOOP = {"rate": "rate", "angle": "angle"}
#: The sweep's band reaches this far below the lowest predicted crossover and above the
#: highest, so that the interpolation between the points finds every crossover inside.
BELOW, ABOVE = 0.5, 1.5
#: The crossovers the band is chosen from.
CROSSOVERS = ("gain_crossover_rad_s", "phase_crossover_rad_s")


def sweep_band(predicted: dict, top_rad_s: float, bottom_rad_s: float) -> tuple:
    """``(low, high)`` rad/s of the sweep that measures a loop: from :data:`BELOW` of its
    lowest predicted crossover to :data:`ABOVE` of its highest, within
    ``[bottom_rad_s, top_rad_s]`` (the firmware's and the signal's limits); up to
    ``top_rad_s`` when a margin's prediction is extrapolated (its crossover may lie anywhere
    above the identified band)."""
    found = [predicted[k] for k in CROSSOVERS if predicted.get(k)]
    if not found:
        raise ValueError("a loop with no predicted crossover")
    low = max(bottom_rad_s, BELOW * min(found))
    if predicted.get("extrapolated"):
        return low, top_rad_s
    return low, min(top_rad_s, max(ABOVE * max(found), 2 * low))


def margins_only(record: dict) -> dict:
    """A loop's margins and the crossovers they are at (what verify.json keeps), and the
    margins predicted by extrapolation when there are any."""
    out = {k: record.get(k) for k in (*MARGINS, *CROSSOVERS)}
    if record.get("extrapolated"):
        out["extrapolated"] = list(record["extrapolated"])
    return out


def measured_margins(omega, closed, gains, loop: str, sigma=None) -> dict:
    """A loop's margins measured from its sweep's points: ``closed`` the closed-loop
    response at ``omega`` (rad/s, increasing), ``gains`` (a Gains) flown; with the points'
    ``sigma``, each margin's ``uncertainty`` (:data:`COVERAGE` standard deviations of its
    spread over :data:`DRAWS` draws of the points)."""
    m = measured_loop(omega, loop_from_closed(omega, closed, gains, loop))
    out = {**margins_only(margins_record(m)), "unmeasured": list(m["unmeasured"])}
    if sigma is not None:
        out["uncertainty"] = _spread(omega, closed, np.asarray(sigma, dtype=float), gains, loop)
    return out


def _spread(omega, closed, sigma, gains, loop: str) -> dict:
    """Each margin's :data:`COVERAGE` standard deviations over :data:`DRAWS` draws of the
    points, the draws in which the margin was found (0 when fewer than two were)."""
    rng = np.random.default_rng(0)
    found = {k: [] for k in MARGINS}
    for _ in range(DRAWS):
        noise = rng.standard_normal((2, len(omega))) * sigma / np.sqrt(2.0)
        m = margins_record(measured_loop(omega, loop_from_closed(
            omega, closed + noise[0] + 1j * noise[1], gains, loop)))
        for key in MARGINS:
            if m.get(key) is not None and np.isfinite(m[key]):
                found[key].append(m[key])
    return {k: COVERAGE * float(np.std(v)) if len(v) > 1 else 0.0 for k, v in found.items()}


def truth_margins(h, h_a, gains, loop: str, band_rad_s) -> dict:
    """A loop's margins around the simulator's truth (``h``, ``h_a`` the sampled responses
    from the torque command to the logged rate and angle) with ``gains``."""
    L = loop_functions(h, h_a, gains, LOOP_DT_S)[loop]
    return margins_only(margins_record(margins(L, band_rad_s)))


def _allowed(predicted: dict, measured: dict) -> dict:
    """The band each margin may lie in around its prediction: the prediction's uncertainty
    and the measurement's, root sum of squares, never tighter than :data:`FLOOR`."""
    spread = predicted.get("uncertainty") or {}
    own = measured.get("uncertainty") or {}
    return {k: max(float(np.hypot(spread.get(k) or 0.0, own.get(k) or 0.0)), FLOOR[k])
            for k in MARGINS}


def judge(predicted: dict, measured: dict, spec: dict) -> tuple:
    """``(allowed, failures)``: the band each margin may lie in, and one phrase per margin
    that failed (not measured, outside the band, below the specification); none: accepted.
    A margin predicted by extrapolation (``predicted["extrapolated"]``: read where the model
    has no data) is held to the specification only: the measurement is its only evidence."""
    allowed, failures = _allowed(predicted, measured), []
    for key, unit in MARGINS.items():
        name = key.split("_margin")[0] + " margin"
        want, got, least = predicted.get(key), measured.get(key), spec.get(key)
        if want is None and got is None:
            continue
        if got is None:
            why = next((u for u in measured.get("unmeasured", []) if u.startswith(name)), None)
            failures.append(f"{name} not measured ({why.split(': ', 1)[1]})" if why else
                            f"{name} not measured")
            continue
        if want is None:
            failures.append(f"{name} {got:.1f} {unit} measured, none predicted")
            continue
        off = got - want
        if abs(off) > allowed[key] and key not in predicted.get("extrapolated", ()):
            failures.append(f"{name} {got:.1f} {unit} measured, {want:.1f} +/- "
                            f"{allowed[key]:.1f} predicted ({abs(off) - allowed[key]:.1f} "
                            f"{unit} outside)")
        if least is not None and got < least:
            failures.append(f"{name} {got:.1f} {unit} below the specification's "
                            f"{least:g} {unit} by {least - got:.1f} {unit}")
    return allowed, failures


def sorted_points(points):
    """``(omega, closed-loop response, sigma)`` of a sweep's points, by frequency, the points
    whose response is not finite left out (a sigma that is not finite taken as 0)."""
    pts = sorted((p for p in points if np.isfinite(p.gain)), key=lambda p: p.omega_rad_s)
    return (np.array([p.omega_rad_s for p in pts]),
            np.array([p.gain for p in pts], dtype=complex),
            np.nan_to_num(np.array([p.sigma for p in pts], dtype=float), nan=0.0,
                          posinf=0.0))
