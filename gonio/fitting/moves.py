"""emcee's moves with every walker of a half-ensemble evaluated and accepted at once.

Kept apart from :mod:`gonio.fitting.mcmc` so that reading a fit result (a report, a
comparison) does not import emcee.

emcee's red-blue moves (the stretch move, differential evolution) loop over walkers in
Python to accept proposals; once the model evaluates a whole half-ensemble in one call
those loops cost more than the model. :class:`VectorisedRedBlue` does them with numpy:
the same proposals (each move's own ``get_proposal``), the same acceptance rule
min(1, exp(factor) p(y)/p(x)), the same random numbers in the same order, so a chain
equals emcee's to the last bit (tests/fitting/test_mcmc.py).

References
----------
J. Goodman, J. Weare, "Ensemble samplers with affine invariance", Comm. App. Math. Comp.
Sci. 5(1), 65 (2010). D. Foreman-Mackey, D. W. Hogg, D. Lang, J. Goodman, "emcee: The
MCMC Hammer", PASP 125, 306 (2013). C. J. F. ter Braak, "A Markov chain Monte Carlo
version of the genetic algorithm Differential Evolution", Stat. Comput. 16, 239 (2006);
B. Nelson, E. B. Ford, M. J. Payne, "RUN DMC", ApJS 210, 11 (2014).
"""
from __future__ import annotations

from typing import Callable

import emcee
import numpy as np

__all__ = ["MOVES", "VectorisedRedBlue", "VectorisedStretchMove", "VectorisedDEMove", "VectorisedDESnookerMove",
           "ensemble_moves", "gaussian_move", "laplace_move", "LAPLACE_DOF"]


class VectorisedRedBlue:
    """Mixin for an emcee red-blue move (``emcee.moves.RedBlueMove`` subclass): each
    half-ensemble's proposals are evaluated and accepted in one vectorised step.

    Identical in distribution, and for the same random state in every number, to the
    move it is mixed into: ``get_proposal`` and ``setup`` are that move's; the uniform
    numbers of the acceptance test are drawn all at once instead of one per walker (the
    same stream). The log posterior of the proposals comes from
    ``log_prob_batch`` when given, else from ``model.compute_log_prob_fn``.
    """

    log_prob_batch: Callable[[np.ndarray], np.ndarray] | None = None

    def propose(self, model, state):
        """One update of both halves of the ensemble; returns the new state and acceptances."""
        self.setup(state.coords)
        nwalkers = state.coords.shape[0]
        accepted = np.zeros(nwalkers, dtype=bool)
        halves = np.arange(nwalkers) % self.nsplits
        if self.randomize_split:
            model.random.shuffle(halves)
        for split in range(self.nsplits):
            moving = halves == split
            others = [state.coords[halves == j] for j in range(self.nsplits) if j != split]
            proposal, factors = self.get_proposal(state.coords[moving], others, model.random)
            if self.log_prob_batch is not None:
                log_prob = np.asarray(self.log_prob_batch(proposal), float)
            else:
                log_prob = np.asarray(model.compute_log_prob_fn(proposal)[0], float)
            gain = factors + log_prob - state.log_prob[moving]
            taken = gain > np.log(model.random.rand(proposal.shape[0]))
            accepted[moving] = taken
            # emcee's Move.update without blobs: the accepted proposals replace their walkers
            rows = np.flatnonzero(moving)[taken]
            state.coords[rows] = proposal[taken]
            state.log_prob[rows] = log_prob[taken]
        return state, accepted


class VectorisedStretchMove(VectorisedRedBlue, emcee.moves.StretchMove):
    """emcee's stretch move (Goodman & Weare 2010), vectorised (:class:`VectorisedRedBlue`).

    Parameters
    ----------
    log_prob_batch : callable, optional
        ``log_prob_batch(coords) -> ndarray``: log posterior of every row of ``coords``
        (used inside ``emcee.EnsembleSampler``, whose own conversion loops over walkers).
    a : float
        Stretch scale (emcee's default 2).
    """

    def __init__(self, log_prob_batch: Callable[[np.ndarray], np.ndarray] | None = None, a: float = 2.0) -> None:
        super().__init__(a=a)
        self.log_prob_batch = log_prob_batch


class VectorisedDEMove(VectorisedRedBlue, emcee.moves.DEMove):
    """emcee's differential-evolution move (ter Braak 2006; Nelson et al. 2014), vectorised.

    A walker moves along the difference of two walkers of the other half-ensemble times
    gamma0 = 2.38 / sqrt(2 d) (emcee's default, the optimal random-walk scale for a
    Gaussian in d dimensions): a random-walk Metropolis step whose proposal covariance is
    the ensemble's own, so it adapts to scales and correlations without a tuning run.

    Parameters
    ----------
    sigma : float
        Relative spread of gamma (emcee's default 1e-5).
    gamma0 : float, optional
        Mean of gamma; default 2.38 / sqrt(2 d).
    """

    def __init__(self, sigma: float = 1.0e-5, gamma0: float | None = None) -> None:
        super().__init__(sigma=sigma, gamma0=gamma0)


class VectorisedDESnookerMove(VectorisedRedBlue, emcee.moves.DESnookerMove):
    """emcee's differential-evolution snooker move (ter Braak & Vrugt 2008), vectorised."""

    def __init__(self, gammas: float = 1.7) -> None:
        super().__init__(gammas=gammas)


def gaussian_move(covariance: np.ndarray) -> emcee.moves.MHMove:
    """Random-walk Metropolis with the proposal covariance (2.38^2 / d) C, the optimal
    scale for a Gaussian target of covariance C in d dimensions (Gelman, Roberts & Gilks
    1996); every walker in one evaluation, each with its own displacement.

    An ``emcee.moves.MHMove`` with its own proposal, not ``emcee.moves.GaussianMove``:
    with a full covariance, emcee 3.1.6's ``GaussianMove`` draws one displacement and adds
    it to every walker (fixed in emcee by pull request 571, after that release), so the
    walkers move together and the ensemble is not a set of independent chains (measured:
    posterior medians 0.1 sd off with 25,000 nominal effective samples).
    """
    covariance = 2.38**2 / np.shape(covariance)[0] * np.asarray(covariance, float)
    mean = np.zeros(covariance.shape[0])

    def propose(coords: np.ndarray, random) -> tuple[np.ndarray, np.ndarray]:
        step = random.multivariate_normal(mean, covariance, size=coords.shape[0])
        return coords + step, np.zeros(coords.shape[0])

    return emcee.moves.MHMove(propose, ndim=covariance.shape[0])


#: Degrees of freedom of the Laplace move's Student t proposal (:func:`laplace_move`).
LAPLACE_DOF = 5.0


def laplace_move(mode: np.ndarray, covariance: np.ndarray, dof: float = LAPLACE_DOF) -> emcee.moves.MHMove:
    """Independence Metropolis-Hastings from the posterior's Laplace approximation.

    Every walker proposes a point drawn afresh, whatever its position, from a multivariate
    Student t with ``dof`` degrees of freedom centred on the posterior mode and scaled by
    the Laplace covariance (``C``, the least-squares covariance with the Gaussian priors in
    it), and accepts it with probability min(1, p(y) q(x) / (p(x) q(y))) (Tierney 1994,
    "independence chains"; the t's heavier tails make the weight p/q bounded where the
    posterior's tails are no heavier than the t's, and so the chain uniformly ergodic).
    The chain targets the posterior exactly whatever the proposal: the approximation
    decides only how often a proposal is taken. Where the posterior is close to its
    Laplace approximation most proposals are taken and a walker forgets its position in
    one or two steps, however strongly the parameters correlate, where a random walk
    (differential evolution included) needs many steps to cross a narrow ridge; where it
    is not close, few are taken and the other moves of the mixture do the work.

    Parameters
    ----------
    mode : numpy.ndarray, shape (d,)
        The posterior mode (the least-squares optimum with the Gaussian priors).
    covariance : numpy.ndarray, shape (d, d)
        Its Laplace covariance, positive definite.
    dof : float
        Degrees of freedom of the t proposal (default :data:`LAPLACE_DOF`).

    References
    ----------
    L. Tierney, "Markov chains for exploring posterior distributions", Ann. Statist. 22,
    1701 (1994), section 2.3.3; A. Gelman et al., *Bayesian Data Analysis*, 3rd ed.,
    section 12.2 (the t approximation as a proposal).
    """
    mode = np.asarray(mode, float)
    factor = np.linalg.cholesky(np.asarray(covariance, float))
    ndim = mode.size

    def log_density(points: np.ndarray) -> np.ndarray:
        """log q up to its constant (which cancels in the acceptance ratio)."""
        standard = np.linalg.solve(factor, (points - mode).T)
        return -0.5 * (dof + ndim) * np.log1p(np.sum(standard**2, axis=0) / dof)

    def propose(coords: np.ndarray, random) -> tuple[np.ndarray, np.ndarray]:
        normal = random.standard_normal((coords.shape[0], ndim))
        stretch = np.sqrt(dof / random.chisquare(dof, size=coords.shape[0]))
        proposal = mode + stretch[:, None] * (normal @ factor.T)
        return proposal, log_density(coords) - log_density(proposal)

    return emcee.moves.MHMove(propose, ndim=ndim)


def _usable(covariance: np.ndarray, ndim: int) -> bool:
    """Whether a least-squares covariance can scale a Gaussian proposal (finite, positive definite)."""
    covariance = np.asarray(covariance, float)
    if covariance.shape != (ndim, ndim) or not np.all(np.isfinite(covariance)):
        return False
    try:
        np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        return False
    return True


#: The move sets :func:`ensemble_moves` builds, by name, with their relative weights.
#: ``laplace+de`` is the default of :func:`gonio.fitting.mcmc.sample_posterior`, chosen by
#: measurement (benchmarks/bench_moves.py, docs/fitting.md "Performance"): it reaches
#: convergence in 43-60 % of DE's steps on the small problems and a fifth on the demo's
#: 11-parameter rig fit, with the same posterior, and is DE where no Laplace covariance is
#: positive definite; DE's autocorrelation time is a quarter of the stretch move's. The
#: Gaussian move needs the least-squares covariance, the Laplace move that or the log
#: posterior's curvature (:func:`gonio.fitting.mcmc.laplace_covariance`): where neither is
#: usable (a parameter piled at a bound) they are left out of a mixture, and ``gaussian``
#: alone becomes ``de``.
MOVES: dict[str, str] = {
    "stretch": "emcee's stretch move (Goodman & Weare 2010), emcee's default",
    "de": "differential evolution (ter Braak 2006; Nelson et al. 2014)",
    "de+snooker": "differential evolution 0.8 + DE snooker 0.2 (ter Braak & Vrugt 2008)",
    "de+stretch": "differential evolution 0.5 + stretch 0.5",
    "gaussian": "random-walk Metropolis scaled by the least-squares covariance",
    "gaussian+de": "Gaussian random walk 0.5 + differential evolution 0.5",
    "gaussian+stretch": "Gaussian random walk 0.5 + stretch 0.5",
    "laplace+de": "independence proposals from the Laplace approximation 0.5 + differential evolution 0.5",
}


def ensemble_moves(name: str, covariance: np.ndarray, ndim: int,
                   mode: np.ndarray | None = None) -> list[tuple[emcee.moves.Move, float]]:
    """The emcee moves and weights of the move set ``name`` (:data:`MOVES`).

    Parameters
    ----------
    name : str
        A key of :data:`MOVES`.
    covariance : numpy.ndarray, shape (ndim, ndim)
        Least-squares covariance of the free parameters (for the Gaussian moves).
    ndim : int
        Number of free parameters.
    mode : numpy.ndarray, shape (ndim,), optional
        The posterior mode (for the Laplace move; without it, or without a usable
        covariance, ``laplace+de`` is ``de``).

    Raises
    ------
    ValueError
        ``name`` is not a known move set.
    """
    check_moves(name)
    gaussian = [gaussian_move(covariance)] if name.startswith("gaussian") and _usable(covariance, ndim) else []
    if name == "stretch":
        return [(VectorisedStretchMove(), 1.0)]
    if name == "laplace+de":
        usable = mode is not None and np.all(np.isfinite(mode)) and _usable(covariance, ndim)
        return ([(laplace_move(mode, covariance), 0.5), (VectorisedDEMove(), 0.5)] if usable
                else [(VectorisedDEMove(), 1.0)])
    if name == "de" or (name == "gaussian" and not gaussian):
        return [(VectorisedDEMove(), 1.0)]
    if name == "de+snooker":
        return [(VectorisedDEMove(), 0.8), (VectorisedDESnookerMove(), 0.2)]
    if name == "de+stretch":
        return [(VectorisedDEMove(), 0.5), (VectorisedStretchMove(), 0.5)]
    if name == "gaussian":
        return [(gaussian[0], 1.0)]
    partner = VectorisedDEMove() if name == "gaussian+de" else VectorisedStretchMove()
    return [(move, 0.5) for move in gaussian] + [(partner, 0.5)]


def check_moves(name: str) -> None:
    """Raise ``ValueError`` unless ``name`` is a key of :data:`MOVES`."""
    if name not in MOVES:
        raise ValueError(f"moves={name!r} is not a known move set; expected one of {sorted(MOVES)}")
