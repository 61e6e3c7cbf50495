"""``posterior.nc``: a fit's posterior as an ArviZ ``InferenceData`` netCDF file, written
with h5netcdf.

ArviZ stores an ``InferenceData`` as one netCDF4 group per group of the object
(``posterior``, ``sample_stats``, ``log_likelihood``, ``posterior_predictive``,
``observed_data``, ``constant_data``), each a dataset
whose variables have the dimensions ``chain`` and ``draw`` (plus ``y_dim_0`` for a
pointwise quantity), with integer coordinate variables ``0 .. size-1`` (the
InferenceData schema of ArviZ's documentation). :func:`write_inference_data` writes that
layout with h5netcdf (the netCDF4 writer ArviZ itself uses here), without importing
ArviZ, xarray or pandas, which together cost 1 to 3 s at start-up (``gonio fit`` of a
small recording takes less than that in all). ``arviz.from_netcdf`` reads the file back
equal, group by group, value by value, dimension by dimension, to
:func:`gonio.fitting.diagnostics.inference_data` of the same arrays (ArviZ's own
``from_dict``), which stays the in-memory form (tests/fitting/test_diagnostics.py).

Unlike ArviZ's ``to_netcdf`` the variables are not zlib-compressed: a chain's random
doubles shrink by a tenth to a quarter at several times the writing time (the same
choice as ``chain.npz``).

References
----------
ArviZ InferenceData schema specification,
https://python.arviz.org/en/stable/schema/schema.html
"""
from __future__ import annotations

import datetime as _dt
import io
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["inference_groups", "write_inference_data"]

#: Name of the data dimension of a pointwise quantity (ArviZ's default for variable ``y``).
DATA_DIMENSION = "y_dim_0"


def inference_groups(chain: np.ndarray, log_prob: np.ndarray, names: Sequence[str],
                     log_likelihood: np.ndarray | None = None, observed: np.ndarray | None = None,
                     predictive: np.ndarray | None = None,
                     geometry: Mapping[str, np.ndarray] | None = None,
                     ) -> dict[str, dict[str, tuple[tuple[str, ...], np.ndarray]]]:
    """The groups of an ``InferenceData`` of an ensemble chain (walkers as chains):
    ``{group: {variable: (dimensions, values)}}``, from the arguments of
    :func:`gonio.fitting.diagnostics.inference_data`: chain (steps, walkers, parameters),
    log posterior (steps, walkers), parameter names, and optionally the pointwise
    log-likelihood (steps, walkers, n), the observed values (n,), replicated data of the
    posterior predictive (steps', walkers, n; ``posterior_predictive``, for
    ``arviz.plot_ppc``) and the measurement geometry by name (n,) each
    (``constant_data``: the inputs the values were measured at, in degrees)."""
    groups: dict[str, dict[str, tuple[tuple[str, ...], np.ndarray]]] = {
        "posterior": {n: (("chain", "draw"), np.ascontiguousarray(chain[:, :, k].T)) for k, n in enumerate(names)},
        "sample_stats": {"lp": (("chain", "draw"), np.ascontiguousarray(np.asarray(log_prob).T))},
    }
    if log_likelihood is not None:
        groups["log_likelihood"] = {"y": (("chain", "draw", DATA_DIMENSION),
                                          np.ascontiguousarray(np.transpose(log_likelihood, (1, 0, 2))))}
    if predictive is not None:
        groups["posterior_predictive"] = {"y": (("chain", "draw", DATA_DIMENSION),
                                                np.ascontiguousarray(np.transpose(predictive, (1, 0, 2))))}
    if observed is not None:
        groups["observed_data"] = {"y": ((DATA_DIMENSION,), np.asarray(observed, float))}
    if geometry:
        groups["constant_data"] = {name: ((DATA_DIMENSION,), np.asarray(values, float))
                                   for name, values in geometry.items()}
    return groups


def write_inference_data(chain: np.ndarray, log_prob: np.ndarray, names: Sequence[str],
                         log_likelihood: np.ndarray | None = None, observed: np.ndarray | None = None,
                         attributes: Mapping[str, Any] | None = None, predictive: np.ndarray | None = None,
                         geometry: Mapping[str, np.ndarray] | None = None) -> bytes:
    """The bytes of a netCDF4 file that ``arviz.from_netcdf`` reads as the
    ``InferenceData`` of :func:`gonio.fitting.diagnostics.inference_data` (same arguments).

    ``attributes`` go to the ``posterior`` group, with ``created_at`` (UTC, ISO 8601) on
    every group as ArviZ writes it.
    """
    import h5netcdf

    created = _dt.datetime.now(_dt.timezone.utc).isoformat()
    buffer = io.BytesIO()
    with h5netcdf.File(buffer, "w") as handle:
        for group_name, variables in inference_groups(chain, log_prob, names, log_likelihood, observed, predictive,
                                                      geometry).items():
            group = handle.create_group(group_name)
            sizes: dict[str, int] = {}
            for dims, values in variables.values():
                sizes.update(zip(dims, values.shape))
            group.dimensions = sizes
            for dimension, size in sizes.items():
                group.create_variable(dimension, (dimension,), data=np.arange(size, dtype=np.int64))
            for name, (dims, values) in variables.items():
                group.create_variable(name, dims, data=values)
            group.attrs["created_at"] = created
            if group_name == "posterior":
                for key, value in dict(attributes or {}).items():
                    group.attrs[key] = value
    return buffer.getvalue()
