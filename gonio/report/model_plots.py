"""Slices of model BRDFs, drawn as the figures of Oren & Nayar (1995), Figs 10-14.

In-plane slices use the signed viewing angle of DESIGN.md on the horizontal axis
(positive on the source side).  Out-of-plane slices fix the azimuth difference
phi_r - phi_i and sweep theta_r from 0 to 90 deg.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
from matplotlib.figure import Figure

from gonio import models
from gonio.geometry import in_plane_angles
from gonio.radiometry import radiance_from_brdf

__all__ = ["slice_values", "plot_slices", "PLANE_LABELS"]

PLANE_LABELS = {"in": "plane of incidence", "perp": "perpendicular plane (phi_r - phi_i = 90 deg)"}
_QUANTITY_LABELS = {
    "radiance": "radiance L_r for E_0 = 1 [W m$^{-2}$ sr$^{-1}$]",
    "brdf": "BRDF f_r [sr$^{-1}$]",
    "normalised": "normalised radiance L_r / L_r(0) [-]",
}


def _plane_azimuth(plane: str | float) -> float | None:
    if plane == "in":
        return None
    if plane == "perp":
        return 90.0
    try:
        return float(plane)
    except ValueError:
        raise ValueError(f"plane {plane!r}: expected 'in', 'perp' or an azimuth difference in degrees") from None


def slice_values(
    name: str, values: dict, theta_i: float, plane: str | float = "in", quantity: str = "radiance", n: int = 181
) -> tuple[np.ndarray, np.ndarray]:
    """Abscissa [deg] and the requested quantity along one slice of a model.

    Parameters
    ----------
    name : str
        Registered model name.
    values : dict
        Model parameters.
    theta_i : float
        Incidence angle [deg] (source azimuth 0).
    plane : {'in', 'perp'} or float
        Plane of incidence (signed viewing angle from -90 to 90 deg), perpendicular plane,
        or a fixed azimuth difference [deg] (theta_r from 0 to 90 deg).
    quantity : {'radiance', 'brdf', 'normalised'}
        Radiance for unit irradiance, BRDF, or radiance divided by its value at the
        normal view (the normalised radiance Oren & Nayar plot in Figs 16-22).
    n : int
        Number of samples along the slice.
    """
    if quantity not in _QUANTITY_LABELS:
        raise ValueError(f"quantity {quantity!r}: expected one of {sorted(_QUANTITY_LABELS)}")
    azimuth = _plane_azimuth(plane)
    if azimuth is None:
        x = np.linspace(-89.5, 89.5, n)
        ti, pi_, tr, pr = in_plane_angles(theta_i, x)
    else:
        x = np.linspace(0.0, 89.5, n)
        ti, pi_, tr, pr = np.broadcast_arrays(float(theta_i), 0.0, x, azimuth)
    f = models.get(name)(ti, pi_, tr, pr, **values)
    if quantity == "brdf":
        return x, f
    radiance = radiance_from_brdf(f, 1.0, ti)
    if quantity == "normalised":
        normal = radiance_from_brdf(models.get(name)(theta_i, 0.0, 0.0, 0.0, **values), 1.0, theta_i)
        return x, radiance / normal
    return x, radiance


def _label(name: str, values: dict) -> str:
    if not values:
        return name
    return name + " (" + ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in values.items()) + ")"


def plot_slices(
    specs: Sequence[tuple[str, dict]],
    theta_i: Iterable[float] = (75.0,),
    planes: Iterable[str | float] = ("in",),
    quantity: str = "radiance",
    out: str | Path = "gonio-slices.png",
    title: str | None = None,
) -> Path:
    """Draw slices of several models, one panel per plane, and save a PNG.

    Parameters
    ----------
    specs : sequence of (name, values)
        Models to overlay.
    theta_i : iterable of float
        Incidence angles [deg]; each gets its own line per model.
    planes : iterable
        Planes, see :func:`slice_values`; one panel each.
    quantity : str
        See :func:`slice_values`.
    out : path
        PNG file to write (parent folders are created).
    title : str, optional
        Figure title.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    planes = list(planes)
    thetas = [float(t) for t in theta_i]
    fig = Figure(figsize=(5.2 * len(planes), 4.2), layout="constrained")
    axes = fig.subplots(1, len(planes), squeeze=False)[0]
    styles = ["-", "--", ":", "-."]
    for ax, plane in zip(axes, planes):
        for m, (name, values) in enumerate(specs):
            for k, ti in enumerate(thetas):
                x, y = slice_values(name, values, ti, plane, quantity)
                label = _label(name, values) + (f", theta_i={ti:g} deg" if len(thetas) > 1 else "")
                ax.plot(x, y, styles[m % len(styles)], color=f"C{k if len(specs) == 1 else m}", label=label)
        azimuth = _plane_azimuth(plane)
        if azimuth is None:
            ax.set_xlabel("signed viewing angle theta_r [deg] (+ source side)")
            for ti in thetas:
                ax.axvline(ti, color="0.7", lw=0.8, zorder=0)
            ax.set_title(PLANE_LABELS["in"] + (f", theta_i = {thetas[0]:g} deg" if len(thetas) == 1 else ""))
        else:
            ax.set_xlabel("viewing angle theta_r [deg]")
            ax.set_title(f"phi_r - phi_i = {azimuth:g} deg" + (f", theta_i = {thetas[0]:g} deg" if len(thetas) == 1 else ""))
        ax.set_ylabel(_QUANTITY_LABELS[quantity])
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    if title:
        fig.suptitle(title)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    return out
