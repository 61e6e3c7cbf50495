"""The sample as labs meet it (drivers.emulator.texture, drivers.emulator.holder).

The texture's random fields have the statistics they are built with; a facet's slope
response is the geometry of a tilted facet (checked against closed forms for a Lambertian
surface); what the camera's window sees of the texture is the texture's mean over the
window; mountings are reproducible by index; spinning averages what turns with the
sample; and a rig whose departures are all 0 renders what it rendered before.
"""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest

import gonio
from drivers.camera import SensorInfo
from drivers.emulator.holder import SampleHolder
from drivers.emulator.rig import EmulatedRig
from drivers.emulator.systematics import Systematics, realism
from drivers.emulator.texture import (Mounting, draw_mounting, gaussian_random_field, lab_texture, mounting_tilt,
                                      pixel_maps, realise_texture, relative_radiance, slope_response)
from drivers.emulator.world import Optics, footprint_coverage
from drivers.roi import roi_for_view

INFO = SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8)


def _lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.9 / np.pi)


def test_random_field_has_unit_variance_and_the_gaussian_correlation():
    """Averaged over 20 realisations, the field's variance is 1 and its correlation at a
    lag of one correlation length is exp(-1/2) = 0.61 (the spectrum's normalisation and
    shape); 20 x 200 x 200 cells of a 4-cell length give both to a few percent."""
    rng = np.random.default_rng(0)
    fields = [gaussian_random_field((200, 200), 0.25, 1.0, rng) for _ in range(20)]
    variance = np.mean([f.var() for f in fields])
    lag = np.mean([np.mean(f[:, 4:] * f[:, :-4]) for f in fields]) / variance
    assert variance == pytest.approx(1.0, abs=0.08)
    assert lag == pytest.approx(math.exp(-0.5), abs=0.05)


def test_texture_has_the_albedo_and_slope_rms_it_is_built_with():
    t = realise_texture(0.03, 1.0, 1.0, np.random.default_rng(3))
    assert t.albedo.mean() == pytest.approx(1.0, abs=0.003)
    assert t.albedo.std() == pytest.approx(0.03, rel=0.1)
    assert np.degrees(t.slope_x.std()) == pytest.approx(1.0, rel=0.1)
    assert np.degrees(t.slope_y.std()) == pytest.approx(1.0, rel=0.1)
    flat = realise_texture(0.0, 0.0, 1.0, np.random.default_rng(3))
    assert np.all(flat.albedo == 1.0) and np.all(flat.slope_x == 0.0)


def test_lambertian_facet_slope_response_is_the_tilted_geometry():
    """For f = rho/pi the apparent reflectance of a facet tipped by s toward the lamp at
    theta_i (camera at the normal) is cos(theta_i - s): d ln F / ds = tan(theta_i). With the
    lamp at the normal and the camera at theta_r, only the projected area changes:
    cos(theta_r - s) / cos(theta_r), so d ln F / ds = tan(theta_r); out of the plane the
    first derivative vanishes by symmetry."""
    lamp = slope_response(_lambert, 60.0, 0.0, 0.0, 0.0, 0.5)
    assert lamp.gx / lamp.value == pytest.approx(math.tan(math.radians(60.0)), rel=2e-3)
    assert lamp.gy / lamp.value == pytest.approx(0.0, abs=1e-9)
    # F = cos(60 - s) cos(s) / (cos 0 n_z) with n_z = cos s: F'' / F = -1 at s = 0
    assert lamp.hxx / lamp.value == pytest.approx(-1.0, abs=2e-3)
    camera = slope_response(_lambert, 0.0, 0.0, 60.0, 0.0, 0.5)
    assert camera.gx / camera.value == pytest.approx(math.tan(math.radians(60.0)), rel=2e-3)
    assert slope_response(_lambert, 60.0, 0.0, 0.0, 0.0, 0.0).gx == 0.0


def test_window_sees_the_mean_of_the_texture_over_the_window():
    """Without slopes, the window's mean relative radiance is the mean albedo over the
    central 25.4 mm square (the window covers it at every view): at the normal view and
    foreshortened at 60 deg alike, within the pixels' rounding."""
    texture = realise_texture(0.05, 0.0, 1.0, np.random.default_rng(5))
    lab = lab_texture(texture, Mounting())
    inside = (np.abs(lab.coordinates_mm) <= 12.7)
    expected = lab.fields[0][np.ix_(inside, inside)].mean()
    for view in (0.0, 60.0):
        maps = pixel_maps(lab, Optics(), view)
        roi = roi_for_view(INFO, view)
        window = maps[0, roi.y0:roi.y0 + roi.height, roi.x0:roi.x0 + roi.width]
        assert window.mean() == pytest.approx(expected, abs=4e-4), view
    assert relative_radiance(maps, slope_response(_lambert, 30.0, 0.0, 60.0, 0.0, 0.0)).shape == (480, 512)


def test_mountings_are_reproducible_and_spinning_averages_what_turns_with_the_sample():
    a = draw_mounting(7, 3, None, False, 0.05, 10)
    assert a == draw_mounting(7, 3, None, False, 0.05, 10)
    assert a != draw_mounting(7, 4, None, False, 0.05, 10)
    assert draw_mounting(7, 3, 90.0, False, 0.05, 10).rotation_deg == 90.0
    # the wedge turns with the sample: rotating it half a turn reverses its tilt
    plain, turned = Mounting(rotation_deg=0.0), Mounting(rotation_deg=180.0)
    assert mounting_tilt(turned, (0.1, 0.05)) == pytest.approx(tuple(-v for v in mounting_tilt(plain, (0.1, 0.05))))
    assert mounting_tilt(Mounting(spin=True, seat_tilt_deg=(0.3, 0.3)), (0.1, 0.0)) == (0.0, 0.0)
    texture = realise_texture(0.05, 1.0, 1.0, np.random.default_rng(1))
    still, spun = lab_texture(texture, Mounting()), lab_texture(texture, Mounting(spin=True))
    centre = np.abs(spun.coordinates_mm) <= 12.7
    block = np.ix_(centre, centre)
    assert spun.fields[0][block].std() < 0.5 * still.fields[0][block].std()
    # slopes turn with the sample: their mean over a turn is near 0 everywhere but the centre
    assert np.abs(spun.fields[1][block]).mean() < 0.3 * np.abs(still.fields[1][block]).mean()


def test_holder_texture_only_for_the_rigs_own_sample():
    holder = SampleHolder(realism("lab", 2), 2, Optics())
    assert holder.textured and holder.mounting.index == 0 and holder.mounting.rotation_deg == 0.0
    image = holder.relative_image(_lambert, (30.0, 0.0, 20.0, 180.0), (1,))
    assert image.shape == (480, 512) and 0.02 < image[200:280, 200:300].std() < 0.06
    holder.mount_other()
    assert holder.relative_image(_lambert, (30.0, 0.0, 20.0, 180.0), (1,)) is None
    assert holder.tilt() == (0.0, 0.0)
    holder.mount(2)
    assert holder.tilt() != (0.0, 0.0)


def test_no_departures_render_what_the_ideal_rig_rendered():
    """A texture's length is a scale, not a departure: with every magnitude 0 the frames are
    the ideal rig's, bit for bit (no draw of any new random stream)."""
    brdf = functools.partial(gonio.brdf, "oren-nayar", sigma=30.0, rho=0.9)
    frames = []
    for systematics in (None, Systematics(texture_length=5.0)):
        with EmulatedRig(brdf, seed=4, lamp_warm=True, motors_on=True, systematics=systematics) as rig:
            frames.append(rig.scene(0.0, 0.02))
    assert np.array_equal(frames[0], frames[1])


def test_monitor_mismatch_varies_the_sample_not_the_monitor():
    """With a mismatch, successive exposures of the same scene differ by its rms while the
    lamp output they share (the monitor's) does not."""
    brdf = functools.partial(gonio.brdf, "lambert", rho=0.5)
    rig = EmulatedRig(brdf, seed=1, lamp_warm=True, motors_on=True,
                      systematics=Systematics(monitor_mismatch=0.01))
    totals = np.array([rig.scene.photons(0.0, 0.02, 1.0).sum() for _ in range(200)])
    assert totals.std() / totals.mean() == pytest.approx(0.01, rel=0.2)


def test_window_mean_texture_offsets_scatter_between_samples_as_the_texture_says():
    """Over 24 seeds (samples) the window's mean relative radiance of the `lab` texture
    scatters by 0.2-0.35 % at a bright geometry: the 3 % local albedo averaged over a
    window 25 correlation lengths wide (sqrt(2 pi l^2 / A) = 0.1) and the slopes' share."""
    offsets = []
    coverage = footprint_coverage(Optics(), 20.0)
    roi = roi_for_view(INFO, -20.0)
    weights = coverage[roi.y0:roi.y0 + roi.height, roi.x0:roi.x0 + roi.width]
    for seed in range(24):
        holder = SampleHolder(realism("lab", seed), seed, Optics())
        image = holder.relative_image(_lambert, (30.0, 0.0, 20.0, 180.0), (seed,))
        window = image[roi.y0:roi.y0 + roi.height, roi.x0:roi.x0 + roi.width]
        offsets.append(np.sum(weights * window) / np.sum(weights) - 1.0)
    assert 0.0015 < np.std(offsets) < 0.004


def test_a_remount_or_another_object_changes_the_image_at_the_same_axis_positions():
    """The pixel pattern kept for an axis position (Scene.pixel_pattern) belongs to what is
    mounted: after a remount the camera sees another part of the texture, with the reference
    standard in the holder no texture at all, and back on the first mounting the first
    image again."""
    brdf = functools.partial(gonio.brdf, "lambert", rho=0.5)
    rig = EmulatedRig(brdf, seed=4, lamp_warm=True, motors_on=True, systematics=realism("lab", 4))
    roi = roi_for_view(INFO, 0.0)

    positions = tuple(float(p) for p in rig.stage.true_positions(rig.clock.now()))

    def window(image=None) -> np.ndarray:
        image = rig.scene.pixel_pattern(positions) if image is None else image
        return image[roi.y0:roi.y0 + roi.height, roi.x0:roi.x0 + roi.width]

    first = window().copy()
    rig.control.remount(1, handling_s=0.0)
    assert np.abs(window() / first - 1).max() > 1e-3
    rig.control.mount_sample(functools.partial(gonio.brdf, "lambert", rho=0.99), handling_s=0.0)
    theta_i, phi_i, theta_r, _ = rig.scene.angles(positions)
    untextured = rig.scene.coverage(theta_r) * rig.scene.beam_map(theta_r, theta_i, phi_i)
    np.testing.assert_allclose(window(), window(untextured), rtol=1e-12)  # a uniform flat object
    rig.control.remount(0, handling_s=0.0)
    np.testing.assert_allclose(window(), first, rtol=1e-12)
