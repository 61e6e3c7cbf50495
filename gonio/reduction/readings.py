"""Every reading of a recording, divided by the lamp, with its own uncertainty budget."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..data import read_metadata, read_points
from ..uncertainty import (
    CameraModel,
    LinearityCorrection,
    ccd_components,
    interpolate_drift,
    interpolation_excess,
    monitor_ratio_variance,
    pooled_excess_variance,
    texture_relative,
)
from .geometry import planned_groups, readback_geometry, geometry_slopes

__all__ = ["Readings", "read_readings", "REFERENCE_BLOCK", "CHECK_BLOCK"]

#: Block name under which reference-standard points are recorded.
REFERENCE_BLOCK = "reference standard"


#: Block name under which lamp-check points are recorded.
CHECK_BLOCK = "lamp check"


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
        (see :func:`combine`).
    linearity : LinearityCorrection or None
        The camera's linearity correction applied to every row (None: not applied).
    linearity_jacobian : numpy.ndarray or None
        Relative sensitivity of every row's value to the correction's coefficients, shape
        (rows, 2) (:meth:`~gonio.uncertainty.LinearityCorrection.jacobian`).
    """

    points: dict[str, np.ndarray]
    index: np.ndarray
    value: np.ndarray
    budget: dict[str, np.ndarray]
    warnings: list[str]
    consistency: dict[str, float]
    unit: str
    shared: dict[str, np.ndarray] = field(default_factory=dict)
    linearity: LinearityCorrection | None = None
    linearity_jacobian: np.ndarray | None = None

    def column(self, name: str) -> np.ndarray:
        """A points.csv column at the usable readings."""
        return self.points[name][self.index]

    def sigma(self) -> np.ndarray:
        """Total standard uncertainty of each usable reading [``unit``]."""
        return np.sqrt(sum(c[self.index] ** 2 for c in self.budget.values()))


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
    readback = readback_geometry(points)
    rows = np.flatnonzero(usable & (points["block"] != REFERENCE_BLOCK))
    groups = planned_groups(points, rows)
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
    groups = planned_groups(points, np.flatnonzero(rows))
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


def read_readings(folder: str | Path, lamp: str = "auto", linearity: bool = True) -> Readings:
    """Every usable reading of a recording, lamp-normalised, with its own budget.

    Parameters
    ----------
    folder : path
        Recording folder.
    lamp : {"auto", "monitor", "checks", "repeats", "none"}
        How the lamp's flicker and drift are handled: ``"auto"`` uses the monitor when the
        recording has its readings, else the lamp checks, else the scatter of repeats;
        the others force one way (``"none"``: the budget has no lamp term).
    linearity : bool
        Correct every reading by the camera's linearity characterisation when the
        recording has one (:func:`correct_linearity`).
    """
    folder = Path(folder)
    return readings_of(read_metadata(folder), read_points(folder), lamp, linearity)


def correct_linearity(meta: Mapping[str, Any], points, rate: np.ndarray, budget: dict[str, np.ndarray],
                      usable: np.ndarray, warnings: list[str], apply: bool = True
                      ) -> tuple[np.ndarray, dict[str, np.ndarray], LinearityCorrection | None, np.ndarray | None]:
    """Every reading corrected by the camera's linearity (:class:`~gonio.uncertainty.LinearityCorrection`).

    The correction acts on each reading's signal ``S = roi_mean - dark_mean`` [DN]: the
    rate is multiplied by ``1 + c1 x + c2 x^2`` and every budget component, an error of
    ``S`` (shot and read noise, dark level, PRNU), by the correction's slope
    ``dS_linear / dS = 1 + 2 c1 x + 3 c2 x^2``. Returns the
    rate, the budget, the correction (None when the recording has none or ``apply`` is
    False, both said in ``warnings``) and the rows' sensitivity to its coefficients.
    Readings above the series' top are corrected by extrapolation and counted in a warning.
    """
    camera = meta.get("camera", {})
    series = camera.get("linearity")
    reason = series.get("error") if isinstance(series, Mapping) else None  # why a series failed
    try:
        correction = LinearityCorrection.from_metadata(camera) if apply else None
    except ValueError as error:  # a record that cannot be read: said as such, not as a missing one
        correction, reason = None, str(error)
    if correction is None:
        if not apply:
            warnings.append("the camera's linearity correction was left out on request")
        elif reason is not None or (camera and "system_gain_dn_per_e" in camera):
            warnings.append("readings not corrected for the camera's non-linearity: "
                            f"{reason or 'the recording has no linearity series'}")
        return rate, budget, None, None
    signal = np.asarray(points["roi_mean"], float) - np.asarray(points["dark_mean"], float)
    factor = correction.factor(signal)
    above = usable & (signal > 1.05 * correction.signal_range)
    if above.any():
        warnings.append(f"{int(above.sum())} reading(s) above the top of the linearity series "
                        f"({correction.signal_range:.0f} DN): their correction is extrapolated")
    slope = correction.slope(signal)
    return rate * factor, {name: c * slope for name, c in budget.items()}, correction, correction.jacobian(signal)


def readings_of(meta: Mapping[str, Any], points: dict[str, np.ndarray], lamp: str = "auto",
                linearity: bool = True) -> Readings:
    """Lamp-normalised values and budgets of every ok, unsaturated row (sample, reference, checks),
    corrected for the camera's linearity (unless ``linearity`` is False)."""
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
    rate, budget, correction, jacobian = correct_linearity(meta, points, rate, budget, usable, warnings, linearity)
    monitored = "monitor_dark" in meta and np.isfinite(points["monitor"][usable]).all() and usable.any()
    checked = (usable & (points["block"] == CHECK_BLOCK)).any()
    sessions = _segments(points)
    if lamp == "auto":
        lamp = "monitor" if monitored else ("checks" if checked else "repeats")
    if (lamp == "monitor" and not monitored) or (lamp == "checks" and not checked):
        raise ValueError(f"lamp={lamp!r}: the recording has no {'monitor readings' if lamp == 'monitor' else 'lamp checks'}")
    if lamp == "monitor":
        value, budget = _normalise_by_monitor(points, np.arange(len(rate)), rate, budget, meta["monitor_dark"])
        budget["monitor_ratio"] = _monitor_ratio(meta, camera, value, points, warnings, consistency)
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
    texture = _texture(meta, value, points, usable, warnings, consistency)
    if texture is not None:
        budget["texture"], shared["texture"] = texture, np.zeros(len(rate), int)  # one sample, one window
    return Readings(points, np.flatnonzero(usable), value, budget, warnings, consistency, unit, shared,
                    correction, jacobian)


def _monitor_ratio(meta: Mapping[str, Any], camera: CameraModel | None, value: np.ndarray, points,
                   warnings: list[str], consistency: dict[str, float]) -> np.ndarray:
    """Every reading's ``monitor_ratio`` component: the lamp's fluctuation the monitor does not
    see, relative ``sqrt(v / frames)`` with ``v`` from the mountings' monitor series
    (:func:`~gonio.uncertainty.monitor_ratio_variance`); 0 (and a warning) without a series."""
    from drivers.monitor import MonitorDark

    dark = MonitorDark.from_dict(meta["monitor_dark"])
    variance, dof = monitor_ratio_variance(meta.get("mountings", {}), camera, dark.noise, dark.offset)
    if dof == 0:
        warnings.append("the lamp monitor's ratio to the sample's irradiance was not measured (no monitor series "
                        "in the recording): what the monitor does not see of the lamp is not in the budget")
        return np.zeros(len(value))
    consistency["monitor_ratio_relative"] = math.sqrt(variance)
    consistency["monitor_ratio_dof"] = float(dof)
    return np.abs(value) * math.sqrt(variance) / np.sqrt(np.maximum(points["frames"], 1))


def _texture(meta: Mapping[str, Any], value: np.ndarray, points, usable: np.ndarray, warnings: list[str],
             consistency: dict[str, float]) -> np.ndarray | None:
    """Every sample reading's ``texture`` component (0 for the reference standard and the lamp
    checks): the window mean's relative uncertainty from the sample's texture, from the
    mountings' images (:func:`~gonio.uncertainty.texture_relative`); None, with a warning,
    when the recording has no image."""
    sample = usable & (points["block"] != REFERENCE_BLOCK) & (points["block"] != CHECK_BLOCK)
    if not sample.any():
        return None
    estimate = texture_relative(meta.get("mountings", {}))
    if estimate is None:
        warnings.append("the sample's texture was not measured (no image of the window in the recording): how much "
                        "the window's mean differs from the sample's mean reflectance is not in the budget")
        return None
    relative, images = estimate
    consistency["texture_relative"] = relative
    consistency["texture_images"] = float(images)
    return np.where(sample, np.abs(value) * relative, 0.0)


def _segments(points) -> np.ndarray:
    """A label per row for the stretches of a recording over which the lamp checks see one
    level: a session, within it a mounting of the sample (the checks measure the sample,
    whose level changes when it is remounted). Rows without a mounting (the reference
    standard) belong to the mounting of the row before them, whose checks bracket them."""
    session = np.where(points["session"] >= 0, points["session"], 0)
    mounting = np.asarray(points["mounting"], int).copy()
    for k in range(len(mounting)):
        if mounting[k] < 0:
            mounting[k] = mounting[k - 1] if k > 0 else 0
    return _labels(list(zip(session.tolist(), mounting.tolist())))


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
