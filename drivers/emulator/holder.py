"""The emulated rig's sample holder: what is mounted, how it sits, and what its texture does.

The rig's own sample (the one the emulator was started with) has the texture, wedge and
seating of :mod:`drivers.emulator.texture` when the rig's
:class:`~drivers.emulator.systematics.Systematics` switch them on; anything else put in the
holder (a reference standard) is taken as uniform, flat and seated square, sharing only
the holder's own tilt. Each mounting of the sample is drawn from the rig's seed and its
index (:func:`~drivers.emulator.texture.draw_mounting`), so the same mounting comes back
the same after a restart.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .systematics import Systematics
from .texture import (Footprints, LabTexture, Mounting, SlopeResponse, TextureRealisation, draw_mounting,
                      footprints, lab_texture, mounting_tilt, realise_texture, relative_radiance_image,
                      slope_response)
from .world import Optics

__all__ = ["SampleHolder", "TEXTURE_STREAM", "MOUNTING_STREAM", "WEDGE_STREAM", "MISMATCH_STREAM"]

#: Random streams of the holder among the children of the rig's seed (the rig uses 0 to 7,
#: the ``lab`` preset's misalignment 8): each source draws from its own, so switching one
#: on or off leaves every other draw of the rig unchanged.
TEXTURE_STREAM, MOUNTING_STREAM, WEDGE_STREAM, MISMATCH_STREAM = 9, 10, 11, 12
#: Rendered texture footprints kept per view (each about 5 MB).
_FOOTPRINT_CACHE = 8

Brdf = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _stream(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(stream,)))


class SampleHolder:
    """What is in the holder of an emulated rig and how it sits.

    Parameters
    ----------
    systematics : Systematics
        The rig's departures from the ideal (texture, wedge, mount tilt used here).
    seed : int
        The rig's seed.
    optics : Optics
        The rig's layout (image geometry, apertures).

    Attributes
    ----------
    mounting : Mounting or None
        How the rig's own sample sits (None while something else is mounted).
    wedge : (float, float)
        The sample's wedge as a tilt toward the sample's +x and +y [deg] (direction drawn
        from the seed, magnitude ``systematics.wedge``).
    """

    def __init__(self, systematics: Systematics, seed: int, optics: Optics) -> None:
        self.systematics = systematics
        self.seed = int(seed)
        self.optics = optics
        azimuth = _stream(seed, WEDGE_STREAM).uniform(0.0, 2 * math.pi) if systematics.wedge else 0.0
        self.wedge = (systematics.wedge * math.cos(azimuth), systematics.wedge * math.sin(azimuth))
        self._mismatch_rng = _stream(seed, MISMATCH_STREAM)
        self._texture: TextureRealisation | None = None
        self._lab: LabTexture | None = None
        self._footprints: dict[float, Footprints] = {}
        self._responses: dict[tuple, SlopeResponse] = {}
        self.mounting: Mounting | None = None
        self.mount(0)

    # -- mounting -------------------------------------------------------------------------
    def mount(self, index: int = 0, rotation_deg: float | None = None, spin: bool = False) -> Mounting:
        """Put the rig's own sample in the holder as mounting ``index`` (rotation drawn
        uniformly when None; the first mounting, index 0 with no rotation given, sits at 0)."""
        if index < 0:
            raise ValueError(f"mounting index must be >= 0, got {index!r}")
        if rotation_deg is not None and not math.isfinite(rotation_deg):
            raise ValueError(f"rotation must be a finite angle in degrees, got {rotation_deg!r}")
        rotation = 0.0 if (rotation_deg is None and index == 0) else rotation_deg
        self.mounting = draw_mounting(self.seed, index, rotation, spin, self.systematics.mount_tilt, MOUNTING_STREAM)
        self._clear()
        return self.mounting

    def mount_other(self) -> None:
        """Something other than the rig's sample is in the holder (uniform, flat, seated square)."""
        self.mounting = None
        self._clear()

    def _clear(self) -> None:
        self._lab = None
        self._footprints.clear()
        self._responses.clear()

    def tilt(self) -> tuple[float, float]:
        """Tilt of what is mounted beyond the holder's own, toward +x and +y [deg]."""
        if self.mounting is None:
            return 0.0, 0.0
        return mounting_tilt(self.mounting, self.wedge)

    # -- what the camera sees ----------------------------------------------------------------
    @property
    def textured(self) -> bool:
        """Whether the mounted object shows a texture."""
        return self.mounting is not None and self.systematics.textured

    def texture(self) -> TextureRealisation:
        """The rig's sample's texture (realised once from the seed)."""
        if self._texture is None:
            s = self.systematics
            self._texture = realise_texture(s.texture_albedo, s.texture_slope, s.texture_length,
                                            _stream(self.seed, TEXTURE_STREAM))
        return self._texture

    def _footprints_at(self, theta_r: float) -> Footprints:
        if self._lab is None:
            self._lab = lab_texture(self.texture(), self.mounting)  # type: ignore[arg-type]
        where = self._footprints.get(theta_r)
        if where is None:
            if len(self._footprints) >= _FOOTPRINT_CACHE:
                self._footprints.pop(next(iter(self._footprints)))
            where = footprints(self._lab, self.optics, theta_r)
            self._footprints[theta_r] = where
        return where

    def relative_image(self, brdf: Brdf, angles: tuple[float, float, float, float], key: tuple) -> np.ndarray | None:
        """Each pixel's radiance relative to the untextured sample's at the true directions
        ``angles`` (theta_i, phi_i, theta_r, phi_r in the sample's mean frame [deg]), or None
        when nothing textured is mounted; ``key`` caches the slope response (the axis
        positions)."""
        if not self.textured:
            return None
        response = self._responses.get(key)
        if response is None:
            if len(self._responses) > 4096:
                self._responses.clear()
            response = slope_response(brdf, *angles, self.systematics.texture_slope)
            self._responses[key] = response
        return relative_radiance_image(self._footprints_at(angles[2]), response)

    def beam_mismatch(self) -> float:
        """The factor of one exposure's irradiance on the sample that the lamp monitor does
        not see, ``1 + monitor_mismatch x N(0, 1)`` (1 without a mismatch: no draw)."""
        rms = self.systematics.monitor_mismatch
        return 1.0 + rms * float(self._mismatch_rng.standard_normal()) if rms else 1.0
