"""FitProblem's inner-loop path (vectors) agrees with its checked path (mappings)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import gonio
from gonio.fitting import Dataset, FitProblem
from gonio.geometry import in_plane_angles


def _normalised_minnaert_data() -> Dataset:
    geometry = in_plane_angles(np.repeat([30.0, 60.0], 9), np.tile(np.arange(-80.0, 81.0, 20.0), 2))
    value = gonio.brdf("minnaert", *geometry, rho=0.6, k=0.7)
    normal = gonio.brdf("minnaert", geometry[0], geometry[1], 0.0, geometry[1], rho=0.6, k=0.7)
    return Dataset(*geometry, value / normal, 0.01, quantity="normalised_radiance")


def test_vector_path_equals_mapping_path():
    """residuals/log_likelihood (unchecked model calls) match predict (checked calls)."""
    data = _normalised_minnaert_data()
    problem = FitProblem("minnaert", data)
    vector = np.array([0.5, 0.8])
    values = problem.values(vector)
    expected = (problem.predict(values) - data.value) / data.sigma
    # Identical arithmetic on both paths: equality to the last bit.
    np.testing.assert_array_equal(problem.residuals(vector), expected)
    chi2 = float(np.dot(expected, expected))
    log_l = -0.5 * chi2 - float(np.sum(np.log(data.sigma))) - 0.5 * data.n * math.log(2 * math.pi)
    assert problem.log_likelihood(vector) == pytest.approx(log_l, rel=1e-14)  # summation order only


@pytest.mark.parametrize("bad", [-0.5, math.nan])
def test_vector_path_rejects_out_of_range_values(bad):
    """A free model parameter outside its bounds raises ValueError naming it, as predict does."""
    problem = FitProblem("minnaert", _normalised_minnaert_data())
    vector = np.array([bad, 0.8])  # rho in [0, 1]
    with pytest.raises(ValueError, match="rho"):
        problem.residuals(vector)
    with pytest.raises(ValueError, match="rho"):
        problem.log_likelihood(vector)
    with pytest.raises(ValueError, match="rho"):
        problem.predict(problem.values(vector))


# ----------------------------------------------------------------------------- correlated errors
def _correlated_lambert(n=12, seed=3, common=0.02, independent=0.01):
    """Lambertian data with an error common to every point (a calibration) and one per point."""
    rng = np.random.default_rng(seed)
    tr = np.linspace(0.0, 70.0, n)
    truth = gonio.brdf("lambert", 30.0, 0.0, tr, 0.0, rho=0.5)
    covariance = np.outer(truth, truth) * common**2 + np.diag((independent * truth) ** 2)
    value = truth * (1 + common * rng.standard_normal()) + independent * truth * rng.standard_normal(n)
    return Dataset(30.0, 0.0, tr, 0.0, value, np.sqrt(np.diag(covariance)), covariance=covariance), truth


def test_a_diagonal_covariance_gives_the_independent_likelihood():
    data = _normalised_minnaert_data()
    same = Dataset(*data.geometry, data.value, data.sigma, quantity=data.quantity, covariance=np.diag(data.sigma**2))
    vector = np.array([0.5, 0.8])
    a, b = FitProblem("minnaert", data), FitProblem("minnaert", same)
    np.testing.assert_allclose(b.residuals(vector), a.residuals(vector), rtol=1e-12)
    assert b.log_likelihood(vector) == pytest.approx(a.log_likelihood(vector), rel=1e-12)


def test_generalised_least_squares_chi_square_and_likelihood():
    """chi^2 = r^T C^-1 r and log L = -chi^2/2 - log det(C)/2 - n/2 log(2 pi), checked against
    the dense formulas."""
    data, _ = _correlated_lambert()
    problem = FitProblem("lambert", data)
    values = {"rho": 0.49}
    r = problem.predict(values) - data.value
    chi2 = float(r @ np.linalg.solve(data.covariance, r))
    assert problem.chi_square(values) == pytest.approx(chi2, rel=1e-10)
    sign, log_det = np.linalg.slogdet(data.covariance)
    expected = -0.5 * chi2 - 0.5 * log_det - 0.5 * data.n * math.log(2 * math.pi)
    assert problem.log_likelihood(np.array([0.49])) == pytest.approx(expected, rel=1e-10)


def test_a_common_error_is_not_averaged_away():
    """With a 2 % error common to every point and 1 % per point, rho's standard error is
    about 2 %/sqrt(1) + 1 %/sqrt(12) in quadrature (~2.04 %), not the 0.6 % a fit treating
    the errors as independent would claim."""
    from gonio.fitting import fit

    data, _ = _correlated_lambert()
    correlated = fit(data, "lambert", mcmc=False).least_squares.stderr["rho"] / 0.5
    independent = fit(Dataset(*data.geometry, data.value, data.sigma), "lambert", mcmc=False).least_squares.stderr["rho"] / 0.5
    assert correlated == pytest.approx(math.hypot(0.02, 0.01 / math.sqrt(12)), rel=0.05)
    assert independent < 0.4 * correlated


def test_covariance_is_checked_and_survives_a_subset_and_json():
    data, _ = _correlated_lambert()
    with pytest.raises(ValueError, match="diagonal entry"):
        Dataset(*data.geometry, data.value, data.sigma * 2, covariance=data.covariance)
    with pytest.raises(ValueError, match="shape"):
        Dataset(*data.geometry, data.value, data.sigma, covariance=data.covariance[:3, :3])
    bad = data.covariance.copy()
    bad[0, 1] = bad[1, 0] = 10 * bad[0, 0]
    with pytest.raises(ValueError, match="positive definite"):
        Dataset(*data.geometry, data.value, data.sigma, covariance=bad)
    part = data.subset(np.arange(data.n) % 2 == 0)
    np.testing.assert_array_equal(part.covariance, data.covariance[::2, ::2])
    again = Dataset.from_dict(data.to_dict())
    np.testing.assert_array_equal(again.covariance, data.covariance)


def _batch_cases():
    from .synthetic import synthetic_dataset

    geometry = in_plane_angles(np.repeat([30.0, 60.0], 9), np.tile(np.linspace(-80, 80, 9), 2))
    brdf = synthetic_dataset("oren-nayar", {"rho": 0.9, "sigma": 30.0}, 0.01, geometry=geometry)
    normalised = synthetic_dataset("oren-nayar", {"rho": 0.9, "sigma": 30.0}, 0.01, geometry=geometry,
                                   quantity="normalised_radiance", relative=True)
    radiance = synthetic_dataset("oren-nayar", {"rho": 0.9, "sigma": 30.0, "scale": 2.0}, 0.01, geometry=geometry,
                                 quantity="radiance")
    n = radiance.n
    common = 0.3 * 0.01**2 * np.ones((n, n))
    covariance = np.diag(radiance.sigma**2 - np.diag(common)) + common
    correlated = Dataset(*radiance.geometry, radiance.value, radiance.sigma, quantity="radiance", covariance=covariance)
    apertures = Dataset(*brdf.geometry, brdf.value, brdf.sigma, metadata={"aperture_sr": [0.003, 0.0009]})
    return [
        ("oren-nayar", brdf, {"ir_weight": 1.0}, False),
        ("oren-nayar", brdf, {}, "absolute"),
        ("oren-nayar-qualitative", normalised, {}, "relative"),
        ("oren-nayar", radiance, {"ir_weight": 1.0}, False),
        ("oren-nayar", correlated, {"ir_weight": 1.0}, False),
        ("lambert", correlated, {}, "absolute"),
        ("oren-nayar-tabulated", apertures, {}, False),
        ("oren-nayar", apertures, {"ir_weight": 1.0}, "relative"),
        ("oren-nayar", correlated, {"ir_weight": 1.0}, "relative"),
    ]


def test_a_covariance_with_a_free_extra_noise_is_the_multivariate_normal():
    """The likelihood LAPACK factors once per walker (a covariance with rel_jitter) is the
    Gaussian density with the covariance plus the extra noise's variance on its diagonal."""
    from scipy.stats import multivariate_normal

    model, data, fixed, jitter = _batch_cases()[8]
    problem = FitProblem(model, data, fixed, jitter=jitter)
    vector = np.array([{"rho": 0.85, "sigma": 28.0, "scale": 2.1, "rel_jitter": 0.03}[n] for n in problem.free])
    values = problem.values(vector)
    predicted = problem.predict(values)
    covariance = data.covariance + np.diag((0.03 * predicted) ** 2)
    expected = multivariate_normal(predicted, covariance).logpdf(data.value)
    assert problem.log_likelihood(vector) == pytest.approx(expected, rel=1e-12)
    assert problem.log_likelihood_batch(vector[None])[0] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("case", range(9))
def test_batch_likelihood_equals_one_walker_at_a_time(case):
    """The ensemble's walkers in one evaluation (emcee vectorize=True) give the same
    log-likelihood as one call per walker: every quantity, extra-noise form, covariance
    and the aperture average."""
    model, data, fixed, jitter = _batch_cases()[case]
    problem = FitProblem(model, data, fixed, jitter=jitter)
    rng = np.random.default_rng(case)
    starts = {"rho": (0.5, 0.95), "sigma": (5.0, 45.0), "ir_weight": (0.2, 1.0), "scale": (1.5, 2.5),
              "jitter": (0.0, 0.02), "rel_jitter": (0.0, 0.05)}
    vectors = np.column_stack([rng.uniform(*starts[name], 7) for name in problem.free])
    one_by_one = np.array([problem.log_likelihood(v) for v in vectors])
    np.testing.assert_allclose(problem.log_likelihood_batch(vectors), one_by_one, rtol=1e-11, atol=1e-9)


@pytest.mark.parametrize("case", range(8))
def test_batch_chi_square_equals_the_whitened_residuals_one_vector_at_a_time(case):
    """The posterior predictive check's discrepancy of many posterior draws in one model
    evaluation equals the squared whitened residuals (the extra noise included) of each:
    every quantity, extra-noise form, covariance (with a free extra noise, one factor per
    row) and the aperture average."""
    model, data, fixed, jitter = _batch_cases()[case]
    problem = FitProblem(model, data, fixed, jitter=jitter)
    rng = np.random.default_rng(100 + case)
    starts = {"rho": (0.5, 0.95), "sigma": (5.0, 45.0), "ir_weight": (0.2, 1.0), "scale": (1.5, 2.5),
              "jitter": (0.0, 0.02), "rel_jitter": (0.0, 0.05)}
    vectors = np.column_stack([rng.uniform(*starts[name], 7) for name in problem.free])
    one_by_one = []
    for vector in vectors:
        values, predicted = problem._predict_vector(vector)
        extra = problem.extra_variance(values, predicted) if problem.jitter else 0.0
        z = problem.whiten(predicted - data.value, extra)[0]
        one_by_one.append(float(z @ z))
    np.testing.assert_allclose(problem.chi_square_batch(vectors), one_by_one, rtol=1e-10)
    assert problem.chi_square_batch(vectors[0]).shape == (1,)


def test_batch_posterior_rejects_walkers_outside_the_support_without_evaluating_them():
    from gonio.fitting.mcmc import LogPosterior, resolve_priors

    from .synthetic import synthetic_dataset

    data = synthetic_dataset("oren-nayar", {"rho": 0.9, "sigma": 30.0}, 0.01)
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0})
    posterior = LogPosterior(problem, resolve_priors(problem, {}))
    vectors = np.array([[0.9, 30.0], [1.2, 30.0], [0.9, -1.0], [0.8, 20.0]])
    batch = posterior.batch(vectors)
    assert np.isneginf(batch[1]) and np.isneginf(batch[2])
    np.testing.assert_allclose(batch[[0, 3]], [posterior(v) for v in vectors[[0, 3]]], rtol=1e-12)
    assert posterior.calls == 2 + 2


@pytest.mark.parametrize("case", [0, 3, 4, 5])
def test_linear_models_use_sufficient_statistics_with_the_same_likelihood(case):
    """Models linear in their coefficients (Oren-Nayar, Lambert; aperture-averaged or not;
    BRDF or radiance; with a covariance) evaluate the ensemble's likelihood from K x K
    statistics, equal to the one-by-one likelihood; not where the prediction is not linear
    (normalised radiance, an extra-noise term, the interpolated table)."""
    model, data, fixed, jitter = _batch_cases()[case]
    problem = FitProblem(model, data, fixed, jitter=False)
    assert problem._linear is not None
    rng = np.random.default_rng(case)
    starts = {"rho": (0.3, 1.0), "sigma": (0.0, 60.0), "ir_weight": (0.0, 1.0), "scale": (1.0, 3.0)}
    vectors = np.column_stack([rng.uniform(*starts[name], 9) for name in problem.free])
    one_by_one = np.array([problem.log_likelihood(v) for v in vectors])
    np.testing.assert_allclose(problem.log_likelihood_batch(vectors), one_by_one, rtol=1e-10, atol=1e-8)
    # a second ensemble far from the first one's expansion point: still equal
    far = vectors.copy()
    far[:, 0] = 0.05
    np.testing.assert_allclose(problem.log_likelihood_batch(far), [problem.log_likelihood(v) for v in far],
                               rtol=1e-10, atol=1e-8)


def test_aperture_averaged_linear_models_keep_the_linear_path():
    from .synthetic import synthetic_dataset

    geometry = in_plane_angles(np.repeat([30.0, 60.0], 9), np.tile(np.linspace(-80, 80, 9), 2))
    brdf = synthetic_dataset("oren-nayar", {"rho": 0.9, "sigma": 30.0}, 0.01, geometry=geometry)
    rig = Dataset(*brdf.geometry, brdf.value * 2.0, brdf.sigma * 2.0, quantity="radiance",
                  metadata={"aperture_sr": [0.003, 0.0009]})
    for model, fixed in (("oren-nayar", {"ir_weight": 1.0}), ("oren-nayar-qualitative", {}), ("lambert", {})):
        problem = FitProblem(model, rig, fixed)
        assert problem._linear is not None
        vectors = np.column_stack([np.linspace(lo, hi, 5) for lo, hi in
                                   [{"rho": (0.5, 0.95), "sigma": (5, 45), "scale": (1.5, 2.5)}[n] for n in problem.free]])
        np.testing.assert_allclose(problem.log_likelihood_batch(vectors),
                                   [problem.log_likelihood(v) for v in vectors], rtol=1e-10, atol=1e-8)
    for model, kwargs in (("oren-nayar-tabulated", {}), ("oren-nayar", {"jitter": "relative"})):
        assert FitProblem(model, rig, **kwargs)._linear is None


@pytest.mark.parametrize("case", [0, 1, 2, 4, 5, 7])
def test_batch_pointwise_likelihood_equals_one_walker_at_a_time(case):
    model, data, fixed, jitter = _batch_cases()[case]
    problem = FitProblem(model, data, fixed, jitter=jitter)
    rng = np.random.default_rng(case)
    starts = {"rho": (0.5, 0.95), "sigma": (5.0, 45.0), "ir_weight": (0.2, 1.0), "scale": (1.5, 2.5),
              "jitter": (0.0, 0.02), "rel_jitter": (0.0, 0.05)}
    vectors = np.column_stack([rng.uniform(*starts[name], 4) for name in problem.free])
    np.testing.assert_allclose(problem.pointwise_log_likelihood_batch(vectors),
                               [problem.pointwise_log_likelihood(v) for v in vectors], rtol=1e-11, atol=1e-10)


@pytest.mark.parametrize("case", [0, 4, 7, 8])
def test_the_batch_methods_in_blocks_of_rows_equal_one_block(case, monkeypatch):
    """Bounded memory for any number of values: with blocks of one or two rows the
    chi-square, pointwise log-likelihood and replicated data equal those of one block (the
    replicated data as a distribution: the same noise stream, drawn block by block)."""
    import gonio.fitting.problem as problem_module

    model, data, fixed, jitter = _batch_cases()[case]
    problem = FitProblem(model, data, fixed, jitter=jitter)
    rng = np.random.default_rng(case)
    starts = {"rho": (0.5, 0.95), "sigma": (5.0, 45.0), "ir_weight": (0.2, 1.0), "scale": (1.5, 2.5),
              "jitter": (0.0, 0.02), "rel_jitter": (0.0, 0.05)}
    vectors = np.column_stack([rng.uniform(*starts[name], 5) for name in problem.free])
    whole = (problem.chi_square_batch(vectors), problem.pointwise_log_likelihood_batch(vectors))
    monkeypatch.setattr(problem_module, "BATCH_ELEMENTS", 2 * data.n)
    assert len(problem._row_blocks(vectors)) == 3
    np.testing.assert_allclose(problem.chi_square_batch(vectors), whole[0], rtol=1e-12)
    np.testing.assert_allclose(problem.pointwise_log_likelihood_batch(vectors), whole[1], rtol=1e-12)
    replicated = problem.replicated_data(np.repeat(vectors[:1], 400, axis=0), np.random.default_rng(0))
    assert replicated.shape == (400, data.n)
    predicted = problem.predict(problem.values(vectors[0]))
    spread = np.std(replicated - predicted, axis=0)
    assert np.all(np.abs(np.mean(replicated - predicted, axis=0)) < 5 * spread / np.sqrt(400))


@pytest.mark.parametrize("quantity", ["brdf", "radiance"])
def test_grazing_points_keep_the_linear_path_point_by_point(quantity):
    """At theta_i = 75 deg eq 33's floor can act, so the linear form is not exact there.
    With independent errors the sufficient statistics still take the other points and the
    model itself those: the batch likelihood equals one walker at a time, and the problem
    stays vectorised. With correlated errors such a point turns the linear path off."""
    from .synthetic import synthetic_dataset

    geometry = in_plane_angles(np.repeat([30.0, 75.0], 9), np.tile(np.linspace(-80, 80, 9), 2))
    truth = {"rho": 0.9, "sigma": 45.0} | ({"scale": 2.0} if quantity == "radiance" else {})
    data = synthetic_dataset("oren-nayar", truth, 0.01, geometry=geometry, quantity=quantity)
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0})
    form = problem._fast.linear_form()
    assert not np.all(form.exact) and np.any(form.exact)  # the grazing points are not exact
    assert problem._linear is not None and problem._linear[2] is not None and problem.vectorised
    rng = np.random.default_rng(5)
    starts = {"rho": (0.2, 1.0), "sigma": (5.0, 80.0), "scale": (1.5, 2.5)}
    vectors = np.column_stack([rng.uniform(*starts[name], 40) for name in problem.free])
    np.testing.assert_allclose(problem.log_likelihood_batch(vectors), [problem.log_likelihood(v) for v in vectors],
                               rtol=1e-11, atol=1e-9)
    n = data.n
    covariance = np.diag(data.sigma**2) + 0.1 * np.outer(data.sigma, data.sigma) * (1 - np.eye(n))
    correlated = Dataset(*data.geometry, data.value, data.sigma, quantity=quantity, covariance=covariance)
    assert FitProblem("oren-nayar", correlated, {"ir_weight": 1.0})._linear is None
