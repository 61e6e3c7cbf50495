"""Surface sample specs: ``kind=vgrooves,sigma=30,rho=0.9[,paths=...,seed=...,bounces=...]``.

The text after ``surface:`` in a sample spec (``gonio emulator --sample surface:...``,
``gonio run``, protocol files, ``gonio demo``).  Keys:

* ``kind``: ``vgroove`` (theta_a, phi_a optional, rho), ``vgrooves`` (sigma, rho),
  ``heightfield`` (sigma, rho, cells and correlation optional), ``pits`` (psi, coverage,
  rho); the parameters of :mod:`.shapes`, angles in degrees;
* ``paths``: paths per table node (default :data:`DEFAULT_PATHS`);
* ``seed``: Monte Carlo seed, and the realisation of a height field (default 0);
* ``bounces``: ``all`` (default) or the number of scattering events (1 = direct light).

Every error names the spec, the key and what was expected.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .shapes import KINDS, HeightField, Surface, VGroove

__all__ = ["SurfaceSpec", "parse_surface_spec", "DEFAULT_PATHS", "OPTIONS"]

#: Paths per table node unless the spec says otherwise (docs/surfaces.md: the resulting
#: Monte Carlo error of the table).
DEFAULT_PATHS = 20_000
#: Keys every kind accepts besides its parameters, with their meaning.
OPTIONS = {"paths": "paths per table node, an integer >= 100",
           "seed": "Monte Carlo seed (and height-field realisation), an integer >= 0",
           "bounces": "'all' or the number of scattering events, an integer >= 1"}
#: Units of the parameters, for messages.
_UNITS = {"theta_a": "deg", "phi_a": "deg", "sigma": "deg", "psi": "deg", "rho": "-", "coverage": "-",
          "cells": "-", "correlation": "cells"}


@dataclass(frozen=True)
class SurfaceSpec:
    """A parsed surface sample: the surface and how its table is rendered.

    Attributes
    ----------
    surface : Surface
        The surface (:mod:`.shapes`).
    paths : int
        Paths per table node.
    seed : int
        Monte Carlo seed.
    bounces : int or None
        Scattering events per path; None = all.
    """

    surface: Surface
    paths: int = DEFAULT_PATHS
    seed: int = 0
    bounces: int | None = None

    def text(self) -> str:
        """The canonical spec (every key, fixed order): equal surfaces give equal texts."""
        values = {"kind": self.surface.kind}
        values.update({k: v for k, v in self.surface.parameters().items()
                       if v is not None and not (isinstance(self.surface, HeightField) and k == "seed")})
        values.update(paths=self.paths, seed=self.seed, bounces="all" if self.bounces is None else self.bounces)
        return ",".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in values.items())


def _parameter_names(kind: type[Surface]) -> list[str]:
    names = [f.name for f in dataclasses.fields(kind)]
    return [n for n in names if not (kind is HeightField and n == "seed")]


def _required(kind: type[Surface]) -> list[str]:
    optional = {"phi_a"} if kind is VGroove else set()
    return [f.name for f in dataclasses.fields(kind)
            if f.default is dataclasses.MISSING and f.name not in optional]


def _number(spec: str, key: str, raw: str) -> float:
    try:
        return float(raw)
    except ValueError:
        raise ValueError(f"surface spec {spec!r}: {key} = {raw!r} is not a number") from None


def _integer(spec: str, key: str, raw: str, low: int) -> int:
    value = _number(spec, key, raw)
    if not value.is_integer() or value < low:
        raise ValueError(f"surface spec {spec!r}: {key} = {raw!r}; expected {OPTIONS[key]}")
    return int(value)


def _split(spec: str) -> dict[str, str]:
    items: dict[str, str] = {}
    for item in filter(None, (part.strip() for part in spec.split(","))):
        key, eq, raw = item.partition("=")
        key = key.strip()
        if not eq or not key or not raw.strip():
            raise ValueError(f"surface spec {spec!r}: expected key=value, got {item!r}")
        if key in items:
            raise ValueError(f"surface spec {spec!r}: {key} is given twice")
        items[key] = raw.strip()
    return items


def parse_surface_spec(spec: str) -> SurfaceSpec:
    """Parse the text after ``surface:`` (module notes).

    Parameters
    ----------
    spec : str
        e.g. ``kind=vgrooves,sigma=30,rho=0.9``.

    Returns
    -------
    SurfaceSpec

    Raises
    ------
    ValueError
        Unknown kind or key, a missing parameter, a value that is not a number or is
        outside its range; the message names the spec and the key.

    Examples
    --------
    >>> parse_surface_spec("kind=pits,psi=60,coverage=0.5,rho=0.8").text()
    'kind=pits,psi=60,coverage=0.5,rho=0.8,paths=20000,seed=0,bounces=all'
    """
    items = _split(spec)
    kind_name = items.pop("kind", None)
    if kind_name not in KINDS:
        known = ", ".join(sorted(KINDS))
        got = "no kind" if kind_name is None else f"unknown kind {kind_name!r}"
        raise ValueError(f"surface spec {spec!r}: {got}; expected kind= one of {known}")
    kind = KINDS[kind_name]
    names = _parameter_names(kind)
    unknown = [key for key in items if key not in names and key not in OPTIONS]
    if unknown:
        accepted = ", ".join([f"{n} [{_UNITS[n]}]" for n in names] + list(OPTIONS))
        raise ValueError(f"surface spec {spec!r}: unknown key {unknown[0]!r} for kind {kind_name}; "
                         f"accepted: {accepted}")
    missing = [name for name in _required(kind) if name not in items]
    if missing:
        raise ValueError(f"surface spec {spec!r}: kind {kind_name} needs {missing[0]} [{_UNITS[missing[0]]}]")
    seed = _integer(spec, "seed", items.pop("seed", "0"), 0)
    paths = _integer(spec, "paths", items.pop("paths", str(DEFAULT_PATHS)), 100)
    bounces_text = items.pop("bounces", "all")
    bounces = None if bounces_text == "all" else _integer(spec, "bounces", bounces_text, 1)
    values: dict[str, float | int] = {key: _number(spec, key, raw) for key, raw in items.items()}
    if kind is HeightField:
        values["seed"] = seed
    if kind is VGroove:
        values.setdefault("phi_a", None)
    try:
        surface = kind(**values)
    except ValueError as error:
        raise ValueError(f"surface spec {spec!r}: {error}") from None
    return SurfaceSpec(surface, paths=paths, seed=seed, bounces=bounces)
