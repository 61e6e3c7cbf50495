"""What one measurement of the rig returns: :class:`Measurement` and :class:`DarkLevel`."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .camera import Roi, RoiStats
from .rig_geometry import AXIS_PHI_I, AXIS_THETA_I, AXIS_VIEW

__all__ = ["DarkLevel", "Measurement"]


@dataclass(frozen=True)
class DarkLevel:
    """Dark (shutter closed) ROI statistics at one exposure and gain.

    Attributes
    ----------
    exposure : float
        Exposure time [s].
    gain : float
        Analog gain factor [-].
    stats : RoiStats
        ROI statistics of the dark frame [DN].
    source : str
        ``"measured"``, ``"cached"`` or ``"model"`` (from :meth:`Rig.calibrate_dark`).
    frame : numpy.ndarray or None
        The full dark frame when requested [DN].
    monitor : float
        Lamp monitor reading during the dark exposure [V] (the lamp still shines on the
        monitor with the camera's shutter closed); NaN without a monitor.
    """

    exposure: float
    gain: float
    stats: RoiStats
    source: str = "measured"
    frame: np.ndarray | None = field(default=None, repr=False, compare=False)
    monitor: float = math.nan

    @property
    def level(self) -> float:
        """Mean dark level in the ROI [DN]."""
        return self.stats.mean


@dataclass(frozen=True)
class Measurement:
    """One radiance measurement at one geometry (all angles in degrees).

    Attributes
    ----------
    theta_i, phi_i, view : float
        Requested geometry: lamp polar angle, lamp azimuth, signed camera angle [deg].
    theta_r, phi_r : float
        Camera direction implied by ``view`` [deg].
    stage_position : dict
        Encoder readback ``{1: view, 2: theta_i, 3: phi_i}`` after the move [deg].
    roi : Roi
        Region of interest [pixel].
    roi_mean, roi_std : float
        Raw ROI mean and standard deviation of the light frame [DN].
    roi_pixels, roi_saturated : int
        Pixel count and saturated pixel count of the ROI [-].
    exposure : float
        Exposure time [s].
    gain : float
        Analog gain factor [-].
    dark_level, dark_std : float
        Dark ROI mean and standard deviation at the same exposure and gain [DN].
    dark_source : str
        How the dark level was obtained (see :class:`DarkLevel`).
    signal : float
        ``roi_mean - dark_level`` [DN].
    radiance : float
        Relative radiance: ``signal / (exposure * gain) * radiance_scale`` [DN/s per
        ROI pixel at unit gain, times the scale].
    radiance_error : float
        One-sigma uncertainty of ``radiance`` from the ROI statistics (spatial standard
        deviation over the square root of the pixel count, light and dark) [same unit].
    lamp_voltage, lamp_current : float
        Lamp supply readings taken just before the exposure [V], [A].
    time_start, time_end : float
        Wall-clock times (``time.time()``) around the measurement [s].
    attempts : int
        Exposures taken to settle the automatic exposure [-].
    monitor : float
        Lamp monitor reading integrated over the exposure [V]; NaN when the rig has no
        monitor (:attr:`Rig.has_monitor`).
    dark_monitor : float
        Lamp monitor reading during the dark frame used [V] (NaN for a cached or
        modelled dark, or without a monitor).
    """

    theta_i: float
    phi_i: float
    view: float
    theta_r: float
    phi_r: float
    stage_position: dict
    roi: Roi
    roi_mean: float
    roi_std: float
    roi_pixels: int
    roi_saturated: int
    exposure: float
    gain: float
    dark_level: float
    dark_std: float
    dark_source: str
    signal: float
    radiance: float
    radiance_error: float
    lamp_voltage: float
    lamp_current: float
    time_start: float
    time_end: float
    attempts: int = 1
    monitor: float = math.nan
    dark_monitor: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """Flat dictionary of plain numbers and strings (for CSV/JSON records)."""
        out = dataclasses.asdict(self)
        roi = out.pop("roi")
        out.update({f"roi_{k}": v for k, v in roi.items()})
        position = out.pop("stage_position")
        out.update({
            "stage_view": position.get(AXIS_VIEW, math.nan),
            "stage_theta_i": position.get(AXIS_THETA_I, math.nan),
            "stage_phi_i": position.get(AXIS_PHI_I, math.nan),
        })
        return out
