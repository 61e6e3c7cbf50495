"""Figures of a fit result (matplotlib Figure API only, no pyplot state).

Each function takes a :class:`gonio.fitting.FitResult` and returns a
:class:`matplotlib.figure.Figure`:

* :func:`geometry_figure` - what was measured: source and viewing directions on the
  hemisphere (polar plot: radius theta [deg], angle phi [deg]); drawn from the dataset
  alone by :func:`measurement_geometry_figure`;
* :func:`data_figure` - data with error bars and the posterior predictive band (median,
  68 % and 95 %), one panel per incidence in the plane it was measured in: in-plane data
  against the signed viewing angle (positive on the source side, DESIGN.md), off-plane
  data against theta_r with one series per azimuth difference (an incidence measured in
  both gets two adjacent panels);
* :func:`residual_figure` - normalised residuals (data - model) / sigma per incidence, and
  measured against model;
* :func:`corner_figure` - one- and two-dimensional marginals of the posterior;
* :func:`trace_figure` - walker traces with the burn-in shaded, and the log posterior.

A figure's cost does not grow with the number of incidences or walkers: points are drawn
as one scatter collection per kind (coloured per point), walker traces as one line
collection per panel (at most MAX_TRACE_WALKERS walkers and MAX_TRACE_POINTS steps), the
model bands of every data panel come from one set of posterior draws, and the axes sit
on fixed margins instead of a layout engine's extra drawing pass
(benchmarks/bench_report.py measures it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize, to_rgba_array
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from gonio.fitting.dataset import QUANTITY_LABELS, Dataset
from gonio.fitting.results import FitResult
from gonio.geometry import azimuth_difference, in_plane_angles

__all__ = [
    "geometry_figure", "measurement_geometry_figure", "data_figure", "residual_figure", "corner_figure",
    "trace_figure",
    "MAX_INCIDENCE_PANELS", "MAX_AZIMUTH_SERIES", "MAX_LEGEND_INCIDENCES", "DENSE_POINTS",
    "MAX_TRACE_POINTS", "MAX_TRACE_WALKERS",
]

@dataclass(frozen=True)
class _Margins:
    """Fixed margins and gaps of a figure's grid of axes [in].

    A fixed layout costs nothing to compute, where matplotlib's constrained layout draws
    the whole figure once more, without rendering, to measure every tick label (a third to
    a half of a report figure's time).

    Attributes
    ----------
    left, right, top, bottom : float
        Space between the grid and the figure's edges [in]: tick labels and an axis
        label, titles, legends and colour bars placed outside the grid.
    gap_x, gap_y : float
        Space between neighbouring axes across columns and across rows [in].
    """

    left: float
    right: float
    top: float
    bottom: float
    gap_x: float = 0.0
    gap_y: float = 0.0


#: At most this many incidences are drawn in the data figure (evenly chosen): every
#: incidence of the shipped protocols (at most 5 in one recording), a sample of image-based
#: data (CUReT, one incidence per value), where a panel holds a value or two and costs
#: about 50 ms to draw (12 panels made most of a 10,000-point report's 2 s).
MAX_INCIDENCE_PANELS = 8
#: At most this many azimuth differences get a series of their own in an off-plane panel
#: (those with the most measurements); the legend says how many were left out.
MAX_AZIMUTH_SERIES = 6
#: With more incidences than this, the geometry and residual figures colour the points by
#: the source's polar angle (one colour bar) instead of one colour and legend entry each.
MAX_LEGEND_INCIDENCES = 10
#: With at most this many incidences the residual figure draws one panel per incidence.
MAX_RESIDUAL_PANELS = 6
#: Scatter plots with more points than this draw smaller markers without edges.
DENSE_POINTS = 1000
#: Steps drawn per walker in the trace figure at most (more than the axes have pixel
#: columns; longer chains are drawn every k-th step).
MAX_TRACE_POINTS = 1000
#: Ticks of the data panels: a panel's cost is mostly its axes' ticks and their labels
#: (about 2 ms each to make and draw), so a few well-placed ones [deg], and at most this
#: many intervals on the value axis (none at the right edge, where the next panel's first
#: label would touch it).
_IN_PLANE_TICKS = (-60, -30, 0, 30, 60)
_POLAR_TICKS = (0, 15, 30, 45, 60, 75)
_PANEL_Y_BINS = 5
#: At most this many tick intervals on the axes of the corner plot and the traces.
_CORNER_BINS = 4
#: Walkers drawn in the trace figure at most (:func:`_shown_walkers` picks them).
MAX_TRACE_WALKERS = 32
_LOWEST_WALKERS = 4
_BAND_POINTS = 121
# Gap between a panel and its title [pt]: titles are placed at a fixed height (matplotlib's
# automatic placement measures every tick label of the panel once more).
_TITLE_PAD_PT = 6.0
_THETA_CMAP = matplotlib.colormaps["viridis"]
# Width and height of one panel of the data figure [in].
_PANEL_SIZE_IN = (4.4, 3.2)
# Margins of the data figure's panel grid [in]: left (tick labels and axis label), right,
# top (panel title), bottom (tick labels, axis label and the figure legend).
_GRID_MARGINS_IN = (0.85, 0.15, 0.35, 1.0)
# Gaps between panels [in]: across columns sharing the vertical axis, across columns with
# their own tick labels, and between rows (tick labels, axis label and the next title).
_GRID_GAPS_IN = (0.2, 0.65, 0.95)
# Fixed margins of the other figures [in] (_Margins): the geometry figure's two-line title
# above and legend below the polar plot; the residual figure's axis labels and title;
# the corner plot's rotated tick labels, axis labels, suptitle and the titles of its
# diagonal panels; the traces' axis labels and two-line suptitle.
_GEOMETRY_MARGINS = _Margins(left=0.55, right=0.55, top=0.8, bottom=1.15)
_RESIDUAL_MARGINS = _Margins(left=0.8, right=0.2, top=0.5, bottom=0.6, gap_x=0.12, gap_y=0.85)
_CORNER_MARGINS = _Margins(left=0.95, right=0.15, top=0.6, bottom=1.0, gap_x=0.12, gap_y=0.3)
_TRACE_MARGINS = _Margins(left=1.05, right=0.2, top=0.65, bottom=0.55, gap_y=0.15)
# The data figure's panels share one vertical axis when the data of every panel span at
# least this fraction of the common range (no panel is flattened to a line).
_SHARED_Y_MIN_FRACTION = 0.25


def _param_label(result: FitResult, name: str) -> str:
    unit = result.specs[name].unit
    return f"{name} [{unit}]" if unit not in ("-", "") else f"{name} [-]"


def _incidence_groups(result: FitResult) -> tuple[np.ndarray, np.ndarray, list[int]]:
    sources, index = result.dataset.incidences()
    shown = list(range(len(sources)))
    if len(shown) > MAX_INCIDENCE_PANELS:
        shown = sorted(set(np.linspace(0, len(sources) - 1, MAX_INCIDENCE_PANELS).round().astype(int).tolist()))
    return sources, index, shown


def _marker_area(n_points: int, area: float) -> float:
    """Marker area [pt^2] for a scatter of ``n_points``: ``area`` up to
    DENSE_POINTS, then shrinking like 1/n (so the ink stays about constant), at least 2."""
    if n_points <= DENSE_POINTS:
        return area
    return max(area * DENSE_POINTS / n_points, 2.0)


def _by_incidence(sources: np.ndarray) -> bool:
    """Whether each incidence gets a colour and a legend entry of its own."""
    return len(sources) <= MAX_LEGEND_INCIDENCES


def _incidence_colours(sources: np.ndarray, index: np.ndarray) -> np.ndarray:
    """RGBA colour of each measurement (shape (n, 4)): its incidence's colour of the cycle
    (C0, C1, ...) with few incidences, else the source's polar angle on :data:`_THETA_CMAP`
    (0 to 90 deg; :func:`_theta_colourbar` explains it)."""
    if _by_incidence(sources):
        palette = to_rgba_array([f"C{k % 10}" for k in range(len(sources))])
        return palette[index]
    return _THETA_CMAP(sources[index, 0] / 90.0)


def _theta_colourbar(fig: Figure, ax: Axes) -> None:
    """Colour bar of :func:`_incidence_colours` with many incidences."""
    mappable = ScalarMappable(norm=Normalize(0.0, 90.0), cmap=_THETA_CMAP)
    bar = fig.colorbar(mappable, ax=ax, shrink=0.7, pad=0.02)
    bar.set_label("source polar angle theta_i [deg]", fontsize=8)
    bar.ax.tick_params(labelsize=8)


def _view_sizes(data: Dataset, index: np.ndarray, n_sources: int) -> np.ndarray:
    """Marker area [pt^2] of each view of the geometry figure: with few incidences, rings
    whose diameter shrinks by 3 pt with the incidence's rank (coincident views of every
    incidence stay visible as concentric rings), else one size for all."""
    if n_sources > MAX_LEGEND_INCIDENCES:
        return np.full(data.n, _marker_area(data.n, 30.0))
    # rings 3 pt apart in diameter: a view measured at every incidence shows every ring
    return (4.0 + 3.0 * (n_sources - 1 - np.asarray(index, float))) ** 2


def geometry_figure(result: FitResult) -> Figure:
    """Polar plot of the measured viewing directions, coloured by incidence, with the
    sources: :func:`measurement_geometry_figure` of the fit's dataset."""
    return measurement_geometry_figure(result.dataset)


def measurement_geometry_figure(data: Dataset) -> Figure:
    """Polar plot of the measured viewing directions, coloured by incidence, with the sources.

    Two scatter collections (views, sources), whatever the number of incidences: with at
    most MAX_LEGEND_INCIDENCES each incidence has its colour and legend entry, beyond that
    views and sources are coloured by the source's polar angle (colour bar). It needs the
    measurements alone, so ``gonio fit --report`` draws it while the fit runs.
    """
    sources, index = data.incidences()
    fig, grid = _fixed_grid(6.0, 6.6, 1, 1, _GEOMETRY_MARGINS)
    ax = fig.add_subplot(grid[0, 0], projection="polar")
    colours = _incidence_colours(sources, index)
    sizes = _view_sizes(data, index, len(sources))
    # Drawn by incidence (stable): later incidences, with smaller markers, on top.
    order = np.argsort(index, kind="stable")
    if _by_incidence(sources):  # hollow rings, one size per incidence: coincident views all show
        ax.scatter(np.radians(data.phi_r[order]), data.theta_r[order], s=sizes[order], facecolors="none",
                   edgecolors=colours[order], linewidths=1.3)
    else:
        ax.scatter(np.radians(data.phi_r[order]), data.theta_r[order], s=sizes[order], c=colours[order],
                   edgecolors="white", linewidths=0.5 if data.n <= DENSE_POINTS else 0.0)
    source_colours = _incidence_colours(sources, np.arange(len(sources)))
    star = 220.0 if _by_incidence(sources) else max(_marker_area(len(sources), 120.0), 8.0)
    ax.scatter(np.radians(sources[:, 1]), sources[:, 0], marker="*", s=star, c=source_colours, edgecolors="k",
               linewidths=0.7 if len(sources) <= DENSE_POINTS else 0.3, zorder=5)
    handles = []
    if _by_incidence(sources):
        handles = [Line2D([], [], ls="none", marker="o", ms=min(math.sqrt(size), 9.0), mfc="none", mec=colour, mew=1.3,
                          label=f"views, theta_i = {theta_i:g} deg, phi_i = {phi_i:g} deg")
                   for (theta_i, phi_i), colour, size in zip(sources, source_colours, _view_sizes(
                       data, np.arange(len(sources)), len(sources)))]
    else:
        _theta_colourbar(fig, ax)
        handles.append(Line2D([], [], ls="none", marker="o", ms=5, color="0.6", mec="white", mew=0.5,
                              label="views (colour: their source's theta_i)"))
    handles.append(Line2D([], [], ls="none", marker="*", ms=math.sqrt(120.0), color="0.6", mec="k", mew=0.7,
                          label="source directions"))
    ax.set_ylim(0, 90)
    ax.set_yticks([30, 60, 90])
    ax.set_yticklabels(["30 deg", "60 deg", "90 deg"])
    ax.set_rlabel_position(112)
    fig.suptitle(f"Measurement geometry: {data.n} measurements, {len(sources)} incidences\n"
                 "radius: polar angle theta [deg], angle: azimuth phi [deg]", fontsize=10)
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.06), fontsize=7.5, frameon=False, ncol=2,
              columnspacing=0.8, handletextpad=0.3)
    return fig


def _band_axes(ax: Axes, x: np.ndarray, band: np.ndarray, colour: str) -> None:
    """Draw the 95 % and 68 % bands and the median of ``band`` (rows: 2.5, 16, 50, 84, 97.5 %)."""
    ax.fill_between(x, band[0], band[4], color=colour, alpha=0.15, lw=0)
    ax.fill_between(x, band[1], band[3], color=colour, alpha=0.3, lw=0)
    ax.plot(x, band[2], color=colour, lw=1.6)


def _span(x: np.ndarray, lo: float, hi: float) -> tuple[float, float]:
    """Range of the model band: the data's range plus 5 deg, within [lo, hi]."""
    if x.size == 0:
        return lo, hi
    return max(float(x.min()) - 5.0, lo), min(float(x.max()) + 5.0, hi)


def _data_range(value: np.ndarray, sigma: np.ndarray) -> tuple[float, float]:
    """Vertical range from the data (the model may diverge outside them, e.g. Minnaert).

    The range starts at zero when the data come close to it, so that nearly flat data
    are not drawn as a strong trend.
    """
    low, high = float(np.min(value - sigma)), float(np.max(value + sigma))
    margin = 0.12 * (high - low) if high > low else 0.1 * max(abs(high), 1e-12)
    bottom = min(low - margin, 0.0) if 0.0 <= low < 0.25 * high else low - margin
    return bottom, high + margin


@dataclass(frozen=True, eq=False)
class _Panel:
    """One panel of the data figure: the measurements of one incidence in one plane.

    Attributes
    ----------
    theta_i, phi_i : float
        Source polar angle and azimuth [deg].
    in_plane : bool
        True for the plane of incidence (x = signed viewing angle), False for off-plane
        sweeps (x = theta_r, one series per azimuth difference).
    selection : numpy.ndarray of bool
        The dataset's measurements drawn in the panel.
    title : str
        The incidence, and the plane when the incidence has panels in both.
    """

    theta_i: float
    phi_i: float
    in_plane: bool
    selection: np.ndarray
    title: str


def _incidence_label(theta_i: float, phi_i: float, with_azimuth: bool) -> str:
    """Panel title of an incidence, e.g. ``'theta_i = 45 deg, phi_i = 0 deg'``."""
    label = f"theta_i = {theta_i:.4g} deg"
    return label + (f", phi_i = {phi_i + 0.0:.4g} deg" if with_azimuth else "")  # + 0.0: no "-0"


def _incidence_panels(data: Dataset, mask: np.ndarray, source: np.ndarray, label: str) -> list[_Panel]:
    """The one or two panels of one incidence, each in the plane its data were measured in.

    Parameters
    ----------
    data : Dataset
        The fitted measurements.
    mask : numpy.ndarray of bool
        The measurements of this incidence.
    source : numpy.ndarray
        (theta_i, phi_i) [deg] of the incidence.
    label : str
        The incidence's title (:func:`_incidence_label`).

    Returns
    -------
    list of _Panel
        An in-plane panel when the incidence has in-plane views other than the normal
        view (or nothing else), an off-plane panel when it has off-plane views; an
        incidence with both gets both, in-plane first. The normal view (theta_r = 0) lies
        on every azimuth: it is drawn in the in-plane panel when there is one, else as the
        start of the off-plane sweep.
    """
    theta_i, phi_i = (float(angle) for angle in source)
    in_plane_views = mask & data.in_plane
    off_plane_views = mask & ~data.in_plane
    beside_normal = in_plane_views & (data.theta_r != 0.0)
    draw_in_plane = bool(np.any(beside_normal)) or not np.any(off_plane_views)
    draw_off_plane = bool(np.any(off_plane_views))
    both = draw_in_plane and draw_off_plane
    panels = []
    if draw_in_plane:
        panels.append(_Panel(theta_i, phi_i, True, in_plane_views,
                             f"{label}, in plane" if both else label))
    if draw_off_plane:
        off_plane_selection = off_plane_views if draw_in_plane else mask
        panels.append(_Panel(theta_i, phi_i, False, off_plane_selection,
                             f"{label}, out of plane" if both else label))
    return panels


def _data_panels(result: FitResult) -> list[list[_Panel]]:
    """The panels of the data figure, grouped by incidence (at most MAX_INCIDENCE_PANELS)."""
    data = result.dataset
    sources, index, shown = _incidence_groups(result)
    several_azimuths = len({round(float(p), 6) for p in sources[:, 1]}) > 1
    return [
        _incidence_panels(data, index == k, sources[k], _incidence_label(*sources[k], several_azimuths))
        for k in shown
    ]


def _grid_columns(n_panels: int) -> int:
    """Columns of the panel grid: one row up to three panels, then 2, 3 or 4 columns."""
    if n_panels <= 3:
        return max(n_panels, 1)
    if n_panels == 4:
        return 2
    return 3 if n_panels <= 9 else 4


def _grid_positions(group_sizes: list[int], columns: int) -> list[tuple[int, int]]:
    """(row, column) of every panel, row by row; an incidence's panels stay on one row."""
    positions = []
    row, column = 0, 0
    for size in group_sizes:
        if column + size > columns:
            row, column = row + 1, 0
        positions.extend((row, column + j) for j in range(size))
        column += size
    return positions


def _shared_ylim(data: Dataset, panels: list[_Panel]) -> tuple[float, float] | None:
    """Common vertical range of all panels, or None when one would be flattened by it."""
    low = [float(np.min(data.value[p.selection] - data.sigma[p.selection])) for p in panels]
    high = [float(np.max(data.value[p.selection] + data.sigma[p.selection])) for p in panels]
    common = max(high) - min(low)
    if common <= 0.0 or min(h - lo for lo, h in zip(low, high)) < _SHARED_Y_MIN_FRACTION * common:
        return None
    selection = np.logical_or.reduce([p.selection for p in panels])
    return _data_range(data.value[selection], data.sigma[selection])


@dataclass(frozen=True, eq=False)
class _Series:
    """One model band of a data panel and the measurements drawn with it.

    Attributes
    ----------
    x : numpy.ndarray
        Abscissa of the band [deg] (signed viewing angle in plane, theta_r off plane).
    geometry : tuple of numpy.ndarray
        (theta_i, phi_i, theta_r, phi_r) [deg] of the band's points, each shaped like ``x``.
    picked : numpy.ndarray of int
        Indices of the dataset's measurements drawn with the band.
    colour : str
        Colour of the band and of the measurements' markers.
    label : str or None
        Legend entry (off-plane series), None in plane.
    """

    x: np.ndarray
    geometry: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    picked: np.ndarray
    colour: str
    label: str | None


def _in_plane_series(data: Dataset, panel: _Panel) -> list[_Series]:
    """The band of an in-plane panel: against the signed viewing angle (+ source side)."""
    picked = np.flatnonzero(panel.selection)
    x = np.linspace(*_span(data.signed_view[picked], -89.0, 89.0), _BAND_POINTS)
    geometry = tuple(np.broadcast_arrays(*in_plane_angles(panel.theta_i, x, panel.phi_i)))
    return [_Series(x, geometry, picked, "C0", None)]


def _draw_in_plane_panel(ax: Axes, data: Dataset, panel: _Panel, series: _Series, band: np.ndarray) -> None:
    """In-plane data and model band against the signed viewing angle (+ source side)."""
    _band_axes(ax, series.x, band, series.colour)
    pick = series.picked
    ax.errorbar(data.signed_view[pick], data.value[pick], data.sigma[pick], fmt="o", ms=4, color="k",
                capsize=2, lw=1)
    ax.axvline(panel.theta_i, color="0.6", ls=":", lw=1)
    ax.set_xlim(-90, 90)
    ax.set_xticks(_IN_PLANE_TICKS)
    ax.set_xlabel("signed viewing angle theta_r [deg] (+ source side)")


def _azimuth_series(data: Dataset, selection: np.ndarray) -> tuple[list[float], np.ndarray, int]:
    """The azimuth differences drawn in an off-plane panel and the series of each point.

    Returns
    -------
    offsets : list of float
        Rounded azimuth differences phi_r - phi_i [deg] that get a series, ascending (at
        most MAX_AZIMUTH_SERIES: those with the most measurements).
    series : numpy.ndarray of int
        For each selected measurement, its position in ``offsets``, or -1 when its series
        is not drawn. Normal views (theta_r = 0, no azimuth) join the nearest series.
    n_offsets : int
        Number of distinct azimuth differences of the off-plane views.
    """
    difference = data.azimuth_difference[selection]
    rounded = np.round(difference)
    off_plane = ~data.in_plane[selection]
    distinct, counts = np.unique(rounded[off_plane], return_counts=True)
    busiest = np.argsort(-counts, kind="stable")[:MAX_AZIMUTH_SERIES]
    offsets = sorted(float(distinct[j]) for j in busiest)
    series = np.full(difference.shape, -1)
    for j, offset in enumerate(offsets):
        series[off_plane & (rounded == offset)] = j
    # The model does not depend on the azimuth at theta_r = 0: any series may hold it.
    distance = np.abs(azimuth_difference(np.asarray(offsets)[None, :], difference[:, None]))
    series[~off_plane] = np.argmin(distance[~off_plane], axis=1)
    return offsets, series, len(distinct)


def _off_plane_series(data: Dataset, panel: _Panel) -> tuple[list[_Series], int]:
    """The bands of an off-plane panel, one per azimuth difference (:func:`_azimuth_series`),
    and the number of distinct azimuth differences measured."""
    offsets, series, n_offsets = _azimuth_series(data, panel.selection)
    picked = np.flatnonzero(panel.selection)
    out = []
    for j, offset in enumerate(offsets):
        pick = picked[series == j]
        x = np.linspace(*_span(data.theta_r[pick], 0.0, 89.0), _BAND_POINTS)
        geometry = tuple(np.broadcast_arrays(panel.theta_i, panel.phi_i, x, panel.phi_i + offset))
        out.append(_Series(x, geometry, pick, f"C{(j + 1) % 10}", f"phi_r - phi_i = {offset:g} deg"))
    return out, n_offsets


def _draw_off_plane_panel(ax: Axes, data: Dataset, series: list[_Series], bands: list[np.ndarray],
                          n_offsets: int) -> None:
    """Off-plane data and model bands against theta_r, one colour per azimuth difference."""
    for one, band in zip(series, bands):
        _band_axes(ax, one.x, band, one.colour)
        pick = one.picked
        ax.errorbar(data.theta_r[pick], data.value[pick], data.sigma[pick], fmt="o", ms=4, color=one.colour,
                    mec="k", mew=0.5, capsize=2, lw=1, label=one.label)
    ax.set_xlim(0, 90)
    ax.set_xticks(_POLAR_TICKS)
    ax.set_xlabel("viewing angle theta_r [deg]")
    if len(series) == 1 and n_offsets == 1:
        # one azimuth: said on the plot, without a legend (which costs as much to draw as
        # the rest of the panel: image data of many incidences has one azimuth each)
        ax.text(0.98, 0.97, series[0].label, transform=ax.transAxes, ha="right", va="top", fontsize=7.5)
        return
    omitted = f"{len(series)} of {n_offsets} azimuths" if n_offsets > len(series) else None
    ax.legend(fontsize=7.5, title=omitted, title_fontsize=7.5)


def _series_bands(result: FitResult, series: list[_Series], n_draws: int) -> list[np.ndarray]:
    """The posterior predictive band of every series, from one evaluation of the model per
    posterior draw on all their points together (the draws are the same for every band)."""
    if not series:
        return []
    geometry = [np.concatenate([one.geometry[k] for one in series]) for k in range(4)]
    bands = result.posterior_predictive(*geometry, n_draws=n_draws)
    ends = np.cumsum([one.x.size for one in series])[:-1]
    return np.split(bands, ends, axis=1)


def _band_legend(fig: Figure, band_name: str, with_source: bool, columns: int) -> None:
    """Figure legend of what every panel shows: bands, median, measurements, source."""
    handles = [
        Patch(color="0.35", alpha=0.15, lw=0, label="95 % band"),
        Patch(color="0.35", alpha=0.3, lw=0, label="68 % band"),
        Line2D([], [], color="0.35", lw=1.6, label="posterior median"),
        Line2D([], [], color="k", marker="o", ms=4, ls="none", label="measured +/- 1 sigma"),
    ]
    if with_source:
        handles.append(Line2D([], [], color="0.6", ls=":", lw=1, label="source direction (in plane)"))
    fig.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.5, 0.0), ncol=len(handles) if columns > 1 else 3,
               fontsize=8, title=band_name, title_fontsize=8, frameon=False)


def _fixed_grid(width: float, height: float, rows: int, columns: int, margins: _Margins, **grid_kw):
    """A figure of ``width`` x ``height`` [in] and its grid of axes with fixed ``margins``.

    Returns
    -------
    fig : matplotlib.figure.Figure
    grid : matplotlib.gridspec.GridSpec
    """
    axes_width = (width - margins.left - margins.right - (columns - 1) * margins.gap_x) / columns
    axes_height = (height - margins.top - margins.bottom - (rows - 1) * margins.gap_y) / rows
    fig = Figure(figsize=(width, height))
    grid = fig.add_gridspec(rows, columns, left=margins.left / width, right=1.0 - margins.right / width,
                            bottom=margins.bottom / height, top=1.0 - margins.top / height,
                            wspace=margins.gap_x / axes_width, hspace=margins.gap_y / axes_height, **grid_kw)
    return fig, grid


def _panel_grid(rows: int, columns: int, shared_y: bool, with_suptitle: bool):
    """The data figure and its grid of panels (:func:`_fixed_grid`).

    The margins hold one line of tick labels and an axis label on each side, a one-line
    panel title, the figure legend below and the optional suptitle above; inner columns
    keep room for tick labels unless the panels share the vertical axis.
    """
    width, height = _PANEL_SIZE_IN
    left, right, top, bottom = _GRID_MARGINS_IN
    gap_x = _GRID_GAPS_IN[0] if shared_y else _GRID_GAPS_IN[1]
    margins = _Margins(left, right, top + (0.2 if with_suptitle else 0.0), bottom, gap_x, _GRID_GAPS_IN[2])
    return _fixed_grid(width * columns, height * rows + 0.9, rows, columns, margins)


def data_figure(result: FitResult, n_draws: int = 200) -> Figure:
    """Data with the model band of each incidence, drawn in the plane it was measured in.

    Parameters
    ----------
    result : FitResult
        The fit; its dataset's incidences are drawn (at most MAX_INCIDENCE_PANELS,
        evenly chosen).
    n_draws : int, optional
        Posterior draws behind the bands.

    Returns
    -------
    matplotlib.figure.Figure
        A grid with one panel per incidence: in-plane data against the signed viewing
        angle, off-plane data against theta_r with one series per azimuth difference; an
        incidence measured in both gets two adjacent panels. The panels share the vertical
        axis when their data ranges are comparable.
    """
    data = result.dataset
    groups = _data_panels(result)
    panels = [panel for group in groups for panel in group]
    columns = _grid_columns(len(panels))
    positions = _grid_positions([len(group) for group in groups], columns)
    rows = positions[-1][0] + 1
    shared_ylim = _shared_ylim(data, panels)
    n_incidences = len(data.incidences()[0])
    shown_all = len(groups) == n_incidences
    fig, grid = _panel_grid(rows, columns, shared_ylim is not None, with_suptitle=not shown_all)
    series = [(_in_plane_series(data, panel), 0) if panel.in_plane else _off_plane_series(data, panel)
              for panel in panels]
    bands = iter(_series_bands(result, [one for group, _ in series for one in group], n_draws))
    first = None
    for panel, (row, column), (panel_series, n_offsets) in zip(panels, positions, series):
        ax = fig.add_subplot(grid[row, column], sharey=first if shared_ylim else None)
        if first is None:
            first = ax
        panel_bands = [next(bands) for _ in panel_series]
        if panel.in_plane:
            _draw_in_plane_panel(ax, data, panel, panel_series[0], panel_bands[0])
        else:
            _draw_off_plane_panel(ax, data, panel_series, panel_bands, n_offsets)
        ax.set_ylim(shared_ylim or _data_range(data.value[panel.selection], data.sigma[panel.selection]))
        ax.yaxis.set_major_locator(MaxNLocator(nbins=_PANEL_Y_BINS))
        # y given: no automatic title placement, which measures every tick label again
        ax.set_title(panel.title, fontsize=10, y=1.0, pad=_TITLE_PAD_PT)
        ax.grid(alpha=0.3)
        if column == 0:
            ax.set_ylabel(QUANTITY_LABELS[data.quantity])
        elif shared_ylim:
            ax.tick_params(labelleft=False)
    band_name = "posterior predictive" if result.mcmc is not None else "least-squares model"
    _band_legend(fig, band_name, any(panel.in_plane for panel in panels), columns)
    if not shown_all:
        fig.suptitle(f"{len(groups)} of {n_incidences} incidences shown", fontsize=9, y=1.0 - 0.05 / fig.get_figheight(),
                     va="top")
    return fig


def residual_figure(result: FitResult) -> Figure:
    """How far the model is from every measurement: normalised residuals and measured
    against model.

    Top row: the normalised residuals (data - posterior median model) / sigma against the
    viewing angle, one panel per incidence when there are few (at most
    :data:`MAX_RESIDUAL_PANELS`; a misfit that one incidence shows stands out), else one
    panel coloured by the source's polar angle. sigma is each value's total uncertainty
    under the fit's likelihood: the stated one with the fitted extra noise (``jitter``, or
    ``rel_jitter`` x prediction) in quadrature. Bottom: every measured value against the
    model's, with its error bar and the 1:1 line, and the relative difference on the right
    axis scale in the title. The title's chi-square is the fit's own, with the data's
    covariance where they have one. For an approximate model, red crosses in the top row
    mark ``(exact - approximation) / sigma`` at each value (:func:`_formula_error`): where
    the data sit on the approximation's map of validity (docs/validity.md).
    """
    data = result.dataset
    problem = result.problem()
    values = result.best_values()
    model = problem.predict(values)
    extra = problem.extra_variance(values, model) if problem.jitter else 0.0
    sigma = problem.total_sigma(values, model)
    z = (data.value - model) / sigma
    whitened = problem.whiten(model - data.value, extra)[0]
    noise_label = {None: "sigma", "absolute": "hypot(sigma, jitter)",
                   "relative": "hypot(sigma, rel_jitter x model)"}[problem.jitter]
    x = np.where(data.in_plane, data.signed_view, data.theta_r)
    sources, index = data.incidences()
    panels = len(sources) if 1 < len(sources) <= MAX_RESIDUAL_PANELS else 1
    fig, grid = _fixed_grid(max(7.5, 2.3 * panels + 1.0), 7.6, 2, panels, _RESIDUAL_MARGINS)
    formula = _formula_error(result)
    limit = max(3.5, float(np.nanmax(np.abs(np.concatenate([z, formula])))) * 1.1) if z.size else 3.5
    first = None
    for k in range(panels):
        ax = fig.add_subplot(grid[0, k], sharey=first)
        first = first or ax
        chosen = np.ones(data.n, bool) if panels == 1 else index == k
        _residual_band(ax)
        _residual_points(fig, ax, data, x, z, chosen, legend=panels == 1)
        shown = chosen & np.isfinite(formula)
        if shown.any():
            ax.plot(x[shown], formula[shown], "x", color="tab:red", ms=4, mew=1.0, zorder=4,
                    label=f"(exact - {result.model}) / sigma: the formula's own error")
        ax.set_xlim(-90, 90)
        ax.set_ylim(-limit, limit)
        if panels > 1:
            theta_i, phi_i = sources[k]
            ax.set_title(f"theta_i = {theta_i:g}, phi_i = {phi_i:g} deg", fontsize=8)
            if k:
                ax.tick_params(labelleft=False)
        ax.set_xlabel("theta_r [deg] (signed in plane)" if panels > 1 else
                      "signed viewing angle theta_r [deg] (in plane; + source side)", fontsize=8)
        ax.grid(alpha=0.3)
    first.set_ylabel(f"(data - model) / {noise_label} [-]", fontsize=8)
    if (panels == 1 or np.isfinite(formula).any()) and first.get_legend_handles_labels()[0]:
        first.legend(fontsize=8, ncol=2, loc="upper left")
    _measured_against_model(fig.add_subplot(grid[1, :]), data, model, sigma, index, sources)
    chi2 = float(np.dot(whitened, whitened))
    correlated = " (with the data's covariance)" if data.covariance is not None else ""
    # centred on the figure (the axes sit right of the vertical label): room for the long line
    fig.suptitle(f"Residuals at the posterior median: chi2{correlated} = {chi2:.1f} for {data.n} points",
                 fontsize=10, y=1.0 - 0.08 / fig.get_figheight(), va="top")
    return fig


def _formula_error(result: FitResult) -> np.ndarray:
    """``(exact - approximation) / sigma`` at each value the fit's validity check compared
    (:mod:`gonio.fitting.validity`), NaN elsewhere and for a model that is not an
    approximation: what the exact model would add to each residual."""
    error = np.full(result.dataset.n, np.nan)
    if result.validity is not None:
        error[result.validity.checked] = -np.asarray(result.validity.error_sd, float)
    return error


def _residual_band(ax: Axes) -> None:
    """The 1- and 2-sigma bands and the zero line behind normalised residuals."""
    ax.axhspan(-1, 1, color="0.85", lw=0)
    ax.axhspan(-2, -1, color="0.93", lw=0)
    ax.axhspan(1, 2, color="0.93", lw=0)
    ax.axhline(0, color="0.4", lw=1)


def _measured_against_model(ax: Axes, data: Dataset, model: np.ndarray, sigma: np.ndarray, index: np.ndarray,
                            sources: np.ndarray) -> None:
    """Measured values against the model's at the same geometries, with 1-sigma error bars
    (one collection whatever the number of points) and the 1:1 line; the title gives the
    rms and largest relative difference."""
    colours = _incidence_colours(sources, index)
    ax.errorbar(model, data.value, yerr=sigma, fmt="none", ecolor="0.6", elinewidth=0.8, zorder=1)
    ax.scatter(model, data.value, s=_marker_area(data.n, 16.0), c=colours, zorder=2,
               edgecolors="face", linewidths=0.0 if data.n > DENSE_POINTS else 1.0)
    finite = np.isfinite(model) & np.isfinite(data.value)
    low = float(min(model[finite].min(), data.value[finite].min())) if finite.any() else 0.0
    high = float(max(model[finite].max(), data.value[finite].max())) if finite.any() else 1.0
    ax.plot([low, high], [low, high], color="0.3", lw=1, label="measured = model")
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = (data.value - model) / np.abs(model)
    shown = relative[finite & np.isfinite(relative)]
    spread = (f": rms {100 * np.sqrt(np.mean(shown**2)):.3g} %, largest {100 * np.max(np.abs(shown)):.3g} %"
              if shown.size else "")
    ax.set_title(f"Measured against model{spread} (relative difference)", fontsize=9)
    ax.set_xlabel(f"model (posterior median) [{data.unit}]", fontsize=8)
    ax.set_ylabel(f"measured [{data.unit}]", fontsize=8)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)


def _residual_points(fig: Figure, ax: Axes, data: Dataset, x: np.ndarray, z: np.ndarray,
                     chosen: np.ndarray | None = None, legend: bool = True) -> None:
    """The normalised residuals of the ``chosen`` values as one scatter per plane (circles
    in plane, triangles out of plane), coloured by incidence (:func:`_incidence_colours`),
    with their legend entries (``legend``) or the colour bar."""
    sources, index = data.incidences()
    colours = _incidence_colours(sources, index)
    size = _marker_area(data.n, 16.0)
    chosen = np.ones(data.n, bool) if chosen is None else chosen
    for plane, marker in ((data.in_plane & chosen, "o"), (~data.in_plane & chosen, "^")):
        if plane.any():
            dense = data.n > DENSE_POINTS
            ax.scatter(x[plane], z[plane], s=size, c=colours[plane], marker=marker, edgecolors="face",
                       linewidths=0.0 if dense else 1.0, alpha=0.6 if dense else 1.0)
    if not legend:
        return
    if _by_incidence(sources):
        for k, (theta_i, _) in enumerate(sources):
            ax.plot([], [], "o", ms=4, color=f"C{k % 10}", label=f"theta_i = {theta_i:g} deg")
    else:
        _theta_colourbar(fig, ax)
    if np.any(~data.in_plane):
        ax.plot([], [], "^", color="0.5", label="out of plane (x = theta_r)")


def _credible_levels(hist: np.ndarray, masses=(0.95, 0.68)) -> list[float]:
    flat = np.sort(hist.ravel())[::-1]
    cumulative = np.cumsum(flat) / flat.sum()
    levels = []
    for mass in masses:
        position = min(int(np.searchsorted(cumulative, mass)), flat.size - 1)
        levels.append(float(flat[position]))
    return levels


def corner_figure(result: FitResult, bins: int = 30) -> Figure:
    """Corner plot: 1-D histograms (median and 68 % interval) and 2-D 68/95 % contours."""
    samples = result.samples()
    names = list(result.free)
    n = len(names)
    size = max(2.4 * n, 5.5)
    fig, grid = _fixed_grid(size, size, n, n, _CORNER_MARGINS)
    if samples.shape[0] == 0:
        ax = fig.add_subplot(grid[:, :])
        ax.text(0.5, 0.5, "no posterior samples (fit run without MCMC)", ha="center", va="center")
        ax.set_axis_off()
        return fig
    # the lower triangle only: an axes costs about as much to make as to draw, so the
    # hidden upper triangle is not made at all
    axes = {(i, j): fig.add_subplot(grid[i, j]) for i in range(n) for j in range(i + 1)}
    ranges = []
    for j in range(n):
        lo, hi = np.percentile(samples[:, j], [0.2, 99.8])
        if not hi > lo:
            lo, hi = lo - 0.5 * max(abs(lo), 1e-9), hi + 0.5 * max(abs(hi), 1e-9)
        ranges.append((lo, hi))
    for i in range(n):
        for j in range(i + 1):
            ax = axes[i, j]
            if i == j:
                ax.hist(samples[:, j], bins=bins, range=ranges[j], color="C0", histtype="stepfilled", alpha=0.6)
                q = np.percentile(samples[:, j], [16, 50, 84])
                for value, style in zip(q, (":", "-", ":")):
                    ax.axvline(value, color="k", ls=style, lw=1)
                ax.set_yticks([])
                ax.set_title(f"{names[j]} = {q[1]:.4g} -{q[1] - q[0]:.2g} +{q[2] - q[1]:.2g}", fontsize=9, y=1.0,
                             pad=_TITLE_PAD_PT)
            else:
                hist, xe, ye = np.histogram2d(samples[:, j], samples[:, i], bins=bins, range=[ranges[j], ranges[i]])
                # One-bin Gaussian smoothing removes the histogram's shot noise from the contours.
                from scipy import ndimage  # loaded by the corner plot only

                hist = ndimage.gaussian_filter(hist, 1.0)
                ax.plot(samples[::max(1, samples.shape[0] // 2000), j], samples[::max(1, samples.shape[0] // 2000), i],
                        ",", color="0.6", alpha=0.5)
                if hist.sum() > 0 and np.count_nonzero(hist) > 3:
                    levels = sorted(set(_credible_levels(hist)))
                    if len(levels) == 2 and levels[0] < levels[1]:
                        centres_x = 0.5 * (xe[1:] + xe[:-1])
                        centres_y = 0.5 * (ye[1:] + ye[:-1])
                        ax.contourf(centres_x, centres_y, hist.T, levels=[levels[0], levels[1], hist.max() + 1],
                                    colors=["#9ecae1", "#3182bd"], alpha=0.8)
                        ax.contour(centres_x, centres_y, hist.T, levels=levels, colors="k", linewidths=0.7)
                ax.set_ylim(ranges[i])
            ax.set_xlim(ranges[j])
            ax.xaxis.set_major_locator(MaxNLocator(nbins=_CORNER_BINS))
            if i != j:
                ax.yaxis.set_major_locator(MaxNLocator(nbins=_CORNER_BINS))
            if i == n - 1:
                ax.set_xlabel(_param_label(result, names[j]))
                ax.tick_params(axis="x", labelrotation=45, labelsize=8)
            else:
                ax.tick_params(axis="x", labelbottom=False)
            if j == 0 and i > 0:
                ax.set_ylabel(_param_label(result, names[i]))
                ax.tick_params(axis="y", labelsize=8)
            elif i != j:
                ax.tick_params(axis="y", labelleft=False)
    fig.suptitle(f"Posterior of {len(samples)} samples: 68 % and 95 % regions", fontsize=10)
    return fig


def _walker_lines(ax: Axes, steps: np.ndarray, values: np.ndarray, colour: str) -> None:
    """Every walker's trace (``values`` of shape (steps, walkers)) as one line collection.

    Non-finite values (a walker at a zero-posterior point) break its line there, as a
    plain line plot does. The data limits are set from the finite values.
    """
    segments = np.stack(np.broadcast_arrays(steps[None, :], values.T), axis=-1)
    ax.add_collection(LineCollection(segments, colors=colour, alpha=0.15, linewidths=0.5), autolim=False)


def _trace_limits(values: np.ndarray, kept: np.ndarray) -> tuple[float, float] | None:
    """Vertical range of a trace panel, or None when no value is finite.

    The 0.5 and 99.5 percentiles of the finite values after burn-in (rows ``kept``), with
    a 10 % margin: walkers starting far out, or a brief excursion of a few, do not flatten
    the chain that is used, while a walker stuck apart for the whole chain (1/32 of the
    values or more) stays inside.
    """
    after = values[kept]
    finite = after[np.isfinite(after)]
    if not finite.size:
        finite = values[np.isfinite(values)]
    if not finite.size:
        return None
    low, high = (float(q) for q in np.percentile(finite, [0.5, 99.5]))
    margin = 0.1 * (high - low) if high > low else 0.5 * max(abs(high), 1e-12)
    return low - margin, high + margin


def _shown_walkers(log_prob: np.ndarray, burn_in: int) -> np.ndarray:
    """Indices of the walkers the trace figure draws (all up to MAX_TRACE_WALKERS).

    A larger ensemble is represented by the :data:`_LOWEST_WALKERS` walkers of lowest
    median log posterior after burn-in (a stuck walker is what a trace plot is looked at
    for) and walkers evenly spaced through the rest.
    """
    n_walkers = log_prob.shape[1]
    if n_walkers <= MAX_TRACE_WALKERS:
        return np.arange(n_walkers)
    after = log_prob[min(burn_in, log_prob.shape[0] - 1):]
    with np.errstate(invalid="ignore"):
        median = np.nanmedian(np.where(np.isfinite(after), after, -np.inf), axis=0)
    lowest = np.argsort(median, kind="stable")[:_LOWEST_WALKERS]
    rest = np.setdiff1d(np.arange(n_walkers), lowest)
    spaced = rest[np.linspace(0, rest.size - 1, MAX_TRACE_WALKERS - _LOWEST_WALKERS).round().astype(int)]
    return np.union1d(lowest, spaced)


def trace_figure(result: FitResult) -> Figure:
    """Walker traces of every free parameter and the log posterior; burn-in shaded."""
    names = list(result.free)
    fig, grid = _fixed_grid(8.0, 1.7 * (len(names) + 1) + 0.5, len(names) + 1, 1, _TRACE_MARGINS)
    if result.mcmc is None:
        ax = fig.add_subplot(grid[:, 0])
        ax.text(0.5, 0.5, "no chain (fit run without MCMC)", ha="center", va="center")
        ax.set_axis_off()
        return fig
    m = result.mcmc
    axes = grid.subplots(sharex=True, squeeze=False)[:, 0]
    steps = np.arange(m.n_steps)
    stride = max(1, math.ceil(m.n_steps / MAX_TRACE_POINTS))
    shown = _shown_walkers(m.log_prob, m.burn_in)
    kept = steps[::stride] >= m.burn_in
    for ax, j in zip(axes, range(len(names))):
        values = m.chain[::stride, shown, j]
        _walker_lines(ax, steps[::stride], values, "k")
        limits = _trace_limits(values, kept)
        if limits is not None:
            ax.set_ylim(*limits)
        ax.set_ylabel(_param_label(result, names[j]), fontsize=9)
        ax.yaxis.set_major_locator(MaxNLocator(nbins=_CORNER_BINS))
    log_prob = m.log_prob[::stride, shown]
    finite = log_prob[np.isfinite(log_prob)]
    _walker_lines(axes[-1], steps[::stride], log_prob, "C3")
    if finite.size:
        top = float(finite.max())
        axes[-1].set_ylim(max(float(np.percentile(finite, 1)), top - 50.0) - 1.0, top + 1.0)
    axes[-1].set_ylabel("log posterior", fontsize=9)
    axes[-1].set_xlabel("step")
    for ax in axes:
        ax.axvspan(0, m.burn_in, color="C1", alpha=0.15, lw=0)
        ax.grid(alpha=0.3)
        ax.set_xlim(0, m.n_steps)
    status = "converged" if m.converged else "NOT CONVERGED (step limit reached)"
    tau = float(np.nanmax(m.tau)) if np.any(np.isfinite(m.tau)) else math.nan
    which = f"{m.n_walkers} walkers" if len(shown) == m.n_walkers else (
        f"{len(shown)} of {m.n_walkers} walkers (the {_LOWEST_WALKERS} of lowest posterior and "
        f"{len(shown) - _LOWEST_WALKERS} evenly chosen)")
    fig.suptitle(f"Traces of {which}; shaded: burn-in ({m.burn_in} steps)\n"
                 f"max tau = {tau:.1f} steps; {status}", fontsize=10, color="black" if m.converged else "#c9302c")
    return fig
