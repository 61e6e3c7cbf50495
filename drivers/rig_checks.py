"""Pure checks the rig applies to what its instruments report.

Each function here decides one question from numbers the instruments returned, so that
the decision can be tested without hardware:

- :func:`position_problem`: did the stage reach its targets (readback within tolerance)?
- :func:`steadiness`: did a series of readings change between two windows by more than
  their own scatter allows?
- :func:`exposure_window`: which raw ROI means does the automatic exposure accept for a
  given aim?
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

__all__ = ["AXIS_LABELS", "position_problem", "steadiness", "exposure_window", "exposure_ladder_floor"]

#: Names of the stage axes in messages.
AXIS_LABELS = {1: "camera (view)", 2: "lamp theta_i", 3: "lamp phi_i"}


def position_problem(readback: Mapping[int, float], targets: Mapping[int, float], tolerance: float) -> str | None:
    """Why the encoder readback does not confirm the targets, or None when every axis agrees.

    Parameters
    ----------
    readback : mapping
        Encoder positions by axis [deg].
    targets : mapping
        Commanded positions by axis [deg].
    tolerance : float
        Largest accepted ``|readback - target|`` [deg].

    Examples
    --------
    >>> position_problem({1: -35.001, 2: 30.0}, {1: -35.0, 2: 30.0}, 0.01) is None
    True
    >>> position_problem({1: -35.0, 2: 37.5}, {1: -35.0, 2: 30.0}, 0.01)
    'lamp theta_i read back 37.5 deg for a target of 30 deg (tolerance 0.01 deg)'
    """
    for axis, target in targets.items():
        value = readback.get(axis, math.nan)
        if not abs(value - target) <= tolerance:  # also catches NaN
            label = AXIS_LABELS.get(axis, f"axis {axis}")
            return f"{label} read back {value:.6g} deg for a target of {target:.6g} deg (tolerance {tolerance:g} deg)"
    return None


def steadiness(first: Sequence[float], second: Sequence[float], limit_sigma: float = 6.0) -> tuple[float, float]:
    """Relative change between two windows of readings, and the largest change their noise allows.

    The tolerance is ``limit_sigma`` standard errors of the difference of the two means,
    with the readings' own scatter (ddof=1) as the noise: a tolerance derived from the
    read-back noise, not a fixed number.

    Parameters
    ----------
    first, second : sequence of float
        Readings before and after a wait, at least two each.
    limit_sigma : float
        Standard errors allowed [-]. With 10 readings per window (18 degrees of freedom)
        6 standard errors are exceeded by chance with probability about 1e-5.

    Returns
    -------
    change, tolerance : float
        ``mean(second) / mean(first) - 1`` and its allowed size [-].

    Examples
    --------
    >>> change, tolerance = steadiness([1.0, 1.002, 0.998], [1.001, 0.999, 1.0])
    >>> round(change, 6), abs(change) < tolerance
    (0.0, True)
    """
    a = np.asarray(first, float)
    b = np.asarray(second, float)
    if a.size < 2 or b.size < 2:
        raise ValueError(f"steadiness needs at least 2 readings per window, got {a.size} and {b.size}")
    level = float(a.mean())
    if not level > 0:
        return math.inf, 0.0
    change = float(b.mean()) / level - 1.0
    standard_error = math.sqrt(a.var(ddof=1) / a.size + b.var(ddof=1) / b.size) / level
    return change, limit_sigma * standard_error


def exposure_window(target_fraction: float) -> tuple[float, float]:
    """Raw ROI means accepted by the automatic exposure, as fractions of the ADC maximum.

    From two thirds of the aim to five thirds of it, but never beyond two thirds of the way
    from the aim to full scale (the rig's default aim 0.45 gives 0.3 to 0.75).

    Examples
    --------
    >>> [round(v, 4) for v in exposure_window(0.45)]
    [0.3, 0.75]
    >>> [round(v, 4) for v in exposure_window(0.9)]
    [0.6, 0.9667]
    """
    if not 0.0 < target_fraction < 1.0:
        raise ValueError(f"target_fraction={target_fraction!r} must be in (0, 1)")
    return 2.0 * target_fraction / 3.0, min(5.0 * target_fraction / 3.0, (2.0 + target_fraction) / 3.0)


def exposure_ladder_floor(seconds: float, steps_per_decade: int = 12) -> float:
    """Largest exposure of the ladder ``10**(k / steps_per_decade)`` not above ``seconds`` [s].

    Examples
    --------
    >>> exposure_ladder_floor(0.03)
    0.0261
    """
    k = math.floor(math.log10(seconds) * steps_per_decade + 1e-9)
    return float(f"{10 ** (k / steps_per_decade):.4g}")
