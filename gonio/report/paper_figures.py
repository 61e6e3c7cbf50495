"""The model figures of Oren & Nayar (1995), Figs 10-14, redrawn from gonio's models.

Each figure is described as data (:data:`PAPER_FIGURES`): panels, and in each panel the
curves as (model name, parameters, label).  :func:`write_paper_figures` draws them all.
The geometries and parameters are those of the figure captions of the paper:

* Fig 10: plane of incidence, sigma = 30 deg, rho = 0.9, theta_i = 75 deg; total radiance
  and the radiance due to direct illumination only (no interreflection).
* Fig 11: effect of roughness, theta_i = 75 deg, rho = 0.9, sigma = 0, 10, 20, 40 deg.
* Fig 12: sigma = 40 deg, rho = 0.9: (a) BRDF in the plane of incidence for several
  incidence angles, (b) radiance outside the plane of incidence.
* Fig 13: numerical evaluation (eq 31) against the functional approximation (eq 33-35),
  sigma = 30 deg, rho = 0.9, several incidence angles.
* Fig 14: numerical evaluation against the qualitative model (eq 36), sigma = 30 deg,
  rho = 0.9, theta_i = 75 deg: (a) in the plane of incidence, (b) outside it.

Where the paper's curve is the numerical evaluation of eq 31, gonio draws
``oren-nayar-numerical``, which is that evaluation.
"""
from __future__ import annotations

import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from matplotlib.figure import Figure

from .model_plots import slice_values

__all__ = ["Curve", "Panel", "PaperFigure", "PAPER_FIGURES", "draw_paper_figure", "write_paper_figures"]


@dataclass(frozen=True)
class Curve:
    """One line: a registered model with parameters at one incidence angle."""

    model: str
    params: dict
    theta_i: float
    label: str
    style: str = "-"
    width: float = 1.8
    plane: str | float | None = None  # overrides the panel's plane for this curve


@dataclass(frozen=True)
class Panel:
    """One axes: curves along one plane ('in', 'perp' or an azimuth difference [deg])."""

    title: str
    plane: str | float
    quantity: str
    curves: tuple[Curve, ...]


@dataclass(frozen=True)
class PaperFigure:
    """A figure of the paper: file stem, caption, panels."""

    stem: str
    caption: str
    panels: tuple[Panel, ...] = field(default_factory=tuple)


_PLASTER = {"rho": 0.9, "sigma": 30.0}
_NUMERICAL = "oren-nayar-numerical"


def _fig10() -> PaperFigure:
    total = Curve(_NUMERICAL, _PLASTER, 75.0, "total (direct + interreflection), eq 31", "-", 2.4)
    direct = Curve(_NUMERICAL, {**_PLASTER, "interreflection": False}, 75.0, "direct illumination only", "-", 1.0)
    return PaperFigure(
        "fig10_plane_of_incidence",
        "Fig 10: radiance in the plane of incidence, sigma = 30 deg, rho = 0.9, theta_i = 75 deg",
        (Panel("plane of incidence, theta_i = 75 deg", "in", "radiance", (total, direct)),),
    )


def _fig11() -> PaperFigure:
    curves = tuple(
        Curve(_NUMERICAL, {"rho": 0.9, "sigma": s}, 75.0, f"sigma = {s:g} deg" + (" (Lambertian)" if s == 0 else ""))
        for s in (0.0, 10.0, 20.0, 40.0)
    )
    return PaperFigure(
        "fig11_roughness",
        "Fig 11: effect of roughness on radiance, theta_i = 75 deg, rho = 0.9",
        (Panel("plane of incidence, theta_i = 75 deg", "in", "radiance", curves),),
    )


def _fig12() -> PaperFigure:
    rough = {"rho": 0.9, "sigma": 40.0}
    brdf = tuple(Curve(_NUMERICAL, rough, t, f"theta_i = {t:g} deg") for t in (0.0, 30.0, 60.0, 75.0))
    off = tuple(
        Curve(_NUMERICAL, rough, 75.0, f"phi_r - phi_i = {p:g} deg", plane=p) for p in (0.0, 45.0, 90.0)
    )
    return PaperFigure(
        "fig12_incidence_and_azimuth",
        "Fig 12: sigma = 40 deg, rho = 0.9: (a) BRDF for several incidence angles, (b) radiance outside the plane of incidence",
        (
            Panel("(a) BRDF, plane of incidence", "in", "brdf", brdf),
            Panel("(b) radiance, theta_i = 75 deg, by azimuth", 0.0, "radiance", off),
        ),
    )


def _comparison(stem: str, caption: str, approximation: str, params: dict, panels_spec) -> PaperFigure:
    panels = []
    for title, plane, thetas in panels_spec:
        curves = []
        for k, t in enumerate(thetas):
            curves.append(Curve(_NUMERICAL, _PLASTER, t, f"numerical eq 31, theta_i = {t:g} deg", "-", 2.6))
            curves.append(Curve(approximation, params, t, f"{approximation}, theta_i = {t:g} deg", "--", 1.2))
        panels.append(Panel(title, plane, "radiance", tuple(curves)))
    return PaperFigure(stem, caption, tuple(panels))


def _fig13() -> PaperFigure:
    return _comparison(
        "fig13_functional_approximation",
        "Fig 13: numerical evaluation (thick) vs functional approximation (thin), sigma = 30 deg, rho = 0.9",
        "oren-nayar",
        _PLASTER,
        [("plane of incidence", "in", (30.0, 60.0, 75.0))],
    )


def _fig14() -> PaperFigure:
    return _comparison(
        "fig14_qualitative_model",
        "Fig 14: numerical evaluation (thick) vs qualitative model (thin), sigma = 30 deg, rho = 0.9, theta_i = 75 deg",
        "oren-nayar-qualitative",
        _PLASTER,
        [("(a) plane of incidence", "in", (75.0,)), ("(b) phi_r - phi_i = 45 deg", 45.0, (75.0,))],
    )


#: The figures, in the paper's order.
PAPER_FIGURES: tuple[Callable[[], PaperFigure], ...] = (_fig10, _fig11, _fig12, _fig13, _fig14)

_YLABEL = {
    "radiance": "radiance L_r for E_0 = 1 [W m$^{-2}$ sr$^{-1}$]",
    "brdf": "BRDF f_r [sr$^{-1}$]",
}


def draw_paper_figure(figure: PaperFigure) -> Figure:
    """Draw one :class:`PaperFigure` and return the matplotlib Figure."""
    fig = Figure(figsize=(5.6 * len(figure.panels), 4.4), layout="constrained")
    axes = fig.subplots(1, len(figure.panels), squeeze=False)[0]
    for ax, panel in zip(axes, figure.panels):
        for k, curve in enumerate(panel.curves):
            plane = panel.plane if curve.plane is None else curve.plane
            x, y = slice_values(curve.model, curve.params, curve.theta_i, plane, panel.quantity)
            color = f"C{k // 2}" if any(c.style == "--" for c in panel.curves) else f"C{k}"
            ax.plot(x, y, curve.style, lw=curve.width, color=color, label=curve.label)
        if panel.plane == "in":
            ax.set_xlabel("signed viewing angle theta_r [deg] (+ source side)")
        else:
            ax.set_xlabel("viewing angle theta_r [deg]")
        ax.set_ylabel(_YLABEL[panel.quantity])
        ax.set_ylim(bottom=0.0)
        ax.set_title(panel.title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    fig.suptitle("\n".join(textwrap.wrap(figure.caption, width=int(70 * len(figure.panels)))), fontsize="medium")
    return fig


def write_paper_figures(out: str | Path, progress: Callable[[str], None] | None = None) -> list[Path]:
    """Draw Figs 10-14 of Oren & Nayar (1995) as PNG files into ``out``.

    Parameters
    ----------
    out : path
        Output folder (created).
    progress : callable, optional
        Called with one line of text per figure written.

    Returns
    -------
    list of pathlib.Path
        The PNG files, in figure order.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for make in PAPER_FIGURES:
        figure = make()
        path = out / f"{figure.stem}.png"
        draw_paper_figure(figure).savefig(path, dpi=110)
        paths.append(path)
        if progress:
            progress(f"wrote {path}  ({figure.caption})")
    return paths
