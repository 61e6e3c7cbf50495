"""Photon-transfer analysis of a camera (EMVA Standard 1288, linear camera model).

EMVA 1288 describes a linear camera by the mean and temporal variance of its digital
signal ``y``:

    mu_y - mu_y.dark            = K * eta * mu_p                        (signal)
    sigma_y^2 - sigma_y.dark^2  = K * (mu_y - mu_y.dark)                (photon transfer)
    sigma_y.dark^2              = K^2 sigma_d^2 + sigma_q^2,  sigma_q^2 = 1/12 DN^2

with the overall system gain ``K`` [DN/e-], the dark noise ``sigma_d`` [e-] and the
quantisation noise ``sigma_q``. The temporal variance is taken from *pairs* of frames at
the same exposure: ``sigma_y^2 = var(y_A - y_B) / 2`` over the pixels of a region, which
removes every fixed pattern (DSNU, PRNU, illumination non-uniformity), and the means from
``(y_A + y_B) / 2``.

Decisions (documented here, tested in tests/drivers/test_driver_ptc.py):

- ``K`` is the slope of a straight line *through the origin* fitted to the photon-transfer
  points, as the model has no intercept after dark subtraction; only points up to
  ``fit_fraction`` (70 %) of the saturation mean are used, the saturation mean being the
  mean at which the temporal variance peaks (EMVA 1288, saturation point), or the largest
  mean when the variance does not peak.
- The dark variance ``sigma_y.dark^2`` is extrapolated to zero exposure with a straight
  line in the exposure time (dark-current shot noise grows linearly with it), and
  ``sigma_d = sqrt(sigma_y.dark^2(0) - 1/12) / K``.
- The dark signal is fitted as ``mu_y.dark = offset + rate * t``; its largest relative
  deviation from the line measures the linearity of the dark signal.

References
----------
European Machine Vision Association, "EMVA Standard 1288: Standard for Characterization
of Image Sensors and Cameras", Release 3.1 (2016), sections 2 (linear model), 6.3
(photon transfer method) and 7 (dark current).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .spatial import spatial_statistics

__all__ = ["PairStatistics", "PhotonTransferResult", "pair_statistics", "photon_transfer", "acquire_photon_transfer"]

#: Quantisation noise variance of a uniform ADC [DN^2].
QUANTIZATION_VARIANCE = 1.0 / 12.0


@dataclass(frozen=True)
class PairStatistics:
    """Mean and temporal variance of a pair of frames over a region [DN], [DN^2].

    ``spatial_variance`` is the variance over the region of the pair's mean image
    ``(A + B) / 2`` [DN^2]: fixed patterns (PRNU, DSNU, illumination, the target's texture)
    plus half the temporal variance (EMVA 1288, section 8: spatial non-uniformity).
    ``white_variance`` is its part that is independent from pixel to pixel
    (:func:`drivers.spatial.spatial_statistics`): the camera's own fixed patterns and the
    temporal noise, without the texture of the target or the beam's profile.
    """

    mean: float
    variance: float
    pixels: int
    spatial_variance: float = float("nan")
    white_variance: float = float("nan")


def pair_statistics(frame_a: np.ndarray, frame_b: np.ndarray) -> PairStatistics:
    """EMVA 1288 mean ``(A + B) / 2`` and temporal variance ``var(A - B) / 2`` of a frame pair.

    The variance uses the difference's own mean (``ddof=1``), which removes a small change
    of the mean level between the two frames (e.g. lamp flicker) from the noise.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> a, b = rng.normal(100, 2, (2, 200, 200))
    >>> s = pair_statistics(a, b)
    >>> round(s.mean), round(s.variance, 1)
    (100, 4.0)
    """
    a = np.asarray(frame_a, dtype=float)
    b = np.asarray(frame_b, dtype=float)
    if a.shape != b.shape or a.size < 2:
        raise ValueError(f"frame shapes {a.shape} and {b.shape} must match and hold >= 2 pixels")
    diff = a - b
    mean_image = 0.5 * (a + b)
    white = spatial_statistics(mean_image).white_variance if a.ndim == 2 and min(a.shape) >= 8 else float("nan")
    return PairStatistics(float(0.5 * (a.mean() + b.mean())), float(diff.var(ddof=1) / 2.0), int(a.size),
                          float(mean_image.var(ddof=1)), float(white))


@dataclass(frozen=True)
class PhotonTransferResult:
    """Result of :func:`photon_transfer`.

    Attributes
    ----------
    system_gain : float
        K [DN/e-].
    system_gain_error : float
        Standard error of K from the fit [DN/e-].
    dark_noise_dn : float
        Temporal dark noise sigma_y.dark at zero exposure [DN].
    dark_noise_e : float
        Dark noise sigma_d in electrons [e-].
    dark_offset : float
        Dark signal at zero exposure [DN].
    dark_rate : float
        Dark signal growth [DN/s].
    dark_linearity : float
        Largest |deviation| of the dark means from their straight line, relative to the
        dark signal range ``rate * (t_max - t_min)`` [-] (0 when it is exactly linear).
    saturation_mean : float
        Mean grey value at the variance peak (or the largest mean) [DN].
    dark_variance_rate : float
        Growth of the temporal dark variance with exposure (dark-current shot noise)
        [DN^2/s]: ``sigma_y.dark^2(t) = dark_noise_dn^2 + dark_variance_rate * t``.
    prnu : float
        Photo-response non-uniformity: rms of the pixel-to-pixel response relative to the
        mean [-], from the spatial variance of the brightest fitted pair after removing
        its temporal part and the dark pair's fixed pattern (EMVA 1288, section 8); NaN
        without spatial statistics. The white part of the spatial variance is used when
        the frames are images (``PairStatistics.white_variance``), so that a textured
        target or the beam's profile, correlated over many pixels, is not taken for the
        camera's non-uniformity.
    exposures, mean, variance, dark_mean, dark_variance : numpy.ndarray
        The per-exposure points [s], [DN], [DN^2].
    used : numpy.ndarray of bool
        Points used in the fit of K.
    """

    system_gain: float
    system_gain_error: float
    dark_noise_dn: float
    dark_noise_e: float
    dark_offset: float
    dark_rate: float
    dark_linearity: float
    saturation_mean: float
    exposures: np.ndarray
    mean: np.ndarray
    variance: np.ndarray
    dark_mean: np.ndarray
    dark_variance: np.ndarray
    used: np.ndarray
    dark_variance_rate: float = float("nan")
    prnu: float = float("nan")


def photon_transfer(
    exposures: Sequence[float],
    light: Sequence[PairStatistics],
    dark: Sequence[PairStatistics],
    *,
    fit_fraction: float = 0.7,
) -> PhotonTransferResult:
    """Fit the EMVA 1288 photon-transfer curve.

    Parameters
    ----------
    exposures : sequence of float
        Exposure times [s], one per point, at least 3 distinct values.
    light, dark : sequence of PairStatistics
        Statistics of the illuminated and dark frame pairs at each exposure.
    fit_fraction : float
        Upper end of the fitted range as a fraction of the saturation mean [-].

    Returns
    -------
    PhotonTransferResult

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> K, sd = 0.1, 12.0                                   # DN/e-, e-
    >>> def pair(electrons):
    ...     f = lambda: np.round(100 + K * (rng.poisson(electrons, 40000) + rng.normal(0, sd, 40000)))
    ...     return pair_statistics(f(), f())
    >>> t = np.linspace(0.001, 0.02, 8)
    >>> r = photon_transfer(t, [pair(1e6 * x) for x in t], [pair(0.0) for x in t])
    >>> abs(r.system_gain / K - 1) < 0.02, abs(r.dark_noise_e / sd - 1) < 0.1
    (True, True)
    """
    t = np.asarray(exposures, dtype=float)
    if not (len(t) == len(light) == len(dark)) or len(np.unique(t)) < 3:
        raise ValueError(
            f"exposures ({len(t)}), light ({len(light)}) and dark ({len(dark)}) must have the "
            "same length with at least 3 distinct exposures"
        )
    if not 0 < fit_fraction <= 1:
        raise ValueError(f"fit_fraction={fit_fraction!r} must be in (0, 1]")
    mean = np.array([s.mean for s in light])
    var = np.array([s.variance for s in light])
    dmean = np.array([s.mean for s in dark])
    dvar = np.array([s.variance for s in dark])
    x = mean - dmean
    y = var - dvar
    peak = int(np.argmax(var))
    saturation_mean = float(mean[peak])
    used = (x > 0) & (mean <= dmean + fit_fraction * (saturation_mean - dmean))
    if peak == len(mean) - 1:  # the variance did not peak: no saturation reached
        used = x > 0
    if used.sum() < 2:
        raise ValueError("fewer than 2 photon-transfer points below the saturation range")
    xs, ys = x[used], y[used]
    gain = float(np.sum(xs * ys) / np.sum(xs * xs))
    residual = ys - gain * xs
    gain_error = float(np.sqrt(np.sum(residual**2) / (len(xs) - 1) / np.sum(xs * xs)))
    var_slope, var0 = np.polyfit(t, dvar, 1)
    dark_noise_dn = float(np.sqrt(max(var0, 0.0)))
    dark_noise_e = float(np.sqrt(max(var0 - QUANTIZATION_VARIANCE, 0.0)) / gain)
    rate, offset = np.polyfit(t, dmean, 1)
    span = abs(rate) * (t.max() - t.min())
    deviation = np.max(np.abs(dmean - (offset + rate * t)))
    linearity = float(deviation / span) if span > 0 else float("inf")
    return PhotonTransferResult(
        system_gain=gain, system_gain_error=gain_error,
        dark_noise_dn=dark_noise_dn, dark_noise_e=dark_noise_e,
        dark_offset=float(offset), dark_rate=float(rate), dark_linearity=linearity,
        saturation_mean=saturation_mean,
        exposures=t, mean=mean, variance=var, dark_mean=dmean, dark_variance=dvar, used=used,
        dark_variance_rate=float(var_slope), prnu=_prnu(light, dark, used),
    )


def _prnu(light: Sequence[PairStatistics], dark: Sequence[PairStatistics], used: np.ndarray) -> float:
    """PRNU from the brightest used pair: sqrt(light fixed-pattern var - dark fixed-pattern var) / signal
    (the white parts of the spatial variances when known)."""
    k = int(np.flatnonzero(used)[np.argmax([light[i].mean for i in np.flatnonzero(used)])])

    def spatial(pair: PairStatistics) -> float:
        return pair.white_variance if np.isfinite(pair.white_variance) else pair.spatial_variance

    fixed_light = spatial(light[k]) - 0.5 * light[k].variance
    fixed_dark = spatial(dark[k]) - 0.5 * dark[k].variance
    signal = light[k].mean - dark[k].mean
    if not (np.isfinite(fixed_light) and np.isfinite(fixed_dark) and signal > 0):
        return float("nan")
    return float(np.sqrt(max(fixed_light - fixed_dark, 0.0)) / signal)


def acquire_photon_transfer(rig, exposures: Sequence[float], region=None, *, fit_fraction: float = 0.7) -> PhotonTransferResult:
    """Run a photon-transfer measurement through a :class:`~drivers.rig.Rig`.

    At each exposure two illuminated and two dark (shutter closed) frames are read and
    reduced over ``region`` (a :class:`~drivers.camera.Roi`). With the default
    ``region=None`` the rig's current ROI is used and only its pixels are transferred
    (``ROI:DATA?``); another region is cut from full frames (``FRAME?``, slower). The rig
    must look at a steadily lit, non-saturating part of the sample.

    Returns
    -------
    PhotonTransferResult
    """
    if region is None and rig._roi is None:
        raise ValueError("region is None and the rig has no ROI yet; move the rig first")
    if region is None or region == rig._roi:
        def light_pixels(t=None):
            return rig.roi_frame(t)

        def dark_pixels():
            return rig.dark_frame(roi_pixels=True).frame
    else:
        rows, cols = region.slices()

        def light_pixels(t=None):
            return rig.frame(t)[rows, cols]

        def dark_pixels():
            return rig.dark_frame(full=True).frame[rows, cols]
    light, dark = [], []
    for t in exposures:
        light.append(pair_statistics(light_pixels(float(t)), light_pixels()))
        dark.append(pair_statistics(dark_pixels(), dark_pixels()))
    return photon_transfer(exposures, light, dark, fit_fraction=fit_fraction)
