"""EMVA 1288 statistics of the emulated CCD, checked on the sensor model directly.

EMVA Standard 1288 release 4.0 Linear: section 2 (linear model: mu_y = mu_y.dark + K eta mu_p,
sigma_y^2 = K^2 sigma_d^2 + sigma_q^2 + K (mu_y - mu_y.dark)) and section 6 (photon transfer
from pairs of frames: temporal variance = var(A - B) / 2).
"""
from __future__ import annotations

import numpy as np
import pytest

from scipy import stats

from drivers.emulator.ccd import CCDParams, CCDSensor, normal_field

SMALL = CCDParams(width=128, height=96)


def photon_transfer(sensor: CCDSensor, photons_per_s: float, exposures: np.ndarray, gain: float, seed: int):
    """Mean signal above dark and temporal variance (EMVA section 6.1) for each exposure."""
    rng = np.random.default_rng(seed)
    means, variances = [], []
    for t in exposures:
        a = sensor.expose(photons_per_s * t, t, gain, rng).frame.astype(float)
        b = sensor.expose(photons_per_s * t, t, gain, rng).frame.astype(float)
        da = sensor.expose(0.0, t, gain, rng).frame.astype(float)
        db = sensor.expose(0.0, t, gain, rng).frame.astype(float)
        hot = sensor.hot_pixels
        a, b, da, db = (x[~hot] for x in (a, b, da, db))
        means.append(0.5 * (a.mean() + b.mean()) - 0.5 * (da.mean() + db.mean()))
        variances.append((0.5 * np.var(a - b) - 0.5 * np.var(da - db)))
    return np.array(means), np.array(variances)


@pytest.mark.parametrize("gain", [1.0, 2.5])
@pytest.mark.parametrize("shot_noise", ["gaussian", "poisson"])
def test_photon_transfer_recovers_system_gain_within_2_percent(gain, shot_noise):
    sensor = CCDSensor(SMALL, seed=3, shot_noise=shot_noise)
    exposures = np.linspace(0.005, 0.06, 8)
    # 4e5 photons/s -> up to 12000 e- at 60 ms: below full well (30000 e-) and the ADC limit.
    means, variances = photon_transfer(sensor, 4e5, exposures, gain, seed=4)
    slope = np.polyfit(means, variances, 1)[0]
    # Each variance comes from ~12k pixel differences: relative sd ~ sqrt(2/12k) ~ 1.3 %;
    # the fit over 8 points brings the slope error well under 1 %, so 2 % is a safe bound.
    assert slope == pytest.approx(sensor.system_gain(gain), rel=0.02)


def test_dark_noise_recovered_within_10_percent():
    sensor = CCDSensor(SMALL, seed=5)
    p = sensor.params
    rng = np.random.default_rng(6)
    t = 0.001  # dark shot noise negligible: sigma_d^2 = 8^2 + 20 * 0.001 e-^2
    a = sensor.expose(0.0, t, 1.0, rng).frame.astype(float)[~sensor.hot_pixels]
    b = sensor.expose(0.0, t, 1.0, rng).frame.astype(float)[~sensor.hot_pixels]
    K = sensor.system_gain(1.0)
    var_y_dark = 0.5 * np.var(a - b)
    sigma_d = np.sqrt(max(var_y_dark - 1.0 / 12.0, 0.0)) / K  # EMVA: remove quantisation noise
    expected = np.sqrt(p.read_noise_e**2 + p.dark_current_e_per_s * t)
    # ~12k pixel differences: sd of the variance estimate ~1.3 % -> 10 % is generous.
    assert sigma_d == pytest.approx(expected, rel=0.10)


def test_mean_is_linear_in_exposure_with_dark_offset():
    sensor = CCDSensor(SMALL, seed=7, fixed_pattern=False)
    rng = np.random.default_rng(8)
    p = sensor.params
    for t in (0.01, 0.03, 0.05):
        frame = sensor.expose(2e5 * t, t, 1.0, rng).frame
        expected = p.offset_dn + p.base_gain_dn_per_e * (p.quantum_efficiency * 2e5 * t + p.dark_current_e_per_s * t)
        # sd of the mean over 12288 pixels < 0.05 DN.
        assert frame.mean() == pytest.approx(expected, abs=0.2)


def test_dark_current_grows_with_exposure():
    sensor = CCDSensor(SMALL, seed=9, fixed_pattern=False)
    rng = np.random.default_rng(10)
    short = sensor.expose(0.0, 0.01, 1.0, rng).frame.mean()
    long = sensor.expose(0.0, 10.0, 1.0, rng).frame.mean()
    # 20 e-/s * 10 s * 0.1 DN/e- = 20 DN more after 10 s (mean over 12k pixels: sd 0.02 DN).
    assert long - short == pytest.approx(20.0 - 0.02, abs=0.3)


def test_saturation_at_full_well_and_at_adc_maximum():
    sensor = CCDSensor(SMALL, seed=11, fixed_pattern=False)
    rng = np.random.default_rng(12)
    p = sensor.params
    full_well = sensor.expose(1e6, 1.0, 1.0, rng)  # 5e5 e- >> 30000 e- full well
    assert full_well.saturated.all()
    # Gain 1: full well is 100 + 0.1 * 30000 = 3100 DN (read noise 0.8 DN) below the ADC maximum.
    assert abs(full_well.frame.mean() - 3100.0) < 1.0
    adc = sensor.expose(1e6, 1.0, 4.0, rng)  # K = 0.4: 30000 e- would be 12100 DN > 4095
    assert (adc.frame == p.max_dn).all() and adc.saturated.all()
    dim = sensor.expose(1000.0, 0.01, 1.0, rng)
    assert not dim.saturated.any()


def test_fixed_pattern_noise_prnu_dsnu_and_hot_pixels():
    params = CCDParams(width=256, height=256, hot_pixel_fraction=1e-3)
    sensor = CCDSensor(params, seed=13)
    normal = ~sensor.hot_pixels
    # PRNU 0.5 % and DSNU 10 % rms, drawn once per sensor (65k pixels: estimates within ~2 %).
    assert np.std(sensor.response_map) == pytest.approx(params.prnu_rel, rel=0.05)
    assert np.std(sensor.dark_map[normal]) / params.dark_current_e_per_s == pytest.approx(params.dsnu_rel, rel=0.05)
    # 1e-3 of 65536 pixels: 66 expected, Poisson sd 8 -> [30, 110] is beyond 4 sd.
    assert 30 < sensor.hot_pixels.sum() < 110
    assert np.all(sensor.dark_map[sensor.hot_pixels] == params.hot_pixel_dark_current_e_per_s)
    # Fixed patterns are the same in every frame: the mean of a long dark frame shows hot pixels.
    frame = sensor.expose(0.0, 5.0, 1.0, np.random.default_rng(1)).frame
    assert frame[sensor.hot_pixels].min() > frame[normal].max()


def test_frames_are_reproducible_from_seeds():
    a = CCDSensor(SMALL, seed=1).expose(500.0, 0.01, 1.0, np.random.default_rng(2)).frame
    b = CCDSensor(SMALL, seed=1).expose(500.0, 0.01, 1.0, np.random.default_rng(2)).frame
    c = CCDSensor(SMALL, seed=1).expose(500.0, 0.01, 1.0, np.random.default_rng(3)).frame
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_bad_shot_noise_option_names_the_parameter():
    with pytest.raises(ValueError, match="shot_noise"):
        CCDSensor(SMALL, shot_noise="binomial")


@pytest.mark.parametrize("shot_noise", ["gaussian", "poisson"])
def test_a_pixel_has_one_value_whichever_region_it_is_read_in(shot_noise):
    """The rig reads its radiance window only (ccd module notes): a window, the whole frame
    and an overlapping window must agree pixel for pixel, near full well too, where the
    pixels that can fill take a second (read-noise) field."""
    sensor = CCDSensor(SMALL, seed=21, shot_noise=shot_noise)
    photons = np.linspace(0.0, 7.68e4, SMALL.width * SMALL.height).reshape(SMALL.height, SMALL.width)
    shot = sensor.expose(photons, 0.01, 1.0, np.random.default_rng(22))
    window, window_saturated = shot.region(17, 60, 40, 30)
    overlap, _ = shot.region(30, 70, 50, 26)
    assert 0 < window_saturated.sum() < window_saturated.size  # the window crosses full well
    full = CCDSensor(SMALL, seed=21, shot_noise=shot_noise).expose(photons, 0.01, 1.0, np.random.default_rng(22))
    assert np.array_equal(window, full.frame[60:90, 17:57])
    assert np.array_equal(window_saturated, full.saturated[60:90, 17:57])
    assert np.array_equal(overlap, full.frame[70:96, 30:80])


def test_noise_fields_are_standard_normal_and_independent():
    key = np.array([5, 7], np.uint64)
    a = normal_field(key, 0, 0, 0, 300, 200, 300, 200).ravel()
    b = normal_field(key, 1, 0, 0, 300, 200, 300, 200).ravel()
    other = normal_field(np.array([5, 8], np.uint64), 0, 0, 0, 300, 200, 300, 200).ravel()
    # 60,000 deviates: the mean's sd is 0.004, the variance's 0.006, a correlation's 0.004
    assert abs(a.mean()) < 0.02 and abs(a.var() - 1.0) < 0.03
    assert stats.kstest(a, "norm").pvalue > 1e-3
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.02 and abs(np.corrcoef(a, other)[0, 1]) < 0.02
    # neighbouring pixels are independent too (the counter's lanes, rows and columns)
    field = a.reshape(200, 300)
    assert abs(np.corrcoef(field[:, 1:].ravel(), field[:, :-1].ravel())[0, 1]) < 0.02
    assert abs(np.corrcoef(field[1:].ravel(), field[:-1].ravel())[0, 1]) < 0.02


def test_successive_frames_have_their_own_noise():
    sensor = CCDSensor(SMALL, seed=23)
    rng = np.random.default_rng(24)
    first, second = (sensor.expose(2000.0, 0.01, 1.0, rng).region(0, 0, 64, 48)[0] for _ in range(2))
    difference = first.astype(float) - second
    # shot + read noise: sqrt(1000 + 64) e- = 3.3 DN per frame, 4.6 DN in a difference
    assert 4.0 < difference.std() < 5.2
