"""Figures of a model's appearance (:mod:`gonio.vision`): a shape rendered with the model
beside Lambert of the same albedo, as in the paper's Fig 3 and Figs 23-24, reflectance
maps beside Lambert's, as in its Fig 25, and the orientations photometric stereo
recovers under each, as in its Figs 26-27."""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

__all__ = ["shape_figure", "reflectance_map_figure", "stereo_figure"]


def _light_label(light: tuple[float, float]) -> str:
    theta, phi = light
    return "source at the viewer" if theta == 0 else f"source at theta {theta:g}, phi {phi:g} deg"


def shape_figure(title: str, rows: Sequence[Mapping[str, np.ndarray]], lights: Sequence[tuple[float, float]],
                 albedo: float) -> Figure:
    """One row per source: the model's image, Lambert's, their brightness along the middle
    row of pixels, and, with posterior draws, the relative width of the 95 % band.

    Parameters
    ----------
    title : str
        What was rendered.
    rows : sequence of mapping
        Per source: ``model`` and ``lambert`` images, optionally ``low`` and ``high`` (the
        2.5 and 97.5 % images over posterior draws).
    lights : sequence of (theta, phi)
        The sources [deg].
    albedo : float
        Lambert's albedo [-].
    """
    with_band = all("low" in row for row in rows)
    columns = 4 if with_band else 3
    fig = Figure(figsize=(3.3 * columns, 3.1 * len(rows) + 0.5))
    axes = fig.subplots(len(rows), columns, squeeze=False)
    for k, (row, light) in enumerate(zip(rows, lights)):
        model, lambert = row["model"], row["lambert"]
        top = float(np.nanmax([np.nanmax(model), np.nanmax(lambert)]))
        for ax, image, name in ((axes[k, 0], model, "model"), (axes[k, 1], lambert, f"Lambert, albedo {albedo:.3g}")):
            shown = ax.imshow(image, cmap="gray", vmin=0.0, vmax=top)
            ax.set_title(f"{name}\n{_light_label(light)}", fontsize=8)
            ax.set_axis_off()
        fig.colorbar(shown, ax=axes[k, 1], fraction=0.046, pad=0.02, label="radiance / E0 [1/sr]")
        middle = model.shape[0] // 2
        x = np.linspace(-1.0, 1.0, model.shape[1])
        axes[k, 2].plot(x, model[middle], label="model")
        axes[k, 2].plot(x, lambert[middle], "--", label="Lambert")
        axes[k, 2].set_xlabel("position across the shape [radius]", fontsize=8)
        axes[k, 2].set_ylabel("radiance / E0 [1/sr]", fontsize=8)
        axes[k, 2].set_title("middle row of pixels", fontsize=8)
        axes[k, 2].legend(fontsize=7)
        axes[k, 2].grid(alpha=0.3)
        if with_band:
            width = np.divide(row["high"] - row["low"], model, out=np.full_like(model, np.nan), where=model > 0)
            shown = axes[k, 3].imshow(100.0 * width, cmap="viridis")
            axes[k, 3].set_title("95 % band of the posterior\n(width / median)", fontsize=8)
            axes[k, 3].set_axis_off()
            fig.colorbar(shown, ax=axes[k, 3], fraction=0.046, pad=0.02, label="[%]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def reflectance_map_figure(title: str, p: np.ndarray, q: np.ndarray, model: np.ndarray, lambert: np.ndarray,
                           light: tuple[float, float], albedo: float) -> Figure:
    """Iso-brightness contours of the model's reflectance map and Lambert's in gradient
    space, at the same levels (the paper's Fig 25)."""
    fig = Figure(figsize=(10.0, 4.6))
    axes = fig.subplots(1, 2)
    top = float(np.nanmax([np.nanmax(model), np.nanmax(lambert)]))
    levels = np.linspace(0.0, top, 11)[1:]
    for ax, values, name in ((axes[0], model, "model"), (axes[1], lambert, f"Lambert, albedo {albedo:.3g}")):
        filled = ax.contourf(p, q, values, levels=np.linspace(0.0, top, 41), cmap="gray")
        lines = ax.contour(p, q, values, levels=levels, colors="tab:red", linewidths=0.8)
        ax.clabel(lines, fontsize=6, fmt="%.3g")
        ax.set_aspect("equal")
        ax.set_xlabel("p = dz/dx", fontsize=8)
        ax.set_ylabel("q = dz/dy", fontsize=8)
        ax.set_title(f"{name}, {_light_label(light)}", fontsize=8)
    fig.colorbar(filled, ax=axes, fraction=0.03, pad=0.02, label="radiance / E0 [1/sr]")
    fig.suptitle(title, fontsize=10)
    return fig


def _normal_colours(normals: np.ndarray) -> np.ndarray:
    """Normals as colours, (n + 1) / 2 per component; white where none was recovered."""
    return np.where(np.isfinite(normals), 0.5 * (np.nan_to_num(normals) + 1.0), 1.0)


def stereo_figure(title: str, results: Mapping[str, object], true_normals: np.ndarray | None,
                  evaluated: np.ndarray, profiles: Mapping[str, np.ndarray] | None = None) -> Figure:
    """One row per method (:class:`gonio.vision.StereoResult`): the recovered normals as
    colours, the angular error against the truth (when known) and the 95 % cone; below,
    the heights integrated along the middle row against the true ones (the paper's
    Fig 27).

    Parameters
    ----------
    title : str
        What was recovered.
    results : mapping of str to StereoResult
        The recoveries by name (e.g. Lambert's and the model's).
    true_normals : numpy.ndarray, shape (H, W, 3), or None
        The shape's true normals.
    evaluated : numpy.ndarray of bool, shape (H, W)
        The pixels whose errors are shown and averaged (lit by enough sources).
    profiles : mapping of str to numpy.ndarray, optional
        Heights along the middle row by name (``"true"`` among them) [radius].
    """
    columns = 3 if true_normals is not None else 2
    rows = len(results) + (1 if profiles else 0)
    fig = Figure(figsize=(3.4 * columns, 3.0 * rows + 0.5))
    axes = fig.subplots(rows, columns, squeeze=False)
    errors = {name: np.where(evaluated, np.degrees(np.arccos(np.clip(np.sum(r.normals * true_normals, axis=-1),
                                                                      -1, 1))), np.nan)
              for name, r in results.items()} if true_normals is not None else {}
    top = max((float(np.nanpercentile(e, 99)) for e in errors.values()), default=1.0)
    for k, (name, result) in enumerate(results.items()):
        axes[k, 0].imshow(_normal_colours(result.normals))
        axes[k, 0].set_title(f"{name}: normals (x, y, z as R, G, B)", fontsize=8)
        column = 1
        if name in errors:
            shown = axes[k, 1].imshow(errors[name], cmap="magma", vmin=0.0, vmax=top)
            axes[k, 1].set_title(f"{name}: angular error, mean {np.nanmean(errors[name]):.2f} deg", fontsize=8)
            fig.colorbar(shown, ax=axes[k, 1], fraction=0.046, pad=0.02, label="[deg]")
            column = 2
        cone = np.where(result.determined, result.cone_deg(), np.nan)
        shown = axes[k, column].imshow(cone, cmap="viridis")
        axes[k, column].set_title(f"{name}: 95 % cone half-angle\n(white: normal not determined)", fontsize=8)
        fig.colorbar(shown, ax=axes[k, column], fraction=0.046, pad=0.02, label="[deg]")
        for ax in axes[k]:
            ax.set_axis_off()
    if profiles:
        _profile_panel(fig, axes[-1], profiles)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _profile_panel(fig: Figure, axes: np.ndarray, profiles: Mapping[str, np.ndarray]) -> None:
    """Heights along the middle row over the whole bottom row of axes (Fig 27)."""
    for ax in axes:
        ax.remove()
    ax = fig.add_subplot(axes[0].get_subplotspec().get_gridspec()[-1, :])
    for name, heights in profiles.items():
        x = np.linspace(-1.0, 1.0, len(heights))
        ax.plot(x, heights, "k-" if name == "true" else "--", label=name, linewidth=1.8 if name == "true" else 1.2)
    ax.set_xlabel("position across the shape [radius]", fontsize=8)
    ax.set_ylabel("height from the centre [radius]", fontsize=8)
    ax.set_title("heights integrated along the middle row (Fig 27)", fontsize=8)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
