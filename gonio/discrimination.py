"""Measurement design for telling models apart (``gonio design --discriminate``).

Where :mod:`gonio.design` chooses geometries that narrow one model's parameters, this
module chooses those that best separate rival models, per second of instrument time.

**Criterion.** For each ordered pair of candidates (``A`` the truth, ``B`` the rival) and
each draw of ``A``'s parameters from the prior, the rival is fitted to ``A``'s values over
every geometry the rig accepts (least squares of ``ln f``, with a free calibration factor
and ``B``'s parameters that have a prior range free within it): the residuals ``r_k`` (in
units of the relative noise per value) and the rival's Jacobian ``j_k`` there. On a design
``S`` the rival refits, to first order, and its chi-square excess is

    lambda(S) = sum_S r_k^2 - b^T A^-1 b,   A = sum_S j_k j_k^T + P,   b = sum_S j_k r_k

(``P`` the rival's prior information: its parameters' uniform ranges, the calibration's
0.5 %). This is T-optimality (Atkinson & Fedorov 1975) with the rival refitted on the
design, averaged over the prior (Bayesian, as Ponce de Leon & Atkinson 1991). ``lambda`` is
the non-centrality of the rival's chi-square: a rival whose best fit misses by
``lambda >> 1`` is rejected. The criterion is the sum over pairs of the mean over draws of
``log(1 + lambda)``, so that the hardest pair gains most from a point; a pair whose rival
contains the truth (``oren-nayar`` at sigma = 0 is ``lambert``) has ``lambda = 0`` whatever
the design and adds nothing.

**Selection.** Greedy by gain per second, each candidate's gain exact for the rank-one
update of ``A`` (Sherman-Morrison), the time from the protocol's plan, as in
:func:`gonio.design.design`.

References
----------
A. C. Atkinson and V. V. Fedorov, "The design of experiments for discriminating between
two rival models", Biometrika 62 (1975) 57-70.
A. C. Ponce de Leon and A. C. Atkinson, "Optimum experimental design for discriminating
between two rival models in the presence of prior information", Biometrika 78 (1991)
601-608.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from scipy.optimize import least_squares

from . import models
from .design import (ALIGNMENT_NUISANCE, DEFAULT_ALIGNMENT_SD, DEFAULT_CALIBRATION, DEFAULT_NOISE, _alignment_jacobians,
                     _blocks_text, candidate_geometries, _grouped, _ordered, _prior_draws, _protocol, _sample_frame,
                     greedy_selection)
from .protocols import RigLimits, plan

__all__ = ["Discrimination", "discriminate", "discrimination_protocol_text", "DISCRIMINATION_DRAWS"]

#: Draws of each true model's parameters from the prior.
DISCRIMINATION_DRAWS = 8
#: Relative step of the rival's finite-difference Jacobian (of each parameter's range).
_STEP = 1e-4


@dataclass(frozen=True)
class Discrimination:
    """Geometries chosen to tell models apart, and the separation expected.

    Attributes
    ----------
    models : tuple of str
    priors, fixed : dict
        Prior ranges and fixed values, by parameter name (a model uses those it has).
    points : tuple of (theta_i, phi_i, view)
        The chosen geometries [deg], in the order of the protocol.
    seconds, budget : float
        The protocol's estimated instrument time and the budget [s].
    separations : dict
        ``{"A|B": lambda}``: the median over prior draws of the chi-square excess of rival
        ``B`` fitted to ``A``'s values at the design (0: ``B`` contains ``A``).
    noise, calibration, alignment_sd : float
    label : str
    reference : bool
    """

    models: tuple[str, ...]
    priors: dict[str, tuple[float, float]]
    fixed: dict[str, float]
    points: tuple[tuple[float, float, float], ...]
    seconds: float
    budget: float
    separations: dict[str, float]
    noise: float = DEFAULT_NOISE
    calibration: float = DEFAULT_CALIBRATION
    label: str = "designed sample"
    reference: bool = True
    alignment_sd: float = DEFAULT_ALIGNMENT_SD
    blocks: dict[tuple[float, float], list[float]] = field(default_factory=dict, repr=False)


def _log_values(name: str, frame: tuple[np.ndarray, ...], params: Mapping[str, np.ndarray]) -> np.ndarray:
    return np.log(np.maximum(models.get(name).at(*frame)(**params), 1e-300))


def _free(name: str, priors: Mapping[str, tuple[float, float]]) -> list[str]:
    return [p for p in models.get(name).param_names if p in priors]


def _rival_fit(rival: str, target: np.ndarray, points: np.ndarray, priors, fixed, noise: float,
               alignment: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Residuals ``r`` (K,) and Jacobian ``J`` (K, P + 1 + A) of ``rival``'s best fit to the
    log values ``target``, in units of ``noise``: the rival's parameters, the calibration,
    the rig's alignment errors (with which a fit of a real rig's recording can also bend
    the rival toward the data)."""
    frame = _sample_frame(points)
    names = _free(rival, priors)
    base = {k: v for k, v in fixed.items() if k in models.get(rival).param_names}
    low = np.array([priors[n][0] for n in names] + [-1.0])
    high = np.array([priors[n][1] for n in names] + [1.0])

    def residual(x: np.ndarray) -> np.ndarray:
        params = {**base, **{n: x[k] for k, n in enumerate(names)}}
        return (target - _log_values(rival, frame, params) - x[-1]) / noise

    best = None
    for fraction in (0.5, 0.2, 0.8):
        start = np.append(low[:-1] + fraction * (high[:-1] - low[:-1]), 0.0)
        fit = least_squares(residual, start, bounds=(low, high), x_scale=np.append(high[:-1] - low[:-1], 0.01))
        best = fit if best is None or fit.cost < best.cost else best
    x = best.x
    jacobian = np.empty((target.size, len(names) + 1))
    for k in range(len(names)):
        h = _STEP * (high[k] - low[k])
        up, down = x.copy(), x.copy()
        up[k], down[k] = min(x[k] + h, high[k]), max(x[k] - h, low[k])
        jacobian[:, k] = -(residual(up) - residual(down)) / (up[k] - down[k])
    jacobian[:, -1] = 1.0 / noise
    if alignment:
        fitted = np.array([x[:-1]])
        tilt = _alignment_jacobians(rival, points, fitted, names, base, alignment)[0] / noise
        jacobian = np.concatenate([jacobian, tilt], axis=1)
    return residual(x), jacobian


class _Separation:
    """``lambda(S)`` of one (truth draw, rival) and its exact gain for each candidate."""

    def __init__(self, residual: np.ndarray, jacobian: np.ndarray, prior: np.ndarray) -> None:
        self.r, self.j = residual, jacobian
        self.inverse = np.linalg.inv(prior)
        self.b = np.zeros(jacobian.shape[1])
        self.s = 0.0

    @property
    def value(self) -> float:
        return max(self.s - self.b @ self.inverse @ self.b, 0.0)

    def values_with_each(self) -> np.ndarray:
        """``lambda(S + k)`` for every candidate ``k``, (K,)."""
        u = self.j @ self.inverse  # A^-1 j_k (A symmetric)
        denominator = 1.0 + np.einsum("kp,kp->k", self.j, u)
        b = self.b + self.j * self.r[:, None]
        quadratic = np.einsum("kp,pq,kq->k", b, self.inverse, b) - np.einsum("kp,kp->k", u, b) ** 2 / denominator
        return np.maximum(self.s + self.r**2 - quadratic, 0.0)

    def add(self, k: int) -> None:
        j = self.j[k]
        u = self.inverse @ j
        self.inverse -= np.outer(u, u) / (1.0 + j @ u)
        self.b += j * self.r[k]
        self.s += self.r[k] ** 2


def discriminate(candidates: Sequence[str], priors: Mapping[str, tuple[float, float]], budget: float,
                 fixed: Mapping[str, float] | None = None, rig: RigLimits | None = None,
                 noise: float = DEFAULT_NOISE, calibration: float = DEFAULT_CALIBRATION, theta_step: float = 5.0,
                 view_step: float = 5.0, azimuths: Sequence[float] = (0.0,), draws: int = DISCRIMINATION_DRAWS,
                 seed: int = 0, label: str = "designed sample", reference: bool = True,
                 alignment_sd: float = DEFAULT_ALIGNMENT_SD, max_angle: float = 90.0) -> Discrimination:
    """Choose geometries that best tell ``candidates`` apart within ``budget`` seconds
    (module notes).

    Parameters
    ----------
    candidates : sequence of str
        Two or more registered model names.
    priors : mapping
        ``{parameter: (low, high)}`` shared by name: each model draws (as the truth) and
        fits (as the rival) those of its parameters named here; the others are held at
        ``fixed`` or their defaults.
    budget, fixed, rig, noise, calibration, theta_step, view_step, azimuths, seed, label, reference, alignment_sd, max_angle
        As :func:`gonio.design.design` (the rival may use the alignment errors too).
    draws : int
        Draws of each true model's parameters.

    Raises
    ------
    ValueError
        Fewer than two candidates, an unknown model, a candidate with no parameter in
        ``priors`` and nothing to fit, or a budget too short for one point.
    """
    rig = rig or RigLimits()
    names = list(dict.fromkeys(candidates))
    if len(names) < 2:
        raise ValueError(f"--discriminate {','.join(candidates)}: expected two or more models to tell apart")
    for name in names:
        models.get(name)  # an unknown name raises, listing the models
    priors = {k: (float(lo), float(hi)) for k, (lo, hi) in priors.items()}
    points = candidate_geometries(rig, theta_step, view_step, azimuths, max_angle)
    separations = _separations(names, priors, dict(fixed or {}), points, noise, calibration, draws, seed,
                               alignment_sd)
    everything = [s for pairs in separations.values() for s in pairs]

    def gains() -> np.ndarray:
        return sum(np.log1p(s.values_with_each()) - math.log1p(s.value) for s in everything)

    def add(index: int) -> None:
        for s in everything:
            s.add(index)

    chosen, seconds = greedy_selection(
        points, rig, budget, gains, add,
        lambda chosen_points: plan(_protocol("+".join(names), chosen_points, label, reference)).estimated_seconds)
    if not chosen:
        raise ValueError(f"budget {budget:g} s: too short for one point; give a longer budget")
    ordered = _ordered(points[chosen])
    medians = {key: float(np.median([s.value for s in pairs])) for key, pairs in separations.items()}
    return Discrimination(tuple(names), priors, dict(fixed or {}), tuple(map(tuple, ordered.tolist())), seconds,
                          float(budget), medians, noise, calibration, label, reference, alignment_sd,
                          _grouped(ordered))


def _separations(names: Sequence[str], priors, fixed, points: np.ndarray, noise: float, calibration: float,
                 draws: int, seed: int, alignment_sd: float) -> dict[str, list[_Separation]]:
    """``{"A|B": [one _Separation per draw of A]}`` for every ordered pair."""
    out: dict[str, list[_Separation]] = {}
    frame = _sample_frame(points)
    alignment = ALIGNMENT_NUISANCE if alignment_sd > 0 else ()
    for truth, rival in itertools.permutations(names, 2):
        truth_free = _free(truth, priors)
        rival_free = _free(rival, priors)
        if not rival_free:
            raise ValueError(f"model {rival}: none of its parameters {list(models.get(rival).param_names)} has a prior "
                             "range (--prior NAME=LOW:HIGH); the rival needs something to fit")
        truth_draws = _prior_draws({n: priors[n] for n in truth_free}, draws, seed) if truth_free else \
            np.zeros((1, 0))
        widths = np.array([priors[n][1] - priors[n][0] for n in rival_free])
        prior = np.diag(np.concatenate([12.0 / widths**2, [1.0 / calibration**2],
                                        np.full(len(alignment), 1.0 / max(alignment_sd, 1e-9) ** 2)]))
        pairs = []
        for draw in truth_draws:
            params = {**{k: v for k, v in fixed.items() if k in models.get(truth).param_names},
                      **{n: float(draw[k]) for k, n in enumerate(truth_free)}}
            target = _log_values(truth, frame, params)
            residual, jacobian = _rival_fit(rival, target, points, priors, fixed, noise, alignment)
            pairs.append(_Separation(residual, jacobian, prior))
        out[f"{truth}|{rival}"] = pairs
    return out


def discrimination_protocol_text(result: Discrimination) -> str:
    """The design as a protocol file: a comment block (how it was chosen, the expected
    separations, the estimated time), then the reference standard and the blocks."""
    priors = ", ".join(f"{n}={lo:g}:{hi:g}" for n, (lo, hi) in result.priors.items())
    separations = "; ".join(f"{key.replace('|', ' true, ')} rival {value:.3g}"
                            for key, value in result.separations.items())
    comment = [
        f"# Designed by gonio design to tell apart {', '.join(result.models)} with priors {priors}.",
        "# Criterion: expected log(1 + chi-square excess of each rival refitted to each truth) over "
        f"{DISCRIMINATION_DRAWS} prior draws",
        f"# per second of instrument time (greedy; relative noise {result.noise:g} per value, calibration "
        f"{result.calibration:g}).",
        f"# Expected chi-square excess (median over draws): {separations}.",
        f"# {len(result.points)} points, estimated instrument time {result.seconds:.0f} s (budget "
        f"{result.budget:.0f} s;",
        "# gonio plan's estimate, lamp warm-up not included). docs/design.md.",
    ]
    return "\n".join(comment) + "\n" + _blocks_text("+".join(result.models), result.blocks, result.label,
                                                     result.reference)
