"""Tabulated versions of the slow exact models: exact accuracy at closed-form speed.

The exact Oren-Nayar model is ``rho f1 + rho^2 f2`` with f1, f2 depending on geometry and
roughness only.  This package tabulates f1, f2 with the exact method on a grid in
coordinates where they are smooth, and interpolates the table with a cubic rule in a
compiled loop.  The registered model is ``oren-nayar-tabulated`` (its table is shipped).

The pitted model (Koenderink et al. 1999) separates in rho the same way, but needs no
table: its single-scattering integral has a closed form
(:mod:`gonio.models.pitted.closed_form`), exact and as fast as a table lookup
(docs/tabulated.md, section "Pitted surfaces").

Modules
-------
coordinates
    The smooth table coordinates and their inverse.
interpolation
    Tensor-product cubic Lagrange interpolation on regular grids (the rule, numpy).
kernel
    The compiled evaluation: table coordinates and tricubic sum per geometry (numba).
oren_nayar_table
    Building the table from ``oren-nayar-exact``.
store
    Shipped tables, the user cache, loading and saving.
lookup
    The table grid and the two-path evaluation (one-off call, fixed geometries).
oren_nayar
    The registered model ``oren-nayar-tabulated``.

Tables are built by ``gonio tables build`` (or :func:`build`) and the one gonio ships is
read from package data; see docs/tabulated.md for the accuracy and why it is shipped.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

__all__ = ["TableSpec", "TABLES", "build", "describe"]


@dataclass(frozen=True)
class TableSpec:
    """How to build one table and what it serves.

    Attributes
    ----------
    name : str
        File name without ``.npz``.
    model : str
        Registered model that reads the table.
    reference : str
        Registered model whose values the table holds.
    builder : callable
        ``builder(rtol, workers, progress) -> dict of arrays``.
    """

    name: str
    model: str
    reference: str
    builder: Callable[..., dict]


def _build_oren_nayar(rtol: float, workers: int | None, progress=None, grid=None) -> dict:
    from .oren_nayar_table import DEFAULT_GRID, build_oren_nayar_table

    return build_oren_nayar_table(grid or DEFAULT_GRID, rtol=rtol, workers=workers, progress=progress)


#: Every table gonio knows how to build, by name.
TABLES: dict[str, TableSpec] = {
    "oren-nayar": TableSpec("oren-nayar", "oren-nayar-tabulated", "oren-nayar-exact", _build_oren_nayar),
}


def _spec(name: str) -> TableSpec:
    if name not in TABLES:
        raise ValueError(f"unknown table {name!r}; known tables: {sorted(TABLES)}")
    return TABLES[name]


def build(name: str, output: Path | None = None, rtol: float = 1e-5, workers: int | None = None,
          progress=None, **options) -> Path:
    """Build table ``name`` with its exact model and write it (default: the user cache).

    Parameters
    ----------
    name : str
        A key of :data:`TABLES`.
    output : path, optional
        Where to write (default ``<cache_dir()>/<name>.npz``).
    rtol : float
        Accuracy of the exact model at the nodes.
    workers : int, optional
        Processes to use (default: all CPUs).
    progress : callable, optional
        Called with (done, total).
    **options
        Passed to the builder (e.g. ``grid``).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    from . import store

    spec = _spec(name)
    arrays = spec.builder(rtol, workers, progress, **options)
    path = store.save(Path(output) if output else store.cache_dir() / f"{name}.npz", arrays)
    _forget_loaded()
    return path


def describe(name: str) -> dict:
    """Facts about the table ``name`` that would be used now (path, grid, size, rtol)."""
    from . import store

    spec = _spec(name)
    path = store.find(name)
    info = {"name": name, "model": spec.model, "reference": spec.reference, "path": str(path) if path else None}
    if path is not None:
        arrays = store.load(name)
        shape = tuple(int(n) for n in arrays["shape"])
        info.update(
            shape=shape,
            nodes=math.prod(shape),
            bytes=path.stat().st_size,
            rtol=float(arrays["rtol"]),
            build_seconds=float(arrays["build_seconds"]),
            shipped=path.parent == store.PACKAGE_DIR,
        )
    return info


def _forget_loaded() -> None:
    import sys

    from . import store

    store.load.cache_clear()
    for name in ("oren_nayar",):
        module = sys.modules.get(f"{__name__}.{name}")
        if module is not None:
            module.reset_table()
