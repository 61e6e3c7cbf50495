"""What each model leaves out, and how far its fitted parameters were measured to fall from
a surface's own.

A model that passes the goodness-of-fit test (:mod:`gonio.fitting.adequacy`) follows the
data within their noise; it does not make its parameters the surface's. Every physical
model of the papers idealises the surface (V-cavities, interreflection cut after two
bounces, spherical pits, a Gaussian distribution of facet slopes), so its parameters are
*effective* parameters of that idealisation. At a real lab's noise (0.3-3 %) a wrong family
can follow the data well enough to pass: a V-groove field rendered with every bounce
passes as the two-bounce V-cavity model at 3 % noise in about half of the seeds
(docs/fitting.md, "Three verdicts"), with rho 5 % high.

:func:`discrepancy_statement` gives, for a fitted model, what it leaves out and, where
gonio has measured it, how its parameters came out when it was fitted to surfaces rendered
with every bounce (:mod:`gonio.surfaces`; ``benchmarks/surfaces_study.py``, docs/surfaces.md):
the surfaces it follows within :data:`CLOSE_RMS` (those a fit could pass on) where a
parameter came out off (rho by 1 % or more, an angle by 1 deg or more), with the fitted
values against the surface's. The measured offsets are the study's, copied into
``gonio/fitting/data/surface_offsets.json`` by :func:`offsets_from_study` (the study writes
it; a test checks that the two agree). The statement opens the fit's summary section
"Model discrepancy", the report and the result's JSON.
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Any, Mapping

__all__ = ["LEFT_OUT", "CLOSE_RMS", "OFFSETS_FILE", "discrepancy_statement", "offsets_from_study", "measured_offsets"]

_V_CAVITY = ("long symmetric V-cavities with Lambertian facets, a Gaussian distribution of facet slopes and "
             "interreflection cut after two bounces (Oren & Nayar 1995, sections 3-4)")
_EMPIRICAL = "an empirical form: its parameters describe the data, not a surface's structure"

#: What each registered model leaves out of a real surface.
LEFT_OUT = {
    "oren-nayar-exact": _V_CAVITY,
    "oren-nayar-tabulated": _V_CAVITY + ", interpolated from a table (docs/tabulated.md)",
    "oren-nayar-numerical": _V_CAVITY + ", integrated numerically",
    "oren-nayar": _V_CAVITY + ", through the functional approximation of eq 33-35 (docs/oren-nayar-accuracy.md)",
    "oren-nayar-qualitative": _V_CAVITY + ", through the qualitative eq 36, without interreflection",
    "pitted": ("spherical pits of one opening angle in a flat Lambertian plane, every pit alike (Koenderink, van "
               "Doorn, Dana & Nayar 1999)"),
    "torrance-sparrow": ("a specular lobe of V-cavity facets with a Gaussian slope distribution, Fresnel reflection "
                         "at one refractive index and a single scattering event (Torrance & Sparrow 1967)"),
    "oren-nayar+torrance-sparrow": ("the Oren-Nayar body term (" + _V_CAVITY + ", eq 33-35) plus a Torrance-Sparrow "
                                    "lobe of single specular scattering"),
    "wolff": ("a smooth dielectric interface over a body of isotropic multiple scattering (Wolff, Nayar & Oren "
              "1998): no surface roughness"),
    "wolff-oren-nayar": ("the Oren-Nayar body term with Wolff's Fresnel transmittances (Wolff, Nayar & Oren 1998, "
                         "eq 9): " + _V_CAVITY),
    "lambert": _EMPIRICAL + " (an ideal diffuse surface)",
    "minnaert": _EMPIRICAL,
    "phong": _EMPIRICAL,
    "lambert+phong": _EMPIRICAL,
    "kvd": "a phenomenological series: its coefficients describe the data, not a surface's structure",
    "fujii-oren-nayar": (_EMPIRICAL + " (a renderer's form of the qualitative Oren-Nayar model, Fujii 2012: r mixes "
                         "a Lambertian and a shaped term and is not a slope statistic)"),
    "eon": (_EMPIRICAL + " (Fujii's form with an energy-preserving multiple-scattering lobe, Portsmouth, Kutz & "
            "Hill 2025: a renderer's model, r is not a slope statistic)"),
}

#: Surfaces a model follows within this relative rms (polar angles <= 80 deg) are those a
#: fit at a real lab's noise can pass on; their measured offsets enter the statement.
CLOSE_RMS = 0.05

#: The measured offsets (written by ``benchmarks/surfaces_study.py``).
OFFSETS_FILE = Path(__file__).with_name("data") / "surface_offsets.json"


def offsets_from_study(payload: Mapping[str, Any]) -> dict[str, list[dict[str, Any]]]:
    """The fitted parameters of every model on every rendered surface of the study.

    Parameters
    ----------
    payload : mapping
        ``docs/benchmarks/surfaces.json`` as ``benchmarks/surfaces_study.py`` writes it.

    Returns
    -------
    dict
        By fitted model: one entry per surface with ``surface`` (its label), ``true`` (its
        parameters), ``fitted`` and ``rms`` (relative misfit at polar angles <= 80 deg).
    """
    out: dict[str, list[dict[str, Any]]] = {}
    for row in payload["comparison"]:
        true = {k: v for k, v in row["parameters"].items() if k in ("sigma", "rho", "psi", "coverage")}
        for model, fitted in row["fitted"].items():
            out.setdefault(model, []).append({"surface": row["surface"], "true": true,
                                              "fitted": dict(fitted["parameters"]),
                                              "rms": float(fitted["theta <= 80 deg"]["rms"])})
    return out


@lru_cache(maxsize=1)
def measured_offsets() -> dict[str, list[dict[str, Any]]]:
    """The study's offsets (:data:`OFFSETS_FILE`); empty if the file is missing."""
    return json.loads(OFFSETS_FILE.read_text()) if OFFSETS_FILE.is_file() else {}


def discrepancy_statement(model: str) -> str:
    """What ``model`` leaves out and its measured offsets on rendered surfaces (module docstring).

    Examples
    --------
    >>> discrepancy_statement("lambert").startswith("lambert is an empirical form")
    True
    """
    left_out = LEFT_OUT.get(model, "an idealised surface")
    if left_out.startswith(("an empirical", "a phenomenological")):
        return f"{model} is {left_out}."
    text = (f"The parameters are effective parameters of {model}: {left_out}. A real surface's own roughness and "
            "albedo differ from them by what the model leaves out.")
    close = [row for row in measured_offsets().get(model, []) if row["rms"] <= CLOSE_RMS and _off(row)]
    if close:
        text += (f" Fitted to surfaces rendered with every bounce that it follows within {100 * CLOSE_RMS:g} % rms "
                 "(docs/surfaces.md), its parameters came out off: " + "; ".join(_offset_text(model, row)
                                                                                 for row in close) + ".")
    return text


def _off(row: Mapping[str, Any]) -> bool:
    """Whether a fit's rho is 1 % or more off the surface's, or an angle 1 deg or more."""
    for name, true in row["true"].items():
        fitted = row["fitted"].get(name)
        if fitted is None:
            continue
        if (name == "rho" and abs(fitted / true - 1) >= 0.01) or (name != "rho" and abs(fitted - true) >= 1.0):
            return True
    return False


def _offset_text(model: str, row: Mapping[str, Any]) -> str:
    """``V-groove field sigma=30: rho 0.947 (true 0.9, +5.2 %), sigma 29.7 deg (true 30), 1.3 % rms``."""
    from gonio import models

    spec = models.get(model)
    parts = []
    for name, fitted in row["fitted"].items():
        true, unit = row["true"].get(name), spec.param(name).unit
        unit = "" if unit == "-" else f" {unit}"
        if name == "rho" and true is not None:
            parts.append(f"rho {fitted:.3f} (true {true:g}, {100 * (fitted / true - 1):+.1f} %)")
        else:
            parts.append(f"{name} {fitted:.3g}{unit}" + (f" (true {true:g}{unit})" if true is not None else ""))
    surface = row["surface"].replace("vgrooves", "V-groove field").replace("heightfield", "Gaussian height field")
    return f"{surface}: " + ", ".join(parts) + f", {100 * row['rms']:.1f} % rms"
