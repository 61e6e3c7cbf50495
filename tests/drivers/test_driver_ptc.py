"""Photon-transfer analysis (EMVA 1288 photon transfer method) on synthetic frames.

drivers.ptc is checked here against frames drawn directly from the EMVA 1288 linear
model with known K and sigma_d; the same analysis run through the driver against the
emulator is in test_driver_noise.py.
"""
from __future__ import annotations

import numpy as np
import pytest

from drivers.ptc import PairStatistics, pair_statistics, photon_transfer

K = 0.1          # system gain [DN/e-]
SIGMA_D = 8.0    # dark noise [e-]
OFFSET = 100.0   # [DN]
DARK_RATE = 20.0 # dark current [e-/s]
FULL_WELL = 30000.0
N = 40000        # pixels per frame


def _frame(rng, photo_e, t):
    e = rng.poisson(photo_e + DARK_RATE * t, N).astype(float)
    e = np.minimum(e, FULL_WELL) + rng.normal(0.0, SIGMA_D, N)
    return np.clip(np.floor(OFFSET + K * e + 0.5), 0, 4095)


def _series(rng, exposures, rate):
    light = [pair_statistics(_frame(rng, rate * t, t), _frame(rng, rate * t, t)) for t in exposures]
    dark = [pair_statistics(_frame(rng, 0.0, t), _frame(rng, 0.0, t)) for t in exposures]
    return light, dark


def test_pair_statistics_removes_fixed_pattern():
    rng = np.random.default_rng(3)
    pattern = rng.normal(0, 50, N)  # a fixed pattern 25x larger than the noise
    a = 1000 + pattern + rng.normal(0, 2, N)
    b = 1000 + pattern + rng.normal(0, 2, N)
    s = pair_statistics(a, b)
    # Temporal variance 4 DN^2; with N = 4e4 its relative standard error is sqrt(2/N) = 0.7 %.
    assert s.variance == pytest.approx(4.0, rel=0.03)
    assert s.mean == pytest.approx(1000.0, abs=0.5)


def test_photon_transfer_recovers_gain_dark_noise_and_dark_linearity():
    rng = np.random.default_rng(7)
    exposures = np.linspace(0.002, 0.05, 10)
    rate = 4.0e5  # photo-electrons/s: 20000 e- (2000 DN) at the longest exposure
    light, dark = _series(rng, exposures, rate)
    r = photon_transfer(exposures, light, dark)
    # Requirements of the issue: K within 2 %, dark noise within 10 %.
    assert r.system_gain == pytest.approx(K, rel=0.02)
    assert r.dark_noise_e == pytest.approx(SIGMA_D, rel=0.10)
    # Dark signal: OFFSET + K * DARK_RATE * t, i.e. 2 DN/s. Each dark mean has a standard
    # error sigma_y.dark / sqrt(N) = 0.8 / 200 = 0.004 DN, so the rate (over 0.048 s) is
    # known to ~0.1 DN/s; 0.5 DN/s bounds it at 5 sigma.
    assert r.dark_rate == pytest.approx(K * DARK_RATE, abs=0.5)
    assert r.dark_offset == pytest.approx(OFFSET, abs=0.02)


def test_points_beyond_saturation_are_excluded():
    rng = np.random.default_rng(11)
    exposures = np.linspace(0.005, 0.2, 14)  # up to 80000 e-: far beyond the full well
    light, dark = _series(rng, exposures, 4.0e5)
    r = photon_transfer(exposures, light, dark)
    assert not r.used[-1] and r.used[0]
    # Saturated points would drag the slope towards 0; excluded, K is still within 2 %.
    assert r.system_gain == pytest.approx(K, rel=0.02)
    # The variance peaks just below the full well, 100 + 0.1 * 30000 = 3100 DN.
    assert 2500 < r.saturation_mean < 3150


def test_photon_transfer_rejects_bad_input():
    s = PairStatistics(100.0, 1.0, 10)
    with pytest.raises(ValueError, match="at least 3 distinct"):
        photon_transfer([0.1, 0.1, 0.1], [s] * 3, [s] * 3)
    with pytest.raises(ValueError, match="same length"):
        photon_transfer([0.1, 0.2, 0.3], [s] * 2, [s] * 3)
    with pytest.raises(ValueError, match="must match"):
        pair_statistics(np.zeros(4), np.zeros(5))


def test_a_textured_target_is_not_taken_for_the_cameras_prnu():
    """Frames of a textured target (3 % albedo correlated over 5 pixels, as the `lab`
    sample's) through a camera of 0.5 % PRNU: the pair's white spatial variance is the
    camera's fixed pattern and half the temporal noise (within 5 %), while the plain
    spatial variance holds the texture too, more than 30 times more."""
    from drivers.emulator.texture import gaussian_random_field

    rng = np.random.default_rng(8)
    shape = (138, 138)
    texture = 1.0 + 0.03 * gaussian_random_field(shape, 1.0, 5.5, rng)
    prnu = 1.0 + 0.005 * rng.standard_normal(shape)
    signal = 1500.0 * texture * prnu
    a, b = (signal + rng.normal(0.0, 3.0, shape) for _ in range(2))
    s = pair_statistics(a, b)
    expected = (1500.0 * 0.005) ** 2 + 0.5 * 9.0
    assert s.white_variance == pytest.approx(expected, rel=0.05)
    assert s.spatial_variance > 30 * expected
