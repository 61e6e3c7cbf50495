"""Reflectance models of the source papers, behind one registry.

>>> import gonio
>>> gonio.models.available()[:3]   # doctest: +SKIP
['kvd', 'lambert', 'lambert+phong']
>>> model = gonio.models.get("oren-nayar")
>>> [p.name for p in model.params]
['rho', 'sigma', 'ir_weight']

Each family lives in its own module, which registers its user-facing models when it is
imported; the list below is the complete set of families.
"""
from __future__ import annotations

import importlib

from ._core import FixedGeometryModel, LinearForm, Model, Option, Param, available, get, register

__all__ = ["Model", "Param", "Option", "FixedGeometryModel", "LinearForm", "available", "get", "register"]

#: Modules that register models, in the order they are imported.
MODEL_MODULES = (
    "lambert",
    "minnaert",
    "phong",
    "kvd",
    "oren_nayar.registered",
    "oren_nayar.exact",
    "tabulated.oren_nayar",
    "torrance_sparrow",
    "pitted.model",
    "wolff",
    "fujii",
    "eon",
)

for _module in MODEL_MODULES:
    importlib.import_module(f"{__name__}.{_module}")
