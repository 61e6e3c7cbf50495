"""Textons and radiance histograms of pitted surfaces, laid out as Figs 13-14 of
Koenderink, van Doorn, Dana & Nayar (1999), and a tiled texture (section 4.2).

Figure API only (no pyplot state), so it works without a display.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from matplotlib.figure import Figure

from gonio.models.pitted.textons import (
    FIGURE_13_GEOMETRIES,
    Texton,
    radiance_histogram,
    render_texton,
    render_texture,
)

__all__ = ["render_figure_13_textons", "plot_textons", "plot_histograms", "plot_texture", "write_texton_figures"]


def _label(geometry: tuple[float, float, float]) -> str:
    alpha, beta, eps = geometry
    if alpha == 0.0 or beta == 0.0:
        return f"({alpha:g}°, {beta:g}°)"
    return f"({alpha:g}°, {beta:g}°, {eps:g}°)"


def render_figure_13_textons(rho: float = 1.0, psi: float = 90.0, pixels: int = 128):
    """Textons for the 13 (alpha, beta, epsilon) cells of Figs 13-14 (None for empty cells)."""
    return [[None if g is None else render_texton(*g, rho=rho, psi=psi, pixels=pixels) for g in row]
            for row in FIGURE_13_GEOMETRIES]


def _grid_axes(fig: Figure, rows: int, cols: int):
    return fig.subplots(rows, cols, squeeze=False)


def plot_textons(textons, title: str = "") -> Figure:
    """Fig 13 layout: each texton scaled so that its maximum radiance is white.

    Parameters
    ----------
    textons : list of list of Texton or None
        As returned by :func:`render_figure_13_textons`.
    title : str
        Figure title.
    """
    rows, cols = len(textons), max(len(r) for r in textons)
    fig = Figure(figsize=(2.2 * cols, 2.3 * rows), layout="constrained")
    axes = _grid_axes(fig, rows, cols)
    for r, row in enumerate(textons):
        for c in range(cols):
            ax = axes[r][c]
            ax.set_axis_off()
            texton: Texton | None = row[c] if c < len(row) else None
            if texton is None:
                continue
            ax.imshow(texton.radiance, cmap="gray", vmin=0.0, vmax=float(texton.radiance.max()),
                      extent=texton.extent, interpolation="nearest")
            ax.set_title(_label(texton.geometry), fontsize=9)
    fig.suptitle(title or "Textons of a spherical pit (alpha, beta, epsilon), Koenderink et al. 1999 Fig 13",
                 fontsize=10)
    return fig


def plot_histograms(textons, bins: int = 64, title: str = "") -> Figure:
    """Fig 14 layout: radiance histograms of the pit pixels of each texton.

    The dashed line marks the diffuse radiance of eq 12 (times cos alpha), where the narrow
    cast-shadow mode sits; the dotted line the radiance of the flat plane.
    """
    rows, cols = len(textons), max(len(r) for r in textons)
    fig = Figure(figsize=(2.6 * cols, 2.0 * rows), layout="constrained")
    axes = _grid_axes(fig, rows, cols)
    for r, row in enumerate(textons):
        for c in range(cols):
            ax = axes[r][c]
            texton = row[c] if c < len(row) else None
            if texton is None:
                ax.set_axis_off()
                continue
            values = texton.pit_radiances
            hi = max(float(values.max()), texton.plane_radiance) * 1.05
            density, edges = radiance_histogram(values, bins=bins, value_range=(0.0, hi))
            ax.stairs(density, edges, fill=True, color="0.35")
            ax.axvline(texton.diffuse_radiance, color="tab:red", ls="--", lw=0.8)
            ax.axvline(texton.plane_radiance, color="tab:blue", ls=":", lw=0.8)
            ax.set_title(_label(texton.geometry), fontsize=9)
            ax.set_yticks([])
            ax.tick_params(labelsize=7)
            if r == rows - 1:
                ax.set_xlabel("radiance [sr$^{-1}$] per unit irradiance", fontsize=7)
    fig.suptitle(title or "Radiance histograms (Fig 14 layout); red dashed: diffuse radiance eq 12, "
                 "blue dotted: flat plane", fontsize=9)
    return fig


def plot_texture(theta_i: float, theta_r: float, epsilon: float, rho: float = 1.0, psi: float = 90.0,
                 coverage: float = 0.5, pixels: int = 256, seed: int = 0) -> Figure:
    """A pitted plane with log-normal pit diameters seen from (theta_r, epsilon), lit from theta_i."""
    texture = render_texture(theta_i, theta_r, epsilon, rho=rho, psi=psi, coverage=coverage,
                             pixels=pixels, seed=seed)
    fig = Figure(figsize=(4.5, 4.8), layout="constrained")
    ax = fig.subplots()
    ax.imshow(texture.radiance, cmap="gray", vmin=0.0, interpolation="nearest")
    ax.set_axis_off()
    ax.set_title(f"texture {_label((theta_i, theta_r, epsilon))}, psi = {psi:g}°, "
                 f"coverage {texture.coverage:.2f}", fontsize=9)
    return fig


def write_texton_figures(out: Path | str, rho: float = 1.0, psi: float = 90.0, pixels: int = 128,
                         progress: Callable[[str], None] | None = None) -> list[Path]:
    """Write textons.png (Fig 13), histograms.png (Fig 14) and texture.png into ``out``.

    Parameters
    ----------
    out : path
        Output folder (created if needed).
    rho : float
        Micro-scale albedo [-] (the paper's figures: 1).
    psi : float
        Aperture [deg] (the paper's figures: 90, the hemispherical pit).
    pixels : int
        Texton image size.
    progress : callable, optional
        Called with each written path.

    Returns
    -------
    list of pathlib.Path
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    textons = render_figure_13_textons(rho=rho, psi=psi, pixels=pixels)
    figures = {
        "textons.png": plot_textons(textons),
        "histograms.png": plot_histograms(textons),
        "texture.png": plot_texture(30.0, 30.0, 180.0, rho=rho, psi=psi, pixels=2 * pixels),
    }
    paths = []
    for name, fig in figures.items():
        path = out / name
        fig.savefig(path, dpi=110)
        paths.append(path)
        if progress is not None:
            progress(str(path))
    return paths
