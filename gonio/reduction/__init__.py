"""Reduce a recording to radiance per geometry, with an uncertainty budget by component.

:func:`reduce_recording` reads a recording (:mod:`gonio.data`) and returns a
:class:`Reduced`: one value per measured geometry (repeats combined) at the geometry the
stage read back, its uncertainty split into the components of
:data:`gonio.uncertainty.COMPONENTS`, and the lamp irradiance ``E_0`` from the reference
standard with its own budget. What each component is and how it is estimated is in
docs/acquisition.md; in short:

- CCD: from the photon-transfer characterisation the run stored (system gain, dark noise,
  PRNU), applied to each point's own signal, exposure and window;
- lamp: divided out by the lamp monitor when the rig has one (what remains is the
  monitor's noise, measured in the dark); otherwise the drift is interpolated between
  the protocol's check measurements and the flicker measured from their frames (or, with
  neither, from repeats); with none of these the budget says the lamp was not measured;
- angle: the readback's quantisation times the local slope of the measured curve;
- linearity: every reading corrected by the camera's linearity series (measured after the
  run's last point, :mod:`drivers.linearity`); the correction's uncertainty is common to
  the readings, a covariance between values relative to the reference standard's;
- calibration: the reference standard reduced exactly like the sample (same budget, the
  same aperture average the fit uses), its certificate and its departure from Lambertian;
  one ``E_0`` for every value, or (``calibration="per-incidence"`` of the datasets) the
  irradiance the standard gave at each lamp polar angle, for a beam that is not uniform.

Nothing is dropped silently: saturated points are excluded and counted, points with
little or negative signal are kept with their uncertainty and flagged ``low_signal``.
"

The package's modules: :mod:`~gonio.reduction.readings` (every reading, lamp-normalised,
with its own budget), :mod:`~gonio.reduction.geometry` (readback geometry, repeats and
local slopes), :mod:`~gonio.reduction.combining` (repeats combined by their
correlations), :mod:`~gonio.reduction.result` (:class:`Reduced`: values, budget,
covariance and the fit datasets) and :mod:`~gonio.reduction.recording`
(:func:`reduce_recording`, :func:`combine_reduced`).
"""
from __future__ import annotations

from .readings import CHECK_BLOCK, REFERENCE_BLOCK, Readings, read_readings
from .recording import combine_reduced, reduce_recording
from .result import (BRDF_COVARIANCE, BRDF_TABLE, CALIBRATIONS, LOW_SIGNAL_SIGMAS, REDUCED_BUDGET, REDUCED_TABLE, REDUCTION_FORMAT, SATURATED_MAJORITY,
                     IncidenceCalibration, Reduced, is_whole_reduction)

__all__ = ["Reduced", "IncidenceCalibration", "Readings", "reduce_recording", "read_readings", "combine_reduced",
           "REFERENCE_BLOCK", "CHECK_BLOCK", "SATURATED_MAJORITY", "LOW_SIGNAL_SIGMAS", "REDUCTION_FORMAT",
           "CALIBRATIONS", "REDUCED_TABLE", "REDUCED_BUDGET", "is_whole_reduction", "BRDF_TABLE",
           "BRDF_COVARIANCE"]
