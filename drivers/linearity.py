"""Linearity of a camera from a series of exposures at constant irradiance, and its correction.

EMVA 1288 characterises a camera's linearity by the mean signal against the irradiation,
varied through the exposure time at constant irradiance (release 4.0 Linear, section
6.6; release 3.1, section 6.6): over 5 % to 95 % of saturation the relative deviation
``delta`` of the signal from a straight line gives the linearity error
``LE = (max delta - min delta) / 2``.  The standard characterises; a measurement that
wants linear values corrects them.  Here the same series fits a low-order correction of
the digital signal ``S`` [DN above the dark level]::

    S_linear = S (1 + c1 x + c2 x^2),    x = S / S_ref,

with ``S_ref`` the top of the series, by weighted least squares of the level means
``y_l = <S / (t M)>`` (signal per unit exposure and unit lamp reading ``M``, 1 without a
lamp monitor), which a linear camera keeps constant: ``y_l (1 + c1 x_l + c2 x_l^2) = k``
is linear in (k, c1, c2).  A constant term would be a gain, which the reference standard
calibrates; the quadratic order covers a deficit growing with the signal (a charge-to-
voltage converter near its limit: the emulator's ``s (1 - a (s / s_fs)^2)`` is corrected
to 2e-5 of the signal over the series by c2 alone, the rest of its inverse being
``3 a^2 x^4``).

Decisions (tested in tests/drivers/test_driver_linearity.py):

- **The series** is measured where the photon-transfer characterisation is (the same
  window and geometry), after it: from the exposure that gave the PTC its brightest pair,
  the exposure is raised by factors of 1.15 until a pixel of the window saturates, and
  ``levels`` exposures from 5 % to 100 % of the last unsaturated one are measured, each
  ``frames`` times going up and again coming down (a linear lamp drift cancels in each
  level's mean), each level's dark level from a dark frame at its exposure.  A frame with
  a saturated pixel in the window (a lamp drifting up since the top was found) is not
  kept: the series is measured again from a top one step lower, up to
  :data:`MAX_TOP_BACK_OFFS` times, then refused.  The PTC alone does not do: it stops at
  the automatic exposure (45-50 % of full scale), while readings go to 75 % and HDR
  brackets to saturation.  Unlike EMVA 1288's 5-95 % of saturation, the series goes to
  100 % of the longest unsaturated exposure: readings and HDR brackets reach it.
- **The noise of each frame** is its shot and read noise from the PTC's system gain and
  dark variance (``(K S + sigma_d^2) / (N S^2)`` relative, ``N`` pixels), plus a lamp
  term ``q / t`` (flicker left by the monitor, or all of it without one, white: averaging
  down with the exposure) whose ``q`` is the pooled excess scatter of the frames within
  runs of consecutive frames at one level (Type A: each pass's frames apart, so that a
  lamp drift between the up and down passes, which cancels in the level's mean, does not
  enter it); each level's mean adds its dark frame's noise.  The covariance of
  (c1, c2) is that of the weighted least squares, not rescaled; its chi-square is recorded.
- **The correction acts on the digital signal**: it is applied to readings at any gain
  and exposure by their signal in DN (a non-linearity of the ADC, as emulated); a rig
  whose non-linearity sits in the charge domain would need a series per gain.

References
----------
European Machine Vision Association, EMVA Standard 1288, release 4.0 Linear (2021),
section 6.6 (linearity), and release 3.1 (2016), section 6.6.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["LinearityResult", "correction_factor", "correction_slope", "correction_jacobian", "fit_linearity",
           "linearity_error", "series_exposures", "acquire_linearity"]

#: Lowest level of the series as a fraction of its top exposure (EMVA 1288: 5 % of saturation).
LOWEST_LEVEL = 0.05
#: Factor by which the exposure is raised while looking for the top of the series.
TOP_SEARCH_STEP = 1.15
#: Times a series with a saturated frame is measured again from a top one
#: :data:`TOP_SEARCH_STEP` lower before it is refused.
MAX_TOP_BACK_OFFS = 3


@dataclass(frozen=True)
class LinearityResult:
    """The linearity series and the correction it gives.

    Attributes
    ----------
    coefficients : numpy.ndarray
        (c1, c2) of ``S_linear = S (1 + c1 x + c2 x^2)``, ``x = S / signal_range`` [-].
    covariance : numpy.ndarray
        Their 2 x 2 covariance [-].
    signal_range : float
        ``S_ref``, the mean signal of the top level [DN above the dark level].
    response : float
        ``k``, the linear signal per unit exposure and lamp reading [DN/s per lamp unit].
    chi2 : float
        Chi-square of the level means about the corrected line.
    dof : int
        Its degrees of freedom (levels - 3).
    linearity_error : float
        EMVA 1288 linearity error of the uncorrected series [-] (:func:`linearity_error`).
    exposures, signal, ratio, ratio_sigma : numpy.ndarray
        Per level: exposure [s], mean signal [DN], mean ``S / (t M)`` and its relative
        standard uncertainty [-].
    lamp_variance : float
        ``q`` [s]: the relative variance of the lamp term times the exposure.
    frames : int
        Frames per level.
    gain : float
        Analog gain factor of the series [-].
    series : mapping or None
        Every frame as measured, the arguments of :func:`fit_linearity` (``exposure`` [s],
        ``signal`` [DN], ``lamp``, ``level``, ``dark_variance`` [DN^2] per frame, in the
        order measured; ``pixels``, ``system_gain`` [DN/e-], ``gain``): ``fit_linearity(
        **series)`` fits it again (:meth:`refit`).
    """

    coefficients: np.ndarray
    covariance: np.ndarray
    signal_range: float
    response: float
    chi2: float
    dof: int
    linearity_error: float
    exposures: np.ndarray
    signal: np.ndarray
    ratio: np.ndarray
    ratio_sigma: np.ndarray
    lamp_variance: float
    frames: int
    gain: float = 1.0
    series: Mapping[str, Any] | None = None

    def refit(self) -> "LinearityResult":
        """The series fitted again from its frames (:attr:`series`)."""
        if self.series is None:
            raise ValueError("this linearity record keeps no frames to fit again")
        return fit_linearity(**self.series)

    def consistency_with_none(self) -> float:
        """``c^T C^-1 c``: chi-square (2 dof) of the coefficients against a linear camera."""
        c = np.asarray(self.coefficients, float)
        return float(c @ np.linalg.solve(self.covariance, c))

    def to_dict(self) -> dict[str, Any]:
        """Plain numbers for a recording's metadata (``metadata["camera"]["linearity"]``)."""
        return {"method": "EMVA 1288 exposure series at constant irradiance, quadratic correction of the signal",
                "coefficients": [float(c) for c in self.coefficients],
                "covariance": np.asarray(self.covariance, float).tolist(),
                "signal_range_dn": self.signal_range, "response": self.response, "chi2": self.chi2, "dof": self.dof,
                "linearity_error": self.linearity_error, "exposures_s": [float(t) for t in self.exposures],
                "signal_dn": [float(s) for s in self.signal], "ratio": [float(r) for r in self.ratio],
                "ratio_sigma": [float(u) for u in self.ratio_sigma], "lamp_variance_s": self.lamp_variance,
                "frames": self.frames, "gain_factor": self.gain,
                **({"series": _plain(self.series)} if self.series is not None else {})}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "LinearityResult":
        """Inverse of :meth:`to_dict`; ``KeyError``/``ValueError`` on an incomplete record."""
        return cls(np.asarray(data["coefficients"], float).reshape(2), np.asarray(data["covariance"], float).reshape(2, 2),
                   float(data["signal_range_dn"]), float(data["response"]), float(data["chi2"]), int(data["dof"]),
                   float(data["linearity_error"]), np.asarray(data["exposures_s"], float),
                   np.asarray(data["signal_dn"], float), np.asarray(data["ratio"], float),
                   np.asarray(data["ratio_sigma"], float), float(data["lamp_variance_s"]), int(data["frames"]),
                   float(data.get("gain_factor", 1.0)), data.get("series"))


def _plain(series: Mapping[str, Any]) -> dict[str, Any]:
    """The frames' record in plain numbers (lists) for JSON."""
    return {k: (np.asarray(v).tolist() if np.ndim(v) else v) for k, v in series.items()}


def _powers(signal: np.ndarray, signal_range: float) -> np.ndarray:
    """(x, x^2) of each signal, ``x = S / S_ref``: shape signal.shape + (2,)."""
    x = np.asarray(signal, float) / signal_range
    return np.stack([x, x * x], axis=-1)


def correction_factor(signal: np.ndarray | float, coefficients: Sequence[float],
                      signal_range: float) -> np.ndarray:
    """``S_linear / S = 1 + c1 x + c2 x^2`` for signals ``S`` [DN above the dark level].

    Examples
    --------
    >>> float(correction_factor(1500.0, [0.0, 0.004], 3000.0))
    1.001
    """
    return 1.0 + _powers(signal, signal_range) @ np.asarray(coefficients, float)


def correction_slope(signal: np.ndarray | float, coefficients: Sequence[float], signal_range: float) -> np.ndarray:
    """``dS_linear / dS = 1 + 2 c1 x + 3 c2 x^2``: what an error of a signal ``S`` [DN above
    the dark level] becomes in the corrected signal (its noise scales by this, not by
    :func:`correction_factor`).

    Examples
    --------
    >>> float(correction_slope(1500.0, [0.0, 0.004], 3000.0))
    1.003
    """
    powers = _powers(signal, signal_range)
    return 1.0 + powers @ (np.array([2.0, 3.0]) * np.asarray(coefficients, float))


def correction_jacobian(signal: np.ndarray | float, coefficients: Sequence[float],
                        signal_range: float) -> np.ndarray:
    """Relative sensitivity of the corrected signal to (c1, c2): ``(x, x^2) / (1 + c1 x + c2 x^2)``,
    shape signal.shape + (2,), so that a coefficient error ``dc`` changes ``S_linear`` by
    the fraction ``jacobian @ dc``."""
    powers = _powers(signal, signal_range)
    return powers / (1.0 + powers @ np.asarray(coefficients, float))[..., None]


def series_exposures(top: float, levels: int) -> np.ndarray:
    """The series' exposures [s]: ``levels`` values evenly spaced from 5 % to 100 % of ``top``.

    Examples
    --------
    >>> series_exposures(0.1, 5).tolist()
    [0.005, 0.02875, 0.0525, 0.07625, 0.1]
    """
    if levels < 4:
        raise ValueError(f"levels={levels!r}: the correction's three numbers need at least 4 levels")
    return np.round(top * np.linspace(LOWEST_LEVEL, 1.0, int(levels)), 9)


def linearity_error(irradiation: np.ndarray, signal: np.ndarray, saturation: float) -> float:
    """EMVA 1288 linearity error ``(max delta - min delta) / 2`` [-].

    ``delta`` is the relative deviation of the mean signal from the straight line
    ``a0 + a1 H`` fitted to the points between 5 % and 95 % of ``saturation`` by least
    squares of the relative deviations (as the standard's reference implementation does).

    Parameters
    ----------
    irradiation : array
        Irradiation of each point in any unit (here exposure times lamp reading).
    signal : array
        Mean signal above the dark level [DN].
    saturation : float
        The saturation signal [DN].

    Examples
    --------
    >>> h = np.linspace(0.0, 1.0, 200)           # the emulator's curve with nonlinearity = 0.01
    >>> round(linearity_error(h, 1000 * h * (1 - 0.01 * h**2), 990.0), 4)
    0.0037
    """
    h, s = np.asarray(irradiation, float), np.asarray(signal, float)
    inside = (s >= 0.05 * saturation) & (s <= 0.95 * saturation)
    if inside.sum() < 3:
        return math.nan
    h, s = h[inside], s[inside]
    design = np.column_stack([np.ones_like(h), h]) / s[:, None]
    (a0, a1), *_ = np.linalg.lstsq(design, np.ones_like(s), rcond=None)
    delta = (s - (a0 + a1 * h)) / (a0 + a1 * h)
    return float((delta.max() - delta.min()) / 2.0)


def _lamp_variance(ratio: np.ndarray, shot: np.ndarray, exposure: np.ndarray, level: np.ndarray) -> float:
    """``q`` [s]: the relative scatter of ``S / (t M)`` beyond the shot and read noise
    ``shot`` (relative variance per frame) within each run of consecutive frames at one
    level (frames in the order measured: a lamp drift between runs stays out), times the
    exposure, pooled over the runs by their degrees of freedom (Type A); 0 when there is
    no excess."""
    weighted, dof = 0.0, 0
    for run in np.split(np.arange(level.size), np.flatnonzero(np.diff(level)) + 1):
        if run.size < 2:
            continue
        r = ratio[run]
        excess = float(np.var(r / r.mean(), ddof=1) - shot[run].mean())
        weighted += (run.size - 1) * excess * float(exposure[run].mean())
        dof += run.size - 1
    return max(weighted / dof, 0.0) if dof else 0.0


def fit_linearity(exposure: Sequence[float], signal: Sequence[float], lamp: Sequence[float],
                  level: Sequence[int], pixels: int, system_gain: float, dark_variance: Sequence[float],
                  gain: float = 1.0) -> LinearityResult:
    """The correction of a linearity series (module notes).

    Parameters
    ----------
    exposure : sequence of float
        Exposure of every frame [s].
    signal : sequence of float
        Mean signal of every frame over the window, above its level's dark level [DN].
    lamp : sequence of float
        Lamp reading during every frame (monitor minus its dark offset), 1 without a monitor.
    level : sequence of int
        Level of every frame (frames of one level share their exposure and dark frame),
        in the order measured.
    pixels : int
        Pixels of the window.
    system_gain : float
        ``K`` [DN/e-] of the photon-transfer characterisation.
    dark_variance : sequence of float
        Temporal dark variance of one pixel at every frame's exposure [DN^2].
    gain : float
        Analog gain factor of the series [-] (recorded).

    Returns
    -------
    LinearityResult

    Raises
    ------
    ValueError
        Fewer than 4 levels, a level without signal, or unequal lengths.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t = np.repeat(np.linspace(0.05, 1.0, 8), 6) * 0.02
    >>> linear = 1.5e5 * t
    >>> bent = linear * (1 - 0.01 * (linear / 3000.0) ** 2) * (1 + 2e-5 * rng.standard_normal(t.size))
    >>> r = fit_linearity(t, bent, np.ones(t.size), np.repeat(np.arange(8), 6), 20000, 0.1, np.full(t.size, 0.7))
    >>> corrected = bent * correction_factor(bent, r.coefficients, r.signal_range)
    >>> [round(float(np.ptp(y / t) / np.mean(y / t)), 4) for y in (bent, corrected)]   # spread of S / t
    [0.01, 0.0001]
    """
    t, s, m = (np.asarray(a, float) for a in (exposure, signal, lamp))
    lv, dark = np.asarray(level, int), np.asarray(dark_variance, float)
    if not (t.size == s.size == m.size == lv.size == dark.size):
        raise ValueError("exposure, signal, lamp, level and dark_variance need one value per frame")
    levels = np.unique(lv)
    if levels.size < 4:
        raise ValueError(f"a linearity series needs at least 4 levels, got {levels.size}")
    if not np.all(s > 0) or not np.all(m > 0):
        raise ValueError("every frame of a linearity series needs a positive signal and lamp reading")
    ratio = s / (t * m)
    shot = (system_gain * s + dark) / (pixels * s * s)
    q = _lamp_variance(ratio, shot, t, lv)
    mean_ratio, mean_signal, mean_t, relative = (np.empty(levels.size) for _ in range(4))
    for k, l in enumerate(levels):
        frames = lv == l
        n = int(frames.sum())
        mean_ratio[k], mean_signal[k], mean_t[k] = ratio[frames].mean(), s[frames].mean(), t[frames].mean()
        per_frame = np.sum(shot[frames] + q / t[frames]) / n**2
        relative[k] = math.sqrt(per_frame + dark[frames].mean() / (pixels * mean_signal[k] ** 2))
    signal_range = float(mean_signal.max())
    powers = _powers(mean_signal, signal_range)
    sigma = mean_ratio * relative
    design = np.column_stack([np.ones(levels.size), -mean_ratio * powers[:, 0], -mean_ratio * powers[:, 1]])
    design /= sigma[:, None]
    target = mean_ratio / sigma
    solution, *_ = np.linalg.lstsq(design, target, rcond=None)
    covariance = np.linalg.inv(design.T @ design)
    residual = design @ solution - target
    irradiation = np.array([np.mean(t[lv == l] * m[lv == l]) for l in levels])
    return LinearityResult(coefficients=solution[1:], covariance=covariance[1:, 1:], signal_range=signal_range,
                           response=float(solution[0]), chi2=float(residual @ residual), dof=int(levels.size - 3),
                           linearity_error=linearity_error(irradiation, mean_signal, signal_range),
                           exposures=mean_t, signal=mean_signal, ratio=mean_ratio, ratio_sigma=relative,
                           lamp_variance=q, frames=int(np.max(np.bincount(lv))), gain=float(gain),
                           series={"exposure": t, "signal": s, "lamp": m, "level": lv, "pixels": int(pixels),
                                   "system_gain": float(system_gain), "dark_variance": dark, "gain": float(gain)})


def _top_exposure(rig, start: float, max_exposure: float) -> float:
    """The longest exposure, from ``start`` up by :data:`TOP_SEARCH_STEP`, without a
    saturated pixel in the window (capped at ``max_exposure``)."""
    top = exposure = float(start)
    while exposure <= max_exposure:
        if rig.measure(exposure=exposure, dark="auto").roi_saturated > 0:
            break
        top = exposure
        exposure = round(exposure * TOP_SEARCH_STEP, 9)
    return top


def _series_frames(rig, exposures: np.ndarray, frames: int, monitor_offset: float) -> list[tuple] | None:
    """The series' frames going up and coming down (exposure, signal, lamp, level, pixels,
    gain), or None at the first frame with a saturated pixel in the window."""
    rows = []
    for k in list(range(exposures.size)) + list(range(exposures.size - 1, -1, -1)):
        for _ in range(frames):
            m = rig.measure(exposure=float(exposures[k]), dark="auto")
            if m.roi_saturated > 0:
                return None
            lamp = m.monitor - monitor_offset if math.isfinite(m.monitor) else 1.0
            rows.append((float(exposures[k]), m.signal, lamp, k, m.roi_pixels, m.gain))
    return rows


def acquire_linearity(rig, start_exposure: float, system_gain: float, dark_variance, *, levels: int = 8,
                      frames: int = 2, max_exposure: float = 10.0, monitor_offset: float = 0.0) -> LinearityResult:
    """Measure a linearity series through a :class:`~drivers.rig.Rig` where it stands.

    Parameters
    ----------
    rig : drivers.rig.Rig
        A rig at the characterisation's geometry (its current window), lamp on and steady.
    start_exposure : float
        An exposure known not to saturate [s] (the photon transfer's brightest).
    system_gain : float
        ``K`` [DN/e-] of the photon-transfer characterisation.
    dark_variance : callable
        Temporal dark variance of one pixel at an exposure [DN^2] (``t -> sigma_d^2(t)``).
    levels, frames : int
        Exposure levels, and frames per level in each of the two passes (up and down).
    max_exposure : float
        Longest exposure the series may use [s].
    monitor_offset : float
        The lamp monitor's dark offset [V] (with a monitor).

    Returns
    -------
    LinearityResult

    Raises
    ------
    ValueError
        A frame saturated at every top tried (:data:`MAX_TOP_BACK_OFFS` steps down), or a
        series :func:`fit_linearity` refuses.
    """
    top = _top_exposure(rig, start_exposure, max_exposure)
    for _ in range(MAX_TOP_BACK_OFFS + 1):
        rows = _series_frames(rig, series_exposures(top, levels), frames, monitor_offset)
        if rows is not None:
            break
        top = round(top / TOP_SEARCH_STEP, 9)
    else:
        raise ValueError(f"a frame of the linearity series saturated at every top exposure from "
                         f"{top * TOP_SEARCH_STEP ** (MAX_TOP_BACK_OFFS + 1):.4g} s down to "
                         f"{top * TOP_SEARCH_STEP:.4g} s: a lamp that is not steady")
    t, s, lamp, level, pixels, gain = (np.array(c) for c in zip(*rows))
    return fit_linearity(t, s, lamp, level.astype(int), int(pixels[0]), system_gain,
                         np.array([dark_variance(x) for x in t]), gain=float(gain[0]))
