"""Many least-squares fits at once (gonio.fitting.least_squares_many) against the single fit.

The batched fit is a faster path of the same least squares, so every comparison is with
:func:`gonio.fitting.fit_least_squares` on the same data (DESIGN.md: a faster path is tested
for equality against the reference path). Tolerances: both optimisers stop when a step
lowers chi-square by less than 1e-8 of itself; near the optimum chi-square rises by
(dx / stderr)^2, so with chi-square ~ N ~ 50 each stops within ~1e-3 stderr of the
minimum. Parameters are compared to 1e-2 stderr, chi-square to 1e-6 relative, and the
standard errors (forward-difference Jacobians at points that differ by that much) to 1e-3
relative.
"""
from __future__ import annotations

import numpy as np
import pytest

import gonio
import gonio.fitting.least_squares_batch as many_module
from gonio.fitting import Dataset, FitProblem, fit_least_squares, least_squares_many

#: 4 incidences x 12 views, in the plane (backward, forward) and across it [deg].
THETA_I = np.repeat([15.0, 35.0, 55.0, 75.0], 12)
THETA_R = np.tile(np.linspace(0.0, 82.0, 12), 4)
PHI_R = np.tile([0.0, 180.0, 90.0], 16)
GEOMETRY = (THETA_I, 0.0, THETA_R, PHI_R)


def noisy(model: str, truth: dict, noise: np.ndarray, seed: int, **fixed) -> np.ndarray:
    """Model values at GEOMETRY for parameter columns ``truth`` plus Gaussian noise."""
    clean = gonio.brdf(model, *GEOMETRY, **truth, **fixed)
    return clean + np.random.default_rng(seed).normal(0.0, 1.0, clean.shape) * noise


def single(model: str, value: np.ndarray, sigma, fixed=None):
    """The reference: gonio's single least-squares fit of one dataset."""
    return fit_least_squares(FitProblem(model, Dataset(*GEOMETRY, value, sigma), fixed=fixed))


def assert_equals_single(result, model: str, values: np.ndarray, sigma: np.ndarray, rows, fixed_of=lambda i: None):
    """Every fit in ``rows`` equals the single fit (tolerances: module docstring)."""
    for i in rows:
        reference = single(model, values[i], sigma[i], fixed_of(i))
        expected = np.array([reference.values[n] for n in result.free])
        errors = np.array([reference.stderr[n] for n in result.free])
        assert result.converged[i], result.reason[i]
        assert np.all(np.abs(result.values[i] - expected) <= 1e-2 * errors + 1e-12), (i, result.values[i], expected)
        np.testing.assert_allclose(result.stderr[i], errors, rtol=1e-3, err_msg=f"fit {i}")
        np.testing.assert_allclose(result.chi2[i], reference.chi2, rtol=1e-6, err_msg=f"fit {i}")
        assert result.dof == reference.dof


@pytest.mark.parametrize("model, fixed", [
    ("lambert", {}),
    ("oren-nayar-qualitative", {}),
    ("oren-nayar", {"ir_weight": 1.0}),
    ("oren-nayar", {"ir_weight": 0.0}),
    ("oren-nayar-tabulated", {}),
])
def test_each_fit_equals_the_single_least_squares_fit(model, fixed):
    rng = np.random.default_rng(7)
    m = 6
    truth = {"rho": rng.uniform(0.2, 0.9, (m, 1))}
    if model != "lambert":
        truth["sigma"] = rng.uniform(5.0, 60.0, (m, 1))
    sigma = rng.uniform(0.002, 0.006, (m, THETA_I.size))  # a different uncertainty for every value
    values = noisy(model, truth, sigma, seed=1, **fixed)
    result = least_squares_many(model, *GEOMETRY, values, sigma, fixed=fixed)
    assert result.free == tuple(n for n in gonio.models.get(model).param_names if n not in fixed)
    assert_equals_single(result, model, values, sigma, range(m), lambda i: fixed)
    # the fits recover the truth within their stated uncertainties (4 sd: 1e-4 per value)
    for k, name in enumerate(result.free):
        assert np.all(np.abs(result.values[:, k] - truth[name][:, 0]) < 4 * result.stderr[:, k])


def test_fixed_values_per_fit():
    # One ir_weight per pixel (shape (M,)): each fit equals the single fit with its own.
    weights = np.array([0.0, 0.5, 1.0])
    truth = {"rho": np.array([[0.4], [0.6], [0.8]]), "sigma": np.array([[10.0], [30.0], [50.0]])}
    sigma = np.full((3, THETA_I.size), 0.003)
    values = noisy("oren-nayar", dict(truth, ir_weight=weights[:, None]), sigma, seed=2)
    result = least_squares_many("oren-nayar", *GEOMETRY, values, sigma, fixed={"ir_weight": weights})
    assert_equals_single(result, "oren-nayar", values, sigma, range(3), lambda i: {"ir_weight": weights[i]})
    np.testing.assert_array_equal(result.value("ir_weight"), weights)


def test_upper_bound_of_a_projected_linear_parameter():
    # Data 5 % brighter than rho = 1 allows: rho sits at its upper bound, as in the single
    # fit (which reports it 'upper'); sigma is still fitted.
    sigma = np.full((2, THETA_I.size), 0.002)
    clean = gonio.brdf("oren-nayar-qualitative", *GEOMETRY, rho=1.0, sigma=30.0)
    values = 1.05 * clean + np.random.default_rng(3).normal(0.0, 0.002, sigma.shape)
    result = least_squares_many("oren-nayar-qualitative", *GEOMETRY, values, sigma)
    assert np.all(result.values[:, 0] == 1.0)
    np.testing.assert_array_equal(result.at_bound, [[1, 0], [1, 0]])
    assert single("oren-nayar-qualitative", values[0], sigma[0]).at_bound == {"rho": "upper"}
    assert_equals_single(result, "oren-nayar-qualitative", values, sigma, range(2))


def test_roughness_near_its_lower_bound_where_the_model_is_stationary():
    # Smooth samples (sigma 0 to 10 deg) fitted with oren-nayar from sigma = 20: the BRDF
    # changes as sigma^2 near 0, so a step clipped onto the bound would strand sigma at 0
    # (one of these fits does, were steps clipped). Every chi-square equals the single
    # fit's, rho agrees, and sigma is at the bound or within its uncertainty of it where
    # the single fit's is.
    rng = np.random.default_rng(0)
    rho = rng.uniform(0.3, 0.9, (40, 1))
    roughness = np.where(np.arange(40)[:, None] < 3, 0.0, rng.uniform(3.0, 10.0, (40, 1)))
    sigma = np.full((40, THETA_I.size), 0.002)
    values = noisy("oren-nayar", {"rho": rho, "sigma": roughness}, sigma, seed=4, ir_weight=1.0)
    result = least_squares_many("oren-nayar", *GEOMETRY, values, sigma, fixed={"ir_weight": 1.0})
    assert result.converged.all()
    for i in range(40):
        reference = single("oren-nayar", values[i], sigma[i], {"ir_weight": 1.0})
        np.testing.assert_allclose(result.chi2[i], reference.chi2, rtol=1e-6, err_msg=f"fit {i}")
        assert abs(result.values[i, 0] - reference.values["rho"]) < 1e-2 * reference.stderr["rho"], i
        if reference.at_bound.get("sigma") == "lower":
            assert result.at_bound[i, 1] == -1 or result.values[i, 1] < 1.0, i


def test_a_fit_that_does_not_converge_is_flagged_and_the_batch_goes_on():
    # Two datasets at the start values and one far from them; with the iteration limit the
    # easy ones need, the far one is flagged and the others are the unlimited fits.
    truth = {"rho": np.array([[0.8], [0.8], [0.2]]), "sigma": np.array([[20.0], [20.0], [75.0]])}
    sigma = np.full((3, THETA_I.size), 0.002)
    values = noisy("oren-nayar", truth, sigma, seed=5)
    free = least_squares_many("oren-nayar", *GEOMETRY, values, sigma, fixed={"ir_weight": 1.0})
    limit = int(free.iterations[:2].max())
    assert free.converged.all() and free.iterations[2] > limit  # the premise
    limited = least_squares_many("oren-nayar", *GEOMETRY, values, sigma, fixed={"ir_weight": 1.0},
                                 max_iterations=limit)
    np.testing.assert_array_equal(limited.converged, [True, True, False])
    assert limited.reason[2] == f"maximum of {limit} iterations reached" and limited.reason[0] == ""
    np.testing.assert_array_equal(limited.values[:2], free.values[:2])
    assert np.all(np.isfinite(limited.values))


def test_blocks_and_starts_do_not_change_the_answer(monkeypatch):
    # Fits run in blocks of BATCH_ELEMENTS values; blocks of one fit give the same numbers.
    rng = np.random.default_rng(8)
    truth = {"rho": rng.uniform(0.2, 0.9, (5, 1)), "sigma": rng.uniform(5.0, 60.0, (5, 1))}
    values = noisy("oren-nayar-qualitative", truth, 0.003, seed=6)
    whole = least_squares_many("oren-nayar-qualitative", *GEOMETRY, values, 0.003)
    for sigma in (np.full(THETA_I.size, 0.003), np.full((5, 1), 0.003), np.full(values.shape, 0.003)):
        np.testing.assert_array_equal(least_squares_many("oren-nayar-qualitative", *GEOMETRY, values, sigma).values,
                                      whole.values)  # any shape that broadcasts to (M, N)
    monkeypatch.setattr(many_module, "BATCH_ELEMENTS", THETA_I.size)
    blocks = least_squares_many("oren-nayar-qualitative", *GEOMETRY, values, 0.003)
    np.testing.assert_array_equal(blocks.values, whole.values)
    starts = least_squares_many("oren-nayar-qualitative", *GEOMETRY, values, 0.003, n_starts=4)
    assert np.all(starts.chi2 <= whole.chi2 * (1 + 1e-9))  # the best of four starts is no worse
    np.testing.assert_allclose(starts.values, whole.values, rtol=1e-4)


def test_without_uncertainties_the_scatter_sets_the_standard_errors():
    # sigma=None: unit weights, covariance times the reduced chi-square (curve_fit's
    # default), i.e. the single fit with sigma = 1 scaled by sqrt(redchi).
    truth = {"rho": np.array([[0.5]]), "sigma": np.array([[25.0]])}
    values = noisy("oren-nayar-qualitative", truth, 0.004, seed=9)
    result = least_squares_many("oren-nayar-qualitative", *GEOMETRY, values)
    reference = single("oren-nayar-qualitative", values[0], 1.0)
    assert result.noise_from_scatter
    expected = np.array([reference.stderr[n] for n in result.free]) * np.sqrt(reference.chi2 / reference.dof)
    np.testing.assert_allclose(result.stderr[0], expected, rtol=1e-3)
    assert 0.5 < result.redchi[0] / 0.004**2 < 2.0  # the scatter is the noise put in


def test_standard_errors_describe_the_scatter_of_repeated_fits():
    # 400 noisy copies of one sample: the spread of the fitted values matches the stated
    # standard errors. The sample standard deviation of 400 values scatters by 1/sqrt(800)
    # = 3.5 %, so 0.85..1.15 is a 4-sd band.
    m = 400
    sigma = np.full((m, THETA_I.size), 0.004)
    values = noisy("oren-nayar", {"rho": np.full((m, 1), 0.6), "sigma": np.full((m, 1), 30.0)}, sigma, seed=10,
                   ir_weight=1.0)
    result = least_squares_many("oren-nayar", *GEOMETRY, values, sigma, fixed={"ir_weight": 1.0})
    assert result.converged.all()
    ratio = result.values.std(axis=0, ddof=1) / np.median(result.stderr, axis=0)
    assert np.all((0.85 < ratio) & (ratio < 1.15)), ratio
    assert 0.9 < np.mean(result.redchi) < 1.1  # chi2/dof averages 1 (sd of the mean 0.01)


def test_no_degrees_of_freedom_without_uncertainties_gives_no_standard_error():
    result = least_squares_many("lambert", 30.0, 0.0, 10.0, 0.0, [[0.1], [0.2]])
    assert result.dof == 0 and np.all(np.isnan(result.stderr)) and np.all(np.isnan(result.redchi))
    np.testing.assert_allclose(result.values[:, 0], np.array([0.1, 0.2]) * np.pi)


def test_unknown_model_is_refused_with_a_suggestion():
    with pytest.raises(ValueError, match=r"unknown model 'oren-nayr'.*did you mean 'oren-nayar'"):
        least_squares_many("oren-nayr", *GEOMETRY, np.ones((2, THETA_I.size)), 0.01)


@pytest.mark.parametrize("values, sigma, match", [
    (np.ones((2, THETA_I.size + 1)), 0.01, r"values has 49 columns .* 48 geometries"),
    (np.ones(THETA_I.size), 0.01, r"shape \(M fits, N geometries\)"),
    (np.where(np.arange(2 * THETA_I.size).reshape(2, -1) == 50, np.nan, 0.1), 0.01,
     r"values\[1, 2\] = nan is not finite; 1 of 96"),
    (np.full((2, THETA_I.size), 0.1), np.zeros(THETA_I.size), "sigma"),
    (np.full((2, THETA_I.size), 0.1), np.ones(3), r"sigma has shape \(3,\)"),
])
def test_bad_data_is_refused_naming_what_is_wrong(values, sigma, match):
    with pytest.raises(ValueError, match=match):
        least_squares_many("lambert", *GEOMETRY, values, sigma)


@pytest.mark.parametrize("kwargs, match", [
    ({"fixed": {"roughness": 1.0}}, r"no parameter 'roughness'"),
    ({"fixed": {"ir_weight": 1.5}}, r"ir_weight = 1.5 .* outside its valid range"),
    ({"fixed": {"ir_weight": np.ones(3)}}, r"shape \(3,\); give one value or one per fit, \(2,\)"),
    ({"fixed": {"rho": 0.5, "sigma": 10.0, "ir_weight": 1.0}}, "nothing to fit"),
    ({"start": {"ir_weight": 0.5}, "fixed": {"ir_weight": 1.0}}, "not free parameters"),
    ({"start": {"sigma": -3.0}}, r"sigma = -3 deg is outside"),
])
def test_bad_parameters_are_refused_naming_them(kwargs, match):
    with pytest.raises(ValueError, match=match):
        least_squares_many("oren-nayar", *GEOMETRY, np.full((2, THETA_I.size), 0.1), 0.01, **kwargs)


def test_nan_angles_are_refused():
    with pytest.raises(ValueError, match=r"theta_r\[3\] = nan is not finite"):
        least_squares_many("lambert", THETA_I, 0.0, np.where(np.arange(THETA_I.size) == 3, np.nan, THETA_R), PHI_R,
                           np.full((1, THETA_I.size), 0.1), 0.01)
