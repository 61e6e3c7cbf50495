"""Forward model, weighted bounded least squares, covariance and degeneracy diagnostics."""
from __future__ import annotations

import math

import numpy as np
import pytest

import gonio
from gonio.fitting import Dataset, FitProblem, fit_least_squares

from .synthetic import brdf_reference, in_plane_geometry, synthetic_dataset


def test_fast_path_prediction_equals_the_reference_path():
    # One implementation, two paths (DESIGN.md): FitProblem uses Model.at, the
    # reference is gonio.brdf.  Equality to 1e-14 relative (identical arithmetic).
    geometry = in_plane_geometry()
    truth = dict(rho=0.5, rho_s=0.2, exponent=15.0)
    data = synthetic_dataset("lambert+phong", truth, 0.01, geometry=geometry)
    problem = FitProblem("lambert+phong", data)
    np.testing.assert_allclose(problem.predict(truth), brdf_reference("lambert+phong", geometry, **truth), rtol=1e-14)


def test_normalised_radiance_is_the_brdf_ratio_to_the_normal_view():
    # Oren & Nayar section 5 (Fig 16): L(theta_r)/L(0) = f_r(theta_r)/f_r(0) at fixed source.
    geometry = in_plane_geometry()
    truth = dict(rho=0.6, k=0.6)
    data = synthetic_dataset("minnaert", truth, 0.01, quantity="normalised_radiance", geometry=geometry)
    ti, pi_, tr, pr = geometry
    expected = gonio.brdf("minnaert", ti, pi_, tr, pr, **truth) / gonio.brdf("minnaert", ti, pi_, 0.0, pi_, **truth)
    np.testing.assert_allclose(FitProblem("minnaert", data).predict(truth), expected, rtol=1e-14)


def test_relative_radiance_is_scale_times_brdf_times_cos_theta_i():
    geometry = in_plane_geometry()
    data = synthetic_dataset("lambert", dict(rho=0.5, scale=3.0), 0.01, quantity="radiance", geometry=geometry)
    expected = 3.0 * 0.5 / np.pi * np.cos(np.radians(geometry[0]))
    np.testing.assert_allclose(FitProblem("lambert", data).predict(dict(rho=0.5, scale=3.0)), expected, rtol=1e-14)


def test_lambert_estimate_and_error_match_the_weighted_mean():
    # For f = rho/pi the weighted least-squares solution is pi x the weighted mean of the
    # data, with standard error pi / sqrt(sum 1/sigma^2) (exact, linear model).
    data = synthetic_dataset("lambert", dict(rho=0.4), 0.003, seed=3)
    weights = 1.0 / data.sigma**2
    fit = fit_least_squares(FitProblem("lambert", data))
    assert fit.values["rho"] == pytest.approx(np.pi * np.sum(weights * data.value) / weights.sum(), rel=1e-7)
    assert fit.stderr["rho"] == pytest.approx(np.pi / math.sqrt(weights.sum()), rel=1e-5)
    assert fit.dof == data.n - 1 and fit.chi2 == pytest.approx(fit.redchi * fit.dof)
    assert fit.warnings == []


@pytest.mark.parametrize(
    "model, truth",
    [
        ("lambert", dict(rho=0.7)),
        ("minnaert", dict(rho=0.6, k=0.7)),
        ("lambert+phong", dict(rho=0.5, rho_s=0.2, exponent=15.0)),
    ],
)
def test_recovers_known_parameters_within_four_standard_errors(model, truth):
    # Gaussian noise of 1 % of the values: the estimate lies within 4 standard errors of
    # the truth (a 6e-5 chance of failing per parameter for a correct fit).
    data = synthetic_dataset(model, truth, 0.01, seed=11, relative=True)
    fit = fit_least_squares(FitProblem(model, data))
    for name, value in truth.items():
        assert abs(fit.values[name] - value) < 4 * fit.stderr[name], (name, fit.values[name], fit.stderr[name])
    assert 0.5 < fit.redchi < 1.6  # chi2/dof of 48+ points: 1 +/- 0.2 (1 sd); 3 sd band


def test_fixed_parameters_stay_fixed_and_are_validated():
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.002)
    fit = fit_least_squares(FitProblem("minnaert", data, fixed={"k": 0.7}))
    assert fit.free == ("rho",) and fit.values["k"] == 0.7
    assert fit.values["rho"] == pytest.approx(0.6, abs=0.002)
    with pytest.raises(ValueError, match="parameter k = 1.5"):
        FitProblem("minnaert", data, fixed={"k": 1.5})
    with pytest.raises(ValueError, match="cannot fix 'sigma'"):
        FitProblem("minnaert", data, fixed={"sigma": 1.0})
    with pytest.raises(ValueError, match="nothing to fit"):
        FitProblem("minnaert", data, fixed={"k": 0.7, "rho": 0.5})


def test_albedo_of_normalised_data_is_reported_insensitive():
    # Normalised radiance divides out rho of a Lambertian surface: rho cannot be fitted.
    data = synthetic_dataset("lambert", dict(rho=0.7), 0.01, quantity="normalised_radiance")
    fit = fit_least_squares(FitProblem("lambert", data))
    assert fit.insensitive == ["rho"]
    assert math.isnan(fit.stderr["rho"])
    assert any("rho: the data do not depend on this parameter" in w and "normalised" in w for w in fit.warnings)


def test_albedo_and_free_scale_are_reported_degenerate():
    # Relative radiance: scale x rho is all the data determine (minnaert is linear in rho).
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7, scale=50.0), 0.01, quantity="radiance", relative=True)
    fit = fit_least_squares(FitProblem("minnaert", data))
    assert fit.degenerate == [["rho", "scale"]]
    assert math.isnan(fit.stderr["rho"]) and math.isnan(fit.stderr["scale"])
    assert fit.stderr["k"] == pytest.approx(fit.stderr["k"]) and math.isfinite(fit.stderr["k"])
    assert fit.values["k"] == pytest.approx(0.7, abs=5 * fit.stderr["k"])
    assert any("rho and scale are degenerate" in w for w in fit.warnings)
    # Fixing rho removes the degeneracy and recovers rho x scale.
    fixed = fit_least_squares(FitProblem("minnaert", data, fixed={"rho": 0.6}))
    assert fixed.degenerate == [] and fixed.values["scale"] == pytest.approx(50.0, rel=0.01)


def test_a_null_direction_along_one_parameter_is_not_called_a_combination():
    """A parameter whose column is a small multiple of another's (a mesoscale slope at 0,
    whose second-order effect looks like a little roughness) makes a null direction along
    itself alone: the warning names it as not determined, not as "a combination of them"."""
    from gonio.fitting.least_squares import _describe, jacobian_diagnostics

    rng = np.random.default_rng(0)
    jacobian = rng.normal(size=(40, 3))
    jacobian[:, 2] = 0.05 * jacobian[:, 0] + 1e-12 * rng.normal(size=40)
    covariance, insensitive, degenerate = jacobian_diagnostics(jacobian, ["a", "b", "c"], [1.0, 1.0, 1.0])
    assert insensitive == [] and degenerate == [["c"]]
    assert np.isnan(covariance[2, 2]) and np.isfinite(covariance[1, 1])
    problem = FitProblem("lambert", synthetic_dataset("lambert", dict(rho=0.5), 0.01))
    notes = _describe(problem, {"rho": 0.5}, {"rho": 0.01}, {}, [], [["rho"]], 10)
    assert notes == ["rho is not determined: at the best fit its effect is matched by small changes of the other "
                     "parameters; fix it (--fix rho=VALUE) or measure where it matters"]


def test_parameter_at_a_physical_bound_is_flagged():
    # Data that darken towards the horizon faster than Lambert (cos(theta_r)^0.3) would need
    # a Minnaert exponent k > 1 (Oren & Nayar section 1: k in [0, 1]); the fit stops at k = 1.
    geometry = in_plane_geometry()
    values = gonio.brdf("lambert", *geometry, rho=0.5) * np.cos(np.radians(geometry[2])) ** 0.3
    data = Dataset(*geometry, values, 0.002)
    fit = fit_least_squares(FitProblem("minnaert", data))
    assert fit.values["k"] == pytest.approx(1.0, abs=1e-12)
    assert fit.at_bound == {"k": "upper"}
    assert any("k = 1 lies at the upper bound" in w for w in fit.warnings)


def test_low_signal_is_reported_as_unconstrained():
    # Noise 100x the signal: the exponent's error exceeds its whole range [0, 1].
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 20.0, seed=5)
    fit = fit_least_squares(FitProblem("minnaert", data))
    assert any("not constrained by the data" in w for w in fit.warnings)


def test_jitter_is_estimated_when_uncertainties_are_too_small():
    # Real scatter 0.01, quoted uncertainties 0.002: the maximum-likelihood jitter is
    # sqrt(0.01^2 - 0.002^2) ~ 0.0098 within the sampling error of 51 points (~10 %).
    geometry = in_plane_geometry()
    exact = gonio.brdf("lambert", *geometry, rho=0.5)
    rng = np.random.default_rng(4)
    data = Dataset(*geometry, exact + 0.01 * rng.standard_normal(exact.shape), 0.002)
    fit = fit_least_squares(FitProblem("lambert", data, jitter=True))
    assert fit.values["jitter"] == pytest.approx(0.0098, rel=0.3)


def test_normal_view_reference_points_are_not_degrees_of_freedom():
    # Normalised radiance is exactly 1 at theta_r = 0 by construction (Oren & Nayar
    # section 5): those points cannot misfit, so they do not count in dof.
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.01, quantity="normalised_radiance", relative=True)
    normal = data.theta_r == 0.0
    exact = Dataset(*data.geometry, np.where(normal, 1.0, data.value), data.sigma, quantity="normalised_radiance")
    fit = fit_least_squares(FitProblem("minnaert", exact))
    assert fit.dof == data.n - int(normal.sum()) - 2


@pytest.mark.parametrize("model, truth", [
    ("torrance-sparrow", {"ks": 0.3, "sigma_s": 10.0, "n": 1.5}),
    ("wolff", {"rho": 0.8, "n": 1.5, "omega": 0.5}),
    ("wolff-oren-nayar", {"rho": 0.8, "sigma": 20.0, "n": 1.5}),
])
def test_a_refractive_index_is_fitted_from_starts_inside_its_one_sided_range(model, truth):
    """n lives on (1, inf): random starts scaled log-normally about 1.5 used to land below 1
    and stop the fit with "n = 0.42 outside (1, inf)" (an internal fault reported as bad
    input). Every start now lies inside, and the fit runs to the truth."""
    from gonio.fitting.least_squares import _start_points

    data = synthetic_dataset(model, truth, noise=1e-3, relative=True, seed=3)
    problem = FitProblem(model, data)
    points = _start_points(problem, None, 200, np.random.default_rng(0))
    for name in problem.free:
        lo, hi = problem.spec(name).bounds
        column = np.array([p[problem.free.index(name)] for p in points])
        assert np.all((column > lo) & (column < hi)), (name, column.min(), column.max())
    result = fit_least_squares(problem, n_starts=12, seed=1)
    assert result.values["n"] > 1.0
    assert result.chi2 / result.dof < 3.0


def test_forward_steps_stay_inside_the_bounds():
    """scipy's 2-point steps: sqrt(eps) max(1, |x|) with the sign of x, turned back at a
    bound, the larger room where neither side has the step."""
    from gonio.fitting.least_squares import _forward_steps

    eps = math.sqrt(np.finfo(float).eps)
    x = np.array([0.5, -3.0, 1.0, 0.0])
    lower = np.array([0.0, -10.0, 0.0, 0.0])
    upper = np.array([1.0, 10.0, 1.0, 1e-9])
    steps = _forward_steps(x, lower, upper)
    assert steps[0] == pytest.approx(eps) and steps[1] == pytest.approx(-3.0 * eps)
    assert steps[2] == pytest.approx(-eps)  # at the upper bound: backwards
    assert steps[3] == 1e-9  # no room for the step on either side: the larger room
    assert np.all((x + steps >= lower) & (x + steps <= upper))


@pytest.mark.parametrize("correlated", [False, True])
def test_batched_residuals_equal_the_one_by_one_values(correlated):
    data = synthetic_dataset("oren-nayar", {"rho": 0.8, "sigma": 25.0}, 0.01, seed=3)
    if correlated:
        covariance = 0.7 * np.diag(data.sigma**2) + 0.3 * np.outer(data.sigma, data.sigma)
        data = Dataset(data.theta_i, data.phi_i, data.theta_r, data.phi_r, data.value, data.sigma,
                       covariance=covariance)
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0})
    vectors = np.array([[0.8, 25.0], [0.7, 10.0], [0.9, 40.0]])
    rows = problem.residuals_batch(vectors)
    for vector, row in zip(vectors, rows):
        np.testing.assert_allclose(row, problem.residuals(vector), rtol=1e-10, atol=1e-12)


def test_the_batched_jacobian_reaches_the_optimum_scipy_s_reaches():
    """The least squares' Jacobian in one batch gives the optimum, errors and chi-square of
    scipy's own 2-point differences (independent and correlated data, a Gaussian prior)."""
    import scipy.optimize

    from gonio.fitting.priors import Normal

    data = synthetic_dataset("oren-nayar", {"rho": 0.8, "sigma": 25.0}, 0.01, seed=5)
    covariance = 0.8 * np.diag(data.sigma**2) + 0.2 * np.outer(data.sigma, data.sigma)
    correlated = Dataset(data.theta_i, data.phi_i, data.theta_r, data.phi_r, data.value, data.sigma,
                         covariance=covariance)
    for dataset in (data, correlated):
        problem = FitProblem("oren-nayar", dataset, {"ir_weight": 1.0})
        priors = {"rho": Normal(0.8, 0.05)}
        batched = fit_least_squares(problem, priors=priors)
        real = scipy.optimize.least_squares
        try:
            scipy.optimize.least_squares = lambda *a, **k: real(*a, **{**k, "jac": "2-point"})
            reference = fit_least_squares(problem, priors=priors)
        finally:
            scipy.optimize.least_squares = real
        for name in problem.free:
            assert batched.values[name] == pytest.approx(reference.values[name], abs=1e-4 * reference.stderr[name])
            assert batched.stderr[name] == pytest.approx(reference.stderr[name], rel=1e-4)
        assert batched.chi2 == pytest.approx(reference.chi2, rel=1e-8)


def test_a_prior_narrower_than_the_physical_range_bounds_the_optimum():
    """Oren-Nayar fitted to Lambertian data with ``sigma ~ uniform(10, 45)``: the optimum
    is sought where the prior has mass, as the sampler's posterior is (it had come out at
    sigma 0.95 deg, a mode the posterior excludes), and on the prior's edge here."""
    from gonio.fitting.priors import Uniform

    data = synthetic_dataset("lambert", {"rho": 0.8}, noise=0.003, seed=0)
    problem = FitProblem("oren-nayar-tabulated", data)
    free = fit_least_squares(problem)
    assert free.values["sigma"] < 5.0
    bounded = fit_least_squares(problem, priors={"sigma": Uniform(10.0, 45.0)})
    assert 10.0 <= bounded.values["sigma"] <= 45.0
    assert bounded.values["sigma"] == pytest.approx(10.0, abs=0.01)
    assert bounded.chi2 > free.chi2


def test_a_prior_outside_the_physical_range_is_refused_by_name():
    from gonio.fitting.priors import Uniform

    data = synthetic_dataset("lambert", {"rho": 0.8}, noise=0.003, seed=0)
    with pytest.raises(ValueError, match="prior of sigma.*physical range"):
        fit_least_squares(FitProblem("oren-nayar-tabulated", data), priors={"sigma": Uniform(100.0, 120.0)})
