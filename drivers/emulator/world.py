"""Geometry and radiometry of the emulated lab: where camera and lamp are, what the camera sees.

The rig is the one of Oren & Nayar (1995), section 5 and Fig. 15: a 2 x 2 inch sample at the
origin (normal +z), a 512 x 480 CCD camera at the end of a 6-foot beam swung in the x-z
plane, and a 300 W incandescent lamp.  The lamp and the camera subtend about 0.003 sr and
0.0009 sr seen from the sample; the measured radiance is therefore an average of the BRDF
over both cones, computed here with a fixed quadrature (7 directions per cone).

Everything here is a pure function of its arguments; angles are in degrees.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = [
    "Optics",
    "unit_vector",
    "camera_angles",
    "separation_deg",
    "cone_half_angle_deg",
    "cone_quadrature",
    "cone_averaged_reflectance",
    "cone_rule_pairs",
    "footprint_coverage",
    "pixel_sample_coordinates",
    "PLANCK_TIMES_C",
]

#: Planck constant times the speed of light [J m].
PLANCK_TIMES_C = 6.62607015e-34 * 299792458.0

Brdf = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Optics:
    """Fixed optical layout of the rig (Oren & Nayar 1995, section 5, Fig. 15).

    Attributes
    ----------
    sample_side_mm : float
        Side of the square sample [mm] (2 inch).
    distance_mm : float
        Sample to camera distance [mm] (6 foot beam).
    focal_length_mm : float
        Camera lens focal length [mm].
    pixel_pitch_um : float
        CCD pixel pitch [um].
    width, height : int
        CCD size [pixels] (512 x 480 as in the paper).
    camera_solid_angle_sr : float
        Solid angle of the camera's entrance pupil seen from the sample [sr] (0.0009).
    lamp_solid_angle_sr : float
        Solid angle of the lamp seen from the sample [sr] (0.003).
    wavelength_nm : float
        Centre wavelength of the camera's band [nm] (photon energy).
    lens_transmittance : float
        Transmittance of lens and filter in the band [-].
    """

    sample_side_mm: float = 50.8
    distance_mm: float = 1828.8
    focal_length_mm: float = 150.0
    pixel_pitch_um: float = 15.0
    width: int = 512
    height: int = 480
    camera_solid_angle_sr: float = 0.0009
    lamp_solid_angle_sr: float = 0.003
    wavelength_nm: float = 550.0
    lens_transmittance: float = 1.0

    @property
    def magnification(self) -> float:
        """Image scale ``f / D`` [-] (far-field thin lens)."""
        return self.focal_length_mm / self.distance_mm

    @property
    def sample_size_px(self) -> float:
        """Side of the sample in the image at normal view [pixels]."""
        return self.sample_side_mm * self.magnification / (self.pixel_pitch_um * 1e-3)

    @property
    def pixel_etendue_m2_sr(self) -> float:
        """Etendue of one pixel: footprint on the sample times the pupil solid angle [m^2 sr].

        Notes
        -----
        The footprint of a pixel on the sample (normal view) is ``(p / m)^2`` and the
        pupil subtends ``Omega_r`` from it, so a pixel collects ``L (p/m)^2 Omega_r``
        watts from a surface of radiance ``L`` (conservation of etendue).
        """
        footprint_m = self.pixel_pitch_um * 1e-6 / self.magnification
        return footprint_m**2 * self.camera_solid_angle_sr

    def photon_rate_per_radiance(self) -> float:
        """Photons per second reaching one pixel per unit sample radiance [1/s per W/(m^2 sr)]."""
        photon_energy = PLANCK_TIMES_C / (self.wavelength_nm * 1e-9)
        return self.pixel_etendue_m2_sr * self.lens_transmittance / photon_energy

    def info(self) -> tuple[int, int, float, float, float]:
        """(width, height, pixel pitch [um], focal length [mm], distance [mm])."""
        return self.width, self.height, self.pixel_pitch_um, self.focal_length_mm, self.distance_mm


def unit_vector(theta: np.ndarray | float, phi: np.ndarray | float) -> np.ndarray:
    """Unit vector(s) of the direction (theta, phi) [deg], shape ``(..., 3)``."""
    t, p = np.radians(np.asarray(theta, float)), np.radians(np.asarray(phi, float))
    s = np.sin(t)
    return np.stack(np.broadcast_arrays(s * np.cos(p), s * np.sin(p), np.cos(t)), axis=-1)


def camera_angles(swing_deg: float) -> tuple[float, float]:
    """Camera direction (theta_r, phi_r) [deg] for the beam swing angle ``a1`` [deg].

    The camera moves in the x-z plane: polar angle ``|a1|``, azimuth 0 for ``a1 >= 0`` and
    180 for ``a1 < 0`` (docs/protocol.md, "Geometry of the rig").

    Examples
    --------
    >>> camera_angles(-30.0)
    (30.0, 180.0)
    """
    return abs(float(swing_deg)), (0.0 if swing_deg >= 0 else 180.0)


def separation_deg(swing_deg: float, theta_i: float, phi_i: float) -> float:
    """Angle between the camera and the lamp seen from the sample [deg].

    Parameters
    ----------
    swing_deg : float
        Camera swing angle ``a1`` [deg].
    theta_i, phi_i : float
        Lamp polar angle and azimuth [deg].

    Examples
    --------
    >>> round(separation_deg(30.0, 30.0, 0.0), 9), round(separation_deg(-30.0, 30.0, 0.0), 9)
    (0.0, 60.0)
    """
    cam = unit_vector(*camera_angles(swing_deg))
    lamp = unit_vector(theta_i, phi_i)
    # arctan2 of |cross| and dot is accurate at small angles, unlike arccos of the dot.
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(cam, lamp)), np.dot(cam, lamp))))


def cone_half_angle_deg(solid_angle_sr: float) -> float:
    """Half-angle of a circular cone of the given solid angle [deg]: ``Omega = 2 pi (1 - cos a)``.

    Examples
    --------
    >>> round(cone_half_angle_deg(0.003), 3)
    1.771
    """
    if not 0 < solid_angle_sr < 2 * np.pi:
        raise ValueError(f"solid_angle_sr must be in (0, 2 pi), got {solid_angle_sr!r}")
    return float(np.degrees(np.arccos(1.0 - solid_angle_sr / (2 * np.pi))))


#: 7-point cubature for the mean over a disk of radius 1 (centre weight 1/4, six points at
#: radius sqrt(2/3) with weight 1/8 each); exact for polynomials of degree <= 3.  See
#: A. H. Stroud, "Approximate calculation of multiple integrals" (1971), formula S2:3-1.
_DISK_RADII = np.array([0.0] + [np.sqrt(2.0 / 3.0)] * 6)
_DISK_ANGLES = np.array([0.0] + [k * np.pi / 3 for k in range(6)])
_DISK_WEIGHTS = np.array([0.25] + [0.125] * 6)


def cone_quadrature(theta_c: float, phi_c: float, solid_angle_sr: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Directions and weights averaging a function over a circular cone of directions.

    The cone (axis ``(theta_c, phi_c)``, solid angle ``Omega``) is mapped to a disk by the
    Lambert azimuthal equal-area projection about its axis, so that a uniform mean over
    the disk is a uniform mean over solid angle; the disk mean uses a 7-point cubature
    exact to degree 3.

    Parameters
    ----------
    theta_c, phi_c : float
        Cone axis [deg].
    solid_angle_sr : float
        Solid angle of the cone [sr].

    Returns
    -------
    theta, phi : numpy.ndarray
        Quadrature directions [deg], shape (7,).  Directions may lie below the horizon
        (theta > 90) near grazing axes; the caller weights them by what they contribute.
    weights : numpy.ndarray
        Weights summing to 1.

    Examples
    --------
    >>> t, p, w = cone_quadrature(0.0, 0.0, 0.003)
    >>> round(float(w.sum()), 12), round(float(t[0]), 12)
    (1.0, 0.0)
    """
    half = np.radians(cone_half_angle_deg(solid_angle_sr))
    disk_radius = 2.0 * np.sin(half / 2.0)  # equal-area projection of the cone's rim
    r = _DISK_RADII * disk_radius
    beta = 2.0 * np.arcsin(r / 2.0)  # polar angle from the cone axis
    axis = unit_vector(theta_c, phi_c)
    # Orthonormal frame (e1, e2, axis): e1 along increasing theta, e2 along increasing phi.
    t, p = np.radians(theta_c), np.radians(phi_c)
    e1 = np.array([np.cos(t) * np.cos(p), np.cos(t) * np.sin(p), -np.sin(t)])
    e2 = np.array([-np.sin(p), np.cos(p), 0.0])
    dirs = (
        np.cos(beta)[:, None] * axis
        + (np.sin(beta) * np.cos(_DISK_ANGLES))[:, None] * e1
        + (np.sin(beta) * np.sin(_DISK_ANGLES))[:, None] * e2
    )
    theta = np.degrees(np.arctan2(np.hypot(dirs[:, 0], dirs[:, 1]), dirs[:, 2]))
    phi = np.degrees(np.arctan2(dirs[:, 1], dirs[:, 0]))
    return theta, phi, _DISK_WEIGHTS.copy()


def cone_averaged_reflectance(
    brdf: Brdf,
    theta_i: float,
    phi_i: float,
    theta_r: float,
    phi_r: float,
    lamp_solid_angle_sr: float = 0.003,
    camera_solid_angle_sr: float = 0.0009,
) -> float:
    """Mean of ``brdf * cos(theta_i)`` over the lamp's and the camera's cones [1/sr].

    The radiance toward the camera from a sample lit by a lamp of uniform radiance
    ``L_lamp`` filling the lamp cone is ``L_r = E_0 <f cos theta_i>``, where
    ``E_0 = L_lamp Omega_i`` is the irradiance the lamp gives on a surface facing it and
    ``<.>`` the mean over incident directions in the lamp cone; the camera then averages
    ``L_r`` over the directions of its pupil.  Both means use :func:`cone_quadrature`
    (7 directions in each cone), combined as :func:`cone_rule_pairs` says: the sparse
    (Smolyak) combination of 13 BRDF evaluations where the integrand is smooth over both
    cones, the full 7 x 7 product (49) where it is not.  Directions below the horizon
    contribute nothing.

    Parameters
    ----------
    brdf : callable
        ``brdf(theta_i, phi_i, theta_r, phi_r) -> array`` [1/sr], degrees, broadcasting.
    theta_i, phi_i, theta_r, phi_r : float
        Lamp and camera directions (cone axes) [deg].
    lamp_solid_angle_sr, camera_solid_angle_sr : float
        Cone solid angles [sr] (Oren & Nayar 1995, section 5: 0.003 and 0.0009).

    Returns
    -------
    float
        ``<f cos theta_i>`` [1/sr]; multiply by ``E_0`` [W/m^2] for the radiance.

    Notes
    -----
    For a Lambertian sample (``f = rho / pi``) this is ``rho cos(theta_i) / pi`` up to the
    averaging of ``cos theta_i`` over the lamp cone (a relative change of order
    ``half_angle^2 / 4 ~ 2e-4`` away from grazing).

    References
    ----------
    M. Oren, S. K. Nayar, "Generalization of the Lambertian model and implications for
    machine vision", IJCV 14(3), 1995, section 5 and Fig. 15.

    Examples
    --------
    >>> lambert = lambda ti, pi, tr, pr: np.full(np.broadcast(ti, tr).shape, 1 / np.pi)
    >>> round(cone_averaged_reflectance(lambert, 0.0, 0.0, 30.0, 0.0) * np.pi, 4)
    0.9998
    """
    ti, pi_, wi = cone_quadrature(theta_i, phi_i, lamp_solid_angle_sr)
    tr, pr, wr = cone_quadrature(theta_r, phi_r, camera_solid_angle_sr)
    lamp_index, camera_index, weights = cone_rule_pairs(
        theta_i, theta_r, cone_half_angle_deg(lamp_solid_angle_sr), cone_half_angle_deg(camera_solid_angle_sr), wi, wr)
    ti, pi_, tr, pr = ti[lamp_index], pi_[lamp_index], tr[camera_index], pr[camera_index]
    f = np.broadcast_to(np.asarray(brdf(ti, pi_, tr, pr), float), ti.shape)
    visible = _above_horizon(ti) * _above_horizon(tr)
    return float(np.sum(weights * visible * np.where(visible > 0, f * np.cos(np.radians(ti)), 0.0)))


#: Where the sparse combination of :func:`cone_rule_pairs` is not used: polar axes closer
#: than this many times the sum of the two cones' half-angles [-] (the integrand's kink at
#: theta_i = theta_r may lie inside the cones), or a cone reaching this close to the
#: horizon [deg] (the integrand is cut there).
KINK_CLEARANCE = 2.0
HORIZON_CLEARANCE_DEG = 1.0


def cone_rule_pairs(theta_i: float, theta_r: float, lamp_half_deg: float, camera_half_deg: float,
                    lamp_weights: np.ndarray, camera_weights: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which (lamp, camera) quadrature directions the cone average evaluates, with weights.

    The full product of the two cone rules takes ``n_l x n_c`` evaluations (49).  Its
    sparse (Smolyak) combination, ``Q_l x C_c + C_l x Q_c - C_l x C_c`` with ``C`` the
    cone's axis alone, takes ``n_l + n_c - 1`` (13) and is exact, like the product, for
    every term of degree <= 3 in the four offsets from the axes; it misses the product
    terms of degree 4 and higher in both cones' offsets (``x_l^2 y_c^2``: relative size
    ``half_l^2 half_c^2 / 16`` times a fourth derivative, ~1e-8 for the rig's cones).

    Decision: the sparse combination is used only where the integrand is smooth over both
    cones.  At ``theta_i = theta_r`` in the plane of incidence the V-cavity models have a
    kink (the shadowing and masking onsets of eq 39 coincide), and there the combination
    was measured 1.5e-5 off the product on the Fig 16 protocol's geometries with
    ``oren-nayar-exact`` at sigma = 30 deg (5e-3 for the functional form at retro-
    reflection): where the polar axes are closer than :data:`KINK_CLEARANCE` times the sum
    of the half-angles, or a cone comes within :data:`HORIZON_CLEARANCE_DEG` of the
    horizon (the integrand is cut there), the full product is used.  With that rule the
    average over the 135 directions the demo's two protocols measure differs from the
    product's by at most 5.6e-7 (median 1e-8), 1/100 of the ideal rig's noise, with 2.9
    times fewer evaluations (tests/drivers/test_emulator_world.py).

    Parameters
    ----------
    theta_i, theta_r : float
        Polar angles of the lamp's and the camera's axes [deg].
    lamp_half_deg, camera_half_deg : float
        The cones' half-angles [deg].
    lamp_weights, camera_weights : numpy.ndarray
        The cone rules' weights, the axis first (:func:`cone_quadrature`).

    Returns
    -------
    lamp_index, camera_index : numpy.ndarray of int
        The directions of each evaluation in the two cone rules.
    weights : numpy.ndarray
        The weight of each evaluation (summing to 1).

    References
    ----------
    S. A. Smolyak, "Quadrature and interpolation formulas for tensor products of certain
    classes of functions", Soviet Math. Dokl. 4, 1963; T. Gerstner, M. Griebel, "Numerical
    integration using sparse grids", Numer. Algorithms 18, 1998 (the combination technique).

    Examples
    --------
    >>> w = np.array([0.25] + [0.125] * 6)
    >>> lamp, camera, weights = cone_rule_pairs(45.0, 20.0, 1.77, 0.97, w, w)
    >>> len(weights), round(float(weights.sum()), 12)
    (13, 1.0)
    >>> len(cone_rule_pairs(45.0, 44.0, 1.77, 0.97, w, w)[2])   # near theta_i = theta_r: the product
    49
    """
    n_l, n_c = len(lamp_weights), len(camera_weights)
    near_kink = abs(theta_i - theta_r) < KINK_CLEARANCE * (lamp_half_deg + camera_half_deg)
    near_horizon = max(theta_i + lamp_half_deg, theta_r + camera_half_deg) > 90.0 - HORIZON_CLEARANCE_DEG
    if near_kink or near_horizon:
        lamp, camera = np.meshgrid(np.arange(n_l), np.arange(n_c), indexing="ij")
        return lamp.ravel(), camera.ravel(), np.outer(lamp_weights, camera_weights).ravel()
    lamp = np.concatenate([np.arange(n_l), np.zeros(n_c - 1, int)])
    camera = np.concatenate([np.zeros(n_l, int), np.arange(1, n_c)])
    weights = np.concatenate([lamp_weights, camera_weights[1:]])
    weights[0] += camera_weights[0] - 1.0  # + C_l x Q_c's axis term - C_l x C_c
    return lamp, camera, weights


def _above_horizon(theta: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """1 above the horizon, 0 below, 1/2 on it (a quadrature point on the boundary of the
    visible half-space counts for half its cell)."""
    return np.where(theta < 90.0 - tol, 1.0, np.where(theta <= 90.0 + tol, 0.5, 0.0))


def _interval_overlap(edges_lo: np.ndarray, edges_hi: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Length of the overlap of each interval [edges_lo, edges_hi) with [lo, hi]."""
    return np.clip(np.minimum(edges_hi, hi) - np.maximum(edges_lo, lo), 0.0, None)


def footprint_coverage(optics: Optics, theta_r: float) -> np.ndarray:
    """Fraction of each pixel covered by the image of the sample, shape (height, width).

    The sample's image is a rectangle centred on the image centre, foreshortened along
    the swing plane (image x) by ``cos(theta_r)``: ``S cos(theta_r)`` by ``S`` pixels with
    ``S = side * f / (D * pitch)`` (about 277.8 pixels).  Edge pixels are covered
    partially (exact area fractions, the rectangle being axis-aligned).

    Parameters
    ----------
    optics : Optics
        Rig layout.
    theta_r : float
        Camera polar angle [deg], 0..90.

    Examples
    --------
    >>> cov = footprint_coverage(Optics(), 60.0)
    >>> round(float(cov.sum()), 3) == round(Optics().sample_size_px**2 * 0.5, 3)
    True
    """
    size = optics.sample_size_px
    half_w = 0.5 * size * max(np.cos(np.radians(theta_r)), 0.0)
    half_h = 0.5 * size
    cx, cy = optics.width / 2.0, optics.height / 2.0
    xs = np.arange(optics.width, dtype=float)
    ys = np.arange(optics.height, dtype=float)
    fx = _interval_overlap(xs, xs + 1.0, cx - half_w, cx + half_w)
    fy = _interval_overlap(ys, ys + 1.0, cy - half_h, cy + half_h)
    return np.outer(fy, fx)


def pixel_sample_coordinates(optics: Optics, theta_r: float) -> tuple[np.ndarray, np.ndarray]:
    """The point of the sample each pixel's centre sees [mm], as x of every column and y of
    every row (origin at the sample's centre; image x runs along the sample's x axis).

    The inverse of the image geometry of :func:`footprint_coverage`: a pixel is
    ``p / m`` [mm] on the sample across the swing plane and ``p / (m cos theta_r)`` along
    it.  At ``theta_r = 90`` the sample has no image and every x is infinite.

    Examples
    --------
    >>> x, y = pixel_sample_coordinates(Optics(), 60.0)
    >>> round(float(x[256] - x[255]), 4), round(float(y[240] - y[239]), 4)    # mm per pixel
    (0.3658, 0.1829)
    """
    pixel_mm = optics.pixel_pitch_um * 1e-3 / optics.magnification
    cos_r = max(np.cos(np.radians(theta_r)), 0.0)
    columns = (np.arange(optics.width) + 0.5 - optics.width / 2.0) * pixel_mm
    with np.errstate(divide="ignore"):
        x = columns / cos_r if cos_r > 0 else np.copysign(np.inf, columns)
    y = (np.arange(optics.height) + 0.5 - optics.height / 2.0) * pixel_mm
    return x, y
