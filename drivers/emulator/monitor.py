"""Lamp monitor: a photodiode behind a beam splitter that sees the lamp, not the sample.

Ratio (reference-beam) detection is how optical instruments cancel the fluctuations of
their source: every sample reading is divided by a simultaneous reading of the source.
The emulated rig has such a monitor, a photodiode with a transimpedance amplifier,
integrated over every camera exposure (the camera triggers it) and read with the
camera's ``MONitor?`` query (docs/protocol.md).

Model of one reading over an exposure of ``t`` seconds::

    reading = responsivity * lamp_output + dark_offset + noise,
    noise ~ N(0, (noise_10ms * sqrt(10 ms / t))^2)

``lamp_output`` is the same mean lamp output (drift, warm-up and the exposure's flicker
included) that lights the sample during that exposure, relative to a warm lamp at rated
voltage.  The noise is additive amplifier noise, white on the time scales of an
exposure, so it averages down as ``1 / sqrt(t)`` and is the same with the lamp off: the
rig can measure it, and the dark offset, in the dark (``drivers.rig.Rig.measure_monitor_dark``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MonitorParams", "LampMonitor"]


@dataclass(frozen=True)
class MonitorParams:
    """Constants of the lamp monitor.

    Attributes
    ----------
    responsivity_v : float
        Reading for a warm lamp at rated voltage, without offset [V].
    dark_offset_v : float
        Reading with the lamp off (amplifier offset and photodiode dark current) [V].
    noise_10ms_v : float
        Rms noise of a reading integrated over 10 ms [V]; scales as ``1 / sqrt(t)``.
    """

    responsivity_v: float = 1.0
    dark_offset_v: float = 0.002
    noise_10ms_v: float = 3e-5


class LampMonitor:
    """The monitor photodiode of an emulated rig.

    Parameters
    ----------
    params : MonitorParams
        Model constants.
    rng : numpy.random.Generator
        Source of the reading noise (its own stream, so switching the monitor's noise
        on or off leaves every other random process of the rig unchanged).

    Examples
    --------
    >>> monitor = LampMonitor(MonitorParams(noise_10ms_v=0.0), np.random.default_rng(0))
    >>> monitor.read(lamp_output=0.5, exposure_s=0.02)
    0.502
    """

    def __init__(self, params: MonitorParams, rng: np.random.Generator) -> None:
        self.params = params
        self.rng = rng

    def noise_rms(self, exposure_s: float) -> float:
        """Rms noise of one reading integrated over ``exposure_s`` [V]."""
        return self.params.noise_10ms_v * math.sqrt(0.01 / exposure_s)

    def read(self, lamp_output: float, exposure_s: float) -> float:
        """One reading integrated over an exposure [V].

        Parameters
        ----------
        lamp_output : float
            Mean lamp output during the exposure, relative to a warm lamp at rated
            voltage [-] (0 with the lamp off).
        exposure_s : float
            Integration time [s], > 0.
        """
        p = self.params
        noise = self.noise_rms(exposure_s) * float(self.rng.standard_normal()) if p.noise_10ms_v else 0.0
        return p.responsivity_v * lamp_output + p.dark_offset_v + noise
