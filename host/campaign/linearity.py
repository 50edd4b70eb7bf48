"""identify's reading of a linearity campaign (``sweep --signal multisine --linearity``,
:mod:`..acquire.linearity`): each realisation's points, the best linear approximation (BLA)
per amplitude with its noise and nonlinear distortion (:mod:`..estimate.linearity`), the
points the models are fitted to (the BLA at the larger amplitude, each point's sigma its
total variance: noise and distortion), and the verdict.

**The flag.** A level is flagged when its distortion is both *above the noise* (so many
lines' scatter across realisations exceeds what the scatter across periods explains that a
linear system would show it less than once in 100 campaigns) and *large enough to matter*:
its RMS over the lines at least :data:`DISTORTION_LIMIT_DB` of the BLA's magnitude (10 %:
one realisation's point then errs by about 1 dB, the accuracy the models are judged by).
Statistical significance alone would flag any friction in still air, where the noise is
tiny; size alone would flag turbulence. The models are flagged when the level they are
fitted to is.

**Amplitude dependence.** Per line, the BLA at the smaller amplitude against the larger:
the ratio in dB and degrees, and whether it exceeds three times its own standard deviation
(the two BLAs' total variances).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base.errors import InputError
from ..estimate.linearity import best_linear_approximation, level_verdict

__all__ = ["is_linearity", "linearity_points", "DISTORTION_LIMIT_DB"]

#: A level's distortion matters from this share of the BLA's magnitude (RMS), dB.
DISTORTION_LIMIT_DB = -20.0
#: A difference between the two amplitudes' BLAs is significant beyond this many sigmas.
DEPENDENCE_SIGMAS = 3.0


def is_linearity(manifest) -> bool:
    """The manifest is a linearity campaign's."""
    return bool((manifest.get("design") or {}).get("linearity"))


def linearity_points(manifest, by_entry, progress) -> tuple:
    """``(points, record)``: the BLA at the larger amplitude as the points to fit, and
    models.json's ``linearity`` (each level's lines and verdict, the amplitude dependence,
    ``flagged``); each level said. ``by_entry``: each realisation's entry with its points,
    as :func:`~.sweep_points.estimate_points` estimated them."""
    peaks = manifest["design"]["linearity"]["peaks"]
    levels = {}
    for entry, found in by_entry:
        if found and "level" in entry:
            levels.setdefault(entry["level"], []).append(found)
    if 0 not in levels:
        raise InputError("no realisation at the larger amplitude was measured")
    out, blas = [], {}
    for level, realisations in sorted(levels.items()):
        lines = best_linear_approximation(realisations)
        verdict = level_verdict(lines)
        verdict["flagged"] = verdict["flagged"] and \
            verdict["distortion_db"] >= DISTORTION_LIMIT_DB
        blas[level] = (lines, realisations)
        out.append({"level": level, "peak": peaks[level], "realisations": len(realisations),
                    **verdict, "lines": [_line_record(line) for line in lines]})
        progress(_level_text(out[-1]))
    record = {"levels": out, "fitted_level": 0, "flagged": out[0]["flagged"],
              "distortion_limit_db": DISTORTION_LIMIT_DB}
    if 1 in blas:
        record["amplitude_dependence"] = _dependence(blas[0][0], blas[1][0])
        progress(_dependence_text(record["amplitude_dependence"], peaks))
    return _bla_points(*blas[0]), record


def _line_record(line) -> dict:
    mag2 = abs(line.gain) ** 2
    return {"order": line.order, "freq_hz": line.omega_rad_s / (2 * math.pi),
            "magnitude_db": 20 * math.log10(abs(line.gain)),
            "phase_deg": math.degrees(np.angle(line.gain)),
            "noise_db": _db(line.var_noise_one / mag2),
            "distortion_db": _db(line.var_distortion / mag2),
            "ratio": line.ratio, "above_noise": bool(line.above_noise)}


def _db(power_ratio: float) -> float:
    return 10 * math.log10(max(power_ratio, 1e-30))


def _level_text(level) -> str:
    said = "flagged: a linear model does not hold here" if level["flagged"] else \
        "a linear model holds" if level["distortion_db"] < DISTORTION_LIMIT_DB else \
        "the distortion is not seen above the noise"
    return (f"  linearity at peak {level['peak']:.3g}: distortion {level['distortion_db']:.1f} "
            f"dB, noise {level['noise_db']:.1f} dB of the response (one realisation, RMS "
            f"over {level['count']} lines); {level['above_noise']} line(s) above the noise "
            f"(chance {level['chance']:.2g} for a linear system); {said}")


def _dependence(large, small) -> dict:
    """Per line shared, the smaller amplitude's BLA over the larger's."""
    small_by = {line.order: line for line in small}
    lines = []
    for a in large:
        b = small_by.get(a.order)
        if b is None:
            continue
        ratio = b.gain / a.gain
        z = abs(b.gain - a.gain) / math.sqrt(a.var_total + b.var_total)
        lines.append({"freq_hz": a.omega_rad_s / (2 * math.pi),
                      "db": 20 * math.log10(abs(ratio)), "deg": math.degrees(np.angle(ratio)),
                      "sigmas": z})
    worst = max(lines, key=lambda e: e["sigmas"]) if lines else None
    return {"lines": lines, "max_db": max((abs(e["db"]) for e in lines), default=0.0),
            "max_deg": max((abs(e["deg"]) for e in lines), default=0.0),
            "significant": bool(worst and worst["sigmas"] > DEPENDENCE_SIGMAS)}


def _dependence_text(dep, peaks) -> str:
    return (f"  amplitude dependence, peak {peaks[1]:.3g} against {peaks[0]:.3g}: up to "
            f"{dep['max_db']:.2f} dB and {dep['max_deg']:.1f} deg, "
            + ("significant" if dep["significant"] else "within the scatter"))


def _bla_points(lines, realisations) -> list:
    """The BLA as points: each line's first realisation's point with the BLA's gain, the
    total variance's sigma and the realisations' smallest coherence."""
    firsts = {}
    for points in realisations:
        for p in points:
            firsts.setdefault(p.order, []).append(p)
    return [dataclasses.replace(
        firsts[line.order][0], gain=line.gain, sigma=math.sqrt(line.var_total),
        coherence=min(p.coherence for p in firsts[line.order]), method="bla",
        input_gain=complex(np.mean([p.input_gain for p in firsts[line.order]])))
        for line in lines]
