"""Checks of the pitted-surface parameters (ValueError naming value and valid range)."""
from __future__ import annotations

import math

__all__ = ["check_pit_parameters"]


def _check(name: str, value: float, lower: float, upper: float, open_lower: bool, unit: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    above = number > lower if open_lower else number >= lower
    if math.isnan(number) or not (above and number <= upper):
        left = "(" if open_lower else "["
        raise ValueError(
            f"{name} = {number:g} {unit} is outside its valid range {left}{lower:g}, {upper:g}] {unit}"
        )
    return number


def check_pit_parameters(rho: float, psi: float, coverage: float = 1.0) -> tuple[float, float, float]:
    """Validate albedo rho in [0, 1], aperture psi in (0, 90] deg, coverage in [0, 1].

    Returns the three values as floats; raises ``ValueError`` naming the parameter, its
    value and the valid range otherwise (never clips).
    """
    return (
        _check("rho", rho, 0.0, 1.0, False, "-"),
        _check("psi", psi, 0.0, 90.0, True, "deg"),
        _check("coverage", coverage, 0.0, 1.0, False, "-"),
    )
