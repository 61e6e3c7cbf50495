"""The Bayesian evidence of a fit: Laplace's approximation with the corrections a bounded
reflectance posterior needs.

Laplace's method replaces the posterior by a Gaussian around its mode theta* with the
covariance C of the posterior there (Kass & Raftery 1995, section 4.1.1; MacKay 2003,
chapter 27)::

    ln Z_Laplace = ln L(theta*) + ln prior(theta*) + (k/2) ln(2 pi) + (1/2) ln det C

It is exact for a quadratic log posterior whose Gaussian lies inside the priors' support.
Reflectance fits often break both conditions, and docs/evidence.md measures by how much
against nested sampling and quadrature: a mode on a bound (rho = 1 of a white sample)
overstates Z by ln 2 per parameter, and a parameter the model is stationary in at its bound
(the Oren-Nayar BRDF depends on sigma through sigma^2, so at sigma = 0 the curvature
vanishes) by up to 1.8, in favour of the model with the unneeded parameter. Two
corrections are added (:class:`LaplaceEvidence`):

* **truncation**: ln of the Gaussian's mass inside the box of the parameters' supports (a
  multivariate normal probability over the parameters within eight standard deviations of
  a bound). It is exact for a Gaussian posterior cut by the support, jointly for several
  parameters on bounds (the mass of two on bounds with correlation r is
  1/4 + arcsin(r) / 2 pi, not 1/4);
* **shape**: for a parameter within three standard deviations of a bound whose profile
  log posterior (the others re-optimised) departs from the Gaussian's by more than 0.05
  within two standard deviations, the Gaussian's integral along it is replaced by the
  numerical integral of the profile (Gauss-Legendre on each side of the mode, out to where
  the profile has dropped by 15, and, where it falls steeply, not far beyond). This repairs a mode held on a bound by a slope (the data
  pull beyond it), the stationary sigma = 0 and an extra-noise term at or near 0; it
  assumes the others' conditional volume does not change along the profile. A profile that
  rises above the mode by more than :data:`MODE_RISE` shows that least squares stopped
  at a local optimum, not at the mode (seen with the Oren-Nayar + Torrance-Sparrow
  candidate stalled at ks = 1e-10 on rig data, its profile 174 higher at ks = 3e-7): the
  evidence is then undefined (NaN) and carries the higher point
  (:attr:`LaplaceEvidence.higher_point`); the comparison restarts that candidate's least
  squares from it once, and computes the evidence by sequential Monte Carlo
  (:func:`tempered_evidence`) only if Laplace's is still undefined there.

An indefinite curvature at the optimum means the data leave a parameter undetermined (a
candidate nested in a simpler one at the nesting point: a pit's aperture at coverage 0).
That parameter is integrated by quadrature over its prior with Laplace's evidence of the
others at each node (:func:`_conditional_evidence`, :attr:`LaplaceEvidence.quadrature_over`).

Where the likelihood alone leaves ``scale`` and an albedo-like factor undetermined
(relative radiance without a calibration prior), the evidence is the Laplace integral over
their product with the prior the two priors induce on it (:func:`_product_evidence`).

References
----------
R. E. Kass, A. E. Raftery, "Bayes factors", J. Am. Stat. Assoc. 90, 773 (1995).
D. J. C. MacKay, Information Theory, Inference, and Learning Algorithms (2003), ch. 27-28.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

__all__ = ["LaplaceEvidence", "TemperedEvidence", "laplace_evidence", "laplace_log_evidence", "log_posterior",
           "tempered_evidence", "scale_degenerate_factor"]

#: A bound within this many standard deviations of the mode enters the truncation mass.
TRUNCATION_SDS = 8.0
#: A bound within this many standard deviations makes a parameter's profile worth checking.
SHAPE_SDS = 3.0
#: Largest departure of the profile from the Gaussian (within two sd) left uncorrected.
SHAPE_TOLERANCE = 0.05
#: The profile is integrated out to where it has dropped by this much.
PROFILE_DEPTH = 15.0
#: A profile rising above the mode's log posterior by more than this (natural-log units,
#: the selection rule's margin) shows that the least-squares point is not the posterior's
#: maximum: there is no Laplace approximation around it and the evidence is undefined.
MODE_RISE = 1.0
#: Gauss-Legendre nodes of a profile's integral on each side of the mode: 12 are within
#: 0.003 of 24 in ln Z on a rig fit's three profiled parameters (``pitted`` on a
#: Lambertian sample, 65 values), in 0.42 of the time (docs/evidence.md).
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(12)


@dataclass(frozen=True)
class LaplaceEvidence:
    """The terms of the evidence (natural-log units).

    Attributes
    ----------
    raw : float
        ln Z of Laplace's formula as it stands.
    truncation : float
        ln of the Gaussian's mass inside the supports (<= 0).
    shape : dict
        Per parameter whose profile is not Gaussian near a bound: ln(profile integral /
        Gaussian integral along it).
    profiles_skipped : tuple of str
        Parameters near a bound whose profile was not checked (``laplace_evidence(...,
        profiles=False)``): ``log_evidence`` then lacks their shape corrections, if any.
    quadrature_over : str or None
        The parameter integrated by quadrature over its prior, Laplace's method for the
        others at each node (an indefinite curvature, :func:`_conditional_evidence`):
        ``raw`` is then the whole ln Z.
    higher_point : dict or None
        Where a profile rose above the least-squares point by more than
        :data:`MODE_RISE` (every free parameter's value there): the least squares stopped
        short of the posterior's mode, ``raw`` is NaN, and a fit restarted from here goes on.
    """

    raw: float
    truncation: float = 0.0
    shape: dict[str, float] = field(default_factory=dict)
    profiles_skipped: tuple[str, ...] = ()
    quadrature_over: str | None = None
    higher_point: dict[str, float] | None = None

    @property
    def log_evidence(self) -> float:
        """ln Z with both corrections."""
        return self.raw + self.truncation + sum(self.shape.values())


def laplace_log_evidence(problem, least_squares, priors, corrected: bool = True) -> float:
    """ln Z of a fit (module docstring); NaN where the posterior's curvature is undefined.

    Parameters
    ----------
    problem : FitProblem
    least_squares : LeastSquaresResult
        The posterior mode (least squares with the Gaussian priors).
    priors : mapping of Prior
        Prior of every free parameter.
    corrected : bool
        Add the truncation and shape corrections (else Laplace's formula as it stands).
    """
    evidence = laplace_evidence(problem, least_squares, priors)
    return evidence.log_evidence if corrected else evidence.raw


def laplace_evidence(problem, least_squares, priors, profiles: bool = True,
                     conditional: bool = True) -> LaplaceEvidence:
    """The terms of ln Z (:class:`LaplaceEvidence`) of a fit.

    ``profiles=False`` leaves out the shape corrections, whose profiles cost a
    least-squares fit per node (about 30 a parameter near a bound), and lists the
    parameters they would have checked in ``profiles_skipped`` (with an indefinite
    curvature, the parameters its quadrature would try, and ``log_evidence`` NaN): for a candidate
    whose evidence cannot change a comparison's choice (:mod:`gonio.fitting.selection`).
    ``conditional=False`` never integrates an undetermined parameter by quadrature where
    the curvature is indefinite (:func:`_conditional_evidence`; the quadrature's own nodes
    use it) and leaves the evidence undefined there.
    """
    names = list(problem.free)
    covariance = np.asarray(least_squares.covariance, float)
    if not np.all(np.isfinite(covariance)):
        factor = scale_degenerate_factor(problem, least_squares, priors)
        if factor is not None:
            return _product_evidence(problem, least_squares, priors, factor)
    if problem.noise_parameter in names:
        covariance = _with_noise_curvature(problem, least_squares, priors)
    elif not np.all(np.isfinite(covariance)):
        covariance = _numerical_covariance(problem, least_squares.values, priors, least_squares.stderr)
    undetermined = _undetermined_first(problem, covariance, priors) if conditional and len(names) > 1 else []
    if undetermined and not profiles:
        return LaplaceEvidence(math.nan, profiles_skipped=tuple(undetermined))
    if undetermined:
        # a parameter the data leave undetermined or barely determined, as where the model
        # is nested in a simpler one (a pit's psi at coverage 0): its integral by
        # quadrature over its prior, Laplace's method for the others at each node
        conditional_evidence = _conditional_evidence(problem, least_squares, priors, undetermined)
        if math.isfinite(conditional_evidence.log_evidence) or not _positive_definite(covariance):
            return conditional_evidence
    if not _positive_definite(covariance):
        return LaplaceEvidence(math.nan)
    sign, log_det = np.linalg.slogdet(covariance)
    mode = np.array([least_squares.values[n] for n in names], float)
    peak = log_posterior(problem, priors, mode)
    if sign <= 0 or not math.isfinite(peak):
        return LaplaceEvidence(math.nan)
    raw = peak + 0.5 * len(names) * math.log(2.0 * math.pi) + 0.5 * log_det
    supports = [_support(problem, priors[n], n) for n in names]
    truncation = _log_mass_inside(mode, covariance, supports)
    if not profiles:
        skipped = tuple(n for k, n in enumerate(names)
                        if _near_bound(mode[k], math.sqrt(covariance[k, k]), supports[k]))
        return LaplaceEvidence(raw, truncation, {}, skipped)
    shape = {}
    for k, name in enumerate(names):
        try:
            correction = _shape_correction(problem, least_squares, priors, k, covariance, supports[k], peak)
        except _NotTheMode as rise:
            return LaplaceEvidence(math.nan, higher_point=rise.values)
        if correction is not None:
            shape[name] = correction
    return LaplaceEvidence(raw, truncation, shape)


#: Gauss-Legendre nodes of the quadrature over an undetermined parameter's prior.
CONDITIONAL_NODES = 12
#: The quadrature is trusted only where no node carries more than this share of it (the
#: integrand is resolved by the nodes, not a peak between two of them).
LARGEST_NODE_SHARE = 0.5


#: A parameter whose Gaussian sd exceeds this share of its support's width is barely
#: determined: Laplace's Gaussian is no description of its posterior, which the
#: quadrature integrates instead (:func:`_undetermined_first`).
BARELY_DETERMINED = 0.25


def _undetermined_first(problem, covariance: np.ndarray, priors) -> list[str]:
    """The model's own free parameters of bounded support to integrate by quadrature,
    least determined first (the Gaussian's sd over the support's width): for an
    indefinite curvature all of them; for a positive definite one those whose sd exceeds
    :data:`BARELY_DETERMINED` of the width.

    Where the curvature is positive definite but a parameter is poorly determined
    (``pitted`` on Lambertian data: psi 45 +- 65 deg over (0, 90]), Laplace's Gaussian,
    even corrected, was off by 2.4 to 2.9 in ln Z in either direction against sequential
    Monte Carlo; the quadrature over psi was within 0.03 (benchmarks/bench_nested_evidence.py)."""
    names = list(problem.free)
    definite = _positive_definite(covariance)
    shares = {}
    for name in (p.name for p in problem.base_model.params if p.name in names):
        lo, hi = _support(problem, priors[name], name)
        if math.isfinite(lo) and math.isfinite(hi) and hi > lo:
            k = names.index(name)
            shares[name] = math.sqrt(abs(covariance[k, k])) / (hi - lo) if math.isfinite(covariance[k, k]) else math.inf
    chosen = [n for n in shares if not definite or shares[n] > BARELY_DETERMINED]
    return sorted(chosen, key=lambda n: -shares[n])


def _conditional_evidence(problem, least_squares, priors, candidates: list[str]) -> LaplaceEvidence:
    """ln Z = ln of the integral over one parameter u's prior of pi(u) Z(others | u).

    u is the first of ``candidates`` (:func:`_undetermined_first`) whose fixing leaves the
    others' curvature positive definite and whose quadrature is resolved; Z(others | u)
    is the corrected Laplace evidence of the problem with u fixed at each of
    :data:`CONDITIONAL_NODES` Gauss-Legendre nodes of u's support (interior points: a
    range open at its bound is never evaluated there), the others fitted by least squares
    from the optimum at the nearest node done. ``raw`` holds the result, with the name of
    u as ``quadrature_over``; NaN where no candidate qualifies.
    """
    for name in candidates:
        reduced = problem.fixing({name: least_squares.values[name]})
        rest = {n: least_squares.values[n] for n in reduced.free}
        if not _positive_definite(_numerical_covariance(reduced, rest, priors, least_squares.stderr)):
            continue
        log_evidence = _quadrature_over(problem, least_squares, priors, name)
        if math.isfinite(log_evidence):
            return LaplaceEvidence(log_evidence, quadrature_over=name)
    return LaplaceEvidence(math.nan)


def _quadrature_over(problem, least_squares, priors, name: str) -> float:
    """ln of the integral over ``name``'s support of its prior times the others' Laplace
    evidence (:func:`_conditional_evidence`); NaN if a node's is undefined or the
    integrand is not resolved.

    The nodes are first spread evenly (:data:`CONDITIONAL_NODES` Gauss-Legendre nodes of
    the support). Where the largest term is an interior node's, that rule is trusted if no
    node carries more than :data:`LARGEST_NODE_SHARE` of the integral. Where it is an end
    node's, the integrand peaks against that bound (a nested candidate near its nesting
    point: a pit's psi or coverage near 0, where the data say the parameter is small but
    not how small), and the integral is taken again with the nodes crowded towards it
    (:func:`_crowded_nodes`), trusted where no node of that rule carries more than
    :data:`LARGEST_NODE_SHARE` or the two rules agree within :data:`RULES_AGREE`.

    Measured against sequential Monte Carlo (2000 particles) on ``pitted`` fitted to
    Lambertian data (tests/fitting/test_adequacy.py's draws): seed 6 (psi 0.3 deg,
    coverage 0) 283.569 against 283.552 +- 0.058, where the even rule alone gave 283.672.
    """
    lo, hi = _support(problem, priors[name], name)
    optima = {float(least_squares.values[name]): dict(least_squares.values)}
    even, weights = np.polynomial.legendre.leggauss(CONDITIONAL_NODES)
    terms = _node_terms(problem, least_squares, priors, name, lo + 0.5 * (hi - lo) * (even + 1.0),
                        0.5 * (hi - lo) * weights, optima)
    if terms is None:
        return math.nan
    from scipy.special import logsumexp, softmax

    shares = softmax(terms)
    top = int(np.argmax(shares))
    if top not in (0, len(terms) - 1):
        return float(logsumexp(terms)) if shares[top] <= LARGEST_NODE_SHARE else math.nan
    nodes, node_weights = _crowded_nodes(lo, hi, towards_upper=top == len(terms) - 1)
    crowded = _node_terms(problem, least_squares, priors, name, nodes, node_weights, optima)
    if crowded is None:
        return math.nan
    if max(softmax(crowded)) <= LARGEST_NODE_SHARE or abs(logsumexp(crowded) - logsumexp(terms)) <= RULES_AGREE:
        return float(logsumexp(crowded))
    return math.nan


#: Two quadrature rules (even and crowded nodes) whose results differ by no more than this
#: [ln units] have resolved the integral, whatever share one node carries.
RULES_AGREE = 0.2
#: Power of the substitution that crowds the quadrature's nodes towards a bound
#: (:func:`_crowded_nodes`).
CROWDING_POWER = 3


def _crowded_nodes(lo: float, hi: float, towards_upper: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [lo, hi] crowded towards one bound.

    The substitution ``u = lo + (hi - lo) t^p`` (p = :data:`CROWDING_POWER`, t the
    :data:`CONDITIONAL_NODES` Gauss-Legendre nodes of [0, 1], weight times
    ``du/dt = p (hi - lo) t^(p-1)``) puts a third of the nodes within 1 % of the range
    from ``lo`` (mirrored for ``towards_upper``). An integrand that is flat against the
    bound and falls away from it, as the evidence of a nested candidate near its nesting
    point, is smooth in t and integrated to the rule's order.

    Examples
    --------
    >>> nodes, weights = _crowded_nodes(0.0, 90.0)
    >>> round(float(weights.sum()), 9), bool(nodes[3] < 0.9)     # the range, 4 nodes within 1 %
    (90.0, True)
    >>> round(float(np.sum(weights * np.exp(-nodes / 2.0))), 3)  # int_0^90 exp(-u/2) du = 2
    2.0
    """
    t, w = np.polynomial.legendre.leggauss(CONDITIONAL_NODES)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    offset = (hi - lo) * t ** CROWDING_POWER
    weights = w * CROWDING_POWER * (hi - lo) * t ** (CROWDING_POWER - 1)
    return (hi - offset if towards_upper else lo + offset), weights


def _node_terms(problem, least_squares, priors, name: str, nodes: np.ndarray, weights: np.ndarray,
                optima: dict[float, dict[str, float]]) -> list[float] | None:
    """ln of each node's weight x prior x the others' Laplace evidence with ``name`` fixed
    there (in the order of ``nodes``), fitted outward from the optimum, each from the
    nearest optimum in ``optima`` (which gains every node's); None if one is undefined."""
    terms = [math.nan] * len(nodes)
    for k in np.argsort(np.abs(nodes - least_squares.values[name])):  # outward from the optimum
        u = float(nodes[k])
        start = optima[min(optima, key=lambda done: abs(done - u))]
        reduced, fitted = _optimum_at(problem, priors, name, u, start)
        optima[u] = dict(fitted.values, **{name: u})
        inner = laplace_evidence(reduced, fitted, priors, conditional=False).log_evidence
        if not math.isfinite(inner):
            inner = _without_uninformed(reduced, fitted, priors)
        if not math.isfinite(inner):
            return None
        terms[k] = math.log(weights[k]) + priors[name].logpdf(u) + inner
    return terms


#: A parameter across whose prior the log-likelihood changes by less than this [ln units]
#: is integrated as its prior alone, a factor 1 (:func:`_without_uninformed`).
UNINFORMED_CHANGE = 0.05


def _without_uninformed(problem, least_squares, priors) -> float:
    """The corrected Laplace ln Z of a problem some of whose parameters the data do not
    inform at its optimum, NaN if it has none or the rest still has no Gaussian.

    At a quadrature node next to the nesting point (a pit's psi of 1e-4 deg) the model no
    longer depends on another parameter (the pits' coverage), whose curvature is then
    zero: Laplace's Gaussian does not exist, but the integral over that parameter is its
    prior's, 1, to within :data:`UNINFORMED_CHANGE` (the log-likelihood's largest change
    between 2 % and 98 % of its support). Such parameters are fixed at the optimum and
    the others' evidence is Laplace's."""
    flat = _uninformed(problem, least_squares.values, priors)
    if not flat:
        return math.nan
    reduced = problem.fixing(flat)
    from .least_squares import fit_least_squares

    fitted = fit_least_squares(reduced, start=least_squares.values, n_starts=1,
                               priors={n: priors[n] for n in reduced.free})
    return laplace_evidence(reduced, fitted, priors, conditional=False).log_evidence


def _uninformed(problem, values: Mapping[str, float], priors) -> dict[str, float]:
    """The model's own free parameters of bounded support across which the log-likelihood,
    the others held at ``values``, changes by less than :data:`UNINFORMED_CHANGE`, with
    their values."""
    names = list(problem.free)
    at = np.array([values[n] for n in names], float)
    level = problem.log_likelihood(at)
    flat = {}
    for name in (p.name for p in problem.base_model.params if p.name in names):
        lo, hi = _support(problem, priors[name], name)
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            continue
        changes = []
        for u in (lo + 0.02 * (hi - lo), hi - 0.02 * (hi - lo)):
            moved = at.copy()
            moved[names.index(name)] = u
            changes.append(abs(problem.log_likelihood(moved) - level))
        if max(changes) < UNINFORMED_CHANGE:
            flat[name] = float(values[name])
    return flat


def _optimum_at(problem, priors, name: str, value: float, start: Mapping[str, float]):
    """The problem with ``name`` fixed at ``value`` and its least squares (one start from
    ``start``, the priors as in the full fit)."""
    from .least_squares import fit_least_squares

    reduced = problem.fixing({name: value})
    return reduced, fit_least_squares(reduced, start=dict(start, **{name: value}), n_starts=1,
                                      priors={n: priors[n] for n in reduced.free})


class _NotTheMode(Exception):
    """A profile rose above the least-squares point by more than :data:`MODE_RISE`; ``values``
    is that point (every free parameter)."""

    def __init__(self, message: str, values: Mapping[str, float]):
        super().__init__(message)
        self.values = dict(values)


def _positive_definite(matrix: np.ndarray) -> bool:
    """Whether a covariance matrix is finite and positive definite (its Cholesky exists)."""
    if not np.all(np.isfinite(matrix)):
        return False
    try:
        np.linalg.cholesky(matrix)
    except np.linalg.LinAlgError:
        return False
    return True


def log_posterior(problem, priors, vector: np.ndarray) -> float:
    prior = sum(priors[n].logpdf(float(v)) for n, v in zip(problem.free, vector))
    return problem.log_likelihood(vector) + prior if math.isfinite(prior) else -math.inf


def _support(problem, prior, name: str) -> tuple[float, float]:
    """Where both the parameter's physical range and its prior allow it."""
    lo, hi = problem.spec(name).bounds
    return max(lo, getattr(prior, "lower", -math.inf)), min(hi, getattr(prior, "upper", math.inf))


def _log_mass_inside(mode: np.ndarray, covariance: np.ndarray, supports: list[tuple[float, float]]) -> float:
    """ln of the mass of N(mode, covariance) inside the box of ``supports``."""
    from scipy import stats

    sd = np.sqrt(np.diag(covariance))
    lows = np.array([lo for lo, _ in supports])
    highs = np.array([hi for _, hi in supports])
    near = ((mode - lows) < TRUNCATION_SDS * sd) | ((highs - mode) < TRUNCATION_SDS * sd)
    if not near.any():
        return 0.0
    index = np.flatnonzero(near)
    mean, sub = mode[index], covariance[np.ix_(index, index)]
    low = np.where(np.isfinite(lows[index]), lows[index], mean - 40 * sd[index])
    high = np.where(np.isfinite(highs[index]), highs[index], mean + 40 * sd[index])
    if len(index) == 1:
        s = float(sd[index[0]])
        mass = stats.norm.cdf(high[0], mean[0], s) - stats.norm.cdf(low[0], mean[0], s)
    else:
        try:
            mass = stats.multivariate_normal(mean, sub).cdf(high, lower_limit=low, rng=np.random.default_rng(0))
        except (np.linalg.LinAlgError, ValueError):  # numerically singular: the parameters one by one
            s = sd[index]
            mass = float(np.prod(stats.norm.cdf(high, mean, s) - stats.norm.cdf(low, mean, s)))
    return math.log(mass) if mass > 0 else -math.inf


def _shape_correction(problem, least_squares, priors, k: int, covariance: np.ndarray,
                      support: tuple[float, float], peak: float) -> float | None:
    """ln(profile integral / Gaussian integral) along parameter ``k``, or None when its
    profile is Gaussian or no bound is near (module docstring)."""
    from scipy import stats

    name = problem.free[k]
    centre = float(least_squares.values[name])
    sd = math.sqrt(covariance[k, k])
    lo, hi = support
    if not _near_bound(centre, sd, support):
        return None

    optima = {centre: dict(least_squares.values)}  # profiled values of ``name``: the others' optimum
    rises: dict[float, float] = {}

    def profile(x: float) -> float:
        if x not in rises:
            nearest = optima[min(optima, key=lambda done: abs(done - x))]
            value, optima[x] = _profile_log_posterior(problem, priors, name, x, nearest)
            rises[x] = value - peak
            if rises[x] > MODE_RISE:
                raise _NotTheMode(f"the profile of {name} at {x:g} is {rises[x]:.3g} above the least-squares point",
                                  optima[x])
        return rises[x]

    probes = [centre + s * sd for s in (-2, -1, 1, 2) if lo <= centre + s * sd <= hi]
    departure = max((abs(profile(x) + 0.5 * ((x - centre) / sd) ** 2) for x in probes), default=0.0)
    if departure <= SHAPE_TOLERANCE:
        return None
    integral = sum(_side_integral(profile, centre, edge, sd) for edge in (lo, hi))
    gaussian = math.sqrt(2 * math.pi) * sd * (stats.norm.cdf(hi, centre, sd) - stats.norm.cdf(lo, centre, sd))
    return math.log(integral) - math.log(gaussian) if integral > 0 and gaussian > 0 else None


def _near_bound(centre: float, sd: float, support: tuple[float, float]) -> bool:
    """Whether a bound of ``support`` lies within :data:`SHAPE_SDS` standard deviations of
    ``centre``, so that the parameter's profile is checked."""
    lo, hi = support
    return centre - lo < SHAPE_SDS * sd or hi - centre < SHAPE_SDS * sd


def _side_integral(profile, centre: float, edge: float, sd: float) -> float:
    """Integral of exp(profile) from ``centre`` towards ``edge``, out to where it is negligible."""
    if abs(edge - centre) < 1e-6 * sd:  # the mode is on this bound: nothing on this side
        return 0.0
    direction, distance = (1.0 if edge > centre else -1.0), abs(edge - centre)
    reach = sd
    while reach < distance and profile(centre + direction * reach) > -PROFILE_DEPTH:
        reach *= 2.0
    reach = min(reach, distance)
    # a mode held on a bound by a slope can fall by hundreds within one sd: the range is
    # halved while the profile falls by more than the depth across half of it (what lies
    # beyond is negligible), so that the nodes resolve it (exp(-30 t) on [0, 1] to 2e-7 with
    # 12 nodes; a Minnaert k held on 1 by a slope of 434 per sd, 0.3 % noise stated as
    # 0.03 %, was 0.03 off in ln Z with 24 nodes over the whole sd). The bound itself is
    # never evaluated: a parameter's range may be open there (a pit's psi > 0).
    while profile(centre + direction * 0.5 * reach) < -PROFILE_DEPTH:
        reach *= 0.5
    end = centre + direction * reach
    half = 0.5 * (end - centre)
    nodes = centre + half * (_NODES + 1.0)
    return abs(half) * float(sum(w * math.exp(profile(float(x))) for w, x in zip(_WEIGHTS, nodes)))


def _profile_log_posterior(problem, priors, name: str, value: float,
                           start: Mapping[str, float]) -> tuple[float, dict[str, float]]:
    """The log posterior maximised over the other free parameters, ``name`` held at
    ``value``, and the values there; the others start from ``start`` (the optimum at the
    nearest value already profiled: a profile's nodes are close, and a start near the
    optimum saves most of the least squares' iterations)."""
    values = dict(start, **{name: value})
    if len(problem.free) > 1:
        values.update(_optimum_at(problem, priors, name, value, start)[1].values)
    return log_posterior(problem, priors, np.array([values[n] for n in problem.free], float)), values


def scale_degenerate_factor(problem, least_squares, priors: Mapping[str, Any] | None = None) -> str | None:
    """The free parameter that only multiplies the free ``scale`` (relative radiance), if any.

    Tested directly: the prediction is unchanged (to 1e-9) when the parameter is multiplied
    by 0.9 and ``scale`` divided by 0.9 (rho of Lambert on relative radiance without a
    calibration prior: only rho x scale is determined). None where ``priors`` give
    ``scale`` a Gaussian prior (the calibration's): the prior determines the pair, whose
    posterior Laplace's Gaussian describes. (On the lab rig a covariance left undefined by
    another parameter, Oren-Nayar's sigma at 0, had sent such a fit to the product form,
    whose induced prior, a 1-D integral across a calibration prior 0.03 % wide, came out 0.)
    """
    from .priors import Normal

    if "scale" not in problem.free or isinstance((priors or {}).get("scale"), Normal):
        return None
    values = dict(least_squares.values)
    base = problem.predict(values)
    for name in problem.free:
        lo, hi = problem.spec(name).bounds
        if name in ("scale", problem.noise_parameter) or not (math.isfinite(lo) and math.isfinite(hi)):
            continue
        if not values[name] > 0 or not problem.spec(name).contains(0.9 * values[name]):
            continue
        moved = problem.predict(dict(values, **{name: 0.9 * values[name], "scale": values["scale"] / 0.9}))
        if np.allclose(moved, base, rtol=1e-9, atol=0.0):
            return name
    return None


class _ProductPrior:
    """Prior of ``scale`` when the factor is held at ``reference``: the density of
    ``factor x scale / reference`` under the two independent priors (a 1-D integral)."""

    lower, upper = 0.0, math.inf

    def __init__(self, factor_prior, scale_prior, factor_bounds: tuple[float, float], reference: float):
        self.factor_prior, self.scale_prior = factor_prior, scale_prior
        self.bounds, self.reference = factor_bounds, reference

    def logpdf(self, x: float) -> float:
        from scipy.integrate import quad

        if not x > 0:
            return -math.inf
        product = self.reference * float(x)
        lo, hi = max(self.bounds[0], 1e-300), self.bounds[1]
        s_lo, s_hi = getattr(self.scale_prior, "lower", 0.0), getattr(self.scale_prior, "upper", math.inf)
        lo, hi = max(lo, product / s_hi if s_hi > 0 else lo), min(hi, product / s_lo if s_lo > 0 else hi)
        if not lo < hi:
            return -math.inf

        def integrand(r: float) -> float:
            return math.exp(self.factor_prior.logpdf(r) + self.scale_prior.logpdf(product / r)) / r

        value = quad(integrand, lo, hi, limit=200, epsrel=1e-8)[0]
        return math.log(self.reference * value) if value > 0 else -math.inf


def _product_evidence(problem, least_squares, priors, factor: str) -> LaplaceEvidence:
    """Laplace evidence over ``factor x scale`` for an exactly degenerate pair.

    The factor is held at its least-squares value r0 and ``scale`` carries the product
    (``scale' = factor x scale / r0``), with the prior the two priors induce on it; the
    prior of the factor is integrated out in that induced prior, so nothing is counted
    twice.
    """
    from .least_squares import fit_least_squares

    reference = least_squares.values[factor]
    if not reference > 0:
        return LaplaceEvidence(math.nan)
    reduced = problem.fixing({factor: reference})
    reduced_ls = fit_least_squares(reduced, start=least_squares.values, n_starts=1)
    reduced_priors: dict[str, Any] = {n: p for n, p in priors.items() if n in reduced.free}
    reduced_priors["scale"] = _ProductPrior(priors[factor], priors["scale"], problem.spec(factor).bounds, reference)
    return laplace_evidence(reduced, reduced_ls, reduced_priors)


def _with_noise_curvature(problem, least_squares, priors) -> np.ndarray:
    """The covariance of a fit with a free extra noise: the least squares' for the other
    parameters (its Jacobian whitened by the total noise, the Gaussian priors in it) and
    the noise's own curvature, by finite differences with a step scaled to its value, the
    cross terms left out (a Gaussian likelihood's information between the mean's
    parameters and the variance's is zero where the variance does not depend on the mean,
    and small for a noise relative to it); the whole curvature by finite differences where
    the least squares' is not positive definite.

    The others' curvature by finite differences is at the mercy of any roughness of the
    likelihood at the step's scale: on the lab rig the holder's and the sample's own tilt
    along the swing axis, which only their priors tell apart, came out indefinite (an
    eigenvalue of -1.3), and the candidate's evidence fell to sampling."""
    from .curvature import inverse_hessian, steps_at_mode

    names = list(problem.free)
    k = names.index(problem.noise_parameter)
    others = [i for i in range(len(names)) if i != k]
    covariance = np.asarray(least_squares.covariance, float)
    block = covariance[np.ix_(others, others)]
    if not _positive_definite(block):
        return _numerical_covariance(problem, least_squares.values, priors, least_squares.stderr)
    mode = np.array([least_squares.values[n] for n in names], float)
    bounds = problem.spec(names[k]).bounds

    def along_noise(value: np.ndarray) -> float:
        point = mode.copy()
        point[k] = value[0]
        return -log_posterior(problem, priors, point)

    step = steps_at_mode([mode[k]], [least_squares.stderr.get(names[k], math.nan)], [bounds])
    noise = inverse_hessian(along_noise, mode[k:k + 1], [bounds], step)[0, 0]
    out = np.zeros((len(names), len(names)))
    out[np.ix_(others, others)] = block
    out[k, k] = noise
    return out


def _numerical_covariance(problem, values: Mapping[str, float], priors,
                          stderr: Mapping[str, float] | None = None) -> np.ndarray:
    """Inverse Hessian of -ln(likelihood x prior) at ``values`` by finite differences
    (:func:`gonio.fitting.curvature.inverse_hessian`): steps of a fraction of each
    parameter's range, the one this module's evidences were measured with against
    sampling, except for a free extra noise, whose posterior can be narrow against its
    range (3e-4 on [0, 10]): its step is scaled to its value
    (:func:`gonio.fitting.curvature.steps_at_mode`, ``stderr`` the least-squares standard
    errors where known)."""
    from .curvature import inverse_hessian, range_steps, steps_at_mode

    names = list(problem.free)
    mode = np.array([values[n] for n in names], float)
    bounds = [problem.spec(n).bounds for n in names]
    steps = range_steps(mode, bounds)
    if problem.noise_parameter in names:
        k = names.index(problem.noise_parameter)
        error = (stderr or {}).get(problem.noise_parameter, math.nan)
        steps[k] = min(steps[k], steps_at_mode([mode[k]], [error], [bounds[k]])[0])
    return inverse_hessian(lambda vector: -log_posterior(problem, priors, vector), mode, bounds, steps)


@dataclass(frozen=True)
class TemperedEvidence:
    """ln Z by sequential Monte Carlo (:func:`tempered_evidence`).

    Attributes
    ----------
    log_evidence : float
        ln Z [natural-log units] (NaN when the particles lost the posterior).
    error : float
        Its standard error, from the incremental weights of every stage [ln units].
    stages : int
        Temperatures from the prior (0) to the posterior (1).
    evaluations : int
        Likelihood evaluations.
    """

    log_evidence: float
    error: float
    stages: int
    evaluations: int


#: Particles of :func:`tempered_evidence`.
PARTICLES = 2000
#: Each temperature step keeps this share of the particles' effective sample size.
ESS_KEPT = 0.7
#: Metropolis moves per stage: enough for this many accepted moves per particle, within
#: the limits below.
ACCEPTED_MOVES = 5.0
#: Independent runs whose spread measures the estimate's error; more, up to MAX_RUNS,
#: while the error of their mean exceeds TARGET_ERROR [ln units] (half the selection
#: threshold of 1).
RUNS = 2
MAX_RUNS = 6
TARGET_ERROR = 0.5
MOVES_PER_STAGE = (2, 30)
#: Most temperature stages before the run is called lost.
MAX_STAGES = 200


def tempered_evidence(problem, priors, seed: int = 0, particles: int = PARTICLES,
                      runs: int = RUNS) -> TemperedEvidence:
    """ln Z by sequential Monte Carlo with likelihood tempering, where Laplace's approximation
    has no Gaussian to expand (a mode held on a bound by a slope, a parameter the data
    leave to its prior, a curved ridge such as ``rho`` x ``kd``).

    Particles drawn from the priors follow the path ``prior x L^beta`` from ``beta = 0`` to
    1 (Del Moral, Doucet & Jasra 2006; Chopin 2002), in the unit cube that the priors'
    quantile functions map onto the parameters (:meth:`Prior.quantile`; there the prior is
    uniform, and a log-uniform prior's decades are as easy to cross as a uniform one's).
    Each step raises ``beta`` as far as keeps :data:`ESS_KEPT` of the particles' effective
    sample size (bisection), multiplies Z by the mean incremental weight
    ``L^(beta' - beta)``, resamples (systematic) and moves every particle by
    differential-evolution Metropolis steps (:func:`_metropolis`), as many as give
    :data:`ACCEPTED_MOVES` accepted moves each. Unlike importance sampling around the
    least-squares point it needs no idea of the posterior's shape, and unlike nested
    sampling it evaluates the likelihood for all particles at once
    (:meth:`FitProblem.log_likelihood_batch`). The estimate is the mean of :data:`RUNS`
    independent runs, more (up to :data:`MAX_RUNS`) while the error of the mean exceeds
    :data:`TARGET_ERROR`; its ``error`` is the larger of the runs' scatter and the
    weights' own variance summed over the stages (Chopin 2002; it ignores the correlation
    resampling brings and understates the error where the moves mix slowly, which the
    scatter of the runs shows). Measured (docs/evidence.md, "Where Laplace has no
    Gaussian"): within 0.07 of grid quadrature on the ten synthetic cases of
    ``benchmarks/bench_evidence.py`` (1-3 parameters, 0.3-2 s); on CUReT sample 10 the
    7-parameter Oren-Nayar + Torrance-Sparrow candidate, whose Laplace evidence is
    undefined, gives 615.1 +- 1.0 against nested sampling's 616.6 +- 0.3 in six runs
    (137 s): its runs scatter by several units (a posterior the moves cross slowly), and
    the error says so.

    Parameters
    ----------
    problem : FitProblem
    priors : mapping of Prior
        The (proper) prior of every free parameter.
    seed : int
        Seed of the particles.
    particles : int
        Number of particles of each run.
    runs : int
        Independent runs (seeds ``seed``, ``seed + 1``, ...).

    References
    ----------
    P. Del Moral, A. Doucet, A. Jasra, "Sequential Monte Carlo samplers", J. R. Stat. Soc. B
    68, 411 (2006). C. J. F. ter Braak, "A Markov chain Monte Carlo version of the genetic
    algorithm Differential Evolution", Statistics and Computing 16, 239 (2006). N. Chopin, "A sequential particle filter method for static models",
    Biometrika 89, 539 (2002). G. O. Roberts, J. S. Rosenthal, "Optimal scaling for various
    Metropolis-Hastings algorithms", Statistical Science 16, 351 (2001) (the DE step size).
    """
    estimates = [_tempered_run(problem, priors, np.random.default_rng(seed + run), particles) for run in range(runs)]
    while _runs_error(estimates) > TARGET_ERROR and len(estimates) < MAX_RUNS:
        estimates.append(_tempered_run(problem, priors, np.random.default_rng(seed + len(estimates)), particles))
    values = np.array([e.log_evidence for e in estimates])
    stages, evaluations = max(e.stages for e in estimates), sum(e.evaluations for e in estimates)
    if not np.all(np.isfinite(values)):
        return TemperedEvidence(math.nan, math.nan, stages, evaluations)
    return TemperedEvidence(float(values.mean()), _runs_error(estimates), stages, evaluations)


def _runs_error(estimates: list[TemperedEvidence]) -> float:
    """The error of the runs' mean: the larger of the weights' own (combined) and the
    runs' scatter (half the spread of two; the standard error of the mean of more)."""
    values = np.array([e.log_evidence for e in estimates])
    if not np.all(np.isfinite(values)):
        return math.nan
    count = len(values)
    weights = math.sqrt(sum(e.error**2 for e in estimates)) / count
    if count == 1:
        return weights
    scatter = 0.5 * float(np.ptp(values)) if count == 2 else float(np.std(values, ddof=1)) / math.sqrt(count)
    return max(weights, scatter)


def _tempered_run(problem, priors, rng, particles: int) -> TemperedEvidence:
    """One sequential Monte Carlo run (:func:`tempered_evidence`)."""
    ordered = [priors[n] for n in problem.free]
    vectors = rng.random((particles, len(ordered)))  # the unit cube the priors' quantiles map
    log_prior, log_like = _prior_and_likelihood(problem, ordered, vectors)
    beta, log_z, variance, stages = 0.0, 0.0, 0.0, 0
    evaluations = particles
    while beta < 1.0:
        stages += 1
        if stages > MAX_STAGES or not np.isfinite(log_like).any():
            return TemperedEvidence(math.nan, math.nan, stages, evaluations)
        step = _next_step(log_like, 1.0 - beta)
        increment = np.where(np.isfinite(log_like), step * log_like, -np.inf)
        shift = np.max(increment)
        weight = np.exp(increment - shift)
        log_z += shift + math.log(np.mean(weight))
        variance += float(np.var(weight) / np.mean(weight) ** 2 / particles)
        beta = min(1.0, beta + step)
        keep = _systematic_resample(rng, weight / weight.sum())
        vectors, log_prior, log_like = vectors[keep], log_prior[keep], log_like[keep]
        vectors, log_prior, log_like, used = _metropolis(problem, ordered, rng, vectors, log_prior, log_like, beta)
        evaluations += used
    return TemperedEvidence(float(log_z), math.sqrt(variance), stages, evaluations)


def _next_step(log_like: np.ndarray, most: float) -> float:
    """The largest temperature increment (at most ``most``) keeping :data:`ESS_KEPT` of the ESS."""
    finite = np.isfinite(log_like)
    target = ESS_KEPT * np.count_nonzero(finite)

    def ess(step: float) -> float:
        w = np.exp(step * (log_like[finite] - np.max(log_like[finite])))
        return float(w.sum() ** 2 / np.sum(w * w))

    if ess(most) >= target:
        return most
    low, high = 0.0, most
    for _ in range(50):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if ess(middle) >= target else (low, middle)
    return max(low, 1e-12)


def _systematic_resample(rng, weight: np.ndarray) -> np.ndarray:
    """Indices of a systematic resample of normalised weights."""
    positions = (rng.random() + np.arange(len(weight))) / len(weight)
    return np.minimum(np.searchsorted(np.cumsum(weight), positions), len(weight) - 1)


def _metropolis(problem, priors, rng, vectors, log_prior, log_like, beta: float):
    """Metropolis moves of every particle at temperature ``beta``: differential-evolution
    proposals ``x + gamma (x_a - x_b) + e`` from two other particles (ter Braak 2006), which
    take the scale and the correlations of the current particles, ridges included, with a
    full jump (gamma = 1) every tenth move to hop between modes."""
    count, k = vectors.shape
    spread = np.std(vectors, axis=0) * 1e-4
    moves, accepted, used = 0, 0.0, 0
    low, high = MOVES_PER_STAGE
    while moves < high and (moves < low or accepted < ACCEPTED_MOVES):
        gamma = 1.0 if moves % 10 == 9 else 2.38 / math.sqrt(2 * k)
        a = rng.integers(0, count, count)
        b = (a + rng.integers(1, count, count)) % count
        proposal = vectors + gamma * (vectors[a] - vectors[b]) + spread * rng.standard_normal(vectors.shape)
        new_prior, new_like = _prior_and_likelihood(problem, priors, proposal)
        used += count
        log_ratio = (new_prior + beta * np.where(np.isfinite(new_like), new_like, -np.inf)) - (
            log_prior + beta * log_like)
        take = np.log(rng.random(count)) < np.nan_to_num(log_ratio, nan=-np.inf)
        vectors[take], log_prior[take], log_like[take] = proposal[take], new_prior[take], new_like[take]
        accepted += float(np.mean(take))
        moves += 1
    return vectors, log_prior, log_like, used


def _prior_and_likelihood(problem, priors, cube: np.ndarray, batch: int = 2000):
    """ln prior density in the unit cube (0 inside, -inf outside) and ln likelihood at the
    parameters the priors' quantiles map every row to (-inf outside the physical ranges)."""
    inside = np.all((cube >= 0.0) & (cube <= 1.0), axis=1)
    vectors = np.column_stack([prior.quantile(np.clip(cube[:, k], 0.0, 1.0)) for k, prior in enumerate(priors)])
    inside &= np.array([problem.in_bounds(v) for v in vectors], bool)
    log_prior = np.where(inside, 0.0, -math.inf)
    log_like = np.full(len(cube), -math.inf)
    index = np.flatnonzero(inside)
    for start in range(0, len(index), batch):
        rows = index[start:start + batch]
        log_like[rows] = problem.log_likelihood_batch(vectors[rows])
    return log_prior, log_like
