"""The rig's systematic errors as fit parameters: its alignment and its stray light.

A rig is never perfectly aligned: each axis reads back ``x`` while its true angle is
``x + offset``, and the sample's normal is tipped by a fraction of a degree.  A fit can
estimate these as nuisance parameters (``FitProblem(..., alignment=...)``,
``gonio fit --alignment``); they change the geometry the model is evaluated at:

=================  =====  ===================================================================
name               unit   meaning
=================  =====  ===================================================================
``view_offset``    deg    zero offset of the camera arm (axis 1): true swing = readback + offset
``theta_i_offset`` deg    zero offset of the lamp's polar axis (axis 2)
``phi_i_offset``   deg    zero offset of the lamp's azimuth axis (axis 3)
``tilt_x``         deg    tilt of the sample's normal toward +x (in the camera's swing plane)
``tilt_y``         deg    tilt of the sample's normal toward +y (along the swing axis)
``sample_tilt_x``  deg    the sample's own tilt toward +x beyond the holder's (its wedge, its seat)
``sample_tilt_y``  deg    the sample's own tilt toward +y beyond the holder's
``texture_slope``  deg    rms of each component of the sample's mesoscale slope: the tilt of
                          its surface from place to place within the camera's window
``stray_light``    -      stray radiance over the image, as a fraction of the radiance
                          ``E_0 / pi`` of a white Lambertian sample at normal incidence
=================  =====  ===================================================================

``tilt_x`` and ``tilt_y`` tip the holder's face, and with it everything mounted there, the
reference standard included; ``sample_tilt_x`` and ``sample_tilt_y`` tip the sample alone (a
wedge between its faces, a speck under one edge of its seat), so the reference standard
does not share them. The distinction matters under calibration: a tilt both share changes
the irradiance the reference reported and the one the sample saw alike, and it cancels from
their ratio; a tilt of the sample alone changes the sample's irradiance by
``tan(theta_i) * tilt`` (0.45 % for 0.15 deg at theta_i = 60 deg), which no tilt of the
holder can mimic. The sample sees the holder's tilt plus its own (the two add, as in the
emulator, ``drivers.emulator.rig``).

A real sample's surface is not flat at the scale the camera resolves: its facets tilt by a
fraction of a degree from place to place (docs/emulator.md, "The sample as labs meet it"),
and the camera reads their mean, weighted by each facet's projected area toward it. That
mean is not the reflectance model's value: to second order in the slope it differs by
``s^2 / 2`` times the apparent reflectance's curvature in the tilt, which grows toward
grazing (a bias of -0.022 deg in sigma, 1.1 standard errors, in the designed sweep of
docs/design.md). ``texture_slope`` carries it (:meth:`RigPrediction.textured_radiance`):
the mean over facets whose slope components are independent with rms ``texture_slope``, by
the 5-point rule exact for the second-order expansion, facets tilted by ``+/- sqrt(3) s``
along each axis (weight 1/6 each) and the mean plane (weight 1/3). The reference standard
is taken as flat. It is named among the alignment parameters (``alignment="texture_slope"``,
not part of ``"all"``: it costs five evaluations of the model), with a uniform prior on
[0, 3] deg.

The geometry is :func:`drivers.rig_geometry.misaligned_angles`, the function the emulator
places its lamp and camera with, and ``stray_light`` means what the emulator's switch of
the same name means (``drivers.emulator.systematics``), so a fit and the emulated rig
agree on every parameter.  The dataset's angles must be in the rig's frame (azimuth 0 =
the side of positive camera swings), as the recordings of ``gonio run`` are.

What the rig reports (:class:`RigPrediction`): the camera measures the radiance per unit
on-axis lamp irradiance ``R = f(true geometry) cos(theta_i,true) + stray_light / pi``
(times ``E_0``); the reduction divided each value by the ``E_0`` the reference standard
gave at its *recorded* geometry and, for absolute BRDF, by the recorded
``cos(theta_i)``.  The prediction is therefore ``scale c R`` (relative radiance),
``c R / cos(theta_i,recorded)`` (absolute BRDF) or ``R / R(normal view)`` (normalised
radiance), with ``c = 1 / sum_k w_k r_k``, ``r_k`` the ratio of the reference standard's
true signal (the same misalignment and stray light act on it) to the one the reduction
assumed at its ``k``-th reading, and ``w_k`` the weights that combined the readings into
``E_0`` (``dataset.metadata["reference_standard"]``).  ``scale`` keeps its meaning, the
lamp irradiance as the reference measured it, so its calibration prior stays the
reference's measurement itself.  With a calibration per incidence
(``metadata["calibration"] == "per-incidence"``, gonio.reduction) each value was divided
by the irradiance of the readings at its own lamp polar angle, and its ``c`` sums over
those readings only, with their weights in that angle's irradiance
(:func:`incidence_weights`).

A fit with free alignment parameters evaluates ``oren-nayar`` and ``lambert`` through the
rig's apertures with the compiled loop of :mod:`gonio.fitting.compiled_rig` (the same
values to rounding, tested); other models, and one-off predictions, take the numpy path
(:func:`~drivers.rig_geometry.misaligned_angles`, then the aperture-averaged model).

Default priors: normal, N(0, 0.5 deg) within the +/-5 deg range, for the alignment
(:data:`DEFAULT_PRIOR_SD`).  A rig aligned by eye and an alignment laser is off by a few
tenths of a degree (docs/emulator.md, "Systematic errors": the ``lab`` preset draws 0.1
to 0.3 deg); 0.5 deg leaves room for a worse alignment while keeping a parameter the data
do not constrain (``phi_i_offset`` from in-plane data) from wandering over degrees.
``stray_light`` is uniform on [0, 0.05]: positive (light only adds), and 5 % of a white
sample's radiance would be a rig without baffles (the ``lab`` preset has 0.2 %).
"""
from __future__ import annotations

import json
from typing import Any, Iterable, Mapping

import numpy as np

from drivers.rig_geometry import ALIGNMENT_ERRORS, misaligned_angles
from gonio import models
from gonio.models import Model, Param

from .dataset import Dataset
from .evaluation import COMPILED_MODELS, apertures_of, combine_prediction, evaluated_model
from .priors import Normal, Prior, Uniform

__all__ = ["ALIGNMENT_PARAMETERS", "ALIGNMENT_NAMES", "SAMPLE_TILT_NAMES", "DEFAULT_PRIOR_SD", "ALIGNMENT_BOUND_DEG",
           "TEXTURE_SLOPE", "GEOMETRY_NAMES", "STRAY_LIGHT", "RIG_ERROR_NAMES", "COMPILED_MODELS", "rig_alignment", "sample_alignment",
           "parse_alignment", "alignment_prior",
           "reference_calibration", "incidence_weights", "RigPrediction", "is_identity"]

#: Range of every alignment parameter [deg]: beyond it the rig is not misaligned but mis-built.
ALIGNMENT_BOUND_DEG = 5.0
_DESCRIPTIONS = {
    "view_offset": "zero offset of the camera arm (axis 1): true swing = readback + offset",
    "theta_i_offset": "zero offset of the lamp's polar axis (axis 2): true angle = readback + offset",
    "phi_i_offset": "zero offset of the lamp's azimuth axis (axis 3): true angle = readback + offset",
    "tilt_x": "tilt of the sample's normal toward +x (in the camera's swing plane)",
    "tilt_y": "tilt of the sample's normal toward +y (along the camera's swing axis)",
    "sample_tilt_x": "the sample's own tilt toward +x beyond the holder's (wedge, seat); the reference does not share it",
    "sample_tilt_y": "the sample's own tilt toward +y beyond the holder's (wedge, seat); the reference does not share it",
}
#: The tilts of the sample alone, beyond the holder's (module docstring).
SAMPLE_TILT_NAMES = ("sample_tilt_x", "sample_tilt_y")
#: The alignment parameters: :func:`drivers.rig_geometry.misaligned_angles`' in its order,
#: then the sample's own tilt.
ALIGNMENT_PARAMETERS = tuple(
    Param(name, "deg", 0.0, (-ALIGNMENT_BOUND_DEG, ALIGNMENT_BOUND_DEG), _DESCRIPTIONS[name])
    for name in ALIGNMENT_ERRORS + SAMPLE_TILT_NAMES)
ALIGNMENT_NAMES = tuple(p.name for p in ALIGNMENT_PARAMETERS)
#: Standard deviation of each parameter's default normal prior [deg] (module docstring).
DEFAULT_PRIOR_SD = {name: 0.5 for name in ALIGNMENT_NAMES}
#: The stray-light parameter (module docstring); its default prior is uniform over its range.
STRAY_LIGHT = Param("stray_light", "-", 0.0, (0.0, 0.05),
                    "stray radiance over the image as a fraction of E_0 / pi (a white Lambertian at normal incidence)")
#: The sample's mesoscale slope (module docstring): rms of each component [deg].
TEXTURE_SLOPE = Param("texture_slope", "deg", 0.0, (0.0, 3.0),
                      "rms of each component of the sample's mesoscale slope within the camera's window")
#: The names ``alignment=`` accepts: the alignment and the sample's mesoscale slope.
GEOMETRY_NAMES = ALIGNMENT_NAMES + (TEXTURE_SLOPE.name,)
#: Every rig-error parameter (with the sample's mesoscale slope, which acts like one).
RIG_ERROR_NAMES = GEOMETRY_NAMES + (STRAY_LIGHT.name,)
#: The facets of :meth:`RigPrediction.textured_radiance`: (weight, tilt toward +x, tilt toward
#: +y in units of sqrt(3) texture_slope). Its mean over slopes of variance s^2 per component
#: is exact for any second-order expansion of the apparent reflectance in the slope (the
#: 3-point Gauss-Hermite rule along each axis, whose centres coincide).
TEXTURE_FACETS = ((1.0 / 3.0, 0.0, 0.0), (1.0 / 6.0, 1.0, 0.0), (1.0 / 6.0, -1.0, 0.0),
                  (1.0 / 6.0, 0.0, 1.0), (1.0 / 6.0, 0.0, -1.0))


def parse_alignment(names: str | Iterable[str] | None) -> tuple[str, ...]:
    """Alignment parameter names from ``"all"``, a comma-separated string or a sequence.

    Returns them in the canonical order of :data:`GEOMETRY_NAMES`, without repeats;
    ``"all"`` is the alignment (:data:`ALIGNMENT_NAMES`), not ``texture_slope``.

    Raises
    ------
    ValueError
        An unknown name (the message lists the valid ones).

    Examples
    --------
    >>> parse_alignment("tilt_y, view_offset")
    ('view_offset', 'tilt_y')
    >>> parse_alignment("all") == ALIGNMENT_NAMES
    True
    >>> parse_alignment("all, texture_slope")[-1]
    'texture_slope'
    """
    if names is None:
        return ()
    items = [n.strip() for n in names.split(",")] if isinstance(names, str) else [str(n).strip() for n in names]
    items = [n for n in items if n]
    unknown = [n for n in items if n not in GEOMETRY_NAMES + ("all",)]
    if unknown:
        raise ValueError(f"unknown alignment parameter {unknown[0]!r}; expected 'all' or names from "
                         f"{list(GEOMETRY_NAMES)}")
    chosen = set(items) | (set(ALIGNMENT_NAMES) if "all" in items else set())
    return tuple(n for n in GEOMETRY_NAMES if n in chosen)


def rig_alignment(alignment: Mapping[str, Any]) -> dict[str, Any]:
    """The alignment the reference standard sees: the rig's, without the sample's own tilt.

    >>> rig_alignment({"tilt_x": 0.1, "sample_tilt_x": 0.2})
    {'tilt_x': 0.1}
    """
    return {name: value for name, value in alignment.items() if name not in SAMPLE_TILT_NAMES}


def sample_alignment(alignment: Mapping[str, Any]) -> dict[str, Any]:
    """The alignment the sample sees, as :func:`~drivers.rig_geometry.misaligned_angles`
    keywords: the holder's tilt plus the sample's own.

    >>> sample_alignment({"tilt_x": 0.1, "sample_tilt_x": 0.2, "sample_tilt_y": 0.0})
    {'tilt_x': 0.30000000000000004, 'tilt_y': 0.0}
    """
    out = rig_alignment(alignment)
    for axis in ("x", "y"):
        own = alignment.get(f"sample_tilt_{axis}")
        if own is not None:
            out[f"tilt_{axis}"] = out.get(f"tilt_{axis}", 0.0) + own
    return out


def alignment_prior(name: str) -> Prior:
    """The default prior of an alignment parameter: N(0, 0.5 deg) within +/-5 deg;
    ``texture_slope``'s uniform over its range, [0, 3] deg."""
    if name == TEXTURE_SLOPE.name:
        return Uniform(*TEXTURE_SLOPE.bounds)
    return Normal(0.0, DEFAULT_PRIOR_SD[name], -ALIGNMENT_BOUND_DEG, ALIGNMENT_BOUND_DEG)


def reference_calibration(metadata: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The reference standard's recorded geometries (K, 4) [deg], combination weights (K,)
    and reflectances (K,) from ``metadata["reference_standard"]`` (written by
    :mod:`gonio.reduction`), or None.

    Raises
    ------
    ValueError
        A record that is not ``{"geometry": [[theta_i, phi_i, theta_r, phi_r], ...],
        "weights": [...], "reflectance": [...]}`` with one non-negative weight and one
        reflectance in (0, 1] per geometry.
    """
    record = metadata.get("reference_standard") if metadata else None
    if record is None:
        return None
    if isinstance(record, str):  # read back from a CSV header line
        try:
            record = json.loads(record)
        except json.JSONDecodeError:
            record = None
    try:
        geometry = np.asarray(record["geometry"], float).reshape(-1, 4)
        weights = np.asarray(record["weights"], float).reshape(-1)
        reflectance = np.asarray(record["reflectance"], float).reshape(-1)
    except (TypeError, KeyError, ValueError):
        raise ValueError(f"dataset metadata reference_standard = {metadata.get('reference_standard')!r:.200}: "
                         "expected {'geometry': [[theta_i, phi_i, theta_r, phi_r], ...], 'weights': [...], "
                         "'reflectance': [...]}") from None
    k = geometry.shape[0]
    if (weights.size != k or reflectance.size != k or k == 0 or np.any(weights < 0)
            or not np.all(np.isfinite(geometry)) or not np.all((reflectance > 0) & (reflectance <= 1))):
        raise ValueError(f"dataset metadata reference_standard: {k} geometries, {weights.size} weights and "
                         f"{reflectance.size} reflectances; expected one finite geometry, one non-negative weight and "
                         "one reflectance in (0, 1] per reference reading")
    return geometry, weights / weights.sum(), reflectance


def incidence_weights(metadata: Mapping[str, Any]) -> np.ndarray:
    """Each value's weights of the reference readings under a calibration per incidence.

    ``metadata["reference_standard"]`` holds, per reading, its planned lamp polar angle
    (``incidence``) and its weight in that angle's irradiance (``incidence_weights``);
    ``metadata["incidence_theta_i"]`` holds, per value, the planned angle of the readings
    that calibrated it (both written by :mod:`gonio.reduction`): a value takes the readings
    planned at its angle, as the reduction divided it by them.

    Returns
    -------
    numpy.ndarray
        Shape (N, K), each row summing to 1.

    Raises
    ------
    ValueError
        A record without the per-reading angles and weights or the per-value angles, or a
        value whose angle no reading shares (naming it).

    Examples
    --------
    >>> record = {"geometry": [[30, 0, 10, 180], [60, 0, 10, 180], [60, 0, 10, 180]], "weights": [1, 1, 1],
    ...           "reflectance": [0.99] * 3, "incidence": [30, 60, 60], "incidence_weights": [1, 0.4, 0.6]}
    >>> incidence_weights({"reference_standard": record, "incidence_theta_i": [60.0, 30.0]}).tolist()
    [[0.0, 0.4, 0.6], [1.0, 0.0, 0.0]]
    """
    record = metadata.get("reference_standard")
    if isinstance(record, str):
        record = json.loads(record)
    try:
        angle = np.round(np.asarray(record["incidence"], float).reshape(-1), 6)
        within = np.asarray(record["incidence_weights"], float).reshape(-1)
        theta = np.round(np.asarray(metadata["incidence_theta_i"], float).reshape(-1), 6)
    except (TypeError, KeyError, ValueError):
        raise ValueError("dataset metadata: a calibration per incidence needs reference_standard's 'incidence' "
                         "(planned theta_i of each reading [deg]) and 'incidence_weights', and each value's "
                         "'incidence_theta_i' (written by gonio.reduction)") from None
    matched = theta[:, None] == angle[None, :]
    unmatched = ~matched.any(axis=1)
    if unmatched.any():
        raise ValueError(f"calibration per incidence: no reference reading at theta_i = {theta[unmatched][0]:g} deg "
                         f"(the readings are at {sorted(set(angle.tolist()))} deg)")
    return np.where(matched, within[None, :], 0.0)


#: Largest distance [deg] of a prediction's lamp polar angle from the calibrated incidence it
#: is matched to (a readback differs from its planned angle by the stage's tolerance).
INCIDENCE_MATCH_DEG = 1.0


def incidences_at(metadata: Mapping[str, Any], theta_i: np.ndarray) -> Mapping[str, Any]:
    """The dataset metadata for predictions at lamp polar angles ``theta_i`` [deg] other
    than the dataset's own (a report's curves): each is calibrated by the incidence the
    reference standard was read at nearest to it, within :data:`INCIDENCE_MATCH_DEG`;
    metadata whose ``incidence_theta_i`` already has one angle per value is returned as is.

    Raises
    ------
    ValueError
        A lamp angle farther than :data:`INCIDENCE_MATCH_DEG` from every calibrated incidence.
    """
    theta_i = np.asarray(theta_i, float).reshape(-1)
    given = metadata.get("incidence_theta_i")
    if given is not None and np.size(given) == theta_i.size:
        return metadata
    record = metadata.get("reference_standard") or {}
    angles = np.unique(np.round(np.asarray(record.get("incidence", []), float), 6))
    if angles.size == 0:
        return metadata
    nearest = angles[np.argmin(np.abs(theta_i[:, None] - angles[None, :]), axis=1)]
    far = np.abs(nearest - theta_i) > INCIDENCE_MATCH_DEG
    if far.any():
        raise ValueError(f"calibration per incidence: no reference reading within {INCIDENCE_MATCH_DEG:g} deg of "
                         f"theta_i = {theta_i[far][0]:g} deg (the readings are at {angles.tolist()} deg)")
    return {**metadata, "incidence_theta_i": nearest.tolist()}


class RigPrediction:
    """The measured quantity of a misaligned rig with stray light at recorded geometries
    (module docstring).

    Parameters
    ----------
    model : Model
        The model as the fit evaluates it (with the rig's apertures when the data have
        them, :func:`gonio.fitting.problem.evaluated_model`).
    quantity : {'brdf', 'normalised_radiance', 'radiance'}
        What the values are.
    geometry : tuple of array_like
        The recorded (read-back) geometries (theta_i, phi_i, theta_r, phi_r) [deg], 1-D.
    options : mapping
        Model options.
    metadata : mapping
        The dataset's metadata (``reference_standard``, ``aperture_sr``).
    compiled : bool
        Evaluate misaligned geometries with the compiled kernel
        (:mod:`gonio.fitting.compiled_rig`) when the model is one it knows (``oren-nayar``,
        ``lambert``, ``oren-nayar-qualitative``, ``oren-nayar-tabulated``, with their default
        options) seen through the rig's apertures: the same values to rounding, about
        15 times faster, after loading numba (worth it for a fit, which evaluates the rig
        thousands of times; not for one prediction).
    """

    def __init__(self, model: Model, quantity: str, geometry, options: Mapping[str, Any],
                 metadata: Mapping[str, Any], compiled: bool = False) -> None:

        self.model = model
        self.quantity = quantity
        self.options = dict(options)
        self._combine = combine_prediction
        self._kernel = _kernel_model(model, self.options, apertures_of(metadata)) if compiled else None
        self._compiled: dict[str, Any] = {}  # compiled rig radiance per geometry, built on first use
        self.geometry = tuple(np.asarray(g, float).reshape(-1) for g in np.broadcast_arrays(*geometry))
        self.cos_recorded = np.cos(np.radians(self.geometry[0]))
        ti, pi_ = self.geometry[0], self.geometry[1]
        self.normal_geometry = (ti, pi_, np.zeros_like(ti), pi_)  # the normal view of each incidence
        self._fixed: dict[str, Any] = {}  # the model at the recorded geometry, built on first use
        self.reference = None
        if quantity in ("brdf", "radiance"):
            calibration = reference_calibration(metadata)
            if calibration is not None:
                geometry_k, weights, reflectance = calibration
                probe = Dataset(*geometry_k.T, np.ones(len(weights)), 1.0, metadata=dict(metadata))
                lambert = evaluated_model("lambert", probe)  # the reduction's model of the standard
                recorded = reflectance * self._signal(lambert, tuple(geometry_k.T))
                self.reference = (lambert, tuple(geometry_k.T), weights, reflectance, recorded)
        #: With a calibration per incidence (``metadata["calibration"]``), each value's
        #: weights of the reference readings, (N, K): those of its lamp polar angle.
        self.value_weights = None
        if self.reference is not None and metadata.get("calibration") == "per-incidence":
            metadata = incidences_at(metadata, self.geometry[0])
            self.value_weights = incidence_weights(metadata)
            if self.value_weights.shape[0] != self.geometry[0].size:
                raise ValueError(f"dataset metadata incidence_theta_i: {self.value_weights.shape[0]} angles for "
                                 f"{self.geometry[0].size} values; expected one per value")

    @staticmethod
    def _signal(lambert: Model, geometry) -> np.ndarray:
        """A white Lambertian standard's signal per unit irradiance, <f cos theta_i> [1/sr]."""
        return lambert(*geometry, rho=1.0) * np.cos(np.radians(geometry[0]))

    def calibration_factor(self, alignment: Mapping[str, Any], stray_light: Any = 0.0) -> np.ndarray | float:
        """``c = 1 / sum_k w_k r_k``: what misalignment and stray light did to ``E_0`` (1
        without a reference standard); shape (W, 1) for parameter columns of shape (W, 1).
        With a calibration per incidence, each value's ``c`` from the readings at its lamp
        polar angle (:attr:`value_weights`): shape (N,) or (W, N)."""
        if self.reference is None:
            return 1.0
        lambert, geometry, weights, reflectance, recorded = self.reference
        alignment = rig_alignment(alignment)
        if is_identity(alignment):
            signal = self._signal(lambert, geometry)
        elif self._kernel is not None:
            signal = self._compiled_radiance("reference", alignment, {"rho": 1.0})
        else:
            signal = self._signal(lambert, misaligned_angles(*geometry, **alignment))
        true = reflectance * signal + np.asarray(stray_light) / np.pi
        if self.value_weights is not None:
            return 1.0 / ((true / recorded) @ self.value_weights.T)
        return 1.0 / np.sum(weights * true / recorded, axis=-1, keepdims=True)

    @property
    def compiled(self) -> bool:
        """Whether misaligned geometries go through the compiled kernel (:mod:`gonio.fitting.compiled_rig`)."""
        return self._kernel is not None

    def _compiled_radiance(self, which: str, alignment: Mapping[str, Any], params: Mapping[str, Any]) -> np.ndarray:
        """The compiled ``<f cos theta_i>`` at the true geometry of the recorded ``which``
        ('data', 'normal' view or 'reference' standard) geometries [1/sr]."""
        from .compiled_rig import CompiledRigRadiance

        rig = self._compiled.get(which)
        if rig is None:
            base, apertures = self._kernel
            if which == "reference":
                base, recorded = models.get("lambert"), self.reference[1]
            else:
                recorded = self.geometry if which == "data" else self.normal_geometry
            rig = self._compiled[which] = CompiledRigRadiance(base, recorded, apertures)
        return rig(params, alignment)

    def _model_at(self, which: str, params: Mapping[str, Any], alignment: Mapping[str, Any]) -> np.ndarray:
        """``f cos(theta_i)`` at the true geometry of the recorded ``which`` ('data' or
        'normal' view) geometries [1/sr]; the fixed-geometry path when nothing moves."""
        recorded = self.geometry if which == "data" else self.normal_geometry
        alignment = sample_alignment(alignment)
        if is_identity(alignment):
            if which not in self._fixed:
                self._fixed[which] = self.model.at(*recorded, **self.options)
            return self._fixed[which].unchecked(**params) * self.cos_recorded
        if self._kernel is not None:
            return self._compiled_radiance(which, alignment, params)
        true = misaligned_angles(*recorded, **alignment)
        return self.model(*true, **params, **self.options) * np.clip(np.cos(np.radians(true[0])), 0.0, None)

    def textured_radiance(self, which: str, params: Mapping[str, Any], alignment: Mapping[str, Any],
                          texture_slope: Any = 0.0) -> np.ndarray:
        """``f cos(theta_i)`` of the recorded ``which`` ('data' or 'normal' view) geometries
        [1/sr], averaged over the sample's facets (module docstring): the facets of
        :data:`TEXTURE_FACETS`, each tilted beyond the sample's mean plane and weighted by
        its projected area toward the camera relative to the mean plane's,
        ``cos(theta_r,facet) / (cos(theta_r) cos(t_x) cos(t_y))`` (0 for a facet the camera
        cannot see). ``texture_slope`` [deg] as a float or a column (W, 1); 0 gives
        :meth:`_model_at` itself.

        Decision: the facets' projected areas are taken on the camera's axis, as in the
        emulator (``drivers.emulator.texture.slope_response``): the apertures change them by a
        fraction of order half-angle^2, 1e-3 of an effect itself of order 1e-3."""
        if np.ndim(texture_slope) == 0 and float(texture_slope) == 0.0:
            return self._model_at(which, params, alignment)
        recorded = self.geometry if which == "data" else self.normal_geometry
        step = np.sqrt(3.0) * np.asarray(texture_slope, float)
        mean_view = np.cos(np.radians(misaligned_angles(*recorded, **sample_alignment(alignment))[2]))
        total = 0.0
        for weight, along_x, along_y in TEXTURE_FACETS:
            facet = dict(alignment)
            for axis, along in (("x", along_x), ("y", along_y)):
                facet[f"sample_tilt_{axis}"] = alignment.get(f"sample_tilt_{axis}", 0.0) + along * step
            view = np.cos(np.radians(misaligned_angles(*recorded, **sample_alignment(facet))[2]))
            area = np.clip(view, 0.0, None) / (np.maximum(mean_view, 1e-12)
                                               * np.cos(np.radians(along_x * step)) * np.cos(np.radians(along_y * step)))
            total = total + weight * area * self._model_at(which, params, facet)
        return total

    def __call__(self, params: Mapping[str, Any], alignment: Mapping[str, Any], scale: Any = 1.0,
                 stray_light: Any = 0.0, texture_slope: Any = 0.0) -> np.ndarray:
        """The predicted measured values: shape (N,) or (W, N) for parameter columns (W, 1).

        ``params`` are the model's (checked), ``alignment`` the alignment values
        (:data:`ALIGNMENT_NAMES`, or some of them) [deg], ``scale``, ``stray_light`` and
        ``texture_slope`` [deg] as in the module docstring.
        """
        stray = np.asarray(stray_light, float) / np.pi
        radiance = self.textured_radiance("data", params, alignment, texture_slope) + stray
        if self.quantity == "normalised_radiance":
            normal = self.textured_radiance("normal", params, alignment, texture_slope) + stray
            return self._combine(self.quantity, radiance, normal, self.cos_recorded, scale)
        apparent = np.divide(radiance, self.cos_recorded, out=np.zeros(np.shape(radiance)),
                             where=self.cos_recorded > 0) * self.calibration_factor(alignment, stray_light)
        return self._combine(self.quantity, apparent, None, self.cos_recorded, scale)

    def of_values(self, values: Mapping[str, Any]) -> np.ndarray:
        """:meth:`__call__` for a mapping of every value of a fit (model parameters, rig
        errors, ``scale``; others such as ``jitter`` ignored); model parameters must be
        valid (they are not checked here), missing ones take their defaults."""
        params = {p.name: values.get(p.name, p.default) for p in self.model.params}
        alignment = {name: values[name] for name in ALIGNMENT_NAMES if name in values}
        return self(params, alignment, values.get("scale", 1.0), values.get(STRAY_LIGHT.name, 0.0),
                    values.get(TEXTURE_SLOPE.name, 0.0))


def _kernel_model(model: Model, options: Mapping[str, Any], apertures) -> tuple[Model, tuple[float, float]] | None:
    """(base model, apertures) when ``model`` is a model of the compiled kernel averaged over
    the dataset's apertures (``NAME@aperture``, :func:`gonio.fitting.problem.evaluated_model`)
    with its default options (the kernel knows no others, e.g. the qualitative model's
    ``variant`` "eq36"); else None."""
    name, _, through = model.name.partition("@")
    if through != "aperture" or name not in COMPILED_MODELS or not apertures:
        return None
    base = models.get(name)
    if options and dict(options) != base.resolve({})[1]:
        return None
    return base, (float(apertures[0]), float(apertures[1]))


def is_identity(alignment: Mapping[str, Any]) -> bool:
    """Whether every alignment value is the scalar 0 (the recorded geometry is the true one)."""
    return all(np.ndim(v) == 0 and float(v) == 0.0 for v in alignment.values())

