"""``pitted-tabulated``: the pitted-surface model with its single-scattering integral tabulated.

The pitted BRDF of Koenderink, van Doorn, Dana & Nayar (1999) separates as
``(1 - coverage) rho/pi + coverage (rho F1 + F2)`` (:mod:`gonio.models.pitted.model`).
F1, the single-scattering factor of eq 14-15, depends on the geometry and the aperture
psi and costs a quadrature per geometry; here it is read from a table
(:mod:`.pitted_table`) by cubic interpolation in the smooth coordinates of
:mod:`.coordinates`, and combined with the closed-form interreflection F2 (eq 12) by the
same :class:`~gonio.models.pitted.model.PitTerms` the exact model uses.

Importing this module registers the model; gonio does not import it (it is not in
``gonio.models.MODEL_MODULES``) because its accuracy is short of the 1e-3 target
(docs/tabulated.md): 99th percentile 1.3e-2 on random geometries and parameters.  It
needs a table built by ``gonio tables build pitted``.
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
            "eq 14-15 (single scattering) tabulated from the pitted model, cubic interpolation"
        ),
        description="plane partly covered by Lambertian spherical pits, single scattering from a table (fast)",
        prepare=_prepare,
        energy_conserving=True,
        reciprocal=True,
    )
)
