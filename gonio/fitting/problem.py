"""The fit problem: a registered model, a dataset, fixed parameters and the likelihood.

:class:`FitProblem` owns everything the least-squares fit and the sampler share: the
parameter specifications (names, units, bounds from ``gonio.models.get(name).params``, plus
the nuisance parameters ``scale`` and ``jitter`` when they apply), which parameters are fixed,
the model prediction of the measured quantity (through the fixed-geometry fast path
:meth:`gonio.models.Model.at`), the weighted residuals and the Gaussian log-likelihood.

Nuisance parameters
-------------------
``scale`` [data units sr]
    Only for ``quantity='radiance'`` (relative radiance): prediction = scale f_r cos(theta_i).
``jitter`` [data units]
    Optional extra noise, added in quadrature to every measurement's uncertainty:
    sigma_tot^2 = sigma^2 + jitter^2 (for correlated data, ``jitter^2`` is added to the
    covariance's diagonal).
``rel_jitter`` [-]
    The relative (multiplicative) form: sigma_tot^2 = sigma^2 + (rel_jitter x prediction)^2,
    for scatter that grows with the signal (an unmonitored lamp, speckle). Range [0, 10].  It absorbs scatter the quoted uncertainties miss
    (speckle, sample inhomogeneity, model error).  Its physical range is taken as
    [0, 10 (max|value| + max sigma)]: scatter ten times the signal would make the data
    meaningless, and a finite range gives it a proper uniform prior.
``view_offset``, ``theta_i_offset``, ``phi_i_offset``, ``tilt_x``, ``tilt_y`` [deg]
    The rig's alignment (``alignment=``): axis zero offsets and the sample's tilt. The
    model is then evaluated at the true geometry of every walker
    (:mod:`gonio.fitting.rig_errors`), so the linear models' sufficient statistics and the
    fixed-geometry fast path do not apply; with every alignment value 0 the likelihood is
    the plain one exactly. Their default priors are normal (N(0, 0.5 deg)):
    :meth:`FitProblem.priors_with_defaults` adds them, as :func:`gonio.fitting.fit` and
    :func:`gonio.fitting.compare_models` do.
``texture_slope`` [deg]
    The rms of the sample's mesoscale slope (``alignment="texture_slope"``): the model is
    averaged over the sample's facets (:mod:`gonio.fitting.rig_errors`). Range [0, 3],
    uniform prior.
``stray_light`` [-]
    Stray radiance over the image as a fraction of ``E_0 / pi`` (``stray_light=True``),
    added to the sample's radiance and to the reference standard's
    (:mod:`gonio.fitting.rig_errors`). Range [0, 0.05], uniform prior.

Correlated errors
-----------------
A dataset with a ``covariance`` C is fitted by generalised least squares: the residual
vector is whitened, r_w = W (prediction - value) with W^T W = C^-1, so chi^2 = r^T C^-1 r
and the Gaussian log-likelihood is -chi^2/2 - 1/2 log det C - n/2 log(2 pi). W is
diag(1/sigma) for independent errors, L^-1 for a dense C = L L^T (Cholesky), and the
symmetric root of C^-1 for a diagonal plus low rank (:class:`gonio.fitting.LowRankCovariance`,
what a reduction gives), never formed as an n x n matrix (:mod:`gonio.fitting.covariance`,
:attr:`FitProblem.noise`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from gonio import models
from gonio.models import Model, Param

from .covariance import DenseNoise, LowRankNoise, noise_of
from .dataset import Dataset
from .evaluation import combine_prediction, evaluated_model
from .rig_errors import ALIGNMENT_PARAMETERS, GEOMETRY_NAMES, RIG_ERROR_NAMES, STRAY_LIGHT, TEXTURE_SLOPE, \
    RigPrediction, alignment_prior, is_identity, parse_alignment
from .priors import Prior

__all__ = ["FitProblem", "combine_prediction", "predict_quantity"]

_SCALE_DESCRIPTION = "radiance per unit BRDF and unit cos(theta_i): irradiance times detector gain"
_JITTER_DESCRIPTION = "extra noise added in quadrature to the measurement uncertainties"
_REL_JITTER_DESCRIPTION = "extra noise proportional to the prediction, added in quadrature to the uncertainties"
#: The extra-noise parameter of each jitter mode.
NOISE_PARAMETERS = {"absolute": "jitter", "relative": "rel_jitter"}
#: Most predictions (rows x values) the batch methods hold at once: 32 MB of doubles per
#: temporary (chi_square_batch, pointwise_log_likelihood_batch, replicated_data).
BATCH_ELEMENTS = 2**22


def jitter_mode(jitter: bool | str | None) -> str | None:
    """``None`` (no extra noise), ``"absolute"`` (``jitter``) or ``"relative"`` (``rel_jitter``).

    ``True`` means absolute. Examples: ``jitter_mode(True) == "absolute"``.
    """
    if jitter in (None, False):
        return None
    if jitter is True:
        return "absolute"
    if jitter not in NOISE_PARAMETERS:
        raise ValueError(f"jitter={jitter!r} is not one of False, True, 'absolute', 'relative'")
    return str(jitter)


def predict_quantity(
    model: str | Model,
    quantity: str,
    theta_i: Any,
    phi_i: Any,
    theta_r: Any,
    phi_r: Any,
    values: Mapping[str, float],
    options: Mapping[str, Any] | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> np.ndarray:
    """Predicted measured quantity at arbitrary geometries [deg] (plots, reports).

    ``values`` holds the model parameters and, for relative radiance, ``scale``; other keys
    (``jitter``) are ignored. Rig errors among them (alignment values, ``stray_light``: not
    all 0) make it the prediction of that rig at these recorded geometries
    (:class:`gonio.fitting.rig_errors.RigPrediction`, with the dataset's ``metadata`` for
    its reference standard); parameter values may then be columns (D, 1) against flat
    geometries, giving (D, N).
    """
    model = models.get(model) if isinstance(model, str) else model
    params = {k: v for k, v in values.items() if k in model.param_names}
    if not is_identity({k: v for k, v in values.items() if k in RIG_ERROR_NAMES}):
        flat = [np.ravel(a) for a in np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))]
        out = RigPrediction(model, quantity, flat, dict(options or {}), metadata or {}).of_values(values)
        return out.reshape(np.shape(out)[:-1] + np.broadcast(theta_i, phi_i, theta_r, phi_r).shape)
    ti, pi_, tr, pr = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_i, phi_i, theta_r, phi_r)))
    brdf = model(ti, pi_, tr, pr, **params, **dict(options or {}))
    normal = model(ti, pi_, np.zeros_like(tr), pi_, **params, **dict(options or {})) if quantity == "normalised_radiance" else None
    return combine_prediction(quantity, brdf, normal, np.cos(np.radians(ti)), float(values.get("scale", 1.0)))


@dataclass
class FloorPoints:
    """The measurements a model's linear form does not describe exactly (where eq 33's
    floor can act), evaluated with the model itself: their chi-square for many parameter
    rows at once (independent errors).

    Attributes
    ----------
    fast : FrozenModel
        The model at these points' geometry (``Model.at``).
    value, sigma : numpy.ndarray, shape (M,)
        Their values and standard uncertainties.
    cos_i : numpy.ndarray or None
        cos(theta_i) for radiance data (prediction = scale BRDF cos theta_i); None for BRDF.
    """

    fast: Any
    value: np.ndarray
    sigma: np.ndarray
    cos_i: np.ndarray | None = None

    def residuals(self, params: Mapping[str, Any], scale: Any = 1.0) -> np.ndarray:
        """(prediction - value) / sigma for parameters given as (W, 1) columns or floats;
        shape (W, M) (NaN where a prediction is undefined)."""
        predicted = np.asarray(self.fast.unchecked(**params), float)
        if self.cos_i is not None:
            predicted = predicted * self.cos_i * scale
        return np.atleast_2d((predicted - self.value) / self.sigma)

    def chi_square(self, params: Mapping[str, Any], scale: Any = 1.0) -> np.ndarray:
        """Sum over the points of ((prediction - value) / sigma)^2 for parameters given as
        (W, 1) columns or floats; shape (W,) (NaN where a prediction is undefined)."""
        return np.sum(self.residuals(params, scale) ** 2, axis=-1)


@dataclass
class SharedSources:
    """What the shared error sources of a diagonal plus low rank covariance ``D + U U^T``
    take off the chi-square of independent errors ``D`` on the linear path.

    With ``I + U^T D^-1 U = L L^T`` (k x k), Woodbury gives ``r^T C^-1 r = r^T D^-1 r -
    |L^-1 U^T D^-1 r|^2``. The first term is a :class:`QuadraticChiSquare` on the exact
    points plus :class:`FloorPoints` on the others, both whitened by ``D``; the second is
    ``|A c - a + B z|^2`` with the exact points' ``A = L^-1 U_E^T D_E^-1 T_E^T`` (k x K) and
    ``a = L^-1 U_E^T D_E^-1 y_E``, and ``B = L^-1 U_F^T D_F^-1/2`` applied to the floor
    points' residuals ``z = D_F^-1/2 (prediction - value)``: each walker costs K k + M k
    operations, whatever the number of exact points.

    Attributes
    ----------
    terms : numpy.ndarray, shape (k, K)
        ``A``.
    value : numpy.ndarray, shape (k,)
        ``a``.
    floor : numpy.ndarray, shape (k, M)
        ``B`` (M = 0 without floor points).
    """

    terms: np.ndarray
    value: np.ndarray
    floor: np.ndarray

    @classmethod
    def of(cls, covariance: Any, terms: np.ndarray, value: np.ndarray, exact: np.ndarray) -> "SharedSources":
        """For a :class:`~gonio.fitting.LowRankCovariance`, the linear form's ``terms``
        (K, N), the data ``value`` (N,) and which points the form describes exactly."""
        d, u = covariance.independent, covariance.factors
        inner = np.eye(covariance.rank) + u.T @ (u / d[:, None])
        factor = np.linalg.cholesky(inner)
        weighted = u[exact] / d[exact, None]  # D_E^-1 U_E
        solve = lambda m: np.linalg.solve(factor, m)  # noqa: E731 (L^-1 applied to m)
        return cls(solve(weighted.T @ terms[:, exact].T), solve(weighted.T @ value[exact]),
                   solve((u[~exact] / np.sqrt(d[~exact, None])).T))

    def __call__(self, coefficients: np.ndarray, floor_residuals: np.ndarray | None) -> np.ndarray:
        """``|A c - a + B z|^2`` of every row of ``coefficients`` (W, K), with the floor
        points' whitened residuals ``z`` (W, M) or None; shape (W,)."""
        b = coefficients @ self.terms.T - self.value
        if floor_residuals is not None:
            b += floor_residuals @ self.floor.T
        return np.einsum("wk,wk->w", b, b)


class QuadraticChiSquare:
    """chi^2 of predictions linear in K coefficients, from K x K sufficient statistics.

    When the prediction is ``T^T c`` (K geometry terms ``T``, shape (K, N), and a
    coefficient vector ``c`` that depends on the parameters only: a model with a
    :class:`~gonio.models.LinearForm`, times ``scale cos(theta_i)`` for radiance), the
    whitened residual is ``W^T c - w`` with ``W`` the whitened terms and ``w`` the
    whitened data, and

        chi^2(c) = chi^2(c0) + 2 d^T W r0 + d^T (W W^T) d,   d = c - c0,  r0 = W^T c0 - w,

    exactly. Each walker then costs K^2 operations instead of N model evaluations. The
    expansion point ``c0`` (the ensemble's mean coefficients on first use) keeps the
    terms of the sum small, so no precision is lost to cancellation.

    Parameters
    ----------
    whitened_terms : numpy.ndarray, shape (K, N)
        ``L^-1`` applied to every term (``L`` the Cholesky factor of the covariance, or
        diag(sigma)).
    whitened_value : numpy.ndarray, shape (N,)
        ``L^-1`` applied to the data.
    """

    def __init__(self, whitened_terms: np.ndarray, whitened_value: np.ndarray) -> None:
        self.terms = np.asarray(whitened_terms, float)
        self.value = np.asarray(whitened_value, float)
        self.gram = self.terms @ self.terms.T
        self._centre: tuple[np.ndarray, float, np.ndarray] | None = None

    def centre(self, c0: np.ndarray) -> None:
        """Expand about ``c0`` (shape (K,))."""
        residual = self.terms.T @ c0 - self.value
        self._centre = (np.asarray(c0, float), float(residual @ residual), 2.0 * (self.terms @ residual))

    def __call__(self, coefficients: np.ndarray) -> np.ndarray:
        """chi^2 of every row of ``coefficients`` (shape (W, K)); shape (W,)."""
        if self._centre is None:
            self.centre(coefficients.mean(axis=0))
        c0, chi0, twice_gradient = self._centre
        d = coefficients - c0
        # d^T (W W^T) d + 2 d^T W r0 = d . (gram d + 2 W r0), row by row
        out = np.sum((d @ self.gram + twice_gradient) * d, axis=1)
        out += chi0
        return out


class FitProblem:
    """A model, a dataset, fixed parameters: prediction, residuals, log-likelihood.

    Parameters
    ----------
    model : str or Model
        Registered model name or model.
    dataset : Dataset
        The measurements.
    fixed : mapping, optional
        Parameter values held fixed (any subset of the model parameters and nuisances).
    options : mapping, optional
        Discrete model options (see ``Model.options``).
    jitter : bool or {"absolute", "relative"}
        Add a free extra-noise parameter: ``jitter`` (True or "absolute") or ``rel_jitter``
        ("relative"); see the module docstring.
    alignment : str or sequence of str, optional
        Alignment nuisance parameters to fit (``"all"`` or names of
        :data:`gonio.fitting.rig_errors.GEOMETRY_NAMES`: the alignment and the sample's
        mesoscale slope ``texture_slope``, which ``"all"`` leaves out); one given in
        ``fixed`` is part of the problem at its fixed value without being listed here.
    stray_light : bool
        Fit the rig's stray light (``stray_light``, :mod:`gonio.fitting.rig_errors`); a
        value in ``fixed`` includes it at that value.

    Raises
    ------
    ValueError
        Unknown parameter names, fixed values outside their physical range, or nothing
        left to fit.

    Examples
    --------
    >>> from gonio.fitting import Dataset
    >>> data = Dataset(30, 0, [0, 30, 60], 0, [0.25, 0.26, 0.25], 0.01)
    >>> problem = FitProblem("lambert", data)
    >>> problem.free
    ('rho',)
    """

    def __init__(
        self,
        model: str | Model,
        dataset: Dataset,
        fixed: Mapping[str, Any] | None = None,
        options: Mapping[str, Any] | None = None,
        jitter: bool | str = False,
        alignment: str | Sequence[str] | None = None,
        stray_light: bool = False,
    ) -> None:
        #: The registered model the user asked for.
        self.base_model = models.get(model) if isinstance(model, str) else model
        #: What is evaluated: the base model, or its aperture average when the dataset was
        #: measured through finite apertures (``dataset.metadata["aperture_sr"]`` =
        #: [lamp, camera] solid angles [sr], set by gonio.acquisition for rig data; see
        #: gonio.instrument).  Fitting the point model to such data biases the roughness.
        self.model = evaluated_model(self.base_model, dataset)
        self.dataset = dataset
        self.options = dict(options or {})
        #: The extra-noise mode (None, "absolute", "relative") and its parameter's name.
        self.jitter = jitter_mode(jitter)
        self.noise_parameter = NOISE_PARAMETERS.get(self.jitter) if self.jitter else None
        specs = list(self.model.params)
        if dataset.quantity == "radiance":
            specs.append(Param("scale", "arb. units sr", 1.0, (0.0, math.inf), _SCALE_DESCRIPTION, open_lower=True))
        if self.jitter == "absolute":
            upper = 10.0 * (float(np.max(np.abs(dataset.value))) + float(np.max(dataset.sigma)))
            specs.append(Param("jitter", "arb. units" if dataset.unit.startswith("arb") else dataset.unit, 0.0, (0.0, upper), _JITTER_DESCRIPTION))
        elif self.jitter == "relative":
            specs.append(Param("rel_jitter", "-", 0.0, (0.0, 10.0), _REL_JITTER_DESCRIPTION))
        included = set(parse_alignment(alignment)) | {name for name in (fixed or {}) if name in GEOMETRY_NAMES}
        #: The alignment parameters of the problem, free or fixed, and the sample's mesoscale
        #: slope where asked for (gonio.fitting.rig_errors).
        self.alignment: tuple[str, ...] = tuple(name for name in GEOMETRY_NAMES if name in included)
        specs.extend(p for p in ALIGNMENT_PARAMETERS + (TEXTURE_SLOPE,) if p.name in included)
        #: Whether the rig's stray light is a parameter (free or fixed).
        self.stray_light = bool(stray_light) or STRAY_LIGHT.name in (fixed or {})
        if self.stray_light:
            specs.append(STRAY_LIGHT)
        self.specs: tuple[Param, ...] = tuple(specs)
        self._spec = {p.name: p for p in self.specs}
        self.fixed: dict[str, float] = {}
        for name, value in dict(fixed or {}).items():
            if name not in self._spec:
                raise ValueError(
                    f"cannot fix {name!r}: model {self.base_model.name!r} fitted to {dataset.quantity} data "
                    f"has the parameters {list(self._spec)}"
                )
            self.fixed[name] = self._spec[name].check(value, self.base_model.name)
        self.free: tuple[str, ...] = tuple(p.name for p in self.specs if p.name not in self.fixed)
        if not self.free:
            raise ValueError(f"every parameter of {self.base_model.name!r} is fixed; nothing to fit")
        _, self.options = self.model.resolve(self.options)
        self._rig_errors = tuple(self.alignment) + ((STRAY_LIGHT.name,) if self.stray_light else ())
        # a fit with free alignment evaluates the rig thousands of times: the compiled path
        self._rig = (RigPrediction(self.model, dataset.quantity, dataset.geometry, self.options, dataset.metadata,
                                   compiled=any(name in self.free for name in self.alignment))
                     if self._rig_errors else None)
        self._fast = self.model.at(*dataset.geometry, **self.options)
        self._normal_index = None
        if dataset.quantity == "normalised_radiance":
            sources, index = dataset.incidences()
            self._fast_normal = self.model.at(sources[:, 0], sources[:, 1], 0.0, sources[:, 1], **self.options)
            self._normal_index = index
        self._cos_i = np.cos(np.radians(dataset.theta_i))
        #: The errors' distribution: independent, a dense covariance or diagonal plus low
        #: rank (gonio.fitting.covariance).
        self.noise = noise_of(dataset.sigma, dataset.covariance)
        #: Every parameter's fixed or default value (the free ones are overwritten per call).
        self._set_values = {p.name: self.fixed.get(p.name, p.default) for p in self.specs}
        #: log of the Gaussian likelihood's normalisation without extra noise: -(1/2 log det C
        #: + N/2 log 2 pi), C = diag(sigma^2) or the covariance.
        self._log_normalisation = -self.noise.half_log_det - 0.5 * dataset.n * math.log(2.0 * math.pi)
        self._linear = self._quadratic_chi_square()
        self._model_names = set(self.model.param_names)
        # The linear path's model parameters: free ones by column of a vector, the others fixed.
        self._linear_free = tuple((name, self.free.index(name)) for name in self.model.param_names if name in self.free)
        self._linear_fixed = {name: self._set_values[name] for name in self.model.param_names if name not in self.free}
        self._scale_column = (self.free.index("scale") if self.dataset.quantity == "radiance" and "scale" in self.free
                              else None)
        # Free model parameters, checked on each evaluation from a vector; fixed values were
        # checked above and defaults lie inside their bounds.
        self._free_model_specs = tuple(self._spec[n] for n in self.free if n in self._model_names)
        #: Number of model evaluations so far (for benchmarks).
        self.evaluations = 0

    def fixing(self, values: Mapping[str, Any] | None = None, options: Mapping[str, Any] | None = None) -> "FitProblem":
        """The same problem (model, data, extra noise, rig errors) with ``values`` fixed
        too and ``options`` overriding its own: a profile's or a quadrature node's reduced
        problem, the exact model at another accuracy."""
        return FitProblem(self.base_model, self.dataset, {**self.fixed, **dict(values or {})},
                          {**self.options, **dict(options or {})}, self.jitter, self.alignment, self.stray_light)

    def _quadratic_chi_square(self) -> tuple[Any, QuadraticChiSquare, FloorPoints | None,
                                             SharedSources | None] | None:
        """(linear form, :class:`QuadraticChiSquare`, :class:`FloorPoints` or None,
        :class:`SharedSources` or None) when the prediction is linear in the form's
        coefficients for every parameter value (BRDF or radiance data, no free extra noise,
        a model with a LinearForm), else None. Not with rig errors that change the
        prediction.

        Points where the form is not exact (eq 33's floor can act there) are taken point by
        point: the sufficient statistics cover the exact points and :class:`FloorPoints`
        evaluates the model at the others, both with the independent part of the errors;
        a diagonal plus low rank covariance adds :class:`SharedSources`. With a dense
        covariance (whitening mixes every point) such a point turns the linear path off."""
        if self.jitter or self.dataset.quantity not in ("brdf", "radiance") or self.has_rig_errors:
            return None
        form = self._fast.linear_form()
        if form is None:
            return None
        exact = np.ones(self.dataset.n, bool) if form.exact is None else np.asarray(form.exact, bool).reshape(-1)
        if not exact.any() or not np.all(np.isfinite(form.terms[:, exact])):
            return None
        terms = form.terms * self._cos_i if self.dataset.quantity == "radiance" else form.terms
        if exact.all():
            whitened = np.stack([self.whiten(t)[0] for t in terms])
            return form, QuadraticChiSquare(whitened, self.whiten(np.asarray(self.dataset.value, float))[0]), None, None
        if isinstance(self.noise, DenseNoise):
            return None
        value = np.asarray(self.dataset.value, float)
        shared = None
        if isinstance(self.noise, LowRankNoise):
            covariance = self.noise.covariance
            sigma = np.sqrt(covariance.independent)
            shared = SharedSources.of(covariance, terms, value, exact)
        else:
            sigma = self.dataset.sigma
        rest = ~exact
        floor = FloorPoints(self.model.at(*(g[rest] for g in self.dataset.geometry), **self.options), value[rest],
                            sigma[rest], self._cos_i[rest] if self.dataset.quantity == "radiance" else None)
        return form, QuadraticChiSquare(terms[:, exact] / sigma[exact], value[exact] / sigma[exact]), floor, shared

    @property
    def has_rig_errors(self) -> bool:
        """Whether a rig error (alignment, stray light) is free or fixed away from 0: the
        prediction is then that of :class:`~gonio.fitting.rig_errors.RigPrediction`."""
        return any(name in self.free or self.fixed[name] != 0.0 for name in self._rig_errors)

    @property
    def vectorised(self) -> bool:
        """Whether :meth:`log_likelihood_batch` evaluates all walkers in one model call
        at a cost that hardly grows with their number (a linear model's sufficient
        statistics, or a model that broadcasts its parameters, at fixed geometry) rather
        than one combination at a time. Free alignment parameters give every walker its
        own geometry: the cost then grows with the walkers, and this is False."""
        if any(name in self.free for name in self.alignment):
            return False
        return self._linear is not None or self.base_model.broadcasts_params

    def priors_with_defaults(self, priors: Mapping[str, Prior] | None = None) -> dict[str, Prior]:
        """``priors`` plus the default normal prior of every free alignment parameter not
        given there (:func:`gonio.fitting.rig_errors.alignment_prior`)."""
        out: dict[str, Prior] = {name: alignment_prior(name) for name in self.alignment if name in self.free}
        out.update(priors or {})
        return out

    @property
    def n_informative(self) -> int:
        """Measurements that carry information about the parameters.

        Normalised radiance at the normal view (theta_r = 0) that equals 1 exactly is the
        normalisation itself: the model predicts exactly 1 there for every parameter value,
        so such points add nothing to chi-square and are not counted as degrees of freedom.
        """
        if self.dataset.quantity != "normalised_radiance":
            return self.dataset.n
        reference = (self.dataset.theta_r == 0.0) & (self.dataset.value == 1.0)
        return self.dataset.n - int(np.count_nonzero(reference))

    # ------------------------------------------------------------------ parameters
    def spec(self, name: str) -> Param:
        """The :class:`~gonio.models.Param` of a fit parameter."""
        return self._spec[name]

    @property
    def ndim(self) -> int:
        """Number of free parameters."""
        return len(self.free)

    def values(self, vector: Any) -> dict[str, float]:
        """All parameter values: ``vector`` for the free ones plus the fixed ones."""
        out = dict(self.fixed)
        out.update(zip(self.free, (float(x) for x in vector)))
        return {p.name: out.get(p.name, p.default) for p in self.specs}

    def in_bounds(self, vector: Any) -> bool:
        """True when every free value lies inside its physical range."""
        return all(self._spec[n].contains(float(x)) for n, x in zip(self.free, vector))

    # ------------------------------------------------------------------ model
    def predict(self, values: Mapping[str, float]) -> np.ndarray:
        """Predicted measured values at the dataset's geometries (fast path).

        The model parameters in ``values`` are validated (``ValueError`` outside their
        physical range); missing ones take their defaults.
        """
        params, _ = self.model.resolve(
            {k: v for k, v in values.items() if k in self._model_names} | self.options
        )
        return self._predict_checked(values, params)

    def _predict_checked(self, values: Mapping[str, Any], params: dict[str, float]) -> np.ndarray:
        """:meth:`predict` for complete, validated model parameters ``params``."""
        self.evaluations += 1
        if self._rig is not None and not is_identity({name: values[name] for name in self._rig_errors}):
            return self._rig.of_values({**values, **params})
        brdf = self._fast.unchecked(**params)
        normal = None
        if self._normal_index is not None:
            normal = self._fast_normal.unchecked(**params)[..., self._normal_index]
        return combine_prediction(self.dataset.quantity, brdf, normal, self._cos_i, values.get("scale", 1.0))

    def _predict_vector(self, vector: Any) -> tuple[dict[str, float], np.ndarray]:
        """All parameter values for ``vector`` and the prediction (fitting's inner loop).

        Only the free model parameters need a bounds check here (a cheap one: the fit
        keeps them inside their bounds); the values raise the same ``ValueError`` as
        :meth:`predict` when they are outside.
        """
        values = self.values(vector)
        for spec in self._free_model_specs:
            if not spec.contains(values[spec.name]):
                spec.check(values[spec.name], self.base_model.name)  # raises, naming the value
        params = {name: values[name] for name in self.model.param_names}
        return values, self._predict_checked(values, params)

    def extra_variance(self, values: Mapping[str, float], predicted: np.ndarray) -> np.ndarray | float:
        """The extra noise's variance per measurement: ``jitter^2`` or ``(rel_jitter x prediction)^2``."""
        if self.jitter == "relative":
            return (values.get("rel_jitter", 0.0) * np.asarray(predicted, float)) ** 2
        return values.get("jitter", 0.0) ** 2

    def total_sigma(self, values: Mapping[str, float], predicted: np.ndarray | None = None) -> np.ndarray:
        """Measurement uncertainty with the extra noise added in quadrature (the prediction
        is needed for the relative form; it is computed when not given)."""
        if self.jitter == "relative" and predicted is None:
            predicted = self.predict(values)
        extra = self.extra_variance(values, predicted) if self.jitter else 0.0
        if np.all(np.asarray(extra) == 0.0):
            return self.dataset.sigma
        return np.sqrt(self.dataset.sigma**2 + extra)

    def whiten(self, difference: np.ndarray, extra: np.ndarray | float = 0.0) -> tuple[np.ndarray, float]:
        """Whitened residuals of ``difference`` (prediction - value) and log det of their factor.

        ``L^-1 difference`` with ``L`` the Cholesky factor of the covariance (plus the extra
        noise's variance ``extra`` on its diagonal), or ``difference / sigma_tot`` for
        independent errors.
        """
        return self.noise.whiten(difference, extra)

    def residuals(self, vector: Any) -> np.ndarray:
        """Whitened residuals (prediction - value) / sigma, or L^-1 (prediction - value) for
        correlated data (jitter not included)."""
        _, predicted = self._predict_vector(vector)
        difference = predicted - self.dataset.value
        if not self.noise.correlated:
            return difference / self.dataset.sigma
        if not np.all(np.isfinite(difference)):
            return np.full(difference.shape, np.nan)
        return self.whiten(difference)[0]

    def residuals_batch(self, vectors: Any) -> np.ndarray:
        """:meth:`residuals` of every row of ``vectors`` (shape (W, n_free), inside the
        physical bounds) in one model evaluation, shape (W, N): a least-squares Jacobian's
        differences at once (:func:`gonio.fitting.least_squares.fit_least_squares`). Equal
        to the one-by-one values to rounding; a row whose prediction is undefined is NaN.
        """
        values = self.batch_values(vectors)
        difference = self._batch_prediction(values) - self.dataset.value
        self.evaluations += difference.shape[0] - 1
        if not self.noise.correlated:
            return difference / self.dataset.sigma
        finite = np.all(np.isfinite(difference), axis=1)
        out = np.full(difference.shape, np.nan)
        if finite.any():
            out[finite] = self.noise.whiten_rows(difference[finite])
        return out

    def log_likelihood(self, vector: Any) -> float:
        """Gaussian log-likelihood of the data (with the extra noise when it is a parameter).

        ``-inf`` when the prediction is undefined (normalised data of a black sample).
        """
        values, predicted = self._predict_vector(vector)
        difference = predicted - self.dataset.value
        if not np.all(np.isfinite(difference)):
            return -math.inf
        z, log_det = self.whiten(difference, self.extra_variance(values, predicted) if self.jitter else 0.0)
        chi2 = float(np.dot(z, z))
        if not math.isfinite(chi2):
            return -math.inf
        return -0.5 * chi2 - log_det - 0.5 * z.size * math.log(2.0 * math.pi)

    def batch_values(self, vectors: Any) -> dict[str, Any]:
        """All parameter values for many vectors at once (the rows of ``vectors``).

        Free parameters become columns of shape (W, 1), which broadcast against the N
        geometries to (W, N) in the model (``Model.at`` takes parameter arrays); fixed and
        default values stay floats.
        """
        vectors = np.asarray(vectors, float).reshape(-1, self.ndim)
        out: dict[str, Any] = dict(self._set_values)
        out.update({name: vectors[:, [k]] for k, name in enumerate(self.free)})  # copies: models may work in place
        return out

    def log_likelihood_batch(self, vectors: Any) -> np.ndarray:
        """:meth:`log_likelihood` of every row of ``vectors`` (shape (W, n_free)) in one
        model evaluation: the ensemble sampler's walkers at once.

        The rows must lie inside the physical bounds (the caller checks them, as
        :class:`~gonio.fitting.mcmc.LogPosterior` does); the result equals the one-by-one
        values to rounding.

        Returns
        -------
        numpy.ndarray
            Shape (W,); ``-inf`` where a prediction is undefined.
        """
        if self._linear is not None:
            return self._linear_log_likelihood(np.array(vectors, float).reshape(-1, self.ndim))
        values = self.batch_values(vectors)
        predicted = self._batch_prediction(values)
        difference = predicted - self.dataset.value
        walkers = difference.shape[0]
        self.evaluations += walkers - 1
        finite = np.all(np.isfinite(difference), axis=1)
        out = np.full(walkers, -math.inf)
        if not finite.any():
            return out
        normaliser = 0.5 * self.dataset.n * math.log(2.0 * math.pi)
        extra = self.extra_variance(values, predicted) if self.jitter else 0.0
        if not self.noise.correlated and not self.jitter:
            z = difference / self.dataset.sigma
            out[finite] = (-0.5 * np.einsum("wn,wn->w", z, z) + self._log_normalisation)[finite]
        elif not self.jitter:
            z = self.noise.whiten_rows(difference[finite])
            out[finite] = -0.5 * np.einsum("wn,wn->w", z, z) + self._log_normalisation
        else:  # a free extra noise: a covariance per walker, the predictions shared
            extra_rows = np.broadcast_to(extra, difference.shape)[finite]
            chi2, log_det = self.noise.chi_square_rows(difference[finite], extra_rows)
            out[finite] = -0.5 * chi2 - log_det - normaliser
        out[~np.isfinite(out)] = -math.inf
        return out

    def replicated_data(self, vectors: Any, rng: np.random.Generator) -> np.ndarray:
        """Data the fit says the instrument would give at each row of ``vectors`` (free
        parameters, shape (D, n_free)): the prediction plus a draw of the likelihood's noise
        (the stated covariance, or sigma, and the extra noise added independently, which
        gives exactly their summed covariance). Shape (D, N): the posterior predictive
        draws of ``posterior.nc``."""
        return np.concatenate([self._replicated_rows(block, rng) for block in self._row_blocks(vectors)])

    def _replicated_rows(self, vectors: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """:meth:`replicated_data` of one block of rows."""
        values = self.batch_values(vectors)
        predicted = self._batch_prediction(values)
        noise = self.noise.draw(rng, predicted.shape[0])
        if self.jitter:
            extra = np.broadcast_to(self.extra_variance(values, predicted), predicted.shape)
            noise = noise + np.sqrt(extra) * rng.standard_normal(predicted.shape)
        return predicted + noise

    def _batch_prediction(self, values: Mapping[str, Any]) -> np.ndarray:
        """The prediction at every row of :meth:`batch_values` ``values``, shape (W, N)."""
        params = {name: values[name] for name in self.model.param_names}
        return np.asarray(self._predict_checked(values, params), float).reshape(-1, self.dataset.n)

    def chi_square_batch(self, vectors: Any) -> np.ndarray:
        """Chi-square of the data under the fit's likelihood (the extra noise included) at
        every row of ``vectors`` (shape (W, n_free), inside the physical bounds), in one
        model evaluation: the discrepancy of the posterior predictive check
        (:func:`gonio.fitting.adequacy.posterior_predictive_pvalue`).

        Equal to the sum of squares of :meth:`whiten` row by row, to rounding; NaN where a
        prediction is undefined. With a free extra noise every row has its own covariance
        (``self.noise.chi_square_rows``: one Cholesky factor per row for a dense covariance,
        one k x k factor per row for a diagonal plus low rank).

        Returns
        -------
        numpy.ndarray
            Shape (W,).
        """
        return np.concatenate([self._chi_square_rows(block) for block in self._row_blocks(vectors)])

    def _row_blocks(self, vectors: Any) -> list[np.ndarray]:
        """``vectors`` (free parameters, shape (D, n_free)) in blocks of rows whose
        predictions hold at most :data:`BATCH_ELEMENTS` values: the batch methods' memory
        stays bounded for any number of values (one block, as before, up to 4e6 values)."""
        vectors = np.asarray(vectors, float).reshape(-1, self.ndim)
        rows = max(1, BATCH_ELEMENTS // max(self.dataset.n, 1))
        return [vectors[start:start + rows] for start in range(0, max(len(vectors), 1), rows)]

    def _chi_square_rows(self, vectors: np.ndarray) -> np.ndarray:
        """:meth:`chi_square_batch` of one block of rows."""
        values = self.batch_values(vectors)
        predicted = self._batch_prediction(values)
        difference = predicted - self.dataset.value
        if self.jitter:
            extra = np.broadcast_to(np.asarray(self.extra_variance(values, predicted), float), difference.shape)
            chi2 = np.full(len(difference), np.nan)
            finite = np.all(np.isfinite(difference), axis=1)
            if finite.any():
                chi2[finite] = self.noise.chi_square_rows(difference[finite], extra[finite])[0]
            return chi2
        z = self.noise.whiten_rows(difference)
        return np.einsum("wn,wn->w", z, z)

    def _linear_log_likelihood(self, vectors: np.ndarray) -> np.ndarray:
        """:meth:`log_likelihood_batch` through the sufficient statistics of a linear model.

        ``vectors`` (shape (W, n_free), a copy the model's coefficients may work on in
        place) gives each free model parameter as a (W, 1) column, the fixed ones stay
        floats; for radiance the coefficients are multiplied by the scale.
        """
        form, chi_square, floor, shared = self._linear
        params = dict(self._linear_fixed)
        for name, k in self._linear_free:
            params[name] = vectors[:, k:k + 1]
        coefficients = np.empty((vectors.shape[0], chi_square.terms.shape[0]))
        for k, c in enumerate(form.coefficients(**params)):  # (W, 1) columns or floats
            coefficients[:, k:k + 1] = c
        scale = (vectors[:, self._scale_column:self._scale_column + 1] if self._scale_column is not None
                 else self._set_values.get("scale", 1.0))
        if self.dataset.quantity == "radiance":
            coefficients *= scale
        self.evaluations += vectors.shape[0]
        out = chi_square(coefficients)
        floor_residuals = None
        if floor is not None:
            floor_residuals = floor.residuals(params, scale)
            out += np.sum(floor_residuals**2, axis=-1)
        if shared is not None:
            out -= shared(coefficients, floor_residuals)
        out *= -0.5
        out += self._log_normalisation
        if not np.isfinite(out).all():
            out[~np.isfinite(out)] = -math.inf
        return out

    def pointwise_log_likelihood(self, vector: Any) -> np.ndarray:
        """Log predictive density of each measurement given the others, at ``vector``.

        For independent errors, ``log N(value_i | prediction_i, sigma_tot_i)``. For
        correlated ones the leave-one-out conditional of the multivariate normal: with
        ``Q = C^-1`` and ``g = Q r``, ``y_i | y_-i ~ N(y_i - g_i / Q_ii, 1 / Q_ii)``, so
        ``-1/2 log(2 pi / Q_ii) - g_i^2 / (2 Q_ii)`` (Buerkner, Gabry & Vehtari 2021, eq 7-8),
        which is what PSIS-LOO needs for non-factorised models.
        """
        values, predicted = self._predict_vector(vector)
        difference = predicted - self.dataset.value
        extra = self.extra_variance(values, predicted) if self.jitter else 0.0
        return self.noise.loo(difference[None, :], extra)[0]

    def pointwise_log_likelihood_batch(self, vectors: Any) -> np.ndarray:
        """:meth:`pointwise_log_likelihood` of every row of ``vectors``, shape (W, N): one
        model evaluation for all rows, except for correlated errors with a free extra
        noise (one covariance per row)."""
        return np.concatenate([self._pointwise_rows(block) for block in self._row_blocks(vectors)])

    def _pointwise_rows(self, vectors: np.ndarray) -> np.ndarray:
        """:meth:`pointwise_log_likelihood_batch` of one block of rows."""
        values = self.batch_values(vectors)
        predicted = self._batch_prediction(values)
        extra = np.asarray(self.extra_variance(values, predicted)) if self.jitter else 0.0
        return self.noise.loo(predicted - self.dataset.value, extra)

    def chi_square(self, values: Mapping[str, float]) -> float:
        """Sum of squared whitened residuals with the measurement uncertainties only."""
        z = self.whiten(self.predict(values) - self.dataset.value)[0]
        return float(np.dot(z, z))

    def optimal_scale(self, values: Mapping[str, float]) -> float:
        """Generalised linear least-squares ``scale`` for the other values (radiance data)."""
        trial = dict(values, scale=1.0)
        shape = self.whiten(self.predict(trial))[0]
        data = self.whiten(np.asarray(self.dataset.value, float))[0]
        denominator = float(np.dot(shape, shape))
        if denominator <= 0 or not math.isfinite(denominator):
            return 1.0
        return max(float(np.dot(shape, data)) / denominator, 1e-300)
