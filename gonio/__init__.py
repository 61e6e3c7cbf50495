"""gonio: a virtual gonioreflectometer and measurement-analysis suite.

The public entry points (DESIGN.md, "Public API contract")::

    import gonio
    gonio.models.available()                      # registered model names
    gonio.models.get("oren-nayar")                # Model: .name, .params, .reference
    gonio.brdf("oren-nayar", 45, 0, 30, 180, rho=0.9, sigma=30)   # [1/sr]
    gonio.fit_recording("plaster", models=["lambert", "oren-nayar"])  # as 'gonio fit' (docs/api.md)
    gonio.fit_many(["a.csv", "b.csv"], ["lambert", "oren-nayar"], out="batch", workers=2)  # docs/batch.md

Angles are in degrees everywhere in the public interface.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from . import geometry, models, radiometry

__all__ = ["__version__", "brdf", "models", "geometry", "radiometry", "fit_recording", "load_data", "fit_many"]


def _installed_version() -> str:
    """The installed distribution's version, or ``0.0.0+unknown`` in a bare source tree."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("gonio")
    except PackageNotFoundError:  # running from a source tree that was not installed
        return "0.0.0+unknown"


def __getattr__(name: str) -> Any:
    """Module attributes resolved on first access (PEP 562).

    ``__version__`` reads the package metadata only when asked for: importing
    :mod:`importlib.metadata` costs about as much as the rest of ``import gonio``
    without numpy.
    """
    if name == "__version__":
        value = _installed_version()
        globals()["__version__"] = value
        return value
    if name in ("fit_recording", "load_data"):  # the analysis stack loads on first use
        from . import analysis

        return getattr(analysis, name)
    if name == "fit_many":  # batch fits (gonio.batch, docs/batch.md)
        from .batch import fit_many

        return fit_many
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def brdf(name: str, theta_i, phi_i, theta_r, phi_r, **params) -> np.ndarray:
    """Evaluate the registered model ``name`` [1/sr].

    Parameters
    ----------
    name : str
        Registered model name (see :func:`gonio.models.available`).
    theta_i, phi_i : array_like
        Source polar angle and azimuth [deg].
    theta_r, phi_r : array_like
        Viewing polar angle and azimuth [deg].
    **params
        Model parameters by name (see ``gonio.models.get(name).params``); missing ones
        take their defaults.

    Returns
    -------
    numpy.ndarray
        BRDF [1/sr], broadcast over the angle arrays; 0 below the horizon, NaN where an
        angle is NaN.

    Raises
    ------
    ValueError
        Unknown model, unknown parameter, or a parameter outside its physical range.

    Examples
    --------
    >>> float(brdf("lambert", 30, 0, 10, 180, rho=0.5)) * 3.141592653589793
    0.5
    """
    return models.get(name)(theta_i, phi_i, theta_r, phi_r, **params)
