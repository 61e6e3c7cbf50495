"""The instrument response of a gonioreflectometer: finite source and detector apertures.

A real rig does not measure the BRDF along single rays: the lamp subtends a solid angle
d omega_i at the sample and the camera's pupil a solid angle d omega_r (Oren & Nayar 1995,
section 5: about 0.003 sr and 0.0009 sr), so the measured radiance is

    L_r = E_0 < f_r(w_i, w_r) cos(theta(w_i)) >   over w_i in the lamp cone, w_r in the camera cone.

Near sharp features (the cut-off of the Oren-Nayar model at theta_r = theta_i, specular
lobes) this average differs measurably from f_r cos(theta_i) at the cone axes, and a fit of
the point model to such data is biased.  :func:`aperture_averaged` wraps any model into
the *effective* BRDF f_eff = <f_r cos theta_i'> / cos(theta_i), so that fits of rig data
predict exactly what the rig measures (prediction = E_0 f_eff cos theta_i).

The average over each cone uses the Lambert azimuthal equal-area map of the cone to a disk
(uniform on the disk is uniform in solid angle) and one of two disk cubatures
(:func:`aperture_rule`):

- the *full* rule, 7 points (A. H. Stroud, *Approximate Calculation of Multiple Integrals*,
  1971, formula S2:3-1: the centre with weight 1/4 and six points at radius sqrt(2/3) with
  weight 1/8; its moments are those of the disk up to degree 5), 7 x 7 = 49 BRDF
  evaluations per geometry: near the horizon and near the retro-reflection direction;
- the *compact* rule, 4 points at radius sqrt(1/2) along the cone frame's two axes
  (increasing polar angle and increasing azimuth, both signs), weight 1/4 each: exact for
  polynomials of degree 3, and for the quartic along either axis, 4 x 4 = 16 evaluations,
  wherever both cone axes are at most :data:`COMPACT_MAX_THETA_DEG` from the normal and
  lamp and camera at least :data:`COMPACT_MIN_SEPARATION_DEG` apart, for the models of
  :data:`COMPACT_RULE_MODELS`.

Validation of the compact rule (``oren-nayar-tabulated``, rho = 0.9, sigma = 10, 30, 60 and
90 deg, 3,000 random geometries, apertures 0.003 and 0.0009 sr): where it applies it agrees
with the full rule to 2.7e-5 relative (largest difference), and the full rule agrees with
a fine product rule (12 Gauss-Legendre radii x 24 angles per cone) to 5e-7 at the demo's
geometries; the rig's noise per value is 0.15-0.6 % (the demo's: 0.25 %), so the rule
changes a prediction by at most 1/55 of the smallest noise.  Outside its domain the
compact rule is not used: near the horizon the cones cross it (1-2 % differences at
88 deg), and near the retro-reflection cusp of the Oren-Nayar models they reach 1.7e-4
within 3 deg of it; ``oren-nayar`` (eq 33-35, its kink at theta_r = theta_i) and
``oren-nayar-qualitative`` (its kink at |phi_r - phi_i| = 90 deg) differ by up to 2.9e-4 and
keep the full rule.  Details and the other rules measured: docs/fitting.md,
"The aperture average".
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .models import FixedGeometryModel, LinearForm, Model, get

__all__ = [
    "LAMP_SOLID_ANGLE_SR",
    "CAMERA_SOLID_ANGLE_SR",
    "RULES",
    "COMPACT_MAX_THETA_DEG",
    "COMPACT_MIN_SEPARATION_DEG",
    "COMPACT_RULE_MODELS",
    "cone_half_angle",
    "cone_offsets",
    "cone_quadrature",
    "aperture_rule",
    "aperture_averaged",
]

#: Solid angle of the lamp seen from the sample (Oren & Nayar 1995, section 5) [sr].
LAMP_SOLID_ANGLE_SR = 0.003
#: Solid angle of the camera's pupil seen from the sample (same source) [sr].
CAMERA_SOLID_ANGLE_SR = 0.0009

#: The disk cubatures of the cone average (module notes): name -> (radii on the unit
#: equal-area disk, angles around the cone's axis [rad], weights summing to 1).
RULES = {
    "full": (np.array([0.0] + [math.sqrt(2.0 / 3.0)] * 6), np.array([0.0] + [k * math.pi / 3.0 for k in range(6)]),
             np.array([0.25] + [0.125] * 6)),
    "compact": (np.full(4, math.sqrt(0.5)), np.array([k * math.pi / 2.0 for k in range(4)]), np.full(4, 0.25)),
}
#: Largest polar angle [deg] of either cone axis where the compact rule is used.
COMPACT_MAX_THETA_DEG = 85.0
#: Smallest angle [deg] between lamp and camera axes where the compact rule is used (the
#: Oren-Nayar models' retro-reflection cusp, where lamp and camera coincide, is sharper
#: than the cones).
COMPACT_MIN_SEPARATION_DEG = 3.0
#: Models whose compact rule was validated against the full one (module notes): smooth
#: diffuse models; a specular lobe, for one, is not.
COMPACT_RULE_MODELS = ("lambert", "oren-nayar-tabulated", "oren-nayar-exact")


def cone_half_angle(solid_angle_sr: float) -> float:
    """Half-angle [deg] of a circular cone of the given solid angle: Omega = 2 pi (1 - cos a)."""
    if not 0.0 < solid_angle_sr < 2.0 * math.pi:
        raise ValueError(f"solid angle must be in (0, 2 pi) sr, got {solid_angle_sr!r}")
    return math.degrees(math.acos(1.0 - solid_angle_sr / (2.0 * math.pi)))


def cone_offsets(solid_angle_sr: float, rule: str = "full") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cubature points of a cone about its axis (:data:`RULES` on the equal-area disk):
    each point's angle from the axis [rad], its angle around the axis [rad] and its weight,
    shapes (7,) for the full rule and (4,) for the compact one, the weights summing to 1
    (:func:`cone_quadrature` places them about axes).

    Examples
    --------
    >>> beta, around, weights = cone_offsets(0.003)
    >>> float(beta[0]), round(float(np.degrees(beta[1])), 4), float(weights.sum())
    (0.0, 1.4457, 1.0)
    >>> beta, around, weights = cone_offsets(0.003, "compact")
    >>> round(float(np.degrees(beta[0])), 4), weights.tolist()
    (1.252, [0.25, 0.25, 0.25, 0.25])
    """
    radii, angles, weights = _rule_points(rule)
    half = math.radians(cone_half_angle(solid_angle_sr))
    r = radii * 2.0 * math.sin(half / 2.0)  # equal-area disk radius of the rim
    return 2.0 * np.arcsin(r / 2.0), angles.copy(), weights.copy()


def _rule_points(rule: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:data:`RULES`' entry ``rule``; ValueError naming the rules for another name."""
    if rule not in RULES:
        raise ValueError(f"aperture rule {rule!r}: expected one of {list(RULES)}")
    return RULES[rule]


def cone_quadrature(theta: ArrayLike, phi: ArrayLike, solid_angle_sr: float,
                    rule: str = "full") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadrature directions and weights averaging over cones about many axes.

    Parameters
    ----------
    theta, phi : array_like
        Cone axes [deg], flattened to shape (n,) (same number of elements).
    solid_angle_sr : float
        Solid angle of every cone [sr].
    rule : {'full', 'compact'}
        The disk cubature (:data:`RULES`, module notes).

    Returns
    -------
    theta_k, phi_k : numpy.ndarray
        Directions [deg], shape (n, k) (k = 7 or 4); they may lie below the horizon near
        grazing axes.
    weights : numpy.ndarray
        Weights, shape (k,), summing to 1.
    """
    t = np.radians(np.ravel(np.asarray(theta, float)))[:, None]
    p = np.radians(np.ravel(np.asarray(phi, float)))[:, None]
    beta, around, weights = cone_offsets(solid_angle_sr, rule)
    cb, sb = np.cos(beta), np.sin(beta)
    ca, sa = cb * 0 + np.cos(around), np.sin(around)
    axis = (np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t))
    e1 = (np.cos(t) * np.cos(p), np.cos(t) * np.sin(p), -np.sin(t))
    e2 = (-np.sin(p), np.cos(p), 0.0 * t)
    x, y, z = (cb * a + sb * ca * b + sb * sa * c for a, b, c in zip(axis, e1, e2))
    return np.degrees(np.arctan2(np.hypot(x, y), z)), np.degrees(np.arctan2(y, x)), weights


def aperture_rule(theta_i: ArrayLike, phi_i: ArrayLike, theta_r: ArrayLike, phi_r: ArrayLike) -> np.ndarray:
    """Where the compact cubature averages a geometry's cones (module notes).

    Parameters
    ----------
    theta_i, phi_i, theta_r, phi_r : array_like
        Lamp and camera axes [deg], broadcasting.

    Returns
    -------
    numpy.ndarray of bool
        True where both axes are at most :data:`COMPACT_MAX_THETA_DEG` from the normal and at
        least :data:`COMPACT_MIN_SEPARATION_DEG` apart (the compact rule), False elsewhere
        (the full rule), flattened to the broadcast shape's size.

    Examples
    --------
    >>> aperture_rule([30, 30, 88], 0, [10, 31, 10], [180, 0, 180]).tolist()
    [True, False, False]
    """
    ti, pi_, tr, pr = (np.radians(np.ravel(a)) for a in np.broadcast_arrays(*(np.asarray(g, float) for g in
                                                                               (theta_i, phi_i, theta_r, phi_r))))
    cos_separation = np.sin(ti) * np.sin(tr) * np.cos(pi_ - pr) + np.cos(ti) * np.cos(tr)
    limit = math.radians(COMPACT_MAX_THETA_DEG)
    return (ti <= limit) & (tr <= limit) & (cos_separation <= math.cos(math.radians(COMPACT_MIN_SEPARATION_DEG)))


def aperture_averaged(
    model: str | Model,
    lamp_solid_angle_sr: float = LAMP_SOLID_ANGLE_SR,
    camera_solid_angle_sr: float = CAMERA_SOLID_ANGLE_SR,
    rule: str = "auto",
) -> Model:
    """The effective BRDF a rig with finite apertures measures, as a :class:`Model`.

    Parameters
    ----------
    model : str or Model
        The sample's reflectance model.
    lamp_solid_angle_sr, camera_solid_angle_sr : float
        Apertures of source and detector seen from the sample [sr].
    rule : {'auto', 'full', 'compact'}
        The cone cubature (module notes): ``'auto'`` (default) the compact rule at the
        geometries :func:`aperture_rule` selects for a model of
        :data:`COMPACT_RULE_MODELS` and the full rule elsewhere; ``'full'`` or
        ``'compact'`` one rule everywhere (for studies of the rules).

    Returns
    -------
    Model
        Same parameters as ``model``; evaluates f_eff = <f cos theta_i'> / cos theta_i
        [1/sr] (the average over both cones, see the module notes).  At theta_i = 90 deg
        (no irradiance) it returns the plain aperture average of f.  Not registered.

    Examples
    --------
    >>> m = aperture_averaged("lambert")   # pi f_eff = rho <cos theta_i'> / cos theta_i
    >>> round(float(m(30, 0, 10, 180, rho=0.5)) * 3.141592653589793, 4)
    0.4999
    """
    base = get(model) if isinstance(model, str) else model
    if rule not in ("auto", *RULES):
        raise ValueError(f"aperture rule {rule!r}: expected 'auto' or one of {list(RULES)}")

    def prepare(ti, pi_, tr, pr, **options: Any):
        shape = np.shape(ti)
        groups = _rule_groups(base, rule, (ti, pi_, tr, pr))
        rays = [(index, _SubRays.of(base, *(np.ravel(g)[index] for g in (ti, pi_, tr, pr)), lamp_solid_angle_sr,
                                    camera_solid_angle_sr, options, name)) for name, index in groups]
        build_forms = [getattr(r.fixed.prepared, "linear_form", None) for _, r in rays]
        if any(build is None for build in build_forms):
            return lambda **params: _grouped_average(rays, params, shape)
        return _contracted(rays, [build() for build in build_forms], shape)

    return Model(
        name=f"{base.name}@aperture",
        params=base.params,
        reference=(f"{base.reference}; averaged over lamp {lamp_solid_angle_sr:g} sr and camera "
                   f"{camera_solid_angle_sr:g} sr apertures (Oren & Nayar 1995, section 5)"),
        description=f"{base.description}, as measured through finite apertures",
        prepare=prepare,
        options=base.options,
        energy_conserving=base.energy_conserving,
        reciprocal=False,
        isotropic=base.isotropic,
        linear_in=base.linear_in,
        broadcasts_params=True,
    )


def _rule_groups(base: Model, rule: str, geometry) -> list[tuple[str, np.ndarray]]:
    """(rule name, flat indices of its geometries) per rule in use; ``geometry`` in [rad]."""
    n = int(np.size(geometry[0]))
    if rule != "auto" or n == 0:
        return [(rule if rule != "auto" else "full", np.arange(n))]
    if base.name not in COMPACT_RULE_MODELS:
        return [("full", np.arange(n))]
    compact = aperture_rule(*(np.degrees(np.ravel(g)) for g in geometry))
    return [(name, index) for name, index in (("compact", np.flatnonzero(compact)), ("full", np.flatnonzero(~compact)))
            if index.size]


def _columns(params: dict[str, Any], index: np.ndarray, n: int) -> dict[str, Any]:
    """The parameters of the geometries ``index``: array parameters run along the flat
    geometry (last axis, length 1 or ``n``)."""
    return {k: (v[..., index] if np.ndim(v) and np.shape(v)[-1] == n and n != 1 else v) for k, v in params.items()}


def _grouped_average(groups: list[tuple[np.ndarray, "_SubRays"]], params: dict[str, Any],
                     shape: tuple[int, ...]) -> np.ndarray:
    """f_eff [1/sr] of every geometry, each rule's group averaged over its own sub-rays."""
    if len(groups) == 1 and groups[0][0].size == int(np.prod(shape, dtype=int)):
        return groups[0][1].average(params, shape)
    n = int(np.prod(shape, dtype=int))
    parts = [(index, rays.average(_columns(params, index, n), (index.size,))) for index, rays in groups]
    lead = np.broadcast_shapes(*(part.shape[:-1] for _, part in parts)) if parts else ()
    out = np.empty(lead + (n,))
    for index, part in parts:
        out[..., index] = part
    return out.reshape(lead + shape)


class _SubRays:
    """The k x k (lamp, camera) sub-rays of every geometry of one rule and their weights
    (k = 7 for the full rule, 4 for the compact one)."""

    def __init__(self, fixed: FixedGeometryModel, weighted_cos: np.ndarray, normaliser: np.ndarray,
                 build: Any) -> None:
        #: The base model on the sub-rays, shape (n, k, k).
        self.fixed = fixed
        #: Quadrature weight times cos(theta_i') per sub-ray, shape (n, k, k).
        self.weighted_cos = weighted_cos
        #: cos(theta_i) of each axis (1 at grazing incidence), shape (n,).
        self.normaliser = normaliser
        self._build = build

    @classmethod
    def of(cls, base: Model, ti, pi_, tr, pr, lamp_sr: float, camera_sr: float, options,
           rule: str = "full") -> "_SubRays":
        """Sub-rays of the geometries ``ti, pi_, tr, pr`` [rad] (any shape, flattened) by ``rule``."""
        n = np.size(ti)
        ti_k, pi_k, w_i = cone_quadrature(np.degrees(ti), np.degrees(pi_), lamp_sr, rule)
        tr_k, pr_k, w_r = cone_quadrature(np.degrees(tr), np.degrees(pr), camera_sr, rule)

        def build(index=slice(None)) -> FixedGeometryModel:
            # all k x k (lamp, camera) pairs per geometry: shape (n, k, k)
            return base.at(ti_k[index, :, None], pi_k[index, :, None], tr_k[index, None, :], pr_k[index, None, :],
                           **options)

        cos_k = np.clip(np.cos(np.radians(ti_k)), 0.0, None)[:, :, None]
        weights = w_i[None, :, None] * w_r[None, None, :]
        cos_axis = np.cos(np.asarray(ti, float)).reshape(n)
        grazing = cos_axis <= 1e-12
        normaliser = np.where(grazing, 1.0, cos_axis)
        weighted_cos = np.where(grazing[:, None, None], 1.0, cos_k) * weights
        return cls(build(), weighted_cos, normaliser, build)

    def subset(self, index: np.ndarray) -> "_SubRays":
        """The sub-rays of the geometries ``index`` only."""
        return _SubRays(self._build(index), self.weighted_cos[index], self.normaliser[index], self._build)

    def average(self, params: dict[str, Any], shape: tuple[int, ...]) -> np.ndarray:
        """f_eff [1/sr]: the base model at every sub-ray, averaged (module notes)."""
        # params were validated by the outer model; arrays run along the flat geometry
        # (last axis, length 1 or n), so two axes for the k x k sub-rays are appended
        inner = {k: (np.expand_dims(v, (-2, -1)) if np.ndim(v) else v) for k, v in params.items()}
        values = self.fixed.unchecked(**inner)
        averaged = np.einsum("...nij,nij->...n", values, self.weighted_cos) / self.normaliser
        return averaged.reshape(averaged.shape[:-1] + shape)


def _contracted(groups: list[tuple[np.ndarray, _SubRays]], forms: list[LinearForm], shape: tuple[int, ...]):
    """f_eff of a model with a :class:`~gonio.models.LinearForm`: its K terms averaged over
    the sub-rays once, so each call costs K terms per geometry instead of k x k model values.
    Geometries where the form is not exact at some sub-ray (e.g. where Oren-Nayar's floor
    at 0 can act) keep the sub-ray average (equal to rounding, tested)."""
    n = int(np.prod(shape, dtype=int))
    averaged = np.zeros((forms[0].terms.shape[0], n))
    rest_groups, rest_all = [], []
    for (index, rays), form in zip(groups, forms):
        fixed = rays.fixed
        terms = np.zeros((form.terms.shape[0],) + fixed.shape)
        terms[:, fixed._valid] = form.terms
        terms[:, fixed._nan] = np.nan
        averaged[:, index] = np.einsum("knij,nij->kn", terms, rays.weighted_cos) / rays.normaliser
        exact = np.ones(fixed.shape, bool)
        if form.exact is not None:
            exact[fixed._valid] = form.exact
        rest = np.flatnonzero(~exact.all(axis=(1, 2)))
        if rest.size:
            rest_groups.append((index[rest], rays.subset(rest)))
            rest_all.append(index[rest])
    rest_index = np.concatenate(rest_all) if rest_all else np.zeros(0, int)
    coefficients, combine = forms[0].coefficients, forms[0].combine

    def evaluate(**params: Any) -> np.ndarray:
        out = combine(coefficients(**params), averaged)
        if rest_groups:
            out = np.array(np.broadcast_to(out, np.broadcast_shapes(out.shape, *(np.shape(v) for v in params.values()))))
            for index, rays in rest_groups:
                out[..., index] = rays.average(_columns(params, index, n), (index.size,))
        return out.reshape(out.shape[:-1] + shape)

    def averaged_form() -> LinearForm:
        exact_points = np.ones(averaged.shape[1], bool)
        exact_points[rest_index] = False
        return LinearForm(averaged, coefficients, exact_points)

    evaluate.linear_form = averaged_form  # type: ignore[attr-defined]
    return evaluate
