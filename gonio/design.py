"""Measurement design: geometries chosen for information about the parameters per second
of instrument time (``gonio design``).

For a gonioreflectometer the slow part is the instrument: every point costs a move, a
settling time and exposures, and a new lamp angle a long lamp move. :func:`design` chooses,
from every geometry the rig accepts (:class:`drivers.acceptance.GeometryRule`, the rule the
rig itself applies), the points that add the most expected information per second:

**Information.** With relative noise ``u`` per value (the realistic rig's budget is about
0.25 % of the value, docs/acquisition.md) the Fisher information of a point about the
parameters ``p`` is ``J J^T`` with ``J = d ln f / d p / u`` (``f`` the BRDF at the point);
a free calibration factor (prior width ``calibration``, the reference standard's) is one
more parameter every point shares, and so are the rig's alignment errors a fit of a real
rig's recording frees (:data:`ALIGNMENT_NUISANCE`: the zero offsets of the camera arm and
the lamp's polar axis and the sample's tilt, prior ``alignment_sd``; ``J`` holds the
derivative of the recorded value along each, through the rig's own geometry,
:func:`drivers.rig_geometry.misaligned_angles`). The design criterion is Bayesian
Ds-optimality: the expected log-determinant of the information about the parameters with
the calibration and the alignment marginalised, over draws from the prior (uniform over
the given ranges, Chaloner & Verdinelli 1995, section 2.1), the priors' own information
(``12 / width^2``) keeping it finite. Without the alignment a design piles its points where
the model is most sensitive, the grazing and normal extremes, which is also where a
misaligned rig's errors are largest: on the emulated rig such a design's fits came out
with reduced chi-square 8-80 and intervals that missed the truth (docs/design.md).

**Cost.** A point costs the protocol's settling and exposure time (as ``gonio plan``
estimates it) and the camera's move from its neighbour in the sweep; a new lamp angle
adds the lamp's move and the camera's return (the stage's trapezoidal profile,
:func:`gonio.protocols.move_time`).

**Greedy exchange.** Starting from no point, the point of largest expected gain per
second is added (the gain of a point needs no refit: by the matrix determinant lemma it
is ``log(1 + J^T F^-1 J)`` per prior draw) until the protocol's estimated time (the plan
of the protocol written so far) reaches the budget. Greedy selection of a D-criterion is
within ``1 - 1/e`` of the best subset for a monotone submodular set function (Nemhauser,
Wolsey & Fisher 1978); log det of an information matrix with a prior term is one.

The result is an ordinary protocol (:func:`design_protocol_text`): the reference standard
read at each lamp polar angle of the design (so that a calibration per incidence has its
own irradiance for each), blocks of lamp angles with their camera angles, in an order the plan visits in one sweep per block, with a
comment block saying how it was chosen, the expected 95 % widths at the prior's centre and
the estimated instrument time.

References
----------
A. C. Atkinson, A. N. Donev and R. D. Tobias, "Optimum Experimental Designs, with SAS",
Oxford University Press (2007), section 10.3 (Ds-optimality).
K. Chaloner and I. Verdinelli, "Bayesian experimental design: a review", Statistical
Science 10 (1995) 273-304.
G. L. Nemhauser, L. A. Wolsey and M. L. Fisher, "An analysis of approximations for
maximizing submodular set functions", Mathematical Programming 14 (1978) 265-294.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from . import models
from .protocols import Protocol, RigLimits, loads, move_time, plan, travel_seconds

__all__ = ["Design", "design", "design_protocol_text", "expected_widths", "DEFAULT_NOISE", "DEFAULT_CALIBRATION",
           "greedy_selection", "DEFAULT_ALIGNMENT_SD", "ALIGNMENT_NUISANCE", "DsCriterion", "candidate_geometries",
           "information_vectors", "prior_information", "PRIOR_DRAWS", "check_priors"]

#: Relative standard uncertainty of one value on the default (realistic) emulated rig [-]:
#: the median of its reduced budget (docs/acquisition.md; NIST STARR states 0.15-0.6 % at k=2).
DEFAULT_NOISE = 0.0025
#: Relative standard uncertainty of the calibration common to every value [-] (a
#: reference standard's certificate, 0.5 %).
DEFAULT_CALIBRATION = 0.005
#: Draws from the prior the criterion averages over.
PRIOR_DRAWS = 24
#: The rig's alignment errors a design is robust to (nuisance parameters): the zero
#: offsets of the camera arm and of the lamp's polar axis, and the sample's tilt in the
#: plane of incidence (gonio.fitting.rig_errors: what a fit of a real rig's recording
#: frees, ``--alignment``).
ALIGNMENT_NUISANCE = ("view_offset", "theta_i_offset", "tilt_x")
#: Prior standard deviation of each alignment error [deg]: the fit's default prior
#: (gonio.fitting.rig_errors.DEFAULT_PRIOR_SD).
DEFAULT_ALIGNMENT_SD = 0.5
#: Step of the derivatives along an alignment error [deg].
_ALIGNMENT_STEP = 0.01
#: Relative step of the finite-difference derivatives (of each parameter's prior width).
_STEP = 1e-4
#: The design's protocol: automatic exposure from 20 ms and a dark frame every 20 points,
#: as the shipped protocols of the paper's figures, the rig's defaults otherwise.
_HEADER = """[protocol]
name = "{name}"
description = "{description}"
[sample]
label = "{label}"
[exposure]
mode = "auto"
time = 0.02
[darks]
at_start = true
every = 20
"""
#: The reference standard a designed protocol measures: a 99 % diffuse standard (as the
#: shipped Fig 16 protocol) read at every lamp polar angle of the design, so that a
#: calibration per incidence (``gonio fit --calibration per-incidence``) has its own
#: irradiance for each.
_REFERENCE = """[reference]
label = "diffuse reflectance standard, 99 %"
reflectance = 0.99
geometries = [{geometries}]
"""
#: Camera angles tried, in order, for a reading of the reference standard [deg].
_REFERENCE_VIEWS = (-10.0, 10.0, -20.0, 20.0)
#: Relative prior width of the calibration factor without a reference standard: free.
_FREE_CALIBRATION = 1e3


@dataclass(frozen=True)
class Design:
    """A chosen set of geometries and what it is expected to give.

    Attributes
    ----------
    model : str
    parameters : tuple of str
        The designed-for parameters (those with a prior range).
    priors : dict
        ``{name: (low, high)}``.
    fixed : dict
        Values of the other parameters.
    points : tuple of (theta_i, phi_i, view)
        The chosen geometries [deg], in the order of the protocol.
    seconds : float
        The protocol's estimated instrument time [s] (``gonio plan``).
    widths : dict
        Expected 95 % interval widths at the prior's centre, by parameter.
    budget : float
        The time asked for [s].
    noise, calibration : float
        The relative noise per value and the calibration's relative uncertainty assumed.
    label : str
        The sample label of the protocol.
    reference : bool
        Whether the protocol measures the reference standard.
    alignment_sd : float
        Prior standard deviation of the rig's alignment errors marginalised [deg].
    blocks : dict
        ``{(theta_i, phi_i): [view, ...]}``: the points by lamp direction [deg].
    reference_at : tuple of float
        Lamp polar angles the reference standard is read at besides the design's own [deg].
    """

    model: str
    parameters: tuple[str, ...]
    priors: dict[str, tuple[float, float]]
    fixed: dict[str, float]
    points: tuple[tuple[float, float, float], ...]
    seconds: float
    widths: dict[str, float]
    budget: float
    noise: float = DEFAULT_NOISE
    calibration: float = DEFAULT_CALIBRATION
    label: str = "designed sample"
    reference: bool = True
    alignment_sd: float = DEFAULT_ALIGNMENT_SD
    blocks: dict[tuple[float, float], list[float]] = field(default_factory=dict, repr=False)
    reference_at: tuple[float, ...] = ()


def candidate_geometries(rig: RigLimits, theta_step: float, view_step: float, azimuths: Sequence[float],
                max_angle: float = 90.0) -> np.ndarray:
    """Every geometry (theta_i, phi_i, view) on the grid that the rig accepts, with lamp and
    camera within ``max_angle`` [deg] of the normal, (K, 3)."""
    rule = rig.geometry_rule
    thetas = np.arange(0.0, min(rig.lamp_theta_range[1] - 4.999, max_angle + 1e-9), theta_step)
    views = np.arange(-90.0 + view_step, 90.0 - view_step + 1e-9, view_step)
    views = views[np.abs(views) <= max_angle + 1e-9]

    out = []
    for phi_i in azimuths:
        for theta_i in thetas:
            if theta_i == 0.0 and phi_i != azimuths[0]:
                continue  # normal incidence has no azimuth
            reasons = rule.refusals(float(theta_i), float(phi_i), views.tolist())
            out += [(float(theta_i), float(phi_i), float(v)) for v, r in zip(views, reasons) if r is None]
    if not out:
        raise ValueError(f"max_angle {max_angle:g} deg: no lamp or camera angle left that the rig accepts on a "
                         f"{theta_step:g}/{view_step:g} deg grid; expected a larger angle")
    return np.array(out)


def _sample_frame(points: np.ndarray) -> tuple[np.ndarray, ...]:
    """Rig geometry (theta_i, phi_i, view) to the sample frame (theta_i, phi_i, theta_r, phi_r)."""
    view = points[:, 2]
    return points[:, 0], points[:, 1], np.abs(view), np.where(view >= 0, 0.0, 180.0)


def _log_jacobians(model: str, points: np.ndarray, draws: np.ndarray, names: Sequence[str],
                   fixed: Mapping[str, float], widths: np.ndarray) -> np.ndarray:
    """``d ln f / d p`` at every point for every prior draw, (D, K, P) (central differences
    of ``_STEP`` times each prior width, inside the bounds)."""
    frozen = models.get(model).at(*_sample_frame(points))
    base = {k: float(v) for k, v in fixed.items()}

    def log_f(values: np.ndarray) -> np.ndarray:
        params = {**base, **{n: values[:, [k]] for k, n in enumerate(names)}}
        return np.log(np.maximum(frozen(**params), 1e-300))

    out = np.empty((draws.shape[0], points.shape[0], len(names)))
    bounds = [models.get(model).param(n).bounds for n in names]
    for k, (low, high) in enumerate(bounds):
        h = _STEP * widths[k]
        up, down = draws.copy(), draws.copy()
        up[:, k] = np.minimum(draws[:, k] + h, high)
        down[:, k] = np.maximum(draws[:, k] - h, low)
        out[:, :, k] = (log_f(up) - log_f(down)) / (up[:, [k]] - down[:, [k]])
    return out


def _prior_draws(priors: Mapping[str, tuple[float, float]], count: int, seed: int) -> np.ndarray:
    """A Latin hypercube of ``count`` draws from the uniform priors, (count, P)."""
    rng = np.random.default_rng(seed)
    ranges = np.array(list(priors.values()), float)
    strata = (np.argsort(rng.random((count, len(ranges))), axis=0) + rng.random((count, len(ranges)))) / count
    return ranges[:, 0] + strata * (ranges[:, 1] - ranges[:, 0])


def _alignment_jacobians(model: str, points: np.ndarray, draws: np.ndarray, names: Sequence[str],
                         fixed: Mapping[str, float], alignment: Sequence[str]) -> np.ndarray:
    """``d ln(value) / d e`` for each alignment error ``e`` [1/deg], (D, K, A): the value a
    reduced recording holds is ``f(true geometry) cos(theta_i,true) / cos(theta_i,read)``
    (gonio.fitting.rig_errors), with the true geometry of a rig misaligned by ``e``
    (:func:`drivers.rig_geometry.misaligned_angles`), central differences of
    :data:`_ALIGNMENT_STEP` about an aligned rig."""
    from drivers.rig_geometry import misaligned_angles

    spec = models.get(model)
    base = {k: float(v) for k, v in fixed.items()}
    params = {**base, **{n: draws[:, [k]] for k, n in enumerate(names)}}
    read = _sample_frame(points)

    def log_value(error: str, step: float) -> np.ndarray:
        true = misaligned_angles(*read, **{error: step})
        behind = true[0] >= 90.0
        value = spec(*(np.where(behind, 89.9, t) if k == 0 else t for k, t in enumerate(true)), **params)
        return np.log(np.maximum(value * np.cos(np.radians(np.minimum(true[0], 89.9))), 1e-300))

    out = np.empty((draws.shape[0], points.shape[0], len(alignment)))
    for k, error in enumerate(alignment):
        out[:, :, k] = (log_value(error, _ALIGNMENT_STEP) - log_value(error, -_ALIGNMENT_STEP)) / (2 * _ALIGNMENT_STEP)
    return out


def _information(jacobians: np.ndarray, alignment: np.ndarray, noise: float) -> np.ndarray:
    """Per-point information vectors, ``[d ln f / d p, 1, d ln f / d e] / noise``: the
    parameters, the calibration factor every value shares, the alignment errors; shape
    (D, K, P + 1 + A)."""
    ones = np.ones(jacobians.shape[:2] + (1,))
    return np.concatenate([jacobians, ones, alignment], axis=2) / noise


def prior_information(widths: np.ndarray, calibration: float, alignment_sd: float, count: int) -> np.ndarray:
    """The priors' own information: ``12 / width^2`` (a uniform prior's variance),
    ``1 / calibration^2`` and ``1 / alignment_sd^2`` for each of ``count`` alignment errors."""
    return np.diag(np.concatenate([12.0 / widths**2, [1.0 / calibration**2], np.full(count, 1.0 / alignment_sd**2 if count else 0.0)]))


def information_vectors(model: str, points: np.ndarray, draws: np.ndarray, names: Sequence[str],
                        fixed: Mapping[str, float], widths: np.ndarray, noise: float,
                        alignment: Sequence[str]) -> np.ndarray:
    """The information vectors of ``points`` for every prior draw (:func:`_information`)."""
    return _information(_log_jacobians(model, points, draws, names, fixed, widths),
                        _alignment_jacobians(model, points, draws, names, fixed, alignment), noise)


def expected_widths(model: str, points: Sequence[tuple[float, float, float]],
                    priors: Mapping[str, tuple[float, float]], fixed: Mapping[str, float] | None = None,
                    noise: float = DEFAULT_NOISE, calibration: float = DEFAULT_CALIBRATION,
                    at: Mapping[str, float] | None = None,
                    alignment_sd: float = DEFAULT_ALIGNMENT_SD) -> dict[str, float]:
    """Expected 95 % interval widths (``2 x 1.96`` standard deviations of the Laplace
    approximation: the inverse of the information with the priors') of the parameters with
    a prior range, measured at ``points`` (rig geometry, ``(theta_i, phi_i, view)`` [deg]),
    at the parameter values ``at`` (default: the centre of each range), the calibration
    and the rig's alignment errors (:data:`ALIGNMENT_NUISANCE`, prior ``alignment_sd``
    [deg]; 0: an aligned rig) marginalised.

    >>> w = expected_widths("lambert", [(30, 0, v) for v in (-40, 0, 40)], {"rho": (0.5, 1.0)})
    >>> 0.0 < w["rho"] < 0.05
    True
    """
    names = list(priors)
    widths = np.array([high - low for low, high in priors.values()], float)
    centre = np.array([[(at or {}).get(n, 0.5 * (low + high)) for n, (low, high) in priors.items()]])
    geometry = np.asarray(points, float).reshape(-1, 3)
    alignment = ALIGNMENT_NUISANCE if alignment_sd > 0 else ()
    vectors = information_vectors(model, geometry, centre, names, fixed or {}, widths, noise, alignment)[0]
    prior = prior_information(widths, calibration, alignment_sd, len(alignment))
    covariance = np.linalg.inv(vectors.T @ vectors + prior)
    return {n: float(2 * 1.96 * math.sqrt(covariance[k, k])) for k, n in enumerate(names)}


def _block_cost(rig: RigLimits, chosen_thetas: set[tuple[float, float]], key: tuple[float, float]) -> float:
    """Time a new lamp direction adds [s]: the lamp's move from the nearest chosen one and
    the camera's return across its swing."""
    if key in chosen_thetas:
        return 0.0
    v, a = rig.estimate_velocity, rig.estimate_acceleration
    nearest = min((abs(key[0] - t) + abs(key[1] - p) for t, p in chosen_thetas), default=key[0])
    return move_time(nearest, v, a) + move_time(90.0, v, a)


def design(model: str, priors: Mapping[str, tuple[float, float]], budget: float,
           fixed: Mapping[str, float] | None = None, rig: RigLimits | None = None, noise: float = DEFAULT_NOISE,
           calibration: float = DEFAULT_CALIBRATION, theta_step: float = 5.0, view_step: float = 5.0,
           azimuths: Sequence[float] = (0.0,), draws: int = PRIOR_DRAWS, seed: int = 0,
           label: str = "designed sample", reference: bool = True,
           alignment_sd: float = DEFAULT_ALIGNMENT_SD, max_angle: float = 90.0,
           reference_at: Sequence[float] = ()) -> Design:
    """Choose geometries for ``model``'s parameters within ``budget`` seconds (module notes).

    Parameters
    ----------
    model : str
        Registered model name.
    priors : mapping
        ``{parameter: (low, high)}``: the parameters designed for, with their prior ranges
        (uniform); the others are held at ``fixed`` or their defaults.
    budget : float
        Instrument time [s] the protocol may take (``gonio plan``'s estimate, lamp warm-up
        not included).
    fixed : mapping, optional
        Values of parameters without a prior range.
    rig : RigLimits, optional
        Limits, separation and timing (default: the emulated rig's).
    noise, calibration : float
        Relative noise per value, relative uncertainty of the common calibration [-].
    theta_step, view_step : float
        Grid of lamp polar angles and camera angles considered [deg].
    azimuths : sequence of float
        Lamp azimuths considered [deg] (0: the plane of incidence; others measure out of it).
    draws, seed : int
        Prior draws of the criterion and their seed.
    label : str
        The sample label of the protocol.
    reference : bool
        Measure the reference standard (absolute calibration; its swaps cost two of the
        rig's ``remount_time``). Without it the calibration factor is free (relative
        values only), whatever ``calibration`` says.
    alignment_sd : float
        Prior standard deviation of the rig's alignment errors the design is robust to
        (:data:`ALIGNMENT_NUISANCE`) [deg]; 0 designs for a perfectly aligned rig.
    max_angle : float
        Largest lamp polar angle and camera angle from the normal considered [deg] (BRDF
        studies often stop at 75-80 deg, where a real sample's texture and the rig's stray
        light start to show, docs/design.md).
    reference_at : sequence of float
        Lamp polar angles at which to read the reference standard besides the design's own
        [deg]: the angles a later adaptive run (:mod:`gonio.adaptive`) may add points at,
        when it calibrates per incidence. Their readings count in the budget.

    Raises
    ------
    ValueError
        An unknown model or parameter, an empty or out-of-bounds range, or a budget too
        small for one point.
    """
    rig = rig or RigLimits()
    calibration = calibration if reference else _FREE_CALIBRATION
    spec = models.get(model)
    fixed = dict(fixed or {})
    priors = {name: (float(low), float(high)) for name, (low, high) in priors.items()}
    check_priors(spec, priors, fixed)
    names = list(priors)
    widths = np.array([high - low for low, high in priors.values()])
    alignment = ALIGNMENT_NUISANCE if alignment_sd > 0 else ()
    candidates = candidate_geometries(rig, theta_step, view_step, azimuths, max_angle)
    vectors = information_vectors(model, candidates, _prior_draws(priors, draws, seed), names, fixed, widths, noise,
                                  alignment)
    criterion = DsCriterion(vectors, prior_information(widths, calibration, alignment_sd, len(alignment)),
                             len(names))
    reference_at = _checked_reference_angles(reference_at, rig) if reference else ()
    chosen, protocol_seconds = greedy_selection(
        candidates, rig, budget, criterion.gains, criterion.add,
        lambda points: plan(_protocol(model, points, label, reference, reference_at)).estimated_seconds)
    if not chosen:
        shortest = plan(_protocol(model, candidates[:1], label, reference, reference_at)).estimated_seconds
        raise ValueError(f"budget {budget:g} s: too short for one point ({shortest:.0f} s with "
                         f"{'the reference standard and ' if reference else ''}the darks); give a longer budget")
    ordered = _ordered(candidates[chosen])
    widths_expected = expected_widths(model, ordered, priors, fixed, noise, calibration, alignment_sd=alignment_sd)
    return Design(model, tuple(names), priors, fixed, tuple(map(tuple, ordered.tolist())), protocol_seconds,
                  widths_expected, float(budget), noise, calibration, label, reference, alignment_sd,
                  _grouped(ordered), reference_at)


def greedy_selection(candidates: np.ndarray, rig: RigLimits, budget: float, gains: Callable[[], np.ndarray],
                     add: Callable[[int], None], seconds_of: Callable[[np.ndarray], float]) -> tuple[list[int], float]:
    """Choose candidates by expected gain per second until the budget is spent.

    Each round takes the candidate of largest ``gains() / cost`` (its settling and
    exposure, plus a new lamp direction's moves, :func:`_block_cost`); it is kept when
    ``seconds_of`` (the plan's estimate of the protocol of the points so far) stays within
    ``budget`` [s], and ``add(index)`` updates the criterion; a point too dear now is
    passed over, a cheaper one may still fit.

    Returns
    -------
    chosen : list of int
        Indices into ``candidates`` in the order chosen.
    seconds : float
        The estimate of the chosen points' protocol [s].
    """
    per_point = _point_seconds(rig, candidates[:, 0])
    chosen: list[int] = []
    blocks: set[tuple[float, float]] = set()
    available = np.ones(len(candidates), bool)
    seconds = 0.0
    while available.any():
        cost = per_point + np.array([_block_cost(rig, blocks, (c[0], c[1])) for c in candidates])
        best = int(np.argmax(np.where(available, gains() / cost, -np.inf)))
        available[best] = False
        trial = seconds_of(candidates[chosen + [best]])
        if trial > budget:
            continue
        chosen, seconds = chosen + [best], trial
        blocks.add((candidates[best][0], candidates[best][1]))
        add(best)
    return chosen, seconds


class DsCriterion:
    """The expected gain of each candidate in ``log det`` of the parameters' information
    with the nuisance (calibration, alignment) marginalised: Ds-optimality (Atkinson,
    Donev & Tobias 2007, section 10.3). With ``F`` the information of everything and
    ``F_n`` its nuisance block (``prior``: the information before any candidate, (P, P) or
    one per prior draw, (D, P, P)), the gain of a point ``v`` is
    ``log(1 + v^T F^-1 v) - log(1 + v_n^T F_n^-1 v_n)`` per prior draw (the matrix
    determinant lemma); both inverses follow each choice by a Sherman-Morrison update."""

    def __init__(self, vectors: np.ndarray, prior: np.ndarray, interest: int) -> None:
        self.vectors, self.interest = vectors, interest
        shape = (vectors.shape[0],) + prior.shape[-2:]
        prior = np.broadcast_to(prior, shape)  # one information for every draw, or one per draw (D, P, P)
        self.inverse = np.linalg.inv(prior)
        self.nuisance_inverse = np.linalg.inv(prior[:, interest:, interest:])

    def gains(self) -> np.ndarray:
        """Mean over the draws of each candidate's gain, (K,)."""
        whole = np.einsum("dkp,dpq,dkq->dk", self.vectors, self.inverse, self.vectors)
        nuisance = self.vectors[:, :, self.interest:]
        part = np.einsum("dkp,dpq,dkq->dk", nuisance, self.nuisance_inverse, nuisance)
        return np.mean(np.log1p(whole) - np.log1p(part), axis=0)

    def add(self, index: int) -> None:
        """Account for candidate ``index`` as measured."""
        _rank_one_update(self.inverse, self.vectors[:, index, :])
        _rank_one_update(self.nuisance_inverse, self.vectors[:, index, self.interest:])


def _rank_one_update(inverse: np.ndarray, v: np.ndarray) -> None:
    """``inverse`` (D, P, P) of ``F`` becomes that of ``F + v v^T`` in place (Sherman-Morrison)."""
    fv = np.einsum("dpq,dq->dp", inverse, v)
    inverse -= np.einsum("dp,dq->dpq", fv, fv) / (1.0 + np.einsum("dp,dp->d", v, fv))[:, None, None]


def check_priors(spec, priors: Mapping[str, tuple[float, float]], fixed: Mapping[str, float]) -> None:
    """Refuse prior ranges (``{name: (low, high)}``) or fixed values that are not the
    parameters of the model ``spec``, or ranges outside its bounds, naming them
    (``ValueError``)."""
    if not priors:
        raise ValueError(f"no prior range given: name the parameters of {spec.name!r} to design for, with their "
                         "ranges (e.g. sigma=10:45)")
    for name, (low, high) in priors.items():
        if name not in spec.param_names:
            raise ValueError(f"{name!r} is not a parameter of {spec.name!r}; its parameters are {list(spec.param_names)}")
        lo, hi = spec.param(name).bounds
        if not (lo <= low < high <= hi):
            raise ValueError(f"prior range {name}={low:g}:{high:g}: expected low < high within the bounds "
                             f"[{lo:g}, {hi:g}]")
    unknown = sorted(set(fixed) - set(spec.param_names))
    if unknown:
        raise ValueError(f"fixed {unknown}: not parameters of {spec.name!r}")


def _point_seconds(rig: RigLimits, theta_i: np.ndarray) -> np.ndarray:
    """Settling and exposure time of one more point at each lamp polar angle ``theta_i``
    with the design's exposure [s]: the plan's estimate of two points less that of one,
    less the camera's move between them (an automatic exposure is longer at grazing
    incidence, :func:`gonio.protocols.plan`)."""
    def seconds(theta: float, views: str) -> float:
        text = (_HEADER.format(name="x", description="x", label="x")
                + f"[[block]]\ntheta_i = {theta:g}\nview = [{views}]\n")
        return plan(loads(text)).estimated_seconds

    move = travel_seconds((0.0, 0.0, -40.0), (0.0, 0.0, -35.0), rig)
    each = {t: seconds(t, "-40, -35") - seconds(t, "-40") - move for t in np.unique(theta_i).tolist()}
    return np.array([each[t] for t in theta_i.tolist()])


def _ordered(points: np.ndarray) -> np.ndarray:
    """Points by lamp direction (azimuth, polar angle), each block's views ascending: one
    sweep of the camera per lamp position."""
    order = np.lexsort((points[:, 2], points[:, 0], points[:, 1]))
    return points[order]


def _grouped(points: np.ndarray) -> dict[tuple[float, float], list[float]]:
    blocks: dict[tuple[float, float], list[float]] = {}
    for theta_i, phi_i, view in points.tolist():
        blocks.setdefault((theta_i, phi_i), []).append(view)
    return blocks


def _protocol(model: str, points: np.ndarray, label: str, reference: bool,
              reference_at: Sequence[float] = ()) -> Protocol:
    return loads(_blocks_text(model, _grouped(_ordered(points)), label, reference, reference_at), source="design")


def _checked_reference_angles(angles: Sequence[float], rig: RigLimits) -> tuple[float, ...]:
    """``reference_at`` as floats, each a lamp polar angle the rig can read the standard at."""
    rule = rig.geometry_rule
    out = tuple(float(a) for a in angles)
    for theta_i in out:
        if not (math.isfinite(theta_i) and any(rule.refusal(theta_i, 0.0, v) is None for v in _REFERENCE_VIEWS)):
            raise ValueError(f"reference_at {theta_i:g} deg: the rig cannot read the reference standard at that lamp "
                             f"angle (camera at {', '.join(f'{v:g}' for v in _REFERENCE_VIEWS)} deg); expected lamp "
                             "polar angles within its range")
    return out


def _reference_text(blocks: Mapping[tuple[float, float], list[float]], reference_at: Sequence[float] = ()) -> str:
    """The ``[reference]`` section: the standard at each lamp polar angle of ``blocks`` and
    of ``reference_at``, in the plane of incidence, at the first camera angle of
    :data:`_REFERENCE_VIEWS` the rig accepts."""
    rule = RigLimits().geometry_rule
    geometries = []
    for theta_i in sorted({theta for theta, _ in blocks} | set(reference_at)):
        view = next((v for v in _REFERENCE_VIEWS if rule.refusal(theta_i, 0.0, v) is None), None)
        if view is not None:
            geometries.append(f"[{theta_i:g}, 0, {view:g}]")
    return _REFERENCE.format(geometries=", ".join(geometries))


def _blocks_text(model: str, blocks: Mapping[tuple[float, float], list[float]], label: str, reference: bool,
                 reference_at: Sequence[float] = ()) -> str:
    text = _HEADER.format(name=f"design-{model}", description=f"geometries designed for {model} (gonio design)",
                          label=label) + (_reference_text(blocks, reference_at) if reference else "")
    for (theta_i, phi_i), views in blocks.items():
        text += (f"[[block]]\nname = \"theta_i={theta_i:g}, phi_i={phi_i:g}\"\ntheta_i = {theta_i:g}\n"
                 f"phi_i = {phi_i:g}\nview = [{', '.join(f'{v:g}' for v in views)}]\n")
    return text


def _alignment_words(alignment_sd: float) -> str:
    if alignment_sd <= 0:
        return "a perfectly aligned rig"
    return f"alignment errors {', '.join(ALIGNMENT_NUISANCE)} of {alignment_sd:g} deg marginalised"


def design_protocol_text(result: Design) -> str:
    """The design as a protocol file: a comment block (how it was chosen, the expected 95 %
    widths at the prior's centre, the estimated time), then the blocks."""
    priors = ", ".join(f"{n}={lo:g}:{hi:g}" for n, (lo, hi) in result.priors.items())
    fixed = ", ".join(f"{n}={v:g}" for n, v in result.fixed.items()) or "none (defaults)"
    widths = ", ".join(f"{n} {w:.3g}" for n, w in result.widths.items())
    comment = [
        f"# Designed by gonio design for {result.model} with priors {priors}; fixed: {fixed}.",
        f"# Criterion: expected log det of the parameters' Fisher information over {PRIOR_DRAWS} prior draws per",
        f"# second of instrument time (greedy; relative noise {result.noise:g} per value, calibration "
        f"{result.calibration:g},",
        f"# {_alignment_words(result.alignment_sd)}).",
        f"# Expected 95 % interval widths at the prior's centre: {widths}.",
        f"# {len(result.points)} points, estimated instrument time {result.seconds:.0f} s (budget {result.budget:.0f} s;",
        "# gonio plan's estimate, lamp warm-up not included). docs/design.md.",
    ]
    if result.reference_at:
        comment.append(f"# The reference standard is read at {', '.join(f'{a:g}' for a in result.reference_at)} deg "
                       "too (--reference-at).")
    return "\n".join(comment) + "\n" + _blocks_text(result.model, result.blocks, result.label, result.reference,
                                                   result.reference_at)
