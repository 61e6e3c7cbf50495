"""Numbers as text: how many digits a value needs beside its uncertainty."""
from __future__ import annotations

import math

__all__ = ["digits_to_resolve"]


def digits_to_resolve(value: float, width: float, least: int = 3) -> int:
    """Significant digits that show ``value`` to a tenth of ``width`` (an interval's or an
    error's), so that the ends of an interval print different: at least ``least``.

    >>> digits_to_resolve(0.9, 1e-4), digits_to_resolve(237500.0, 300.0), digits_to_resolve(30.0, 2.0)
    (5, 5, 3)
    """
    if not (math.isfinite(value) and math.isfinite(width)) or width <= 0 or value == 0:
        return least
    return max(least, min(12, math.floor(math.log10(abs(value))) - math.floor(math.log10(width / 10)) + 1))
