"""Arguments several commands share: ``NAME=VALUE`` lists (``--fix``, ``--option``,
``--prior``, ``--columns``), repeatable or comma-separated."""
from __future__ import annotations

import re

from . import CLIError

__all__ = ["name_value_pairs", "number", "parse_duration", "prior_ranges"]

#: Durations ``--budget`` accepts: a number with an optional unit.
_DURATION = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(s|sec|min|h)?\s*$")
_UNIT_SECONDS = {None: 1.0, "s": 1.0, "sec": 1.0, "min": 60.0, "h": 3600.0}


def name_value_pairs(items: list[str], what: str) -> dict[str, str]:
    """``{name: value}`` of ``NAME=VALUE`` items, each possibly comma-separated.

    >>> name_value_pairs(["sigma=30,rho=0.9", "n=1.5"], "--fix")
    {'sigma': '30', 'rho': '0.9', 'n': '1.5'}

    Raises
    ------
    CLIError
        An item without a name, an ``=`` or a value, naming the option ``what``.
    """
    pairs = {}
    for item in items:
        for part in item.split(","):
            if not part.strip():
                continue
            name, sep, value = part.partition("=")
            if not sep or not name.strip() or not value.strip():
                raise CLIError(f"{what} {part!r}: expected NAME=VALUE")
            pairs[name.strip()] = value.strip()
    return pairs


def number(name: str, text: str, what: str) -> float:
    """``text`` as a number, or a :class:`CLIError` naming ``what`` and ``name``."""
    try:
        return float(text)
    except ValueError:
        raise CLIError(f"{what} {name}={text!r}: the value must be a number") from None


def parse_duration(text: str, what: str = "--budget") -> float:
    """Seconds of ``300``, ``300s``, ``5min`` or ``1.5h``; a :class:`CLIError` naming ``what``.

    >>> parse_duration("5min"), parse_duration("300"), parse_duration("1.5h")
    (300.0, 300.0, 5400.0)
    """
    match = _DURATION.match(text)
    if not match:
        raise CLIError(f"{what} {text!r}: expected a duration such as 300s, 5min or 1.5h")
    return float(match.group(1)) * _UNIT_SECONDS[match.group(2)]


def prior_ranges(items: list[str], what: str = "--prior") -> dict[str, tuple[float, float]]:
    """``{name: (low, high)}`` of ``NAME=LOW:HIGH`` items.

    >>> prior_ranges(["sigma=10:45,rho=0.5:1"])
    {'sigma': (10.0, 45.0), 'rho': (0.5, 1.0)}
    """
    ranges = {}
    for name, span in name_value_pairs(items, what).items():
        low, colon, high = span.partition(":")
        try:
            if not colon:
                raise ValueError
            ranges[name] = (float(low), float(high))
        except ValueError:
            raise CLIError(f"{what} {name}={span!r}: expected NAME=LOW:HIGH, e.g. sigma=10:45") from None
    return ranges
