"""Figures of a fit result (matplotlib Figure API only, no pyplot state).

Each function takes a :class:`gonio.fitting.FitResult` and returns a
:class:`matplotlib.figure.Figure`:

* :func:`geometry_figure` - what was measured: source and viewing directions on the
  hemisphere (polar plot: radius theta [deg], angle phi [deg]);
* :func:`data_figure` - data with error bars and the posterior predictive band (median,
  68 % and 95 %), one panel per incidence in the plane it was measured in: in-plane data
  against the signed viewing angle (positive on the source side, DESIGN.md), off-plane
  data against theta_r with one series per azimuth difference (an incidence measured in
  both gets two adjacent panels);
* :func:`residual_figure` - normalised residuals (data - model) / sigma;
* :func:`corner_figure` - one- and two-dimensional marginals of the posterior;
* :func:`trace_figure` - walker traces with the burn-in shaded, and the log posterior.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from scipy import ndimage

from gonio.fitting.dataset import QUANTITY_LABELS, Dataset
from gonio.fitting.results import FitResult
from gonio.geometry import azimuth_difference, in_plane_angles

__all__ = [
    "geometry_figure", "data_figure", "residual_figure", "corner_figure", "trace_figure",
    "MAX_INCIDENCE_PANELS", "MAX_AZIMUTH_SERIES",
]

#: At most this many incidences are drawn in the data figure (evenly chosen).
MAX_INCIDENCE_PANELS = 12
#: At most this many azimuth differences get a series of their own in an off-plane panel
#: (those with the most measurements); the legend says how many were left out.
MAX_AZIMUTH_SERIES = 6
_BAND_POINTS = 121
# Width and height of one panel of the data figure [in].
_PANEL_SIZE_IN = (4.4, 3.2)
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


def geometry_figure(result: FitResult) -> Figure:
    """Polar plot of the measured viewing directions, coloured by incidence, with the sources."""
    data = result.dataset
    sources, index = data.incidences()
    fig = Figure(figsize=(6.0, 6.6), layout="constrained")
    ax = fig.add_subplot(projection="polar")
    for k, (theta_i, phi_i) in enumerate(sources):
        mask = index == k
        colour = f"C{k % 10}"
        # Decreasing sizes keep coincident views of several incidences visible.
        size = max(70.0 - 50.0 * k / max(len(sources) - 1, 1), 12.0)
        ax.scatter(np.radians(data.phi_r[mask]), data.theta_r[mask], s=size, color=colour, edgecolor="white", linewidth=0.5,
                   label=f"views, theta_i = {theta_i:g} deg, phi_i = {phi_i:g} deg" if len(sources) <= 10 else None)
        ax.scatter(np.radians(phi_i), theta_i, marker="*", s=220, color=colour, edgecolor="k", linewidth=0.7, zorder=5)
    ax.scatter([], [], marker="*", s=120, color="0.6", edgecolor="k", label="source directions")
    ax.set_ylim(0, 90)
    ax.set_yticks([30, 60, 90])
    ax.set_yticklabels(["30 deg", "60 deg", "90 deg"])
    ax.set_rlabel_position(112)
    fig.suptitle(f"Measurement geometry: {data.n} measurements, {len(sources)} incidences\n"
                 "radius: polar angle theta [deg], angle: azimuth phi [deg]", fontsize=10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.06), fontsize=8, frameon=False, ncol=2)
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


def _draw_in_plane_panel(ax: Axes, result: FitResult, panel: _Panel, n_draws: int) -> None:
    """In-plane data and model band against the signed viewing angle (+ source side)."""
    data = result.dataset
    view = data.signed_view[panel.selection]
    x = np.linspace(*_span(view, -89.0, 89.0), _BAND_POINTS)
    band = result.posterior_predictive(*in_plane_angles(panel.theta_i, x, panel.phi_i), n_draws=n_draws)
    _band_axes(ax, x, band, "C0")
    ax.errorbar(view, data.value[panel.selection], data.sigma[panel.selection], fmt="o", ms=4, color="k",
                capsize=2, lw=1)
    ax.axvline(panel.theta_i, color="0.6", ls=":", lw=1)
    ax.set_xlim(-90, 90)
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


def _draw_off_plane_panel(ax: Axes, result: FitResult, panel: _Panel, n_draws: int) -> None:
    """Off-plane data and model bands against theta_r, one colour per azimuth difference."""
    data = result.dataset
    offsets, series, n_offsets = _azimuth_series(data, panel.selection)
    picked = np.flatnonzero(panel.selection)
    for j, offset in enumerate(offsets):
        colour = f"C{(j + 1) % 10}"
        pick = picked[series == j]
        x = np.linspace(*_span(data.theta_r[pick], 0.0, 89.0), _BAND_POINTS)
        ti, pi_, tr, pr = np.broadcast_arrays(panel.theta_i, panel.phi_i, x, panel.phi_i + offset)
        _band_axes(ax, x, result.posterior_predictive(ti, pi_, tr, pr, n_draws=n_draws), colour)
        ax.errorbar(data.theta_r[pick], data.value[pick], data.sigma[pick], fmt="o", ms=4, color=colour,
                    mec="k", mew=0.5, capsize=2, lw=1, label=f"phi_r - phi_i = {offset:g} deg")
    ax.set_xlim(0, 90)
    ax.set_xlabel("viewing angle theta_r [deg]")
    omitted = f"{len(offsets)} of {n_offsets} azimuths" if n_offsets > len(offsets) else None
    ax.legend(fontsize=7.5, title=omitted, title_fontsize=7.5)


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
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles) if columns > 1 else 3, fontsize=8,
               title=band_name, title_fontsize=8, frameon=False)


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
    width, height = _PANEL_SIZE_IN
    fig = Figure(figsize=(width * columns, height * rows + 0.9), layout="constrained")
    grid = fig.add_gridspec(rows, columns)
    shared_ylim = _shared_ylim(data, panels)
    first = None
    for panel, (row, column) in zip(panels, positions):
        ax = fig.add_subplot(grid[row, column], sharey=first if shared_ylim else None)
        if first is None:
            first = ax
        if panel.in_plane:
            _draw_in_plane_panel(ax, result, panel, n_draws)
        else:
            _draw_off_plane_panel(ax, result, panel, n_draws)
        ax.set_ylim(shared_ylim or _data_range(data.value[panel.selection], data.sigma[panel.selection]))
        ax.set_title(panel.title, fontsize=10)
        ax.grid(alpha=0.3)
        if column == 0:
            ax.set_ylabel(QUANTITY_LABELS[data.quantity])
        elif shared_ylim:
            ax.tick_params(labelleft=False)
    band_name = "posterior predictive" if result.mcmc is not None else "least-squares model"
    _band_legend(fig, band_name, any(panel.in_plane for panel in panels), columns)
    n_incidences = len(data.incidences()[0])
    if len(groups) < n_incidences:
        fig.suptitle(f"{len(groups)} of {n_incidences} incidences shown", fontsize=9)
    return fig


def residual_figure(result: FitResult) -> Figure:
    """Normalised residuals (data - posterior median model) / sigma against the viewing angle.

    sigma is each value's total uncertainty under the fit's likelihood: the stated one with
    the fitted extra noise (``jitter``, or ``rel_jitter`` x prediction) in quadrature. The
    title's chi-square is the fit's own, with the data's covariance where they have one.
    """
    data = result.dataset
    sources, index = data.incidences()
    problem = result.problem()
    values = result.best_values()
    model = problem.predict(values)
    extra = problem.extra_variance(values, model) if problem.jitter else 0.0
    z = (data.value - model) / problem.total_sigma(values, model)
    whitened = problem.whiten(model - data.value, extra)[0]
    noise_label = {None: "sigma", "absolute": "hypot(sigma, jitter)",
                   "relative": "hypot(sigma, rel_jitter x model)"}[problem.jitter]
    x = np.where(data.in_plane, data.signed_view, data.theta_r)
    fig = Figure(figsize=(7.5, 3.8), layout="constrained")
    ax = fig.add_subplot()
    ax.axhspan(-1, 1, color="0.85", lw=0)
    ax.axhspan(-2, -1, color="0.93", lw=0)
    ax.axhspan(1, 2, color="0.93", lw=0)
    ax.axhline(0, color="0.4", lw=1)
    for k, (theta_i, _) in enumerate(sources):
        mask = index == k
        marker_in = mask & data.in_plane
        marker_out = mask & ~data.in_plane
        label = f"theta_i = {theta_i:g} deg" if len(sources) <= 10 else None
        ax.plot(x[marker_in], z[marker_in], "o", ms=4, color=f"C{k % 10}", label=label)
        if marker_out.any():
            ax.plot(x[marker_out], z[marker_out], "^", ms=4, color=f"C{k % 10}")
    if np.any(~data.in_plane):
        ax.plot([], [], "^", color="0.5", label="out of plane (x = theta_r)")
    ax.set_xlim(-90, 90)
    limit = max(3.5, float(np.nanmax(np.abs(z))) * 1.1) if z.size else 3.5
    ax.set_ylim(-limit, limit)
    ax.set_xlabel("signed viewing angle theta_r [deg] (in plane; + source side)")
    ax.set_ylabel(f"(data - model) / {noise_label} [-]")
    chi2 = float(np.dot(whitened, whitened))
    correlated = " (with the data's covariance)" if data.covariance is not None else ""
    ax.set_title(f"Normalised residuals at the posterior median: chi2{correlated} = {chi2:.1f} for {data.n} points",
                 fontsize=10)
    ax.legend(fontsize=8, ncol=2, loc="upper left")
    ax.grid(alpha=0.3)
    return fig


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
    fig = Figure(figsize=(size, size), layout="constrained")
    if samples.shape[0] == 0:
        ax = fig.add_subplot()
        ax.text(0.5, 0.5, "no posterior samples (fit run without MCMC)", ha="center", va="center")
        ax.set_axis_off()
        return fig
    axes = fig.subplots(n, n, squeeze=False)
    ranges = []
    for j in range(n):
        lo, hi = np.percentile(samples[:, j], [0.2, 99.8])
        if not hi > lo:
            lo, hi = lo - 0.5 * max(abs(lo), 1e-9), hi + 0.5 * max(abs(hi), 1e-9)
        ranges.append((lo, hi))
    for i in range(n):
        for j in range(n):
            ax = axes[i, j]
            if j > i:
                ax.set_axis_off()
                continue
            if i == j:
                ax.hist(samples[:, j], bins=bins, range=ranges[j], color="C0", histtype="stepfilled", alpha=0.6)
                q = np.percentile(samples[:, j], [16, 50, 84])
                for value, style in zip(q, (":", "-", ":")):
                    ax.axvline(value, color="k", ls=style, lw=1)
                ax.set_yticks([])
                ax.set_title(f"{names[j]} = {q[1]:.4g} -{q[1] - q[0]:.2g} +{q[2] - q[1]:.2g}", fontsize=9)
            else:
                hist, xe, ye = np.histogram2d(samples[:, j], samples[:, i], bins=bins, range=[ranges[j], ranges[i]])
                # One-bin Gaussian smoothing removes the histogram's shot noise from the contours.
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
            if i == n - 1:
                ax.set_xlabel(_param_label(result, names[j]))
                ax.tick_params(axis="x", labelrotation=45, labelsize=8)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(_param_label(result, names[i]))
                ax.tick_params(axis="y", labelsize=8)
            elif i != j:
                ax.set_yticklabels([])
    fig.suptitle(f"Posterior of {len(samples)} samples: 68 % and 95 % regions", fontsize=10)
    return fig


def trace_figure(result: FitResult) -> Figure:
    """Walker traces of every free parameter and the log posterior; burn-in shaded."""
    names = list(result.free)
    fig = Figure(figsize=(8.0, 1.7 * (len(names) + 1) + 0.5), layout="constrained")
    if result.mcmc is None:
        ax = fig.add_subplot()
        ax.text(0.5, 0.5, "no chain (fit run without MCMC)", ha="center", va="center")
        ax.set_axis_off()
        return fig
    m = result.mcmc
    axes = fig.subplots(len(names) + 1, 1, sharex=True, squeeze=False)[:, 0]
    steps = np.arange(m.n_steps)
    stride = max(1, m.n_steps // 2000)
    for ax, j in zip(axes, range(len(names))):
        ax.plot(steps[::stride], m.chain[::stride, :, j], color="k", alpha=0.15, lw=0.5)
        ax.set_ylabel(_param_label(result, names[j]), fontsize=9)
    log_prob = m.log_prob[::stride]
    finite = log_prob[np.isfinite(log_prob)]
    axes[-1].plot(steps[::stride], log_prob, color="C3", alpha=0.15, lw=0.5)
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
    fig.suptitle(f"Traces of {m.n_walkers} walkers; shaded: burn-in ({m.burn_in} steps); "
                 f"max tau = {tau:.1f} steps; {status}", fontsize=10, color="black" if m.converged else "#c9302c")
    return fig
