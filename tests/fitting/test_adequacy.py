"""Goodness of fit, the verdict, the extra-noise forms, one likelihood for selection, and the
convergence diagnostics: every fit says when its model cannot explain the data."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gonio.cli import main
from gonio.fitting import ConvergenceWarning, Dataset, FitResult, compare_models, fit
from gonio.fitting.adequacy import ALPHA, assess, chi2_pvalue
from gonio.fitting.least_squares import fit_least_squares
from gonio.fitting.problem import FitProblem, predict_quantity
from gonio.fitting.results import EXIT_INADEQUATE, EXIT_NOT_CONVERGED
from gonio.fitting.mcmc import resolve_priors
from gonio.fitting.selection import laplace_log_evidence

from .synthetic import in_plane_geometry, synthetic_dataset

QUICK = dict(n_walkers=16, max_steps=6000, rhat_limit=1.05)


def _exact_plaster(noise: float = 1e-3, seed: int = 3, sigma: float = 30.0) -> Dataset:
    """Data made by the exact V-cavity model (not by any closed form fitted to it)."""
    geometry = in_plane_geometry(views=np.arange(-70.0, 71.0, 10.0))
    exact = predict_quantity("oren-nayar-exact", "brdf", *geometry, {"rho": 0.9, "sigma": sigma})
    rng = np.random.default_rng(seed)
    return Dataset(*geometry, exact + noise * rng.standard_normal(exact.shape), np.full(exact.shape, noise),
                   label="exact V-cavity plaster")


def test_chi2_pvalue_is_scipy_stats_chi2_survival_function():
    # chi2_pvalue calls scipy.special.chdtrc to spare a least-squares fit the import of
    # scipy.stats: the same function, so equal to rounding (1e-13 relative) over the
    # range of chi-square and degrees of freedom a fit meets, tails included.
    from scipy import stats

    for dof in (1, 2, 7, 88, 1000):
        for chi2 in (0.01, 0.5 * dof, dof, 2.0 * dof + 10.0, 10.0 * dof + 100.0):
            assert chi2_pvalue(chi2, dof) == pytest.approx(float(stats.chi2.sf(chi2, dof)), rel=1e-13, abs=0.0)


def test_chi2_pvalue_matches_the_distribution():
    assert chi2_pvalue(10.0, 10) == pytest.approx(0.4405, abs=1e-4)
    assert chi2_pvalue(200.0, 10) < 1e-30
    assert math.isnan(chi2_pvalue(3.0, 0))


def test_the_true_model_is_adequate():
    data = synthetic_dataset("oren-nayar", dict(rho=0.8, sigma=20.0, ir_weight=1.0), 0.002, seed=5)
    result = fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, seed=1, **QUICK)
    a = result.adequacy
    assert a.adequate and a.chi2_p > ALPHA and a.ppc_p > ALPHA
    assert result.summary().splitlines()[0].startswith("model adequate")
    assert result.exit_code() == 0


def test_the_approximation_fitted_to_the_exact_model_is_flagged_inadequate(tmp_path):
    """Eq 33-35 fitted to the exact model with 0.1 % noise: it misses sigma and says so."""
    data = _exact_plaster()
    result = fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False)
    assert result.least_squares.redchi > 10
    assert result.adequate is False and result.exit_code() == EXIT_INADEQUATE
    assert result.summary().splitlines()[0].startswith("MODEL INADEQUATE")
    assert result.flags[0].startswith("MODEL INADEQUATE")
    result.save(tmp_path / "fit")
    saved = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert saved["adequacy"]["adequate"] is False and saved["adequacy"]["chi2_p"] < ALPHA
    assert FitResult.load(tmp_path / "fit").adequate is False


def test_an_extra_noise_term_cannot_swallow_the_misfit():
    """With jitter the chi-square p-value is fine by construction; the jitter, much larger
    than the stated uncertainties, still marks the model inadequate."""
    data = _exact_plaster()
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0}, jitter=True)
    least_squares = fit_least_squares(problem)
    verdict = assess(problem, least_squares)
    assert verdict.chi2_p > ALPHA
    assert verdict.extra_noise_ratio > 1 and not verdict.adequate
    assert "extra noise" in verdict.headline()


def test_relative_extra_noise_is_recovered():
    """Stated uncertainties of 0.1 % with 3 % multiplicative scatter: rel_jitter ~ 0.03."""
    clean = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 1e-300)
    rng = np.random.default_rng(11)
    noisy = clean.value * (1 + 0.03 * rng.standard_normal(clean.n))
    data = Dataset(*clean.geometry, noisy, 0.001 * np.abs(clean.value))
    result = fit(data, "minnaert", jitter="relative", seed=2, **QUICK)
    assert result.jitter == "relative" and "rel_jitter" in result.free
    low, high = result.posterior["p2_5"]["rel_jitter"], result.posterior["p97_5"]["rel_jitter"]
    assert low < 0.03 < high and high < 0.05
    problem = result.problem()
    total = problem.total_sigma(result.best_values())
    assert np.corrcoef(total, np.abs(clean.value))[0, 1] > 0.99  # grows with the prediction


def test_comparison_never_chooses_a_model_that_fails_the_goodness_of_fit_test():
    data = _exact_plaster(noise=2e-3)
    comparison = compare_models(data, ["lambert", ("oren-nayar", {"ir_weight": 1.0}), "oren-nayar-tabulated"])
    rows = {row["label"]: row for row in comparison.rows}
    assert not rows["lambert"]["adequate"] and not rows["oren-nayar (ir_weight=1)"]["adequate"]
    assert comparison.chosen == "oren-nayar-tabulated" and comparison.chosen_adequate
    assert "INADEQUATE" in comparison.summary()
    only_bad = compare_models(data, ["lambert", ("oren-nayar", {"ir_weight": 1.0})])
    assert not only_bad.chosen_adequate and only_bad.reason.startswith("NO candidate")


def test_evidence_is_finite_for_models_linear_in_rho_on_relative_radiance():
    """rho x scale is exactly degenerate without a calibration prior; the priors bound it."""
    data = synthetic_dataset("lambert", dict(rho=0.5, scale=200.0), 0.5, seed=4, quantity="radiance")
    for name in ("lambert", "oren-nayar-qualitative"):
        problem = FitProblem(name, data)
        least_squares = fit_least_squares(problem)
        priors = resolve_priors(problem, least_squares.values)
        assert math.isfinite(laplace_log_evidence(problem, least_squares, priors)), name


def test_evidence_of_the_degenerate_pair_matches_direct_integration():
    """Lambert on relative radiance: ln Z over (rho, scale) by quadrature equals the
    Laplace value over their product (the likelihood is Gaussian in the product)."""
    from scipy.integrate import quad

    data = synthetic_dataset("lambert", dict(rho=0.5, scale=200.0), 0.5, seed=4, quantity="radiance")
    problem = FitProblem("lambert", data)
    least_squares = fit_least_squares(problem)
    priors = resolve_priors(problem, least_squares.values)
    product = least_squares.values["rho"] * least_squares.values["scale"]
    peak = least_squares.log_likelihood

    def over_scale(rho: float) -> float:
        centre = product / rho
        density = lambda s: math.exp(problem.log_likelihood(np.array([rho, s])) - peak  # noqa: E731
                                     + priors["scale"].logpdf(s))
        return quad(density, 0.98 * centre, 1.02 * centre, points=[centre], epsabs=0, epsrel=1e-9)[0]

    total = quad(lambda r: over_scale(r) * math.exp(priors["rho"].logpdf(r)), 1e-6, 1.0, limit=200, epsrel=1e-8)[0]
    assert laplace_log_evidence(problem, least_squares, priors) == pytest.approx(peak + math.log(total), abs=1e-3)


def test_a_calibration_prior_on_scale_keeps_the_pair_out_of_the_product_form():
    """Oren-Nayar fitted to a Lambertian sample's radiance, sigma at its bound 0 (its
    covariance undefined), with a calibration prior on ``scale`` 0.03 % wide: the prior
    determines rho and scale, so the evidence is Laplace's over both (with the quadrature
    over sigma), not the product form, whose induced prior across so narrow a prior came out
    20 ln units low. Checked against sequential Monte Carlo."""
    from gonio.fitting import Normal
    from gonio.fitting.evidence import scale_degenerate_factor, tempered_evidence

    data = synthetic_dataset("lambert", dict(rho=0.5, scale=200.0), 0.002, seed=4, quantity="radiance",
                             relative=True)
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0})
    calibration = {"scale": Normal(200.0, 0.06, 0.0, math.inf)}
    least_squares = fit_least_squares(problem, priors=calibration)
    priors = resolve_priors(problem, least_squares.values, calibration)
    assert least_squares.values["sigma"] < 1e-6 and not np.all(np.isfinite(least_squares.covariance))
    assert scale_degenerate_factor(problem, least_squares) == "rho"  # the likelihood alone
    assert scale_degenerate_factor(problem, least_squares, priors) is None
    sampled = tempered_evidence(problem, priors)
    assert laplace_log_evidence(problem, least_squares, priors) == pytest.approx(
        sampled.log_evidence, abs=3 * sampled.error + 0.1)


def test_comparison_uses_the_fits_extra_noise():
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.003, seed=8)
    plain = compare_models(data, ["lambert", "minnaert"])
    noisy = compare_models(data, ["lambert", "minnaert"], jitter=True)
    assert all("jitter" not in row["values"] for row in plain.rows)
    assert all("jitter" in row["values"] for row in noisy.rows)
    assert all(math.isfinite(row["log_evidence"]) for row in noisy.rows)
    assert noisy.chosen == "lambert"


def test_rhat_and_ess_are_reported_and_required_for_convergence(tmp_path):
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.005, seed=2)
    result = fit(data, "minnaert", seed=0, n_walkers=16, max_steps=8000)
    d = result.mcmc.diagnostics
    assert set(d) == {"rho", "k"} and result.converged
    assert all(v["r_hat"] < 1.01 and v["ess_bulk"] > 400 and v["ess_tail"] > 400 for v in d.values())
    assert "R-hat" in result.summary() and "ESS bulk" in result.summary()
    with pytest.warns(ConvergenceWarning):
        short = fit(data, "minnaert", seed=0, n_walkers=8, max_steps=300)
    assert short.converged is False and short.exit_code() == EXIT_NOT_CONVERGED


def test_posterior_exports_to_arviz_and_offers_psis_loo(tmp_path):
    import arviz as az

    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.005, seed=2)
    result = fit(data, "minnaert", seed=0, **QUICK)
    result.save(tmp_path / "fit")
    idata = az.from_netcdf(tmp_path / "fit" / "posterior.nc")
    m = result.mcmc
    from gonio.fitting.results import INFERENCE_DRAWS

    # thinned further where the chain holds more than INFERENCE_DRAWS draws
    thin = max(m.thin, math.ceil((m.n_steps - m.burn_in) / (INFERENCE_DRAWS // m.n_walkers)))
    kept = m.chain[m.burn_in :: thin]
    assert kept.size // 2 <= INFERENCE_DRAWS
    assert idata.posterior["rho"].shape == (m.n_walkers, kept.shape[0])
    np.testing.assert_allclose(idata.posterior["k"].values.T, kept[:, :, 1])
    assert idata.log_likelihood["y"].shape[-1] == data.n
    loo = result.loo()
    # for independent Gaussian errors, elpd_loo is close to the log-likelihood at the optimum
    # minus the number of parameters (the effective number p_loo ~ 2)
    assert loo.p_loo == pytest.approx(2.0, abs=1.0)
    assert float(np.max(loo.pareto_k)) < 0.7


def test_psis_loo_prefers_the_true_model():
    from gonio.fitting import compare_loo
    from gonio.fitting.selection import loo_summary

    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.005, seed=2)
    fits = {name: fit(data, name, seed=0, **QUICK) for name in ("lambert", "minnaert")}
    table = compare_loo(fits)
    assert list(table.index) == ["minnaert", "lambert"]
    assert table.loc["lambert", "elpd_diff"] > 2 * table.loc["lambert", "dse"]
    assert "minnaert" in loo_summary(table).splitlines()[2]
    with pytest.raises(ValueError, match="without MCMC"):
        compare_loo({"a": fits["lambert"], "b": fit(data, "lambert", mcmc=False)})


@pytest.mark.slow
def test_no_walker_is_stuck_on_lambertian_rig_data(tmp_path):
    """Oren-Nayar with an extra-noise term on a Lambertian sample measured by the emulated
    rig: every walker samples the same posterior (once two of 32 started 100 times too
    high in jitter and stayed at sigma 89.5 deg while the result said converged)."""
    from gonio import acquisition, protocols
    from gonio.cli.run import emulated_rig
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    text = (root / "protocols" / "oren-nayar-fig16-plaster.toml").read_text().replace("step = 5", "step = 10")
    with emulated_rig("lambert:rho=0.8", 4, name="stuck-walkers", realism="ideal") as (rig, emulator, change, meta):
        acquisition.run_protocol(protocols.loads(text), rig, tmp_path / "rec", metadata=meta,
                                 clock=emulator.control.now, change_sample=lambda which: change(which, 0.99))
    dataset, priors = acquisition.reduce_recording(tmp_path / "rec").fit_inputs()
    result = fit(dataset, "oren-nayar", fixed={"ir_weight": 1.0}, priors=priors, jitter=True, seed=0, n_walkers=32)  # the 32 walkers of the report
    assert result.converged
    m = result.mcmc
    sigma = m.chain[m.burn_in :, :, list(result.free).index("sigma")]
    per_walker = np.median(sigma, axis=0)
    assert per_walker.max() < 20.0, np.round(per_walker, 1)  # no walker far out at large sigma
    assert result.posterior["p97_5"]["sigma"] < 20.0
    assert m.diagnostics["sigma"]["r_hat"] < 1.01


def test_cli_fit_exit_status_says_inadequate(tmp_path, capsys):
    path = _exact_plaster().to_csv(tmp_path / "plaster.csv")
    code = main(["fit", str(path), "--model", "oren-nayar", "--fix", "ir_weight=1", "--no-mcmc", "--quiet"])
    assert code == EXIT_INADEQUATE
    captured = capsys.readouterr()
    assert captured.out.splitlines()[0].startswith("MODEL INADEQUATE")
    assert "MODEL INADEQUATE" in captured.err
    assert main(["fit", str(path), "--model", "lambert", "--model", "oren-nayar", "--fix", "ir_weight=1"]) == \
        EXIT_INADEQUATE
    assert main(["fit", str(path), "--model", "oren-nayar-tabulated", "--no-mcmc", "--quiet",
                 "--out", str(tmp_path / "table")]) == 0


def test_truncation_mass_of_gaussians_cut_by_bounds():
    from gonio.fitting.evidence import _log_mass_inside

    assert _log_mass_inside(np.array([1.0]), np.array([[0.01]]), [(0.0, 1.0)]) == pytest.approx(math.log(0.5))
    r = 0.55
    covariance = np.array([[1.0, r], [r, 1.0]]) * 1e-4
    corner = _log_mass_inside(np.array([1.0, 1.0]), covariance, [(0.0, 1.0), (0.0, 1.0)])
    assert corner == pytest.approx(math.log(0.25 + math.asin(r) / (2 * math.pi)), abs=1e-4)
    assert _log_mass_inside(np.array([0.5]), np.array([[1e-4]]), [(0.0, 1.0)]) == 0.0  # far from both bounds


def test_evidence_at_the_stationary_sigma_0_matches_quadrature():
    """Oren-Nayar on Lambertian data with its optimum on sigma = 0, where the BRDF depends
    on sigma^2 and the curvature vanishes: Laplace's formula is 1.8 too high; with the
    truncation and profile corrections it matches a 2-D quadrature."""
    from gonio.fitting.evidence import laplace_evidence
    from gonio.geometry import in_plane_angles

    views = np.arange(-80.0, 81.0, 5.0)
    geometry = in_plane_angles(np.repeat([30.0, 45.0, 60.0], views.size), np.tile(views, 3))
    exact = predict_quantity("lambert", "brdf", *geometry, {"rho": 0.5})
    sigma = 0.01 * exact
    data = Dataset(*geometry, exact + sigma * np.random.default_rng(100).standard_normal(exact.size), sigma)
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0})
    least_squares = fit_least_squares(problem)
    priors = resolve_priors(problem, least_squares.values)
    assert least_squares.values["sigma"] < 1e-6
    evidence = laplace_evidence(problem, least_squares, priors)
    rho0, rho_sd = least_squares.values["rho"], least_squares.stderr["rho"]
    rhos = np.linspace(rho0 - 8 * rho_sd, rho0 + 8 * rho_sd, 161)
    sigmas = np.linspace(0.0, 4.0, 161)
    log_post = np.array([[problem.log_likelihood(np.array([r, s])) + priors["rho"].logpdf(r)
                          + priors["sigma"].logpdf(s) for s in sigmas] for r in rhos])
    peak = log_post.max()
    assert log_post[:, -1].max() < peak - 20  # the grid holds the whole posterior
    quadrature = peak + math.log(np.trapezoid(np.trapezoid(np.exp(log_post - peak), sigmas, axis=1), rhos))
    assert evidence.raw - quadrature > 1.0
    assert evidence.log_evidence == pytest.approx(quadrature, abs=0.02)


def test_an_indefinite_curvature_gives_an_undefined_evidence_not_an_error():
    """A least-squares optimum whose covariance is not positive definite (a parameter
    stalled on a bound where the posterior rises away from it; seen with the Oren-Nayar +
    Torrance-Sparrow candidate on Lambertian rig data) has no Laplace approximation: the
    evidence is NaN (the comparison then samples it, gonio.fitting.evidence.tempered_evidence), never a math domain error."""
    import dataclasses

    from gonio.fitting.evidence import laplace_evidence

    data = _exact_plaster()
    problem = FitProblem("oren-nayar-qualitative", data)
    least_squares = fit_least_squares(problem)
    priors = resolve_priors(problem, least_squares.values)
    stalled = dataclasses.replace(least_squares, values=dict(least_squares.values, sigma=1e-7),
                                  covariance=np.array([[-1e-6, 0.0], [0.0, -4.0]]))
    assert math.isnan(laplace_evidence(problem, stalled, priors).log_evidence)


def test_a_profile_above_the_mode_gives_an_undefined_evidence_not_an_overflow():
    """Where the profile log posterior of a parameter near a bound rises above the least-
    squares point (a local optimum: seen with the Oren-Nayar + Torrance-Sparrow candidate
    stalled at ks = 1e-10 on rig data of the exact model, the profile 174 higher at
    ks = 3e-7), that point is not the posterior's maximum and Laplace's approximation
    around it does not exist: the evidence is NaN (the comparison samples it instead),
    never an OverflowError from exp(profile)."""
    import dataclasses

    from gonio.fitting.evidence import laplace_evidence

    data = _exact_plaster()
    problem = FitProblem("oren-nayar-qualitative", data)
    least_squares = fit_least_squares(problem)
    priors = resolve_priors(problem, least_squares.values)
    # sigma moved next to its bound with rho kept at the rough optimum: re-optimising rho
    # along the sigma profile gains far more than MODE_RISE (and than exp() can hold)
    stalled = dataclasses.replace(least_squares, values=dict(least_squares.values, sigma=1e-3))
    peak = problem.log_likelihood(np.array([stalled.values[n] for n in problem.free])) + sum(
        priors[n].logpdf(stalled.values[n]) for n in problem.free)
    lambertian = fit_least_squares(FitProblem("oren-nayar-qualitative", data, {"sigma": 1e-3}))
    assert lambertian.log_likelihood + priors["rho"].logpdf(lambertian.values["rho"]) + priors["sigma"].logpdf(
        1e-3) - peak > 710  # the rise exp() would overflow on
    undefined = laplace_evidence(problem, stalled, priors)
    assert math.isnan(undefined.log_evidence)
    # it carries the point the profile found, higher than the stalled one
    higher = np.array([undefined.higher_point[n] for n in problem.free])
    assert problem.log_likelihood(higher) + sum(priors[n].logpdf(undefined.higher_point[n]) for n in problem.free) \
        > peak + 1.0
    # the true optimum's evidence is still defined (the check does not fire at a real mode)
    assert math.isfinite(laplace_evidence(problem, least_squares, priors).log_evidence)


def test_a_comparison_goes_on_from_where_a_profile_found_the_posterior_higher(monkeypatch):
    """A candidate whose least squares stopped short of the mode (sigma left at its bound
    on data of sigma = 8 deg, which it still passes) is restarted from the profile's higher
    point: its row holds the real optimum and a finite Laplace evidence, flagged, not a
    sampled one."""
    import dataclasses

    import gonio.fitting.least_squares as least_squares_module

    data = synthetic_dataset("oren-nayar-qualitative", {"rho": 0.8, "sigma": 8.0}, noise=0.02, seed=2)
    real = least_squares_module.fit_least_squares
    calls = []

    def stalls_first(problem, *args, **kwargs):
        result = real(problem, *args, **kwargs)
        calls.append(kwargs.get("start"))
        if len(calls) == 1:  # the comparison's own fit: stopped next to sigma's bound
            return dataclasses.replace(result, values=dict(result.values, sigma=1e-3))
        return result

    monkeypatch.setattr(least_squares_module, "fit_least_squares", stalls_first)
    comparison = compare_models(data, ["oren-nayar-qualitative"])
    row = comparison.row("oren-nayar-qualitative")
    truth = real(FitProblem("oren-nayar-qualitative", data)).values
    assert row["values"]["sigma"] == pytest.approx(truth["sigma"], rel=1e-3)
    assert row["evidence_method"] == "laplace" and math.isfinite(row["log_evidence"])
    assert any("restarted from a higher point" in w for w in row["warnings"])


@pytest.mark.parametrize("slope_per_sd", [3.0, 40.0, 434.0])
def test_a_profile_falling_steeply_from_its_bound_is_integrated_over_its_own_scale(slope_per_sd):
    """A mode held on a bound by a slope (gonio.fitting.evidence._side_integral): the
    profile can fall by hundreds within the Gaussian's sd; its integral must still be the
    exact one, sd / slope (with 12 nodes over the whole sd, 434 per sd is 45 % off)."""
    from gonio.fitting.evidence import _side_integral

    sd = 0.01
    evaluated = []

    def profile(x: float) -> float:
        evaluated.append(x)
        return -slope_per_sd * (1.0 - x) / sd

    integral = _side_integral(profile, 1.0, 0.0, sd)
    assert integral == pytest.approx(sd / slope_per_sd * (1.0 - math.exp(-slope_per_sd * 1.0 / sd)), rel=1e-5)
    assert len(evaluated) < 60


@pytest.mark.parametrize("slope_per_sd", [0.5, 434.0])
def test_a_profile_is_never_evaluated_on_its_bound(slope_per_sd):
    """A parameter's range may be open at its bound (a pit's aperture psi > 0, the model
    refuses psi = 0): the profile's integral up to a bound half an sd away uses interior
    points only, and is still the exact integral."""
    from gonio.fitting.evidence import _side_integral

    sd, edge = 0.01, 0.995

    def profile(x: float) -> float:
        if x <= edge:
            raise ValueError(f"evaluated at {x}, on or beyond the bound {edge}")
        return -slope_per_sd * (1.0 - x) / sd

    expected = sd / slope_per_sd * (1.0 - math.exp(-slope_per_sd * (1.0 - edge) / sd))
    assert _side_integral(profile, 1.0, edge, sd) == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("seed, method", [(0, "barely determined: Laplace 2.4 high"),
                                          (4, "the even rule accepted 0.6 high"),
                                          (6, "the even rule refused: one node 75 %")])
def test_a_nested_candidate_near_its_nesting_point_matches_sampling(seed, method):
    """``pitted`` on Lambertian data, where the data say the pits are shallow or few but
    not how shallow: psi 45 +- 65 deg (seed 0, a positive definite curvature whose Gaussian
    is no description), coverage and psi both near 0 (seeds 4 and 6, the integrand peaks
    against a bound). The quadrature (crowded towards the bound where the integrand peaks
    there) agrees with sequential Monte Carlo: measured 288.148, 282.426 and 283.569
    against 288.162, 282.381 and 283.552 (+- 0.04-0.06, 2000 particles)."""
    from gonio.fitting.evidence import laplace_evidence, tempered_evidence

    data = synthetic_dataset("lambert", {"rho": 0.8}, noise=0.003, seed=seed, relative=True)
    problem = FitProblem("pitted", data)
    least_squares = fit_least_squares(problem)
    priors = resolve_priors(problem, least_squares.values, problem.priors_with_defaults(None))
    evidence = laplace_evidence(problem, least_squares, priors)
    assert evidence.quadrature_over in ("psi", "coverage"), method
    sampled = tempered_evidence(problem, priors, particles=500)
    assert evidence.log_evidence == pytest.approx(sampled.log_evidence, abs=3 * sampled.error + 0.1), method


def test_crowded_nodes_integrate_a_peak_against_the_bound():
    """The crowded rule resolves what the even rule cannot: exp(-u / 0.3) on [0, 90]
    (a posterior piled against psi = 0) to 1 % where 12 even nodes are 55 % off, and
    mirrored towards the upper bound."""
    from gonio.fitting.evidence import CONDITIONAL_NODES, _crowded_nodes

    exact = 0.3 * (1.0 - math.exp(-90.0 / 0.3))
    nodes, weights = _crowded_nodes(0.0, 90.0)
    assert np.sum(weights * np.exp(-nodes / 0.3)) == pytest.approx(exact, rel=0.01)
    upper, upper_weights = _crowded_nodes(0.0, 90.0, towards_upper=True)
    assert np.sum(upper_weights * np.exp(-(90.0 - upper) / 0.3)) == pytest.approx(exact, rel=0.01)
    even, even_weights = np.polynomial.legendre.leggauss(CONDITIONAL_NODES)
    even_sum = np.sum(45.0 * even_weights * np.exp(-45.0 * (even + 1.0) / 0.3))
    assert abs(even_sum / exact - 1.0) > 0.5


def test_an_undetermined_parameter_is_integrated_by_quadrature_not_sampled():
    """``pitted`` on a Lambertian sample with its optimum at coverage 0.04, psi 7 deg: the
    curvature is indefinite (psi and coverage trade off), Laplace's Gaussian does not
    exist. The evidence integrates one of them by quadrature, Laplace for the others
    (gonio.fitting.evidence._conditional_evidence), and agrees with sequential Monte Carlo
    of the same integrand (measured 284.850 against 284.873 +- 0.046 with 2000 particles);
    the comparison names the method."""
    from gonio.fitting.evidence import laplace_evidence, tempered_evidence

    data = synthetic_dataset("lambert", {"rho": 0.8}, noise=0.003, seed=2, relative=True)
    problem = FitProblem("pitted", data)
    least_squares = fit_least_squares(problem)
    priors = resolve_priors(problem, least_squares.values, problem.priors_with_defaults(None))
    assert math.isnan(laplace_evidence(problem, least_squares, priors, conditional=False).log_evidence)
    evidence = laplace_evidence(problem, least_squares, priors)
    assert evidence.quadrature_over in ("psi", "coverage")
    sampled = tempered_evidence(problem, priors, particles=500)
    assert evidence.log_evidence == pytest.approx(sampled.log_evidence, abs=3 * sampled.error + 0.2)
    row = compare_models(data, ["lambert", "pitted"]).row("pitted")
    assert row["evidence_method"] == f"laplace, quadrature over {evidence.quadrature_over}"
    assert row["log_evidence"] == pytest.approx(evidence.log_evidence, abs=1e-6)


def test_the_evidence_of_a_narrow_extra_noise_is_its_quadrature():
    """An extra relative noise of 3.3e-4 on its range of [0, 10] (0.04 % scatter, 0.01 %
    stated): the curvature is taken with steps scaled to the fit's errors, not to the
    range (a step of 1e-3 differenced it about 2e-3, beyond its peak, and the evidence was
    undefined). Laplace then agrees with the quadrature over the noise, each node the
    others' Laplace evidence, within 0.1."""
    from scipy.special import logsumexp

    from gonio.fitting import evidence

    data = synthetic_dataset("oren-nayar", dict(rho=0.8, sigma=20.0), 4e-4, seed=1, relative=True)
    data = Dataset(*data.geometry, data.value, 1e-4 * np.abs(data.value), quantity=data.quantity)
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0}, jitter="relative")
    ls = fit_least_squares(problem)
    priors = resolve_priors(problem, ls.values, {})
    assert 2e-4 < ls.values["rel_jitter"] < 5e-4
    laplace = evidence.laplace_evidence(problem, ls, priors).log_evidence
    nodes = np.linspace(1e-5, 1.2e-3, 60)
    terms = []
    for value in nodes:
        reduced, fitted = evidence._optimum_at(problem, priors, "rel_jitter", float(value), ls.values)
        terms.append(evidence.laplace_evidence(reduced, fitted, priors, conditional=False).log_evidence
                     + priors["rel_jitter"].logpdf(value))
    assert terms[0] < max(terms) - 30 and terms[-1] < max(terms) - 30  # the grid holds the whole peak
    quadrature = logsumexp(terms) + math.log(nodes[1] - nodes[0])
    assert laplace == pytest.approx(quadrature, abs=0.1)


def test_with_an_extra_noise_the_others_curvature_is_the_least_squares(monkeypatch):
    """With a free extra noise the other parameters' curvature is the least squares' (their
    Jacobian whitened by the total noise), not a finite difference of the whole posterior,
    which any roughness of the likelihood at the step's scale can make indefinite (the lab
    rig's two tilts along the swing axis: an eigenvalue of -1.3, and the candidate fell to
    sampling). Forced indefinite here, the evidence is still Laplace's, equal to the
    quadrature over the noise within 0.1."""
    from gonio.fitting import evidence

    data = synthetic_dataset("oren-nayar", dict(rho=0.8, sigma=20.0), 4e-4, seed=1, relative=True)
    data = Dataset(*data.geometry, data.value, 1e-4 * np.abs(data.value), quantity=data.quantity)
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0}, jitter="relative")
    ls = fit_least_squares(problem)
    priors = resolve_priors(problem, ls.values, {})
    expected = evidence.laplace_evidence(problem, ls, priors).log_evidence
    rough = np.diag([1e-4, -1e-3, 1e-8])  # what finite differences of a rough likelihood can give
    monkeypatch.setattr(evidence, "_numerical_covariance", lambda *args, **kwargs: rough)
    forced = evidence.laplace_evidence(problem, ls, priors)
    assert forced.quadrature_over is None and forced.log_evidence == pytest.approx(expected, abs=1e-9)
    assert forced.log_evidence == pytest.approx(377.94, abs=0.1)  # the quadrature of the test above
