"""Surfaces no model wrote: Monte Carlo rendered micro-surfaces of Lambertian facets.

Every emulated sample that is one of gonio's formulas asks a fit to recover the formula
itself.  This package renders the surfaces the papers' models approximate -- long
V-grooves (Oren & Nayar 1995), Gaussian random height fields, planes with spherical pits
(Koenderink, van Doorn, Dana & Nayar 1999) -- by path tracing with exact shadowing,
masking and interreflection to any number of bounces, with the Monte Carlo standard error
of every value.

Modules
-------
shapes
    The surface kinds and their parameters (:class:`VGroove`, :class:`VGrooveField`,
    :class:`HeightField`, :class:`PittedPlane`).
heightfield
    Periodic Gaussian random height fields with a prescribed facet slope.
kernel
    The compiled path tracer (numba; loaded on first render).
estimator
    :func:`render` (the estimator and its derivation) and :func:`render_albedo`.
analytic
    The scattering orders the papers give exactly for a surface (summed, not sampled,
    in its table).
table
    Rendered BRDF tables: grids, the node estimator, interpolation, the on-disk cache, the
    emulator's sample.
spec
    ``kind=...,key=value`` sample specs.

Importing this package loads neither numba nor scipy.
"""
from __future__ import annotations

from .estimator import RENDERER_VERSION, Albedo, Rendering, render, render_albedo
from .shapes import KINDS, HeightField, PittedPlane, Surface, VGroove, VGrooveField, rms_slope_angle

__all__ = ["Surface", "VGroove", "VGrooveField", "HeightField", "PittedPlane", "KINDS", "rms_slope_angle",
           "Albedo", "Rendering", "render", "render_albedo", "RENDERER_VERSION"]
