"""Bayesian fit with emcee's ensemble moves.

Posterior = prior x likelihood.  Priors are proper (:mod:`gonio.fitting.priors`); the
likelihood is Gaussian with the measurement uncertainties (and the optional ``jitter``
added in quadrature, :mod:`gonio.fitting.problem`).  The model is evaluated through its
fixed-geometry fast path (``Model.at``), built once by :class:`FitProblem`, for a whole
half-ensemble at a time.

The walkers are advanced by emcee's moves (:mod:`gonio.fitting.moves`). By default half
the steps are independence proposals drawn from the posterior's Laplace approximation (a
Student t about the least-squares optimum, scaled by its covariance,
:func:`~gonio.fitting.moves.laplace_move`) and half differential evolution (a walker moves
along the difference of two others): where the posterior is close to its Laplace
approximation a walker forgets where it was in a step or two however strongly the
parameters correlate, and where it is not, or no Laplace covariance is positive definite
(a parameter piled at a bound), differential evolution does the work, at a quarter of the
stretch move's autocorrelation time (benchmarks/bench_moves.py, docs/fitting.md
"Performance"). Both are exact Metropolis-Hastings steps: the approximation decides only
how many proposals are taken. The loop is gonio's over preallocated arrays
(:class:`gonio.fitting.ensemble.EnsembleChain`, the chain of ``emcee.EnsembleSampler``
bit for bit, without its per-step bookkeeping).

Convergence follows the emcee documentation (Foreman-Mackey et al. 2013; emcee
"Autocorrelation analysis & convergence" tutorial) and Vehtari et al. (2021): every
``check_every`` steps the integrated autocorrelation time tau of each parameter is
estimated; the run stops when the chain is at least ``tau_multiple`` (default 50) times
the largest tau long, the tau estimate changed by less than ``tau_rtol`` since the
previous check, *and* the rank-normalised split R-hat of every parameter (ArviZ, each
walker a chain, after burn-in) is below 1.01 (:mod:`gonio.fitting.diagnostics`).  If ``max_steps`` is
reached first the result is marked not converged and a :class:`ConvergenceWarning` is
issued: its numbers must not be trusted without a longer run.  The burn-in discarded is
2 max(tau) steps and the samples are thinned by max(1, min(tau)/2), as that tutorial
recommends.  The effective sample size of a parameter is
n_walkers (n_steps - burn_in) / tau.

References
----------
D. Foreman-Mackey, D. W. Hogg, D. Lang, J. Goodman, "emcee: The MCMC Hammer",
PASP 125, 306 (2013); https://emcee.readthedocs.io/en/stable/tutorials/autocorr/
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from .diagnostics import RHAT_LIMIT, convergence_diagnostics
from .least_squares import LeastSquaresResult
from .priors import Prior, Uniform, default_prior
from .problem import FitProblem

__all__ = ["DEFAULT_WALKERS", "SERIAL_WALKERS", "default_walkers", "VectorisedStretchMove", "ConvergenceWarning", "McmcResult", "resolve_priors", "sample_posterior", "start_spread", "LogPosterior", "laplace_covariance"]


#: Default ensemble size where the likelihood evaluates every walker at once (models that
#: broadcast their parameters or are linear in their coefficients), chosen by measurement:
#: the run ends when every walker's chain has an R-hat below 1.01, which takes about 100
#: autocorrelation times whatever the ensemble, so the time to convergence is least for a
#: small ensemble whose steps cost little. With the default moves (Laplace + DE) 24 walkers
#: take as many steps as 32 or fewer on all five problems of benchmarks/bench_moves.py
#: (medians of 3 seeds: Fig 16 400 against 500, near-Gaussian 300 and 300, bound 1000 and
#: 1000, skewed 500 and 600, the demo's 11-parameter rig fit 800 and 800, 3.8 s against
#: 5.2 s), each step a quarter cheaper where the model dominates it; 16 need more steps
#: where they are allowed at all (emcee needs twice the free parameters), and their 95 %
#: endpoints stray further (docs/fitting.md "Performance"). More parameters than 11 get
#: :func:`default_walkers`' 2 k + 2.
DEFAULT_WALKERS = 24
#: Most memory a chain may take at ``max_steps`` [bytes]: walkers x steps x (parameters
#: + 1) x 8 bytes (the defaults: 24 walkers, 20,000 steps, 11 parameters: 46 MB).
CHAIN_MEMORY_LIMIT = 2 * 2**30
#: Default ensemble size where the model is evaluated one walker at a time or a walker at
#: a time's cost (a step costs in proportion to the walkers, so more of them only lengthen
#: the run; the demo's rig fit above, whose compiled aperture loop costs 0.2 ms a walker).
SERIAL_WALKERS = 24


def default_walkers(problem: FitProblem) -> int:
    """:data:`DEFAULT_WALKERS` when ``problem`` evaluates all walkers at once, else
    :data:`SERIAL_WALKERS`; at least 2 k + 2 for k free parameters (emcee's moves need
    twice k, and two more keep each half-ensemble larger than k)."""
    return max(DEFAULT_WALKERS if problem.vectorised else SERIAL_WALKERS, 2 * problem.ndim + 2)

#: Growth of the chain between autocorrelation estimates (a fraction of its length): the
#: stopping rule is met at most this much later than with a check every ``check_every`` steps.
CHECK_GROWTH = 0.1


class ConvergenceWarning(UserWarning):
    """The chain reached its step limit before the autocorrelation criterion was met."""


def __getattr__(name: str):
    """:class:`~gonio.fitting.moves.VectorisedStretchMove`, still importable from here
    (PEP 562: loading it imports emcee, which reading results does not need)."""
    if name == "VectorisedStretchMove":
        from .moves import VectorisedStretchMove

        return VectorisedStretchMove
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def resolve_priors(
    problem: FitProblem, reference: Mapping[str, float], overrides: Mapping[str, Prior] | None = None
) -> dict[str, Prior]:
    """The prior of every free parameter: the user's where given, else the default.

    Raises
    ------
    ValueError
        A prior is given for a parameter that is not free.
    """
    overrides = dict(overrides or {})
    unknown = [name for name in overrides if name not in problem.free]
    if unknown:
        raise ValueError(
            f"prior given for {unknown[0]!r}, which is not a free parameter; free parameters are {list(problem.free)}"
        )
    return {
        name: overrides.get(name) or default_prior(name, problem.spec(name).bounds, reference.get(name, math.nan))
        for name in problem.free
    }


class LogPosterior:
    """log prior + log likelihood of a parameter vector, timing the model evaluations.

    The physical range is enforced in addition to the prior's support, so that the
    model is never called outside it.
    """

    def __init__(self, problem: FitProblem, priors: Mapping[str, Prior]):
        self.problem = problem
        self.priors = [priors[name] for name in problem.free]
        self.specs = [problem.spec(name) for name in problem.free]
        self.model_seconds = 0.0
        self.calls = 0
        self._lower, self._upper = support_box(self.specs, self.priors)
        uniform = [k for k, p in enumerate(self.priors) if isinstance(p, Uniform)]
        self._uniform_log_density = sum(-math.log(self.priors[k].upper - self.priors[k].lower) for k in uniform)
        self._shaped = [(k, p) for k, p in enumerate(self.priors) if k not in uniform]

    def log_prior(self, vector) -> float:
        total = 0.0
        for x, prior, spec in zip(vector, self.priors, self.specs):
            x = float(x)
            if not spec.contains(x):
                return -math.inf
            total += prior.logpdf(x)
            if total == -math.inf:
                return -math.inf
        return total

    def __call__(self, vector) -> float:
        prior = self.log_prior(vector)
        if prior == -math.inf:
            return -math.inf
        start = time.perf_counter()
        likelihood = self.problem.log_likelihood(vector)
        self.model_seconds += time.perf_counter() - start
        self.calls += 1
        return prior + likelihood

    def batch(self, vectors) -> np.ndarray:
        """Log posterior of every row of ``vectors`` (shape (W, n_free)) in one model
        evaluation; equal to calling the posterior row by row (to rounding). Rows outside
        a physical range or the prior's support get ``-inf`` and are not evaluated."""
        vectors = np.asarray(vectors, float).reshape(-1, self._lower.size)
        inside = ((vectors >= self._lower) & (vectors <= self._upper)).all(axis=1)
        every = bool(inside.all())
        if not every and not inside.any():
            return np.full(vectors.shape[0], -math.inf)
        rows = vectors if every else vectors[inside]
        start = time.perf_counter()
        posterior = self.problem.log_likelihood_batch(rows)
        self.model_seconds += time.perf_counter() - start
        self.calls += rows.shape[0]
        posterior += self._uniform_log_density
        for k, prior in self._shaped:
            posterior += prior.logpdf_array(rows[:, k])
        if every:
            return posterior
        out = np.full(vectors.shape[0], -math.inf)
        out[inside] = posterior
        return out


def support_box(specs, priors) -> tuple[np.ndarray, np.ndarray]:
    """Closed lower and upper limits of each parameter where both its physical range and
    its prior allow it (an open physical bound becomes the next float inside)."""
    lower, upper = [], []
    for spec, prior in zip(specs, priors):
        lo, hi = spec.bounds
        lower.append(max(np.nextafter(lo, math.inf) if spec.open_lower else lo, prior.lower))
        upper.append(min(np.nextafter(hi, -math.inf) if spec.open_upper else hi, prior.upper))
    return np.array(lower, float), np.array(upper, float)


@dataclass
class McmcResult:
    """Chain and convergence diagnostics of :func:`sample_posterior`.

    Attributes
    ----------
    free : tuple of str
        Parameter names (last axis of ``chain``).
    chain : ndarray, shape (n_steps, n_walkers, n_free)
        Every position of every walker (burn-in included).
    log_prob : ndarray, shape (n_steps, n_walkers)
        Log posterior of each position.
    tau : ndarray
        Integrated autocorrelation time of each parameter [steps].
    acceptance_fraction : ndarray
        Per walker.
    burn_in, thin : int
        Steps discarded at the start, and thinning of the kept samples.
    converged : bool
        Whether the autocorrelation criterion was met before ``max_steps``.
    tau_multiple, tau_rtol : float
        The criterion: chain length >= tau_multiple max(tau), relative change of tau < tau_rtol.
    max_steps : int
        Step limit.
    wall_seconds, model_seconds : float
        Total sampling time and the part spent in the likelihood (model evaluation).
    evaluations : int
        Likelihood evaluations (inside the prior support).
    tau_history : list of (int, float)
        (steps, max tau) at each check.
    diagnostics : dict
        ``{name: {"r_hat", "ess_bulk", "ess_tail"}}`` of the chain after burn-in (ArviZ).
    rhat_limit : float
        The R-hat criterion.
    moves : str
        The emcee moves of the chain (a name of :data:`gonio.fitting.moves.MOVES`).
    """

    free: tuple[str, ...]
    chain: np.ndarray
    log_prob: np.ndarray
    tau: np.ndarray
    acceptance_fraction: np.ndarray
    burn_in: int
    thin: int
    converged: bool
    tau_multiple: float
    tau_rtol: float
    max_steps: int
    wall_seconds: float
    model_seconds: float
    evaluations: int
    tau_history: list[tuple[int, float]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    diagnostics: dict[str, dict[str, float]] = field(default_factory=dict)
    rhat_limit: float = RHAT_LIMIT
    moves: str = "stretch"

    @property
    def n_steps(self) -> int:
        return int(self.chain.shape[0])

    @property
    def n_walkers(self) -> int:
        return int(self.chain.shape[1])

    @property
    def ess(self) -> np.ndarray:
        """Effective sample size of each parameter."""
        kept = max(self.n_steps - self.burn_in, 0)
        with np.errstate(divide="ignore", invalid="ignore"):  # tau may be NaN for a failed estimate
            return self.n_walkers * kept / self.tau

    def samples(self) -> np.ndarray:
        """Posterior samples after burn-in and thinning, shape (n, n_free)."""
        return self.chain[self.burn_in :: self.thin].reshape(-1, len(self.free))

    def sample_log_prob(self) -> np.ndarray:
        """Log posterior of :meth:`samples`."""
        return self.log_prob[self.burn_in :: self.thin].reshape(-1)


#: At most this many walkers (evenly spaced) enter the autocorrelation estimate.
TAU_WALKERS = 64


def integrated_time(chain: np.ndarray, c: float = 5.0, max_walkers: int = TAU_WALKERS) -> np.ndarray:
    """Integrated autocorrelation time of each parameter of an ensemble chain [steps].

    emcee's estimator (``emcee.autocorr.integrated_time`` with ``tol=0``: the normalised
    autocorrelation function averaged over walkers, summed up to Sokal's automatic window
    ``M >= c tau``), computed with one FFT over all walkers and parameters instead of one
    per walker.  Equal to emcee's to rounding for up to ``max_walkers`` walkers
    (tests/fitting/test_mcmc.py); a larger ensemble is estimated from ``max_walkers``
    evenly spaced walkers (a decision: the walker-averaged autocorrelation function of 64
    walkers is already an average of 64 estimates, and the estimate of every 100 steps
    would otherwise cost as much as the steps themselves with a few hundred walkers).

    Parameters
    ----------
    chain : numpy.ndarray, shape (steps, walkers, parameters)
    c : float
        Window constant.
    max_walkers : int
        Largest number of walkers used.
    """
    x = np.asarray(chain, float)
    if x.shape[1] > max_walkers:
        x = x[:, np.linspace(0, x.shape[1] - 1, max_walkers).round().astype(int)]
    n = x.shape[0]
    size = 1 << int(math.ceil(math.log2(max(n, 1))))
    centred = x - x.mean(axis=0)
    spectrum = np.fft.rfft(centred, n=2 * size, axis=0)
    acf = np.fft.irfft(spectrum * np.conj(spectrum), n=2 * size, axis=0)[:n]
    with np.errstate(invalid="ignore", divide="ignore"):
        acf /= acf[0]
    mean_acf = acf.mean(axis=1)  # (steps, parameters)
    taus = 2.0 * np.cumsum(mean_acf, axis=0) - 1.0
    inside = np.arange(n)[:, None] < c * taus
    window = np.where(inside.all(axis=0), n - 1, np.argmin(inside, axis=0))
    return taus[window, np.arange(x.shape[2])]


#: Rounds of start-ball draws (one candidate per walker each) before the remaining walkers
#: are drawn from the priors.
START_ROUNDS = 50


def _initial_walkers(
    posterior: LogPosterior, centre: np.ndarray, spread: np.ndarray, n_walkers: int, rng: np.random.Generator
) -> np.ndarray:
    """Start positions: Gaussian draws around ``centre`` inside the support.

    Every walker comes from the ball unless :data:`START_ROUNDS` rounds of ``n_walkers``
    draws leave some without a position of finite posterior (a ball mostly outside the
    support); only those are drawn from the priors. (A fixed budget of 200 draws in all
    once started 56 of 256 walkers from the priors, up to 30,000 posterior sd away, and
    their way in outlasted the burn-in: docs/fitting.md, "Performance".)
    """
    walkers = np.empty((n_walkers, centre.size))
    filled = 0
    for _ in range(START_ROUNDS):
        trial = centre + spread * rng.standard_normal((n_walkers, centre.size))
        inside = trial[np.isfinite(posterior.batch(trial))][: n_walkers - filled]
        walkers[filled : filled + len(inside)] = inside
        filled += len(inside)
        if filled == n_walkers:
            return walkers
    while filled < n_walkers:
        trial = np.array([p.sample(rng, 1)[0] for p in posterior.priors])
        if math.isfinite(posterior(trial)):
            walkers[filled] = trial
            filled += 1
    return walkers


def sample_posterior(
    problem: FitProblem,
    start: LeastSquaresResult,
    priors: Mapping[str, Prior] | None = None,
    n_walkers: int | None = None,
    max_steps: int = 20000,
    tau_multiple: float = 50.0,
    tau_rtol: float = 0.05,
    check_every: int = 100,
    seed: int | None = 0,
    progress: Callable[[int, int, float], None] | None = None,
    rhat_limit: float = RHAT_LIMIT,
    moves: str = "laplace+de",
) -> tuple[McmcResult, dict[str, Prior]]:
    """Sample the posterior with emcee until the autocorrelation criterion holds.

    Parameters
    ----------
    problem : FitProblem
        Model, data, fixed parameters.
    start : LeastSquaresResult
        The walkers start in a small Gaussian ball around its optimum (:func:`start_spread`).
    priors : mapping, optional
        Overrides of the default priors (module :mod:`gonio.fitting.priors`).
    n_walkers : int, optional
        Ensemble size (at least twice the number of free parameters; emcee requirement);
        default :func:`default_walkers`.
    max_steps : int
        Step limit; reaching it marks the result not converged (loud warning).
    tau_multiple, tau_rtol : float
        Convergence criterion (module docstring).  Values below 50 are for quick tests.
    rhat_limit : float
        Largest R-hat of a converged chain (default 1.01; larger values are for quick tests).
    check_every : int
        Steps between autocorrelation estimates and progress reports.
    seed : int, optional
        Seed of the walkers' start and of the sampler.
    progress : callable, optional
        ``progress(steps, max_steps, max_tau)`` after every check.
    moves : str
        The emcee moves (:data:`gonio.fitting.moves.MOVES`): ``"laplace+de"`` (the
        default, chosen by measurement: independence proposals from the Laplace
        approximation 0.5 + differential evolution 0.5, DE alone where no Laplace
        covariance is positive definite, :func:`laplace_covariance`), ``"de"``,
        ``"stretch"`` (emcee's default move), or another mixture.

    Returns
    -------
    McmcResult, dict
        The chain with diagnostics, and the priors used.
    """
    ndim = problem.ndim
    n_walkers = default_walkers(problem) if n_walkers is None else int(n_walkers)
    if n_walkers < 2 * ndim:
        raise ValueError(f"n_walkers = {n_walkers} must be at least 2 x {ndim} free parameters")
    if max_steps < check_every:
        raise ValueError(f"max_steps = {max_steps} must be at least check_every = {check_every}")
    if not (math.isfinite(rhat_limit) and rhat_limit > 1.0):
        raise ValueError(f"rhat_limit = {rhat_limit!r}: expected a finite number above 1 (R-hat approaches 1 from "
                         f"above as the chains agree; {RHAT_LIMIT} is the default)")
    chain_bytes = 8.0 * n_walkers * max_steps * (ndim + 1)  # positions and log-probabilities
    if chain_bytes > CHAIN_MEMORY_LIMIT:
        raise ValueError(f"n_walkers = {n_walkers} with max_steps = {max_steps} and {ndim} free parameters would keep "
                         f"a chain of up to {chain_bytes / 2**30:.3g} GiB in memory (limit "
                         f"{CHAIN_MEMORY_LIMIT / 2**30:g} GiB); use fewer walkers (default {DEFAULT_WALKERS}) or steps")
    priors = resolve_priors(problem, start.values, priors)
    posterior = LogPosterior(problem, priors)
    rng = np.random.default_rng(seed)
    centre = np.array([start.values[name] for name in problem.free])
    spread = []
    for name, value in zip(problem.free, centre):
        spread.append(start_spread(problem, name, float(value), start.stderr.get(name, math.nan)))
        # Keep the ball clear of a bound the optimum sits on, so walkers start inside.
        lo, hi = problem.spec(name).bounds
        centre[problem.free.index(name)] = min(max(value, lo + spread[-1]), hi - spread[-1]) if math.isfinite(hi - lo) else value
    walkers = _initial_walkers(posterior, centre, np.array(spread), n_walkers, rng)

    from .ensemble import EnsembleChain
    from .moves import ensemble_moves

    # emcee's moves draw from a legacy RandomState
    random = np.random.RandomState(int(rng.integers(2**31)))
    mode = np.array([start.values[name] for name in problem.free], float)
    covariance = laplace_covariance(problem, posterior, start) if moves.startswith("laplace") else start.covariance
    sampler = EnsembleChain(posterior.batch, ensemble_moves(moves, covariance, ndim, mode), walkers, random)
    posterior.model_seconds = 0.0
    posterior.calls = 0
    history: list[tuple[int, float]] = []
    previous = np.full(ndim, np.inf)
    converged = False
    steps = 0
    began = time.perf_counter()
    tau = np.full(ndim, np.nan)
    next_rhat = 0
    next_check = check_every
    largest = math.inf
    while steps < max_steps:
        n = min(check_every, max_steps - steps)
        sampler.run(n)
        steps += n
        if steps < next_check and steps < max_steps:
            if progress is not None:
                progress(steps, max_steps, largest)
            continue
        # tau costs O(steps log steps): estimated again only after the chain grew by
        # CHECK_GROWTH (at least check_every steps), so the checks stay a small share
        next_check = steps + max(check_every, int(CHECK_GROWTH * steps) // check_every * check_every)
        tau = integrated_time(sampler.get_chain())
        largest = float(np.max(tau)) if np.all(np.isfinite(tau)) else math.inf
        history.append((steps, largest))
        if math.isfinite(largest):  # no check before the chain can be tau_multiple tau long
            hopeless = int(math.ceil(0.9 * tau_multiple * largest / check_every)) * check_every
            next_check = max(next_check, min(hopeless, max_steps))
        if progress is not None:
            progress(steps, max_steps, largest)
        stable = bool(np.all(np.abs(previous - tau) < tau_rtol * tau))
        if math.isfinite(largest) and steps >= tau_multiple * largest and stable and steps >= next_rhat:
            # R-hat costs ~0.1 s: computed on the thinned chain, and again only after it grew by 25 %
            burn, thin = min(int(math.ceil(2.0 * largest)), steps // 2), max(1, int(0.5 * float(np.min(tau))))
            r_hat = convergence_diagnostics(sampler.get_chain()[burn::thin], problem.free, ess=False)
            next_rhat = int(1.25 * steps)
            if all(d["r_hat"] < rhat_limit for d in r_hat.values()):
                converged = True
                break
        previous = tau
    wall = time.perf_counter() - began

    chain = sampler.get_chain().copy()
    log_prob = sampler.get_log_prob().copy()
    notes = []
    if np.all(np.isfinite(tau)):
        burn_in = min(int(math.ceil(2.0 * tau.max())), steps // 2)
        thin = max(1, int(0.5 * tau.min()))
    else:
        burn_in, thin = steps // 2, 1
    acceptance = np.asarray(sampler.acceptance_fraction, float)
    diagnostics = convergence_diagnostics(chain[burn_in::thin], problem.free)
    if not converged:
        largest = float(np.nanmax(tau)) if np.any(np.isfinite(tau)) else math.nan
        worst = max(diagnostics.items(), key=lambda item: np.nan_to_num(item[1]["r_hat"], nan=np.inf))
        message = (
            f"CHAIN NOT CONVERGED: {steps} steps reached the limit max_steps = {max_steps} but the "
            f"criterion needs {tau_multiple:g} x tau = {tau_multiple * largest:.0f} steps with a stable tau "
            f"(tau = {largest:.1f}) and R-hat < {rhat_limit:g} (largest: {worst[0]} {worst[1]['r_hat']:.3g}); "
            "the posterior numbers are unreliable. Run longer (--max-steps), fix degenerate parameters, "
            "or simplify the model."
        )
        notes.append(message)
        warnings.warn(message, ConvergenceWarning, stacklevel=2)
    mean_acceptance = float(acceptance.mean())
    if not 0.1 <= mean_acceptance <= 0.9:
        notes.append(
            f"mean acceptance fraction {mean_acceptance:.2f} is outside [0.1, 0.9]: the sampler "
            "moves poorly (multi-modal or badly scaled posterior)"
        )
    stuck = int(np.sum(acceptance < 0.2 * mean_acceptance))
    if stuck:
        notes.append(f"{stuck} of {n_walkers} walkers accepted far fewer moves than the rest (stuck walkers)")
    result = McmcResult(
        free=problem.free,
        chain=chain,
        log_prob=log_prob,
        tau=tau,
        acceptance_fraction=acceptance,
        burn_in=burn_in,
        thin=thin,
        converged=converged,
        tau_multiple=float(tau_multiple),
        tau_rtol=float(tau_rtol),
        max_steps=int(max_steps),
        wall_seconds=wall,
        model_seconds=posterior.model_seconds,
        evaluations=posterior.calls,
        tau_history=history,
        warnings=notes,
        diagnostics=diagnostics,
        rhat_limit=float(rhat_limit),
        moves=moves,
    )
    return result, priors


def laplace_covariance(problem: FitProblem, posterior: LogPosterior, start: LeastSquaresResult) -> np.ndarray:
    """The covariance of the posterior's Laplace approximation about the least-squares optimum.

    The least-squares covariance where every entry is determined (the Gaussian priors are
    in it); else, as where a free extra-noise term makes the residuals' Jacobian silent
    about it, the inverse Hessian of the log posterior itself at the optimum
    (:func:`gonio.fitting.curvature.inverse_hessian`, 2 k^2 + 1 evaluations, steps of a
    hundredth of each least-squares standard error, or a thousandth of the value where
    that is undetermined). Either may
    still be unusable (an indefinite curvature at a bound): the moves then leave the
    Laplace move out (:func:`gonio.fitting.moves.ensemble_moves`).
    """
    from .curvature import inverse_hessian, steps_at_mode

    covariance = np.asarray(start.covariance, float)
    if np.all(np.isfinite(covariance)):
        return covariance
    mode = np.array([start.values[name] for name in problem.free], float)
    bounds = [problem.spec(name).bounds for name in problem.free]
    steps = steps_at_mode(mode, [start.stderr.get(name, math.nan) for name in problem.free], bounds)
    return inverse_hessian(lambda vector: -posterior(vector), mode, bounds, steps)


def _width(bounds: tuple[float, float]) -> float:
    """The width of a range, 1 where it is unbounded."""
    return bounds[1] - bounds[0] if math.isfinite(bounds[1] - bounds[0]) else 1.0


def start_spread(problem: FitProblem, name: str, value: float, error: float) -> float:
    """Width of the walkers' start ball for one parameter, from the least-squares optimum.

    A tenth of the least-squares standard error; where that is undetermined, 1e-3 of the
    optimum's magnitude, and for an extra-noise parameter a tenth of the larger of its
    optimum and a tenth of the typical stated uncertainty (never a fraction of the prior's
    width: 1e-3 of the jitter's range once started walkers 100 times too high, where two of
    32 stayed stuck).
    """
    if math.isfinite(error) and error > 0:
        return 0.1 * error
    data = problem.dataset
    if name == "jitter":
        return 0.1 * max(abs(value), 0.1 * float(np.median(data.sigma)))
    if name == "rel_jitter":
        typical = float(np.median(data.sigma / np.maximum(np.abs(data.value), 1e-300)))
        return 0.1 * max(abs(value), 0.1 * typical)
    lo, hi = problem.spec(name).bounds
    floor = 1e-6 * (hi - lo) if math.isfinite(hi - lo) else 1e-12
    return 1e-3 * max(abs(value), floor)
