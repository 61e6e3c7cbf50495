"""Which geometries the rig measures: the one rule of the driver and of a protocol's plan.

A geometry ``(theta_i, phi_i, view)`` is refused when

1. an axis target lies outside its travel limits (or is not finite),
2. camera and lamp come closer than the minimum separation plus
   :data:`drivers.rig_geometry.SEPARATION_MARGIN` (:func:`drivers.rig_geometry.too_close`), or
3. the radiance window does not fit on the sample's image with its margin
   (:func:`drivers.roi.roi_for_view`; the grazing views near 90 deg).

:class:`drivers.rig.Rig` builds a :class:`GeometryRule` from what its controller and camera
report (``SL?``/``SR?``, ``SENS:INFO?``); ``gonio.protocols.plan`` builds one from the
protocol's ``[rig]`` table. Both ask the same :meth:`GeometryRule.refusals`, so ``gonio
plan`` predicts exactly what ``gonio run`` refuses on a rig whose limits and camera the
protocol describes (the emulated rig by default).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .camera import SensorInfo
from .errors import GeometryError
from .rig_geometry import (AXIS_PHI_I, AXIS_THETA_I, AXIS_VIEW, angular_separation, camera_direction, separation_refusal,
                           too_close, travel_refusal)
from .roi import SAMPLE_SIZE_MM, roi_for_view

__all__ = ["GeometryRule", "EMULATED_SENSOR"]

#: What the emulated camera reports to ``SENS:INFO?``: 512 x 480 pixels of 15 um, 12 bit,
#: a 150 mm lens on the 6-foot (1828.8 mm) beam (docs/emulator.md, "Optics").
EMULATED_SENSOR = SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8)


@dataclass(frozen=True)
class GeometryRule:
    """Everything that decides whether the rig can measure a geometry.

    Attributes
    ----------
    camera_range, lamp_theta_range, lamp_phi_range : tuple of float
        Travel limits of axis 1 (signed camera angle), 2 (lamp polar angle) and 3 (lamp
        azimuth) [deg].
    min_separation : float
        Smallest camera-lamp angle the rig allows [deg] (:func:`drivers.rig_geometry.too_close`).
    sensor : SensorInfo
        The camera's sensor and optics (where the sample is imaged).
    roi_fraction : float
        Side of the radiance window as a fraction of the sample side [-].
    sample_size_mm : float
        Side of the square sample [mm].
    roi_margin_px : float
        Margin between the window and the edge of the sample's image [pixel].
    """

    camera_range: tuple[float, float]
    lamp_theta_range: tuple[float, float]
    lamp_phi_range: tuple[float, float]
    min_separation: float
    sensor: SensorInfo = EMULATED_SENSOR
    roi_fraction: float = 0.5
    sample_size_mm: float = SAMPLE_SIZE_MM
    roi_margin_px: float = 2.0

    def refusal(self, theta_i: float, phi_i: float, view: float) -> str | None:
        """Why the rig refuses the geometry, or None if it measures it.

        Parameters
        ----------
        theta_i, phi_i : float
            Lamp polar angle and azimuth [deg].
        view : float
            Signed camera angle [deg].
        """
        return self.refusals(theta_i, phi_i, (view,))[0]

    def refusals(self, theta_i: float, phi_i: float, views: Sequence[float]) -> list[str | None]:
        """:meth:`refusal` for every camera angle of one lamp direction (one array pass).

        The first failing test names the reason: travel (view, then lamp), separation, window.
        """
        lamp = (travel_refusal(AXIS_THETA_I, float(theta_i), self.lamp_theta_range)
                or travel_refusal(AXIS_PHI_I, float(phi_i), self.lamp_phi_range))
        reasons = [travel_refusal(AXIS_VIEW, float(view), self.camera_range) or lamp for view in views]
        open_views = [i for i, reason in enumerate(reasons) if reason is None]
        if not open_views:
            return reasons
        view_array = np.array([float(views[i]) for i in open_views])
        separations = angular_separation(theta_i, phi_i, *camera_direction(view_array))
        close = too_close(separations, self.min_separation)
        for i, separation, is_close in zip(open_views, separations.tolist(), close.tolist()):
            reasons[i] = separation_refusal(separation, self.min_separation) if is_close else self._window_refusal(views[i])
        return reasons

    def _window_refusal(self, view: float) -> str | None:
        try:
            roi_for_view(self.sensor, float(view), fraction=self.roi_fraction,
                         sample_size_mm=self.sample_size_mm, margin_px=self.roi_margin_px)
        except GeometryError as error:
            return str(error)
        return None
