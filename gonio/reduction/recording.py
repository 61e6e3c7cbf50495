"""Reduce a recording folder (:func:`reduce_recording`) and join reduced recordings."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..data import RecordingError, _describe_duplicates, duplicated_rows, read_metadata, read_points
from ..protocols import loads
from .combining import combine, combine_groups
from .geometry import planned_groups, readback_geometry, readback_or_plan
from .readings import CHECK_BLOCK, REFERENCE_BLOCK, Readings, readings_of
from .result import LOW_SIGNAL_SIGMAS, Reduced

__all__ = ["reduce_recording", "combine_reduced"]

def _reference(rows: Readings, protocol, aperture) -> tuple[float | None, float | None, dict[str, float], dict, dict]:
    """E_0 from the reference standard, reduced like the sample, with its budget (relative),
    the consistency of its readings and, as ``{"geometry", "weights", "reflectance"}``, the
    read-back geometry (theta_i, phi_i, theta_r, phi_r) [deg] of every reading, its weight
    in E_0 and the standard's reflectance (what a fit of the rig's errors needs,
    gonio.fitting.rig_errors)."""
    p = rows.points
    ref = rows.index[p["block"][rows.index] == REFERENCE_BLOCK]
    if ref.size == 0 or protocol is None or protocol.reference is None:
        return None, None, {}, {}, {}
    from ..instrument import aperture_averaged

    standard = protocol.reference
    lamp_sr, camera_sr = aperture if aperture is not None else (1e-12, 1e-12)
    theta_i = readback_or_plan(p, "stage_lamp_theta", "theta_i")[ref]
    phi_i = readback_or_plan(p, "stage_lamp_phi", "phi_i")[ref]
    view = readback_or_plan(p, "stage_camera", "view")[ref]
    model = aperture_averaged("lambert", lamp_sr, camera_sr)
    theta_r, phi_r = np.abs(view), np.where(view >= 0, phi_i * 0, 180.0)
    expected = model(theta_i, phi_i, theta_r, phi_r, rho=standard.reflectance) * np.cos(np.radians(theta_i))
    e0 = rows.value[ref] / expected
    components = {n: c[ref] / expected for n, c in rows.budget.items()}
    shared = {n: labels[ref] for n, labels in rows.shared.items() if n != "prnu"}  # a window per geometry
    mean, parts, chi2, varying = combine(np.arange(ref.size), e0, components, shared)
    weights = 1.0 / varying**2 if np.all(varying > 0) else np.ones(ref.size)  # as combine weights them
    record = {"geometry": np.column_stack([theta_i, phi_i, theta_r, phi_r]).tolist(),
              "weights": (weights / weights.sum()).tolist(), "reflectance": [float(standard.reflectance)] * ref.size}
    relative = {f"reference {n}": v / mean for n, v in parts.items() if v > 0}
    relative["certificate"] = standard.reflectance_uncertainty
    relative["angular behaviour"] = standard.angular_uncertainty
    consistency = {"reference_reduced_chi2": chi2 / (ref.size - 1)} if ref.size > 1 else {}
    total = mean * math.sqrt(sum(v**2 for v in relative.values()))
    return float(mean), float(total), {k: float(v) for k, v in relative.items()}, consistency, record


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
    (:func:`combine`) at their mean readback geometry. Points that were refused or
    failed are ignored (they stay in the recording); saturated points are excluded and
    counted in ``excluded``; values at or below three standard deviations of their own
    noise are kept and flagged ``low_signal``.
    """
    folder = Path(folder)
    meta = read_metadata(folder)
    points = read_points(folder)
    duplicates = duplicated_rows(read_points(folder, as_arrays=False))
    if duplicates:

        raise RecordingError(_describe_duplicates(folder, duplicates))
    protocol_text = meta.get("protocol", {}).get("text")
    protocol = loads(protocol_text, source=str(folder / "metadata.json")) if protocol_text else None
    aperture = _aperture(meta, protocol)
    rows = readings_of(meta, points, lamp)
    reference, reference_sigma, calibration, ref_consistency, ref_record = _reference(rows, protocol, aperture)
    sample = rows.index[(points["block"][rows.index] != REFERENCE_BLOCK) & (points["block"][rows.index] != CHECK_BLOCK)]
    if sample.size == 0:
        raise ValueError(f"{folder}: the recording holds no successfully measured, unsaturated sample points")
    groups = planned_groups(points, sample)
    keys = sorted(groups)
    resolution = {int(k): float(v) for k, v in meta.get("stage", {}).get("encoder_resolution_deg", {}).items()}
    combined = combine_groups([np.array(groups[k]) for k in keys], rows, readback_geometry(points), resolution)
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
    # A lamp read back a hair past the normal (encoder noise at theta_i = 0) is the same
    # direction at |theta_i| and phi_i + 180 deg.
    ti, pi_ = np.abs(ti), np.where(ti < 0.0, (pi_ + 360.0) % 360.0 - 180.0, pi_)
    label = meta.get("sample", {}).get("label", folder.name)
    return Reduced(
        theta_i=ti, phi_i=pi_, theta_r=np.abs(view), phi_r=np.where(view >= 0, 0.0, 180.0), view=view,
        radiance=values, radiance_sigma=total,
        repeats=np.array(counts, int), reference_irradiance=reference, reference_irradiance_sigma=reference_sigma,
        label=label,
        metadata={"recording": str(folder), "protocol": meta.get("protocol", {}).get("name"),
                  "planned_view": [k[2] for k in keys],
                  **({"aperture_sr": [float(a) for a in aperture]} if aperture else {}),
                  **({"reference_standard": ref_record} if ref_record else {})},
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
    irradiance = sigma = reference_record = None
    calibration: dict[str, float] = {}
    if refs:
        common = ("certificate", "angular behaviour")
        statistical = [p.reference_irradiance * math.sqrt(sum(v**2 for k, v in p.calibration.items() if k not in common))
                       for p in refs]
        weights = np.array([1.0 / max(s, 1e-300) ** 2 for s in statistical])
        irradiance = float(np.sum(weights * np.array([p.reference_irradiance for p in refs])) / np.sum(weights))
        reference_record = _combined_reference_record(refs, weights / np.sum(weights))
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
                  **({"aperture_sr": parts[0].metadata["aperture_sr"]} if "aperture_sr" in parts[0].metadata else {}),
                  **({"reference_standard": reference_record} if reference_record else {})},
        budget=budget, calibration=calibration,
        flags=np.concatenate([p.flags if p.flags is not None else np.full(len(p.radiance), "", object) for p in parts]),
        excluded={k: sum(p.excluded.get(k, 0) for p in parts) for k in {k for p in parts for k in p.excluded}},
        warnings=tuple(dict.fromkeys(w for p in parts for w in p.warnings)), consistency=consistency,
        unit=parts[0].unit,
        window=None if any(p.window is None for p in parts) else np.concatenate([p.window for p in parts]),
    )


def _combined_reference_record(refs: "list[Reduced]", weights: np.ndarray) -> dict[str, list] | None:
    """The reference readings of joined recordings with their weights in the joint E_0: each
    recording's own weights times the recording's weight (None when a part lacks them)."""
    records = [p.metadata.get("reference_standard") for p in refs]
    if any(not r for r in records):
        return None
    geometry = [g for r in records for g in r["geometry"]]
    joint = [float(w * v) for w, r in zip(weights, records) for v in r["weights"]]
    return {"geometry": geometry, "weights": joint, "reflectance": [v for r in records for v in r["reflectance"]]}
