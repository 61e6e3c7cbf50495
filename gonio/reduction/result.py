"""The reduced recording: values, their budget and covariance, and the datasets fits use."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..uncertainty import COMPONENTS

__all__ = ["Reduced", "SATURATED_MAJORITY", "LOW_SIGNAL_SIGMAS", "REDUCTION_FORMAT"]

#: A fit is refused when more than this fraction of the sample points saturated.
SATURATED_MAJORITY = 0.5


#: A value at or below this many standard uncertainties is flagged ``low_signal`` (kept).
LOW_SIGNAL_SIGMAS = 3.0


#: Marks a budget.json written by :meth:`Reduced.write`.
REDUCTION_FORMAT = "gonio reduction 1"


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

        from ..files import write_atomic

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
        from ..fitting import Dataset

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
        from ..fitting import Dataset

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
        from ..fitting import Dataset

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
        from ..fitting import Normal

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
