"""Systematic errors of the emulated rig (drivers/emulator/systematics.py, docs/emulator.md
"Systematic errors"): each switch changes what it should and nothing else."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivers.emulator.ccd import CCDParams, CCDSensor
from drivers.emulator.rig import EmulatedRig
from drivers.emulator.systematics import (
    ANGULAR,
    LAB_FIXED,
    LAB_SPREAD_DEG,
    Systematics,
    beam_profile,
    lab_systematics,
    nonlinear_signal,
    realism,
)
from drivers.rig_geometry import misaligned_angles


def lambert(rho=0.9):
    return lambda ti, pi, tr, pr: np.full(np.broadcast(ti, pi, tr, pr).shape, rho / np.pi)


def ask(rig, device, line):
    return rig.channels[device].process(line).decode("ascii")


def rig_with(systematics=None, brdf=None, seed=5):
    return EmulatedRig(brdf or lambert(), seed=seed, lamp_warm=True, motors_on=True, systematics=systematics)


def move(rig, view, theta_i, phi_i):
    """Camera first, then the lamp (every move here keeps 5 deg of separation that way)."""
    ask(rig, "stage", f"1PA{view};1WS;2PA{theta_i};3PA{phi_i};2WS;3WS")
    assert ask(rig, "stage", "TE?") == "0\r\n"  # no move refused


# ----------------------------------------------------------------------------- geometry
def test_zero_offsets_move_the_true_geometry_by_exactly_the_offsets_and_not_the_readback():
    offsets = dict(view_offset=0.3, theta_i_offset=-0.2, phi_i_offset=0.4)
    ideal, shifted = rig_with(), rig_with(Systematics(**offsets))
    for rig in (ideal, shifted):
        move(rig, -40, 30, 10)
    readback = [ask(r, "stage", "1TP;2TP;3TP") for r in (ideal, shifted)]
    assert readback[0] == readback[1]  # the encoders see nothing of the offsets
    a1, a2, a3 = ideal.control.true_state().positions_deg
    truth = shifted.control.true_state()
    # true angle = mechanical angle + offset: view -40 + 0.3 is the camera at 39.7 deg, phi_r 180
    expected = (a2 - 0.2, a3 + 0.4, -(a1 + 0.3), 180.0)
    assert (truth.theta_i, truth.phi_i, truth.theta_r, truth.phi_r) == pytest.approx(expected, abs=1e-9)
    assert truth.positions_deg == (a1, a2, a3)


def test_a_lamp_offset_through_the_normal_flips_its_azimuth():
    # theta_i = 0.1 with an offset of -0.3: the lamp sits 0.2 deg from the normal on the other side
    ti, pi_, _, _ = misaligned_angles(0.1, 20.0, 10.0, 0.0, theta_i_offset=-0.3)
    assert float(ti) == pytest.approx(0.2, abs=1e-12) and float(pi_) == pytest.approx(-160.0, abs=1e-9)


@pytest.mark.parametrize("tilt_x, tilt_y, phi_i, expected_ti", [(0.5, 0.0, 0.0, 29.5), (0.0, 0.5, 90.0, 29.5),
                                                                 (0.0, -0.5, 90.0, 30.5), (0.5, 0.0, 180.0, 30.5)])
def test_sample_tilt_tips_the_normal_toward_x_and_y(tilt_x, tilt_y, phi_i, expected_ti):
    rig = rig_with(Systematics(tilt_x=tilt_x, tilt_y=tilt_y))
    move(rig, 20, 30, phi_i)
    truth = rig.control.true_state()
    assert truth.theta_i == pytest.approx(expected_ti, abs=0.01)  # repeatability 0.002 deg: 5 sigma
    # the camera in the swing plane (x-z) moves only with tilt_x
    assert truth.theta_r == pytest.approx(20.0 - tilt_x, abs=0.01)


def test_misaligned_angles_keep_the_angle_between_lamp_and_camera():
    # a rotation of the sample frame cannot change the angle between two directions
    rng = np.random.default_rng(1)
    ti, pi_, tr, pr = rng.uniform(0, 85, 50), rng.uniform(-180, 180, 50), rng.uniform(0, 85, 50), rng.uniform(-180, 180, 50)
    tilted = misaligned_angles(ti, pi_, tr, pr, tilt_x=0.7, tilt_y=-0.4)

    def cosine(a, b, c, d):
        a, b, c, d = (np.radians(v) for v in (a, b, c, d))
        return np.sin(a) * np.sin(c) * np.cos(b - d) + np.cos(a) * np.cos(c)

    assert cosine(*tilted) == pytest.approx(cosine(ti, pi_, tr, pr), abs=1e-13)


def test_misaligned_angles_broadcast_walkers_against_points():
    geometry = (np.array([30.0, 45.0, 60.0]), 0.0, np.array([10.0, 20.0, 70.0]), 180.0)
    offsets = np.array([[0.1], [-0.2]])
    batch = misaligned_angles(*geometry, view_offset=offsets, tilt_y=offsets)
    assert batch[0].shape == (2, 3)
    for k in range(2):
        one = misaligned_angles(*geometry, view_offset=float(offsets[k, 0]), tilt_y=float(offsets[k, 0]))
        for a, b in zip(batch, one):
            assert np.array_equal(a[k], b)


def test_an_aligned_rig_reads_the_geometry_it_moved_to():
    rig = rig_with(Systematics(stray_light=1e-3, nonlinearity=1e-3, beam_falloff=0.01))
    move(rig, 35, 45, -20)
    truth = rig.control.true_state()
    a1, a2, a3 = truth.positions_deg
    assert (truth.theta_i, truth.phi_i, truth.theta_r, truth.phi_r) == (a2, a3, a1, 0.0)


# ----------------------------------------------------------------------------- radiometry
def photons(rig, exposure=0.02):
    return rig.scene.photons(rig.clock.now(), exposure, 1.0)


def test_stray_light_adds_the_stated_radiance_over_the_whole_image():
    ideal, stray = rig_with(), rig_with(Systematics(stray_light=2e-3))
    for rig in (ideal, stray):
        move(rig, 30, 45, 0)
    extra = photons(stray) - photons(ideal)
    radiance = 2e-3 * stray.scene.lamp_irradiance_w_m2 / np.pi  # stray_light x E_0 / pi
    expected = radiance * stray.optics.photon_rate_per_radiance() * 0.02
    assert extra == pytest.approx(np.full(extra.shape, expected), rel=1e-12)
    assert stray.control.true_state().stray_radiance_w_m2_sr == pytest.approx(radiance * stray.lamp.output(stray.clock.now()))
    assert ideal.control.true_state().stray_radiance_w_m2_sr == 0.0


def test_stray_light_is_not_in_dark_frames():
    rig = rig_with(Systematics(stray_light=0.05))
    ask(rig, "camera", "SHUT CLOSE;EXP 0.05;ROI 206,190,100,100;ACQ")
    mean = float(ask(rig, "camera", "ROI:STAT?").split(",")[0])
    # as test_emulator_camera.test_shutter_closed_gives_dark_frames: offset + dark current
    assert mean == pytest.approx(100.1, abs=0.1)


def test_nonlinearity_is_the_stated_curve_and_vanishes_at_low_signal():
    full = 3995.0
    s = np.array([10.0, 1000.0, 2000.0, full])
    out = nonlinear_signal(s, 0.01, full)
    assert out == pytest.approx(s * (1 - 0.01 * (s / full) ** 2), rel=1e-15)
    assert out[-1] / s[-1] == pytest.approx(0.99, rel=1e-15)  # the deficit at full scale
    assert 1 - out[0] / s[0] < 1e-7  # 10 DN: 0.01 x (10 / 3995)^2 = 6e-8
    assert np.array_equal(nonlinear_signal(s, 0.0, full), s)


@pytest.mark.parametrize("level", [0.05, 0.5, 0.7])
def test_camera_nonlinearity_in_frames(level):
    params = CCDParams(width=200, height=200, full_well_e=1e6)  # the ADC saturates first
    linear = CCDSensor(params, seed=3, fixed_pattern=False)
    bent = CCDSensor(params, seed=3, fixed_pattern=False, nonlinearity=0.02)
    full = params.max_dn - params.offset_dn
    photons_px = level * full / (params.base_gain_dn_per_e * params.quantum_efficiency)
    a = linear.expose(np.full((200, 200), photons_px), 1e-4, 1.0, np.random.default_rng(7)).frame.mean()
    b = bent.expose(np.full((200, 200), photons_px), 1e-4, 1.0, np.random.default_rng(7)).frame.mean()
    ratio = (b - params.offset_dn) / (a - params.offset_dn)
    # The same noise draws: only the curve and rounding to whole DN (1/sqrt(12) DN per pixel
    # averaged over 4e4 pixels) separate them: 1e-4 of the level covers it.
    assert ratio == pytest.approx(1 - 0.02 * level**2, abs=1e-4 / level)


def test_beam_profile_formula():
    assert float(beam_profile(0.0, 0.0, 40.0, 10.0, 0.05)) == 1.0  # on the axis
    # normal incidence: r is the distance on the sample
    assert float(beam_profile(0.0, 25.4, 0.0, 0.0, 0.05)) == pytest.approx(0.95, rel=1e-15)
    # along the lamp's azimuth the footprint stretches: r = x cos(theta_i); across it not
    assert float(beam_profile(25.4, 0.0, 60.0, 0.0, 0.04)) == pytest.approx(1 - 0.04 * 0.25, rel=1e-14)
    assert float(beam_profile(0.0, 25.4, 60.0, 0.0, 0.04)) == pytest.approx(0.96, rel=1e-14)
    assert float(beam_profile(0.0, 25.4, 60.0, 90.0, 0.04)) == pytest.approx(1 - 0.04 * 0.25, rel=1e-14)


@pytest.mark.parametrize("theta_i", [0.0, 60.0])
def test_beam_nonuniformity_changes_the_window_irradiance_as_documented(theta_i):
    from drivers.rig import roi_for_view
    from drivers.camera import SensorInfo

    falloff = 0.04
    ideal, beam = rig_with(), rig_with(Systematics(beam_falloff=falloff))
    view = -30.0
    for rig in (ideal, beam):
        move(rig, view, theta_i, 0)
    roi = roi_for_view(SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8), view)
    window = (slice(roi.y0, roi.y0 + roi.height), slice(roi.x0, roi.x0 + roi.width))
    ratio = photons(beam)[window].mean() / photons(ideal)[window].mean()
    # The window is the central n_x x n_y pixels, each p / (m cos theta_r) by p / m on the
    # sample (p / m = 0.18288 mm): the mean of x^2 over its pixel centres is
    # (p / (m cos theta_r))^2 (n_x^2 - 1) / 12, and r^2 = x^2 cos^2(theta_i) + y^2 (lamp azimuth 0).
    pixel = 15e-3 * 1828.8 / 150.0
    cos_r = np.cos(np.radians(beam.control.true_state().theta_r))
    mean_x2 = (pixel / cos_r) ** 2 * (roi.width**2 - 1) / 12
    mean_y2 = pixel**2 * (roi.height**2 - 1) / 12
    cos_i = np.cos(np.radians(beam.control.true_state().theta_i))
    expected = 1 - falloff * (mean_x2 * cos_i**2 + mean_y2) / 25.4**2
    # About 1 - falloff (cos^2 theta_i + 1) / 12 for the nominal central half of the sample.
    assert expected == pytest.approx(1 - falloff * (cos_i**2 + 1) / 12, abs=1e-4)
    assert ratio == pytest.approx(expected, rel=1e-12)


def test_ideal_systematics_change_nothing():
    default, explicit = rig_with(), rig_with(Systematics())
    for rig in (default, explicit):
        move(rig, 25, 40, 5)
        ask(rig, "camera", "EXP 0.02;ACQ")
    assert np.array_equal(default.camera.last.frame, explicit.camera.last.frame)
    assert default.systematics.is_ideal


# ----------------------------------------------------------------------------- presets
def test_lab_preset_turns_on_every_documented_error():
    lab = realism("lab", seed=2)
    assert lab == lab_systematics(2) and not lab.is_ideal
    assert all(getattr(lab, name) != 0.0 for name in ANGULAR)
    assert {k: getattr(lab, k) for k in LAB_FIXED} == LAB_FIXED
    assert realism("ideal", seed=2).is_ideal


def test_lab_misalignment_is_a_seeded_draw_with_the_documented_spread():
    draws = np.array([[getattr(lab_systematics(seed), n) for n in ANGULAR] for seed in range(400)])
    spread = np.array([LAB_SPREAD_DEG[n] for n in ANGULAR])
    # 400 draws: the sample sd is within 3 x sd / sqrt(800) = 11 % of the truth, the mean within 3 sd / 20
    assert draws.std(axis=0) == pytest.approx(spread, rel=0.11)
    assert np.all(np.abs(draws.mean(axis=0)) < 3 * spread / 20)
    assert lab_systematics(7) == lab_systematics(7)


def test_realism_overrides_and_bad_specs():
    spec = realism("lab:stray_light=0,tilt_y=-0.25", seed=1)
    assert spec.stray_light == 0.0 and spec.tilt_y == -0.25 and spec.nonlinearity == LAB_FIXED["nonlinearity"]
    assert realism(" ideal : view_offset=0.2 ").view_offset == 0.2
    with pytest.raises(ValueError, match="unknown preset 'field'.*ideal.*lab"):
        realism("field")
    with pytest.raises(ValueError, match="'tilt=1' is not NAME=VALUE"):
        realism("lab:tilt=1")
    with pytest.raises(ValueError, match="stray_light='a lot' is not a number"):
        realism("lab:stray_light=a lot")
    with pytest.raises(ValueError, match="stray_light=-0.1: expected a fraction"):
        realism("ideal:stray_light=-0.1")
    with pytest.raises(ValueError, match="view_offset=45.0 deg"):
        realism("ideal:view_offset=45")
    with pytest.raises(ValueError, match="tilt_x=nan"):
        Systematics(tilt_x=float("nan"))
    with pytest.raises(ValueError, match="Systematics"):
        EmulatedRig(lambert(), systematics={"tilt_x": 0.1})


def test_only_keeps_one_systematic():
    lab = realism("lab", seed=4)
    alone = lab.only("tilt_x", "tilt_y")
    assert (alone.tilt_x, alone.tilt_y) == (lab.tilt_x, lab.tilt_y)
    assert dataclasses.replace(alone, tilt_x=0.0, tilt_y=0.0).is_ideal
    with pytest.raises(ValueError, match="unknown systematic error 'tilt'"):
        lab.only("tilt")
