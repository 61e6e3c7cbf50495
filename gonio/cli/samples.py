"""Sample specs of the emulated rig: a registered model or a measured CUReT material.

The one parser behind ``--sample`` of ``gonio emulator`` and ``gonio run`` (and the
in-process rig of tests and the demo, :func:`gonio.cli.run.emulated_rig`):

``MODEL[:key=value,...]``
    A registered model with parameter values, e.g. ``oren-nayar:sigma=30,rho=0.9``
    (:func:`gonio.cli.models.parse_model_spec`).
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
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import CLIError
from .models import parse_model_spec

__all__ = ["CURET_PREFIX", "SPEC_SYNTAX", "EmulatedSample", "parse_sample_spec"]

#: Prefix of a CUReT sample spec.
CURET_PREFIX = "curet:"
#: The accepted forms, for help texts and error messages.
SPEC_SYNTAX = "MODEL[:key=value,...] or curet:NUMBER|NAME"


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
        Registered model name, or ``"curet"``.
    parameters : dict
        Model parameters, or the CUReT sample and its interpolation (plain values for the
        recording's metadata).
    """

    spec: str
    brdf: Callable[..., np.ndarray]
    model: str
    parameters: dict = field(default_factory=dict)


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
        ``MODEL[:key=value,...]`` or ``curet:NUMBER|NAME``.

    Returns
    -------
    EmulatedSample

    Raises
    ------
    CLIError
        Unknown model or parameter, out-of-range value, unknown CUReT sample (naming the
        key and the valid numbers and names), missing CUReT files (naming the folder).

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
    name, values = parse_model_spec(spec)
    return EmulatedSample(text, functools.partial(gonio.brdf, name, **values), name, dict(values))
