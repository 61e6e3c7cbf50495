"""A fit held against the truth, when the truth is known: data measured on the emulator.

A recording of the emulated rig names its sample (``metadata["emulated_sample"]``, set by
:func:`gonio.reduction.reduce_recording`): the model and parameters the emulator rendered.
Every parameter of the fitted model that the sample states is then compared with the
fit's 95 % interval; a truth outside it is reported as ``BIAS`` with the distance in units
of the interval's half-width on that side. The summary, the report and ``gonio demo``
print the same table (:func:`truth_lines`).
"""
from __future__ import annotations

from typing import Any, Mapping

from gonio.data import EMULATED_SAMPLE

from .text import digits_to_resolve

__all__ = ["EMULATED_SAMPLE", "known_truth", "truth_lines"]

#: Parameters a sample states that fits can be held against (the physical ones).
TRUTH_PARAMETERS = ("rho", "sigma", "k", "n", "m", "c", "ks", "kd", "psi")


def known_truth(metadata: Mapping[str, Any]) -> tuple[str, dict[str, float]] | None:
    """The emulated sample's spec and its numeric parameters, or None for other data.

    >>> known_truth({"emulated_sample": {"spec": "oren-nayar-exact:rho=0.9,sigma=30",
    ...                                  "parameters": {"rho": 0.9, "sigma": 30.0, "kind": "x"}}})
    ('oren-nayar-exact:rho=0.9,sigma=30', {'rho': 0.9, 'sigma': 30.0})
    """
    sample = metadata.get(EMULATED_SAMPLE) if metadata else None
    if not isinstance(sample, Mapping):
        return None
    parameters = sample.get("parameters") or {}
    truth = {name: float(parameters[name]) for name in TRUTH_PARAMETERS
             if isinstance(parameters.get(name), (int, float)) and not isinstance(parameters.get(name), bool)}
    return str(sample.get("spec", "")), truth


def truth_lines(rows: list[Mapping[str, Any]], truth: Mapping[str, float], model: str,
                cause: str | None = None) -> tuple[list[str], list[str]]:
    """The truth table (parameter, truth, fitted median, 95 % interval, inside) and the
    ``BIAS`` lines of the truths outside their interval.

    Parameters
    ----------
    rows : list of dict
        :meth:`gonio.fitting.FitResult.parameter_rows`.
    truth : mapping
        True values by parameter name.
    model : str
        The fitted model (named when a truth is not one of its parameters).
    cause : str, optional
        What a BIAS line blames (default: the model does not reproduce the sample).
    """
    cause = cause or f"{model} does not reproduce the emulated sample within these data's noise"
    by_name = {row["name"]: row for row in rows}
    lines = ["parameter   truth     fitted (median)   95 % interval           truth inside"]
    bias = []
    for name, value in truth.items():
        row = by_name.get(name)
        if row is None:
            lines.append(f"{name:<10} {value:8.4g}   (not a parameter of {model})")
            continue
        median = row.get("median", row["value"])
        low, high = row.get("p2_5"), row.get("p97_5")
        if low is None:
            lines.append(f"{name:<10} {value:8.4g}   {median:12.5g}      (no interval: least squares only)")
            continue
        inside = low <= value <= high
        digits = max(5, digits_to_resolve(median, (high - low) / 4))
        interval = f"[{low:#.{digits}g}, {high:#.{digits}g}]"  # trailing zeros kept: 30.000, not 30
        lines.append(f"{name:<10} {value:8.4g}   {median:#12.{digits}g}      {interval:<20} {row['unit']:<6}  "
                     f"{'yes' if inside else 'NO'}")
        if not inside:
            half_width = (median - low) if value < low else (high - median)
            unit = "" if row["unit"] in ("", "-") else f" {row['unit']}"
            bias.append(f"BIAS: {name} is {median - value:+.3g}{unit} from the truth, "
                        f"{abs(median - value) / max(half_width, 1e-300):.1f} times the interval's half-width: {cause}")
    return lines, bias
