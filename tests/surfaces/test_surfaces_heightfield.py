"""The Gaussian height field and its mapping onto Oren & Nayar's roughness sigma."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.surfaces import HeightField, rms_slope_angle
from gonio.surfaces.heightfield import facet_slopes, realise, rms_facet_angle, unit_gaussian_heights


@pytest.mark.parametrize("sigma", [5.0, 20.0, 40.0, 60.0])
def test_the_realised_field_has_the_rms_slope_angle_of_the_groove_field(sigma):
    # the mapping (docs/surfaces.md): projected-area rms facet slope angle of the
    # triangles = sqrt(E[theta_a^2]) of eq 32's slope-area density; root-found to 1e-12
    field = realise(HeightField(sigma, 0.5, cells=64, correlation=4.0, seed=2))
    assert field.rms_angle == pytest.approx(rms_slope_angle(sigma), rel=1e-9)
    assert rms_facet_angle(field.heights) == pytest.approx(field.rms_angle, rel=1e-12)


def test_rms_slope_angle_of_eq32():
    # small sigma: the slope-area density is a 2-D Gaussian in the tilt, E[theta^2] = 2 sigma^2
    assert rms_slope_angle(0.5) == pytest.approx(math.sqrt(2) * 0.5, rel=1e-4)
    assert rms_slope_angle(0.0) == 0.0
    # truncation at 90 deg pulls it below sqrt(2) sigma, monotonically in sigma
    values = [rms_slope_angle(s) for s in (10.0, 20.0, 30.0, 40.0, 60.0, 90.0)]
    assert np.all(np.diff(values) > 0) and values[-1] < 90.0
    assert values[2] == pytest.approx(39.78, abs=0.01) and values[2] < math.sqrt(2) * 30.0
    with pytest.raises(ValueError, match=r"sigma \[deg\] = 91 is outside"):
        rms_slope_angle(91.0)


def test_the_triangles_resolve_the_smooth_field():
    # at the default correlation length (8 cells) the triangles' rms slope angle is within
    # 1 % of that of the spectral gradient of the same heights (measured 0.4 %)
    heights = unit_gaussian_heights(256, 8.0, seed=0)
    k = 2.0 * np.pi * np.fft.fftfreq(256)
    spectrum = np.fft.fft2(heights)
    gx = np.fft.ifft2(1j * k[:, None] * spectrum).real
    gy = np.fft.ifft2(1j * k[None, :] * spectrum).real
    for scale in (0.5, 2.0, 5.0):
        exact = np.degrees(np.sqrt(np.mean(np.arctan(scale * np.hypot(gx, gy)) ** 2)))
        assert rms_facet_angle(scale * heights) == pytest.approx(exact, rel=0.01)


def test_heights_are_periodic_stationary_and_seeded():
    heights = unit_gaussian_heights(256, 6.0, seed=5)
    assert np.mean(heights) == pytest.approx(0.0, abs=1e-12) and np.mean(heights**2) == pytest.approx(1.0)
    # correlation exp(-r^2/l^2): at r = l (6 cells) e^-1 = 0.368, averaged over both axes
    # (across the period: periodic) and four realisations; the spread of this average over
    # ten sets of seeds was 0.0085, so 0.04 is 4.7 of it (a filter with twice or half the
    # exponent gives 0.61 or 0.14)
    lags = [np.mean(h * np.roll(h, 6, axis=axis)) for seed in range(4)
            for h in [unit_gaussian_heights(256, 6.0, seed=seed)] for axis in (0, 1)]
    assert np.mean(lags) == pytest.approx(math.exp(-1.0), abs=0.04)
    assert np.array_equal(heights, unit_gaussian_heights(256, 6.0, seed=5))
    assert not np.array_equal(heights, unit_gaussian_heights(256, 6.0, seed=6))


def test_facet_slopes_follow_the_renderer_split():
    # a tilted plane z = 0.3 x - 0.2 y is one slope everywhere but across the period's wrap
    x, y = np.meshgrid(np.arange(8.0), np.arange(8.0), indexing="ij")
    b, c = facet_slopes(0.3 * x - 0.2 * y)
    inner = (slice(None), slice(0, 7), slice(0, 7))
    assert np.allclose(b[inner], 0.3) and np.allclose(c[inner], -0.2)


def test_height_field_parameters_are_checked():
    with pytest.raises(ValueError, match=r"sigma \[deg\] = 61 is outside its valid range \[0, 60\]"):
        HeightField(61.0, 0.5)
    with pytest.raises(ValueError, match="cells = 10 is outside its valid range"):
        HeightField(20.0, 0.5, cells=10)
    with pytest.raises(ValueError, match=r"cells = 64.5 must be an integer"):
        HeightField(20.0, 0.5, cells=64.5)
    with pytest.raises(ValueError, match=r"correlation \[cells\] = 40 is outside its valid range \[2, 32\]"):
        HeightField(20.0, 0.5, cells=256, correlation=40.0)
