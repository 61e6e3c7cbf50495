"""``pitted-tabulated``: the pitted-surface model with its single-scattering integral tabulated.

The pitted BRDF of Koenderink, van Doorn, Dana & Nayar (1999) separates as
``(1 - coverage) rho/pi + coverage (rho F1 + F2)`` (:mod:`gonio.models.pitted.model`).
F1, the single-scattering factor of eq 14-15, depends on the geometry and the aperture
psi and costs a fine quadrature per geometry; here it is the product of a coarse
quadrature G (the same panels, split at every kink of the integrand, with few nodes) and
the ratio F1/G read from a table (:mod:`.pitted_table`) by cubic interpolation in the
smooth coordinates of :mod:`.coordinates`.  It is combined with the closed-form
interreflection F2 (eq 12) by the same :class:`~gonio.models.pitted.model.PitTerms` the
exact model uses, so the parameters, the limits (psi -> 0: Lambert), reciprocity and the
grazing behaviour are those of ``pitted``.

Accuracy and speed against ``pitted`` are in docs/tabulated.md (section "Pitted"):
relative error of the BRDF at most 1.2e-4 on random geometries and parameters (F1 alone
is worse, up to a few percent, only where F1 < ~1e-3 1/sr: deep pits near the forward
direction).  F1 and F2 are kept per geometry and aperture, so fitting ``rho`` and
``coverage`` at a fixed aperture costs a few operations per geometry, while each new
aperture costs the coarse quadrature (~4e4 geometries/s on one core, no faster than
``pitted`` itself).

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, "Bidirectional reflection
distribution function of thoroughly pitted surfaces", IJCV 31(2/3), 1999, eq 12, 14-15.

Examples
--------
>>> import gonio
>>> f = gonio.brdf("pitted-tabulated", 30.0, 0.0, 60.0, 180.0, rho=1.0, psi=90.0, coverage=1.0)
>>> round(float(f), 4)   # pitted gives 0.159155
0.1592
"""
from __future__ import annotations

import math

import numpy as np

from .._core import Model, Param, register
from ..pitted.model import PitTerms
from .pitted_table import table

__all__ = ["PITTED_TABULATED"]


def _prepare(theta_i, phi_i, theta_r, phi_r):
    factor = table().prepare(theta_i, phi_i, theta_r, phi_r)
    cache: dict[float, PitTerms] = {}

    def evaluate(rho: float, psi: float, coverage: float) -> np.ndarray:
        if psi not in cache:
            if len(cache) > 8:
                cache.clear()
            psi_rad = math.radians(psi)
            cache[psi] = PitTerms(factor(psi), math.sin(psi_rad) ** 2 / (4.0 * math.pi), math.sin(psi_rad / 2.0) ** 2)
        return cache[psi].brdf(rho, coverage)

    return evaluate


PITTED_TABULATED = register(
    Model(
        name="pitted-tabulated",
        params=(
            Param("rho", "-", 0.8, (0.0, 1.0), "micro-scale Lambertian albedo of pits and plane"),
            Param("psi", "deg", 90.0, (0.0, 90.0), "pit aperture; 90 is a hemispherical pit", open_lower=True),
            Param("coverage", "-", 0.4, (0.0, 1.0), "fraction of the plane covered by pit orifices"),
        ),
        reference=(
            "Koenderink, van Doorn, Dana & Nayar 1999, IJCV 31: eq 12 (interreflection, closed form) and "
            "eq 14-15 (single scattering): a coarse quadrature times the tabulated ratio to the pitted model's"
        ),
        description="plane partly covered by Lambertian spherical pits, single scattering from a table times a coarse quadrature",
        prepare=_prepare,
        energy_conserving=True,
        reciprocal=True,
    )
)
