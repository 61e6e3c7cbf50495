"""Sample specs of the emulated rig as text: their forms, and a check that builds nothing.

``MODEL[:key=value,...]`` (a registered model with parameter values),
``surface:kind=KIND,...`` (a rendered micro-surface, :mod:`gonio.surfaces.spec`) or
``curet:NUMBER|NAME`` (a CUReT material). :func:`check_sample_spec` is what a protocol's
``[sample] emulated`` is checked with (:mod:`gonio.protocols`); building the sample's BRDF
for the emulator is :func:`gonio.cli.samples.parse_sample_spec`, which parses with the
same rules. Errors are ``ValueError`` naming what was wrong and what was expected.
"""
from __future__ import annotations

from gonio import models

#: The emulated sample when none is named (``gonio demo``, ``gonio run``, ``gonio emulator``):
#: Oren & Nayar's wall plaster as the physical V-cavity model itself (sigma 30 deg, rho 0.9).
PLASTER_MODEL = "oren-nayar-exact"
PLASTER_TRUTH = {"rho": 0.9, "sigma": 30.0}
DEFAULT_SAMPLE = f"{PLASTER_MODEL}:" + ",".join(f"{k}={v:g}" for k, v in PLASTER_TRUTH.items())
__all__ = ["split_model_spec", "DEFAULT_SAMPLE", "PLASTER_MODEL", "PLASTER_TRUTH", "CURET_PREFIX", "SURFACE_PREFIX", "SPEC_SYNTAX", "parse_model_spec", "check_sample_spec"]

#: Prefix of a CUReT sample spec.
CURET_PREFIX = "curet:"
#: Prefix of a rendered-surface sample spec.
SURFACE_PREFIX = "surface:"
#: The accepted forms, for help texts and error messages.
SPEC_SYNTAX = "MODEL[:key=value,...] or surface:kind=KIND,... or curet:NUMBER|NAME"


def parse_model_spec(text: str) -> tuple[str, dict[str, float | str]]:
    """Parse ``NAME[:key=value,key=value]`` into a model name and its values.

    Numbers become floats; anything else stays a string (model options).

    Examples
    --------
    >>> parse_model_spec("oren-nayar:sigma=30,rho=0.9")
    ('oren-nayar', {'sigma': 30.0, 'rho': 0.9})
    """
    name, _, rest = text.partition(":")
    values: dict[str, float | str] = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, eq, raw = item.partition("=")
        if not eq or not key.strip():
            raise ValueError(f"model spec {text!r}: expected key=value after ':', got {item!r}")
        try:
            values[key.strip()] = float(raw)
        except ValueError:
            values[key.strip()] = raw.strip()
    model = models.get(name.strip())
    model.resolve(values)  # unknown names and out-of-range values fail here, by name
    return model.name, values


def split_model_spec(text: str) -> tuple[str, dict[str, float], dict[str, str]]:
    """A candidate model spec ``NAME[:key=value,...]`` as its name, the parameters it fixes
    (numbers) and its options (text): the ``--model`` of ``gonio fit`` and ``gonio curet fit``.

    >>> split_model_spec("oren-nayar:ir_weight=1")
    ('oren-nayar', {'ir_weight': 1.0}, {})
    """
    name, values = parse_model_spec(text)
    fixed = {k: float(v) for k, v in values.items() if not isinstance(v, str)}
    return name, fixed, {k: v for k, v in values.items() if isinstance(v, str)}


def check_sample_spec(text: str) -> None:
    """Check a sample spec without building its BRDF (for protocol files).

    Model and surface specs are checked completely (model, kind, parameter names and
    ranges; no table is read or rendered); a CUReT spec for its form (``curet:`` and a
    number or name), since its data need not be present where the protocol is read.

    Raises
    ------
    ValueError
        What :func:`gonio.cli.samples.parse_sample_spec` would say.

    Examples
    --------
    >>> check_sample_spec("surface:kind=vgrooves,sigma=30,rho=0.9")
    >>> check_sample_spec("surface:kind=vgrooves,sigma=300,rho=0.9")
    Traceback (most recent call last):
    ...
    ValueError: surface spec 'kind=vgrooves,sigma=300,rho=0.9': sigma [deg] = 300 is outside its valid range [0, 90]
    """
    spec = text.strip()
    if spec.lower().startswith(CURET_PREFIX):
        if not spec[len(CURET_PREFIX):].strip():
            raise ValueError(f"sample spec {spec!r}: expected curet:NUMBER or curet:NAME, e.g. curet:10")
        return
    if spec.lower().startswith(SURFACE_PREFIX):
        from gonio.surfaces.spec import parse_surface_spec

        parse_surface_spec(spec[len(SURFACE_PREFIX):])
        return
    parse_model_spec(spec)
