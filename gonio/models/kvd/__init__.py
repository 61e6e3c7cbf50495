"""Koenderink-van Doorn (1998) reciprocal series for isotropic BRDFs.

An isotropic BRDF is expanded in the orthonormal, reciprocity-respecting modes I_nml
built from Zernike polynomials carried to the hemisphere (:mod:`gonio.zernike`).  One
concept per module:

* :mod:`.basis` -- the modes I_nml (eq 26), their normalisation A_nml (eq 27), the index
  rules (eq 30-31) and the product basis H_nmkl (eq 20-21);
* :mod:`.series` -- coefficient sets, truncation, damping, and a series as a gonio model;
* :mod:`.projection` -- coefficients of any isotropic model by quadrature (eq 29);
* :mod:`.least_squares` -- coefficients from scattered measurements (regularised);
* :mod:`.cross_validation` -- the series order by leave-one-out cross-validation;
* :mod:`.examples` -- Lambert, ideal mirror and retroreflector series (eq 32-39);
* :mod:`.model` -- the registered ``kvd`` model (order 2) and the registry design.

>>> import gonio
>>> from gonio.models import kvd
>>> series = kvd.project("oren-nayar", order=4, params={"rho": 0.8, "sigma": 20.0})
>>> model = series.model()                       # a gonio Model of order 4
>>> value = model(30.0, 0.0, 45.0, 180.0)        # BRDF [1/sr]

References
----------
J. J. Koenderink, A. J. van Doorn, "Phenomenological description of bidirectional surface
reflection", JOSA A 15(11), 1998.
"""
from __future__ import annotations

from .basis import (
    check_isotropic_index,
    design_matrix,
    isotropic_basis,
    isotropic_indices,
    isotropic_normalisation,
    reciprocal_product,
)
from .cross_validation import SELECTION_RULES, OrderSelection, leave_one_out_residuals, select_order
from .examples import lambert_coefficients, mirror_coefficients, retroreflector_coefficients
from .least_squares import SeriesFit, fit_series, penalty_weights
from .model import KVD, REGISTERED_ORDER
from .projection import ProductQuadrature, product_quadrature, project, relative_l2_error
from .series import DAMPING_WINDOWS, KvdCoefficients, coefficient_name, damping_window, series_model

__all__ = [
    "check_isotropic_index",
    "design_matrix",
    "isotropic_basis",
    "isotropic_indices",
    "isotropic_normalisation",
    "reciprocal_product",
    "lambert_coefficients",
    "mirror_coefficients",
    "retroreflector_coefficients",
    "SELECTION_RULES",
    "OrderSelection",
    "leave_one_out_residuals",
    "select_order",
    "SeriesFit",
    "fit_series",
    "penalty_weights",
    "KVD",
    "REGISTERED_ORDER",
    "ProductQuadrature",
    "product_quadrature",
    "project",
    "relative_l2_error",
    "DAMPING_WINDOWS",
    "KvdCoefficients",
    "coefficient_name",
    "damping_window",
    "series_model",
]
