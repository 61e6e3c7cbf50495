"""CCD camera model after the EMVA 1288 linear camera model.

Per pixel and exposure (EMVA Standard 1288, release 4.0 "Linear", section 2, Fig. 1-2):

- ``mu_p`` photons hit the pixel; a fraction ``eta`` (quantum efficiency) become electrons,
  with shot noise: the number of photo-electrons is Poisson distributed;
- a dark current ``I_d`` [e-/s] adds Poisson distributed thermal electrons ``I_d t``;
- (by default the sum of both Poisson counts is drawn from the normal distribution with
  the same mean and variance: EMVA 1288 uses only these two moments, the read noise
  hides the difference at low counts, and it is 10 times faster than exact Poisson
  draws for a full frame; ``shot_noise="poisson"`` draws exact Poisson counts);
- the charge saturates at the full-well capacity;
- the read-out adds Gaussian read noise ``sigma_r`` [e-];
- the amplifier and ADC convert with the system gain ``K`` [DN/e-] plus an offset, round to
  integers (quantisation noise ``1/12 DN^2``) and clip at the ADC range.

Hence ``mu_y = y_off + K (eta mu_p + I_d t)`` and, below saturation,
``sigma_y^2 = K^2 (sigma_r^2 + I_d t) + K (mu_y - mu_y,dark) + 1/12``: the photon-transfer
curve (temporal variance against mean) is a straight line of slope ``K``, which is what
the EMVA 1288 characterisation measures.  Spatial non-uniformities are fixed per sensor:
PRNU scales ``eta`` per pixel, DSNU scales ``I_d`` per pixel, and a few hot pixels have a
large dark current.  They are fixed patterns, so they cancel in the difference of two
frames (EMVA 1288 computes temporal variances from such differences).

References
----------
European Machine Vision Association, "EMVA Standard 1288: Standard for characterization of
image sensors and cameras", release 4.0 Linear (2021), sections 2 (sensor model) and 6
(photon transfer method).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .systematics import nonlinear_signal

__all__ = ["CCDParams", "CCDSensor", "Exposure"]


@dataclass(frozen=True)
class CCDParams:
    """EMVA 1288 parameters of the camera.

    Attributes
    ----------
    width, height : int
        Sensor size [pixels].
    bits : int
        ADC resolution [bit]; the maximum value is ``2^bits - 1`` [DN].
    quantum_efficiency : float
        ``eta`` at the band centre [-].
    base_gain_dn_per_e : float
        System gain ``K0`` at gain factor 1 [DN/e-]; ``K = K0 * factor``.
    full_well_e : float
        Full-well capacity [e-].
    read_noise_e : float
        Read noise ``sigma_r`` [e- rms].
    dark_current_e_per_s : float
        Mean dark current ``I_d`` [e-/s] at the operating temperature.
    dsnu_rel : float
        Relative rms pixel-to-pixel variation of the dark current (DSNU) [-].
    prnu_rel : float
        Relative rms pixel-to-pixel variation of the response (PRNU) [-].
    hot_pixel_fraction : float
        Fraction of pixels with a large dark current [-].
    hot_pixel_dark_current_e_per_s : float
        Dark current of hot pixels [e-/s].
    offset_dn : float
        Dark offset ``y_off`` [DN].
    readout_s : float
        Read-out time of a full frame [s].
    temperature_c : float
        Sensor temperature [degC] (reported, constant).
    """

    width: int = 512
    height: int = 480
    bits: int = 12
    quantum_efficiency: float = 0.5
    base_gain_dn_per_e: float = 0.1
    full_well_e: float = 30000.0
    read_noise_e: float = 8.0
    dark_current_e_per_s: float = 20.0
    dsnu_rel: float = 0.1
    prnu_rel: float = 0.005
    hot_pixel_fraction: float = 1e-4
    hot_pixel_dark_current_e_per_s: float = 2000.0
    offset_dn: float = 100.0
    readout_s: float = 0.05
    temperature_c: float = 25.0

    @property
    def max_dn(self) -> int:
        """Largest ADC value [DN]."""
        return (1 << self.bits) - 1


@dataclass(frozen=True)
class Exposure:
    """One rendered frame.

    Attributes
    ----------
    frame : numpy.ndarray
        Digital values, uint16, shape (height, width) [DN].
    saturated : numpy.ndarray
        Boolean mask: pixel at full well or at the ADC maximum.
    """

    frame: np.ndarray
    saturated: np.ndarray


class CCDSensor:
    """A CCD sensor with fixed-pattern maps drawn once from ``seed``.

    Parameters
    ----------
    params : CCDParams
        Model parameters.
    seed : int or numpy.random.SeedSequence
        Seed of the fixed patterns (PRNU, DSNU, hot pixels).
    fixed_pattern : bool
        False disables PRNU, DSNU and hot pixels (an ideal EMVA sensor).
    shot_noise : {"gaussian", "poisson"}
        How the electron count is drawn: ``"poisson"`` exactly; ``"gaussian"`` (default)
        from the normal distribution with the Poisson mean and variance (see the module
        notes).
    nonlinearity : float
        Relative signal deficit at the ADC's full scale (a systematic error outside the
        linear EMVA 1288 model, :func:`drivers.emulator.systematics.nonlinear_signal`;
        default 0, a linear camera).

    Examples
    --------
    >>> sensor = CCDSensor(CCDParams(width=64, height=48), seed=1)
    >>> shot = sensor.expose(np.full((48, 64), 1000.0), 0.01, 1.0, np.random.default_rng(2))
    >>> bool(130 < shot.frame.mean() < 170)    # 100 DN offset + 0.1 DN/e- * 0.5 * 1000 photons
    True
    """

    def __init__(self, params: CCDParams = CCDParams(), seed: int | np.random.SeedSequence = 0,
                 fixed_pattern: bool = True, shot_noise: str = "gaussian", nonlinearity: float = 0.0) -> None:
        if shot_noise not in ("gaussian", "poisson"):
            raise ValueError(f"shot_noise must be 'gaussian' or 'poisson', got {shot_noise!r}")
        if not 0.0 <= nonlinearity < 1.0 / 3.0:
            raise ValueError(f"nonlinearity must be in [0, 1/3) (a monotonic response), got {nonlinearity!r}")
        self.shot_noise = shot_noise
        self.nonlinearity = float(nonlinearity)
        self.params = params
        rng = np.random.default_rng(seed)
        shape = (params.height, params.width)
        if fixed_pattern:
            self.response_map = 1.0 + params.prnu_rel * rng.standard_normal(shape)
            # Log-normal keeps the dark current positive with relative rms dsnu_rel.
            s2 = np.log1p(params.dsnu_rel**2)
            self.dark_map = params.dark_current_e_per_s * np.exp(np.sqrt(s2) * rng.standard_normal(shape) - s2 / 2)
            hot = rng.random(shape) < params.hot_pixel_fraction
            self.dark_map[hot] = params.hot_pixel_dark_current_e_per_s
            self.hot_pixels = hot
        else:
            self.response_map = np.ones(shape)
            self.dark_map = np.full(shape, params.dark_current_e_per_s)
            self.hot_pixels = np.zeros(shape, bool)
        self._qe_map = params.quantum_efficiency * self.response_map

    def system_gain(self, gain_factor: float) -> float:
        """System gain ``K`` [DN/e-] for an analog gain factor."""
        return self.params.base_gain_dn_per_e * gain_factor

    def mean_dn(self, photons: np.ndarray | float, exposure_s: float, gain_factor: float) -> np.ndarray:
        """Expected digital value per pixel below saturation (EMVA eq. for ``mu_y``, with
        the non-linearity when there is one) [DN]."""
        p = self.params
        electrons = p.quantum_efficiency * np.asarray(photons, float) * self.response_map + self.dark_map * exposure_s
        return p.offset_dn + nonlinear_signal(self.system_gain(gain_factor) * electrons, self.nonlinearity,
                                              p.max_dn - p.offset_dn)

    def expose(self, photons: np.ndarray | float, exposure_s: float, gain_factor: float,
               rng: np.random.Generator) -> Exposure:
        """Render one frame.

        Parameters
        ----------
        photons : array_like
            Mean number of photons reaching each pixel during the exposure, shape
            (height, width) or scalar (0 for a dark frame).
        exposure_s : float
            Exposure time [s] (sets the dark signal).
        gain_factor : float
            Analog gain factor; ``K = K0 * gain_factor``.
        rng : numpy.random.Generator
            Source of the temporal noise.

        Returns
        -------
        Exposure
            Frame [DN] and saturation mask.
        """
        p = self.params
        shape = (p.height, p.width)
        mean_e = self.dark_map * exposure_s
        mean_e += np.asarray(photons, float) * self._qe_map
        read_var = p.read_noise_e**2
        if self.shot_noise == "poisson":
            electrons = rng.poisson(mean_e).astype(np.float64)  # photon + dark shot noise
            full = electrons >= p.full_well_e
            np.minimum(electrons, p.full_well_e, out=electrons)
            electrons += p.read_noise_e * rng.standard_normal(shape)
        elif mean_e.max() + 10.0 * np.sqrt(mean_e.max() + read_var) < p.full_well_e:
            # No pixel can reach full well (10 sigma): shot and read noise in one normal draw
            # with the summed variance (same distribution as drawing them one after the other).
            full = np.zeros(shape, bool)
            electrons = _add_scaled_noise(mean_e, read_var, rng.standard_normal(shape))
        else:  # same mean and variance as the Poisson count, clipped at full well
            electrons = _add_scaled_noise(mean_e, 0.0, rng.standard_normal(shape))
            full = electrons >= p.full_well_e
            np.minimum(electrons, p.full_well_e, out=electrons)
            electrons += p.read_noise_e * rng.standard_normal(shape)
        dn = electrons
        dn *= self.system_gain(gain_factor)
        if self.nonlinearity:
            nonlinear_signal(dn, self.nonlinearity, p.max_dn - p.offset_dn, out=dn)
        dn += p.offset_dn + 0.5
        np.floor(dn, out=dn)
        np.clip(dn, 0, p.max_dn, out=dn)
        saturated = dn >= p.max_dn
        saturated |= full
        return Exposure(frame=dn.astype(np.uint16), saturated=saturated)


def _add_scaled_noise(mean: np.ndarray, extra_variance: float, noise: np.ndarray) -> np.ndarray:
    """``mean + sqrt(mean + extra_variance) * noise``, written into ``noise`` (a frame's
    worth of temporaries fewer; the same numbers as the expression)."""
    scale = mean + extra_variance
    np.sqrt(scale, out=scale)
    noise *= scale
    np.add(mean, noise, out=noise)
    return noise
