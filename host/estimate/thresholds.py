"""The thresholds an identification's points and models are judged by: a point's coherence
(:data:`LOW_COHERENCE`), a model's and its points' accuracy against the simulator's truth
(:data:`ACCURACY_DB`, :data:`ACCURACY_DEG`), and whether the points' sigmas are honest
(:data:`ROUND_OFF_SIGMA`, :func:`honest_sigma_bound`). One definition each: the identification
records them, the report and the commands flag by them, the plots draw them."""

from __future__ import annotations

__all__ = ["LOW_COHERENCE", "ACCURACY_DB", "ACCURACY_DEG", "ROUND_OFF_SIGMA", "NORMAL_99",
           "honest_sigma_bound"]

#: A point whose coherence is below this is flagged (and drawn as the gate in bode.png).
LOW_COHERENCE = 0.6
#: The accuracy the report judges a model and its points by, against the simulator's truth
#: (magnitude dB, phase deg, anywhere in the identified band): an error below it would not
#: change a controller designed on the model. Loops are designed to margins of 6 dB and
#: 45 deg (MIL-F-9490D's, the usual requirement); 1 dB moves the gain margin by a sixth and
#: 5 deg the phase margin by a ninth, what a designer's own guard on them absorbs, and
#: CIFER's cost weighs 1 dB about like 7.6 deg, so the two are of a size. The same bar the
#: demo's test holds its models to (they are within 0.06-0.22 dB and 1.2-1.9 deg); a model
#: several dB or tens of degrees off is flagged.
ACCURACY_DB, ACCURACY_DEG = 1.0, 5.0
#: Points' sigmas (median, relative to their magnitude) below this are round-off, not noise:
#: telemetry's single-precision floats resolve 6e-8 of a value, and a noise-free simulation
#: leaves only that; their error/sigma then measures nothing.
ROUND_OFF_SIGMA = 1e-6
#: The one-sided 99 % point of the standard normal, for the honest sigmas' bound
#: (:func:`honest_sigma_bound`).
NORMAL_99 = 2.326


def honest_sigma_bound(n_points: int) -> float:
    """The largest RMS error/sigma over ``n_points`` points that honest sigmas give 99 times
    in 100. A point's error is complex and sigma its whole standard deviation, so
    ``|e/sigma|^2`` summed over the points is chi-square with 2n degrees of freedom over 2;
    its 99 % point by Wilson and Hilferty's approximation (within 1 % from 2 degrees of
    freedom up). 15 points: 1.30; 5 points: 1.52."""
    k = 2 * max(int(n_points), 1)
    chi2 = k * (1 - 2 / (9 * k) + NORMAL_99 * (2 / (9 * k)) ** 0.5) ** 3
    return (chi2 / k) ** 0.5
