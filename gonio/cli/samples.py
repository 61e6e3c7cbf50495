"""Sample specs of the emulated rig: a registered model, a rendered surface or a CUReT material.

The one parser behind ``--sample`` of ``gonio emulator`` and ``gonio run`` (and the
in-process rig of tests and the demo, :func:`gonio.cli.run.emulated_rig`):

``MODEL[:key=value,...]``
    A registered model with parameter values, e.g. ``oren-nayar:sigma=30,rho=0.9``
    (:func:`gonio.sample_specs.parse_model_spec`).
``surface:kind=KIND,key=value,...``
    A micro-surface rendered by Monte Carlo path tracing (:mod:`gonio.surfaces`), e.g.
    ``surface:kind=vgrooves,sigma=30,rho=0.9``: a surface no model wrote.  Its BRDF table
    is read from the table cache, or rendered there on first use with progress on
    stderr (:mod:`gonio.surfaces.table`; keys: :mod:`gonio.surfaces.spec`).
``curet:SAMPLE``
    A CUReT material (Dana et al. 1999) by number or name, e.g. ``curet:10`` or
    ``curet:plaster_a``: its 205 measured values interpolated over the hemisphere by the
    reciprocal Koenderink-van Doorn series of cross-validated order, floored at 0
    (:mod:`gonio.curet_sample`).  The data are read from ``$GONIO_CURET_DIR``, else
    ``shared/data/curet`` beside the checkout (:func:`gonio.curet.default_directory`).

This module is where gonio models are turned into the plain callable the emulator takes
(``drivers`` never imports ``gonio``).
"""
from __future__ import annotations

import functools
import sys
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from gonio.sample_specs import CURET_PREFIX, SPEC_SYNTAX, SURFACE_PREFIX, check_sample_spec, parse_model_spec

from . import CLIError

#: Options an emulated sample's model takes unless its spec sets them. The exact V-cavity
#: model to ``rtol`` 1e-5 (3.6e-6 worst relative error measured, :data:`gonio.models.oren_nayar.exact._QUADRATURE`;
#: a seventeenth of the ideal rig's 6e-5 per value, a seven-hundredth of a lab's 0.25 %)
#: takes three quarters of the time of its 1e-6 default, most of the emulator's work.
SAMPLE_MODEL_OPTIONS: dict[str, dict[str, float]] = {"oren-nayar-exact": {"rtol": 1e-5}}

__all__ = ["CURET_PREFIX", "SURFACE_PREFIX", "SPEC_SYNTAX", "EmulatedSample", "parse_sample_spec",
           "check_sample_spec", "table_progress"]

@dataclass(frozen=True)
class EmulatedSample:
    """A parsed sample spec.

    Attributes
    ----------
    spec : str
        The text as given.
    brdf : callable
        ``brdf(theta_i, phi_i, theta_r, phi_r) -> numpy.ndarray`` [1/sr], degrees.
    model : str
        Registered model name, ``"surface"`` or ``"curet"``.
    parameters : dict
        Model parameters, the rendered surface (kind, parameters, paths, seed, bounces,
        table file), or the CUReT sample and its interpolation (plain values for the
        recording's metadata).
    """

    spec: str
    brdf: Callable[..., np.ndarray]
    model: str
    parameters: dict = field(default_factory=dict)

    def prepare(self) -> None:
        """Load what the BRDF needs before the rig starts: a rendered surface's table is
        read from the cache, or rendered now (with progress on stderr)."""
        load = getattr(self.brdf, "load", None)
        if callable(load):
            load()


def table_progress(spec: str) -> Callable[[int, int, float | None], None]:
    """A progress printer on stderr for the rendering of a surface table, with time left."""
    from .progress import ProgressLine

    line = ProgressLine("table nodes")
    started = []

    def show(done: int, total: int, seconds_left: float | None) -> None:
        if not started:
            started.append(True)
            print(f"rendering the BRDF table of {spec} (first use; cached for later runs)", file=sys.stderr,
                  flush=True)
        line.update(done, total, seconds_left)

    return show


def _surface_sample(spec: str) -> EmulatedSample:
    from gonio.surfaces.spec import parse_surface_spec
    from gonio.surfaces.table import TabulatedSurface

    try:
        parsed = parse_surface_spec(spec[len(SURFACE_PREFIX):])
        brdf = TabulatedSurface(parsed, progress=table_progress(spec))
    except ValueError as error:
        raise CLIError(str(error)) from None
    parameters = {"kind": parsed.surface.kind, **{k: v for k, v in parsed.surface.parameters().items()},
                  "paths": parsed.paths, "seed": parsed.seed,
                  "bounces": "all" if parsed.bounces is None else parsed.bounces,
                  "canonical": SURFACE_PREFIX + parsed.text(), "table": brdf.path.name}
    return EmulatedSample(spec, brdf, "surface", parameters)


def _curet_sample(spec: str) -> EmulatedSample:
    from gonio.curet import default_directory
    from gonio.curet_sample import curet_brdf

    key = spec[len(CURET_PREFIX):].strip()
    folder = default_directory()
    if not key:
        raise CLIError(f"sample spec {spec!r}: expected curet:NUMBER or curet:NAME, e.g. curet:10 or curet:plaster_a")
    missing = [name for name in ("abrdf.dat", "table.txt") if not (folder / name).is_file()]
    if missing:
        raise CLIError(f"sample spec {spec!r}: the CUReT folder {folder} lacks {' and '.join(missing)}; "
                       "set $GONIO_CURET_DIR to the folder holding abrdf.dat and table.txt")
    try:
        brdf = curet_brdf(key, folder)
    except ValueError as error:
        raise CLIError(f"sample spec {spec!r}: {error}") from None
    parameters = {"curet_sample": brdf.number, "curet_name": brdf.name, "kvd_order": brdf.order,
                  "kvd_amplitudes": len(brdf.coefficients.modes),
                  "regularization": brdf.selection.regularization, "order_rule": brdf.selection.rule,
                  "negative": "floored at 0"}
    return EmulatedSample(spec, brdf, "curet", parameters)


def parse_sample_spec(text: str) -> EmulatedSample:
    """Parse a sample spec (module notes) into the emulator's BRDF callable.

    Parameters
    ----------
    text : str
        ``MODEL[:key=value,...]``, ``surface:kind=KIND,...`` or ``curet:NUMBER|NAME``.

    Returns
    -------
    EmulatedSample
        For a surface, the table is not touched yet: :meth:`EmulatedSample.prepare` (or
        the first evaluation) loads or renders it.

    Raises
    ------
    ValueError
        Unknown model, surface kind or parameter, out-of-range value, unknown CUReT
        sample (naming the key and the valid numbers and names), missing CUReT files
        (naming the folder); a :class:`gonio.cli.CLIError` for surfaces and CUReT.

    Examples
    --------
    >>> sample = parse_sample_spec("lambert:rho=0.5")
    >>> sample.model, round(float(sample.brdf(30.0, 0.0, 45.0, 180.0)) * np.pi, 12)
    ('lambert', 0.5)
    """
    import gonio

    spec = text.strip()
    if spec.lower().startswith(CURET_PREFIX):
        return _curet_sample(spec)
    if spec.lower().startswith(SURFACE_PREFIX):
        return _surface_sample(spec)
    name, values = parse_model_spec(spec)
    evaluated = {**SAMPLE_MODEL_OPTIONS.get(name, {}), **values}
    return EmulatedSample(text, functools.partial(gonio.brdf, name, **evaluated), name, dict(values))
