"""Transfer-function fitting: exact recovery, noise, stability, delay, selection."""

import math

import numpy as np
import pytest

from heliquad.host.estimate import fit as fit_module
from heliquad.host.estimate.fit import TfModel, fit_levy, fit_tf, model_response, parse_order
from heliquad.host.estimate.metrics import cifer_weight, evaluate_model, recommend
from heliquad.host.estimate.models import fit_orders
from heliquad.host.records.points import frequency_points
from heliquad.host.records import paper
from heliquad.sim.base.errors import InputError

N_POINTS = 15
DECADES = 1.5

#: Known models for synthetic recovery: name -> (num, den, delay_s, centre rad/s).
SYNTHETIC = {
    "first order": ([2.0], [1.0, 1.5], 0.0, 2.0),
    "underdamped second order (roll-like)": ([28.19], [1, 5.13, 22.93], 0.0, 6.0),
    "third order with zeros": (list(20.0 * np.poly([-1.0, -2.0])),
                               list(np.poly([-6.0, -3 + 12j, -3 - 12j]).real), 0.0, 5.6),
    "second order with 20 ms delay": ([28.19], [1, 5.13, 22.93], 0.020, 6.0),
}


def band(centre_rad_s):
    half = DECADES / 2
    return centre_rad_s * np.logspace(-half, half, N_POINTS)


def order_of(num, den):
    return len(num) - 1, len(den) - 1


@pytest.mark.parametrize("name", SYNTHETIC)
def test_noise_free_recovery_within_half_a_percent(name):
    num, den, tau, centre = SYNTHETIC[name]
    omega = band(centre)
    F = model_response(num, den, tau, omega)
    model = fit_tf(omega, F, order_of(num, den), delay=tau > 0)
    np.testing.assert_allclose(model.num, num, rtol=5e-3)
    np.testing.assert_allclose(model.den, den, rtol=5e-3)
    assert model.delay_s == pytest.approx(tau, rel=5e-3, abs=1e-9)
    assert model.stable


@pytest.mark.parametrize("axis, order", [(a, o) for a in paper.MODELS for o in paper.MODELS[a]])
def test_published_models_refit_at_their_own_order_within_one_percent(axis, order):
    num, den = paper.MODELS[axis][order]
    lo, hi = paper.BANDS_HZ[axis]
    omega = 2 * np.pi * np.logspace(math.log10(lo), math.log10(hi), N_POINTS)
    model = fit_tf(omega, model_response(num, den, 0.0, omega), order)
    np.testing.assert_allclose(model.num, num, rtol=1e-2)
    np.testing.assert_allclose(model.den, den, rtol=1e-2)


def noisy(F, seed, level=0.05):
    """5 % complex noise: F (1 + e), e complex Gaussian with E|e|^2 = level^2."""
    rng = np.random.default_rng(seed)
    e = (rng.normal(size=F.size) + 1j * rng.normal(size=F.size)) * level / math.sqrt(2)
    return F * (1 + e)


def band_error(response, num, den, tau, omega):
    """Relative complex error of a response against the truth on a dense grid in the band."""
    dense = np.logspace(np.log10(omega[0]), np.log10(omega[-1]), 400)
    err = np.abs(response(dense) / model_response(num, den, tau, dense) - 1)
    return float(np.sqrt(np.mean(err ** 2))), float(np.max(err))


#: "Within the noise": the fitted response's RMS relative error across the band stays below
#: the 5 % noise of a single point, and its worst error below twice that.
NOISE = 0.05


@pytest.mark.parametrize("name", SYNTHETIC)
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fit_with_five_percent_noise_stays_within_the_noise(name, seed):
    num, den, tau, centre = SYNTHETIC[name]
    omega = band(centre)
    F = noisy(model_response(num, den, tau, omega), seed)
    model = fit_tf(omega, F, order_of(num, den), delay=tau > 0)
    rms, worst = band_error(model.response, num, den, tau, omega)
    assert rms < NOISE and worst < 2 * NOISE
    assert model.stable


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_plain_levy_fails_the_same_criterion(seed):
    # The criterion above discriminates: Levy's equation error weights each point by
    # |D(j w)|^2, and with the zeros low in the band that drowns the low frequencies.
    num, den, tau, centre = SYNTHETIC["third order with zeros"]
    omega = band(centre)
    F = noisy(model_response(num, den, tau, omega), seed)
    lnum, lden = fit_levy(omega, F, order_of(num, den))
    rms, worst = band_error(lambda w: model_response(lnum, lden, 0.0, w), num, den, tau, omega)
    assert not (rms < NOISE and worst < 2 * NOISE)


def test_unstable_data_gives_a_stable_model_by_default_and_a_flag_when_allowed():
    num, den = [4.0], [1.0, -0.5, 4.0]          # poles at 0.25 +/- 1.98j
    omega = np.logspace(-0.5, 1.0, N_POINTS)
    F = model_response(num, den, 0.0, omega)
    constrained = fit_tf(omega, F, (0, 2))
    assert constrained.stable and np.all(constrained.poles.real < 0)
    free = fit_tf(omega, F, (0, 2), stable=False)
    assert not free.stable
    np.testing.assert_allclose(free.den, den, atol=1e-6)


def test_unstable_models_are_never_recommended():
    num, den = [4.0], [1.0, -0.5, 4.0]
    omega = np.logspace(-0.5, 1.0, N_POINTS)
    points = frequency_points(omega, model_response(num, den, 0.0, omega))
    result = fit_orders(points, [(0, 2)], stable=False)
    assert result.recommended is None and "no stable" in result.reason


def test_recommendation_is_the_lowest_aicc_of_the_acceptable_models():
    # The paper's roll model with 2 % noise and sigma weights: the higher orders fit the
    # noise no better than 0/2 and pay for their parameters in AICc.
    num, den = paper.MODELS["roll"][(0, 2)]
    omega = 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), N_POINTS)
    F = model_response(num, den, 0.0, omega)
    points = frequency_points(omega, noisy(F, 4, 0.02), sigma=0.02 * np.abs(F))
    result = fit_orders(points, paper.DEFAULT_ORDERS["roll"])
    assert result.models[result.recommended].order == (0, 2)
    assert "lowest AICc" in result.reason and result.quality[0] == "good"
    aicc = [m.metrics["aicc"] for m in result.models
            if m.stable and not m.degenerate and m.metrics["J"] <= 100]
    assert result.models[result.recommended].metrics["aicc"] == min(aicc)


def test_the_recommendation_is_never_visibly_worse_than_another_candidate():
    # Noise-free third-order data: whatever AICc says, the pick's J is never above twice
    # another acceptable model's and 5 more.
    num, den, _, centre = SYNTHETIC["third order with zeros"]
    omega = band(centre)
    points = frequency_points(omega, model_response(num, den, 0.0, omega))
    result = fit_orders(points, [(0, 1), (0, 2), (2, 3)])
    assert result.models[result.recommended].order == (2, 3)
    pick = result.models[result.recommended].metrics["J"]
    for m in result.models:
        if m.stable and not m.degenerate and m.metrics["J"] <= 100:
            assert not (pick > 2 * m.metrics["J"] and pick - m.metrics["J"] > 5)


def test_visibly_better_fit_overrides_aicc():
    # Two acceptable models: AICc prefers one (its weighted residuals are smaller), the
    # other's J is a tenth of it and 20 lower: the rule takes the one that fits visibly
    # better, and says why.
    a = TfModel((0, 1), np.array([1.0]), np.array([1.0, 1.0]),
                metrics={"J": 30.0, "aicc": -50.0, "n_parameters": 2})
    b = TfModel((0, 2), np.array([1.0]), np.array([1.0, 1.0, 1.0]),
                metrics={"J": 3.0, "aicc": -40.0, "n_parameters": 3})
    index, reason = recommend([a, b])
    assert index == 1 and "fits visibly better" in reason
    b.metrics["J"] = 26.0                      # lower, but not visibly: AICc decides
    assert recommend([a, b])[0] == 0


def test_metrics_of_an_exact_model():
    num, den = [28.19], [1, 5.13, 22.93]
    omega = band(6.0)
    F = model_response(num, den, 0.0, omega)
    model = fit_tf(omega, F, (0, 2))
    metrics = evaluate_model(model, omega, F, 1 / np.abs(F))
    assert metrics["J"] < 1e-12 and metrics["rms"] < 1e-10
    assert model.dc_gain == pytest.approx(28.19 / 22.93, rel=1e-8)
    np.testing.assert_allclose(np.sort_complex(model.poles),
                               np.sort_complex(np.roots(den)), rtol=1e-8)


def test_cifer_cost_of_a_known_error():
    # Every point 1 dB high and 10 deg late: J = 20 (1 + 0.01745 * 100) = 54.9 at coherence 1
    # times W = (1.58 (1 - e^-1))^2 = 0.9976.
    omega = band(2.0)
    F = model_response([1.0], [1.0, 1.0], 0.0, omega)
    model = fit_tf(omega, F, (0, 1))
    shifted = F / (10 ** (1 / 20) * np.exp(-1j * np.radians(10)))
    J = evaluate_model(model, omega, shifted, 1 / np.abs(F))["J"]
    assert J == pytest.approx(20 * (1 + 0.01745 * 100) * (1.58 * (1 - math.exp(-1))) ** 2,
                              rel=1e-6)


@pytest.mark.parametrize("text, expected", [("0/2", (0, 2)), (" 2 / 4 ", (2, 4)),
                                            ("0/2i", (0, 2, 1)), ("1/3i", (1, 3, 1))])
def test_parse_order(text, expected):
    assert parse_order(text) == expected


@pytest.mark.parametrize("text, match", [("2", "form M/N"), ("a/b", "form M/N"),
                                         ("3/2", "improper"), ("0/0", "at least 1"),
                                         ("-1/2", "form M/N"), ("0/1i", "integrator"),
                                         ("2/2i", "integrator")])
def test_parse_order_rejects(text, match):
    with pytest.raises(InputError, match=match):
        parse_order(text)


def test_an_integrator_structure_recovers_a_free_rigs_rate_response():
    # K e^(-s T) / (s (s + a)), a rate that integrates the command through one lag, with
    # 2 % noise: the 0/2i fit with delay recovers K, a and T, its pole at the origin exact,
    # and counts one parameter less than 0/2.
    omega = 2 * np.pi * np.geomspace(0.5, 4.5, N_POINTS)
    F = model_response([500.0], [1.0, 32.0, 0.0], 0.0125, omega)
    model = fit_tf(omega, noisy(F, 5, 0.01), (0, 2, 1), delay=True)
    assert model.integrator and model.structure == (0, 2, 1) and model.den[-1] == 0.0
    assert model.num[-1] == pytest.approx(500, rel=0.05)
    assert model.den[1] == pytest.approx(32, rel=0.05)
    assert model.delay_s == pytest.approx(0.0125, abs=1e-3)
    assert model.stable and not model.degenerate
    evaluate_model(model, omega, F, 1 / np.abs(F))
    assert model.metrics["n_parameters"] == 3              # K, a, T (the pole at 0 is fixed)
    assert model.dc_gain == math.inf


def test_too_few_points_for_the_order():
    omega = np.array([1.0, 2.0, 3.0])
    points = frequency_points(omega, model_response([1.0], [1, 1], 0.0, omega))
    with pytest.raises(InputError, match="needs at least"):
        fit_orders(points, [(2, 4)])


def test_recommend_without_acceptable_model_says_so():
    # A first-order model cannot follow the roll model's resonance and -180 deg phase.
    omega = band(6.0)
    F = model_response([28.19], [1, 5.13, 22.93], 0.0, omega)
    model = fit_tf(omega, F, (0, 1))
    evaluate_model(model, omega, F, 1 / np.abs(F))
    assert model.metrics["J"] > 100 and not model.degenerate
    index, reason = recommend([model])
    assert index == 0 and "no stable model reaches" in reason


def test_an_order_the_points_do_not_support_is_flagged_degenerate():
    # A 0/3 fit to exact 0/2 data sends its extra pole off the band.
    omega = band(6.0)
    F = model_response([28.19], [1, 5.13, 22.93], 0.0, omega)
    model = fit_tf(omega, F, (0, 3))
    evaluate_model(model, omega, F, 1 / np.abs(F))
    assert model.degenerate
    assert recommend([model])[0] is None
    assert "edge of the allowed range" in model.degenerate_why


def points_of(num, den, delay_s, omega):
    F = model_response(num, den, delay_s, omega)
    return frequency_points(omega, F, sigma=0.01 * np.abs(F))


def test_a_spare_order_that_matches_noise_free_points_to_rounding_is_not_recommended():
    # On noise-free 0/2 points with a delay, a 2/4 can spend its spare pair of poles and zeros
    # far above the band (a zero pair cancelling a pole pair, or a zero so far up it changes
    # nothing) and match the points to rounding error; its AICc is then lower by chance.
    # What it adds changes nothing the points show: degenerate, not recommended.
    omega = 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), 12)
    result = fit_orders(points_of([28.19], [1, 5.13, 22.93], 0.02, omega),
                        [(0, 2), (2, 4)], delay=True)
    spare = result.models[1]
    assert spare.metrics["max_mag_err_db"] < 1e-6
    assert spare.degenerate and spare.degenerate_why.startswith(("a zero cancels a pole",
                                                                  "a zero at"))
    assert result.recommended == 0


def test_a_zero_that_cancels_a_pole_marks_the_model_degenerate():
    # What a 2/4 fitted to those points once did: a pair of each at 1322 rad/s, 1e-5 apart.
    from heliquad.host.estimate.models import _flag_unsupported_zeros

    pair = [1.0, 2 * 0.5 * 1322.0, 1322.0 ** 2]
    near = [1.0, 2 * 0.5 * 1322.0 * (1 + 1e-5), (1322.0 * (1 + 1e-5)) ** 2]
    model = TfModel(order=(2, 4), num=28.19 * np.array(near) / near[-1] * pair[-1],
                    den=np.polymul([1, 5.13, 22.93], pair), delay_s=0.02)
    _flag_unsupported_zeros(model, 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), 12))
    assert model.degenerate and model.degenerate_why.startswith("a zero cancels a pole at 1322")


def test_a_zero_far_above_the_band_marks_the_model_degenerate():
    # The yaw demo's 2/3 with delay: a numerator coefficient of 1e-5 put a zero at 2.4e7
    # rad/s, a 1/3 in disguise that validate cannot take; not recommended, and it says why.
    from heliquad.host.estimate.models import _flag_unsupported_zeros

    model = TfModel(order=(2, 3), num=np.array([1.0999e-05, 262.25, 1424.2]),
                    den=np.array([1.0, 46.014, 244.0, 21.618]), delay_s=0.00367)
    _flag_unsupported_zeros(model, 2 * np.pi * np.logspace(math.log10(0.15), math.log10(1.6), 15))
    assert model.degenerate and model.degenerate_why.startswith("a zero at 2.38e+07 rad/s")


@pytest.mark.parametrize("order", [o for o in paper.MODELS["roll"] if o[0] > 0])
def test_a_model_whose_zeros_shape_the_band_is_not_flagged(order):
    # The paper's roll models with zeros, on their own points: the zeros matter in the band.
    num, den = paper.MODELS["roll"][order]
    omega = 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), 15)
    result = fit_orders(points_of(num, den, 0.0, omega), [order])
    assert not result.models[0].degenerate, result.models[0].degenerate_why


# --- the refinement's Jacobian and the choice of starts --------------------------------------

def finite_difference_jacobian(fun, params, step=1e-6):
    columns = []
    for k in range(params.size):
        h = step * max(1.0, abs(params[k]))
        e = np.zeros_like(params)
        e[k] = h
        columns.append((fun(params + e) - fun(params - e)) / (2 * h))
    return np.column_stack(columns)


def random_problem(order, stable, delay, seed):
    """A generator and the output-error problem of noisy points of a 1/3 with delay."""
    rng = np.random.default_rng(seed + 100 * stable + 1000 * delay)
    x = np.logspace(-0.75, 0.75, N_POINTS)
    F = noisy(model_response([1.2, 0.5], [1, 0.8, 1.1, 0.3], 0.2, x), 5, 0.03)
    return rng, fit_module._OutputError(x, F, *order, 1 / np.abs(F), stable, delay)


def random_poles(rng, n, stable, spread):
    """Random pole parameters: log factors within +/- spread, or a stable polynomial's free
    coefficients scaled at random."""
    return (rng.uniform(-spread, spread, n) if stable
            else np.poly(-rng.uniform(0.3, 2.0, n))[1:] * rng.uniform(0.5, 1.5, n))

@pytest.mark.parametrize("delay", [False, True], ids=["no delay", "delay"])
@pytest.mark.parametrize("stable", [True, False], ids=["log factors", "free coefficients"])
@pytest.mark.parametrize("order", [(0, 1), (0, 2), (1, 3), (2, 4), (2, 5)])
def test_the_analytic_jacobian_matches_finite_differences(order, stable, delay):
    # At random parameters the residual is far from zero, so both terms of the projection's
    # derivative count (dropping the one in r, Kaufman's approximation, misses by far more).
    m, n = order
    rng, problem = random_problem(order, stable, delay, 10 * m + n)
    for _ in range(3):
        params = random_poles(rng, n, stable, 2.0)
        if delay:
            params = np.append(params, rng.uniform(0.0, 0.5))
        J = problem.jacobian(params)
        J_fd = finite_difference_jacobian(problem.residuals, params)
        assert J.shape == J_fd.shape == (2 * N_POINTS, n + delay)
        assert np.max(np.abs(J - J_fd)) <= 1e-6 * np.max(np.abs(J_fd))


ZOH_HZ = 200.0


def sweep_like(axis, truth, delay_s, noise, seed):
    """A sweep's points: a paper model with a delay, a 200 Hz zero-order hold and noise."""
    num, den = paper.MODELS[axis][truth]
    lo, hi = paper.BANDS_HZ[axis]
    omega = 2 * np.pi * np.logspace(math.log10(lo), math.log10(hi), N_POINTS)
    s_t = 1j * omega / ZOH_HZ
    F = model_response(num, den, delay_s, omega) * (1 - np.exp(-s_t)) / s_t
    return omega, (noisy(F, seed, noise) if noise else F)


def relative_cost(model, omega, F):
    """What fit_tf's output-error stage minimises with its default weights."""
    return float(np.sum(np.abs((F - model.response(omega)) / F) ** 2))


#: Points on which refining fewer starts than the default misses the best minimum with a
#: delay, with how many of each kind do: orders above what the data need have several minima,
#: and the starts that cost least before refinement lead to worse ones; on the noise-free yaw
#: points they sit at zero delay, in a minimum of their own.
MISSED_WITH_FEWER = {("roll", (0, 2), 0.020, 0.01, 1, (2, 4)): 1,
                     ("roll", (0, 3), 0.015, 0.03, 1, (2, 4)): 1,
                     ("yaw", (2, 2), 0.015, 0.0, 0, (2, 2)): 1}
#: More points with several minima, on which the screen once missed the best.
SEVERAL_MINIMA = (("yaw", (0, 1), 0.015, 0.01, 1, (2, 3)), ("yaw", (0, 1), 0.015, 0.01, 2, (2, 2)))
#: Points whose best minimum lies at the end of a long valley (hundreds of evaluations).
LONG_VALLEY = ("yaw", (0, 1), 0.010, 0.02, 2, (2, 2))
#: Points on which a screen of 5 evaluations a parameter misses the best minimum without a
#: delay (of 1620 sets of the three axes' paper models, delays, noise and orders up to 3/4,
#: seven, by up to 5 %; a screen of SCREEN_EVALUATIONS misses none of them).
SHORT_SCREEN_MISSES = (("roll", (0, 3), 0.020, 0.03, 2, (3, 4)),
                       ("pitch", (0, 2), 0.010, 0.03, 1, (2, 4)))


def fit_cost(monkeypatch, case, per_kind, delay=True, screen=None):
    axis, truth, delay_s, noise, seed, order = case
    omega, F = sweep_like(axis, truth, delay_s, noise, seed)
    monkeypatch.setattr(fit_module, "STARTS_PER_KIND", per_kind)
    if screen is not None:
        monkeypatch.setattr(fit_module, "SCREEN_EVALUATIONS", screen)
    return relative_cost(fit_tf(omega, F, order, delay=delay, cost="relative"), omega, F)


@pytest.fixture(scope="module")
def exhaustive_cost():
    """The best cost of refining every start (on the delay grid with a delay), once per set."""
    found = {}

    def cost(case, delay=True):
        if (case, delay) not in found:
            with pytest.MonkeyPatch.context() as patch:
                found[case, delay] = fit_cost(patch, case, None, delay)
        return found[case, delay]
    return cost


@pytest.mark.parametrize("case, delay", [*((c, True) for c in MISSED_WITH_FEWER),
                                         *((c, True) for c in SEVERAL_MINIMA),
                                         (LONG_VALLEY, True), (LONG_VALLEY, False),
                                         *((c, False) for c in SHORT_SCREEN_MISSES)])
def test_refining_the_screened_starts_finds_the_exhaustive_best(monkeypatch, exhaustive_cost,
                                                                 case, delay):
    every = exhaustive_cost(case, delay)
    screened = fit_cost(monkeypatch, case, fit_module.STARTS_PER_KIND, delay)
    # relative 1e-6, and absolute 1e-12 of the points' weighted sum (N for these weights)
    assert screened <= every * (1 + 1e-6) + 1e-12 * N_POINTS


@pytest.mark.parametrize("case", MISSED_WITH_FEWER)
def test_fewer_starts_per_kind_miss_it_on_these_sets(monkeypatch, exhaustive_cost, case):
    fewer = MISSED_WITH_FEWER[case]
    assert fewer < fit_module.STARTS_PER_KIND
    assert fit_cost(monkeypatch, case, fewer) > exhaustive_cost(case) * 1.005


@pytest.mark.parametrize("case", SHORT_SCREEN_MISSES)
def test_a_shorter_screen_misses_it_on_these_sets(monkeypatch, exhaustive_cost, case):
    assert fit_module.SCREEN_EVALUATIONS > 5
    short = fit_cost(monkeypatch, case, fit_module.STARTS_PER_KIND, delay=False, screen=5)
    assert short > exhaustive_cost(case, delay=False) * 1.005


# --- the J stage ----------------------------------------------------------------------------

def j_of(model, omega, F, coherence=None):
    return evaluate_model(model, omega, F, 1 / np.abs(F), coherence)["J"]


def best_reachable_j(monkeypatch, omega, F, order, delay, coherence=None):
    """J's stage from every output-error start refined fully (not the few of lowest cost)."""
    with monkeypatch.context() as patch:
        patch.setattr(fit_module, "STARTS_PER_KIND", None)
        patch.setattr(fit_module, "J_STARTS", 10 ** 6)
        patch.setattr(fit_module, "J_EVALUATIONS", fit_module.REFINE_EVALUATIONS)
        return j_of(fit_tf(omega, F, order, delay=delay, coherence=coherence), omega, F,
                    coherence)


#: Sweep-like points (10 % noise) on which the relative fit's J is 1.2-5 % above the best
#: reachable for the order (measured when J's stage was added).
J_CASES = (("roll", (0, 2), 0.015, 0.1, 2, (0, 2), False),
           ("pitch", (0, 2), 0.015, 0.1, 2, (0, 3), True),
           ("yaw", (0, 1), 0.015, 0.1, 2, (2, 3), False),
           ("yaw", (0, 1), 0.015, 0.1, 2, (2, 2), True))


@pytest.mark.parametrize("case", J_CASES, ids=lambda c: f"{c[0]} {c[5]} delay={c[6]}")
def test_the_j_stage_reaches_the_best_j_for_the_order(monkeypatch, case):
    axis, truth, delay_s, noise, seed, order, delay = case
    omega, F = sweep_like(axis, truth, delay_s, noise, seed)
    relative = j_of(fit_tf(omega, F, order, delay=delay, cost="relative"), omega, F)
    model = fit_tf(omega, F, order, delay=delay)
    best = best_reachable_j(monkeypatch, omega, F, order, delay)
    assert model.cost == "j" and model.stable
    assert relative > 1.01 * best                       # what the stage is for
    assert j_of(model, omega, F) <= 1.001 * best        # within 0.1 % of the best


@pytest.mark.parametrize("delay", [False, True], ids=["no delay", "delay"])
@pytest.mark.parametrize("stable", [True, False], ids=["log factors", "free coefficients"])
@pytest.mark.parametrize("order", [(0, 1), (0, 2), (1, 3), (2, 4)])
def test_the_j_stages_jacobian_matches_finite_differences(order, stable, delay):
    m, n = order
    rng, problem = random_problem(order, stable, delay, 7 * m + n)
    cost = fit_module._JCost(problem, rng.uniform(0.2, 1.0, N_POINTS))
    for _ in range(3):
        poles = random_poles(rng, n, stable, 1.0)
        theta = np.concatenate([poles, rng.uniform(0.5, 1.5, m + 1),
                                rng.uniform(0.0, 0.3, int(delay))])
        J = cost.jacobian(theta)
        J_fd = finite_difference_jacobian(cost.residuals, theta)
        assert J.shape == J_fd.shape == (2 * N_POINTS, n + m + 1 + delay)
        assert np.max(np.abs(J - J_fd)) <= 1e-6 * np.max(np.abs(J_fd))


def test_the_j_stage_minimises_the_j_the_table_reports():
    # Its residuals' sum of squares is the metric's J, coherence weights and all, at any model.
    omega, F = sweep_like("roll", (0, 2), 0.015, 0.1, 3)
    coherence = np.linspace(0.3, 1.0, N_POINTS)
    model = fit_tf(omega, F, (0, 3), delay=True, coherence=coherence)
    x, w0, Fn, g0, w = fit_module._normalised(omega, F, None)
    problem = fit_module._OutputError(x, Fn, 0, 3, w, True, True)
    cost = fit_module._JCost(problem, cifer_weight(coherence))
    den = model.den * w0 ** -np.arange(4.0)                  # back to scaled frequency
    num = model.num * w0 ** -(3.0 - np.arange(len(model.num) - 1, -1, -1)) / g0
    theta = np.concatenate([fit_module._roots_to_params(np.roots(den)), num, [model.delay_s * w0]])
    r = cost.residuals(theta)
    assert float(r @ r) == pytest.approx(j_of(model, omega, F, coherence), rel=1e-9)


def test_a_point_of_coherence_zero_does_not_move_a_j_fit():
    # CIFER's weight of coherence 0 is 0: an outlier measured in pure noise counts for
    # nothing under J; it moves a fit of the relative error (by 2.6 % here).
    omega, F = sweep_like("roll", (0, 2), 0.015, 0.01, 1)
    spoiled = F.copy()
    spoiled[7] *= 3.0 * np.exp(1j)
    coherence = np.ones(N_POINTS)
    coherence[7] = 0.0
    clean = fit_tf(omega, F, (0, 2), coherence=coherence)
    fitted = fit_tf(omega, spoiled, (0, 2), coherence=coherence)
    relative = fit_tf(omega, spoiled, (0, 2), cost="relative")
    keep = np.arange(N_POINTS) != 7
    moved = lambda m: np.max(np.abs(m.response(omega[keep]) / clean.response(omega[keep]) - 1))
    assert moved(fitted) < 1e-6
    assert moved(relative) > 0.01


def test_an_unknown_cost_is_refused():
    omega, F = sweep_like("roll", (0, 2), 0.015, 0.0, 1)
    with pytest.raises(InputError, match="unknown cost 'dB'; use one of j, relative"):
        fit_tf(omega, F, (0, 2), cost="dB")

# -- the refinement's solver ----------------------------------------------------------------

def test_the_solver_finds_a_minimum_inside_the_box_as_scipy_does():
    # Output-error problems at random starts: the solver reaches the cost scipy's trust-region
    # reflective solver reaches (to round-off), converged by its tolerances.
    import scipy.optimize

    x = np.logspace(-0.75, 0.75, N_POINTS)
    F = noisy(model_response([1.2, 0.5], [1, 0.8, 1.1], 0.2, x), 3, 0.02)
    problem = fit_module._OutputError(x, F, 1, 2, 1 / np.abs(F), True, True)
    lower, upper = (np.append(b, 0.0) for b in problem.bounds())
    upper[-1] = np.pi / x.max()
    rng = np.random.default_rng(5)
    for _ in range(5):
        x0 = np.append(rng.uniform(-1, 1, 2), rng.uniform(0, upper[-1]))
        got, r, done = fit_module._least_squares(problem.residuals, problem.jacobian, x0,
                                                 lower, upper, 2000)
        ref = scipy.optimize.least_squares(problem.residuals, x0, jac=problem.jacobian,
                                           bounds=(lower, upper), x_scale="jac",
                                           xtol=1e-15, ftol=1e-15, gtol=1e-15)
        assert done
        assert r @ r <= np.sum(ref.fun ** 2) * (1 + 1e-9)
        np.testing.assert_allclose(got, ref.x, rtol=1e-6, atol=1e-8)


def test_the_solver_stops_on_a_bound_the_minimum_lies_beyond():
    # min (x0 - 3)^2 + 10 (x1 + 2)^2 over [0, 1] x [-1, 1]: the corner (1, -1), each
    # parameter held on its bound, converged.
    def fun(p):
        return np.array([p[0] - 3.0, math.sqrt(10) * (p[1] + 2.0)])

    def jac(p):
        return np.array([[1.0, 0.0], [0.0, math.sqrt(10)]])

    got, r, done = fit_module._least_squares(fun, jac, np.array([0.5, 0.5]), np.array([0.0, -1.0]),
                                             np.array([1.0, 1.0]), 100)
    assert done and got.tolist() == [1.0, -1.0]
    assert r @ r == pytest.approx(4.0 + 10.0)


def rosenbrock(p):
    """Rosenbrock's valley as residuals, and their Jacobian."""
    return (np.array([10.0 * (p[1] - p[0] ** 2), 1.0 - p[0]]),
            np.array([[-20.0 * p[0], 10.0], [-1.0, 0.0]]))


@pytest.mark.parametrize("budget", [500, 5])
def test_the_solver_follows_a_curved_valley_to_its_end_or_says_it_did_not(budget):
    # From the classic start: the minimum (1, 1) to 1e-8; or, with too few evaluations,
    # not done, and somewhere finite.
    inf = np.full(2, np.inf)
    got, r, done = fit_module._least_squares(lambda p: rosenbrock(p)[0],
                                             lambda p: rosenbrock(p)[1],
                                             np.array([-1.2, 1.0]), -inf, inf, budget)
    assert done == (budget == 500) and np.all(np.isfinite(got))
    if done:
        np.testing.assert_allclose(got, [1.0, 1.0], atol=1e-8)


def test_the_solver_takes_a_jacobian_without_full_rank():
    # Two parameters only their sum matters to (a zero cancelling a pole does this to a fit):
    # the shortest step, no singular matrix.
    def fun(p):
        return np.array([p[0] + p[1] - 1.0, 2.0 * (p[0] + p[1] - 1.0)])

    def jac(p):
        return np.array([[1.0, 1.0], [2.0, 2.0]])

    inf = np.full(2, np.inf)
    got, r, done = fit_module._least_squares(fun, jac, np.array([3.0, -4.0]), -inf, inf, 50)
    assert done and r @ r < 1e-20 and got.sum() == pytest.approx(1.0)


def test_the_solver_stops_where_the_residuals_or_the_jacobian_are_not_finite():
    inf = np.full(2, np.inf)
    nan_r = (lambda p: np.array([np.nan, p[0]]), lambda p: np.eye(2))
    huge_j = (lambda p: np.array([p[0] - 1.0, p[1]]), lambda p: np.diag([1e200, 1e-200]))
    inf_j = (lambda p: np.array([p[0] - 1.0, p[1]]), lambda p: np.diag([np.inf, 1.0]))
    for fun, jac in (nan_r, huge_j, inf_j):
        with np.errstate(over="ignore", invalid="ignore"):
            got, r, done = fit_module._least_squares(fun, jac, np.array([3.0, 2.0]), -inf, inf, 50)
        assert done and got.shape == (2,)


def test_a_wide_band_gets_the_orders_its_rotors_and_sensor_need():
    from heliquad.host.acquire.sweep import TUNING_TOP_HZ, tuning_freqs_hz
    from heliquad.host.estimate.models import WIDE_BAND_ORDERS, default_orders

    # the paper's band: the paper's orders and the integrator structures only
    for axis in ("roll", "pitch", "yaw"):
        narrow = default_orders(axis, paper.BANDS_HZ[axis][1])
        assert narrow == default_orders(axis)
        assert set(WIDE_BAND_ORDERS) - set(narrow)
        # the tuning band: every wide-band order, each once, the paper's first
        freqs = tuning_freqs_hz(axis)
        assert freqs[0] == pytest.approx(paper.BANDS_HZ[axis][0])
        assert freqs[-1] == pytest.approx(TUNING_TOP_HZ)
        wide = default_orders(axis, freqs[-1])
        assert wide[:len(narrow)] == narrow and set(WIDE_BAND_ORDERS) <= set(wide)
        assert len(set(wide)) == len(wide)
