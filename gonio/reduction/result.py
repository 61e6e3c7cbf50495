"""The reduced recording: values, their budget and covariance, and the datasets fits use."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from ..uncertainty import COMPONENTS, LinearityCorrection
from .brdf_table import BRDF_COVARIANCE, BRDF_TABLE, brdf_table_text, csv_text

if TYPE_CHECKING:  # gonio.fitting imports the reduction's results: imported where used
    from ..fitting import Dataset, LowRankCovariance, Prior

__all__ = ["Reduced", "IncidenceCalibration", "CALIBRATIONS", "COMMON_CALIBRATION", "ANGULAR_BEHAVIOUR",
           "SATURATED_MAJORITY", "LOW_SIGNAL_SIGMAS", "REDUCTION_FORMAT", "REDUCED_TABLE", "REDUCED_BUDGET",
           "is_whole_reduction", "BRDF_TABLE", "BRDF_COVARIANCE"]

#: A fit is refused when more than this fraction of the sample points saturated.
SATURATED_MAJORITY = 0.5


#: A value at or below this many standard uncertainties is flagged ``low_signal`` (kept).
LOW_SIGNAL_SIGMAS = 3.0


#: Marks a budget.json written by :meth:`Reduced.write`.
REDUCTION_FORMAT = "gonio reduction 1"
#: The files of a reduction folder: the table, then the budget that lists it.
REDUCED_TABLE, REDUCED_BUDGET = "reduced.csv", "budget.json"


def is_whole_reduction(folder: str | Path) -> bool:
    """Whether ``folder`` holds one whole reduction :meth:`Reduced.write` wrote: a
    ``budget.json`` of :data:`REDUCTION_FORMAT` whose manifest names the SHA-256 of the
    ``reduced.csv`` beside it. A budget that merely claims the format, or a table from
    another reduction (a write interrupted between the two files), is not."""
    import hashlib
    import json

    folder = Path(folder)
    try:
        budget = json.loads((folder / REDUCED_BUDGET).read_text(encoding="utf-8"))
        files = budget.get("files") if isinstance(budget, dict) and budget.get("format") == REDUCTION_FORMAT else None
        if not isinstance(files, dict) or REDUCED_TABLE not in files:
            return False
        return all(hashlib.sha256((folder / name).read_bytes()).hexdigest() == digest for name, digest in files.items()
                   if name in (REDUCED_TABLE, BRDF_TABLE, BRDF_COVARIANCE))
    except (OSError, ValueError, TypeError):
        return False


#: How a recording is calibrated by its reference standard (:meth:`Reduced.fit_inputs`):
#: one lamp irradiance E_0 for every value, or the irradiance measured at each value's
#: lamp polar angle.
CALIBRATIONS = ("common", "per-incidence")
#: The standard's departure from Lambertian (a component of :attr:`Reduced.calibration`):
#: common to every value under one ``E_0``; under a calibration per incidence each ``E_k``
#: carries the departure at its own angle, an error of that angle's values alone.
ANGULAR_BEHAVIOUR = "angular behaviour"
#: Components of the calibration budget common to the values of every recording: the
#: standard's certificate and its departure from Lambertian, as opposed to its readings'
#: noise (joined recordings do not average them down).
COMMON_CALIBRATION = ("certificate", ANGULAR_BEHAVIOUR)
#: Opening of the reduction's warning that the standard's irradiance differs between lamp
#: polar angles (gonio.reduction.recording): a dataset calibrated per incidence drops it.
INCONSISTENT_INCIDENCES = "the reference standard's irradiance differs between lamp polar angles"


@dataclass(frozen=True)
class IncidenceCalibration:
    """The reference standard's readings at one lamp polar angle: the irradiance there.

    A lamp beam that is not uniform lights the camera's window with an irradiance that
    depends on the lamp's polar angle (its footprint stretches by 1/cos(theta_i));
    the standard measured at the same polar angle calibrates it (docs/acquisition.md,
    "Calibration per incidence").

    Attributes
    ----------
    theta_i : float
        The lamp's planned polar angle [deg].
    irradiance : float
        ``E_k`` from the readings at this angle [radiance unit per sr].
    sigma : float
        Relative standard uncertainty of ``E_k`` from its readings' budget [-] (the
        certificate and the standard's departure from Lambertian are not in it:
        :meth:`Reduced._incidence_deviations`).
    weight : float
        Weight of these readings in the common ``E_0`` [-].
    readings : tuple of int
        The readings (indices into ``metadata["reference_standard"]``) and
    reading_weights : tuple of float
        their weights in ``E_k``.
    linearity : numpy.ndarray or None
        Sensitivity of ``E_k`` to the camera's linearity coefficients (as
        :attr:`Reduced.linearity_jacobian`).
    """

    theta_i: float
    irradiance: float
    sigma: float
    weight: float
    readings: tuple[int, ...]
    reading_weights: tuple[float, ...]
    linearity: np.ndarray | None = None


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
    linearity_jacobian : numpy.ndarray or None
        Relative sensitivity of each value to the coefficients of the camera's linearity
        corrections (two per recording), shape (n, P); None when no correction was applied.
    linearity_covariance : numpy.ndarray or None
        Covariance of those coefficients, (P, P).
    reference_linearity : numpy.ndarray or None
        Sensitivity of ``E_0`` to them, (P,): the budget's ``linearity`` component and the
        covariance take each value's sensitivity relative to it (the part common to the
        values and the standard cancels in the calibration).
    incidences : tuple of IncidenceCalibration
        The reference standard's irradiance at each lamp polar angle it was measured at.
    incidence : numpy.ndarray or None
        For each value, its entry in ``incidences`` (-1: no reference at its polar angle).
    mounting_factors : numpy.ndarray or None
        Factors ``F`` (n, r) of the covariance ``F F^T`` the mountings of the sample give the
        values [``unit``] (:func:`gonio.uncertainty.mounting_factors`, scaled by each value
        and divided by the square root of its number of mountings); None when the sample
        was mounted once.
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
    linearity_jacobian: np.ndarray | None = None
    linearity_covariance: np.ndarray | None = None
    reference_linearity: np.ndarray | None = None
    incidences: tuple[IncidenceCalibration, ...] = ()
    incidence: np.ndarray | None = None
    mounting_factors: np.ndarray | None = None

    # -- correlations --------------------------------------------------------------------
    def covariance(self) -> np.ndarray:
        """Covariance matrix of the values' errors [``unit``^2]: :meth:`covariance_factors`
        as the dense (n, n) matrix."""
        return self.covariance_factors().dense()

    def covariance_factors(self) -> "LowRankCovariance":
        """Covariance of the values' errors [``unit``^2] as a diagonal plus low rank
        (:class:`gonio.fitting.covariance.LowRankCovariance`), never forming n x n.

        Every component is independent between values except PRNU, the linearity
        correction, the sample's texture and its mountings. The texture of the sample's
        central area, which every window covers, is one error of every value of the sample:
        values share ``t_i t_j`` (their ``texture`` components; one factor column). The
        mountings' scatter enters as the low-rank covariance :attr:`mounting_factors`
        ``F F^T`` (its diagonal is the ``mounting`` component; values measured in fewer
        mountings than the others keep theirs independent). The camera windows of a
        recording are centred and nested (they shrink with cos(theta_r) along one image
        axis), so the PRNU error of a window relative to the largest one is a random walk
        in the window size: values i and j share ``p^2 x_i x_j min(a_i, a_j)`` with
        ``a = 1/N - 1/N_max`` (:func:`gonio.uncertainty.ccd_components`); values measured
        through the same window (the same |view|) share all of it. ``min(a_i, a_j)`` is a
        sum over the distinct window terms ``l_1 < l_2 < ...``: ``sum_m (l_m - l_m-1)
        [a_i >= l_m] [a_j >= l_m]``, one factor column per distinct window. The linearity
        correction's coefficients are common to every reading: values share ``(x_i d_i) C
        (x_j d_j)^T`` with ``d`` their sensitivity relative to the reference standard's
        (:attr:`reference_linearity`; one column per coefficient). Without window terms,
        texture, mountings and correction there are no columns.
        """
        return self._covariance(self.reference_linearity)

    def _covariance(self, linearity_reference) -> "LowRankCovariance":
        """:meth:`covariance_factors` with the linearity sensitivities taken relative to
        ``linearity_reference`` ((P,) or one row per value)."""
        from ..fitting.covariance import LowRankCovariance

        total = np.asarray(self.radiance_sigma, float)
        columns = [self._prnu_factors(), self._texture_factors()]
        if self.mounting_factors is not None and self.mounting_factors.size:
            columns.append(np.asarray(self.mounting_factors, float).reshape(total.size, -1))
        factors = np.hstack(columns)
        linear = np.asarray(self.budget.get("linearity", np.zeros_like(total)), float)
        independent = total**2 - linear**2 - np.einsum("nk,nk->n", factors, factors)
        if self.linearity_jacobian is not None:
            reference = 0.0 if linearity_reference is None else linearity_reference
            factors = np.hstack([factors, LinearityCorrection.value_factors(
                self.radiance, self.linearity_jacobian - reference, self.linearity_covariance)])
        return LowRankCovariance(independent, factors)

    def _prnu_factors(self) -> np.ndarray:
        """The PRNU's factor columns, one per distinct window term (:meth:`covariance_factors`)."""
        total = np.asarray(self.radiance_sigma, float)
        prnu = np.asarray(self.budget.get("prnu", np.zeros_like(total)), float)
        if self.window is None or not np.any(prnu > 0):
            return np.zeros((total.size, 0))
        a = np.asarray(self.window, float)
        shared = (a > 0) & (prnu > 0)
        per_unit = np.zeros_like(total)  # p x / sqrt(a): the walk's scale for each value
        per_unit[shared] = np.sign(self.radiance[shared]) * prnu[shared] / np.sqrt(a[shared])
        levels = np.unique(a[shared])
        steps = np.sqrt(np.diff(levels, prepend=0.0))
        return np.where(a[:, None] >= levels[None, :], per_unit[:, None] * steps[None, :], 0.0)

    def _texture_factors(self) -> np.ndarray:
        """The texture's factor column (every value's ``texture`` component, signed)."""
        total = np.asarray(self.radiance_sigma, float)
        texture = np.asarray(self.budget.get("texture", np.zeros_like(total)), float)
        if not np.any(texture > 0):
            return np.zeros((total.size, 0))
        return (np.sign(self.radiance) * texture)[:, None]

    # -- the calibration per incidence -----------------------------------------------------
    def _incidence_groups(self) -> np.ndarray:
        """Each value's entry in :attr:`incidences`; ``ValueError`` when a value's lamp polar
        angle has no reference reading (naming the angles, and those that have one)."""
        group = self.incidence if self.incidence is not None else np.full(len(self.radiance), -1)
        if self.reference_irradiance is None or not self.incidences:
            raise ValueError("no reference standard was measured in this recording: it cannot be calibrated per "
                             "incidence (use normalised_radiance() or relative_radiance())")
        missing = sorted({round(float(t), 2) for t in self.theta_i[group < 0]})
        if missing:
            raise ValueError(
                f"calibration per incidence: no reference reading at theta_i = {missing} deg (the standard was "
                f"measured at {sorted(c.theta_i for c in self.incidences)} deg); add [reference] geometries at "
                "those lamp angles to the protocol, or calibrate with one common E_0 (calibration='common')")
        return group

    def _per_incidence(self) -> tuple[np.ndarray, np.ndarray, "LowRankCovariance"]:
        """Each value's factor ``E_0 / E_k``, its group, and the values' covariance with each
        value's linearity sensitivity relative to its own incidence's readings."""
        group = self._incidence_groups()
        factor = self.reference_irradiance / np.array([c.irradiance for c in self.incidences])[group]
        reference = None
        if self.linearity_jacobian is not None:
            reference = np.array([c.linearity for c in self.incidences])[group]
        return factor, group, self._covariance(reference)

    def _incidence_variances(self) -> np.ndarray:
        """Relative variance of each ``E_k`` [-]: its readings' budget and the standard's
        departure from Lambertian at its angle (:data:`ANGULAR_BEHAVIOUR`, taken
        independent between angles: the departure the calibration per incidence absorbs
        into each angle's irradiance)."""
        angular = self.calibration.get(ANGULAR_BEHAVIOUR, 0.0)
        return np.array([c.sigma for c in self.incidences]) ** 2 + angular**2

    def _incidence_deviations(self) -> np.ndarray:
        """Covariance of the relative errors of ``E_k / E_0`` between incidences, (K, K):
        ``delta_kl u_k^2 - W_l u_l^2 - W_k u_k^2 + sum_m W_m^2 u_m^2`` (``W`` the weights of
        the incidences' readings in ``E_0``, ``u`` the relative uncertainties of the ``E_k``,
        :meth:`_incidence_variances`).

        Approximation (docs/acquisition.md, "Calibration per incidence"): the ``E_k`` are
        taken as independent, and ``W`` as their inverse-variance weights, which makes
        these errors uncorrelated with ``E_0``'s, so that the prior on the scale keeps its
        width (:meth:`fit_inputs`). Both hold to first order only: readings at different
        angles can share a dark frame (the same exposure and window) and a lamp-drift
        interval between checks, and ``E_0`` weights its readings by their independent
        components only (:func:`~gonio.reduction.combining.combine`) while ``u_k`` counts
        the shared ones in full."""
        u2 = self._incidence_variances()
        w = np.array([c.weight for c in self.incidences])
        w = w / w.sum()
        return np.diag(u2) - np.add.outer(w * u2, w * u2) + np.sum(w**2 * u2)

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
            "reference_per_incidence": [{"theta_i": c.theta_i, "irradiance": c.irradiance, "sigma_relative": c.sigma,
                                         "weight": c.weight} for c in self.incidences],
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
        if len(self.incidences) > 1:
            parts = ", ".join(f"{c.theta_i:g} deg {c.irradiance / self.reference_irradiance - 1:+.2e} "
                              f"+/- {c.sigma:.1e}" for c in self.incidences)
            lines.append(f"reference per lamp polar angle (E_k / E_0 - 1): {parts}")
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

    def write(self, folder: str | Path, brdf: str | None = None) -> tuple[Path, ...]:
        """Write ``reduced.csv`` (one row per value, every budget component as ``u_<name>``),
        with ``brdf`` (a calibration of :data:`CALIBRATIONS`) also ``brdf.csv`` and
        ``brdf_covariance.npy`` (:func:`gonio.reduction.brdf_table.brdf_table_text`), and
        then ``budget.json`` (:meth:`budget_summary`, the reference irradiance, the repeat
        statistics, and the SHA-256 of every table it belongs to: the folder's manifest,
        :func:`is_whole_reduction`) into ``folder``, each atomically. Returns the paths,
        ``budget.json`` last.

        Raises
        ------
        ValueError
            ``brdf`` given for a recording without a reference standard (naming why).
        """
        import hashlib
        import io
        import json

        from ..files import write_atomic

        folder = Path(folder)
        tables = {REDUCED_TABLE: csv_text(self.table_rows()).encode("utf-8")}
        if brdf is not None:
            text, covariance = brdf_table_text(self, brdf)
            buffer = io.BytesIO()
            np.save(buffer, covariance, allow_pickle=False)
            tables[BRDF_TABLE], tables[BRDF_COVARIANCE] = text.encode("utf-8"), buffer.getvalue()
        summary = {"format": REDUCTION_FORMAT, "label": self.label, "metadata": dict(self.metadata),
                   "reference_irradiance": self.reference_irradiance,
                   "reference_irradiance_sigma": self.reference_irradiance_sigma,
                   **self.budget_summary(), "repeat_statistics": list(self.repeat_statistics),
                   "files": {name: hashlib.sha256(data).hexdigest() for name, data in tables.items()}}
        folder.mkdir(parents=True, exist_ok=True)
        paths = [write_atomic(folder / name, data) for name, data in tables.items()]
        paths.append(write_atomic(folder / REDUCED_BUDGET, json.dumps(summary, indent=2, default=float) + "\n"))
        return tuple(paths)

    def brdf_components(self, calibration: str = "common") -> tuple[Dataset, dict[str, np.ndarray]]:
        """The absolute BRDF (:meth:`brdf`) and its standard uncertainty by component [1/sr].

        Every radiance component of :attr:`budget` divided by the value's calibration
        factor ``E cos(theta_i)``, and ``calibration``: the reference standard's part
        (``f u_cal`` with ``u_cal`` the relative uncertainty of ``E_0``, or of the
        irradiance at the value's lamp polar angle and the certificate, per incidence).
        ``linearity`` is the correction's part relative to the standard's readings that
        calibrate the value. The components add in quadrature to the dataset's ``sigma``.
        """
        data = self.brdf(calibration)
        scale = self.radiance / data.value
        components = {name: np.asarray(values, float) / np.abs(scale) for name, values in self.budget.items()}
        if _calibration(calibration) == "per-incidence":
            group = self._incidence_groups()
            common = sum(self.calibration.get(k, 0.0) ** 2 for k in COMMON_CALIBRATION if k != ANGULAR_BEHAVIOUR)
            relative = np.sqrt(self._incidence_variances()[group] + common)
            radiance_covariance = self._per_incidence()[2]
        else:
            relative = np.full(data.n, self.reference_irradiance_sigma / self.reference_irradiance)
            radiance_covariance = self.covariance_factors()
        if "linearity" in components:
            total, linear = np.asarray(self.radiance_sigma, float), np.asarray(self.budget["linearity"], float)
            own = radiance_covariance.variance() - total**2 + linear**2  # the correction's variance in this calibration
            components["linearity"] = np.sqrt(np.maximum(own, 0.0)) / np.abs(scale)
        components["calibration"] = np.abs(data.value) * relative
        return data, components

    def _dataset_metadata(self, calibration: str = "common", group: np.ndarray | None = None) -> dict[str, Any]:
        """The metadata a dataset carries; calibrated per incidence, with each value's
        ``incidence_theta_i``: the planned lamp polar angle [deg] of the reference readings
        that calibrate it (``group``, its entries in :attr:`incidences`), which a fit of the
        rig's errors calibrates it by (:func:`gonio.fitting.rig_errors.incidence_weights`)."""
        out = {k: v for k, v in self.metadata.items() if k not in ("planned_view", "planned_theta_i")}
        if calibration != "common":
            out["calibration"] = calibration
            out["incidence_theta_i"] = [float(self.incidences[g].theta_i) for g in group]
        out["uncertainty_budget"] = {k: v["median_relative"] for k, v in self.budget_summary()["components"].items()}
        if self.calibration:
            out["calibration_budget"] = dict(self.calibration)
        if self.excluded:
            out["excluded"] = dict(self.excluded)
        warnings = [w for w in self.warnings if calibration == "common" or not w.startswith(INCONSISTENT_INCIDENCES)]
        if warnings:
            out["reduction_warnings"] = warnings
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
    def relative_radiance(self, calibration: str = "common") -> Dataset:
        """Dataset of relative radiance (quantity ``'radiance'``: fit with a free scale).

        With ``calibration="per-incidence"`` every value is brought to the common level by
        the reference standard read at its lamp polar angle, ``L E_0 / E_k``; the
        covariance adds the errors of ``E_k / E_0`` (common to the values of one angle,
        :meth:`_incidence_deviations`), so that a prior on the scale from ``E_0``
        (:meth:`fit_inputs`) keeps its meaning.
        """
        from ..fitting import Dataset

        self._require_usable()
        value, covariance, metadata = self.radiance, self.covariance_factors(), self._dataset_metadata()
        if _calibration(calibration) == "per-incidence":
            factor, group, covariance = self._per_incidence()
            value = self.radiance * factor
            shared = value[:, None] * _square_root(self._incidence_deviations())[group]
            covariance = covariance.scaled(factor).with_factors(shared)
            metadata = self._dataset_metadata(calibration, group)
        return Dataset(self.theta_i, self.phi_i, self.theta_r, self.phi_r, value, np.sqrt(covariance.variance()),
                       quantity="radiance", label=self.label, metadata=metadata, covariance=covariance)

    def normalised_radiance(self) -> Dataset:
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
        informative = keep != k0  # the normal-view points are 1 by construction: no data
        keep, k0, x0, value = keep[informative], k0[informative], x0[informative], value[informative]
        covariance = _ratio_covariance(self.covariance_factors(), keep, k0, x0, value)
        return Dataset(self.theta_i[keep], self.phi_i[keep], self.theta_r[keep], self.phi_r[keep], value,
                       np.sqrt(covariance.variance()),
                       quantity="normalised_radiance", label=self.label, metadata=self._dataset_metadata(),
                       covariance=covariance)

    def brdf(self, calibration: str = "common") -> Dataset:
        """Dataset of absolute BRDF [1/sr], calibrated by the reference standard.

        ``f = L / (E_0 cos theta_i)``; the covariance adds the calibration's relative
        uncertainty as an error common to all points (``f_i f_j u_cal^2``), so a fit of
        this dataset does not average it away (:meth:`fit_inputs` puts it into one prior
        on the scale instead, which is equivalent). With ``calibration="per-incidence"``,
        ``f = L / (E_k cos theta_i)`` with the irradiance ``E_k`` the standard gave at the
        value's lamp polar angle: its readings' error and the standard's departure from
        Lambertian there are common to the values of that angle, the certificate to all.
        """
        from ..fitting import Dataset

        if self.reference_irradiance is None:
            raise ValueError("no reference standard was measured in this recording: absolute BRDF "
                             "is not available (use normalised_radiance() or relative_radiance())")
        self._require_usable()
        cos_i = np.cos(np.radians(self.theta_i))
        if _calibration(calibration) == "per-incidence":
            factor, group, covariance = self._per_incidence()
            scale = self.reference_irradiance / factor * cos_i
            value = self.radiance / scale
            common = sum(self.calibration.get(k, 0.0) ** 2 for k in COMMON_CALIBRATION if k != ANGULAR_BEHAVIOUR)
            u2 = self._incidence_variances()
            # the irradiance at the value's angle (one column per angle) and the certificate
            shared = np.hstack([value[:, None] * np.sqrt(u2)[None, :] * np.equal.outer(group, np.arange(u2.size)),
                                value[:, None] * math.sqrt(common)])
            covariance = covariance.scaled(1.0 / scale).with_factors(shared)
            return Dataset(self.theta_i, self.phi_i, self.theta_r, self.phi_r, value, np.sqrt(covariance.variance()),
                           quantity="brdf", label=self.label, metadata=self._dataset_metadata(calibration, group),
                           covariance=covariance)
        scale = self.reference_irradiance * cos_i
        value = self.radiance / scale
        rel_cal = self.reference_irradiance_sigma / self.reference_irradiance
        covariance = self.covariance_factors().scaled(1.0 / scale).with_factors(value * rel_cal)
        return Dataset(self.theta_i, self.phi_i, self.theta_r, self.phi_r, value, np.sqrt(covariance.variance()),
                       quantity="brdf", label=self.label, metadata=self._dataset_metadata(), covariance=covariance)

    def best_dataset(self) -> Dataset:
        """Absolute BRDF when calibrated, else normalised radiance."""
        return self.brdf() if self.reference_irradiance is not None else self.normalised_radiance()

    def fit_inputs(self, calibration: str = "common") -> tuple[Dataset, dict[str, Prior]]:
        """The dataset and priors a fit of this recording should use.

        With a reference standard: relative radiance, whose ``scale`` (the lamp irradiance
        E_0 in the recording's units) gets a Gaussian prior centred on the reference
        estimate with the calibration budget's total uncertainty as its width. The
        calibration error is common to every point, so it belongs in one nuisance
        parameter, not in per-point uncertainties (which would let many points average it
        away). Without a reference: normalised radiance L(theta_r)/L(0) and no prior.

        Parameters
        ----------
        calibration : {"common", "per-incidence"}
            ``"common"`` (the default): every value divided by one lamp irradiance, right
            for a uniform beam. ``"per-incidence"``: each value brought to the common level
            by the standard read at its lamp polar angle (:meth:`relative_radiance`), for a
            beam whose irradiance over the window changes with the lamp's angle; the prior
            on the scale is the same. Needs a reference reading at every sample polar angle
            (``ValueError`` otherwise, and without a reference standard).

        Returns
        -------
        dataset : gonio.fitting.Dataset
        priors : dict of name -> gonio.fitting.Prior
        """
        from ..fitting import Normal

        if self.reference_irradiance is None:
            if _calibration(calibration) == "per-incidence":
                self._incidence_groups()  # refused, as the command line refuses it, naming why
            return self.normalised_radiance(), {}
        return self.relative_radiance(calibration), {
            "scale": Normal(self.reference_irradiance, self.reference_irradiance_sigma, 0.0, math.inf)}


def _calibration(calibration: str) -> str:
    """``calibration`` checked against :data:`CALIBRATIONS`."""
    if calibration not in CALIBRATIONS:
        raise ValueError(f"calibration={calibration!r}: expected one of {list(CALIBRATIONS)}")
    return calibration


def _nanmedian(values) -> float:
    values = np.asarray(values, float)
    return float(np.nanmedian(values)) if np.isfinite(values).any() else math.nan


def _nanmax(values) -> float:
    values = np.asarray(values, float)
    return float(np.nanmax(values)) if np.isfinite(values).any() else math.nan


def _square_root(covariance: np.ndarray) -> np.ndarray:
    """``S`` with ``S S^T = covariance`` (K, K), from its eigenvectors (rounding-level
    negative eigenvalues taken as 0)."""
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    return eigenvectors * np.sqrt(np.maximum(eigenvalues, 0.0))


def _ratio_covariance(covariance: "LowRankCovariance", keep: np.ndarray, k0: np.ndarray, x0: np.ndarray,
                      ratio: np.ndarray) -> "LowRankCovariance":
    """Covariance of ``r = x_keep / x_k0`` to first order (``dr_i = (dx_i - r_i dx_k0(i)) /
    x_k0(i)``, :meth:`Reduced.normalised_radiance`), for values ``keep`` none of which is a
    ``k0``: the shared factors ``(U_i - r_i U_k0(i)) / x_k0(i)``, the independent variances
    ``d_i / x_k0(i)^2``, and one more column per normal-view value ``k0`` for its own
    independent error, ``-r_i sqrt(d_k0) / x_k0(i)`` on the values it normalises."""
    factors = (covariance.factors[keep] - ratio[:, None] * covariance.factors[k0]) / x0[:, None]
    normals, column = np.unique(k0, return_inverse=True)
    own = np.zeros((keep.size, normals.size))
    own[np.arange(keep.size), column] = -ratio * np.sqrt(covariance.independent[k0]) / x0
    return type(covariance)(covariance.independent[keep] / x0**2, np.hstack([factors, own]))
