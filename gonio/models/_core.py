"""Parameter specifications, the :class:`Model` wrapper and the model registry.

Every reflectance model in gonio is a :class:`Model`: a pure *kernel* working in radians
on directions that lie above the horizon, wrapped with everything the public interface
promises (DESIGN.md, "Public API contract" and "Bad input"):

* angles in degrees, broadcasting array arguments;
* parameters checked against their physical bounds (``ValueError`` naming the parameter,
  the value and the valid range, never a silent clip);
* BRDF 0 for directions below the horizon (theta > 90 deg), NaN in gives NaN out.

A kernel is written once.  Models whose cost is dominated by geometry-only terms (trig
functions of the four angles) supply a ``prepare`` function instead: it takes the four
angles [rad] and returns a function of the parameters.  The plain evaluation path then
*is* ``prepare(...)(**params)``, so the fixed-geometry path used by fitting
(:meth:`Model.at`) and the ordinary path share one implementation of the formula.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

__all__ = [
    "Param",
    "Option",
    "Model",
    "FixedGeometryModel",
    "register",
    "available",
    "get",
]

Kernel = Callable[..., np.ndarray]
Preparer = Callable[..., Callable[..., np.ndarray]]


@dataclass(frozen=True)
class Param:
    """Specification of one continuous model parameter.

    Parameters
    ----------
    name : str
        Parameter name used as keyword argument (DESIGN.md naming: ``rho``, ``sigma``...).
    unit : str
        Unit in human-readable form: ``"-"`` for dimensionless, ``"deg"``, ``"1/sr"``.
    default : float
        Value used when the caller does not give one.
    bounds : tuple of float
        Physical range ``(lower, upper)``; ``math.inf`` for an unbounded side.
    description : str
        One line saying what the parameter means physically.
    open_lower, open_upper : bool
        Whether the corresponding bound itself is excluded (e.g. ``psi`` in (0, 90]).
    """

    name: str
    unit: str
    default: float
    bounds: tuple[float, float]
    description: str
    open_lower: bool = False
    open_upper: bool = False

    def range_text(self) -> str:
        """The valid range in interval notation with unit, e.g. ``[0, 1] -``."""
        lo, hi = self.bounds
        left = "(" if self.open_lower or math.isinf(lo) else "["
        right = ")" if self.open_upper or math.isinf(hi) else "]"
        return f"{left}{_fmt(lo)}, {_fmt(hi)}{right}"

    def contains(self, value: float) -> bool:
        """True when ``value`` lies inside the physical range."""
        lo, hi = self.bounds
        above = value > lo if self.open_lower else value >= lo
        below = value < hi if self.open_upper else value <= hi
        return bool(above and below)

    def check(self, value: Any, model: str) -> float:
        """Return ``value`` as float, or raise ``ValueError`` naming what was wrong."""
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ValueError(
                f"model {model!r}: parameter {self.name!r} must be a real number in "
                f"{self.range_text()} {self.unit}, got {value!r}"
            ) from None
        if math.isnan(number) or not self.contains(number):
            raise ValueError(
                f"model {model!r}: parameter {self.name} = {number:g} {self.unit} is outside "
                f"its valid range {self.range_text()} {self.unit} ({self.description})"
            )
        return number


@dataclass(frozen=True)
class Option:
    """A discrete, non-fitted model setting (e.g. which Fresnel factor to use).

    Parameters
    ----------
    name : str
        Keyword name.
    default : object
        Value used when not given.
    choices : tuple
        Allowed values.
    description : str
        One line saying what the option selects.
    """

    name: str
    default: Any
    choices: tuple
    description: str

    def check(self, value: Any, model: str) -> Any:
        """Return ``value`` if it is one of the choices, else raise ``ValueError``."""
        if value not in self.choices:
            raise ValueError(
                f"model {model!r}: option {self.name} = {value!r} is not one of "
                f"{list(self.choices)} ({self.description})"
            )
        return value


def _fmt(x: float) -> str:
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:g}"


_RIGHT_ANGLE = 90.0


def _as_angles(
    theta_i: Any, phi_i: Any, theta_r: Any, phi_r: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Broadcast the four angles [deg] to float arrays and reject negative polar angles."""
    arrays = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (theta_i, phi_i, theta_r, phi_r))
    )
    for label, theta in (("theta_i", arrays[0]), ("theta_r", arrays[2])):
        negative = theta < 0
        if np.any(negative):
            bad = float(theta[negative].flat[0])
            raise ValueError(
                f"{label} = {bad:g} deg is negative; polar angles are measured from the "
                "surface normal and lie in [0, 90] deg (use "
                "gonio.geometry.in_plane_angles() to convert signed in-plane viewing angles)"
            )
    return arrays[0], arrays[1], arrays[2], arrays[3]


@dataclass(frozen=True)
class Model:
    """A registered reflectance model.

    Parameters
    ----------
    name : str
        Registry name: lower-case with hyphens (``"oren-nayar"``).
    params : tuple of Param
        Ordered parameter specifications.
    reference : str
        Citation: paper, equation and figure the model implements.
    description : str
        One line for listings.
    kernel : callable, optional
        ``kernel(theta_i, phi_i, theta_r, phi_r, **values) -> ndarray`` with angles in
        radians, all directions above the horizon, values as Python floats/options.
    prepare : callable, optional
        ``prepare(theta_i, phi_i, theta_r, phi_r, **options) -> f(**params)``: precomputes
        geometry-only terms.  Give ``kernel`` or ``prepare``, not both.
    options : tuple of Option
        Discrete settings passed to the kernel with the parameters.
    energy_conserving : bool
        Whether the model claims directional-hemispherical reflectance <= 1 for albedo <= 1.
    reciprocal : bool
        Whether the model obeys Helmholtz reciprocity exactly.
    isotropic : bool
        Whether the BRDF depends on the azimuths only through phi_r - phi_i.
    linear_in : tuple of str
        Names of parameters the BRDF is linear in (used by fitting to profile them out).
    """

    name: str
    params: tuple[Param, ...]
    reference: str
    description: str
    kernel: Kernel | None = None
    prepare: Preparer | None = None
    options: tuple[Option, ...] = ()
    energy_conserving: bool = True
    reciprocal: bool = True
    isotropic: bool = True
    linear_in: tuple[str, ...] = ()
    _by_name: Mapping[str, Param] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if (self.kernel is None) == (self.prepare is None):
            raise TypeError(f"model {self.name!r}: give exactly one of kernel or prepare")
        object.__setattr__(self, "_by_name", {p.name: p for p in self.params})

    # ------------------------------------------------------------------ parameters
    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of the continuous parameters, in order."""
        return tuple(p.name for p in self.params)

    @property
    def defaults(self) -> dict[str, float]:
        """Default value of every parameter."""
        return {p.name: p.default for p in self.params}

    def param(self, name: str) -> Param:
        """The :class:`Param` called ``name`` (``ValueError`` if there is none)."""
        try:
            return self._by_name[name]
        except KeyError:
            raise ValueError(
                f"model {self.name!r} has no parameter {name!r}; its parameters are "
                f"{list(self.param_names)}"
            ) from None

    def resolve(self, values: Mapping[str, Any]) -> tuple[dict[str, float], dict[str, Any]]:
        """Validate keyword values and fill defaults.

        Returns
        -------
        params, options : dict
            Checked parameter floats and option values.

        Raises
        ------
        ValueError
            Unknown name, non-number, or value outside the physical range.
        """
        option_by_name = {o.name: o for o in self.options}
        unknown = [k for k in values if k not in self._by_name and k not in option_by_name]
        if unknown:
            known = list(self.param_names) + list(option_by_name)
            hint = difflib.get_close_matches(unknown[0], known, n=1)
            raise ValueError(
                f"model {self.name!r} has no parameter {unknown[0]!r}"
                + (f" (did you mean {hint[0]!r}?)" if hint else "")
                + f"; valid names are {known}"
            )
        params = {
            p.name: p.check(values.get(p.name, p.default), self.name) for p in self.params
        }
        options = {
            o.name: o.check(values.get(o.name, o.default), self.name) for o in self.options
        }
        return params, options

    # ------------------------------------------------------------------ evaluation
    def _kernel_call(self, ti, pi_, tr, pr, params, options) -> np.ndarray:
        if self.kernel is not None:
            return self.kernel(ti, pi_, tr, pr, **params, **options)
        return self.prepare(ti, pi_, tr, pr, **options)(**params)

    def __call__(self, theta_i, phi_i, theta_r, phi_r, **values: Any) -> np.ndarray:
        """Evaluate the BRDF [1/sr] at angles in degrees.

        Parameters
        ----------
        theta_i, phi_i : array_like
            Polar angle and azimuth of the source direction [deg].
        theta_r, phi_r : array_like
            Polar angle and azimuth of the viewing direction [deg].
        **values
            Model parameters and options (scalars).

        Returns
        -------
        numpy.ndarray
            BRDF [1/sr] with the broadcast shape of the angles; 0 below the horizon,
            NaN where any angle is NaN.
        """
        params, options = self.resolve(values)
        ti, pi_, tr, pr = _as_angles(theta_i, phi_i, theta_r, phi_r)
        valid, nan = _domain(ti, pi_, tr, pr)
        if valid.all():
            out = self._kernel_call(*_radians(ti, pi_, tr, pr), params, options)
            return np.broadcast_to(np.asarray(out, dtype=float), ti.shape).copy()
        out = np.zeros(ti.shape)
        out[nan] = np.nan
        if valid.any():
            geometry = _radians(ti[valid], pi_[valid], tr[valid], pr[valid])
            out[valid] = self._kernel_call(*geometry, params, options)
        return out

    def at(self, theta_i, phi_i, theta_r, phi_r, **options: Any) -> "FixedGeometryModel":
        """Freeze the geometry and return a fast function of the parameters.

        Fitting evaluates one model at a fixed set of geometries for many parameter
        vectors; geometry-only terms are computed once here.

        Parameters
        ----------
        theta_i, phi_i, theta_r, phi_r : array_like
            Measurement geometry [deg].
        **options
            Discrete model options (not continuous parameters).

        Returns
        -------
        FixedGeometryModel
        """
        _, opts = self.resolve({k: v for k, v in options.items()})
        ti, pi_, tr, pr = _as_angles(theta_i, phi_i, theta_r, phi_r)
        return FixedGeometryModel(self, ti, pi_, tr, pr, opts)

    def __repr__(self) -> str:
        return f"<gonio model {self.name!r} params={list(self.param_names)}>"


def _domain(ti, pi_, tr, pr) -> tuple[np.ndarray, np.ndarray]:
    nan = np.isnan(ti) | np.isnan(pi_) | np.isnan(tr) | np.isnan(pr)
    with np.errstate(invalid="ignore"):
        above = (ti <= _RIGHT_ANGLE) & (tr <= _RIGHT_ANGLE)
    return above & ~nan, nan


def _radians(*angles: np.ndarray) -> tuple[np.ndarray, ...]:
    return tuple(np.radians(a) for a in angles)


class FixedGeometryModel:
    """A model bound to fixed geometries: ``f(**params)`` or ``f.evaluate(vector)``.

    Created by :meth:`Model.at`.  Geometry-only terms are computed once (when the model
    supplies ``prepare``); each call only combines them with the parameters.
    """

    def __init__(self, model: Model, ti, pi_, tr, pr, options: dict[str, Any]):
        self.model = model
        self.shape = ti.shape
        self._valid, self._nan = _domain(ti, pi_, tr, pr)
        self._all_valid = bool(self._valid.all())
        self._options = options
        geometry = _radians(ti[self._valid], pi_[self._valid], tr[self._valid], pr[self._valid])
        if model.prepare is not None:
            evaluate = model.prepare(*geometry, **options)
        else:
            kernel = model.kernel

            def evaluate(**params: float) -> np.ndarray:
                return kernel(*geometry, **params, **options)

        self._evaluate = evaluate

    def __call__(self, **values: Any) -> np.ndarray:
        """BRDF [1/sr] at the frozen geometries for these parameter values.

        The values are validated (:meth:`Model.resolve`: unknown names, non-numbers and
        values outside the physical bounds raise ``ValueError``); missing ones take their
        defaults.
        """
        params, _ = self.model.resolve({**values, **self._options})
        return self.unchecked(**params)

    def unchecked(self, **params: float) -> np.ndarray:
        """BRDF [1/sr] for parameter values that are already validated (no checks).

        The inner loop of a fit evaluates the model many times with values that it keeps
        inside the physical bounds itself; this path skips :meth:`Model.resolve` for them.

        Parameters
        ----------
        **params : float
            Every model parameter, as a float inside its physical range (as returned by
            :meth:`Model.resolve` or :meth:`Param.check`).  Nothing is checked, neither
            names nor ranges nor missing values: the result of anything else is undefined.
            Use ``self(**values)`` for values that come from users.

        Returns
        -------
        numpy.ndarray
            The same values as ``self(**params)`` [1/sr].
        """
        return self._scatter(self._evaluate(**params))

    def evaluate(self, vector, names: tuple[str, ...] | None = None, **fixed: float) -> np.ndarray:
        """Evaluate from a parameter vector (fitting's inner loop).

        Parameters
        ----------
        vector : sequence of float
            Values for ``names`` (all model parameters in order when ``names`` is None).
        names : tuple of str, optional
            Which parameters ``vector`` holds.
        **fixed
            Values of the remaining parameters.
        """
        names = self.model.param_names if names is None else names
        return self(**dict(zip(names, vector)), **fixed)

    def _scatter(self, values: np.ndarray) -> np.ndarray:
        if self._all_valid:  # the kernel saw the geometry flattened to 1-D
            values = np.asarray(values, dtype=float)
            if values.shape != (self._valid.size,):  # e.g. a constant BRDF as a scalar
                values = np.broadcast_to(values, (self._valid.size,))
            return values.reshape(self.shape).copy()
        out = np.zeros(self.shape)
        out[self._nan] = np.nan
        out[self._valid] = values
        return out


# ---------------------------------------------------------------------- registry
_REGISTRY: dict[str, Model] = {}


def register(model: Model) -> Model:
    """Add ``model`` to the registry under ``model.name`` and return it."""
    if model.name in _REGISTRY:
        raise ValueError(f"a model named {model.name!r} is already registered")
    if model.name != model.name.lower() or " " in model.name or "_" in model.name:
        raise ValueError(f"model name {model.name!r} must be lower-case with hyphens")
    _REGISTRY[model.name] = model
    return model


def available() -> list[str]:
    """Names of all registered models, sorted."""
    return sorted(_REGISTRY)


def get(name: str) -> Model:
    """The registered model called ``name``.

    Raises
    ------
    ValueError
        If no model has that name (the message lists close matches and all names).
    """
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        hint = difflib.get_close_matches(str(name), list(_REGISTRY), n=1)
        raise ValueError(
            f"unknown model {name!r}"
            + (f" (did you mean {hint[0]!r}?)" if hint else "")
            + f"; available models: {available()}"
        ) from None
