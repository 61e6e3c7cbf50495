"""Uncertainty budget of a radiance reading, component by component (GUM).

Pure functions of recorded numbers, used by :mod:`gonio.reduction`. Every component is a
standard uncertainty of one reading's signal rate, in the rate's own unit [DN/s] unless
it says *relative*; components are independent and add in quadrature, except where a
function says they are common to several readings. The names of the components are the
keys of :data:`COMPONENTS`; docs/acquisition.md explains how each is estimated.

References
----------
JCGM 100:2008, "Evaluation of measurement data - Guide to the expression of uncertainty in
measurement" (GUM), sections 4.2 (Type A), 4.3 (Type B) and 5.1 (uncorrelated input
quantities). EMVA Standard 1288 release 4.0 Linear (2021), section 2 (sensor model) and
section 8 (spatial non-uniformity).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

__all__ = [
    "COMPONENTS",
    "CameraModel",
    "LinearityCorrection",
    "ccd_components",
    "pooled_excess_variance",
    "interpolate_drift",
    "interpolation_excess",
    "local_slopes",
    "quantisation_sigma",
    "texture_relative",
    "monitor_ratio_variance",
    "MountingFactors",
    "mounting_factors",
]

#: Budget components of one reduced value: name -> what it is.
COMPONENTS: dict[str, str] = {
    "shot_read": "photon shot and read noise of the light frames (EMVA 1288 temporal noise)",
    "dark": "temporal noise of the dark frame subtracted",
    "prnu": "photo-response non-uniformity averaged over the ROI, relative to the largest ROI (fixed per window)",
    "ccd": "CCD noise from the ROI statistics alone (recordings without a camera characterisation)",
    "lamp_monitor": "lamp monitor noise and dark offset (flicker and drift cancel in the ratio)",
    "lamp_flicker": "lamp flicker of the exposure (unmonitored; measured from checks or repeats)",
    "lamp_drift": "uncertainty of the lamp drift interpolated between checks (unmonitored)",
    "angle": "stage readback uncertainty times the local slope of the measured curve",
    "linearity": "camera linearity correction's uncertainty, relative to the reference standard's readings "
                 "(correlated between values)",
    "monitor_ratio": "irradiance on the sample that the lamp monitor does not see (Type A from each mounting's "
                     "monitor series)",
    "texture": "the sample's texture averaged over the camera's window (Type A from each mounting's image; "
               "common to every value of the sample)",
    "mounting": "change of the values between mountings of the sample: its seating, tilt and the texture the "
                "window sees (Type A from the mountings; correlated between values of one mounting)",
}


@dataclass(frozen=True)
class CameraModel:
    """EMVA 1288 parameters of the camera as characterised during a run.

    Attributes
    ----------
    system_gain : float
        K at ``gain_factor`` [DN/e-].
    dark_variance : float
        Temporal dark variance at zero exposure [DN^2].
    dark_variance_rate : float
        Its growth with exposure [DN^2/s].
    prnu : float
        Relative rms pixel response non-uniformity [-].
    gain_factor : float
        Analog gain factor of the characterisation [-].
    """

    system_gain: float
    dark_variance: float
    dark_variance_rate: float
    prnu: float
    gain_factor: float = 1.0

    @classmethod
    def from_metadata(cls, data: Mapping) -> "CameraModel | None":
        """From ``metadata["camera"]`` of a recording; None when missing or failed."""
        try:
            return cls(float(data["system_gain_dn_per_e"]), float(data["dark_variance_dn2"]),
                       max(float(data["dark_variance_rate_dn2_per_s"]), 0.0),
                       float(data["prnu"]) if np.isfinite(float(data["prnu"])) else 0.0,
                       float(data.get("gain_factor", 1.0)))
        except (KeyError, TypeError, ValueError):
            return None

    def dark_variance_at(self, exposure: np.ndarray, gain: np.ndarray) -> np.ndarray:
        """Temporal dark variance of one pixel [DN^2] at exposure [s] and gain factor [-].

        The variance is taken to scale with the square of the analog gain factor relative
        to the characterisation's (the read noise referred to the input is fixed); runs
        use one gain, so this only matters when they do not.
        """
        scale = (np.asarray(gain, float) / self.gain_factor) ** 2
        return scale * (self.dark_variance + self.dark_variance_rate * np.asarray(exposure, float))


@dataclass(frozen=True)
class LinearityCorrection:
    """The camera's linearity correction as characterised during a run (EMVA 1288 series).

    ``S_linear = S (1 + c1 x + c2 x^2)``, ``x = S / signal_range``, for a reading's signal
    ``S`` [DN above the dark level] (:mod:`drivers.linearity`, which measures and fits it).
    The error of (c1, c2) is common to every reading of the recording: a reading's
    relative error is ``jacobian(S) @ dc``, so the correction's uncertainty is a
    covariance between values (:meth:`value_covariance`), not a per-reading noise.

    Attributes
    ----------
    coefficients : numpy.ndarray
        (c1, c2) [-].
    covariance_matrix : numpy.ndarray
        Their 2 x 2 covariance [-].
    signal_range : float
        ``S_ref``, the top of the series [DN].
    """

    coefficients: np.ndarray
    covariance_matrix: np.ndarray
    signal_range: float

    @classmethod
    def from_metadata(cls, camera: Mapping) -> "LinearityCorrection | None":
        """From ``metadata["camera"]["linearity"]``; None when the series is missing or
        failed (its ``error``).

        Raises
        ------
        ValueError
            A series record that cannot be read, naming what is wrong with it.
        """
        from drivers.linearity import LinearityResult

        series = camera.get("linearity")
        if series is None or (isinstance(series, Mapping) and "error" in series):
            return None
        try:
            result = LinearityResult.from_dict(series)
        except (KeyError, TypeError, ValueError) as error:
            reason = f"no {error}" if isinstance(error, KeyError) else str(error)
            raise ValueError(f"metadata camera.linearity cannot be read ({type(error).__name__}: {reason}); "
                             "expected the record drivers.linearity.LinearityResult.to_dict writes") from None
        return cls(result.coefficients, result.covariance, result.signal_range)

    def factor(self, signal: np.ndarray) -> np.ndarray:
        """``S_linear / S`` of signals [DN] (:func:`drivers.linearity.correction_factor`)."""
        from drivers.linearity import correction_factor

        return correction_factor(signal, self.coefficients, self.signal_range)

    def slope(self, signal: np.ndarray) -> np.ndarray:
        """``dS_linear / dS`` of signals [DN]: the factor of their errors
        (:func:`drivers.linearity.correction_slope`)."""
        from drivers.linearity import correction_slope

        return correction_slope(signal, self.coefficients, self.signal_range)

    def jacobian(self, signal: np.ndarray) -> np.ndarray:
        """Relative sensitivity of corrected signals to (c1, c2), shape signal.shape + (2,)."""
        from drivers.linearity import correction_jacobian

        return correction_jacobian(signal, self.coefficients, self.signal_range)

    @staticmethod
    def value_covariance(values: np.ndarray, jacobian: np.ndarray, coefficient_covariance: np.ndarray) -> np.ndarray:
        """Covariance of ``values`` from the correction's coefficients: ``(v J) C (v J)^T``
        (:meth:`value_factors` times its transpose).

        Examples
        --------
        >>> J = np.array([[0.5, 0.25], [0.25, 0.0625]])
        >>> LinearityCorrection.value_covariance(np.array([2.0, 1.0]), J, np.diag([1e-8, 1e-8])).round(12).tolist()
        [[1.25e-08, 2.812e-09], [2.812e-09, 6.64e-10]]
        """
        factors = LinearityCorrection.value_factors(values, jacobian, coefficient_covariance)
        return factors @ factors.T

    @staticmethod
    def value_factors(values: np.ndarray, jacobian: np.ndarray, coefficient_covariance: np.ndarray) -> np.ndarray:
        """Factors ``F`` (n, P) with ``F F^T`` the covariance of ``values`` from the
        correction's coefficients: ``(v J) S`` with ``S S^T = C`` (from C's eigenvectors,
        its rounding-level negative eigenvalues taken as 0)."""
        scaled = np.asarray(values, float)[:, None] * np.asarray(jacobian, float)
        eigenvalues, eigenvectors = np.linalg.eigh(np.asarray(coefficient_covariance, float))
        return scaled @ (eigenvectors * np.sqrt(np.maximum(eigenvalues, 0.0)))


def ccd_components(camera: CameraModel, signal: np.ndarray, exposure: np.ndarray, gain: np.ndarray,
                   pixels: np.ndarray, frames: np.ndarray, largest_window: float | None = None) -> dict[str, np.ndarray]:
    """Shot and read, dark and PRNU components of the signal rate ``signal / (t g)`` [DN/s].

    Parameters
    ----------
    camera : CameraModel
    signal : array
        Dark-subtracted ROI mean, averaged over the frames [DN].
    exposure, gain, pixels, frames : array
        Exposure [s], analog gain factor [-], ROI pixel count and frames averaged.
    largest_window : float, optional
        Pixel count of the largest ROI of the recording (default: the largest of
        ``pixels``), see the notes.

    Returns
    -------
    dict
        ``shot_read = sqrt(K S + sigma_d^2(t)) / sqrt(N F)``, ``dark = sigma_d(t) / sqrt(N)``
        (one dark frame) and ``prnu = p S sqrt(1/N - 1/N_max)``, each divided by ``t g``
        [DN/s]. A signal at or below zero has no shot noise.

    Notes
    -----
    The ROIs of a sweep are centred windows that shrink with ``cos(theta_r)`` along one
    image axis, so every window lies inside the largest one (normal view), and the mean
    PRNU of a window ``A`` is that of the largest window ``B`` plus a difference of variance
    ``p^2 (1/|A| - 1/|B|)``. The part common to all windows is a scale factor of every
    value: it cancels against the reference standard (measured through a window of nearly
    the largest size) and in ``L / L(0)``, and a free scale absorbs it. The budget states
    the difference; the reference's own difference enters the calibration.

    Examples
    --------
    >>> cam = CameraModel(0.1, 0.7, 0.2, 0.005)
    >>> c = ccd_components(cam, np.array([1900.0]), np.array([0.025]), np.array([1.0]),
    ...                    np.array([19044]), np.array([1]))
    >>> round(float(c["shot_read"][0] / (1900 / 0.025)), 7)   # relative: sqrt(0.1 * 1900 + 0.7) / 1900 / 138
    5.27e-05
    """
    S = np.asarray(signal, float)
    t, g = np.asarray(exposure, float), np.asarray(gain, float)
    n, f = np.asarray(pixels, float), np.asarray(frames, float)
    k = camera.system_gain * g / camera.gain_factor
    dark_var = camera.dark_variance_at(t, g)
    per_rate = 1.0 / (t * g)
    n_max = float(np.nanmax(n)) if largest_window is None else float(largest_window)
    return {
        "shot_read": np.sqrt(k * np.clip(S, 0.0, None) + dark_var) / np.sqrt(n * f) * per_rate,
        "dark": np.sqrt(dark_var / n) * per_rate,
        "prnu": camera.prnu * np.abs(S) * np.sqrt(np.clip(1.0 / n - 1.0 / n_max, 0.0, None)) * per_rate,
    }


def pooled_excess_variance(values: Sequence[np.ndarray], noise: Sequence[np.ndarray]) -> tuple[float, int]:
    """Relative variance of repeated readings beyond their known noise (Type A, pooled).

    Parameters
    ----------
    values : sequence of arrays
        Groups of repeated readings of one quantity each (groups of one are skipped).
    noise : sequence of arrays
        Known standard uncertainty of each reading (same shapes).

    Returns
    -------
    variance, dof : float, int
        ``sum((x - mean)^2 / mean^2) / dof - mean((u / mean)^2)``, clipped at 0, and the
        pooled degrees of freedom ``sum(n - 1)``.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> groups = [100 * (1 + 0.01 * rng.standard_normal(50)) for _ in range(20)]
    >>> v, dof = pooled_excess_variance(groups, [np.zeros(50)] * 20)
    >>> round(math.sqrt(v), 3), dof
    (0.01, 980)
    """
    scatter, known, dof = 0.0, [], 0
    for x, u in zip(values, noise):
        x, u = np.asarray(x, float), np.asarray(u, float)
        if x.size < 2:
            continue
        level = float(np.mean(x))
        if not level > 0:
            continue
        scatter += float(np.sum((x - level) ** 2)) / level**2
        known.append(np.mean((u / level) ** 2) * (x.size - 1))
        dof += x.size - 1
    if dof == 0:
        return math.nan, 0
    return max(scatter / dof - float(np.sum(known)) / dof, 0.0), dof


def interpolate_drift(times: np.ndarray, levels: np.ndarray, sigmas: np.ndarray,
                      at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lamp drift at times ``at`` by linear interpolation between check measurements.

    Parameters
    ----------
    times : array
        Instrument times of the checks [s], increasing.
    levels : array
        Check levels relative to their common reference [-].
    sigmas : array
        Relative standard uncertainty of each check level [-].
    at : array
        Times to interpolate to [s].

    Returns
    -------
    drift, sigma, extrapolated, fraction : numpy.ndarray
        Interpolated level [-], its relative uncertainty from the two checks around each
        time (``sqrt(((1 - w) u_j)^2 + (w u_j+1)^2)``), whether the time lies outside
        the checks' span (then the nearest check is used) and the fraction ``w`` of the
        way from the earlier check to the later one.

    Examples
    --------
    >>> d, s, x, w = interpolate_drift(np.array([0.0, 10.0]), np.array([1.0, 1.002]),
    ...                                np.array([1e-4, 1e-4]), np.array([5.0, 20.0]))
    >>> np.round(d, 6).tolist(), np.round(s * 1e4, 4).tolist(), x.tolist(), w.tolist()
    ([1.001, 1.002], [0.7071, 1.0], [False, True], [0.5, 1.0])
    """
    times, levels, sigmas, at = (np.asarray(a, float) for a in (times, levels, sigmas, at))
    if times.size == 1:
        return np.full(at.shape, levels[0]), np.full(at.shape, sigmas[0]), at != times[0], np.zeros(at.shape)
    j = np.clip(np.searchsorted(times, at, side="right") - 1, 0, times.size - 2)
    span = times[j + 1] - times[j]
    w = np.clip(np.where(span > 0, (at - times[j]) / np.where(span > 0, span, 1.0), 0.0), 0.0, 1.0)
    drift = (1 - w) * levels[j] + w * levels[j + 1]
    sigma = np.hypot((1 - w) * sigmas[j], w * sigmas[j + 1])
    return drift, sigma, (at < times[0]) | (at > times[-1]), w


def interpolation_excess(times: np.ndarray, levels: np.ndarray, sigmas: np.ndarray) -> tuple[float, float]:
    """How far linear interpolation between checks misses the lamp, from the checks themselves.

    Each interior check is predicted from its two neighbours (leave one out); the mean
    squared miss beyond what the checks' own noise explains is the interpolation error
    over twice the check interval, where it is four times the largest error within one
    interval (the error of a curved drift grows as the interval squared and peaks half
    way). Callers scale it by ``w (1 - w)`` at fraction ``w`` of an interval.

    Returns
    -------
    excess, chi2 : float
        ``sqrt(max(mean(miss^2 - noise^2), 0))`` [-] (0 with fewer than 3 checks) and the
        reduced chi-square of the misses (NaN with fewer than 3).

    Examples
    --------
    >>> t = np.arange(0.0, 100.0, 10.0)
    >>> excess, chi2 = interpolation_excess(t, 1 + 1e-3 * np.sin(t / 15), np.full(t.size, 1e-6))
    >>> round(excess, 4)   # f'' (2 dt)^2 / 8 = 1e-3 / 225 * 400 / 8 = 2.2e-4 times |sin|, rms 1.6e-4
    0.0002
    """
    times, levels, sigmas = (np.asarray(a, float) for a in (times, levels, sigmas))
    if times.size < 3:
        return 0.0, math.nan
    w = (times[1:-1] - times[:-2]) / (times[2:] - times[:-2])
    miss = levels[1:-1] - ((1 - w) * levels[:-2] + w * levels[2:])
    noise = sigmas[1:-1] ** 2 + ((1 - w) * sigmas[:-2]) ** 2 + (w * sigmas[2:]) ** 2
    return math.sqrt(max(float(np.mean(miss**2 - noise)), 0.0)), float(np.mean(miss**2 / noise))


def local_slopes(axis_values: np.ndarray, others: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Slope d(value)/d(axis) of a measured curve at each point [value unit per deg].

    Points that share ``others`` (the remaining coordinates, rows of an array) form one
    curve along ``axis_values``; the slope is numpy's second-order finite difference on
    the (possibly uneven) spacing. Curves with a single point get slope 0.

    Examples
    --------
    >>> v = np.array([0.0, 10.0, 20.0, 0.0])
    >>> local_slopes(v, np.array([[1], [1], [1], [2]]), np.array([1.0, 2.0, 3.0, 5.0])).tolist()
    [0.1, 0.1, 0.1, 0.0]
    """
    slopes = np.zeros(len(values))
    others = np.asarray(others).reshape(len(values), -1)
    keys = [tuple(row) for row in np.round(others, 6)]
    for key in set(keys):
        members = np.array([i for i, k in enumerate(keys) if k == key])
        order = members[np.argsort(axis_values[members])]
        x = axis_values[order]
        if len(order) < 2 or np.unique(x).size < len(x):
            continue
        slopes[order] = np.gradient(values[order], x, edge_order=1)
    return slopes


def quantisation_sigma(resolution: float) -> float:
    """Standard uncertainty of a reading rounded to ``resolution``: ``resolution / sqrt(12)``.

    Examples
    --------
    >>> round(quantisation_sigma(0.001), 6)
    0.000289
    """
    return float(resolution) / math.sqrt(12.0)


def texture_relative(mountings: Mapping[str, Mapping]) -> tuple[float, int] | None:
    """Relative standard uncertainty that the sample's texture gives the window's mean [-].

    The root mean square of the mountings' image estimates (``texture_relative`` of
    :func:`gonio.acquisition.characterise_mounting`; the windows of all mountings cover
    the sample's central area, so the estimates describe one error, common to every
    value, and are pooled, not averaged down), with the number of images. None when no
    mounting has an image.

    Examples
    --------
    >>> texture_relative({"0": {"texture_relative": 0.003}, "1": {"texture_relative": 0.004}})
    (0.0035355339059327377, 2)
    >>> texture_relative({"0": {"error": "no frame"}}) is None
    True
    """
    values = [float(m["texture_relative"]) for m in mountings.values()
              if isinstance(m, Mapping) and "texture_relative" in m and math.isfinite(float(m["texture_relative"]))]
    if not values:
        return None
    return math.sqrt(float(np.mean(np.square(values)))), len(values)


def monitor_ratio_variance(mountings: Mapping[str, Mapping], camera: CameraModel | None,
                           monitor_noise, monitor_offset: float) -> tuple[float, int]:
    """Relative variance of the signal-to-monitor ratio beyond the camera's and the monitor's noise.

    Each mounting's monitor series (exposures at one geometry and exposure time, without
    moving) gives ratios ``r = rate / (monitor - offset)``; their scatter, relative to
    their mean, minus the camera's temporal noise of each exposure (shot and read noise of
    the window's mean, ``(K S + sigma_d^2) / N`` in DN^2 with ``S`` the dark-subtracted
    signal) and the monitor's reading noise, pooled over the series with their degrees of
    freedom, is the part of the lamp's fluctuation the monitor does not see.

    Parameters
    ----------
    mountings : mapping
        ``metadata["mountings"]`` of a recording.
    camera : CameraModel or None
        The camera's characterisation (None: the CCD noise from the series' pixel spread
        is not known, and the whole scatter is counted).
    monitor_noise : callable
        Rms noise of one monitor reading at an exposure [V] (``MonitorDark.noise``).
    monitor_offset : float
        The monitor's dark offset [V].

    Returns
    -------
    variance, dof : float, int
        Clipped at 0; ``(nan, 0)`` without a series.
    """
    scatter, known, dof = 0.0, 0.0, 0
    for record in mountings.values():
        series = record.get("monitor_series") if isinstance(record, Mapping) else None
        if not series:
            continue
        rate = np.asarray(series["signal_rate"], float)
        lamp = np.asarray(series["monitor"], float) - monitor_offset
        good = np.isfinite(rate) & np.isfinite(lamp) & (lamp > 0)
        if good.sum() < 2:
            continue
        ratio = rate[good] / lamp[good]
        level = float(np.mean(ratio))
        n = int(good.sum())
        scatter += float(np.sum((ratio - level) ** 2)) / level**2
        t = float(series["exposure"])
        noise = np.full(n, (float(monitor_noise(t)) / np.mean(lamp[good])) ** 2)
        if camera is not None:
            signal = np.asarray(series["roi_mean"], float)[good] - np.asarray(series["dark_mean"], float)[good]
            gain = float(series.get("gain", 1.0))
            k = camera.system_gain * gain / camera.gain_factor
            ccd = (k * np.clip(signal, 0, None) + camera.dark_variance_at(np.array(t), np.array(gain))) \
                / float(series["roi_pixels"]) / signal**2
            noise = noise + ccd
        known += float(np.sum(noise)) * (n - 1) / n
        dof += n - 1
    if dof == 0:
        return math.nan, 0
    return max((scatter - known) / dof, 0.0), dof


@dataclass(frozen=True)
class MountingFactors:
    """The change of the values between mountings of the sample, as the mountings showed it.

    Attributes
    ----------
    relative : numpy.ndarray
        Factors ``F`` (geometries x components) of the relative covariance
        ``Sigma = F F^T`` of one mounting's values about the mean mounting [-].
    sigma : numpy.ndarray
        ``sqrt(diag(Sigma))`` per geometry [-]; geometries not measured in every mounting get
        the median of the others (and no factor: their part is taken independent).
    complete : numpy.ndarray of bool
        Geometries measured in every mounting (those the factors describe).
    mountings : int
        Mountings compared.
    """

    relative: np.ndarray
    sigma: np.ndarray
    complete: np.ndarray
    mountings: int


def mounting_factors(values: np.ndarray, noise: np.ndarray) -> MountingFactors:
    """How the values change between mountings: a low-rank covariance from the mountings' scatter.

    ``values[k, g]`` is mounting ``k``'s value at geometry ``g`` (NaN where not measured)
    and ``noise[k, g]`` its standard uncertainty from everything that differs between
    readings (camera, lamp, angle; not the mounting). Over the geometries measured in
    every mounting the relative deviations ``d_k = x_k / mean_k(x) - 1`` give the sample
    covariance ``S = D^T D / (M - 1)`` of rank ``M - 1`` at most: its eigenvectors are the
    patterns in which the mountings differed (a tilt raises one side of a sweep and lowers
    the other; the texture moves the whole level). Along each, the expected contribution
    of the readings' own noise is removed (``v^T diag(mean_k (u_k / x)^2) v``); what
    remains, clipped at 0, is the mounting's covariance ``F F^T``. No shape is assumed, so
    its correlation between geometries is the one the data show; with few mountings each
    eigenvalue is known to ``sqrt(2 / (M - 1))`` of itself (docs/acquisition.md, "Mountings").

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> tilt = np.linspace(-1, 1, 40)                        # a pattern: one side up, the other down
    >>> x = 1 + 0.01 * rng.standard_normal((400, 1)) * tilt    # 400 mountings
    >>> f = mounting_factors(x, np.full(x.shape, 1e-6))
    >>> round(float(f.sigma[-1]), 3), round(float(f.sigma[20]), 4)   # 0.01 at the ends, ~0 in the middle
    (0.01, 0.0003)
    """
    values, noise = np.asarray(values, float), np.asarray(noise, float)
    m = values.shape[0]
    complete = np.all(np.isfinite(values), axis=0) & np.all(np.isfinite(noise), axis=0)
    sigma = np.zeros(values.shape[1])
    if m < 2 or not complete.any():
        return MountingFactors(np.zeros((values.shape[1], 0)), sigma, complete, m)
    x = values[:, complete]
    level = x.mean(axis=0)
    deviations = x / level - 1.0
    noise_rel = np.mean((noise[:, complete] / level) ** 2, axis=0)
    _, singular, vt = np.linalg.svd(deviations, full_matrices=False)
    eigen = singular**2 / (m - 1)
    remaining = np.clip(eigen - np.einsum("jg,g,jg->j", vt, noise_rel, vt), 0.0, None)
    keep = remaining > 0
    relative = np.zeros((values.shape[1], int(keep.sum())))
    relative[complete] = (vt[keep] * np.sqrt(remaining[keep])[:, None]).T
    sigma = np.sqrt(np.sum(relative**2, axis=1))
    if (~complete).any():
        sigma[~complete] = float(np.median(sigma[complete]))
    return MountingFactors(relative, sigma, complete, m)
