"""The registered ``kvd`` model: the order-2 isotropic Koenderink-van Doorn series.

Registry design
---------------
A KvD series has as many amplitudes as modes (5 at order 2, 14 at order 4, 91 at
order 10), while a registered gonio model has a fixed parameter tuple.  gonio therefore
registers one member of the family and builds the others on demand:

* ``kvd`` (registered): the series truncated at radial order 2, whose five amplitudes
  ``a_0_0_0, a_1_1_1, a_2_0_0, a_2_2_0, a_2_2_2`` are the parameters.  They are
  dimensionless (I_nml carries 1/sr); ``a_0_0_0 = 2 rho`` for a Lambertian surface of
  albedo rho and is bounded below by 0 (it is the integral of the BRDF over both
  hemispheres divided by 2 pi); the others are unbounded.  The default is the
  Lambertian surface of albedo 0.8.  Fitting can use it directly: the BRDF is linear in
  every parameter.
* :func:`gonio.models.kvd.series_model` (``KvdCoefficients.model()``): a model of any
  order from a coefficient set, e.g. one returned by
  :func:`gonio.models.kvd.project` or :func:`gonio.models.kvd.fit_series`.  It is not
  registered (there is one per coefficient set); it behaves like any registered model
  (degrees, horizon, NaN, ``Model.at``).

Both are exactly reciprocal and isotropic by construction.  A truncated series can be
negative; it is returned unclipped.

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998, eq 26-31, Table 2.
"""
from __future__ import annotations

from dataclasses import replace

from gonio.models._core import Model, register

from .examples import lambert_coefficients
from .series import KvdCoefficients, series_model

__all__ = ["KVD", "REGISTERED_ORDER"]

#: Radial order of the registered ``kvd`` model.
REGISTERED_ORDER = 2


def _registered_defaults() -> KvdCoefficients:
    return KvdCoefficients.zeros(REGISTERED_ORDER) + lambert_coefficients(0.8)


KVD: Model = register(
    replace(
        series_model(_registered_defaults(), name="kvd"),
        description="Koenderink-van Doorn isotropic reciprocal series, order 2 (5 amplitudes; default Lambert 0.8)",
    )
)
