"""Readings combined into one value per geometry, each budget component by its correlations."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Mapping, NamedTuple

import numpy as np

from ..uncertainty import MountingFactors, mounting_factors, quantisation_sigma
from .geometry import AXES, DEFAULT_RESOLUTION, geometry_slopes

if TYPE_CHECKING:
    from .readings import Readings

__all__ = ["scatter_fraction", "Combined", "combine", "combine_groups", "mounting_scatter", "COMMON_TO_MOUNTINGS"]

#: Components that every mounting's reading of one geometry shares (the window's PRNU, the
#: texture of the sample's central area): they do not make the mountings differ.
COMMON_TO_MOUNTINGS = ("prnu", "texture", "linearity")

def scatter_fraction(labels: np.ndarray) -> float:
    """Share of a component's variance that shows in the scatter of readings about their mean.

    A component common to blocks of readings (``labels`` name the blocks) adds
    ``u^2 (n - sum(m_b^2) / n) / (n - 1)`` to the expected sample variance of ``n``
    readings in blocks of sizes ``m_b``: all of ``u^2`` when every reading has its own
    value, nothing when all share one.
    """
    n = len(labels)
    if n < 2:
        return 1.0
    _, sizes = np.unique(labels, return_counts=True)
    return float((n - np.sum(sizes**2) / n) / (n - 1))


class Combined(NamedTuple):
    """Readings combined by :func:`combine`."""

    #: The inverse-variance mean.
    mean: float
    #: Standard uncertainty of the mean by component.
    components: dict[str, float]
    #: Chi-square of the readings about the mean with the part of the budget that varies
    #: between them (:func:`scatter_fraction`).
    chi2: float
    #: That part per reading (the repeat scatter it predicts).
    varying: np.ndarray
    #: Each reading's weight in the mean (summing to 1): any other quantity of the readings
    #: (e.g. their sensitivity to a correction) is averaged as ``weights @ quantity``.
    weights: np.ndarray


def combine(members: np.ndarray, value: np.ndarray, budget: Mapping[str, np.ndarray],
             shared: Mapping[str, np.ndarray] | None = None) -> Combined:
    """Inverse-variance mean of readings with each component combined by its correlations.

    Parameters
    ----------
    members : array of int
        Rows to combine.
    value : array
        Value of every row.
    budget : mapping of str to array
        Standard uncertainty of every row by component.
    shared : mapping of str to array, optional
        For components common to blocks of readings, a block label per row (PRNU: one
        window for all repeats; dark: readings using the same dark frame; angle: readings
        made without moving the stage in between; lamp drift: readings between the same
        two checks). A component of one block adds linearly within it and in quadrature
        across blocks; components not listed are independent per reading.

    Returns
    -------
    Combined
        The mean, its components, the chi-square, the varying part of each reading's
        budget and each reading's weight.
    """
    shared = shared or {}
    fractions = {name: scatter_fraction(shared[name][members]) if name in shared else 1.0 for name in budget}
    varying = np.sqrt(sum(fractions[name] * budget[name][members] ** 2 for name in budget))
    weights = np.where(varying > 0, 1.0 / np.maximum(varying, 1e-300) ** 2, 1.0) if np.all(varying > 0) \
        else np.ones(len(members))
    weights = weights / weights.sum()
    mean = float(np.sum(weights * value[members]))
    out = {}
    for name, u in budget.items():
        contribution = weights * u[members]
        if name in shared:
            _, block = np.unique(shared[name][members], return_inverse=True)
            contribution = np.bincount(block.ravel(), weights=contribution)
        out[name] = float(np.sqrt(np.sum(contribution**2)))
    chi2 = float(np.sum(((value[members] - mean) / np.where(varying > 0, varying, np.inf)) ** 2)) if len(members) > 1 else 0.0
    return Combined(mean, out, chi2, varying, weights)


def combine_groups(groups: list[np.ndarray], rows: Readings, readback: np.ndarray, resolution: Mapping[int, float],
                   carried: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], np.ndarray, list[dict], np.ndarray | None]:
    """Combine the readings of each planned geometry at their mean readback geometry.

    Repeats of a geometry sit at slightly different real angles (the stage's
    repeatability; the readback records them). Each reading is moved to the group's mean
    readback geometry with the local slopes of the measured curve
    (:func:`geometry_slopes`) before the readings are combined and their scatter compared
    with their budget, so that the repeat statistics measure noise, not stage positions.
    What remains of the angles is the readback's quantisation, which enters every
    reading's budget as ``angle = |slope| * resolution / sqrt(12)`` per axis.

    ``carried`` (rows, m), e.g. the readings' sensitivity to the linearity correction, is
    averaged with the weights of the values.

    Returns
    -------
    geometry, values, budget, counts, repeat_statistics, carried
        ``carried`` per value, shape (groups, m) (None when not given).
    """
    geometry = np.array([readback[m].mean(axis=0) for m in groups])
    counts = np.array([len(m) for m in groups], int)
    first = np.array([combine(m, rows.value, rows.budget, rows.shared).mean for m in groups])
    slopes = geometry_slopes(geometry, first)
    q = np.array([quantisation_sigma(resolution.get(axis, DEFAULT_RESOLUTION)) for _, axis in AXES])
    budget = dict(rows.budget, angle=np.zeros(len(rows.value)))
    corrected = rows.value.copy()
    for g, members in enumerate(groups):
        corrected[members] -= (readback[members] - geometry[g]) @ slopes[g]
        budget["angle"][members] = math.sqrt(float(np.sum((slopes[g] * q) ** 2)))
    values, parts, stats, means = [], [], [], []
    for g, members in enumerate(groups):
        mean, components, chi2, varying, weights = combine(members, corrected, budget, rows.shared)
        values.append(mean)
        parts.append(components)
        if carried is not None:
            means.append(weights @ np.asarray(carried, float)[members])
        if len(members) > 1:
            stats.append({"geometry": geometry[g].tolist(), "n": int(len(members)), "chi2": chi2,
                          "observed_std": float(np.std(corrected[members], ddof=1)),
                          "stated_std": float(np.sqrt(np.mean(varying**2)))})
    combined = {name: np.array([p[name] for p in parts]) for name in budget}
    return geometry, np.array(values), combined, counts, stats, None if carried is None else np.array(means)


def mounting_scatter(groups: list[np.ndarray], rows: Readings, mounting: np.ndarray
                     ) -> tuple[np.ndarray, MountingFactors] | None:
    """The ``mounting`` component of every reading, from the scatter between mountings.

    Each geometry's readings of one mounting are combined (:func:`combine`) into that
    mounting's value, with the uncertainty of everything that differs between mountings'
    readings but the mounting itself (every component but :data:`COMMON_TO_MOUNTINGS`);
    :func:`~gonio.uncertainty.mounting_factors` turns the values of every mounting at every
    geometry into the mounting's relative covariance between geometries.

    Parameters
    ----------
    groups : list of arrays
        Rows of each geometry (every mounting).
    rows : Readings
    mounting : numpy.ndarray
        Mounting of every row.

    Returns
    -------
    (component, factors) or None
        The component of every row (``|value| sigma_g``, 0 outside the groups) and the
        factors per group; None with fewer than two mountings.
    """
    members = np.concatenate(groups) if groups else np.zeros(0, int)
    labels = np.unique(mounting[members])
    if labels.size < 2:
        return None
    values = np.full((labels.size, len(groups)), np.nan)
    noise = np.full(values.shape, np.nan)
    for g, group in enumerate(groups):
        for k, label in enumerate(labels):
            own = group[mounting[group] == label]
            if own.size:
                mean, parts, *_ = combine(own, rows.value, rows.budget, rows.shared)
                values[k, g] = mean
                noise[k, g] = math.sqrt(sum(v**2 for n, v in parts.items() if n not in COMMON_TO_MOUNTINGS))
    factors = mounting_factors(values, noise)
    component = np.zeros(len(rows.value))
    for g, group in enumerate(groups):
        component[group] = np.abs(rows.value[group]) * factors.sigma[g]
    return component, factors
