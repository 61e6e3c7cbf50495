"""Run a sweep protocol on a rig, record every point as it is measured, and resume.

:func:`run_protocol` executes the plan of a :class:`~gonio.protocols.Protocol` on any
object with the Rig interface of ``drivers.rig.Rig`` (the emulator or a real instrument:
``lamp_on``, ``wait_lamp_stable``, ``check_geometry``, ``measure``), appending each point to
a recording (:mod:`gonio.data`) and flushing it to disk before the next move.  An
interrupted run (Ctrl-C, a crash, a dead lamp) is continued with ``resume=True``: points
already recorded are skipped, nothing is measured twice and nothing is lost.

:func:`reduce_recording` turns a recording into radiance per geometry with uncertainties,
and into the datasets fitting uses: relative radiance, normalised radiance
L(theta_r)/L(0) as Oren & Nayar plot it (section 5, Figs 16-22), and absolute BRDF when
a reference standard was measured.
"""
from __future__ import annotations

import math
import platform
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from . import __version__
from .data import RecordingWriter, point_key, read_metadata, read_points
from .protocols import PlannedPoint, Protocol, load, loads, plan

__all__ = [
    "RunResult",
    "Progress",
    "AcquisitionError",
    "run_protocol",
    "Reduced",
    "reduce_recording",
    "combine_reduced",
    "LAMP_STABILITY",
    "REFERENCE_BLOCK",
]

#: A typical relative instability of a 300 W incandescent lamp on a regulated supply over a
#: run (the emulated lamp drifts by up to 0.1 %, docs/emulator.md).  Not added by default:
#: :func:`reduce_recording` reports the uncertainty of the CCD noise model and of repeats,
#: and a fit learns any extra scatter with its jitter term; pass
#: ``lamp_stability=LAMP_STABILITY`` to add it in quadrature instead.
LAMP_STABILITY = 1e-3
#: Block name under which reference-standard points are recorded.
REFERENCE_BLOCK = "reference standard"


class AcquisitionError(RuntimeError):
    """A run cannot start or had to stop (the recording keeps everything measured)."""


@dataclass(frozen=True)
class Progress:
    """Progress report passed to the ``progress`` callback after every point."""

    done: int
    total: int
    measured: int
    refused: int
    errors: int
    elapsed_wall: float
    eta_wall: float
    instrument_time: float
    point: PlannedPoint | None
    status: str


@dataclass
class RunResult:
    """What a run did: counts, final status and where the recording is."""

    folder: Path
    status: str = "running"
    measured: int = 0
    refused: int = 0
    errors: int = 0
    skipped: int = 0
    wall_seconds: float = 0.0
    instrument_seconds: float = 0.0
    messages: list[str] = field(default_factory=list)

    def summary(self) -> str:
        return (
            f"{self.status}: {self.measured} points measured, {self.refused} refused, "
            f"{self.errors} failed, {self.skipped} already recorded; "
            f"{self.wall_seconds:.1f} s wall, {self.instrument_seconds:.1f} s instrument time; "
            f"recording in {self.folder}"
        )


def _now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _software_versions() -> dict[str, str]:
    import scipy
    import serial

    return {
        "gonio": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "pyserial": getattr(serial, "__version__", "unknown"),
    }


def _point_row(point: PlannedPoint, status: str, message: str = "") -> dict[str, Any]:
    return {
        "index": point.index, "block": point.block, "repeat": point.repeat,
        "theta_i": point.theta_i, "phi_i": point.phi_i, "view": point.view,
        "theta_r": point.theta_r, "phi_r": point.phi_r, "status": status, "message": message,
    }


def _combine(measurements: list) -> dict[str, Any]:
    """Combine several measurements of one point (frames or HDR brackets).

    Unsaturated measurements are averaged with inverse-variance weights (HDR: the longer,
    less noisy exposures dominate); if all are saturated the shortest is kept and the row
    says so through its ``saturated`` count.
    """
    usable = [m for m in measurements if m.roi_saturated == 0] or [min(measurements, key=lambda m: m.exposure)]
    weights = np.array([1.0 / max(m.radiance_error, 1e-300) ** 2 for m in usable])
    rates = np.array([m.radiance for m in usable])
    rate = float(np.sum(weights * rates) / np.sum(weights))
    sigma = float(1.0 / math.sqrt(np.sum(weights)))
    last = usable[-1]
    return {
        "roi_mean": last.roi_mean, "roi_std": last.roi_std, "roi_pixels": last.roi_pixels,
        "saturated": max(m.roi_saturated for m in measurements), "exposure": last.exposure,
        "gain": last.gain, "frames": len(usable), "dark_mean": last.dark_level, "dark_std": last.dark_std,
        "signal_rate": rate, "signal_rate_sigma": sigma,
        "lamp_voltage": last.lamp_voltage, "lamp_current": last.lamp_current,
        "stage_camera": last.stage_position.get(1, math.nan),
        "stage_lamp_theta": last.stage_position.get(2, math.nan),
        "stage_lamp_phi": last.stage_position.get(3, math.nan),
    }


def _measure_point(rig, protocol: Protocol, point: PlannedPoint, dark_due: bool) -> tuple[dict, list]:
    exposure = protocol.exposure
    dark = "measure" if dark_due else "auto"
    if exposure.mode == "hdr":
        times: list[float | str] = list(exposure.brackets) * exposure.frames
    elif exposure.mode == "fixed":
        times = [exposure.time] * exposure.frames
    else:
        times = ["auto"] * exposure.frames
    measurements = []
    for k, t in enumerate(times):
        if k == 0:
            m = rig.measure(point.theta_i, point.phi_i, point.view, exposure=t, dark=dark)
        else:
            m = rig.measure(exposure=t, dark="auto")
        measurements.append(m)
    return _combine(measurements), measurements


def _dark_due(protocol: Protocol, measured_since_dark: int | None, resume: bool) -> bool:
    """Whether the next point takes a fresh dark frame (protocol ``[darks]`` policy).

    ``measured_since_dark`` is None before the first point of this session: a dark is taken
    then if the protocol asks for one at the start, or when resuming (conditions may have
    changed while the run was stopped).  After that, every ``darks.every`` points.
    """
    if measured_since_dark is None:
        return protocol.darks.at_start or resume
    return protocol.darks.every > 0 and measured_since_dark >= protocol.darks.every


def run_protocol(
    protocol: Protocol | str | Path,
    rig,
    folder: str | Path,
    *,
    resume: bool = False,
    metadata: Mapping[str, Any] | None = None,
    lamp_voltage: float = 120.0,
    warm_up: bool = True,
    change_sample: Callable[[str], None] | None = None,
    clock: Callable[[], float] | None = None,
    progress: Callable[[Progress], None] | None = None,
    max_consecutive_errors: int = 3,
) -> RunResult:
    """Measure every point of a protocol on ``rig`` into the recording ``folder``.

    Parameters
    ----------
    protocol : Protocol, str or Path
        A loaded protocol or the path of a protocol file.
    rig : drivers.rig.Rig or compatible
        An opened rig (``lamp_on``, ``wait_lamp_stable``, ``check_geometry``, ``measure``).
    folder : path
        Recording folder (see :mod:`gonio.data`).
    resume : bool
        Continue an interrupted recording in ``folder``; points already recorded as ok or
        refused are skipped, failed points are measured again.
    metadata : mapping, optional
        Extra metadata stored with the recording (rig and emulator configuration, seed).
    lamp_voltage : float
        Lamp supply voltage [V].
    warm_up : bool
        Wait for the lamp to stabilise before the first point.
    change_sample : callable, optional
        ``change_sample("reference")`` / ``change_sample("sample")`` swaps the sample for
        the reference standard and back (a prompt on a real rig, the emulator's sample
        holder otherwise).  Required when the protocol has a ``[reference]`` section.
    clock : callable, optional
        Instrument clock [s] recorded with each point (default: wall-clock monotonic time).
    progress : callable, optional
        Called with a :class:`Progress` after every point.
    max_consecutive_errors : int
        Stop the run after this many failed points in a row (a broken instrument), marking
        the recording "failed"; it can be resumed once the cause is fixed.

    Returns
    -------
    RunResult

    Raises
    ------
    KeyboardInterrupt
        Re-raised after the recording is marked "interrupted" (resume it later).
    AcquisitionError
        The run could not start or stopped on repeated errors.
    """
    if not isinstance(protocol, Protocol):
        protocol = load(protocol)
    if protocol.reference is not None and change_sample is None:
        raise AcquisitionError(
            f"{protocol.source}: the protocol measures a reference standard ({protocol.reference.label}) "
            "but no way to swap the sample was given (change_sample)"
        )
    clock = clock or time.monotonic
    the_plan = plan(protocol)
    info = {
        "protocol": {"name": protocol.name, "source": protocol.source, "text": protocol.text},
        "sample": {"label": protocol.sample, "metadata": dict(protocol.metadata)},
        "software": _software_versions(),
        "started": _now_iso(),
        "lamp_voltage": lamp_voltage,
        **dict(metadata or {}),
    }
    writer = RecordingWriter(Path(folder), info, resume=resume)
    done = writer.done_keys()
    result = RunResult(folder=Path(folder))
    jobs: list[tuple[PlannedPoint, str | None, bool]] = []
    for refusal in the_plan.refused:
        jobs.append((refusal.point, refusal.reason, False))
    reference_points = []
    if protocol.reference is not None:
        for k, (ti, pi_, view) in enumerate(protocol.reference.geometries):
            reference_points.append(PlannedPoint(-1 - k, REFERENCE_BLOCK, 0, ti, pi_, view))
    for point in the_plan.points:
        jobs.append((point, None, False))
    for point in reference_points:
        jobs.append((point, None, True))
    todo = [job for job in jobs if point_key(*job[0].key) not in done]
    result.skipped = len(jobs) - len(todo)
    start_wall = time.perf_counter()
    start_instrument = clock()
    measured_since_dark = None  # None: no dark taken yet in this session
    consecutive_errors = 0
    on_reference = False
    try:
        if any(reason is None for _, reason, _ in todo):
            rig.lamp_on(lamp_voltage)
            if warm_up:
                rig.wait_lamp_stable()
        for count, (point, reason, is_reference) in enumerate(todo, start=1):
            if is_reference != on_reference and reason is None:
                change_sample("reference" if is_reference else "sample")
                on_reference = is_reference
            status, message = "ok", ""
            row: dict[str, Any] = {}
            if reason is None:
                reason = rig.check_geometry(point.theta_i, point.phi_i, point.view)
            if reason is not None:
                status, message = "refused", reason
                result.refused += 1
            else:
                dark_due = _dark_due(protocol, measured_since_dark, resume)
                try:
                    row, raw = _measure_point(rig, protocol, point, dark_due)
                except KeyboardInterrupt:
                    raise
                except Exception as error:  # an instrument error: record it, go on, or stop
                    if type(error).__name__ == "LampError":
                        writer.append_point({**_point_row(point, "error", f"{type(error).__name__}: {error}"),
                                             "instrument_time": clock(), "wall_time": _now_iso()})
                        result.errors += 1
                        raise AcquisitionError(f"lamp failure at point {point.index}: {error}") from error
                    status, message = "error", f"{type(error).__name__}: {error}"
                    result.errors += 1
                    consecutive_errors += 1
                else:
                    consecutive_errors = 0
                    result.measured += 1
                    measured_since_dark = 0 if dark_due else (measured_since_dark or 0) + 1
                    if dark_due:
                        first = raw[0]
                        writer.append_dark({
                            "after_index": point.index, "exposure": first.exposure, "gain": first.gain,
                            "roi_mean": first.dark_level, "roi_std": first.dark_std,
                            "roi_pixels": first.roi_pixels, "instrument_time": clock(), "wall_time": _now_iso(),
                        })
            writer.append_point({**_point_row(point, status, message), **row,
                                 "instrument_time": clock(), "wall_time": _now_iso()})
            if progress:
                elapsed = time.perf_counter() - start_wall
                progress(Progress(
                    done=count, total=len(todo), measured=result.measured, refused=result.refused,
                    errors=result.errors, elapsed_wall=elapsed,
                    eta_wall=elapsed / count * (len(todo) - count),
                    instrument_time=clock() - start_instrument, point=point, status=status,
                ))
            if consecutive_errors >= max_consecutive_errors:
                raise AcquisitionError(
                    f"{consecutive_errors} points failed in a row (last: {message}); stopping. "
                    "Fix the instrument and resume the run."
                )
        if on_reference:
            change_sample("sample")
    except KeyboardInterrupt:
        result.status = "interrupted"
        _finish(writer, result, start_wall, start_instrument, clock)
        raise
    except Exception as error:
        result.status = "failed"
        result.messages.append(str(error))
        _finish(writer, result, start_wall, start_instrument, clock, error=str(error))
        if isinstance(error, AcquisitionError):
            raise
        raise AcquisitionError(f"run stopped: {type(error).__name__}: {error}") from error
    result.status = "complete"
    _finish(writer, result, start_wall, start_instrument, clock)
    return result


def _finish(writer: RecordingWriter, result: RunResult, start_wall: float, start_instrument: float,
            clock: Callable[[], float], error: str | None = None) -> None:
    result.wall_seconds = time.perf_counter() - start_wall
    result.instrument_seconds = clock() - start_instrument
    extra = {"finished": _now_iso(), "last_run": {
        "measured": result.measured, "refused": result.refused, "errors": result.errors,
        "skipped": result.skipped, "wall_seconds": result.wall_seconds,
        "instrument_seconds": result.instrument_seconds}}
    if error:
        extra["error"] = error
    writer.finish(result.status, **extra)


# --------------------------------------------------------------------------- reduction
@dataclass(frozen=True)
class Reduced:
    """Radiance per measured geometry, repeats combined.

    Attributes
    ----------
    theta_i, phi_i, theta_r, phi_r : numpy.ndarray
        Geometry in the sample frame [deg] (azimuth 0 = the camera's swing plane, + side).
    view : numpy.ndarray
        Signed camera angle [deg].
    radiance, radiance_sigma : numpy.ndarray
        Relative radiance [DN/s per pixel at unit gain] and its 1-sigma uncertainty.
    repeats : numpy.ndarray
        Number of measurements combined into each value.
    reference_irradiance : float or None
        Irradiance of the lamp E_0 in the same relative units per steradian, from the
        reference standard (None when none was measured).
    reference_irradiance_sigma : float or None
        Its 1-sigma uncertainty.
    label : str
        Sample label.
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

    def relative_radiance(self):
        """Dataset of relative radiance (quantity ``'radiance'``: fit with a free scale)."""
        from .fitting import Dataset

        return Dataset(self.theta_i, self.phi_i, self.theta_r, self.phi_r, self.radiance,
                       self.radiance_sigma, quantity="radiance", label=self.label, metadata=dict(self.metadata))

    def normalised_radiance(self):
        """Dataset of L(theta_r)/L(0) per incidence (Oren & Nayar section 5, Figs 16-22).

        Each lamp direction is normalised by its own normal-view measurement (view = 0);
        lamp directions without one are left out.  The uncertainty propagates both
        measurements' uncertainties (the normal point's is shared across its incidence;
        the correlation is neglected).
        """
        from .fitting import Dataset

        keep = np.zeros(self.radiance.shape, bool)
        value = np.zeros_like(self.radiance)
        sigma = np.zeros_like(self.radiance)
        for ti, pi_ in {(a, b) for a, b in zip(self.theta_i, self.phi_i)}:
            same = (self.theta_i == ti) & (self.phi_i == pi_)
            normal = same & (self.view == 0.0)
            if not normal.any():
                continue
            k = int(np.flatnonzero(normal)[0])
            l0, s0 = self.radiance[k], self.radiance_sigma[k]
            value[same] = self.radiance[same] / l0
            sigma[same] = np.abs(value[same]) * np.hypot(self.radiance_sigma[same] / self.radiance[same], s0 / l0)
            sigma[normal] = np.maximum(sigma[normal], 1e-12)
            keep |= same
        return Dataset(self.theta_i[keep], self.phi_i[keep], self.theta_r[keep], self.phi_r[keep], value[keep],
                       np.maximum(sigma[keep], 1e-12), quantity="normalised_radiance", label=self.label,
                       metadata=dict(self.metadata))

    def brdf(self):
        """Dataset of absolute BRDF [1/sr], calibrated by the reference standard.

        f_r = L / (E_0 cos theta_i) with E_0 from the reference measurement
        (a Lambertian standard of albedo rho_ref: L_ref = rho_ref / pi E_0 cos theta_i).
        """
        from .fitting import Dataset

        if self.reference_irradiance is None:
            raise ValueError("no reference standard was measured in this recording: absolute BRDF "
                             "is not available (use normalised_radiance() or relative_radiance())")
        cos_i = np.cos(np.radians(self.theta_i))
        value = self.radiance / (self.reference_irradiance * cos_i)
        rel = np.hypot(self.radiance_sigma / self.radiance, self.reference_irradiance_sigma / self.reference_irradiance)
        return Dataset(self.theta_i, self.phi_i, self.theta_r, self.phi_r, value, np.abs(value) * rel,
                       quantity="brdf", label=self.label, metadata=dict(self.metadata))

    def best_dataset(self):
        """Absolute BRDF when calibrated, else normalised radiance."""
        return self.brdf() if self.reference_irradiance is not None else self.normalised_radiance()

    def fit_inputs(self, calibration_stability: float = LAMP_STABILITY):
        """The dataset and priors a fit of this recording should use.

        With a reference standard: relative radiance, whose ``scale`` (the lamp irradiance
        E_0 in the recording's units) gets a Gaussian prior centred on the reference
        estimate with its uncertainty and ``calibration_stability`` (lamp drift between
        the reference and the sample) in quadrature.  The calibration error is common to
        every point, so it belongs in one nuisance parameter, not in per-point
        uncertainties (which would make the albedo's interval too narrow).  Without a
        reference: normalised radiance L(theta_r)/L(0) and no extra prior.

        Returns
        -------
        dataset : gonio.fitting.Dataset
        priors : dict of name -> gonio.fitting.Prior
        """
        from .fitting import Normal

        if self.reference_irradiance is None:
            return self.normalised_radiance(), {}
        e0 = self.reference_irradiance
        sd = e0 * math.hypot(self.reference_irradiance_sigma / e0, calibration_stability)
        return self.relative_radiance(), {"scale": Normal(e0, sd, 0.0, math.inf)}


def _combine_repeats(values: np.ndarray, sigmas: np.ndarray, floor: float = 0.0) -> tuple[float, float]:
    """Weighted mean of repeats; uncertainty = max(propagated, observed scatter / sqrt(n)),
    with a relative ``floor`` added in quadrature."""
    weights = 1.0 / np.maximum(sigmas, 1e-300) ** 2
    mean = float(np.sum(weights * values) / np.sum(weights))
    propagated = float(1.0 / math.sqrt(np.sum(weights)))
    if len(values) > 1:
        scatter = float(np.std(values, ddof=1) / math.sqrt(len(values)))
        propagated = max(propagated, scatter)
    return mean, math.hypot(propagated, floor * mean)


def reduce_recording(folder: str | Path, lamp_stability: float = 0.0) -> Reduced:
    """Reduce a recording to radiance per geometry with uncertainties.

    Parameters
    ----------
    folder : path
        Recording folder.
    lamp_stability : float
        Relative uncertainty [-] added in quadrature to every value for lamp drift and
        flicker (e.g. :data:`LAMP_STABILITY`); 0 keeps the CCD-noise and repeat
        uncertainties alone (fit with a jitter term to learn the rest from the data).

    Notes
    -----
    Repeats of a geometry are combined (:func:`_combine_repeats`).  Points that were
    refused or failed are ignored (they stay in the recording).  If the recording holds
    reference-standard points, the lamp irradiance E_0 is estimated from them.
    """
    folder = Path(folder)
    meta = read_metadata(folder)
    points = read_points(folder)
    ok = points["status"] == "ok"
    ok &= np.isfinite(points["signal_rate"]) & (points["signal_rate"] > 0)
    is_ref = points["block"] == REFERENCE_BLOCK
    label = meta.get("sample", {}).get("label", folder.name)
    protocol_text = meta.get("protocol", {}).get("text")
    protocol = loads(protocol_text, source=str(folder / "metadata.json")) if protocol_text else None
    aperture = meta.get("rig", {}).get("aperture_sr")
    if aperture is None and protocol is not None:
        aperture = [protocol.rig.lamp_solid_angle, protocol.rig.camera_solid_angle]
    if aperture is not None and min(aperture) <= 0:
        aperture = None  # ideal point apertures: fit the model itself
    reference_irradiance = reference_sigma = None
    if (ok & is_ref).any():
        reflectance = protocol.reference.reflectance if protocol is not None and protocol.reference else None
        if reflectance:
            cos_i = np.cos(np.radians(points["theta_i"][ok & is_ref]))
            e0 = np.pi * points["signal_rate"][ok & is_ref] / (reflectance * cos_i)
            e0_sigma = np.pi * points["signal_rate_sigma"][ok & is_ref] / (reflectance * cos_i)
            reference_irradiance, reference_sigma = _combine_repeats(e0, e0_sigma, lamp_stability)
    sample = ok & ~is_ref
    groups: dict[tuple, list[int]] = {}
    for k in np.flatnonzero(sample):
        key = (round(points["theta_i"][k], 6), round(points["phi_i"][k], 6), round(points["view"][k], 6))
        groups.setdefault(key, []).append(int(k))
    rows = []
    for (ti, pi_, view), members in sorted(groups.items()):
        mean, sigma = _combine_repeats(points["signal_rate"][members], points["signal_rate_sigma"][members], lamp_stability)
        rows.append((ti, pi_, abs(view), 0.0 if view >= 0 else 180.0, view, mean, sigma, len(members)))
    if not rows:
        raise ValueError(f"{folder}: the recording holds no successfully measured sample points")
    columns = [np.array(c, dtype=float) for c in zip(*rows)]
    return Reduced(
        theta_i=columns[0], phi_i=columns[1], theta_r=columns[2], phi_r=columns[3], view=columns[4],
        radiance=columns[5], radiance_sigma=columns[6], repeats=columns[7].astype(int),
        reference_irradiance=reference_irradiance, reference_irradiance_sigma=reference_sigma,
        label=label, metadata={"recording": str(folder), "protocol": meta.get("protocol", {}).get("name"),
                               **({"aperture_sr": [float(a) for a in aperture]} if aperture else {})},
    )


def combine_reduced(parts: "list[Reduced]", label: str | None = None) -> Reduced:
    """Join reduced recordings of one sample (e.g. in-plane and off-plane runs).

    The geometries are concatenated; the reference irradiances, when present, are
    combined by their inverse-variance weighted mean (the runs must share lamp, voltage
    and camera settings for their relative radiances to be comparable).
    """
    if not parts:
        raise ValueError("combine_reduced needs at least one reduced recording")
    apertures = {tuple(p.metadata.get("aperture_sr", ())) for p in parts}
    if len(apertures) > 1:
        raise ValueError(f"cannot combine recordings measured through different apertures: {sorted(apertures)}")
    cat = lambda name: np.concatenate([getattr(p, name) for p in parts])  # noqa: E731
    refs = [(p.reference_irradiance, p.reference_irradiance_sigma) for p in parts if p.reference_irradiance is not None]
    irradiance = sigma = None
    if refs:
        weights = np.array([1.0 / s**2 for _, s in refs])
        irradiance = float(np.sum(weights * np.array([e for e, _ in refs])) / np.sum(weights))
        sigma = float(1.0 / math.sqrt(np.sum(weights)))
    return Reduced(
        theta_i=cat("theta_i"), phi_i=cat("phi_i"), theta_r=cat("theta_r"), phi_r=cat("phi_r"), view=cat("view"),
        radiance=cat("radiance"), radiance_sigma=cat("radiance_sigma"), repeats=cat("repeats"),
        reference_irradiance=irradiance, reference_irradiance_sigma=sigma,
        label=label or parts[0].label,
        metadata={"recordings": [p.metadata.get("recording") for p in parts],
                  **({"aperture_sr": parts[0].metadata["aperture_sr"]} if "aperture_sr" in parts[0].metadata else {})},
    )
