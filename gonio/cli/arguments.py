"""Arguments several commands share: ``NAME=VALUE`` lists (``--fix``, ``--option``,
``--prior``, ``--columns``), repeatable or comma-separated."""
from __future__ import annotations

from . import CLIError

__all__ = ["name_value_pairs", "number"]


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
