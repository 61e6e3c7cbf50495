"""Run a sweep protocol on a rig, record every point as it is measured, and resume.

:func:`run_protocol` executes the plan of a :class:`~gonio.protocols.Protocol` on any
object with the Rig interface of ``drivers.rig.Rig`` (the emulator or a real instrument),
appending each point to a recording (:mod:`gonio.data`) and flushing it to disk before the
next move.  An interrupted run (Ctrl-C, a crash, a dead lamp) is continued with
``resume=True``: points already recorded are skipped, nothing is measured twice and
nothing is lost; a resume that would mix experiments is refused.

Besides the protocol's points a run records what the reduction needs to state honest
uncertainties (:mod:`gonio.reduction`, docs/acquisition.md):

- the camera's photon-transfer characterisation (EMVA 1288: system gain, dark noise,
  PRNU), measured once per recording at the first point, and its linearity (a series of
  exposures at constant irradiance, with the correction the reduction applies) at the
  same geometry after the last point;
- with a lamp monitor, its dark offset and noise, measured once per recording with the
  lamp off; every exposure then carries the monitor's reading;
- without one, the protocol's lamp checks: a fixed geometry re-measured with several
  frames at the start, every ``checks.every`` points, around the reference standard, at
  the start of every resumed session and around every remounting of the sample;
- in every mounting of the sample (``[sample] mountings``), once, at the photon transfer's
  geometry: an image of the window, whose spatial statistics measure the sample's texture
  (:func:`drivers.spatial.spatial_statistics`), and with a lamp monitor a series of
  exposures whose ratio to the monitor measures what the monitor does not see
  (:func:`characterise_mounting`).

:func:`reduce_recording` and the other reduction names are re-exported from
:mod:`gonio.reduction`.
"""
from __future__ import annotations

import hashlib
import math
import platform
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from drivers.errors import DriverError

from .data import RecordingError, RecordingWriter, point_key
from .protocols import PlannedPoint, Protocol, extended, load, plan
from .reduction import (
    CHECK_BLOCK,
    LOW_SIGNAL_SIGMAS,
    REFERENCE_BLOCK,
    Reduced,
    combine_reduced,
    reduce_recording,
)

__all__ = [
    "RunResult",
    "Progress",
    "Extension",
    "AcquisitionError",
    "run_protocol",
    "combine_frames",
    "Reduced",
    "reduce_recording",
    "combine_reduced",
    "REFERENCE_BLOCK",
    "CHECK_BLOCK",
]

#: Wait after switching the lamp off before the monitor's dark reading [s] (the filament
#: cools with 0.15 s; 3 s leave 2e-9 of its light).
MONITOR_DARK_COOLING_S = 3.0
#: Metadata keys of a hardware rig that may change between sessions (port paths).
_PORT_KEYS = ("stage", "camera", "lamp")


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
    flagged: int = 0
    wall_seconds: float = 0.0
    instrument_seconds: float = 0.0
    #: Instrument time of the lamp's switch-on and warm-up (and the monitor's dark reading
    #: before it) [s]: what ``gonio plan``'s estimate leaves out.
    warm_up_seconds: float = 0.0
    messages: list[str] = field(default_factory=list)
    #: False when the final status could not be written to metadata.json (a full disk).
    status_recorded: bool = True

    def summary(self) -> str:
        flagged = f", {self.flagged} flagged (saturated or low signal)" if self.flagged else ""
        return (
            f"{self.status}: {self.measured} points measured{flagged}, {self.refused} refused, "
            f"{self.errors} failed, {self.skipped} already recorded; "
            f"{self.wall_seconds:.1f} s wall, {self.instrument_seconds:.1f} s instrument time"
            f"{f' ({self.warm_up_seconds:.0f} s of it warming the lamp)' if self.warm_up_seconds >= 0.5 else ''}; "
            f"recording in {self.folder}"
        )


@dataclass(frozen=True)
class Extension:
    """What a run's ``extend`` callback decided once every point so far was measured
    (:func:`run_protocol`).

    Attributes
    ----------
    text : str or None
        Protocol text to append and measure in the same session (``[[block]]`` sections
        and comments, :func:`gonio.protocols.extended`), or None: the run ends.
    note : mapping
        Why (JSON-serialisable): stored with the text in the recording's
        ``metadata["extensions"]``.
    """

    text: str | None
    note: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SampleMounting:
    """What the operator is asked to do when the sample goes (back) into its holder.

    Attributes
    ----------
    index : int
        The mounting (0-based).
    count : int
        Mountings in the protocol.
    rotation : float or None
        Rotation of the sample about its normal [deg]; None: as the operator puts it.
    spin : bool
        Spin the sample during the exposures.
    """

    index: int
    count: int
    rotation: float | None = None
    spin: bool = False

    def instruction(self) -> str:
        """The operator's instruction, e.g. ``"mounting 2 of 4, rotated to 90 deg about its normal"``."""
        text = f"mounting {self.index + 1} of {self.count}"
        if self.rotation is not None:
            text += f", rotated to {self.rotation:g} deg about its normal"
        return text + (", spinning" if self.spin else "")


@dataclass(frozen=True)
class Job:
    """One thing to record: a planned point, a plan refusal, a reference or a check point."""

    point: PlannedPoint
    kind: str = "sample"  # "sample", "reference" or "check"
    refusal: str | None = None


def _now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _software_versions() -> dict[str, str]:
    import scipy
    import serial

    import gonio  # its version is read from the package metadata when first asked for

    return {
        "gonio": gonio.__version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "pyserial": getattr(serial, "__version__", "unknown"),
    }


def experiment_description(protocol: Protocol, lamp_voltage: float, rig: Any,
                           metadata: Mapping[str, Any] | None) -> dict[str, Any]:
    """What must stay the same for a recording to be resumed (``metadata["experiment"]``).

    The protocol by the SHA-256 of its text, the lamp voltage, the rig's configuration as
    the caller describes it (emulated sample, model parameters, seed, the realism of its
    systematic errors; port paths of a real rig excluded, they may change between
    sessions), the instruments' identities and whether a lamp monitor is fitted.
    """
    rig_meta = dict((metadata or {}).get("rig", {}))
    for key in _PORT_KEYS:
        rig_meta.pop(key, None)
    return {
        "protocol_sha256": protocol_sha256(protocol),
        "protocol_name": protocol.name,
        "sample": protocol.sample,
        "lamp_voltage": float(lamp_voltage),
        "rig": rig_meta,
        "instruments": dict(getattr(rig, "identities", {}) or {}),
        "lamp_monitor": bool(getattr(rig, "has_monitor", False)),
    }


def protocol_sha256(protocol: Protocol) -> str:
    """The SHA-256 of the protocol's text (hex): what a resume compares."""
    return hashlib.sha256(protocol.text.encode("utf-8")).hexdigest()


def _check_geometry(protocol: Protocol, the_plan) -> tuple[float, float, float]:
    """The lamp-check geometry: the protocol's, else the first measurable planned point."""
    if protocol.checks.geometry is not None:
        return tuple(float(x) for x in protocol.checks.geometry)
    if not the_plan.points:
        raise AcquisitionError(f"{protocol.source}: lamp checks need a measurable point, and the plan has none")
    p = the_plan.points[0]
    return (p.theta_i, p.phi_i, p.view)


def _check_apertures(protocol: Protocol, metadata: Mapping[str, Any] | None) -> None:
    """Refuse a protocol whose stated apertures contradict the ones the rig reports.

    ``rig.lamp_solid_angle`` and ``rig.camera_solid_angle`` tell the reduction what a real
    rig's apertures are; a rig that knows its own (the emulator, ``metadata["rig"]
    ["aperture_sr"]``) must agree within 1 %, or the protocol describes another rig.
    """
    known = (metadata or {}).get("rig", {}).get("aperture_sr")
    if known is None:
        return
    stated = (protocol.rig.lamp_solid_angle, protocol.rig.camera_solid_angle)
    for name, said, actual in zip(("lamp_solid_angle", "camera_solid_angle"), stated, known):
        if not abs(said - actual) <= 0.01 * actual:
            raise AcquisitionError(
                f"{protocol.source}: field 'rig.{name}': the protocol says {said:g} sr but this rig's aperture is "
                f"{actual:g} sr; remove the field or give the rig's value"
            )


def _characterisation_point(rig, the_plan) -> PlannedPoint | None:
    """The planned point with the largest ROI (smallest |view|) the rig accepts."""
    for point in sorted(the_plan.points, key=lambda p: (abs(p.view), p.index)):
        if rig.check_geometry(point.theta_i, point.phi_i, point.view) is None:
            return point
    return None


def build_jobs(protocol: Protocol, the_plan, session: int = 0) -> list[Job]:
    """Every job of a run in order: refusals, checks and sample points, reference, checks.

    With ``checks.every = N > 0`` a lamp check precedes the first sample point, follows
    every N sample points and the last one (before the reference standard), follows the
    reference block, and (``session > 0``, a resumed run) starts the session.
    """
    jobs = [Job(r.point, "sample", r.reason) for r in the_plan.refused]
    every = protocol.checks.every
    geometry = _check_geometry(protocol, the_plan) if every > 0 else None
    count = 0

    def check(mounting: int = 0) -> Job:
        nonlocal count
        job = Job(PlannedPoint(-1000 - count, CHECK_BLOCK, count, *geometry, mounting), "check")
        count += 1
        return job

    points = the_plan.points
    if geometry is not None and session > 0 and points:
        jobs.append(Job(PlannedPoint(-900 - session, CHECK_BLOCK, -session, *geometry, points[0].mounting), "check"))
    for k, point in enumerate(points):
        remounted = k > 0 and point.mounting != points[k - 1].mounting
        if geometry is not None and remounted:  # the level the checks see changes with the mounting
            jobs.append(check(points[k - 1].mounting))
        if geometry is not None and (k % every == 0 or remounted):
            jobs.append(check(point.mounting))
        jobs.append(Job(point))
    if geometry is not None and points:
        jobs.append(check(points[-1].mounting))
    if protocol.reference is not None:
        for k, (ti, pi_, view) in enumerate(protocol.reference.geometries):
            jobs.append(Job(PlannedPoint(-1 - k, REFERENCE_BLOCK, 0, ti, pi_, view, -1), "reference"))
        if geometry is not None:
            jobs.append(check(points[-1].mounting if points else 0))
    return jobs


def _point_row(point: PlannedPoint, status: str, message: str = "", session: int = 0,
               rotation: float | None = None) -> dict[str, Any]:
    return {
        "index": point.index, "block": point.block, "repeat": point.repeat,
        "mounting": point.mounting if point.mounting >= 0 else None, "rotation": rotation,
        "theta_i": point.theta_i, "phi_i": point.phi_i, "view": point.view,
        "theta_r": point.theta_r, "phi_r": point.phi_r, "status": status, "message": message,
        "session": session,
    }


def combine_frames(measurements: list) -> dict[str, Any]:
    """The recording row of one point from its exposures (``drivers.rig.Measurement``).

    The frames of the longest exposure whose frames are all unsaturated are averaged (for
    HDR brackets that is the bracket with the best signal-to-noise ratio; the shorter
    ones add little and are not mixed in, so that the row describes one exposure time);
    exposures left out for saturation are counted in ``frames_saturated``. When every
    exposure saturated, the shortest is kept and the row is flagged ``saturated``.
    """
    by_exposure: dict[float, list] = {}
    for m in measurements:
        by_exposure.setdefault(m.exposure, []).append(m)
    clean = [t for t, ms in by_exposure.items() if all(m.roi_saturated == 0 for m in ms)]
    chosen = max(clean) if clean else min(by_exposure)
    used = by_exposure[chosen]
    rates = np.array([m.radiance for m in used])
    sigmas = np.array([m.radiance_error for m in used])
    monitor = np.array([m.monitor for m in used])
    last = used[-1]
    saturated = max(m.roi_saturated for m in used)
    rate = float(rates.mean())
    sigma = float(np.sqrt(np.sum(sigmas**2)) / len(used))
    flags = []
    if saturated:
        flags.append("saturated")
    if rate <= LOW_SIGNAL_SIGMAS * sigma:
        flags.append("low_signal")
    return {
        "flags": ";".join(flags),
        "roi_mean": float(np.mean([m.roi_mean for m in used])),
        "roi_std": float(np.sqrt(np.mean([m.roi_std**2 for m in used]))),
        "roi_pixels": last.roi_pixels, "saturated": saturated, "exposure": chosen, "gain": last.gain,
        "frames": len(used), "frames_saturated": sum(len(ms) for t, ms in by_exposure.items() if t not in clean),
        "dark_mean": float(np.mean([m.dark_level for m in used])), "dark_std": last.dark_std,
        "signal_rate": rate, "signal_rate_sigma": sigma,
        "frame_rate_std": float(rates.std(ddof=1)) if len(used) > 1 else math.nan,
        "monitor": float(monitor.mean()) if np.isfinite(monitor).all() else math.nan,
        "lamp_voltage": last.lamp_voltage, "lamp_current": last.lamp_current,
        "stage_camera": last.stage_position.get(1, math.nan),
        "stage_lamp_theta": last.stage_position.get(2, math.nan),
        "stage_lamp_phi": last.stage_position.get(3, math.nan),
    }


def _exposure_times(protocol: Protocol, frames: int) -> list[float | str]:
    exposure = protocol.exposure
    if exposure.mode == "hdr":
        return [t for t in exposure.brackets for _ in range(frames)]
    if exposure.mode == "fixed":
        return [exposure.time] * frames
    return ["auto"] + ["same"] * (frames - 1)


def _measure_point(rig, protocol: Protocol, point: PlannedPoint, dark_due: bool, frames: int) -> tuple[dict, list]:
    """Move, settle and expose one point as the protocol's exposure policy says."""
    exposure = protocol.exposure
    auto = {"target_fraction": exposure.target_fraction, "max_exposure": exposure.max_time,
            "start_exposure": exposure.time}
    measurements = []
    for k, t in enumerate(_exposure_times(protocol, frames)):
        if t == "same":
            t = measurements[0].exposure
        options = auto if t == "auto" else {}
        if k == 0:
            m = rig.measure(point.theta_i, point.phi_i, point.view, exposure=t,
                            dark="measure" if dark_due else "auto", settle_time=protocol.rig.settle_time, **options)
        else:
            m = rig.measure(exposure=t, dark="auto", **options)
        measurements.append(m)
    return combine_frames(measurements), measurements


def _dark_due(protocol: Protocol, measured_since_dark: int | None, resume: bool) -> bool:
    """Whether the next point takes a fresh dark frame (protocol ``[darks]`` policy).

    ``measured_since_dark`` is None before the first point of this session: a dark is taken
    then if the protocol asks for one at the start, or when resuming (conditions may have
    changed while the run was stopped).  After that, every ``darks.every`` points.
    """
    if measured_since_dark is None:
        return protocol.darks.at_start or resume
    return protocol.darks.every > 0 and measured_since_dark >= protocol.darks.every


def characterise_camera(rig, point: PlannedPoint, protocol: Protocol) -> dict[str, Any]:
    """Photon-transfer characterisation of the camera at ``point`` (EMVA 1288).

    The automatic exposure at the point sets the brightest exposure; six exposures from
    10 % to 100 % of it give pairs of light and dark ROI frames
    (:func:`drivers.ptc.acquire_photon_transfer`). Returns the system gain, the temporal
    dark variance law and the PRNU for metadata["camera"] (the linearity is measured at
    the end of the run, :func:`characterise_linearity`).
    """
    from drivers.ptc import acquire_photon_transfer

    first = rig.measure(point.theta_i, point.phi_i, point.view, exposure="auto",
                        target_fraction=protocol.exposure.target_fraction, max_exposure=protocol.exposure.max_time,
                        start_exposure=protocol.exposure.time)
    exposures = [round(first.exposure * f, 9) for f in (0.1, 0.28, 0.46, 0.64, 0.82, 1.0)]
    result = acquire_photon_transfer(rig, exposures)
    return {
        "method": "EMVA 1288 photon transfer, pairs of ROI frames at the first point",
        "geometry": [point.theta_i, point.phi_i, point.view],
        "gain_factor": first.gain, "roi_pixels": first.roi_pixels,
        "system_gain_dn_per_e": result.system_gain, "system_gain_error": result.system_gain_error,
        "dark_variance_dn2": result.dark_noise_dn**2, "dark_variance_rate_dn2_per_s": result.dark_variance_rate,
        "prnu": result.prnu, "exposures_s": [float(t) for t in result.exposures],
    }


#: What makes a linearity series fail without stopping the run (recorded as the series'
#: ``error``; a resume measures it again): an instrument's error or timeout, and a series
#: the fit refuses (too few levels, no signal, a singular design). Anything else is a
#: fault of the program and stops the run like one.
SERIES_FAILURES = (DriverError, OSError, ValueError)


#: Frames of the window averaged into a mounting's texture image.
TEXTURE_FRAMES = 2
#: Exposures of a mounting's monitor-ratio series (47 degrees of freedom for the
#: irradiance the monitor does not see: its standard deviation to 10 % from one mounting;
#: with 24 exposures three recordings of one mounting each stated it 12-28 % low, 1.3 of
#: their standard errors and less).
RATIO_SERIES = 48


def characterise_mounting(rig, geometry: tuple[float, float, float], protocol: Protocol,
                          monitor_offset: float = 0.0) -> dict[str, Any]:
    """What one mounting of the sample shows: its texture, and the monitor's view of the lamp.

    At ``geometry`` (the photon transfer's, the largest window) with the automatic
    exposure: the mean of :data:`TEXTURE_FRAMES` frames of the window, dark level
    subtracted, gives the texture's spatial statistics
    (:func:`drivers.spatial.spatial_statistics`): the variance that the window's mean has
    from the sample's texture, relative to the signal, is what the reduction states as
    the ``texture`` component of every value. With a lamp monitor,
    :data:`RATIO_SERIES` further exposures give the scatter of the signal's ratio to the
    monitor, from which the reduction takes the irradiance fluctuation the monitor does
    not see (component ``monitor_ratio``) once the camera's and the monitor's own noise
    are removed.

    Returns
    -------
    dict
        For metadata["mountings"][index]: the geometry, exposure, signal, the spatial
        statistics (relative to the signal) and the monitor series.
    """
    from drivers.spatial import spatial_statistics

    theta_i, phi_i, view = geometry
    first = rig.measure(theta_i, phi_i, view, exposure="auto", target_fraction=protocol.exposure.target_fraction,
                        max_exposure=protocol.exposure.max_time, start_exposure=protocol.exposure.time,
                        settle_time=protocol.rig.settle_time)
    image = np.mean([np.asarray(rig.roi_frame(first.exposure), float) for _ in range(TEXTURE_FRAMES)], axis=0)
    signal = float(image.mean() - first.dark_level)
    if not signal > 0:
        raise ValueError(f"no signal in the texture image at {list(geometry)} ({signal:.3g} DN above the dark level)")
    stats = spatial_statistics(image)
    record: dict[str, Any] = {
        "geometry": [float(g) for g in geometry], "exposure": first.exposure, "gain": first.gain,
        "frames": TEXTURE_FRAMES, "pixels": stats.pixels, "signal_dn": signal,
        "texture_relative": math.sqrt(stats.mean_variance) / signal,
        "texture_pixel_relative": math.sqrt(stats.correlated_variance) / signal,
        "white_pixel_relative": math.sqrt(stats.white_variance) / signal,
        "correlation_lengths_px": list(stats.correlation_lengths),
        "correlation_area_px": stats.correlation_area,
    }
    if getattr(rig, "has_monitor", False):
        series = [rig.measure(exposure=first.exposure) for _ in range(RATIO_SERIES)]
        record["monitor_series"] = {
            "signal_rate": [m.radiance for m in series], "monitor": [m.monitor for m in series],
            "roi_mean": [m.roi_mean for m in series], "dark_mean": [m.dark_level for m in series],
            "roi_pixels": series[0].roi_pixels, "exposure": first.exposure, "gain": first.gain,
            "monitor_offset": monitor_offset,
        }
    return record


def characterise_linearity(rig, camera: Mapping[str, Any], protocol: Protocol,
                           monitor_offset: float = 0.0) -> dict[str, Any]:
    """The camera's linearity series at the photon transfer's geometry (EMVA 1288), or why it failed.

    Measured once per recording after its last point, on the sample, at the geometry and
    from the brightest exposure of the photon transfer ``camera`` (metadata["camera"]):
    exposures from 5 % to 100 % of the longest unsaturated one give the correction the
    reduction applies (:func:`drivers.linearity.acquire_linearity`). After the points, so
    that a seeded emulated run measures its points with the same random draws as
    without the series.
    """
    from drivers.linearity import acquire_linearity

    try:
        theta_i, phi_i, view = camera["geometry"]
        gain, dark, rate = (float(camera[k]) for k in ("system_gain_dn_per_e", "dark_variance_dn2",
                                                         "dark_variance_rate_dn2_per_s"))
        start = max(float(t) for t in camera["exposures_s"])
        rig.measure(theta_i, phi_i, view, exposure=start, settle_time=protocol.rig.settle_time)
        result = acquire_linearity(rig, start, gain, lambda t: dark + max(rate, 0.0) * t,
                                   max_exposure=protocol.exposure.max_time, monitor_offset=monitor_offset)
    except SERIES_FAILURES as error:  # the instrument, or a series the fit refuses: readings not corrected
        return {"error": f"linearity series failed ({type(error).__name__}: {error})"}
    return result.to_dict()


def _series_missing(camera: Mapping[str, Any]) -> bool:
    """Whether a recording's ``camera`` metadata lacks a linearity series, or holds only
    one that failed (its ``error``): the series a run measures after its last point."""
    series = camera.get("linearity")
    return not isinstance(series, Mapping) or "error" in series


class _Run:
    """State of one session of :func:`run_protocol` (what was measured, darks, sample mounted)."""

    def __init__(self, protocol, the_plan, rig, writer, result, clock, change_sample, resume, session, progress,
                 max_consecutive_errors):
        self.protocol, self.plan, self.rig, self.writer, self.result = protocol, the_plan, rig, writer, result
        self.clock, self.change_sample, self.resume, self.session = clock, change_sample, resume, session
        self.progress, self.max_consecutive_errors = progress, max_consecutive_errors
        self.measured_since_dark: int | None = None
        self.consecutive_errors = 0
        self.on_reference = False
        # the sample's mounting in the holder: a protocol without declared mountings finds
        # the sample mounted; one with them has the operator mount it for its first point
        self.mounting: int | None = None if protocol.mountings.declared else 0
        self.characterisation_point: PlannedPoint | None = None
        self.prepared = False
        self.start_wall = time.perf_counter()
        self.start_instrument = clock()

    # -- before the first point ----------------------------------------------------------
    def prepare(self, lamp_voltage: float, warm_up: bool, first: PlannedPoint | None) -> None:
        """Motion settings, monitor dark, lamp on and warm, camera characterisation."""
        rig, stored = self.rig, self.writer.stored_metadata
        self.prepared = True
        started = self.clock()
        limits = self.protocol.rig
        if limits.velocity is not None or limits.acceleration is not None:
            rig.set_motion(limits.velocity, limits.acceleration)
        if getattr(rig, "has_monitor", False) and "monitor_dark" not in stored:
            if rig.lamp_is_on():
                rig.lamp_off()
                rig.wait(MONITOR_DARK_COOLING_S)
            self.writer.update(monitor_dark=rig.measure_monitor_dark().to_dict())
        rig.lamp_on(lamp_voltage)
        if warm_up:
            rig.wait_lamp_stable()
        self.result.warm_up_seconds += self.clock() - started
        if "camera" not in stored and first is not None and hasattr(rig, "roi_frame"):
            self.writer.update(camera=self._characterise(first))

    def characterise_linearity(self, lamp_voltage: float, warm_up: bool) -> None:
        """The camera's linearity series once per recording, after the last point
        (:func:`characterise_linearity`): when the photon transfer succeeded and the
        recording has no series yet, or only one that failed. A resumed session with no
        point left to measure did not :meth:`prepare` the rig: the lamp is switched on
        (and warmed) first."""
        camera = self.writer.stored_metadata.get("camera", {})
        if "system_gain_dn_per_e" not in camera or not _series_missing(camera):
            return
        if not self.prepared:
            self.prepare(lamp_voltage, warm_up, None)
        offset = self.writer.stored_metadata.get("monitor_dark", {}).get("offset_v", 0.0)
        self.writer.update(camera={**camera, "linearity": characterise_linearity(self.rig, camera, self.protocol,
                                                                                 offset)})

    def _characterise(self, point: PlannedPoint) -> dict[str, Any]:
        """The camera characterisation, or why it failed (the reduction then falls back)."""
        try:
            return characterise_camera(self.rig, point, self.protocol)
        except KeyboardInterrupt:
            raise
        except Exception as error:  # an instrument problem shows again at the points
            message = f"camera characterisation failed ({type(error).__name__}: {error})"
            self.result.messages.append(message)
            return {"error": message}

    # -- the sample in its holder -----------------------------------------------------------
    def hold(self, job: Job) -> None:
        """Put what ``job`` measures in the holder: the reference standard, or the sample in
        the job's mounting (then characterise that mounting once, :meth:`characterise_mounting`)."""
        if job.kind == "reference":
            if not self.on_reference:
                self.change_sample("reference")
                self.on_reference = True
            return
        wanted = max(job.point.mounting, 0)
        if self.on_reference or self.mounting != wanted:
            spec = self.protocol.mountings
            if spec.declared:
                self.change_sample("sample", mounting=SampleMounting(wanted, spec.count, spec.rotations[wanted],
                                                                     spec.spin))
            else:
                self.change_sample("sample")
            self.on_reference, self.mounting = False, wanted
        if job.kind == "sample":
            self.characterise_mounting(wanted)

    def characterise_mounting(self, index: int) -> None:
        """The texture image and monitor series of mounting ``index`` (:func:`characterise_mounting`),
        once per recording, at the photon transfer's geometry; a failure is recorded as the
        mounting's ``error`` (the reduction then says the texture is not estimated)."""
        stored = self.writer.stored_metadata.get("mountings", {})
        if str(index) in stored or not hasattr(self.rig, "roi_frame"):
            return
        camera = self.writer.stored_metadata.get("camera", {})
        point = self.characterisation_point
        geometry = camera.get("geometry") or ([point.theta_i, point.phi_i, point.view] if point else None)
        if geometry is None:
            return
        offset = self.writer.stored_metadata.get("monitor_dark", {}).get("offset_v", 0.0)
        try:
            record = characterise_mounting(self.rig, tuple(geometry), self.protocol, offset)
        except KeyboardInterrupt:
            raise
        except SERIES_FAILURES as error:  # an instrument problem shows again at the points
            record = {"error": f"mounting characterisation failed ({type(error).__name__}: {error})"}
            self.result.messages.append(record["error"])
        spec = self.protocol.mountings
        record.update(rotation=spec.rotations[index], spin=spec.spin)
        self.writer.update(mountings={**stored, str(index): record})

    # -- one job ---------------------------------------------------------------------------
    def do(self, count: int, total: int, job: Job) -> None:
        point, reason = job.point, job.refusal
        if reason is None:
            self.hold(job)
            reason = self.rig.check_geometry(point.theta_i, point.phi_i, point.view)
        if reason is not None:
            status, message, row = "refused", reason, {}
            self.result.refused += 1
        else:
            status, message, row = self._measure(job)
        self.writer.append_point({**_point_row(point, status, message, self.session, self._rotation(job)), **row,
                                  "instrument_time": self.clock(), "wall_time": _now_iso()})
        self._report(count, total, point, status)
        if self.consecutive_errors >= self.max_consecutive_errors:
            raise AcquisitionError(
                f"{self.consecutive_errors} points failed in a row (last: {message}); stopping. "
                "Fix the instrument and resume the run."
            )

    def return_sample(self) -> None:
        """After the reference standard, the sample back in the holder, in the mounting of
        the last planned point (as the run found it)."""
        if self.on_reference:
            last = self.plan.points[-1].mounting if self.plan.points else 0
            self.hold(Job(PlannedPoint(0, "", 0, 0.0, 0.0, 0.0, last), "check"))

    def extend(self, decision: Extension, lamp_voltage: float, warm_up: bool) -> list[Job] | None:
        """Record an ``extend`` callback's ``decision`` in ``metadata["extensions"]``; when it
        appends blocks, make the extended protocol the recording's (its text and the
        experiment's hash, so that a resume continues it) and return the jobs not yet
        recorded (None: the run ends)."""
        stored = self.writer.stored_metadata
        entry = {"instrument_time": self.clock(), "wall_time": _now_iso(), "appended": decision.text,
                 "note": dict(decision.note)}
        extensions = list(stored.get("extensions", [])) + [entry]
        if decision.text is None:
            self.writer.update(extensions=extensions)
            return None
        try:
            protocol = extended(self.protocol, decision.text)
        except ValueError as error:
            raise AcquisitionError(f"the run's extension is not a protocol's continuation: {error}") from error
        self.protocol, self.plan = protocol, plan(protocol)
        self.writer.update(
            extensions=extensions,
            protocol={**stored["protocol"], "text": protocol.text},
            experiment={**stored["experiment"], "protocol_sha256": protocol_sha256(protocol)})
        done = self.writer.done_keys()
        todo = [job for job in build_jobs(protocol, self.plan, self.session) if point_key(*job.point.key) not in done]
        if not self.prepared and any(job.refusal is None for job in todo):
            self.prepare(lamp_voltage, warm_up, self.characterisation_point)
        return todo

    def _rotation(self, job: Job) -> float | None:
        """The rotation the protocol set for the mounting of ``job`` [deg] (None: not set)."""
        if job.kind == "reference" or job.point.mounting < 0:
            return None
        return self.protocol.mountings.rotations[job.point.mounting]

    def _measure(self, job: Job) -> tuple[str, str, dict]:
        point = job.point
        dark_due = _dark_due(self.protocol, self.measured_since_dark, self.resume)
        frames = self.protocol.checks.frames if job.kind == "check" else self.protocol.exposure.frames
        try:
            row, raw = _measure_point(self.rig, self.protocol, point, dark_due, frames)
        except KeyboardInterrupt:
            raise
        except Exception as error:  # an instrument error: record it, go on, or stop
            message = f"{type(error).__name__}: {error}"
            self.result.errors += 1
            if type(error).__name__ == "LampError":
                self.writer.append_point({**_point_row(point, "error", message, self.session, self._rotation(job)),
                                          "instrument_time": self.clock(), "wall_time": _now_iso()})
                raise AcquisitionError(f"lamp failure at point {point.index}: {error}") from error
            self.consecutive_errors += 1
            return "error", message, {}
        self.consecutive_errors = 0
        self.result.measured += 1
        self.result.flagged += bool(row["flags"])
        # points measured since the last fresh dark, this one included
        self.measured_since_dark = 1 if dark_due else (self.measured_since_dark or 0) + 1
        if dark_due:
            first = raw[0]
            self.writer.append_dark({
                "after_index": point.index, "exposure": first.exposure, "gain": first.gain,
                "roi_mean": first.dark_level, "roi_std": first.dark_std, "roi_pixels": first.roi_pixels,
                "monitor": first.dark_monitor,
                "instrument_time": self.clock(), "wall_time": _now_iso(),
            })
        return "ok", "", row

    def _report(self, count: int, total: int, point: PlannedPoint, status: str) -> None:
        if not self.progress:
            return
        elapsed = time.perf_counter() - self.start_wall
        r = self.result
        self.progress(Progress(
            done=count, total=total, measured=r.measured, refused=r.refused, errors=r.errors,
            elapsed_wall=elapsed, eta_wall=elapsed / count * (total - count),
            instrument_time=self.clock() - self.start_instrument, point=point, status=status,
        ))

    def finish(self, status: str, error: str | None = None) -> None:
        """Record the final status; a failure to write it is reported, never raised."""
        r = self.result
        r.status = status
        r.wall_seconds = time.perf_counter() - self.start_wall
        try:
            r.instrument_seconds = self.clock() - self.start_instrument
        except Exception:  # noqa: BLE001 - the clock is read over a line that may be the one lost,
            r.instrument_seconds = math.nan  # and the status must still be written
        extra: dict[str, Any] = {"finished": _now_iso(), "last_run": {
            "measured": r.measured, "refused": r.refused, "errors": r.errors, "skipped": r.skipped,
            "flagged": r.flagged, "wall_seconds": r.wall_seconds,
            "instrument_seconds": r.instrument_seconds if math.isfinite(r.instrument_seconds) else None,
            "warm_up_seconds": r.warm_up_seconds}}
        if error:
            extra["error"] = error
        try:
            self.writer.finish(status, **extra)
        except OSError as failure:
            r.status_recorded = False
            r.messages.append(f"metadata.json could not be updated ({failure.strerror or failure}): it still says "
                              f"'running'; the points recorded so far are in {self.writer.points_path}")


def _is_file_system_error(error: BaseException) -> bool:
    """Whether ``error`` comes from the file system (a full disk, a vanished folder): an
    ``OSError`` with an error number. An instrument's reply timeout is an ``OSError`` too
    (``TimeoutError``), without one, and was reported as "cannot write the recording"."""
    return isinstance(error, OSError) and not isinstance(error, TimeoutError) and error.errno is not None


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
    extend: Callable[[RunResult], Extension] | None = None,
) -> RunResult:
    """Measure every point of a protocol on ``rig`` into the recording ``folder``.

    Parameters
    ----------
    protocol : Protocol, str or Path
        A loaded protocol or the path of a protocol file.
    rig : drivers.rig.Rig or compatible
        An opened rig.
    folder : path
        Recording folder (see :mod:`gonio.data`).
    resume : bool
        Continue an interrupted recording in ``folder``; points already recorded as ok or
        refused are skipped, failed points are measured again. A different experiment
        (protocol content, sample, rig settings, seed, lamp voltage, instruments) is
        refused with a message naming what differs.
    metadata : mapping, optional
        Extra metadata stored with the recording (under ``"rig"``: the rig and emulator
        configuration, seed); it takes part in the resume check.
    lamp_voltage : float
        Lamp supply voltage [V].
    warm_up : bool
        Wait for the lamp to stabilise before the first point.
    change_sample : callable, optional
        ``change_sample("reference")`` / ``change_sample("sample")`` swaps the sample for
        the reference standard and back (a prompt on a real rig, the emulator's sample
        holder otherwise).  A protocol that declares mountings (``[sample] mountings``,
        ``rotations`` or ``spin``) calls ``change_sample("sample", mounting=SampleMounting(...))``
        before the first point of every mounting.  Required when the protocol has a
        ``[reference]`` section or declares mountings.
    clock : callable, optional
        Instrument clock [s] recorded with each point (default: the rig's ``instrument_clock``,
        the emulator's simulated clock, when it offers one, else wall-clock monotonic time).
    progress : callable, optional
        Called with a :class:`Progress` after every point.
    max_consecutive_errors : int
        Stop the run after this many failed points in a row (a broken instrument), marking
        the recording "failed"; it can be resumed once the cause is fixed. A run that
        reaches the end with some failed points is "incomplete" (a resume measures them
        again); "complete" means every planned point was measured or refused.
    extend : callable, optional
        Called with the run's :class:`RunResult` (``instrument_seconds`` so far) once every
        point of the protocol so far is measured, the sample back in its holder and the
        camera's linearity series taken: an :class:`Extension` with ``[[block]]`` sections to
        append and measure in the same session (the recording's protocol becomes the
        extended one, so an interrupted run resumes it), or with ``text=None`` to end the
        run. Every decision is stored, with its note, in ``metadata["extensions"]``. An
        adaptive run (:mod:`gonio.adaptive`) chooses its next points this way.

    Returns
    -------
    RunResult

    Raises
    ------
    KeyboardInterrupt
        Re-raised after the recording is marked "interrupted" (resume it later).
    AcquisitionError
        The run could not start or stopped on repeated errors.
    gonio.data.RecordingError
        The folder cannot hold this recording (it holds another, or resume was refused).
    """
    if not isinstance(protocol, Protocol):
        protocol = load(protocol)
    if protocol.reference is not None and change_sample is None:
        raise AcquisitionError(
            f"{protocol.source}: the protocol measures a reference standard ({protocol.reference.label}) "
            "but no way to swap the sample was given (change_sample)"
        )
    if protocol.mountings.declared and change_sample is None:
        raise AcquisitionError(
            f"{protocol.source}: the protocol mounts the sample {protocol.mountings.count} time(s) "
            f"{'spinning ' if protocol.mountings.spin else ''}but no way to mount it was given (change_sample)"
        )
    clock = clock or getattr(rig, "instrument_clock", None) or time.monotonic
    _check_apertures(protocol, metadata)
    the_plan = plan(protocol)
    if protocol.checks.every > 0:
        _check_geometry(protocol, the_plan)  # refuse a protocol without a check point before writing
    info = {
        "protocol": {"name": protocol.name, "source": protocol.source, "text": protocol.text},
        "sample": {"label": protocol.sample, "metadata": dict(protocol.metadata)},
        "software": _software_versions(),
        "started": _now_iso(),
        "lamp_voltage": lamp_voltage,
        "stage": {"encoder_resolution_deg": {str(a): r for a, r in getattr(rig, "encoder_resolution", {}).items()},
                  "position_tolerance_deg": getattr(rig, "position_tolerance", None)},
        **dict(metadata or {}),
        "experiment": experiment_description(protocol, lamp_voltage, rig, metadata),
    }
    writer = RecordingWriter(Path(folder), info, resume=resume)
    session = len(writer.stored_metadata.get("resumes", []))
    done = writer.done_keys()
    jobs = build_jobs(protocol, the_plan, session)
    todo = [job for job in jobs if point_key(*job.point.key) not in done]
    result = RunResult(folder=Path(folder), skipped=len(jobs) - len(todo))
    run = _Run(protocol, the_plan, rig, writer, result, clock, change_sample, resume, session, progress,
               max_consecutive_errors)
    try:
        run.characterisation_point = _characterisation_point(rig, the_plan)
        if any(job.refusal is None for job in todo):
            run.prepare(lamp_voltage, warm_up, run.characterisation_point)
        while todo is not None:
            for count, job in enumerate(todo, start=1):
                run.do(count, len(todo), job)
            run.return_sample()
            run.characterise_linearity(lamp_voltage, warm_up)
            result.instrument_seconds = clock() - run.start_instrument
            todo = run.extend(extend(result), lamp_voltage, warm_up) if extend is not None else None
    except KeyboardInterrupt:
        run.finish("interrupted")
        raise
    except Exception as error:
        result.messages.append(str(error))
        run.finish("failed", error=str(error))
        if isinstance(error, (AcquisitionError, RecordingError)):
            raise
        if _is_file_system_error(error):
            raise AcquisitionError(f"run stopped: cannot write the recording: {error.strerror or error}"
                                   + "".join(f"; {m}" for m in result.messages[1:])) from error
        by_instrument = type(error).__module__.split(".")[0] == "drivers"  # the driver layer's errors
        raise AcquisitionError(f"run stopped{' by an instrument fault' if by_instrument else ''}: "
                               f"{type(error).__name__}: {error}") from error
    # every planned point measured or refused; failed points make the recording incomplete
    # (a resume measures them again), not complete
    run.finish("complete" if result.errors == 0 else "incomplete")
    return result
