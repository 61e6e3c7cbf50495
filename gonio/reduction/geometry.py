"""Geometry of a recording's readings: readback angles, repeats, local slopes of the curve."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from ..uncertainty import local_slopes

__all__ = ["AXES", "DEFAULT_RESOLUTION", "readback_or_plan", "readback_geometry", "lamp_direction", "planned_groups",
           "geometry_slopes"]

#: Encoder resolution assumed for recordings that did not store it [deg].
DEFAULT_RESOLUTION = 0.001


AXES = ((0, 2), (1, 3), (2, 1))  # (column of the geometry array, stage axis): theta_i, phi_i, view


def readback_or_plan(points: Mapping[str, np.ndarray], readback: str, planned: str) -> np.ndarray:
    """A readback column [deg], the planned one where the readback is missing (older recordings)."""
    values = np.asarray(points[readback], float)
    return np.where(np.isfinite(values), values, np.asarray(points[planned], float))


def lamp_direction(theta_i: np.ndarray, phi_i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lamp's polar angle and azimuth [deg] of a stage readback, as a direction.

    At normal incidence the polar axis reads back a few encoder counts either side of 0:
    a reading of -0.004 deg at azimuth phi is the direction 0.004 deg at phi + 180 deg
    (the azimuth wrapped to (-180, 180]), which the models accept (polar angles in
    [0, 90] deg).

    >>> lamp_direction(np.array([-0.004, 30.0]), np.array([0.0, 10.0]))
    (array([4.e-03, 3.e+01]), array([180.,  10.]))
    """
    theta_i, phi_i = np.asarray(theta_i, float), np.asarray(phi_i, float)
    negative = theta_i < 0
    turned = phi_i + 180.0
    turned = np.where(turned > 180.0, turned - 360.0, turned)
    return np.abs(theta_i), np.where(negative, turned, phi_i)


def readback_geometry(points) -> np.ndarray:
    """(theta_i, phi_i, view) of every row from the stage readback (the plan where missing),
    as the stage read them (a polar angle a hair below 0 stays: :func:`lamp_direction`
    makes it a direction where a model is evaluated)."""
    return np.stack([readback_or_plan(points, "stage_lamp_theta", "theta_i"),
                     readback_or_plan(points, "stage_lamp_phi", "phi_i"),
                     readback_or_plan(points, "stage_camera", "view")], axis=1)


def planned_groups(points, indices: np.ndarray) -> dict[tuple, list[int]]:
    """Rows by planned geometry (theta_i, phi_i, view): the repeats of one geometry."""
    groups: dict[tuple, list[int]] = {}
    for i in indices:
        key = (round(float(points["theta_i"][i]), 6), round(float(points["phi_i"][i]), 6),
               round(float(points["view"][i]), 6))
        groups.setdefault(key, []).append(int(i))
    return groups


def geometry_slopes(geometry: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Local slope of the measured values along theta_i, phi_i and view [value unit per deg].

    ``geometry`` holds (theta_i, phi_i, view) per value. Along view and phi_i the slope is
    the finite difference of the measured curve (:func:`~gonio.uncertainty.local_slopes`).
    Along theta_i the value is split into the irradiance factor ``cos(theta_i)``, known
    exactly, and ``g = value / cos(theta_i)``, whose slope comes from neighbouring lamp
    angles when the recording has them (else 0): near grazing incidence the cosine
    dominates, and it is there that the lamp's repeatability matters most.

    Returns
    -------
    numpy.ndarray
        Shape (n, 3): slopes along theta_i, phi_i, view.
    """
    slopes = np.zeros((len(values), 3))
    for column, _ in AXES:
        others = np.delete(geometry, column, axis=1)
        if column == 0:
            cos_i = np.cos(np.radians(geometry[:, 0]))
            g = values / np.where(cos_i > 1e-9, cos_i, np.nan)
            g_slope = np.nan_to_num(local_slopes(geometry[:, 0], others, np.nan_to_num(g)))
            slopes[:, 0] = -np.radians(1.0) * np.sin(np.radians(geometry[:, 0])) * np.nan_to_num(g) + cos_i * g_slope
        else:
            slopes[:, column] = local_slopes(geometry[:, column], others, values)
    return slopes
