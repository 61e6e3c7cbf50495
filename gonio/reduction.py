"""Reduce a recording to radiance per geometry, with an uncertainty budget by component.

:func:`reduce_recording` reads a recording (:mod:`gonio.data`) and returns a
:class:`Reduced`: one value per measured geometry (repeats combined) at the geometry the
stage read back, its uncertainty split into the components of
:data:`gonio.uncertainty.COMPONENTS`, and the lamp irradiance ``E_0`` from the reference
standard with its own budget. What each component is and how it is estimated is in
docs/acquisition.md; in short:

- CCD: from the photon-transfer characterisation the run stored (system gain, dark noise,
  PRNU), applied to each point's own signal, exposure and window;
- lamp: divided out by the lamp monitor when the rig has one (what remains is the
  monitor's noise, measured in the dark); otherwise the drift is interpolated between
  the protocol's check measurements and the flicker measured from their frames (or, with
  neither, from repeats); with none of these the budget says the lamp was not measured;
- angle: the readback's quantisation times the local slope of the measured curve;
- calibration: the reference standard reduced exactly like the sample (same budget, the
  same aperture average the fit uses), its certificate and its departure from Lambertian.

Nothing is dropped silently: saturated points are excluded and counted, points with
little or negative signal are kept with their uncertainty and flagged ``low_signal``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .data import duplicated_rows, read_metadata, read_points
from .protocols import loads
from .uncertainty import (
    COMPONENTS,
    CameraModel,
    ccd_components,
    interpolate_drift,
    interpolation_excess,
    local_slopes,
    pooled_excess_variance,
    quantisation_sigma,
)

__all__ = ["Reduced", "Readings", "reduce_recording", "read_readings", "combine_reduced", "REFERENCE_BLOCK",
           "CHECK_BLOCK", "SATURATED_MAJORITY"]

#: Block name under which reference-standard points are recorded.
REFERENCE_BLOCK = "reference standard"
#: Block name under which lamp-check points are recorded.
CHECK_BLOCK = "lamp check"
#: A fit is refused when more than this fraction of the sample points saturated.
SATURATED_MAJORITY = 0.5
#: A value at or below this many standard uncertainties is flagged ``low_signal`` (kept).
LOW_SIGNAL_SIGMAS = 3.0
#: Marks a budget.json written by :meth:`Reduced.write`.
REDUCTION_FORMAT = "gonio reduction 1"
#: Encoder resolution assumed for recordings that did not store it [deg].
_DEFAULT_RESOLUTION = 0.001


# --------------------------------------------------------------------------- result
@dataclass(frozen=True)
class Reduced:
    """Radiance per measured geometry, repeats combined, with its uncertainty budget.

    Attributes
    ----------
    theta_i, phi_i, theta_r, phi_r : numpy.ndarray
        Geometry in the sample frame from the stage readback (mean over repeats) [deg].
    view : numpy.ndarray
        Signed camera angle (readback) [deg].
    radiance, radiance_sigma : numpy.ndarray
        Relative radiance [``unit``] and its total 1-sigma uncertainty.
    repeats : numpy.ndarray
        Number of measurements combined into each value.
    reference_irradiance, reference_irradiance_sigma : float or None
        Lamp irradiance E_0 in the radiance unit per steradian from the reference
        standard, and its total uncertainty (None when none was measured).
    label : str
        Sample label.
    metadata : mapping
        Recording, protocol, apertures and the budget summary (passed to datasets).
    budget : mapping of str to numpy.ndarray
        Standard uncertainty of each value by component [``unit``]; they add in
        quadrature to ``radiance_sigma``.
    calibration : mapping of str to float
        Relative standard uncertainties of E_0 by component [-].
    flags : numpy.ndarray
        Quality flags of each value (``"low_signal"`` or ``""``).
    excluded : mapping of str to int
        Points left out and why (``saturated``).
    warnings : tuple of str
        What the budget could not measure, and what looks inconsistent.
    consistency : mapping of str to float
        Checks of the budget against the data (reduced chi-square of repeats about
        their mean, of the checks about the drift curve).
    unit : str
        Unit of ``radiance``.
    repeat_statistics : tuple of dict
        For every geometry measured more than once: its readback geometry, the number of
        readings, the observed standard deviation of one reading (after moving each to
        the mean geometry), the stated one (root mean square of the readings' budgets
        without the components common to the repeats) and their chi-square.
    window : numpy.ndarray or None
        ``1/N - 1/N_max`` of each value's camera window (N its pixel count, N_max the
        largest window of the recording) [1/pixel]: the PRNU errors of two values are
        correlated as ``sqrt(min/max)`` of their window terms (:meth:`covariance`).
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_r: np.ndarray
    phi_r: np.ndarray
    view: np.ndarray
    radiance: np.ndarray
    radiance_sigma: np.ndarray
    repeats: np.ndarray
    reference_irradiance: float | None
    reference_irradiance_sigma: float | None
    label: str
    metadata: Mapping[str, Any] = field(default_factory=dict)
    budget: Mapping[str, np.ndarray] = field(default_factory=dict)
    calibration: Mapping[str, float] = field(default_factory=dict)
    flags: np.ndarray | None = None
    excluded: Mapping[str, int] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    consistency: Mapping[str, float] = field(default_factory=dict)
    unit: str = "DN/s"
    repeat_statistics: tuple = ()
    window: np.ndarray | None = None

    # -- correlations --------------------------------------------------------------------
    def covariance(self) -> np.ndarray:
        """Covariance matrix of the values' errors [``unit``^2].

        Every component is independent between values except PRNU: the camera windows
        of a recording are centred and nested (they shrink with cos(theta_r) along one
        image axis), so the PRNU error of a window relative to the largest one is a random
        walk in the window size: values i and j share ``p^2 x_i x_j min(a_i, a_j)`` with
        ``a = 1/N - 1/N_max`` (:func:`gonio.uncertainty.ccd_components`); values measured
        through the same window (the same |view|) share all of it. Without window terms
        the matrix is diagonal.
        """
        total = np.asarray(self.radiance_sigma, float)
        prnu = np.asarray(self.budget.get("prnu", np.zeros_like(total)), float)
        covariance = np.diag(total**2 - prnu**2)
        if self.window is not None and np.any(prnu > 0):
            a = np.asarray(self.window, float)
            with np.errstate(invalid="ignore", divide="ignore"):
                correlation = np.sqrt(np.minimum.outer(a, a) / np.maximum.outer(a, a))
            correlation = np.nan_to_num(correlation)  # a window with a = 0 has no PRNU term
            sign = np.sign(self.radiance)
            covariance += np.outer(sign * prnu, sign * prnu) * correlation
        np.fill_diagonal(covariance, total**2)
        return covariance

    # -- the budget ----------------------------------------------------------------------
    def budget_summary(self) -> dict[str, Any]:
        """Median and largest relative size of each component, the calibration, exclusions."""
        level = np.abs(self.radiance)
        rel = {name: values / np.where(level > 0, level, np.nan) for name, values in self.budget.items()}
        return {
            "unit": self.unit,
            "components": {name: {"median_relative": _nanmedian(r), "max_relative": _nanmax(r),
                                  "meaning": COMPONENTS.get(name, "")} for name, r in rel.items()},
            "total_median_relative": _nanmedian(self.radiance_sigma / np.where(level > 0, level, np.nan)),
            "calibration_relative": dict(self.calibration),
            "excluded": dict(self.excluded),
            "low_signal": int(np.sum(self.flags == "low_signal")) if self.flags is not None else 0,
            "consistency": dict(self.consistency),
            "warnings": list(self.warnings),
        }

    def budget_table(self) -> str:
        """The budget as a plain-text table (what ``gonio reduce`` prints)."""
        summary = self.budget_summary()
        lines = [f"uncertainty budget of {len(self.radiance)} values ({self.unit}), relative to each value:",
                 f"  {'component':<14}{'median':>10}{'max':>10}  meaning"]
        for name, row in summary["components"].items():
            lines.append(f"  {name:<14}{row['median_relative']:>10.2e}{row['max_relative']:>10.2e}  {row['meaning']}")
        lines.append(f"  {'total':<14}{summary['total_median_relative']:>10.2e}")
        if self.calibration:
            parts = ", ".join(f"{k} {v:.2e}" for k, v in self.calibration.items())
            lines.append(f"calibration (E_0, common to every value): {parts}")
        for key, value in self.consistency.items():
            lines.append(f"consistency: {key} = {value:.3g}")
        for key, count in self.excluded.items():
            lines.append(f"excluded: {count} {key} point(s)")
        if summary["low_signal"]:
            lines.append(f"flagged: {summary['low_signal']} low-signal value(s) kept with their uncertainty")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def table_rows(self) -> list[dict[str, Any]]:
        """One dict per value: geometry, value, total uncertainty, components, repeats, flags."""
        rows = []
        for k in range(len(self.radiance)):
            row = {"theta_i": self.theta_i[k], "phi_i": self.phi_i[k], "theta_r": self.theta_r[k],
                   "phi_r": self.phi_r[k], "view": self.view[k], "value": self.radiance[k],
                   "sigma": self.radiance_sigma[k]}
            row.update({f"u_{name}": float(c[k]) for name, c in self.budget.items()})
            row.update(repeats=int(self.repeats[k]), flags=str(self.flags[k]) if self.flags is not None else "")
            rows.append({key: (float(v) if isinstance(v, (np.floating, float)) else v) for key, v in row.items()})
        return rows

    def write(self, folder: str | Path) -> tuple[Path, Path]:
        """Write ``reduced.csv`` (one row per value, every budget component as ``u_<name>``)
        and ``budget.json`` (:meth:`budget_summary`, the reference irradiance, the repeat
        statistics) into ``folder``, atomically. Returns both paths."""
        import csv
        import io
        import json

        from .files import write_atomic

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        rows = self.table_rows()
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()} for r in rows)
        summary = {"format": REDUCTION_FORMAT, "label": self.label, "metadata": dict(self.metadata),
                   "reference_irradiance": self.reference_irradiance,
                   "reference_irradiance_sigma": self.reference_irradiance_sigma,
                   **self.budget_summary(), "repeat_statistics": list(self.repeat_statistics)}
        csv_path = write_atomic(folder / "reduced.csv", buffer.getvalue())
        json_path = write_atomic(folder / "budget.json", json.dumps(summary, indent=2, default=float) + "\n")
        return csv_path, json_path

    def _dataset_metadata(self) -> dict[str, Any]:
        out = {k: v for k, v in self.metadata.items() if k != "planned_view"}
        out["uncertainty_budget"] = {k: v["median_relative"] for k, v in self.budget_summary()["components"].items()}
        if self.calibration:
            out["calibration_budget"] = dict(self.calibration)
        if self.excluded:
            out["excluded"] = dict(self.excluded)
        if self.warnings:
            out["reduction_warnings"] = list(self.warnings)
        return out

    def _require_usable(self) -> None:
        saturated = self.excluded.get("saturated", 0)
        total = saturated + int(np.sum(self.repeats))
        if total and saturated > SATURATED_MAJORITY * total:
            raise ValueError(
                f"{self.metadata.get('recording', self.label)}: {saturated} of {total} sample measurements "
                "saturated; fitting what is left would describe the exposure, not the sample. Measure again "
                "with the automatic or an HDR exposure, or a shorter fixed exposure"
            )

    # -- datasets --------------------------------------------------------------------------
    def relative_radiance(self):
        """Dataset of relative radiance (quantity ``'radiance'``: fit with a free scale)."""
        from .fitting import Dataset

        self._require_usable()
        return Dataset(self.theta_i, self.phi_i, self.theta_r, self.phi_r, self.radiance,
                       self.radiance_sigma, quantity="radiance", label=self.label, metadata=self._dataset_metadata(),
                       covariance=self.covariance())

    def normalised_radiance(self):
        """Dataset of L(theta_r)/L(0) per incidence (Oren & Nayar section 5, Figs 16-22).

        Each lamp direction is normalised by its own normal-view measurement (planned
        view 0); lamp directions without one are left out. The covariance propagates the
        values' covariance (:meth:`covariance`) through ``r_i = x_i / x_0`` to first order,
        so the normal-view value shared by an incidence's points and the PRNU shared by
        their windows are both in it, and it stays finite for low and negative values. The
        normal-view points themselves are 1 by construction, carry no information and are
        left out.
        """
        from .fitting import Dataset

        self._require_usable()
        planned = self.metadata.get("planned_view")
        views = np.asarray(planned, float) if planned is not None else self.view
        lamp = np.round(np.stack([self.theta_i, self.phi_i], axis=1), 1)
        normal_of = np.full(self.radiance.shape, -1)
        for key in {tuple(row) for row in lamp}:
            same = np.all(lamp == key, axis=1)
            normal = np.flatnonzero(same & (np.abs(views) < 1e-6))
            if normal.size:
                normal_of[same] = normal[0]
        keep = np.flatnonzero(normal_of >= 0)
        k0 = normal_of[keep]
        x0 = self.radiance[k0]
        value = self.radiance[keep] / x0
        full = self.covariance()
        # r_i = x_i / x_0(i), linearised: dr_i = (dx_i - r_i dx_0(i)) / x_0(i)
        covariance = (full[np.ix_(keep, keep)] - full[np.ix_(keep, k0)] * value[None, :]
                      - value[:, None] * full[np.ix_(k0, keep)] + np.outer(value, value) * full[np.ix_(k0, k0)])
        covariance /= np.outer(x0, x0)
        covariance = 0.5 * (covariance + covariance.T)
        informative = keep != k0  # the normal-view points are 1 by construction: no data
        covariance = covariance[np.ix_(informative, informative)]
        keep, value = keep[informative], value[informative]
        return Dataset(self.theta_i[keep], self.phi_i[keep], self.theta_r[keep], self.phi_r[keep], value,
                       np.sqrt(np.diag(covariance)),
                       quantity="normalised_radiance", label=self.label, metadata=self._dataset_metadata(),
                       covariance=covariance)

    def brdf(self):
        """Dataset of absolute BRDF [1/sr], calibrated by the reference standard.

        ``f = L / (E_0 cos theta_i)``; the covariance adds the calibration's relative
        uncertainty as an error common to all points (``f_i f_j u_cal^2``), so a fit of
        this dataset does not average it away (:meth:`fit_inputs` puts it into one prior
        on the scale instead, which is equivalent).
        """
        from .fitting import Dataset

        if self.reference_irradiance is None:
            raise ValueError("no reference standard was measured in this recording: absolute BRDF "
                             "is not available (use normalised_radiance() or relative_radiance())")
        self._require_usable()
        cos_i = np.cos(np.radians(self.theta_i))
        scale = self.reference_irradiance * cos_i
        value = self.radiance / scale
        rel_cal = self.reference_irradiance_sigma / self.reference_irradiance
        covariance = self.covariance() / np.outer(scale, scale) + np.outer(value, value) * rel_cal**2
        return Dataset(self.theta_i, self.phi_i, self.theta_r, self.phi_r, value, np.sqrt(np.diag(covariance)),
                       quantity="brdf", label=self.label, metadata=self._dataset_metadata(), covariance=covariance)

    def best_dataset(self):
        """Absolute BRDF when calibrated, else normalised radiance."""
        return self.brdf() if self.reference_irradiance is not None else self.normalised_radiance()

    def fit_inputs(self):
        """The dataset and priors a fit of this recording should use.

        With a reference standard: relative radiance, whose ``scale`` (the lamp irradiance
        E_0 in the recording's units) gets a Gaussian prior centred on the reference
        estimate with the calibration budget's total uncertainty as its width. The
        calibration error is common to every point, so it belongs in one nuisance
        parameter, not in per-point uncertainties (which would let many points average it
        away). Without a reference: normalised radiance L(theta_r)/L(0) and no prior.

        Returns
        -------
        dataset : gonio.fitting.Dataset
        priors : dict of name -> gonio.fitting.Prior
        """
        from .fitting import Normal

        if self.reference_irradiance is None:
            return self.normalised_radiance(), {}
        return self.relative_radiance(), {
            "scale": Normal(self.reference_irradiance, self.reference_irradiance_sigma, 0.0, math.inf)}


def _nanmedian(values) -> float:
    values = np.asarray(values, float)
    return float(np.nanmedian(values)) if np.isfinite(values).any() else math.nan


def _nanmax(values) -> float:
    values = np.asarray(values, float)
    return float(np.nanmax(values)) if np.isfinite(values).any() else math.nan


# --------------------------------------------------------------------------- the rows
@dataclass
class Readings:
    """Every recorded reading with its lamp-normalised value and its own budget.

    Attributes
    ----------
    points : dict of numpy.ndarray
        The columns of points.csv (every row).
    index : numpy.ndarray
        Rows that are usable readings: ok, not saturated, with a signal.
    value : numpy.ndarray
        Lamp-normalised signal rate of every row [``unit``] (meaningful at ``index``).
    budget : dict of numpy.ndarray
        Standard uncertainty of ``value`` by component, every row [``unit``]. The
        ``angle`` component is added per reduced value, not per reading.
    warnings : list of str
    consistency : dict of float
    unit : str
    shared : dict of numpy.ndarray
        Block label per row of the components that are common to several readings
        (see :func:`_combine`).
    """

    points: dict[str, np.ndarray]
    index: np.ndarray
    value: np.ndarray
    budget: dict[str, np.ndarray]
    warnings: list[str]
    consistency: dict[str, float]
    unit: str
    shared: dict[str, np.ndarray] = field(default_factory=dict)

    def column(self, name: str) -> np.ndarray:
        """A points.csv column at the usable readings."""
        return self.points[name][self.index]

    def sigma(self) -> np.ndarray:
        """Total standard uncertainty of each usable reading [``unit``]."""
        return np.sqrt(sum(c[self.index] ** 2 for c in self.budget.values()))


def _readback_or_plan(points: Mapping[str, np.ndarray], readback: str, planned: str) -> np.ndarray:
    values = np.asarray(points[readback], float)
    return np.where(np.isfinite(values), values, np.asarray(points[planned], float))


def _ccd_budget(points, rows, camera: CameraModel | None) -> dict[str, np.ndarray]:
    """CCD components of the raw signal rate of ``rows`` [DN/s]."""
    if camera is None:
        return {"ccd": np.asarray(points["signal_rate_sigma"][rows], float)}
    signal = (points["roi_mean"] - points["dark_mean"])[rows]
    frames = np.maximum(points["frames"][rows], 1)
    with np.errstate(invalid="ignore"):  # rows without statistics (refused, failed) give NaN
        return ccd_components(camera, signal, points["exposure"][rows], points["gain"][rows],
                              points["roi_pixels"][rows], frames)


def _random_relative(budget: Mapping[str, np.ndarray], rate: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Relative temporal CCD noise of ONE frame (shot and read; or the ROI estimate)."""
    per_frame = budget.get("shot_read", budget.get("ccd")) * np.sqrt(frames)
    return per_frame / np.where(np.abs(rate) > 0, np.abs(rate), np.nan)


def _normalise_by_monitor(points, rows, rate, budget, monitor_dark) -> tuple[np.ndarray, dict]:
    """Divide by the monitor reading minus its dark offset; add the monitor's own noise."""
    from drivers.monitor import MonitorDark

    dark = MonitorDark.from_dict(monitor_dark)
    lamp = points["monitor"][rows] - dark.offset
    frames = np.maximum(points["frames"][rows], 1)
    value = rate / lamp
    scaled = {name: c / lamp for name, c in budget.items()}
    noise = dark.noise(points["exposure"][rows]) / np.sqrt(frames)
    scaled["lamp_monitor"] = np.abs(value) * np.hypot(noise, dark.offset_sigma) / lamp
    return value, scaled


def _check_levels(points, rate: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Check readings moved to the checks' mean readback geometry (other rows unchanged).

    Every check re-arrives at the check geometry with the stage's repeatability, and the
    readback says where. The local slopes at the check geometry come from the recording
    itself, exactly as for repeats of a sample geometry (:func:`geometry_slopes` over
    the raw signal of every planned geometry: the irradiance factor ``cos(theta_i)``
    always, the measured curve along the view when the check geometry lies on a sweep),
    so that the check levels measure the lamp, not the stage.
    """
    readback = _readback(points)
    rows = np.flatnonzero(usable & (points["block"] != REFERENCE_BLOCK))
    groups = _groups(points, rows)
    keys = sorted(groups)
    geometry = np.array([readback[groups[k]].mean(axis=0) for k in keys])
    slopes = geometry_slopes(geometry, np.array([rate[groups[k]].mean() for k in keys]))
    level = rate.copy()
    checks = usable & (points["block"] == CHECK_BLOCK)
    for g, key in enumerate(keys):
        members = [i for i in groups[key] if checks[i]]
        if members:
            level[members] -= (readback[members] - geometry[g]) @ slopes[g]
    return level


def _checks_by_session(points, level, rate, ccd_rel, sessions) -> dict[int, dict[str, np.ndarray]]:
    """Check measurements per session: time, level (:func:`_check_levels`), frames and
    per-frame relative scatter."""
    is_check = (points["block"] == CHECK_BLOCK) & (points["status"] == "ok")
    out: dict[int, dict[str, np.ndarray]] = {}
    for s in np.unique(sessions[is_check]):
        k = np.flatnonzero(is_check & (sessions == s))
        k = k[np.argsort(points["instrument_time"][k])]
        out[int(s)] = {"time": points["instrument_time"][k], "level": level[k], "frames": np.maximum(points["frames"][k], 1),
                       "scatter": points["frame_rate_std"][k] / rate[k], "ccd_rel": ccd_rel[k], "rows": k}
    return out


def _flicker_from_checks(checks) -> tuple[float, float, int]:
    """Relative flicker variance of one exposure at the check exposure, from the check frames."""
    scatter = np.concatenate([c["scatter"] for c in checks.values()])
    frames = np.concatenate([c["frames"] for c in checks.values()])
    ccd = np.concatenate([c["ccd_rel"] for c in checks.values()])
    good = np.isfinite(scatter) & (frames > 1)
    if not good.any():
        return math.nan, math.nan, 0
    dof = frames[good] - 1
    variance = float(np.sum(dof * scatter[good] ** 2) / np.sum(dof) - np.sum(dof * ccd[good] ** 2) / np.sum(dof))
    return max(variance, 0.0), float(np.sum(dof)), int(good.sum())


def _normalise_by_checks(points, rows_all, rate, budget_all, sessions, exposure, warnings, consistency):
    """Divide every row by the lamp drift interpolated between checks; add flicker and drift terms.

    The drift term holds the uncertainty of the two checks around a reading and, when the
    checks themselves show that linear interpolation misses the lamp's drift
    (:func:`~gonio.uncertainty.interpolation_excess`), that miss at the reading's place
    in its interval.

    Returns the values, their budget and a label per row naming the pair of checks its
    drift correction comes from (rows between the same checks share its error).
    """
    frames = np.maximum(points["frames"], 1)
    ccd_rel = _random_relative(budget_all, rate, frames)
    checks = _checks_by_session(points, _check_levels(points, rate, rows_all), rate, ccd_rel, sessions)
    flicker_var, dof, _ = _flicker_from_checks(checks)
    check_exposure = float(np.median(np.concatenate([exposure[c["rows"]] for c in checks.values()])))
    reference_level = float(np.mean(np.concatenate([c["level"] for c in checks.values()])))
    drift = np.ones(rate.shape)
    drift_sigma = np.zeros(rate.shape)
    outside = np.zeros(rate.shape, bool)
    interval = np.full(rate.shape, -1)
    chi2 = []
    for s, c in checks.items():
        level = c["level"] / reference_level
        sigma = np.sqrt((flicker_var + c["ccd_rel"] ** 2) / c["frames"])
        here = rows_all & (sessions == s)
        d, u, x, w = interpolate_drift(c["time"], level, sigma, points["instrument_time"][here])
        excess, session_chi2 = interpolation_excess(c["time"], level, sigma)
        drift[here], outside[here] = d, x
        drift_sigma[here] = np.hypot(u, excess * w * (1 - w))
        interval[here] = np.searchsorted(c["time"], points["instrument_time"][here])
        if np.isfinite(session_chi2):
            chi2.append(session_chi2)
    if chi2:
        consistency["checks_reduced_chi2"] = float(np.mean(chi2))
    uncovered = rows_all & ~np.isin(sessions, list(checks))
    if uncovered.any():
        warnings.append(f"{int(uncovered.sum())} point(s) were measured in a session without lamp checks; "
                        "their lamp drift is not corrected")
    if (outside & rows_all).any():
        warnings.append(f"{int((outside & rows_all).sum())} point(s) lie outside the span of their session's lamp "
                        "checks (an interrupted session); the nearest check corrects them")
    value = rate / drift
    scaled = {name: c / drift for name, c in budget_all.items()}
    flicker = math.sqrt(flicker_var) * np.sqrt(check_exposure / exposure) / np.sqrt(frames)
    scaled["lamp_flicker"] = np.abs(value) * flicker
    scaled["lamp_drift"] = np.abs(value) * drift_sigma
    consistency["flicker_relative_at_check_exposure"] = math.sqrt(flicker_var)
    consistency["flicker_dof"] = dof
    return value, scaled, _labels(list(zip(sessions, interval)))


def _flicker_from_repeats(points, rows, value, budget, exposure, warnings) -> dict[str, np.ndarray]:
    """Unmonitored, no checks: the excess scatter of repeats measures the lamp's flicker."""
    groups = _groups(points, np.flatnonzero(rows))
    ccd = np.sqrt(budget.get("shot_read", budget.get("ccd")) ** 2 + budget.get("dark", 0.0) ** 2)
    frames = np.maximum(points["frames"], 1)
    variance, dof = pooled_excess_variance([value[g] for g in groups.values()], [ccd[g] for g in groups.values()])
    out = dict(budget)
    if dof == 0:
        warnings.append("the lamp's flicker and drift were not measured (no lamp monitor, no [checks] in the "
                        "protocol, no repeats): the stated uncertainties omit them")
        return out
    warnings.append(f"lamp flicker and drift estimated from the scatter of repeats ({dof} degrees of freedom); "
                    "a lamp monitor or [checks] measure them better")
    out["lamp_flicker"] = np.abs(value) * math.sqrt(variance) / np.sqrt(frames)
    return out


def _groups(points, indices: np.ndarray) -> dict[tuple, list[int]]:
    """Rows by planned geometry (theta_i, phi_i, view): the repeats of one geometry."""
    groups: dict[tuple, list[int]] = {}
    for i in indices:
        key = (round(float(points["theta_i"][i]), 6), round(float(points["phi_i"][i]), 6),
               round(float(points["view"][i]), 6))
        groups.setdefault(key, []).append(int(i))
    return groups


def read_readings(folder: str | Path, lamp: str = "auto") -> Readings:
    """Every usable reading of a recording, lamp-normalised, with its own budget.

    Parameters
    ----------
    folder : path
        Recording folder.
    lamp : {"auto", "monitor", "checks", "repeats", "none"}
        How the lamp's flicker and drift are handled: ``"auto"`` uses the monitor when the
        recording has its readings, else the lamp checks, else the scatter of repeats;
        the others force one way (``"none"``: the budget has no lamp term).
    """
    folder = Path(folder)
    return _readings(read_metadata(folder), read_points(folder), lamp)


def _readings(meta: Mapping[str, Any], points: dict[str, np.ndarray], lamp: str = "auto") -> Readings:
    """Lamp-normalised values and budgets of every ok, unsaturated row (sample, reference, checks)."""
    if lamp not in ("auto", "monitor", "checks", "repeats", "none"):
        raise ValueError(f"lamp={lamp!r} is not one of 'auto', 'monitor', 'checks', 'repeats', 'none'")
    ok = points["status"] == "ok"
    saturated = np.array(["saturated" in str(f).split(";") for f in points["flags"]]) | (
        (points["flags"] == "") & (points["saturated"] > 0) & (points["frames_saturated"] < 0))
    usable = ok & ~saturated & np.isfinite(points["signal_rate"])
    camera = CameraModel.from_metadata(meta.get("camera", {}))
    rate = np.asarray(points["signal_rate"], float)
    exposure = np.asarray(points["exposure"], float)
    warnings: list[str] = []
    consistency: dict[str, float] = {}
    if camera is None:
        warnings.append("no camera characterisation in the recording: the CCD noise is estimated from the ROI "
                        "statistics of each frame (component 'ccd')")
    budget = _ccd_budget(points, np.arange(len(rate)), camera)
    monitored = "monitor_dark" in meta and np.isfinite(points["monitor"][usable]).all() and usable.any()
    checked = (usable & (points["block"] == CHECK_BLOCK)).any()
    sessions = np.where(points["session"] >= 0, points["session"], 0)
    if lamp == "auto":
        lamp = "monitor" if monitored else ("checks" if checked else "repeats")
    if (lamp == "monitor" and not monitored) or (lamp == "checks" and not checked):
        raise ValueError(f"lamp={lamp!r}: the recording has no {'monitor readings' if lamp == 'monitor' else 'lamp checks'}")
    if lamp == "monitor":
        value, budget = _normalise_by_monitor(points, np.arange(len(rate)), rate, budget, meta["monitor_dark"])
        unit = "DN/s per V of lamp monitor"
    elif lamp == "checks":
        value, budget, drift_labels = _normalise_by_checks(points, usable, rate, budget, sessions, exposure,
                                                           warnings, consistency)
        unit = "DN/s (lamp drift corrected by the checks)"
    elif lamp == "none":
        value, unit = rate, "DN/s"
        warnings.append("the lamp's flicker and drift were left out of the budget on request")
    else:
        sample = usable & (points["block"] != REFERENCE_BLOCK) & (points["block"] != CHECK_BLOCK)
        value = rate
        budget = _flicker_from_repeats(points, sample, value, budget, exposure, warnings)
        unit = "DN/s"
    shared = {"prnu": np.zeros(len(rate), int), "dark": _dark_labels(points), "angle": _arrival_labels(points)}
    if lamp == "checks":
        shared["lamp_drift"] = drift_labels
    return Readings(points, np.flatnonzero(usable), value, budget, warnings, consistency, unit, shared)


def _labels(keys: list) -> np.ndarray:
    """Integer label per row for hashable keys (equal keys, equal labels)."""
    table: dict = {}
    return np.array([table.setdefault(k, len(table)) for k in keys], int)


def _dark_labels(points) -> np.ndarray:
    """Rows that subtracted the same dark frame (same session, exposure, ROI size and level)."""
    return _labels(list(zip(points["session"], points["exposure"], points["roi_pixels"], points["dark_mean"])))


def _arrival_labels(points) -> np.ndarray:
    """Rows measured at one stage arrival: consecutive rows of one planned geometry.

    Any other row in between (another geometry, a check, a failed attempt) means the stage
    moved, and the readback's quantisation error is drawn anew.
    """
    previous, arrival, out = None, -1, []
    for k in range(len(points["index"])):
        key = (points["session"][k], points["theta_i"][k], points["phi_i"][k], points["view"][k], points["status"][k])
        if key != previous or points["status"][k] != "ok":
            arrival += 1
        previous = key
        out.append(arrival)
    return np.array(out, int)


_AXES = ((0, 2), (1, 3), (2, 1))  # (column of the geometry array, stage axis): theta_i, phi_i, view


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
    for column, _ in _AXES:
        others = np.delete(geometry, column, axis=1)
        if column == 0:
            cos_i = np.cos(np.radians(geometry[:, 0]))
            g = values / np.where(cos_i > 1e-9, cos_i, np.nan)
            g_slope = np.nan_to_num(local_slopes(geometry[:, 0], others, np.nan_to_num(g)))
            slopes[:, 0] = -np.radians(1.0) * np.sin(np.radians(geometry[:, 0])) * np.nan_to_num(g) + cos_i * g_slope
        else:
            slopes[:, column] = local_slopes(geometry[:, column], others, values)
    return slopes


def _scatter_fraction(labels: np.ndarray) -> float:
    """Share of a component's variance that shows in the scatter of readings about their mean.

    A component common to blocks of readings (``labels`` name the blocks) adds
    ``u^2 (n - sum(m_b^2) / n) / (n - 1)`` to the expected sample variance of ``n``
    readings in blocks of sizes ``m_b``: all of ``u^2`` when every reading has its own
    value, nothing when all share one.
    """
    n = len(labels)
    if n < 2:
        return 1.0
    _, sizes = np.unique(labels, return_counts=True)
    return float((n - np.sum(sizes**2) / n) / (n - 1))


def _combine(members: np.ndarray, value: np.ndarray, budget: Mapping[str, np.ndarray],
             shared: Mapping[str, np.ndarray] | None = None) -> tuple[float, dict[str, float], float, np.ndarray]:
    """Inverse-variance mean of readings with each component combined by its correlations.

    Parameters
    ----------
    members : array of int
        Rows to combine.
    value : array
        Value of every row.
    budget : mapping of str to array
        Standard uncertainty of every row by component.
    shared : mapping of str to array, optional
        For components common to blocks of readings, a block label per row (PRNU: one
        window for all repeats; dark: readings using the same dark frame; angle: readings
        made without moving the stage in between; lamp drift: readings between the same
        two checks). A component of one block adds linearly within it and in quadrature
        across blocks; components not listed are independent per reading.

    Returns
    -------
    mean : float
    components : dict of float
        Standard uncertainty of the mean by component.
    chi2 : float
        Chi-square of the readings about the mean with the part of the budget that
        varies between them (:func:`_scatter_fraction`).
    varying : numpy.ndarray
        That part per reading (the repeat scatter it predicts).
    """
    shared = shared or {}
    fractions = {name: _scatter_fraction(shared[name][members]) if name in shared else 1.0 for name in budget}
    varying = np.sqrt(sum(fractions[name] * budget[name][members] ** 2 for name in budget))
    weights = np.where(varying > 0, 1.0 / np.maximum(varying, 1e-300) ** 2, 1.0) if np.all(varying > 0) \
        else np.ones(len(members))
    weights = weights / weights.sum()
    mean = float(np.sum(weights * value[members]))
    out = {}
    for name, u in budget.items():
        contribution = weights * u[members]
        if name in shared:
            _, block = np.unique(shared[name][members], return_inverse=True)
            contribution = np.bincount(block.ravel(), weights=contribution)
        out[name] = float(np.sqrt(np.sum(contribution**2)))
    chi2 = float(np.sum(((value[members] - mean) / np.where(varying > 0, varying, np.inf)) ** 2)) if len(members) > 1 else 0.0
    return mean, out, chi2, varying


def _readback(points) -> np.ndarray:
    """(theta_i, phi_i, view) of every row from the stage readback (the plan where missing)."""
    return np.stack([_readback_or_plan(points, "stage_lamp_theta", "theta_i"),
                     _readback_or_plan(points, "stage_lamp_phi", "phi_i"),
                     _readback_or_plan(points, "stage_camera", "view")], axis=1)


def _combine_groups(groups: list[np.ndarray], rows: Readings, readback: np.ndarray, resolution: Mapping[int, float]):
    """Combine the readings of each planned geometry at their mean readback geometry.

    Repeats of a geometry sit at slightly different real angles (the stage's
    repeatability; the readback records them). Each reading is moved to the group's mean
    readback geometry with the local slopes of the measured curve
    (:func:`geometry_slopes`) before the readings are combined and their scatter compared
    with their budget, so that the repeat statistics measure noise, not stage positions.
    What remains of the angles is the readback's quantisation, which enters every
    reading's budget as ``angle = |slope| * resolution / sqrt(12)`` per axis.

    Returns
    -------
    geometry, values, budget, counts, repeat_statistics
    """
    geometry = np.array([readback[m].mean(axis=0) for m in groups])
    counts = np.array([len(m) for m in groups], int)
    first = np.array([_combine(m, rows.value, rows.budget, rows.shared)[0] for m in groups])
    slopes = geometry_slopes(geometry, first)
    q = np.array([quantisation_sigma(resolution.get(axis, _DEFAULT_RESOLUTION)) for _, axis in _AXES])
    budget = dict(rows.budget, angle=np.zeros(len(rows.value)))
    corrected = rows.value.copy()
    for g, members in enumerate(groups):
        corrected[members] -= (readback[members] - geometry[g]) @ slopes[g]
        budget["angle"][members] = math.sqrt(float(np.sum((slopes[g] * q) ** 2)))
    values, parts, stats = [], [], []
    for g, members in enumerate(groups):
        mean, components, chi2, varying = _combine(members, corrected, budget, rows.shared)
        values.append(mean)
        parts.append(components)
        if len(members) > 1:
            stats.append({"geometry": geometry[g].tolist(), "n": int(len(members)), "chi2": chi2,
                          "observed_std": float(np.std(corrected[members], ddof=1)),
                          "stated_std": float(np.sqrt(np.mean(varying**2)))})
    combined = {name: np.array([p[name] for p in parts]) for name in budget}
    return geometry, np.array(values), combined, counts, stats


def _reference(rows: Readings, protocol, aperture) -> tuple[float | None, float | None, dict[str, float], dict]:
    """E_0 from the reference standard, reduced like the sample, with its budget (relative)."""
    p = rows.points
    ref = rows.index[p["block"][rows.index] == REFERENCE_BLOCK]
    if ref.size == 0 or protocol is None or protocol.reference is None:
        return None, None, {}, {}
    from .instrument import aperture_averaged

    standard = protocol.reference
    lamp_sr, camera_sr = aperture if aperture is not None else (1e-12, 1e-12)
    theta_i = _readback_or_plan(p, "stage_lamp_theta", "theta_i")[ref]
    phi_i = _readback_or_plan(p, "stage_lamp_phi", "phi_i")[ref]
    view = _readback_or_plan(p, "stage_camera", "view")[ref]
    model = aperture_averaged("lambert", lamp_sr, camera_sr)
    expected = model(theta_i, phi_i, np.abs(view), np.where(view >= 0, phi_i * 0, 180.0),
                     rho=standard.reflectance) * np.cos(np.radians(theta_i))
    e0 = rows.value[ref] / expected
    components = {n: c[ref] / expected for n, c in rows.budget.items()}
    shared = {n: labels[ref] for n, labels in rows.shared.items() if n != "prnu"}  # a window per geometry
    mean, parts, chi2, _ = _combine(np.arange(ref.size), e0, components, shared)
    relative = {f"reference {n}": v / mean for n, v in parts.items() if v > 0}
    relative["certificate"] = standard.reflectance_uncertainty
    relative["angular behaviour"] = standard.angular_uncertainty
    consistency = {"reference_reduced_chi2": chi2 / (ref.size - 1)} if ref.size > 1 else {}
    total = mean * math.sqrt(sum(v**2 for v in relative.values()))
    return float(mean), float(total), {k: float(v) for k, v in relative.items()}, consistency


def reduce_recording(folder: str | Path, lamp: str = "auto") -> Reduced:
    """Reduce a recording to radiance per geometry with an uncertainty budget.

    Parameters
    ----------
    folder : path
        Recording folder (:mod:`gonio.data`).
    lamp : str
        How the lamp's flicker and drift are handled (see :func:`read_readings`).

    Returns
    -------
    Reduced

    Raises
    ------
    gonio.data.RecordingError
        Unreadable files, or a point recorded twice (a recording that mixes runs).
    ValueError
        No successfully measured sample point.

    Notes
    -----
    Repeats of a planned geometry are combined by inverse-variance weights
    (:func:`_combine`) at their mean readback geometry. Points that were refused or
    failed are ignored (they stay in the recording); saturated points are excluded and
    counted in ``excluded``; values at or below three standard deviations of their own
    noise are kept and flagged ``low_signal``.
    """
    folder = Path(folder)
    meta = read_metadata(folder)
    points = read_points(folder)
    duplicates = duplicated_rows(read_points(folder, as_arrays=False))
    if duplicates:
        from .data import RecordingError, _describe_duplicates

        raise RecordingError(_describe_duplicates(folder, duplicates))
    protocol_text = meta.get("protocol", {}).get("text")
    protocol = loads(protocol_text, source=str(folder / "metadata.json")) if protocol_text else None
    aperture = _aperture(meta, protocol)
    rows = _readings(meta, points, lamp)
    reference, reference_sigma, calibration, ref_consistency = _reference(rows, protocol, aperture)
    sample = rows.index[(points["block"][rows.index] != REFERENCE_BLOCK) & (points["block"][rows.index] != CHECK_BLOCK)]
    if sample.size == 0:
        raise ValueError(f"{folder}: the recording holds no successfully measured, unsaturated sample points")
    groups = _groups(points, sample)
    keys = sorted(groups)
    resolution = {int(k): float(v) for k, v in meta.get("stage", {}).get("encoder_resolution_deg", {}).items()}
    combined = _combine_groups([np.array(groups[k]) for k in keys], rows, _readback(points), resolution)
    geometry, values, budget, counts, repeat_stats = combined
    pixels = np.array([points["roi_pixels"][groups[k][0]] for k in keys], float)
    window = np.clip(1.0 / pixels - 1.0 / float(np.max(points["roi_pixels"])), 0.0, None)  # as ccd_components
    total = np.sqrt(sum(b**2 for b in budget.values()))
    flags = np.where(values <= LOW_SIGNAL_SIGMAS * total, "low_signal", "").astype(object)
    consistency = dict(rows.consistency)
    consistency.update(ref_consistency)
    dof = sum(r["n"] - 1 for r in repeat_stats)
    if dof:
        consistency["repeats_reduced_chi2"] = sum(r["chi2"] for r in repeat_stats) / dof
    excluded = _excluded(points)
    ti, pi_, view = geometry[:, 0], geometry[:, 1], geometry[:, 2]
    label = meta.get("sample", {}).get("label", folder.name)
    return Reduced(
        theta_i=ti, phi_i=pi_, theta_r=np.abs(view), phi_r=np.where(view >= 0, 0.0, 180.0), view=view,
        radiance=values, radiance_sigma=total,
        repeats=np.array(counts, int), reference_irradiance=reference, reference_irradiance_sigma=reference_sigma,
        label=label,
        metadata={"recording": str(folder), "protocol": meta.get("protocol", {}).get("name"),
                  "planned_view": [k[2] for k in keys],
                  **({"aperture_sr": [float(a) for a in aperture]} if aperture else {})},
        budget=budget, calibration=calibration, flags=flags, excluded=excluded,
        warnings=tuple(rows.warnings), consistency=consistency, unit=rows.unit, repeat_statistics=tuple(repeat_stats),
        window=window,
    )


def _excluded(points) -> dict[str, int]:
    sample = (points["status"] == "ok") & (points["block"] != REFERENCE_BLOCK) & (points["block"] != CHECK_BLOCK)
    saturated = np.array(["saturated" in str(f).split(";") for f in points["flags"]]) & sample
    return {"saturated": int(saturated.sum())} if saturated.any() else {}


def _aperture(meta: Mapping[str, Any], protocol) -> list[float] | None:
    aperture = meta.get("rig", {}).get("aperture_sr")
    if aperture is None and protocol is not None:
        aperture = [protocol.rig.lamp_solid_angle, protocol.rig.camera_solid_angle]
    if aperture is not None and min(aperture) <= 0:
        return None  # ideal point apertures: fit the model itself
    return aperture


def combine_reduced(parts: "list[Reduced]", label: str | None = None) -> Reduced:
    """Join reduced recordings of one sample (e.g. in-plane and off-plane runs).

    The geometries and budgets are concatenated; the reference irradiances, when present,
    are combined by their inverse-variance weighted mean (the runs must share lamp,
    voltage, monitor and camera settings for their relative radiances to be comparable);
    the calibration's certificate and angular components are common to the runs and are
    not averaged down.
    """
    if not parts:
        raise ValueError("combine_reduced needs at least one reduced recording")
    apertures = {tuple(p.metadata.get("aperture_sr", ())) for p in parts}
    if len(apertures) > 1:
        raise ValueError(f"cannot combine recordings measured through different apertures: {sorted(apertures)}")
    units = {p.unit for p in parts}
    if len(units) > 1:
        raise ValueError(f"cannot combine recordings in different units: {sorted(units)}")
    cat = lambda name: np.concatenate([getattr(p, name) for p in parts])  # noqa: E731
    names = sorted({n for p in parts for n in p.budget})
    budget = {n: np.concatenate([p.budget.get(n, np.zeros(len(p.radiance))) for p in parts]) for n in names}
    refs = [p for p in parts if p.reference_irradiance is not None]
    irradiance = sigma = None
    calibration: dict[str, float] = {}
    if refs:
        common = ("certificate", "angular behaviour")
        statistical = [p.reference_irradiance * math.sqrt(sum(v**2 for k, v in p.calibration.items() if k not in common))
                       for p in refs]
        weights = np.array([1.0 / max(s, 1e-300) ** 2 for s in statistical])
        irradiance = float(np.sum(weights * np.array([p.reference_irradiance for p in refs])) / np.sum(weights))
        calibration["reference (combined)"] = float(1.0 / math.sqrt(np.sum(weights)) / irradiance)
        for key in common:
            calibration[key] = max(p.calibration.get(key, 0.0) for p in refs)
        sigma = irradiance * math.sqrt(sum(v**2 for v in calibration.values()))
    consistency = {f"{k} ({p.metadata.get('protocol')})": v for p in parts for k, v in p.consistency.items()}
    return Reduced(
        theta_i=cat("theta_i"), phi_i=cat("phi_i"), theta_r=cat("theta_r"), phi_r=cat("phi_r"), view=cat("view"),
        radiance=cat("radiance"), radiance_sigma=cat("radiance_sigma"), repeats=cat("repeats"),
        reference_irradiance=irradiance, reference_irradiance_sigma=sigma,
        label=label or parts[0].label,
        metadata={"recordings": [p.metadata.get("recording") for p in parts],
                  "planned_view": [v for p in parts for v in p.metadata.get("planned_view", list(p.view))],
                  **({"aperture_sr": parts[0].metadata["aperture_sr"]} if "aperture_sr" in parts[0].metadata else {})},
        budget=budget, calibration=calibration,
        flags=np.concatenate([p.flags if p.flags is not None else np.full(len(p.radiance), "", object) for p in parts]),
        excluded={k: sum(p.excluded.get(k, 0) for p in parts) for k in {k for p in parts for k in p.excluded}},
        warnings=tuple(dict.fromkeys(w for p in parts for w in p.warnings)), consistency=consistency,
        unit=parts[0].unit,
        window=None if any(p.window is None for p in parts) else np.concatenate([p.window for p in parts]),
    )
