"""Dark characterisation of a lamp monitor: its offset and its reading noise.

The rig's lamp monitor (camera ``MON?``, docs/protocol.md) reads the lamp output over each
exposure.  Dividing the sample signal by the reading cancels the lamp's flicker and
drift; what is left is the monitor's own noise and offset.  Both are measured with the
lamp off, where the reading is offset plus noise only:

- the offset is the mean of the dark readings [V];
- the noise is their scatter at two integration times ``t1 < t2``, interpolated as
  ``sigma^2(t) = a / t + b`` (white amplifier noise averaging down over the integration,
  plus a floor ``b >= 0`` such as the reading's quantisation).

:func:`characterise` turns dark readings into a :class:`MonitorDark`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["MonitorDark", "characterise"]


@dataclass(frozen=True)
class MonitorDark:
    """Offset and noise of the lamp monitor measured in the dark.

    Attributes
    ----------
    offset : float
        Mean reading with the lamp off [V].
    offset_sigma : float
        Standard error of ``offset`` [V].
    white : float
        ``a`` of ``sigma^2(t) = a / t + b`` [V^2 s].
    floor : float
        ``b`` of the same law [V^2].
    exposures : tuple of float
        Integration times of the dark readings [s].
    readings : int
        Dark readings per integration time.
    """

    offset: float
    offset_sigma: float
    white: float
    floor: float
    exposures: tuple[float, ...]
    readings: int

    def noise(self, exposure: float | np.ndarray) -> float | np.ndarray:
        """Rms noise of one reading integrated over ``exposure`` [V].

        Examples
        --------
        >>> float(MonitorDark(0.002, 1e-6, 9e-12, 0.0, (0.01, 0.1), 16).noise(0.01))
        3e-05
        """
        return np.sqrt(self.white / np.asarray(exposure, float) + self.floor)

    def to_dict(self) -> dict[str, Any]:
        """Plain numbers for a recording's metadata."""
        return {"offset_v": self.offset, "offset_sigma_v": self.offset_sigma, "white_v2_s": self.white,
                "floor_v2": self.floor, "exposures_s": list(self.exposures), "readings": self.readings}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "MonitorDark":
        """Inverse of :meth:`to_dict`."""
        return cls(float(data["offset_v"]), float(data["offset_sigma_v"]), float(data["white_v2_s"]),
                   float(data["floor_v2"]), tuple(float(t) for t in data["exposures_s"]), int(data["readings"]))


def characterise(readings_by_exposure: Mapping[float, Sequence[float]]) -> MonitorDark:
    """Offset and noise law of the monitor from dark readings at two integration times.

    Parameters
    ----------
    readings_by_exposure : mapping
        ``{exposure [s]: [reading [V], ...]}`` with exactly two exposures and at least 4
        readings each, taken with the lamp off.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> dark = characterise({t: 0.002 + 3e-5 * np.sqrt(0.01 / t) * rng.standard_normal(400) for t in (0.01, 0.1)})
    >>> round(dark.offset, 5), round(float(dark.noise(0.01)) / 3e-5, 1)
    (0.002, 1.0)
    """
    if len(readings_by_exposure) != 2:
        raise ValueError(f"need dark readings at exactly 2 integration times, got {sorted(readings_by_exposure)}")
    (t1, r1), (t2, r2) = sorted((float(t), np.asarray(r, float)) for t, r in readings_by_exposure.items())
    if not 0 < t1 < t2 or min(r1.size, r2.size) < 4:
        raise ValueError("need two distinct positive integration times with at least 4 readings each")
    v1, v2 = r1.var(ddof=1), r2.var(ddof=1)
    # sigma^2 = a / t + b through both points.  Sampling noise can make b or a negative:
    # b < 0 -> pure white noise (a from both points); a < 0 (the longer integration is no
    # quieter) -> a constant noise, the larger of the two variances.
    white = (v1 - v2) / (1.0 / t1 - 1.0 / t2)
    floor = v1 - white / t1
    if white < 0:
        white, floor = 0.0, max(v1, v2)
    elif floor < 0:
        white, floor = 0.5 * (v1 * t1 + v2 * t2), 0.0
    both = np.concatenate([r1, r2])
    weights = np.concatenate([np.full(r1.size, 1.0 / max(v1, 1e-300)), np.full(r2.size, 1.0 / max(v2, 1e-300))])
    offset = float(np.sum(weights * both) / np.sum(weights))
    return MonitorDark(offset, float(1.0 / math.sqrt(np.sum(weights))), float(white), float(floor),
                       (t1, t2), int(min(r1.size, r2.size)))
