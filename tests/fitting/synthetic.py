"""Synthetic datasets for the fitting tests: a registered model plus Gaussian noise."""
from __future__ import annotations

import numpy as np

import gonio
from gonio.fitting import Dataset
from gonio.fitting.problem import predict_quantity
from gonio.geometry import in_plane_angles

#: The geometries of Oren & Nayar (1995) Fig 16: plane of incidence, theta_i = 30, 45, 60
#: deg, camera every 10 deg from -80 to 80 deg (signed; + on the source side).
FIG16_INCIDENCES = (30.0, 45.0, 60.0)
FIG16_VIEWS = np.arange(-80.0, 81.0, 10.0)


def in_plane_geometry(incidences=FIG16_INCIDENCES, views=FIG16_VIEWS):
    """(theta_i, phi_i, theta_r, phi_r) [deg] of every (incidence, signed view) pair."""
    ti = np.repeat(np.asarray(incidences, float), len(views))
    sv = np.tile(np.asarray(views, float), len(incidences))
    return in_plane_angles(ti, sv)


def synthetic_dataset(
    model: str,
    truth: dict,
    noise: float,
    seed: int = 0,
    quantity: str = "brdf",
    geometry=None,
    relative: bool = False,
) -> Dataset:
    """Model values (gonio.brdf via predict_quantity) plus Gaussian noise of known sigma.

    ``noise`` is the standard deviation: absolute, or relative to each value when
    ``relative`` is true.
    """
    geometry = in_plane_geometry() if geometry is None else geometry
    exact = predict_quantity(model, quantity, *geometry, truth)
    sigma = noise * np.abs(exact) if relative else np.full(exact.shape, noise)
    rng = np.random.default_rng(seed)
    return Dataset(*geometry, exact + sigma * rng.standard_normal(exact.shape), sigma, quantity=quantity,
                   label=f"synthetic {model}")


def brdf_reference(model: str, geometry, **params) -> np.ndarray:
    """The public reference path, for equality checks against the fast path."""
    return gonio.brdf(model, *geometry, **params)
