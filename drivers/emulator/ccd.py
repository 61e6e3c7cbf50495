"""CCD camera model after the EMVA 1288 linear camera model.

Per pixel and exposure (EMVA Standard 1288, release 4.0 "Linear", section 2, Fig. 1-2):

- ``mu_p`` photons hit the pixel; a fraction ``eta`` (quantum efficiency) become electrons,
  with shot noise: the number of photo-electrons is Poisson distributed;
- a dark current ``I_d`` [e-/s] adds Poisson distributed thermal electrons ``I_d t``;
- (by default the sum of both Poisson counts is drawn from the normal distribution with
  the same mean and variance: EMVA 1288 uses only these two moments, the read noise
  hides the difference at low counts, and a pixel's deviate can be drawn without the
  others', see below; ``shot_noise="poisson"`` draws exact Poisson counts);
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

A frame is rendered where it is read (:class:`Exposure`): the rig reads the statistics of
its radiance window, a few percent of the sensor, and only those pixels are computed. Each
pixel's noise is the deviate at its own position in a counter-based stream keyed per frame
(:func:`normal_field`), so a pixel has the same value whichever region it is read in.

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


class Exposure:
    """One frame, rendered where it is read.

    A camera that reports the statistics of a region of interest reads a few percent of
    its pixels (the rig's radiance window is about 120 x 120 of 512 x 480); the frame's
    noise is therefore drawn pixel by pixel from a counter-based generator keyed per frame
    (:func:`normal_field`), and only the pixels asked for are rendered. A pixel's value
    does not depend on which region it was read in: :meth:`region` and :attr:`frame` agree
    wherever they overlap, and a frame read twice is the same frame.

    Parameters
    ----------
    sensor : CCDSensor
        The sensor that took it (its fixed patterns and parameters).
    photons : numpy.ndarray or float
        Mean photons per pixel during the exposure, shape (height, width) or scalar.
    exposure_s, gain_factor : float
        Exposure time [s] and analog gain factor.
    key : numpy.ndarray
        The frame's key of the noise generator: two unsigned 64-bit integers.
    """

    def __init__(self, sensor: "CCDSensor", photons: np.ndarray | float, exposure_s: float, gain_factor: float,
                 key: np.ndarray) -> None:
        self.sensor = sensor
        self.photons = photons if np.ndim(photons) == 0 else np.asarray(photons, float)
        self.exposure_s = float(exposure_s)
        self.gain_factor = float(gain_factor)
        self.key = key
        self._rendered: dict[tuple[int, int, int, int], tuple[np.ndarray, np.ndarray]] = {}

    def region(self, x0: int, y0: int, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """The digital values (uint16) [DN] and the saturation mask of a rectangle of pixels,
        shape (height, width); the last two rectangles asked for are kept."""
        box = (int(x0), int(y0), int(width), int(height))
        if box not in self._rendered:
            if len(self._rendered) >= 2:
                self._rendered.pop(next(iter(self._rendered)))
            self._rendered[box] = self.sensor.render(self, *box)
        return self._rendered[box]

    @property
    def frame(self) -> np.ndarray:
        """Digital values of the whole sensor, uint16, shape (height, width) [DN]."""
        return self.region(0, 0, self.sensor.params.width, self.sensor.params.height)[0]

    @property
    def saturated(self) -> np.ndarray:
        """Boolean mask of the whole sensor: pixel at full well or at the ADC maximum."""
        return self.region(0, 0, self.sensor.params.width, self.sensor.params.height)[1]


def normal_field(key: np.ndarray, stream: int, x0: int, y0: int, width: int, height: int,
                 sensor_width: int, sensor_height: int) -> np.ndarray:
    """Standard normal deviates of a rectangle of pixels, the same whatever rectangle a
    pixel is read in [-].

    Pixel (row, column) of field ``stream`` takes the uniform deviate number
    ``(stream * sensor_height + row) * sensor_width + column`` of a Philox generator keyed
    by ``key`` (Salmon et al. 2011, a counter-based generator: draw ``n`` is reached by
    setting the counter, without drawing the ones before it), mapped to a normal deviate
    by the inverse normal CDF at the centre of its 2^-53 bin (tails cut at 8.3 sd).

    Parameters
    ----------
    key : numpy.ndarray
        Two unsigned 64-bit integers.
    stream : int
        Which of the frame's independent fields (0, 1, ...).
    x0, y0, width, height : int
        The rectangle [pixels].
    sensor_width, sensor_height : int
        The sensor's size [pixels].

    Returns
    -------
    numpy.ndarray
        Shape (height, width).

    References
    ----------
    J. K. Salmon, M. A. Moraes, R. O. Dror, D. E. Shaw, "Parallel random numbers: as easy
    as 1, 2, 3", SC '11 (2011).
    """
    from scipy.special import ndtri

    first = (stream * sensor_height + y0) * sensor_width + x0
    block, skip = divmod(first, _PHILOX_LANES)
    generator = np.random.Generator(np.random.Philox(key=key, counter=np.array([block, 0, 0, 0], np.uint64)))
    rows = generator.random(skip + height * sensor_width)[skip:].reshape(height, sensor_width)[:, :width]
    rows += _HALF_BIN
    return ndtri(rows)


#: 64-bit outputs of one Philox counter value (numpy's Philox 4x64).
_PHILOX_LANES = 4
#: Half the spacing of ``Generator.random``'s doubles (k / 2^53): their bins' centres.
_HALF_BIN = 2.0 ** -54


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
        """Take one frame (rendered where it is read, :class:`Exposure`).

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
            Source of the temporal noise: the frame's key is drawn from it.

        Returns
        -------
        Exposure
            The frame [DN] and its saturation mask.
        """
        return Exposure(self, photons, exposure_s, gain_factor, rng.integers(0, 2**64, size=2, dtype=np.uint64))

    def render(self, shot: Exposure, x0: int, y0: int, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Digital values (uint16) [DN] and saturation mask of a rectangle of a frame.

        Gaussian shot noise: a pixel that cannot reach full well (10 sd below it) takes the
        shot and read noise in one normal deviate of the summed variance (the same
        distribution as drawing them one after the other); any other pixel takes its shot
        noise from field 0, is clipped at full well and takes its read noise from field 1.
        Poisson shot noise draws the whole frame from the frame's key (exact counts are not
        addressable pixel by pixel) and crops it.
        """
        p = self.params
        rows, cols = slice(y0, y0 + height), slice(x0, x0 + width)
        mean_e = self.dark_map[rows, cols] * shot.exposure_s
        photons = shot.photons if np.ndim(shot.photons) == 0 else shot.photons[rows, cols]
        mean_e += photons * self._qe_map[rows, cols]
        read_var = p.read_noise_e**2
        if self.shot_noise == "poisson":
            frame_e = self._poisson_frame(shot)
            electrons = frame_e[rows, cols].copy()
            full = electrons >= p.full_well_e
            np.minimum(electrons, p.full_well_e, out=electrons)
            electrons += p.read_noise_e * normal_field(shot.key, 1, x0, y0, width, height, p.width, p.height)
        else:
            field = normal_field(shot.key, 0, x0, y0, width, height, p.width, p.height)
            can_fill = mean_e + 10.0 * np.sqrt(mean_e + read_var) >= p.full_well_e
            filling = bool(can_fill.any())
            if filling:
                shot_only = mean_e[can_fill] + np.sqrt(mean_e[can_fill]) * field[can_fill]
            electrons = _add_scaled_noise(mean_e, read_var, field)
            full = np.zeros((height, width), bool)
            if filling:
                full[can_fill] = shot_only >= p.full_well_e
                read = normal_field(shot.key, 1, x0, y0, width, height, p.width, p.height)[can_fill]
                electrons[can_fill] = np.minimum(shot_only, p.full_well_e) + p.read_noise_e * read
        dn = electrons
        dn *= self.system_gain(shot.gain_factor)
        if self.nonlinearity:
            nonlinear_signal(dn, self.nonlinearity, p.max_dn - p.offset_dn, out=dn)
        dn += p.offset_dn + 0.5
        np.floor(dn, out=dn)
        np.clip(dn, 0, p.max_dn, out=dn)
        saturated = dn >= p.max_dn
        saturated |= full
        return dn.astype(np.uint16), saturated

    def _poisson_frame(self, shot: Exposure) -> np.ndarray:
        """The whole frame's electron counts with exact Poisson shot noise [e-]."""
        mean_e = self.dark_map * shot.exposure_s + np.asarray(shot.photons, float) * self._qe_map
        generator = np.random.Generator(np.random.Philox(key=shot.key))
        return generator.poisson(mean_e).astype(np.float64)


def _add_scaled_noise(mean: np.ndarray, extra_variance: float, noise: np.ndarray) -> np.ndarray:
    """``mean + sqrt(mean + extra_variance) * noise``, written into ``noise`` (a frame's
    worth of temporaries fewer; the same numbers as the expression)."""
    scale = mean + extra_variance
    np.sqrt(scale, out=scale)
    noise *= scale
    np.add(mean, noise, out=noise)
    return noise
