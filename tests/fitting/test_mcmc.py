"""Bayesian fits with emcee: recovery, interval coverage, convergence flags, bounds.

Sampler settings in these tests are smaller than the defaults to keep the suite fast:
16 walkers (emcee needs at least 2 x the free parameters) and a chain of 20 (not 50)
autocorrelation times.  20 tau with 16 walkers still gives a few hundred independent
samples, enough for the 2.5/97.5 percentiles to within about a tenth of a standard
deviation, which is all the assertions below resolve.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import gonio
from gonio.fitting import ConvergenceWarning, FitProblem, Normal, fit, fit_least_squares, sample_posterior
from gonio.fitting.problem import predict_quantity

from .synthetic import FIG16_INCIDENCES, in_plane_geometry, synthetic_dataset

QUICK = dict(n_walkers=16, tau_multiple=20.0, max_steps=6000, rhat_limit=1.05)  # quick: not the 50 tau, 1.01 defaults


@pytest.mark.parametrize(
    "model, truth",
    [("minnaert", dict(rho=0.6, k=0.7)), ("lambert+phong", dict(rho=0.5, rho_s=0.2, exponent=15.0))],
)
def test_95_percent_interval_contains_the_truth(model, truth):
    # One fixed noise realisation: a correct posterior misses the truth for 1 seed in 20
    # per parameter; the rate itself is checked by test_interval_coverage_over_seeds.
    data = synthetic_dataset(model, truth, 0.01, seed=1, relative=True)
    result = fit(data, model, **QUICK)
    assert result.converged
    post = result.posterior
    for name, value in truth.items():
        assert post["p2_5"][name] < value < post["p97_5"][name], (name, post["p2_5"][name], post["p97_5"][name])
        # The posterior width agrees with the least-squares error for these well-determined,
        # nearly Gaussian posteriors (to 25 %, the sampling error of a percentile of ~300
        # effective samples plus the non-linearity of the model).
        half_width = 0.5 * (post["p84"][name] - post["p16"][name])
        assert half_width == pytest.approx(result.least_squares.stderr[name], rel=0.25)
    assert 0.2 < post["acceptance_fraction"] < 0.8
    assert all(ess > 100 for ess in post["ess"].values())


def test_interval_coverage_over_seeds():
    # Frequentist check of the Bayesian intervals: over 12 noise realisations x 2
    # parameters (24 intervals) the 68 % intervals should contain the truth 16.3 times on
    # average (binomial sd 2.3) and the 95 % intervals 22.8 times (sd 1.1).  Accepted:
    # 11..22 and >= 20, i.e. about +/-2.5 sd; too narrow intervals (over-confident) or
    # too wide ones (68 % containing all 24) fail.
    truth = dict(rho=0.6, k=0.7)
    inside68 = inside95 = 0
    for seed in range(12):
        data = synthetic_dataset("minnaert", truth, 0.02, seed=100 + seed, relative=True,
                                 geometry=in_plane_geometry(views=np.arange(-70.0, 71.0, 20.0)))
        post = fit(data, "minnaert", seed=seed, **QUICK).posterior
        for name, value in truth.items():
            inside68 += post["p16"][name] < value < post["p84"][name]
            inside95 += post["p2_5"][name] < value < post["p97_5"][name]
    assert 11 <= inside68 <= 22, inside68
    assert inside95 >= 20, inside95


def test_least_squares_error_coverage_over_many_seeds():
    # The covariance (J^T J)^-1 calibrates the errors: over 150 seeds the +/-1 standard
    # error interval of each of 2 parameters should contain the truth 68.3 % of 300 times
    # = 205 (binomial sd 8.1); accepted 180..230 (+/-3 sd).
    truth = dict(rho=0.6, k=0.7)
    geometry = in_plane_geometry(views=np.arange(-70.0, 71.0, 20.0))
    inside = 0
    for seed in range(150):
        data = synthetic_dataset("minnaert", truth, 0.02, seed=seed, relative=True, geometry=geometry)
        ls = fit_least_squares(FitProblem("minnaert", data), n_starts=1)
        inside += sum(abs(ls.values[n] - v) < ls.stderr[n] for n, v in truth.items())
    assert 180 <= inside <= 230, inside


def test_step_limit_is_flagged_loudly():
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.01, relative=True)
    with pytest.warns(ConvergenceWarning, match="CHAIN NOT CONVERGED"):
        result = fit(data, "minnaert", n_walkers=8, max_steps=200)
    assert result.converged is False
    assert any("CHAIN NOT CONVERGED" in flag for flag in result.flags)
    assert "!!! NOT CONVERGED" in result.summary()


def test_posterior_piled_at_a_bound_is_flagged():
    # A Lambertian sample fitted with Lambert + Phong: the specular albedo's posterior
    # piles up against 0 and the summary asks for an upper limit instead.
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # the exponent is then unconstrained
        result = fit(data, "lambert+phong", fixed={"exponent": 20.0}, **QUICK)
    assert any(flag.startswith("rho_s: the posterior piles up at the lower bound") for flag in result.flags)
    assert not any(flag.startswith("rho: the posterior piles") for flag in result.flags)


def test_walkers_use_the_fixed_geometry_fast_path():
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.01, relative=True)
    problem = FitProblem("minnaert", data)
    start = fit_least_squares(problem)
    before = problem.evaluations
    with pytest.warns(ConvergenceWarning):  # 300 steps are too few for a stable tau; not the point here
        chain, _ = sample_posterior(problem, start, n_walkers=8, max_steps=300, tau_multiple=1.0, check_every=100)
    # Every likelihood evaluation went through FitProblem.predict (Model.at).
    assert problem.evaluations - before >= chain.evaluations > 0
    assert chain.model_seconds <= chain.wall_seconds


def test_user_prior_overrides_the_default():
    # A tight prior on k dominates weak data: the posterior median moves to the prior mean.
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.05, relative=True)
    # The likelihood alone gives k = 0.7 +/- 0.01; with a prior 0.4 +/- 0.001 the posterior
    # mean is the precision-weighted mean 0.403.
    result = fit(data, "minnaert", priors={"k": Normal(0.4, 0.001, 0.0, 1.0)}, **QUICK)
    assert result.posterior["median"]["k"] == pytest.approx(0.403, abs=0.003)
    assert str(result.priors["k"]) == "normal(0.4, 0.001) on [0, 1]"
    with pytest.raises(ValueError, match="not a free parameter"):
        fit(data, "minnaert", fixed={"k": 0.7}, priors={"k": Normal(0.4, 0.1)}, mcmc=True, **QUICK)


@pytest.mark.skipif("oren-nayar" not in gonio.models.available(), reason="oren-nayar is not registered yet")
def test_oren_nayar_fig16_recovery():
    # Oren & Nayar (1995) Fig 16: wall plaster, sigma = 30 deg, rho = 0.90, normalised
    # radiance in the plane of incidence at theta_i = 30, 45, 60 deg, camera every 10 deg.
    # With 1 % noise the 95 % interval of sigma contains 30 deg.  rho enters normalised
    # radiance only through the interreflection term, so its interval is wide but must
    # still contain 0.9.
    model = gonio.models.get("oren-nayar")
    truth = dict(rho=0.9, sigma=30.0)
    fixed = {p.name: p.default for p in model.params if p.name not in truth}
    geometry = in_plane_geometry(FIG16_INCIDENCES, np.arange(-80.0, 81.0, 10.0))
    exact = predict_quantity("oren-nayar", "normalised_radiance", *geometry, dict(truth, **fixed))
    rng = np.random.default_rng(16)
    from gonio.fitting import Dataset

    data = Dataset(*geometry, exact * (1 + 0.01 * rng.standard_normal(exact.shape)), 0.01 * exact,
                   quantity="normalised_radiance")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        result = fit(data, "oren-nayar", fixed=fixed, **QUICK)
    post = result.posterior
    for name, value in truth.items():
        assert post["p2_5"][name] <= value <= post["p97_5"][name], (name, post["p2_5"][name], post["p97_5"][name])
    assert post["p97_5"]["sigma"] - post["p2_5"]["sigma"] < 10.0  # sigma is well determined


@pytest.mark.skipif("oren-nayar" not in gonio.models.available(), reason="oren-nayar is not registered yet")
def test_oren_nayar_roughness_of_a_lambertian_sample_is_an_upper_limit():
    # sigma = 0 is Lambert (Oren & Nayar eq 33-35 reduce to rho/pi), and the BRDF is
    # stationary in sigma there, so Lambertian data only bound sigma from above: the fit
    # must say "upper limit", not report sigma = x +/- y.
    data = synthetic_dataset("lambert", dict(rho=0.8), 0.002, seed=3)
    result = fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, **QUICK)
    assert any(flag.startswith("sigma: the posterior piles up at the lower bound 0 deg") for flag in result.flags)
    assert result.posterior["p97_5"]["sigma"] < 5.0  # 0.2 % noise excludes visible roughness
    assert result.posterior["p2_5"]["rho"] < 0.8 < result.posterior["p97_5"]["rho"]


def test_the_clis_state_the_default_ensemble_size():
    """The CLI help quotes the default numbers of walkers without importing the sampler."""
    import inspect

    import gonio.cli.curet
    import gonio.cli.fit
    from gonio.fitting.mcmc import DEFAULT_WALKERS, SERIAL_WALKERS

    assert DEFAULT_WALKERS == SERIAL_WALKERS  # the help says one number for every model
    for module in (gonio.cli.fit, gonio.cli.curet):
        assert f"default {DEFAULT_WALKERS}, for every model" in inspect.getsource(module)


def test_default_ensemble_size_follows_the_likelihood():
    from gonio.fitting import FitProblem
    from gonio.fitting.mcmc import DEFAULT_WALKERS, SERIAL_WALKERS, default_walkers

    from .synthetic import synthetic_dataset

    data = synthetic_dataset("oren-nayar", {"rho": 0.9, "sigma": 30.0}, 0.01)
    assert default_walkers(FitProblem("oren-nayar", data, {"ir_weight": 1.0})) == DEFAULT_WALKERS
    assert default_walkers(FitProblem("oren-nayar-tabulated", data)) == SERIAL_WALKERS


def test_default_ensemble_keeps_two_walkers_more_than_twice_the_parameters():
    """emcee's moves need at least twice as many walkers as free parameters: a model with
    the rig's errors as parameters beyond 11 gets 2 k + 2."""
    from gonio.fitting import FitProblem
    from gonio.fitting.mcmc import DEFAULT_WALKERS, default_walkers

    from .synthetic import synthetic_dataset

    data = synthetic_dataset("oren-nayar", {"rho": 0.9, "sigma": 30.0}, 0.01)
    small = FitProblem("oren-nayar", data, {"ir_weight": 1.0}, alignment="all")
    large = FitProblem("oren-nayar+torrance-sparrow", data, alignment="all", stray_light=True)
    assert small.ndim <= 11 and default_walkers(small) == DEFAULT_WALKERS
    assert large.ndim > 11 and default_walkers(large) == 2 * large.ndim + 2


def test_vectorised_stretch_move_is_emcees_stretch_move():
    """Same proposals, same acceptance rule, same random stream: the chain equals emcee's
    own StretchMove to the last bit (only the loops over walkers are vectorised)."""
    import emcee

    from gonio.fitting.mcmc import VectorisedStretchMove

    precision = np.array([[2.0, 0.6], [0.6, 1.0]])

    def log_prob(x):
        x = np.atleast_2d(x)
        return -0.5 * np.einsum("wi,ij,wj->w", x, precision, x)

    start = np.random.default_rng(4).normal(size=(16, 2))
    chains = []
    for move in (emcee.moves.StretchMove(), VectorisedStretchMove(log_prob)):
        sampler = emcee.EnsembleSampler(16, 2, log_prob, vectorize=True, moves=move)
        sampler.run_mcmc(emcee.State(start, random_state=np.random.RandomState(9).get_state()), 300, progress=False)
        chains.append(sampler.get_chain())
    np.testing.assert_array_equal(chains[0], chains[1])


def test_integrated_time_is_emcees_estimator():
    """One FFT over all walkers gives emcee's integrated autocorrelation time."""
    import emcee

    from gonio.fitting.mcmc import integrated_time

    rng = np.random.default_rng(8)
    noise = rng.standard_normal((3000, 24, 2))
    chain = np.empty_like(noise)
    chain[0] = noise[0]
    for t in range(1, chain.shape[0]):  # AR(1) chains with known correlation
        chain[t] = np.array([0.9, 0.6]) * chain[t - 1] + noise[t]
    np.testing.assert_allclose(integrated_time(chain), emcee.autocorr.integrated_time(chain, tol=0), rtol=1e-9)
    np.testing.assert_allclose(integrated_time(chain[:257]), emcee.autocorr.integrated_time(chain[:257], tol=0),
                               rtol=1e-9)


@pytest.mark.parametrize("moves", ["stretch", "de", "mixture"])
def test_ensemble_loop_equals_emcees_sampler(moves):
    """gonio's loop (preallocated chain, emcee's move choice and random stream) gives
    emcee's EnsembleSampler chain to the last bit, for the vectorised stretch and
    differential-evolution moves and a mixture of them (which also makes the loop draw
    the move per step as emcee does)."""
    import emcee

    from gonio.fitting.ensemble import EnsembleChain
    from gonio.fitting.moves import VectorisedDEMove, VectorisedStretchMove

    precision = np.array([[2.0, 0.6], [0.6, 1.0]])

    def log_prob(x):
        return -0.5 * np.einsum("wi,ij,wj->w", np.atleast_2d(x), precision, np.atleast_2d(x))

    def chosen(vectorised: bool):
        stretch = VectorisedStretchMove() if vectorised else emcee.moves.StretchMove()
        de = VectorisedDEMove() if vectorised else emcee.moves.DEMove()
        return {"stretch": [(stretch, 1.0)], "de": [(de, 1.0)], "mixture": [(de, 0.7), (stretch, 0.3)]}[moves]

    start = np.random.default_rng(4).normal(size=(16, 2))
    sampler = emcee.EnsembleSampler(16, 2, log_prob, vectorize=True, moves=chosen(False))
    sampler.run_mcmc(emcee.State(start, random_state=np.random.RandomState(9).get_state()), 300, progress=False)
    ours = EnsembleChain(log_prob, chosen(True), start, np.random.RandomState(9))
    ours.run(120)
    ours.run(180)  # in two pieces, as between convergence checks
    np.testing.assert_array_equal(ours.get_chain(), sampler.get_chain())
    np.testing.assert_array_equal(ours.get_log_prob(), sampler.get_log_prob())
    np.testing.assert_array_equal(ours.acceptance_fraction, sampler.acceptance_fraction)


def test_every_walker_of_a_large_ensemble_starts_in_the_ball():
    """With 256 walkers each starts within the ball around the least-squares optimum (a
    fixed budget of 200 draws once sent 56 of 256 walkers to draws from the priors, up to
    30,000 posterior sd away: a thinned posterior sd 1.5 times too large)."""
    from gonio.fitting.mcmc import LogPosterior, _initial_walkers, resolve_priors

    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.01, relative=True)
    problem = FitProblem("minnaert", data)
    start = fit_least_squares(problem)
    posterior = LogPosterior(problem, resolve_priors(problem, start.values))
    centre = np.array([start.values[n] for n in problem.free])
    spread = np.array([0.1 * start.stderr[n] for n in problem.free])
    walkers = _initial_walkers(posterior, centre, spread, 256, np.random.default_rng(0))
    # 6 spreads: a Gaussian draw beyond that has probability 2e-9 per coordinate
    assert np.all(np.abs(walkers - centre) < 6 * spread)
    assert len(np.unique(walkers[:, 0])) == 256


def test_gaussian_move_gives_every_walker_its_own_displacement():
    """One displacement per walker (emcee 3.1.6's GaussianMove with a full covariance adds
    the same one to all): the accepted moves of one step differ between walkers, and their
    covariance is (2.38^2 / d) C (within 10 %: 4000 walkers, relative sd 2 %)."""
    from gonio.fitting.moves import gaussian_move

    covariance = np.array([[1.0, 0.5], [0.5, 2.0]])
    move = gaussian_move(covariance)
    coords = np.zeros((4000, 2))
    proposal, factors = move.get_proposal(coords, np.random.RandomState(3))
    assert np.all(factors == 0.0)
    assert len(np.unique(proposal[:, 0])) == 4000
    np.testing.assert_allclose(np.cov(proposal.T), 2.38**2 / 2 * covariance, rtol=0.1)


@pytest.mark.parametrize("limit", [float("inf"), float("nan"), 0.0, 1.0])
def test_an_rhat_limit_that_cannot_mean_convergence_is_refused(limit):
    """inf would call any chain converged, and nan, 0 or 1 none: each is refused by name."""
    data = synthetic_dataset("lambert", {"rho": 0.5}, 0.005)
    problem = FitProblem("lambert", data)
    with pytest.raises(ValueError, match="rhat_limit"):
        sample_posterior(problem, fit_least_squares(problem), rhat_limit=limit)


def test_an_ensemble_too_large_for_memory_is_refused_before_it_grows():
    data = synthetic_dataset("lambert", {"rho": 0.5}, 0.005)
    problem = FitProblem("lambert", data)
    with pytest.raises(ValueError, match="n_walkers = 1000000000 .* GiB"):
        sample_posterior(problem, fit_least_squares(problem), n_walkers=1_000_000_000)


def _correlated_target(rho: float = 0.98):
    """A 3-d Gaussian target with a strongly correlated pair: its covariance and log density."""
    covariance = np.array([[1.0, rho, 0.0], [rho, 1.0, 0.0], [0.0, 0.0, 4.0]])
    precision = np.linalg.inv(covariance)

    def log_prob(x):
        x = np.atleast_2d(x)
        return -0.5 * np.einsum("wi,ij,wj->w", x, precision, x)

    return covariance, log_prob


def test_laplace_move_targets_the_posterior_whatever_its_proposal():
    """Independence Metropolis-Hastings is exact for any proposal: centred 1.5 sd off and
    half as wide as the target along every axis, the chain still gives the target's mean
    and covariance (the Hastings factor log q(x) - log q(y) is what makes it so: without
    it, or with its sign turned, the chain leans to the proposal and the mean is 1.1-1.3 sd
    off, far beyond the 0.1 sd tolerance of 32 x 20000 draws)."""
    from gonio.fitting.ensemble import EnsembleChain
    from gonio.fitting.moves import laplace_move

    covariance, log_prob = _correlated_target()
    move = laplace_move(np.array([1.5, 1.5, 3.0]), 0.25 * covariance)
    start = np.random.default_rng(1).multivariate_normal(np.zeros(3), covariance, size=32)
    chain = EnsembleChain(log_prob, [(move, 1.0)], start, np.random.RandomState(2))
    chain.run(20000)
    samples = chain.get_chain()[1000:].reshape(-1, 3)
    sd = np.sqrt(np.diag(covariance))
    np.testing.assert_allclose(samples.mean(axis=0) / sd, 0.0, atol=0.1)
    np.testing.assert_allclose(np.cov(samples.T), covariance, atol=0.1 * 4.0, rtol=0.1)


def test_laplace_move_decorrelates_a_narrow_ridge_in_a_few_steps():
    """With the target's own covariance as its scale the walkers take most proposals and
    the autocorrelation time is a few steps on a ridge correlated at 0.995, where the
    differential-evolution move alone needs several times longer."""
    from gonio.fitting.ensemble import EnsembleChain
    from gonio.fitting.mcmc import integrated_time
    from gonio.fitting.moves import VectorisedDEMove, laplace_move

    covariance, log_prob = _correlated_target(0.995)
    start = np.random.default_rng(1).multivariate_normal(np.zeros(3), covariance, size=32)
    taus = {}
    for name, moves in {"laplace": [(laplace_move(np.zeros(3), covariance), 1.0)],
                        "de": [(VectorisedDEMove(), 1.0)]}.items():
        chain = EnsembleChain(log_prob, moves, start, np.random.RandomState(2))
        chain.run(4000)
        taus[name] = float(np.max(integrated_time(chain.get_chain()[500:])))
    assert taus["laplace"] < 3.0
    assert taus["de"] > 2.0 * taus["laplace"]


@pytest.mark.parametrize("covariance, mode", [(np.full((2, 2), np.nan), np.zeros(2)),
                                              (np.array([[1.0, 2.0], [2.0, 1.0]]), np.zeros(2)),
                                              (np.eye(2), None)])
def test_laplace_mixture_falls_back_to_de_without_a_laplace_approximation(covariance, mode):
    """An undetermined (NaN), indefinite or absent approximation leaves DE alone, as the
    Gaussian move sets do."""
    from gonio.fitting.moves import VectorisedDEMove, ensemble_moves

    moves = ensemble_moves("laplace+de", covariance, 2, mode)
    assert len(moves) == 1 and isinstance(moves[0][0], VectorisedDEMove)


def test_the_default_moves_use_the_laplace_approximation():
    """The default move set mixes the Laplace move into DE, and a fit records it."""
    import inspect

    assert inspect.signature(sample_posterior).parameters["moves"].default == "laplace+de"
    data = synthetic_dataset("lambert", {"rho": 0.5}, 0.005)
    problem = FitProblem("lambert", data)
    result, _ = sample_posterior(problem, fit_least_squares(problem), **QUICK)
    assert result.moves == "laplace+de"


def test_an_extra_noise_term_keeps_the_laplace_move():
    """The least-squares covariance says nothing of a free extra noise (its row is NaN);
    the Laplace move then takes the log posterior's own curvature at the optimum, which
    matches the chain's covariance (every sd within 15 %), instead of leaving DE alone:
    the fit converges in fewer steps than DE's with the same posterior."""
    from gonio.fitting.mcmc import LogPosterior, laplace_covariance, resolve_priors
    from gonio.fitting.moves import laplace_move

    data = synthetic_dataset("oren-nayar", dict(rho=0.9, sigma=30.0), 0.02, relative=True, seed=3)
    data = type(data)(*data.geometry, data.value, 0.5 * data.sigma)  # half the real scatter stated
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0}, jitter="relative")
    start = fit_least_squares(problem)
    assert not np.all(np.isfinite(start.covariance))
    covariance = laplace_covariance(problem, LogPosterior(problem, resolve_priors(problem, start.values)), start)
    laplace_move(np.zeros(problem.ndim), covariance)  # positive definite: its Cholesky exists
    runs = {moves: sample_posterior(problem, start, moves=moves, seed=1)[0] for moves in ("de", "laplace+de")}
    assert runs["laplace+de"].n_steps < runs["de"].n_steps
    chain_sd = runs["laplace+de"].samples().std(axis=0)
    np.testing.assert_allclose(np.sqrt(np.diag(covariance)), chain_sd, rtol=0.15)
    np.testing.assert_allclose(chain_sd, runs["de"].samples().std(axis=0), rtol=0.1)
