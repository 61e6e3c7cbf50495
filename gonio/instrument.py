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
(uniform on the disk is uniform in solid angle) and the 7-point disk cubature exact for
polynomials of degree 3 (A. H. Stroud, *Approximate Calculation of Multiple Integrals*,
1971, formula S2:3-1: the centre with weight 1/4 and six points at radius sqrt(2/3) with
weight 1/8), 7 x 7 = 49 BRDF evaluations per geometry.
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
    "cone_half_angle",
    "cone_offsets",
    "cone_quadrature",
    "aperture_averaged",
]

#: Solid angle of the lamp seen from the sample (Oren & Nayar 1995, section 5) [sr].
LAMP_SOLID_ANGLE_SR = 0.003
#: Solid angle of the camera's pupil seen from the sample (same source) [sr].
CAMERA_SOLID_ANGLE_SR = 0.0009

_DISK_RADII = np.array([0.0] + [math.sqrt(2.0 / 3.0)] * 6)
_DISK_ANGLES = np.array([0.0] + [k * math.pi / 3.0 for k in range(6)])
_DISK_WEIGHTS = np.array([0.25] + [0.125] * 6)


def cone_half_angle(solid_angle_sr: float) -> float:
    """Half-angle [deg] of a circular cone of the given solid angle: Omega = 2 pi (1 - cos a)."""
    if not 0.0 < solid_angle_sr < 2.0 * math.pi:
        raise ValueError(f"solid angle must be in (0, 2 pi) sr, got {solid_angle_sr!r}")
    return math.degrees(math.acos(1.0 - solid_angle_sr / (2.0 * math.pi)))


def cone_offsets(solid_angle_sr: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cubature points of a cone about its axis (Stroud S2:3-1 on the equal-area disk):
    each point's angle from the axis [rad], its angle around the axis [rad] and its weight,
    shapes (7,), the weights summing to 1 (:func:`cone_quadrature` places them about axes).

    Examples
    --------
    >>> beta, around, weights = cone_offsets(0.003)
    >>> float(beta[0]), round(float(np.degrees(beta[1])), 4), float(weights.sum())
    (0.0, 1.4457, 1.0)
    """
    half = math.radians(cone_half_angle(solid_angle_sr))
    r = _DISK_RADII * 2.0 * math.sin(half / 2.0)  # equal-area disk radius of the rim
    return 2.0 * np.arcsin(r / 2.0), _DISK_ANGLES.copy(), _DISK_WEIGHTS.copy()


def cone_quadrature(theta: ArrayLike, phi: ArrayLike, solid_angle_sr: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadrature directions and weights averaging over cones about many axes.

    Parameters
    ----------
    theta, phi : array_like
        Cone axes [deg], flattened to shape (n,) (same number of elements).
    solid_angle_sr : float
        Solid angle of every cone [sr].

    Returns
    -------
    theta_k, phi_k : numpy.ndarray
        Directions [deg], shape (n, 7); they may lie below the horizon near grazing axes.
    weights : numpy.ndarray
        Weights, shape (7,), summing to 1.
    """
    t = np.radians(np.ravel(np.asarray(theta, float)))[:, None]
    p = np.radians(np.ravel(np.asarray(phi, float)))[:, None]
    beta, around, weights = cone_offsets(solid_angle_sr)
    cb, sb = np.cos(beta), np.sin(beta)
    ca, sa = cb * 0 + np.cos(around), np.sin(around)
    axis = (np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t))
    e1 = (np.cos(t) * np.cos(p), np.cos(t) * np.sin(p), -np.sin(t))
    e2 = (-np.sin(p), np.cos(p), 0.0 * t)
    x, y, z = (cb * a + sb * ca * b + sb * sa * c for a, b, c in zip(axis, e1, e2))
    return np.degrees(np.arctan2(np.hypot(x, y), z)), np.degrees(np.arctan2(y, x)), weights


def aperture_averaged(
    model: str | Model,
    lamp_solid_angle_sr: float = LAMP_SOLID_ANGLE_SR,
    camera_solid_angle_sr: float = CAMERA_SOLID_ANGLE_SR,
) -> Model:
    """The effective BRDF a rig with finite apertures measures, as a :class:`Model`.

    Parameters
    ----------
    model : str or Model
        The sample's reflectance model.
    lamp_solid_angle_sr, camera_solid_angle_sr : float
        Apertures of source and detector seen from the sample [sr].

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

    def prepare(ti, pi_, tr, pr, **options: Any):
        shape = np.shape(ti)
        rays = _SubRays.of(base, ti, pi_, tr, pr, lamp_solid_angle_sr, camera_solid_angle_sr, options)
        build_form = getattr(rays.fixed.prepared, "linear_form", None)
        if build_form is None:
            return lambda **params: rays.average(params, shape)
        return _contracted(rays, build_form(), shape)

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


class _SubRays:
    """The 7 x 7 (lamp, camera) sub-rays of every geometry and their weights."""

    def __init__(self, fixed: FixedGeometryModel, weighted_cos: np.ndarray, normaliser: np.ndarray,
                 build: Any) -> None:
        #: The base model on the sub-rays, shape (n, 7, 7).
        self.fixed = fixed
        #: Quadrature weight times cos(theta_i') per sub-ray, shape (n, 7, 7).
        self.weighted_cos = weighted_cos
        #: cos(theta_i) of each axis (1 at grazing incidence), shape (n,).
        self.normaliser = normaliser
        self._build = build

    @classmethod
    def of(cls, base: Model, ti, pi_, tr, pr, lamp_sr: float, camera_sr: float, options) -> "_SubRays":
        """Sub-rays of the geometries ``ti, pi_, tr, pr`` [rad] (any shape, flattened)."""
        n = np.size(ti)
        ti_k, pi_k, w_i = cone_quadrature(np.degrees(ti), np.degrees(pi_), lamp_sr)
        tr_k, pr_k, w_r = cone_quadrature(np.degrees(tr), np.degrees(pr), camera_sr)

        def build(index=slice(None)) -> FixedGeometryModel:
            # all 49 (lamp, camera) pairs per geometry: shape (n, 7, 7)
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
        # (last axis, length 1 or n), so two axes for the 7 x 7 sub-rays are appended
        inner = {k: (np.expand_dims(v, (-2, -1)) if np.ndim(v) else v) for k, v in params.items()}
        values = self.fixed.unchecked(**inner)
        averaged = np.einsum("...nij,nij->...n", values, self.weighted_cos) / self.normaliser
        return averaged.reshape(averaged.shape[:-1] + shape)


def _contracted(rays: _SubRays, form: LinearForm, shape: tuple[int, ...]):
    """f_eff of a model with a :class:`~gonio.models.LinearForm`: its K terms averaged over
    the sub-rays once, so each call costs K terms per geometry instead of 49 model values.
    Geometries where the form is not exact at some sub-ray (e.g. where Oren-Nayar's floor
    at 0 can act) keep the sub-ray average (equal to rounding, tested)."""
    fixed = rays.fixed
    terms = np.zeros((form.terms.shape[0],) + fixed.shape)
    terms[:, fixed._valid] = form.terms
    terms[:, fixed._nan] = np.nan
    averaged = np.einsum("knij,nij->kn", terms, rays.weighted_cos) / rays.normaliser
    exact = np.ones(fixed.shape, bool)
    if form.exact is not None:
        exact[fixed._valid] = form.exact
    rest = np.flatnonzero(~exact.all(axis=(1, 2)))
    rest_rays = rays.subset(rest) if rest.size else None

    def evaluate(**params: Any) -> np.ndarray:
        out = form.combine(form.coefficients(**params), averaged)
        if rest_rays is not None:
            out = np.array(np.broadcast_to(out, np.broadcast_shapes(out.shape, *(np.shape(v) for v in params.values()))))
            local = {k: (v[..., rest] if np.shape(v)[-1:] not in ((), (1,)) else v) for k, v in params.items()}
            out[..., rest] = rest_rays.average(local, (rest.size,))
        return out.reshape(out.shape[:-1] + shape)

    def averaged_form() -> LinearForm:
        exact_points = np.ones(averaged.shape[1], bool)
        exact_points[rest] = False
        return LinearForm(averaged, form.coefficients, exact_points)

    evaluate.linear_form = averaged_form  # type: ignore[attr-defined]
    return evaluate
