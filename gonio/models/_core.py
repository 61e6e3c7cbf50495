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
    "LinearForm",
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

    def check(self, value: Any, model: str) -> float | np.ndarray:
        """Return ``value`` as a float (or a float array), or raise ``ValueError``.

        Parameters
        ----------
        value : float or array_like
            One value, or an array of values (parameters broadcast like angles: a map of
            albedo over an image, a grid of roughness, walkers x geometries).
        model : str
            Model name, for the message.

        Returns
        -------
        float or numpy.ndarray
            A Python float for a scalar, a float array (same shape) otherwise.

        Raises
        ------
        ValueError
            ``value`` is not a real number (or array of them), or some element is NaN or
            outside the physical range; the message names the first offending element.
        """
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"model {model!r}: parameter {self.name!r} must be a real number (or an array of "
                f"them) in {self.range_text()} {self.unit}, got {value!r}"
            ) from None
        if array.ndim == 0:
            number = float(array)
            if math.isnan(number) or not self.contains(number):
                raise ValueError(
                    f"model {model!r}: parameter {self.name} = {number:g} {self.unit} is outside "
                    f"its valid range {self.range_text()} {self.unit} ({self.description})"
                )
            return number
        bad = ~self.contains_array(array)
        if bad.any():
            index = tuple(int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"model {model!r}: parameter {self.name}[{', '.join(map(str, index))}] = "
                f"{float(array[index]):g} {self.unit} is outside its valid range "
                f"{self.range_text()} {self.unit} ({self.description}); {int(bad.sum())} of "
                f"{array.size} values are"
            )
        return array

    def contains_array(self, values: np.ndarray) -> np.ndarray:
        """Elementwise :meth:`contains` of a float array (False for NaN)."""
        lo, hi = self.bounds
        with np.errstate(invalid="ignore"):
            above = values > lo if self.open_lower else values >= lo
            below = values < hi if self.open_upper else values <= hi
        return above & below


@dataclass(frozen=True)
class LinearForm:
    """A prepared model as a linear combination of geometry-only terms.

    ``f(params) = sum_k coefficients(**params)[k] * terms[k]`` at the points where
    ``exact`` is true, for every parameter value in range.  A model's ``prepare`` may
    attach a function building one to the function it returns (attribute ``linear_form``,
    :func:`with_linear_form`; built only when asked for, so the plain call pays nothing for
    it); averages over
    geometry (the instrument's apertures, :func:`gonio.instrument.aperture_averaged`) then
    average the K terms once instead of the model at every call.

    Parameters
    ----------
    terms : numpy.ndarray
        Shape (K, n): the geometry-only terms on the prepared (flat) geometry [1/sr per
        unit coefficient].
    coefficients : callable
        ``coefficients(**params) -> tuple`` of K values (floats, or arrays broadcasting
        like the parameters) [-].
    exact : numpy.ndarray or None
        Shape (n,), where the combination equals the model for every parameter value (False
        where, e.g., a floor at 0 can act); None means everywhere.
    """

    terms: np.ndarray
    coefficients: Callable[..., tuple]
    exact: np.ndarray | None = None

    def combine(self, coefficients: tuple, terms: np.ndarray | None = None) -> np.ndarray:
        """``sum_k coefficients[k] * terms[k]`` (``terms`` defaults to :attr:`terms`)."""
        terms = self.terms if terms is None else terms
        out = np.multiply(coefficients[0], terms[0])
        for c, t in zip(coefficients[1:], terms[1:]):
            out = out + np.multiply(c, t)
        return out


def with_linear_form(evaluate: Callable[..., np.ndarray], build: Callable[[], LinearForm]) -> Callable[..., np.ndarray]:
    """Attach ``build`` (a function returning the :class:`LinearForm` of ``evaluate``) to
    a prepared model function as its attribute ``linear_form``, and return the function."""
    evaluate.linear_form = build  # type: ignore[attr-defined]
    return evaluate


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
#: Geometries evaluated at a time by the plain call on large inputs: the arrays of one
#: chunk (64 KiB each) stay in the cache and below the allocator's mmap threshold.
CHUNK = 8192
#: Geometries per chunk of the allocation-free plain call (:attr:`Model.fill`): each chunk
#: pays the ~50 numpy calls' own cost once for 4 times as many geometries as a
#: :data:`CHUNK`, its temporaries (about 13 arrays of 256 KiB) still in the caches
#: (2e6 Oren-Nayar geometries: 32 ms against 38 ms in chunks of 8192 at a load of 2 on
#: the 2-core benchmark machine, equal at a load of 0.8; 131072 was no better).
FILL_CHUNK = 4 * CHUNK
#: Smallest plain call evaluated in chunks, and through a model's compiled path where it
#: has one (:attr:`Model.compiled`): a smaller call never pays for loading numba.
COMPILED_MIN = 2 * CHUNK
#: Geometries the plain calls of a process evaluate with numpy before the compiled paths
#: are loaded.  Loading numba and the cached loops costs about 0.5 s (1.1 s when they
#: must be compiled; benchmarks/closed_form_speed.py), what numpy needs for about 2e7
#: Oren-Nayar geometries; switching once the numpy work has cost as much bounds a
#: process's total at twice the better of the two choices, whatever it evaluates later
#: (the rent-or-buy rule), and a single call of moderate size never waits for numba.
COMPILED_AFTER = 20_000_000
_numpy_geometries = 0
#: Largest plain call evaluated one geometry at a time in plain Python, through a model's
#: :attr:`Model.point` where it has one: up to it, about 0.55 us per geometry beats the
#: fixed cost of the numpy path's ~60 array operations, about 50 us whatever the size
#: below a few hundred geometries (for Oren-Nayar the two meet near 80 geometries,
#: benchmarks/bench_call_overhead.py).
POINT_MAX = 64
#: Types of the scalar arguments the small plain call takes as they are.
_SCALAR_TYPES = (float, int, np.float64)
#: The (native, canonical) float64 dtype of the arrays the small plain call takes.
_FLOAT64 = np.dtype(np.float64)


def _compiled_due(size: int) -> bool:
    """Whether a plain call of ``size`` geometries takes the compiled path; otherwise it
    counts towards :data:`COMPILED_AFTER`."""
    global _numpy_geometries
    if _numpy_geometries >= COMPILED_AFTER:
        return True
    _numpy_geometries += size
    return False


def _as_angles(
    theta_i: Any, phi_i: Any, theta_r: Any, phi_r: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Broadcast the four angles [deg] to float arrays and reject negative polar angles."""
    arrays = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (theta_i, phi_i, theta_r, phi_r))
    )
    for label, theta in (("theta_i", arrays[0]), ("theta_r", arrays[2])):
        # one pass, no temporary: the smallest non-NaN angle (fmin ignores NaN)
        if theta.size and np.fmin.reduce(theta, axis=None) < 0:
            bad = float(theta[theta < 0].flat[0])
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
    broadcasts_params : bool
        Whether ``kernel`` (or the function ``prepare`` returns) accepts parameter arrays
        that broadcast against the geometry arrays (numpy broadcasting, any shapes).  When
        False, array parameters are evaluated one distinct parameter combination at a
        time (:func:`_evaluate_by_combination`): the same values, slower.  Every model
        that sets it is tested against that loop (tests/test_models_contract.py).
    compiled : callable, optional
        ``compiled() -> evaluate``: loads (importing numba) a compiled plain call
        ``evaluate(theta_i, phi_i, theta_r, phi_r, params, options)`` of 1-D contiguous
        angles [deg] and checked scalar parameters, giving the BRDF [1/sr] with the
        horizon and NaN rules (:mod:`gonio.models._compiled`).  Used for plain calls of
        at least :data:`COMPILED_MIN` geometries once the process has evaluated
        :data:`COMPILED_AFTER` geometries with numpy; a faster path of the same formula,
        tested equal to ``kernel``/``prepare`` (tests/models/test_compiled_closed_forms.py).
    point : callable, optional
        ``point(params, options) -> value``: for checked scalar parameters (floats), a
        plain-Python ``value(theta_i, phi_i, theta_r, phi_r) -> float``, the BRDF [1/sr]
        of one geometry given as floats [deg], returning :func:`outside` of the angles
        unless ``0 <= theta <= 90`` holds for both polar angles (and NaN for a NaN
        azimuth, as its formula gives; an infinite azimuth may raise).  Used for
        plain calls of at most :data:`POINT_MAX` geometries given as floats or float64
        arrays of one shape with float parameters (:meth:`_call_points`): a call then
        costs a few microseconds instead of the numpy path's ~50 array operations.
        Tested equal to ``prepare`` to 1e-14 (tests/test_models_fast_paths.py).
    fill : callable, optional
        ``fill(params, options, size) -> f``: for checked scalar parameters, a function
        ``f(theta_i, phi_i, theta_r, phi_r, out)`` writing the BRDF [1/sr] of at most
        ``size`` flat geometries [rad] (above the horizon, not NaN) into ``out`` without
        allocating (its temporaries are allocated once by ``fill``).  Used for plain
        calls of at least :data:`CHUNK` geometries that the compiled path leaves,
        :data:`FILL_CHUNK` geometries at a time (:meth:`_call_filled`); the same operations as
        ``prepare`` (smaller calls, where the numpy calls' own cost dominates, go through
        ``prepare``: 40 % faster at 100 geometries, equal at 8192).
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
    broadcasts_params: bool = False
    compiled: Callable[[], Callable[..., np.ndarray]] | None = None
    point: Callable[[dict, dict], Callable[[float, float, float, float], float]] | None = None
    fill: Callable[[dict, dict, int], Callable[..., np.ndarray]] | None = None
    _by_name: Mapping[str, Param] = field(init=False, repr=False, compare=False)
    _names: frozenset = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if (self.kernel is None) == (self.prepare is None):
            raise TypeError(f"model {self.name!r}: give exactly one of kernel or prepare")
        object.__setattr__(self, "_by_name", {p.name: p for p in self.params})
        object.__setattr__(self, "_names", frozenset(self._by_name) | {o.name for o in self.options})

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

    def _flat_call(self, geometry: tuple[np.ndarray, ...], params: dict[str, Any], options) -> np.ndarray:
        """Kernel values on flat (1-D, equal length) geometry [rad] and parameter arrays."""
        if self.broadcasts_params:
            return self._kernel_call(*geometry, params, options)
        return _evaluate_by_combination(
            params, lambda index, scalars: self._kernel_call(*(g[index] for g in geometry), scalars, options),
            geometry[0].size,
        )

    def __call__(self, theta_i, phi_i, theta_r, phi_r, **values: Any) -> np.ndarray:
        """Evaluate the BRDF [1/sr] at angles in degrees.

        Parameters
        ----------
        theta_i, phi_i : array_like
            Polar angle and azimuth of the source direction [deg].
        theta_r, phi_r : array_like
            Polar angle and azimuth of the viewing direction [deg].
        **values
            Model parameters (scalars or arrays that broadcast with the angles) and
            options.

        Returns
        -------
        numpy.ndarray
            BRDF [1/sr] with the broadcast shape of the angles and parameters; 0 below
            the horizon, NaN where any angle is NaN.
        """
        if self.point is not None:
            out = self._call_points(theta_i, phi_i, theta_r, phi_r, values)
            if out is not None:
                return out
        params, options = self.resolve(values)
        ti, pi_, tr, pr = _as_angles(theta_i, phi_i, theta_r, phi_r)
        if _any_array(params):
            return self._call_broadcast(ti, pi_, tr, pr, params, options)
        if ti.size >= COMPILED_MIN and self.compiled is not None and _compiled_due(ti.size):
            return self._call_compiled(ti, pi_, tr, pr, params, options)
        if self.fill is not None and ti.size >= CHUNK:
            return self._call_filled(ti, pi_, tr, pr, params, options)
        if ti.size >= COMPILED_MIN:
            return self._call_in_chunks(ti, pi_, tr, pr, params, options)
        return self._call_scalar_params(ti, pi_, tr, pr, params, options)

    def _call_points(self, theta_i, phi_i, theta_r, phi_r, values: Mapping[str, Any]) -> np.ndarray | None:
        """The plain call through :attr:`point`, one geometry at a time in plain Python, or
        None when the call is not a small one of known names with float parameters inside
        their ranges and angles that are floats or float64 arrays of one shape (every
        other call, and every error, is left to the general path).

        Returns
        -------
        numpy.ndarray or None
            BRDF [1/sr] with the angles' shape (0-d for float angles); 0 below the
            horizon, NaN where an angle is NaN.
        """
        columns = _point_columns(theta_i, phi_i, theta_r, phi_r)
        if columns is None:
            return None
        checked = self._float_values(values)
        if checked is None:
            return None
        shape, angles = columns
        try:
            out = list(map(self.point(*checked), *angles))
        except (ValueError, ArithmeticError):  # a negative polar angle, an infinite azimuth
            return None
        if shape is None:
            return np.array(out[0])
        return np.array(out) if len(shape) == 1 else np.array(out).reshape(shape)

    def _float_values(self, values: Mapping[str, Any]) -> tuple[dict[str, float], dict[str, Any]] | None:
        """:meth:`resolve` for known names and float values inside their ranges, else None."""
        if not self._names.issuperset(values):
            return None
        params = {}
        for p in self.params:
            value = values.get(p.name, p.default)
            if type(value) not in _SCALAR_TYPES or not p.contains(value):
                return None
            params[p.name] = float(value)
        options = {}
        for o in self.options:
            value = values.get(o.name, o.default)
            if value not in o.choices:
                return None
            options[o.name] = value
        return params, options

    def _call_filled(self, ti, pi_, tr, pr, params, options) -> np.ndarray:
        """The plain call through :attr:`fill`, :data:`FILL_CHUNK` geometries at a time,
        with preallocated temporaries: the arrays of a chunk stay in the processor's
        caches, and nothing is allocated and freed per chunk, so a process's first large
        call does not fault in fresh pages chunk after chunk (glibc returns the freed top
        of its heap to the system until a large block has been freed once: through
        ``prepare`` in chunks, the first call of 2e6 Oren-Nayar geometries in a fresh
        interpreter took 3 times as long as the next, benchmarks/closed_form_speed.py).
        Chunks with a geometry below the horizon or a NaN (or infinite) angle go through
        :meth:`_call_scalar_params`."""
        flat = [np.ravel(a) for a in (ti, pi_, tr, pr)]
        size = ti.size
        out = np.empty(size)
        width = min(size, FILL_CHUNK)
        fill = self.fill(params, options, width)
        radians = np.empty((4, width))
        for start in range(0, size, FILL_CHUNK):
            part = slice(start, start + FILL_CHUNK)
            chunk = [a[part] for a in flat]
            if _inside(*chunk):
                rows = radians[:, : chunk[0].size]
                for angle, row in zip(chunk, rows):
                    np.multiply(angle, _DEGREE, out=row)
                fill(*rows, out[part])
            else:
                out[part] = self._call_scalar_params(*chunk, params, options)
        return out.reshape(ti.shape)

    def _call_compiled(self, ti, pi_, tr, pr, params, options) -> np.ndarray:
        """:meth:`_call_in_chunks` through the model's compiled path (:attr:`compiled`)."""
        flat = [np.ascontiguousarray(np.ravel(a)) for a in (ti, pi_, tr, pr)]
        return self.compiled()(*flat, params, options).reshape(ti.shape)

    def _call_scalar_params(self, ti, pi_, tr, pr, params, options) -> np.ndarray:
        """The BRDF of checked scalar parameters at angles [deg] of one shape."""
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

    def _call_in_chunks(self, ti, pi_, tr, pr, params, options) -> np.ndarray:
        """:meth:`_call_scalar_params` on :data:`CHUNK` geometries at a time: the model's
        temporaries then stay in the processor's cache instead of streaming through
        memory (2 to 3 times faster for the closed forms on 1e6 geometries,
        benchmarks/closed_form_speed.py)."""
        flat = [np.ravel(a) for a in (ti, pi_, tr, pr)]
        out = np.empty(ti.size)
        for start in range(0, ti.size, CHUNK):
            part = slice(start, start + CHUNK)
            out[part] = self._call_scalar_params(*(a[part] for a in flat), params, options)
        return out.reshape(ti.shape)

    def _call_broadcast(self, ti, pi_, tr, pr, params, options) -> np.ndarray:
        """:meth:`__call__` with array parameters: everything broadcast, valid points flat."""
        shape = np.broadcast_shapes(ti.shape, *(np.shape(v) for v in params.values()))
        angles = [np.broadcast_to(a, shape) for a in (ti, pi_, tr, pr)]
        valid, nan = _domain(*angles)
        out = np.zeros(shape)
        out[nan] = np.nan
        if valid.any():
            geometry = _radians(*(a[valid] for a in angles))
            flat = {k: (np.broadcast_to(v, shape)[valid] if np.ndim(v) else v) for k, v in params.items()}
            out[valid] = np.broadcast_to(self._flat_call(geometry, flat, options), geometry[0].shape)
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


def _inside(ti: np.ndarray, pi_: np.ndarray, tr: np.ndarray, pr: np.ndarray) -> bool:
    """Whether every geometry [deg] is above the horizon with finite angles, by four
    reductions (no temporaries): a NaN makes the maxima NaN, a NaN or an infinity the
    sums not finite; False also when finite azimuths sum to an overflow (the caller's
    general path is right for every geometry)."""
    return bool(np.maximum.reduce(ti) <= _RIGHT_ANGLE and np.maximum.reduce(tr) <= _RIGHT_ANGLE
                and math.isfinite(np.add.reduce(pi_)) and math.isfinite(np.add.reduce(pr)))


def _point_columns(theta_i: Any, phi_i: Any, theta_r: Any, phi_r: Any) -> tuple[tuple[int, ...] | None, list] | None:
    """The four angles [deg] of a small plain call as columns (lists of floats).

    Returns
    -------
    (shape, columns) or None
        ``shape`` None for four scalar angles (columns of one float each), else the shape
        of the float64 arrays (scalars repeated along them); None when an angle is neither
        a float nor a float64 array, the arrays differ in shape, or the call has more
        than :data:`POINT_MAX` geometries.
    """
    angles = (theta_i, phi_i, theta_r, phi_r)
    ndarray = np.ndarray
    if type(theta_i) is ndarray and type(phi_i) is ndarray and type(theta_r) is ndarray and type(phi_r) is ndarray:
        shape = theta_i.shape   # the common case, checked at once
        if (theta_i.size > POINT_MAX or not (phi_i.shape == theta_r.shape == phi_r.shape == shape)
                or not (theta_i.dtype is phi_i.dtype is theta_r.dtype is phi_r.dtype is _FLOAT64)):
            return None
        if len(shape) == 1:
            return shape, [theta_i.tolist(), phi_i.tolist(), theta_r.tolist(), phi_r.tolist()]
        return shape, [a.ravel().tolist() for a in angles]
    shape = None
    for angle in angles:
        kind = type(angle)
        if kind is float or kind is int or kind is np.float64:
            continue
        if kind is not ndarray or angle.dtype is not _FLOAT64:
            return None
        if shape is None:
            size = angle.size
            if size > POINT_MAX:
                return None
            shape = angle.shape
        elif angle.shape != shape:
            return None
    if shape is None:
        return None, [(float(a),) for a in angles]
    return shape, [a.ravel().tolist() if type(a) is ndarray else [float(a)] * size for a in angles]


def outside(theta_i: float, phi_i: float, theta_r: float, phi_r: float) -> float:
    """The BRDF [1/sr] of a geometry [deg] outside the domain of a model's formula: NaN
    where an angle is NaN, else 0 (below the horizon); ``ValueError`` for a negative
    polar angle.

    The rule of :func:`_domain` for one geometry, called by a model's one-geometry
    ``value`` (:attr:`Model.point`) when ``0 <= theta <= 90`` fails for theta_i or
    theta_r; the small plain call leaves the ``ValueError`` to the general path, which
    raises with its message.
    """
    if theta_i != theta_i or theta_r != theta_r or phi_i != phi_i or phi_r != phi_r:
        return math.nan
    if theta_i < 0.0 or theta_r < 0.0:
        raise ValueError("negative polar angle")
    return 0.0


_DEGREE = math.pi / 180.0


def _radians(*angles: np.ndarray) -> tuple[np.ndarray, ...]:
    # a multiplication by pi/180: the same values as np.radians, at a quarter of its cost
    return tuple(a * _DEGREE for a in angles)


def _any_array(params: Mapping[str, Any]) -> bool:
    """Whether any checked parameter value is an array (checked scalars are floats)."""
    return any(isinstance(v, np.ndarray) for v in params.values())


def _distinct_rows(table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of a 2-D ``table`` and each row's index among them, as
    ``np.unique(table, axis=0, return_inverse=True)`` (inverse flat).

    Parameter tables repeat each combination over long runs of consecutive rows (a
    batch row's value over every geometry and sub-ray of an aperture average), so the
    sort runs over the first row of each run only: sorting every row had been a third
    of the time of fitting ``pitted`` to a misaligned rig's recording.

    Examples
    --------
    >>> rows, index = _distinct_rows(np.array([[2.0, 1.0], [2.0, 1.0], [0.5, 1.0], [2.0, 1.0]]))
    >>> rows.tolist(), index.tolist()
    ([[0.5, 1.0], [2.0, 1.0]], [1, 1, 0, 1])
    """
    if table.shape[0] == 0:
        return table[:0], np.zeros(0, dtype=np.intp)
    starts = np.flatnonzero(np.concatenate(([True], np.any(table[1:] != table[:-1], axis=1))))
    distinct, run_index = np.unique(table[starts], axis=0, return_inverse=True)
    return distinct, np.repeat(run_index.reshape(-1), np.diff(np.append(starts, table.shape[0])))


def _members(index: np.ndarray, count: int) -> list[np.ndarray]:
    """The positions of each value ``0 .. count - 1`` in ``index``, in order: one stable sort
    instead of a comparison of every position per value (quadratic where each of two
    thousand particles of an evidence's sampler is its own combination).

    >>> [m.tolist() for m in _members(np.array([1, 0, 1, 2]), 3)]
    [[1], [0, 2], [3]]
    """
    order = np.argsort(index, kind="stable")
    return np.split(order, np.searchsorted(index[order], np.arange(1, count)))


def _evaluate_by_combination(
    params: Mapping[str, Any], evaluate: Callable[[np.ndarray, dict[str, float]], np.ndarray], size: int
) -> np.ndarray:
    """Values of a scalar-parameter kernel for parameter arrays, one combination at a time.

    Parameters
    ----------
    params : mapping
        Parameter values: floats, or arrays broadcastable to shape ``(..., size)`` whose last
        axis runs along the (flat) geometry.
    evaluate : callable
        ``evaluate(index, scalars)``: the kernel at the geometry points ``index`` (an index
        array into the flat geometry) for scalar parameter values ``scalars``.
    size : int
        Number of flat geometry points.

    Returns
    -------
    numpy.ndarray
        Shape: the broadcast shape of the parameters and ``(size,)``.
    """
    shape = np.broadcast_shapes((size,), *(np.shape(v) for v in params.values()))
    names = list(params)
    table = np.stack([np.broadcast_to(np.asarray(params[n], float), shape).reshape(-1) for n in names], axis=1)
    combinations, inverse = _distinct_rows(table)
    point = np.broadcast_to(np.arange(size), shape).reshape(-1)
    out = np.empty(table.shape[0])
    for row, where in zip(combinations, _members(inverse, len(combinations))):
        values = evaluate(point[where], {n: float(x) for n, x in zip(names, row)})
        out[where] = np.broadcast_to(np.asarray(values, float), where.shape)
    return out.reshape(shape)


class FixedGeometryModel:
    """A model bound to fixed geometries: ``f(**params)`` or ``f.evaluate(vector)``.

    Created by :meth:`Model.at`.  Geometry-only terms are computed once (when the model
    supplies ``prepare``); each call only combines them with the parameters.

    Parameters may be arrays that broadcast against the geometry's shape ``self.shape``
    (numpy rules): ``rho`` of shape ``(W, 1)`` with geometries of shape ``(N,)`` gives a
    ``(W, N)`` result, one row per walker of an ensemble sampler.
    """

    def __init__(self, model: Model, ti, pi_, tr, pr, options: dict[str, Any]):
        self.model = model
        self.shape = ti.shape
        self._valid, self._nan = _domain(ti, pi_, tr, pr)
        self._all_valid = bool(self._valid.all())
        self._valid_flat = np.flatnonzero(self._valid)
        self._options = options
        self._geometry = _radians(ti[self._valid], pi_[self._valid], tr[self._valid], pr[self._valid])
        if model.prepare is not None:
            evaluate = model.prepare(*self._geometry, **options)
        else:
            kernel, geometry = model.kernel, self._geometry

            def evaluate(**params: float) -> np.ndarray:
                return kernel(*geometry, **params, **options)

        self._evaluate = evaluate

    @property
    def prepared(self) -> Callable[..., np.ndarray]:
        """The model's function of the parameters on the valid geometries (flat, [1/sr])."""
        return self._evaluate

    def linear_form(self) -> LinearForm | None:
        """The model's :class:`LinearForm` on all ``self.shape`` geometries (flattened), or
        None when the model has none or a geometry is NaN.

        Geometries below the horizon get zero terms (the BRDF is 0 there for every
        parameter value) and count as exact.
        """
        build = getattr(self._evaluate, "linear_form", None)
        if build is None or self._nan.any():
            return None
        form = build()
        terms = np.zeros((len(form.terms), self._valid.size))
        terms[:, self._valid_flat] = np.asarray(form.terms, float).reshape(len(form.terms), -1)
        exact = np.ones(self._valid.size, bool)
        if form.exact is not None:
            exact[self._valid_flat] = np.reshape(form.exact, -1)
        return LinearForm(terms, form.coefficients, exact)

    def __call__(self, **values: Any) -> np.ndarray:
        """BRDF [1/sr] at the frozen geometries for these parameter values.

        The values are validated (:meth:`Model.resolve`: unknown names, non-numbers and
        values outside the physical bounds raise ``ValueError``); missing ones take their
        defaults.  Array values broadcast against ``self.shape``.
        """
        params, _ = self.model.resolve({**values, **self._options})
        return self.unchecked(**params)

    def unchecked(self, **params: Any) -> np.ndarray:
        """BRDF [1/sr] for parameter values that are already validated (no checks).

        The inner loop of a fit evaluates the model many times with values that it keeps
        inside the physical bounds itself; this path skips :meth:`Model.resolve` for them.

        Parameters
        ----------
        **params : float or numpy.ndarray
            Every model parameter, as a float (or float array broadcasting against
            ``self.shape``) inside its physical range (as returned by
            :meth:`Model.resolve` or :meth:`Param.check`).  Nothing is checked, neither
            names nor ranges nor missing values: the result of anything else is undefined.
            Use ``self(**values)`` for values that come from users.

        Returns
        -------
        numpy.ndarray
            The same values as ``self(**params)`` [1/sr].
        """
        if not _any_array(params):
            return self._scatter(self._evaluate(**params))
        lead, flat = self._flat_params(params)
        if self.model.broadcasts_params:
            values = self._evaluate(**flat)
        elif all(np.shape(v)[-1:] in ((), (1,)) for v in flat.values()):
            values = self._by_leading_combination(flat, lead)
        else:
            values = self.model._flat_call(self._geometry_for(lead), _broadcast_flat(flat, lead, self._valid_flat.size),
                                           self._options).reshape(lead + (-1,))
        return self._scatter(values, lead)

    def _flat_params(self, params: Mapping[str, Any]) -> tuple[tuple[int, ...], dict[str, Any]]:
        """The leading (batch) shape and the parameters reshaped to ``(..., 1)`` (constant
        over the geometry) or ``(..., n_valid)`` (varying along it)."""
        columns = [v for v in params.values() if np.ndim(v)]
        if len(self.shape) == 1 and all(np.ndim(v) == 2 and np.shape(v)[1] == 1 for v in columns):
            # the sampler's case: (W, 1) columns against N flat geometries, nothing to reshape
            return np.broadcast_shapes(*(np.shape(v)[:1] for v in columns)), dict(params)
        geometry_ndim = len(self.shape)
        shape = np.broadcast_shapes(self.shape, *(np.shape(v) for v in params.values()))
        lead = shape[: len(shape) - geometry_ndim]
        flat: dict[str, Any] = {}
        for name, value in params.items():
            if np.ndim(value) == 0:
                flat[name] = value
                continue
            padded = np.reshape(value, (1,) * (len(shape) - np.ndim(value)) + np.shape(value))
            batch = padded.shape[: len(lead)]
            if all(n == 1 for n in padded.shape[len(lead):]):
                flat[name] = padded.reshape(batch + (1,))
            else:
                along = np.broadcast_to(padded, batch + self.shape).reshape(batch + (-1,))
                flat[name] = along[..., self._valid_flat]
        return lead, flat

    def _by_leading_combination(self, flat: Mapping[str, Any], lead: tuple[int, ...]) -> np.ndarray:
        """Values for parameters constant over the geometry, one combination at a time."""
        n = self._valid_flat.size
        rows = {k: (np.broadcast_to(v, lead + (1,)).reshape(-1) if np.ndim(v) else v) for k, v in flat.items()}
        size = int(np.prod(lead, dtype=int))
        names = list(rows)
        columns = np.stack([np.broadcast_to(np.asarray(rows[k], float), (size,)) for k in names], axis=1)
        combinations, inverse = _distinct_rows(columns)
        out = np.empty((size, n))
        for row, where in zip(combinations, _members(inverse, len(combinations))):
            values = self._evaluate(**{name: float(x) for name, x in zip(names, row)})
            out[where] = np.broadcast_to(np.asarray(values, float), (n,))
        return out.reshape(lead + (n,))

    def _geometry_for(self, lead: tuple[int, ...]) -> tuple[np.ndarray, ...]:
        """The valid geometry [rad] repeated over the leading shape, flat."""
        return tuple(np.broadcast_to(g, lead + g.shape).reshape(-1) for g in self._geometry)

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

    def _scatter(self, values: np.ndarray, lead: tuple[int, ...] = ()) -> np.ndarray:
        """Flat values on the valid geometries -> shape ``lead + self.shape`` (0 below the
        horizon, NaN where an angle is NaN)."""
        values = np.broadcast_to(np.asarray(values, dtype=float), lead + (self._valid_flat.size,))
        if self._all_valid:  # the kernel saw the geometry flattened to 1-D
            return values.reshape(lead + self.shape).copy()
        out = np.zeros(lead + self.shape)
        out[..., self._nan] = np.nan
        out[..., self._valid] = values
        return out


def _broadcast_flat(flat: Mapping[str, Any], lead: tuple[int, ...], n: int) -> dict[str, Any]:
    """Parameters of shape ``(..., 1)`` or ``(..., n)`` broadcast to ``lead + (n,)`` and flattened."""
    return {k: (np.broadcast_to(v, lead + (n,)).reshape(-1) if np.ndim(v) else v) for k, v in flat.items()}


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
