"""Figures of a fit result (matplotlib Figure API only, no pyplot state).

Each function takes a :class:`gonio.fitting.FitResult` and returns a
:class:`matplotlib.figure.Figure`:

* :func:`geometry_figure` - what was measured: source and viewing directions on the
  hemisphere (polar plot: radius theta [deg], angle phi [deg]);
* :func:`data_figure` - data with error bars and the posterior predictive band (median,
  68 % and 95 %) for each incidence: in-plane data against the signed viewing angle
  (positive on the source side, DESIGN.md), out-of-plane data against theta_r for each
  azimuth difference;
* :func:`residual_figure` - normalised residuals (data - model) / sigma;
* :func:`corner_figure` - one- and two-dimensional marginals of the posterior;
* :func:`trace_figure` - walker traces with the burn-in shaded, and the log posterior.
"""
from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from scipy import ndimage

from gonio.fitting.dataset import QUANTITY_LABELS
from gonio.fitting.results import FitResult
from gonio.geometry import in_plane_angles

__all__ = ["geometry_figure", "data_figure", "residual_figure", "corner_figure", "trace_figure", "MAX_INCIDENCE_PANELS"]

#: At most this many incidences get their own panel in the data figure (evenly chosen).
MAX_INCIDENCE_PANELS = 8
_BAND_POINTS = 121


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


def _band_axes(ax, x, band, colour, label):
    ax.fill_between(x, band[0], band[4], color=colour, alpha=0.15, lw=0, label="95 % band" if label else None)
    ax.fill_between(x, band[1], band[3], color=colour, alpha=0.3, lw=0, label="68 % band" if label else None)
    ax.plot(x, band[2], color=colour, lw=1.6, label="posterior median" if label else None)


def _span(x: np.ndarray, lo: float, hi: float) -> tuple[float, float]:
    """Range of the model band: the data's range plus 5 deg, within [lo, hi]."""
    if x.size == 0:
        return lo, hi
    return max(float(x.min()) - 5.0, lo), min(float(x.max()) + 5.0, hi)


def _data_ylim(ax, value: np.ndarray, sigma: np.ndarray) -> None:
    """Vertical range from the data (the model may diverge outside them, e.g. Minnaert)."""
    if value.size == 0:
        return
    low, high = float(np.min(value - sigma)), float(np.max(value + sigma))
    margin = 0.12 * (high - low) if high > low else 0.1 * max(abs(high), 1e-12)
    ax.set_ylim(min(low - margin, 0.0) if low >= 0 and low < 0.25 * high else low - margin, high + margin)


def data_figure(result: FitResult, n_draws: int = 200) -> Figure:
    """Data with the posterior predictive band for each incidence (module docstring)."""
    data = result.dataset
    sources, index, shown = _incidence_groups(result)
    in_plane = data.in_plane
    has_out = bool(np.any(~in_plane))
    has_in = bool(np.any(in_plane))
    columns = int(has_in) + int(has_out)
    fig = Figure(figsize=(5.6 * columns, 2.9 * len(shown) + 0.6), layout="constrained")
    axes = fig.subplots(len(shown), columns, squeeze=False)
    ylabel = QUANTITY_LABELS[data.quantity]
    band_name = "posterior predictive" if result.mcmc is not None else "least-squares model"
    several_azimuths = len({round(float(p), 6) for p in sources[:, 1]}) > 1
    for row, k in enumerate(shown):
        theta_i, phi_i = sources[k]
        mask = index == k
        incidence = f"theta_i = {theta_i:g} deg" + (f", phi_i = {phi_i:g} deg" if several_azimuths else "")
        in_sel, out_sel = mask & in_plane, mask & ~in_plane
        if np.any(out_sel):  # an off-plane sweep: its normal view (theta_r = 0) belongs to it
            at_normal = data.theta_r == 0.0
            in_sel, out_sel = in_sel & ~at_normal, out_sel | (mask & at_normal)
        column = 0
        if has_in:
            ax = axes[row, column]
            column += 1
            sel = in_sel
            if not np.any(sel):
                ax.text(0.5, 0.5, f"{incidence}:\nno in-plane data", transform=ax.transAxes,
                        ha="center", va="center", color="0.5")
                ax.set_axis_off()
            else:
                x = np.linspace(*_span(data.signed_view[sel], -89.0, 89.0), _BAND_POINTS)
                geometry = in_plane_angles(theta_i, x, phi_i)
                band = result.posterior_predictive(*geometry, n_draws=n_draws)
                _band_axes(ax, x, band, "C0", row == 0)
                ax.errorbar(data.signed_view[sel], data.value[sel], data.sigma[sel], fmt="o", ms=4, color="k",
                            capsize=2, lw=1, label="measured" if row == 0 else None)
                ax.axvline(theta_i, color="0.6", ls=":", lw=1, label="source direction" if row == 0 else None)
                ax.set_xlim(-90, 90)
                _data_ylim(ax, data.value[sel], data.sigma[sel])
                ax.set_xlabel("signed viewing angle theta_r [deg] (+ source side)")
                ax.set_ylabel(ylabel)
                ax.set_title(f"in plane, {incidence}", fontsize=10)
                if row == 0:
                    ax.legend(fontsize=8, title=band_name, title_fontsize=8)
        if has_out:
            ax = axes[row, column]
            sel = out_sel
            if not np.any(sel):
                ax.text(0.5, 0.5, f"{incidence}:\nno out-of-plane data", transform=ax.transAxes,
                        ha="center", va="center", color="0.5")
                ax.set_axis_off()
                continue
            offsets = np.round(data.azimuth_difference[sel])
            x = np.linspace(*_span(data.theta_r[sel], 0.0, 89.0), _BAND_POINTS)
            for j, offset in enumerate(np.unique(offsets)[:6]):
                colour = f"C{(j + 1) % 10}"
                ti, pi_, tr, pr = np.broadcast_arrays(theta_i, phi_i, x, phi_i + offset)
                band = result.posterior_predictive(ti, pi_, tr, pr, n_draws=n_draws)
                _band_axes(ax, x, band, colour, False)
                pick = np.flatnonzero(sel)[offsets == offset]
                ax.errorbar(data.theta_r[pick], data.value[pick], data.sigma[pick], fmt="o", ms=4, color=colour,
                            mec="k", mew=0.5, capsize=2, lw=1, label=f"phi_r - phi_i = {offset:g} deg")
            ax.set_xlim(0, 90)
            _data_ylim(ax, data.value[sel], data.sigma[sel])
            ax.set_xlabel("viewing angle theta_r [deg]")
            ax.set_ylabel(ylabel)
            ax.set_title(f"out of plane, {incidence}", fontsize=10)
            ax.legend(fontsize=8)
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    if len(shown) < len(sources):
        fig.suptitle(f"{len(shown)} of {len(sources)} incidences shown", fontsize=9)
    return fig


def residual_figure(result: FitResult) -> Figure:
    """Normalised residuals (data - posterior median model) / sigma against the viewing angle
    (sigma includes the fitted extra-noise term ``jitter`` in quadrature when there is one)."""
    data = result.dataset
    sources, index = data.incidences()
    model = result.predict(*data.geometry)
    jitter = result.best_values().get("jitter", 0.0)  # fitted extra noise, in quadrature
    z = (data.value - model) / np.hypot(data.sigma, jitter)
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
    ax.set_ylabel("(data - model) / sigma [-]" if not jitter else "(data - model) / hypot(sigma, jitter) [-]")
    chi2 = float(np.sum(z**2))
    ax.set_title(f"Normalised residuals at the posterior median: chi2 = {chi2:.1f} for {data.n} points", fontsize=10)
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
