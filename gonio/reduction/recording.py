"""Reduce a recording folder (:func:`reduce_recording`) and join reduced recordings."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..data import (EMULATED_SAMPLE, RecordingError, _describe_duplicates, check_measured_rows, duplicated_rows, read_metadata,
                    read_points)
from ..protocols import loads
from .combining import combine, combine_groups, mounting_scatter
from .geometry import lamp_direction, planned_groups, readback_geometry
from .readings import CHECK_BLOCK, REFERENCE_BLOCK, Readings, readings_of
from .result import (ANGULAR_BEHAVIOUR, COMMON_CALIBRATION, INCONSISTENT_INCIDENCES, LOW_SIGNAL_SIGMAS,
                     IncidenceCalibration, Reduced)

__all__ = ["reduce_recording", "combine_reduced"]

@dataclass(frozen=True)
class _Reference:
    """The reference standard reduced like the sample (:func:`_reference`)."""

    irradiance: float
    sigma: float
    calibration: dict[str, float]
    consistency: dict[str, float]
    record: dict[str, list]
    incidences: tuple[IncidenceCalibration, ...]
    linearity: np.ndarray | None


def _reference(rows: Readings, protocol, aperture) -> _Reference | None:
    """E_0 from the reference standard, reduced like the sample, with its budget (relative),
    the consistency of its readings, the irradiance at each lamp polar angle it was read at
    and, as ``{"geometry", "weights", "reflectance", "incidence", "incidence_weights"}``, the
    read-back geometry (theta_i, phi_i, theta_r, phi_r) [deg] of every reading, its weight
    in E_0, the standard's reflectance, its planned polar angle and its weight in that
    angle's irradiance (what a fit of the rig's errors needs, gonio.fitting.rig_errors)."""
    p = rows.points
    ref = rows.index[p["block"][rows.index] == REFERENCE_BLOCK]
    if ref.size == 0 or protocol is None or protocol.reference is None:
        return None
    from ..instrument import aperture_averaged

    standard = protocol.reference
    lamp_sr, camera_sr = aperture if aperture is not None else (1e-12, 1e-12)
    stage_theta, stage_phi, view = readback_geometry(p)[ref].T
    theta_i, phi_i = lamp_direction(stage_theta, stage_phi)
    model = aperture_averaged("lambert", lamp_sr, camera_sr)
    theta_r, phi_r = np.abs(view), np.where(view >= 0, phi_i * 0, 180.0)
    expected = model(theta_i, phi_i, theta_r, phi_r, rho=standard.reflectance) * np.cos(np.radians(theta_i))
    e0 = rows.value[ref] / expected
    components = {n: c[ref] / expected for n, c in rows.budget.items()}
    shared = {n: labels[ref] for n, labels in rows.shared.items() if n != "prnu"}  # a window per geometry
    jacobian = None if rows.linearity_jacobian is None else rows.linearity_jacobian[ref]
    readings = _ReferenceReadings(e0, components, shared, jacobian)
    mean, parts, chi2, _, weights = combine(np.arange(ref.size), e0, components, shared)
    planned = np.round(np.asarray(p["theta_i"], float)[ref], 6)
    incidences = tuple(readings.at(np.flatnonzero(planned == t), float(t), weights) for t in np.unique(planned))
    within = np.zeros(ref.size)
    for incidence in incidences:
        within[list(incidence.readings)] = incidence.reading_weights
    record = {"geometry": np.column_stack([theta_i, phi_i, theta_r, phi_r]).tolist(),
              "weights": weights.tolist(), "reflectance": [float(standard.reflectance)] * ref.size,
              "incidence": planned.tolist(), "incidence_weights": within.tolist()}
    relative = {f"reference {n}": v / mean for n, v in parts.items() if v > 0}
    relative["certificate"] = standard.reflectance_uncertainty
    relative[ANGULAR_BEHAVIOUR] = standard.angular_uncertainty
    consistency = {"reference_reduced_chi2": chi2 / (ref.size - 1)} if ref.size > 1 else {}
    total = mean * math.sqrt(sum(v**2 for v in relative.values()))
    return _Reference(float(mean), float(total), {k: float(v) for k, v in relative.items()}, consistency, record,
                      incidences, readings.linearity(np.arange(ref.size), weights))


def _check_incidences(incidences: tuple[IncidenceCalibration, ...], sample_theta_i, warnings: list[str]) -> None:
    """Warn when the standard's irradiance differs between lamp polar angles beyond its
    readings' noise (the chi-square test of the fits' adequacy, at its threshold): a beam
    that is not uniform (or a misaligned rig) that one common E_0 does not calibrate. The
    remedy named depends on whether the standard was read at every planned lamp polar
    angle of the sample (``sample_theta_i`` [deg]).

    The chi-square takes the ``E_k`` as independent with their stated errors: readings
    of different angles that share a dark frame or a lamp-drift interval make it
    approximate (docs/acquisition.md, "Calibration per incidence")."""
    from ..fitting.adequacy import ALPHA, chi2_pvalue

    if len(incidences) < 2:
        return
    e = np.array([c.irradiance for c in incidences])
    inverse = 1.0 / np.array([c.irradiance * c.sigma for c in incidences]) ** 2
    mean = np.sum(inverse * e) / np.sum(inverse)
    chi2 = float(np.sum(inverse * (e - mean) ** 2))
    p = chi2_pvalue(chi2, len(e) - 1)
    if p >= ALPHA:
        return
    spread = ", ".join(f"{c.theta_i:g} deg {c.irradiance / mean - 1:+.1e}" for c in incidences)
    missing = sorted(set(np.round(np.asarray(sample_theta_i, float), 2).tolist())
                     - {round(float(c.theta_i), 2) for c in incidences})
    remedy = ("Calibrate per incidence (gonio fit --calibration per-incidence) or fit the alignment (--alignment)"
              if not missing else
              f"Fit the alignment (--alignment), or read the standard at theta_i = {missing} deg too (the sample's "
              "lamp angles without a reading) to calibrate per incidence")
    warnings.append(f"{INCONSISTENT_INCIDENCES} beyond its noise "
                    f"(chi-square {chi2:.3g} for {len(e) - 1} degrees of freedom, p = {p:.1e}; {spread}): a lamp "
                    f"beam that is not uniform, or a misaligned rig. {remedy}")


@dataclass(frozen=True)
class _ReferenceReadings:
    """The reference readings' E_0 estimates, their budget (by component, shared labels) and
    their sensitivity to the linearity correction, for combining any subset of them."""

    e0: np.ndarray
    components: dict[str, np.ndarray]
    shared: dict[str, np.ndarray]
    jacobian: np.ndarray | None

    def linearity(self, members: np.ndarray, weights: np.ndarray) -> np.ndarray | None:
        """The sensitivity to the linearity coefficients of the readings ``members``
        combined with ``weights``."""
        return None if self.jacobian is None else weights @ self.jacobian[members]

    def at(self, members: np.ndarray, theta_i: float, weights: np.ndarray) -> IncidenceCalibration:
        """The irradiance from the readings ``members`` (those at one lamp polar angle)."""
        mean, parts, _, _, own = combine(members, self.e0, self.components, self.shared)
        return IncidenceCalibration(theta_i, float(mean), float(math.sqrt(sum(v**2 for v in parts.values())) / mean),
                                    float(weights[members].sum()), tuple(int(m) for m in members),
                                    tuple(float(w) for w in own), self.linearity(members, own))


def _check_points_are_planned(folder: Path, protocol, rows) -> None:
    """Refuse a points.csv whose sample points the metadata's protocol does not plan: the
    metadata.json of another recording (copied or swapped in) was reduced as if it were this
    one's."""
    from ..data import point_key, row_key
    from ..protocols import plan

    the_plan = plan(protocol)
    planned = {point_key(*p.key) for p in the_plan.points} | {point_key(*r.point.key) for r in the_plan.refused}
    for line, row in enumerate(rows, start=2):
        if row["block"] not in (REFERENCE_BLOCK, CHECK_BLOCK) and row_key(row) not in planned:
            raise RecordingError(
                f"{folder / 'points.csv'}, line {line}: point ({row['block']!r}, theta_i {row['theta_i']:g}, view "
                f"{row['view']:g}) is not in the plan of the protocol in {folder / 'metadata.json'} "
                f"({protocol.name!r}): the metadata belongs to another recording, or the points do")


def _emulated_sample(meta: Mapping[str, Any]) -> dict[str, Any]:
    """``{EMULATED_SAMPLE: {"spec", "parameters"}}`` for a recording of the emulator, else empty."""
    rig = meta.get("rig")
    if not isinstance(rig, Mapping) or rig.get("kind") != "emulator" or "sample" not in rig:
        return {}
    return {EMULATED_SAMPLE: {"spec": rig["sample"], "parameters": dict(rig.get("parameters") or {})}}


def reduce_recording(folder: str | Path, lamp: str = "auto", linearity: bool = True) -> Reduced:
    """Reduce a recording to radiance per geometry with an uncertainty budget.

    Parameters
    ----------
    folder : path
        Recording folder (:mod:`gonio.data`).
    lamp : str
        How the lamp's flicker and drift are handled (see :func:`read_readings`).
    linearity : bool
        Correct the readings by the camera's linearity series when the recording has one
        (:func:`~gonio.reduction.readings.correct_linearity`); False leaves them as read.

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
    (:func:`combine`) at their mean readback geometry. Points that were refused or
    failed are ignored (they stay in the recording); saturated points are excluded and
    counted in ``excluded``; values at or below three standard deviations of their own
    noise are kept and flagged ``low_signal``.
    """
    folder = Path(folder)
    meta = read_metadata(folder)
    points = read_points(folder)
    if points["index"].size == 0:
        raise RecordingError(f"{folder}: the recording holds no points yet (points.csv has its header only: the run "
                             f"stopped before its first point; resume it with gonio run ... --out {folder} --resume)")
    check_measured_rows(folder, points)
    point_rows = read_points(folder, as_arrays=False)
    duplicates = duplicated_rows(point_rows)
    if duplicates:
        raise RecordingError(_describe_duplicates(folder, duplicates))
    protocol_text = meta.get("protocol", {}).get("text")
    protocol = loads(protocol_text, source=str(folder / "metadata.json")) if protocol_text else None
    if protocol is not None:
        _check_points_are_planned(folder, protocol, point_rows)
    aperture = _aperture(meta, protocol)
    rows = readings_of(meta, points, lamp, linearity)
    reference = _reference(rows, protocol, aperture)
    sample = rows.index[(points["block"][rows.index] != REFERENCE_BLOCK) & (points["block"][rows.index] != CHECK_BLOCK)]
    if sample.size == 0:
        raise ValueError(f"{folder}: the recording holds no successfully measured, unsaturated sample points")
    groups = planned_groups(points, sample)
    keys = sorted(groups)
    if reference is not None:
        _check_incidences(reference.incidences, [k[0] for k in keys], rows.warnings)
    resolution = {int(k): float(v) for k, v in meta.get("stage", {}).get("encoder_resolution_deg", {}).items()}
    member_lists = [np.array(groups[k]) for k in keys]
    mounting = np.maximum(np.asarray(points["mounting"], int), 0)
    scatter = _add_mounting_component(member_lists, rows, mounting)
    combined = combine_groups(member_lists, rows, readback_geometry(points), resolution,
                              carried=rows.linearity_jacobian)
    geometry, values, budget, counts, repeat_stats, jacobian = combined
    factors = None
    if scatter is not None:
        present = np.array([np.unique(mounting[m]).size for m in member_lists], float)
        factors = values[:, None] * scatter.relative / np.sqrt(present)[:, None]
        described = scatter.complete
        budget["mounting"] = np.where(described, np.sqrt(np.sum(factors**2, axis=1)), budget["mounting"])
        factors[~described] = 0.0
    if jacobian is not None:
        budget["linearity"] = _linearity_component(values, jacobian, rows.linearity.covariance_matrix,
                                                   reference.linearity if reference is not None else None)
    pixels = np.array([points["roi_pixels"][groups[k][0]] for k in keys], float)
    window = np.clip(1.0 / pixels - 1.0 / float(np.max(points["roi_pixels"])), 0.0, None)  # as ccd_components
    total = np.sqrt(sum(b**2 for b in budget.values()))
    flags = _low_signal_flags(values, total)
    consistency = dict(rows.consistency)
    consistency.update(reference.consistency if reference else {})
    dof = sum(r["n"] - 1 for r in repeat_stats)
    if dof:
        consistency["repeats_reduced_chi2"] = sum(r["chi2"] for r in repeat_stats) / dof
    excluded = _excluded(points)
    ti, pi_ = lamp_direction(geometry[:, 0], geometry[:, 1])
    view = geometry[:, 2]
    label = meta.get("sample", {}).get("label", folder.name)
    return Reduced(
        theta_i=ti, phi_i=pi_, theta_r=np.abs(view), phi_r=np.where(view >= 0, 0.0, 180.0), view=view,
        radiance=values, radiance_sigma=total,
        repeats=np.array(counts, int), reference_irradiance=reference.irradiance if reference else None,
        reference_irradiance_sigma=reference.sigma if reference else None, label=label,
        metadata={"recording": str(folder), "protocol": meta.get("protocol", {}).get("name"),
                  "planned_view": [k[2] for k in keys], "planned_theta_i": [float(k[0]) for k in keys],
                  **({"aperture_sr": [float(a) for a in aperture]} if aperture else {}),
                  **({"reference_standard": reference.record} if reference else {}),
                  **_emulated_sample(meta)},
        budget=budget, calibration=reference.calibration if reference else {}, flags=flags, excluded=excluded,
        warnings=tuple(rows.warnings), consistency=consistency, unit=rows.unit, repeat_statistics=tuple(repeat_stats),
        window=window, linearity_jacobian=jacobian, mounting_factors=factors,
        linearity_covariance=None if jacobian is None else rows.linearity.covariance_matrix,
        reference_linearity=reference.linearity if reference else None,
        incidences=reference.incidences if reference else (),
        incidence=_incidence_of([k[0] for k in keys], reference.incidences if reference else ()),
    )


def _add_mounting_component(groups: list[np.ndarray], rows: Readings, mounting: np.ndarray):
    """Add the ``mounting`` component to every reading (shared by the readings of one mounting)
    when the sample was mounted more than once, and return its factors
    (:func:`~gonio.reduction.combining.mounting_scatter`); else warn that the mountings'
    scatter is not in the budget and return None."""
    found = mounting_scatter(groups, rows, mounting)
    if found is None:
        rows.warnings.append(
            "the sample was mounted once: how much its values change when it is taken out and put back (its "
            "seating and tilt, the part of its texture the camera sees) is not in the budget. Measure it: add "
            "'mountings = 4' (or 'rotations = [0, 90, 180, 270]') to [sample] in the protocol; a fit can take "
            "this mounting's tilt as a parameter (--alignment sample_tilt_x,sample_tilt_y)")
        return None
    component, factors = found
    rows.budget["mounting"] = component
    rows.shared["mounting"] = mounting
    rows.consistency["mountings"] = float(factors.mountings)
    rows.consistency["mounting_median_relative"] = float(np.median(factors.sigma))
    return factors


def _linearity_component(values: np.ndarray, jacobian: np.ndarray, covariance: np.ndarray,
                         reference: np.ndarray | None) -> np.ndarray:
    """The budget's ``linearity`` component of each value: ``|x| sqrt(d C d^T)`` with ``d`` its
    sensitivity to the correction's coefficients relative to the reference standard's
    (``reference``, None without a standard)."""
    d = jacobian - (reference if reference is not None else 0.0)
    return np.abs(values) * np.sqrt(np.einsum("ni,ij,nj->n", d, covariance, d))


def _low_signal_flags(values: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``"low_signal"`` for the values at or below :data:`LOW_SIGNAL_SIGMAS` of their
    uncertainty, else ``""``."""
    return np.where(values <= LOW_SIGNAL_SIGMAS * sigma, "low_signal", "").astype(object)


def _incidence_of(planned_theta_i, incidences: tuple[IncidenceCalibration, ...]) -> np.ndarray:
    """For each value (its planned lamp polar angle [deg]), its entry in ``incidences``: the
    reference readings planned at the same angle (-1 when there are none)."""
    where = {round(float(c.theta_i), 6): k for k, c in enumerate(incidences)}
    return np.array([where.get(round(float(t), 6), -1) for t in planned_theta_i], int)


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
    not averaged down. Each recording's linearity coefficients are its own (independent
    between recordings), and each value's ``linearity`` component and total uncertainty
    are taken again relative to the joint ``E_0`` (as :meth:`Reduced.covariance`), the
    ``low_signal`` flags with them.
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
    irradiance = sigma = reference_record = None
    calibration: dict[str, float] = {}
    weights = np.zeros(0)
    if refs:
        statistical = [p.reference_irradiance * math.sqrt(sum(v**2 for k, v in p.calibration.items()
                                                              if k not in COMMON_CALIBRATION)) for p in refs]
        weights = np.array([1.0 / max(s, 1e-300) ** 2 for s in statistical])
        irradiance = float(np.sum(weights * np.array([p.reference_irradiance for p in refs])) / np.sum(weights))
        weights = weights / np.sum(weights)
        calibration["reference (combined)"] = float(1.0 / math.sqrt(np.sum(1.0 / np.square(statistical))) / irradiance)
        for key in COMMON_CALIBRATION:
            calibration[key] = max(p.calibration.get(key, 0.0) for p in refs)
        sigma = irradiance * math.sqrt(sum(v**2 for v in calibration.values()))
    linearity = _JointLinearity.of(parts)
    jacobian, coefficients, reference = linearity.jacobian(), linearity.covariance(), linearity.reference(refs, weights)
    incidences = _joint_incidences(refs, weights, linearity)
    radiance = cat("radiance")
    if jacobian is not None:  # each value's sensitivity now relative to the joint E_0's
        budget["linearity"] = _linearity_component(radiance, jacobian, coefficients, reference)
    total = np.sqrt(sum(b**2 for b in budget.values()))
    planned_theta_i = [float(t) for p in parts for t in p.metadata.get("planned_theta_i", p.theta_i)]
    if refs:
        reference_record = _combined_reference_record(refs, weights, incidences)
    consistency = {f"{k} ({p.metadata.get('protocol')})": v for p in parts for k, v in p.consistency.items()}
    return Reduced(
        theta_i=cat("theta_i"), phi_i=cat("phi_i"), theta_r=cat("theta_r"), phi_r=cat("phi_r"), view=cat("view"),
        radiance=radiance, radiance_sigma=total, repeats=cat("repeats"),
        reference_irradiance=irradiance, reference_irradiance_sigma=sigma,
        label=label or parts[0].label,
        metadata={"recordings": [p.metadata.get("recording") for p in parts],
                  "planned_view": [v for p in parts for v in p.metadata.get("planned_view", list(p.view))],
                  "planned_theta_i": planned_theta_i,
                  **({"aperture_sr": parts[0].metadata["aperture_sr"]} if "aperture_sr" in parts[0].metadata else {}),
                  **({"reference_standard": reference_record} if reference_record else {}),
                  **({EMULATED_SAMPLE: parts[0].metadata[EMULATED_SAMPLE]}
                     if len({json.dumps(p.metadata.get(EMULATED_SAMPLE), sort_keys=True) for p in parts}) == 1
                     and EMULATED_SAMPLE in parts[0].metadata else {})},
        budget=budget, calibration=calibration,
        flags=_low_signal_flags(radiance, total),
        excluded={k: sum(p.excluded.get(k, 0) for p in parts) for k in {k for p in parts for k in p.excluded}},
        warnings=tuple(dict.fromkeys(w for p in parts for w in p.warnings)), consistency=consistency,
        unit=parts[0].unit,
        window=None if any(p.window is None for p in parts) else np.concatenate([p.window for p in parts]),
        linearity_jacobian=jacobian, linearity_covariance=coefficients, reference_linearity=reference,
        incidences=incidences, incidence=_incidence_of(planned_theta_i, incidences),
        mounting_factors=_joint_factors(parts),
    )


def _joint_factors(parts: "list[Reduced]") -> np.ndarray | None:
    """The joined recordings' mounting factors, block-diagonal (each recording's mountings are
    its own); None when no part has any."""
    blocks = [p.mounting_factors if p.mounting_factors is not None else np.zeros((len(p.radiance), 0)) for p in parts]
    columns = sum(b.shape[1] for b in blocks)
    if columns == 0:
        return None
    out = np.zeros((sum(len(p.radiance) for p in parts), columns))
    row = column = 0
    for b in blocks:
        out[row:row + b.shape[0], column:column + b.shape[1]] = b
        row, column = row + b.shape[0], column + b.shape[1]
    return out


@dataclass(frozen=True)
class _JointLinearity:
    """The joined recordings' linearity corrections: two coefficients per corrected
    recording, each recording's in its own columns (``starts[k]:starts[k + 1]``)."""

    parts: tuple
    starts: np.ndarray

    @classmethod
    def of(cls, parts: "list[Reduced]") -> "_JointLinearity":
        sizes = [0 if p.linearity_jacobian is None else p.linearity_jacobian.shape[1] for p in parts]
        return cls(tuple(parts), np.concatenate([[0], np.cumsum(sizes)]).astype(int))

    @property
    def columns(self) -> int:
        return int(self.starts[-1])

    def pad(self, part: "Reduced", vector: np.ndarray | None) -> np.ndarray:
        """``part``'s sensitivities (..., its columns) in the joint columns (0 elsewhere; a
        part without a correction, ``vector`` None: zeros, (P,))."""
        if vector is None:
            return np.zeros(self.columns)
        k = next(i for i, p in enumerate(self.parts) if p is part)
        out = np.zeros(np.shape(vector)[:-1] + (self.columns,))
        out[..., self.starts[k]:self.starts[k + 1]] = vector
        return out

    def jacobian(self) -> np.ndarray | None:
        """Every value's sensitivity to the joint coefficients, (n, P); None without any."""
        if not self.columns:
            return None
        return np.concatenate([self.pad(p, p.linearity_jacobian) if p.linearity_jacobian is not None
                               else np.zeros((len(p.radiance), self.columns)) for p in self.parts])

    def covariance(self) -> np.ndarray | None:
        """The joint coefficients' covariance, block-diagonal (the recordings' series are
        independent), (P, P)."""
        if not self.columns:
            return None
        out = np.zeros((self.columns, self.columns))
        for k, p in enumerate(self.parts):
            if self.starts[k + 1] > self.starts[k]:
                out[self.starts[k]:self.starts[k + 1], self.starts[k]:self.starts[k + 1]] = p.linearity_covariance
        return out

    def reference(self, refs: "list[Reduced]", weights: np.ndarray) -> np.ndarray | None:
        """The joint E_0's sensitivity: the recordings' by their weights in it."""
        if not self.columns or not refs:
            return None
        return sum((w * self.pad(p, p.reference_linearity) for w, p in zip(weights, refs)), np.zeros(self.columns))


def _joint_incidences(refs: "list[Reduced]", weights: np.ndarray,
                      linearity: _JointLinearity) -> tuple[IncidenceCalibration, ...]:
    """The irradiance at each lamp polar angle from the joined recordings' reference readings
    (an angle read in several recordings: their inverse-variance mean)."""
    offsets = np.concatenate([[0], np.cumsum([len(p.metadata.get("reference_standard", {}).get("weights", []))
                                              for p in refs])]).astype(int)
    merged = []
    for theta in sorted({c.theta_i for p in refs for c in p.incidences}):
        here = [(k, p, c) for k, p in enumerate(refs) for c in p.incidences if c.theta_i == theta]
        inverse = np.array([1.0 / (c.irradiance * c.sigma) ** 2 for _, _, c in here])
        share = inverse / inverse.sum()
        value = float(np.sum(share * [c.irradiance for _, _, c in here]))
        linear = None if not linearity.columns else sum(
            s * linearity.pad(p, c.linearity) for s, (_, p, c) in zip(share, here))
        merged.append(IncidenceCalibration(
            theta, value, float(1.0 / math.sqrt(inverse.sum()) / value),
            float(sum(weights[k] * c.weight for k, _, c in here)),
            tuple(int(offsets[k] + r) for k, _, c in here for r in c.readings),
            tuple(float(s * w) for s, (_, _, c) in zip(share, here) for w in c.reading_weights), linear))
    return tuple(merged)


def _combined_reference_record(refs: "list[Reduced]", weights: np.ndarray,
                               incidences: tuple[IncidenceCalibration, ...]) -> dict[str, list] | None:
    """The reference readings of joined recordings with their weights in the joint E_0: each
    recording's own weights times the recording's weight (None when a part lacks them), and
    their weights in the joint irradiance at their lamp polar angle."""
    records = [p.metadata.get("reference_standard") for p in refs]
    if any(not r for r in records):
        return None
    geometry = [g for r in records for g in r["geometry"]]
    joint = [float(w * v) for w, r in zip(weights, records) for v in r["weights"]]
    record = {"geometry": geometry, "weights": joint, "reflectance": [v for r in records for v in r["reflectance"]]}
    if all("incidence" in r for r in records):
        within = np.zeros(len(geometry))
        for c in incidences:
            within[list(c.readings)] = c.reading_weights
        record.update(incidence=[v for r in records for v in r["incidence"]], incidence_weights=within.tolist())
    return record
