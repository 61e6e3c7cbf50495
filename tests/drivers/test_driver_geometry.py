"""Rig geometry (docs/protocol.md "Geometry of the rig") and the optics-derived ROI.

Pure functions, no instrument: axis conventions, camera/lamp separation, move planning
under the controller's end-point interlock, and the ROI that keeps the same sample area.
"""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.camera import Roi, SensorInfo
from drivers.errors import GeometryError
from drivers.rig import roi_for_view, roi_problem, sample_image_size
from drivers.rig_geometry import (
    SEPARATION_MARGIN,
    angular_separation,
    camera_direction,
    check_targets,
    plan_moves,
    separation_of_axes,
)

LIMITS = {1: (-90.0, 90.0), 2: (0.0, 90.0), 3: (-180.0, 180.0)}
INFO = SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8)  # SENS:INFO? of docs/protocol.md


def test_camera_direction_sign_convention():
    # Protocol: camera at polar |a1|, azimuth 0 for a1 >= 0, 180 for a1 < 0.
    assert camera_direction(30.0) == (30.0, 0.0)
    assert camera_direction(-30.0) == (30.0, 180.0)
    assert camera_direction(0.0) == (0.0, 0.0)


def test_in_plane_separation_is_difference_of_signed_angles():
    # Lamp at phi_i = 0: in the plane of incidence the separation is |view - theta_i|
    # on the lamp's side and view + theta_i (as |view|) on the far side.
    assert separation_of_axes({1: 40.0, 2: 30.0, 3: 0.0}) == pytest.approx(10.0, abs=1e-12)
    assert separation_of_axes({1: -40.0, 2: 30.0, 3: 0.0}) == pytest.approx(70.0, abs=1e-12)
    assert separation_of_axes({1: 40.0, 2: 30.0, 3: 180.0}) == pytest.approx(70.0, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.floats(0, 90), st.floats(-180, 180), st.floats(0, 90), st.floats(-180, 180))
def test_separation_matches_spherical_law_of_cosines(ti, pi, tr, pr):
    # cos(sep) = cos ti cos tr + sin ti sin tr cos(pi - pr); compared where arccos is
    # well conditioned (the atan2 form is used precisely because arccos is not near 0).
    c = (math.cos(math.radians(ti)) * math.cos(math.radians(tr))
         + math.sin(math.radians(ti)) * math.sin(math.radians(tr)) * math.cos(math.radians(pi - pr)))
    sep = float(angular_separation(ti, pi, tr, pr))
    assert 0.0 <= sep <= 180.0
    if abs(c) < 0.999:
        assert sep == pytest.approx(math.degrees(math.acos(c)), abs=1e-9)
    assert sep == pytest.approx(float(angular_separation(tr, pr, ti, pi)), abs=1e-12)


def test_separation_of_nearly_parallel_directions_is_accurate():
    # 1e-6 deg apart: arccos(dot) would give ~1e-6 +- 1e-6 from rounding; atan2 is exact.
    assert float(angular_separation(30.0, 0.0, 30.0 + 1e-6, 0.0)) == pytest.approx(1e-6, rel=1e-6)


def test_check_targets_reports_limits_and_separation():
    assert check_targets({1: -20.0, 2: 30.0, 3: 0.0}, LIMITS, 5.0) is None
    reason = check_targets({1: 95.0, 2: 30.0, 3: 0.0}, LIMITS, 5.0)
    assert "view" in reason and "95" in reason and "[-90, 90]" in reason
    reason = check_targets({1: 10.0, 2: -1.0, 3: 0.0}, LIMITS, 5.0)
    assert "theta_i" in reason and "[0, 90]" in reason
    reason = check_targets({1: 32.0, 2: 30.0, 3: 0.0}, LIMITS, 5.0)
    assert "2.00 deg apart" in reason and "minimum separation, 5 deg" in reason
    assert "not a finite" in check_targets({1: math.nan, 2: 30.0, 3: 0.0}, LIMITS, 5.0)


def _plan_is_safe(start, plan, min_sep):
    targets = dict(start)
    for stage in plan.stages:
        for axis, value in stage:
            targets[axis] = value
            if float(separation_of_axes(targets)) < min_sep:
                return False
    return True


angles = st.tuples(st.floats(-90, 90), st.floats(0, 90), st.floats(-180, 180))


@settings(max_examples=80, deadline=None)
@given(angles, angles)
def test_planned_moves_never_command_a_refused_end_point(a, b):
    # The controller refuses a move whose end point (with the other axes' targets) is
    # closer than the minimum (error x29); every prefix of the plan must be allowed.
    start = dict(zip((1, 2, 3), a))
    end = dict(zip((1, 2, 3), b))
    if separation_of_axes(start) < 5.0 + SEPARATION_MARGIN or separation_of_axes(end) < 5.0:
        return
    plan = plan_moves(start, end, 5.0, LIMITS)
    assert plan is not None
    assert _plan_is_safe(start, plan, 5.0)
    final = dict(start)
    for stage in plan.stages:
        final.update(dict(stage))
    # The planner skips axis moves below 1e-9 deg (trig round-off of the same nominal
    # position; re-commanding them would cost a real move), so compare at that dead-band.
    assert all(final[k] == pytest.approx(end[k], abs=1e-9) for k in (1, 2, 3))


def test_swapping_sides_in_plane_needs_a_waypoint():
    # Camera at 30, lamp at 50 -> camera 50, lamp 30: either single move first puts them
    # on top of each other, so the plan detours through one waypoint.
    plan = plan_moves({1: 30.0, 2: 50.0, 3: 0.0}, {1: 50.0, 2: 30.0, 3: 0.0}, 5.0, LIMITS)
    assert len(plan.stages) == 2
    assert _plan_is_safe({1: 30.0, 2: 50.0, 3: 0.0}, plan, 5.0)


def test_sample_image_size_matches_protocol_numbers():
    # docs/protocol.md: s m / p = 50.8 mm * (150 / 1828.8) / 15 um = 277.78 pixels
    # ("about 277.9" there), times cos(theta_r) along x.
    w, h = sample_image_size(INFO, 0.0)
    assert w == pytest.approx(277.78, abs=0.01) and h == pytest.approx(277.78, abs=0.01)
    w60, _ = sample_image_size(INFO, -60.0)
    assert w60 == pytest.approx(0.5 * w, rel=1e-12)


@pytest.mark.parametrize("view", [-80.0, -60.0, -30.0, 0.0, 15.0, 45.0, 75.0])
def test_roi_covers_the_same_sample_area_at_every_view(view):
    roi = roi_for_view(INFO, view)
    w0, h0 = sample_image_size(INFO, 0.0)
    cos = math.cos(math.radians(view))
    # Sample-plane extent of the ROI: width / cos(theta_r) along the swing plane. Even
    # pixel sizes quantise the width by up to 1 pixel on each side of the exact value,
    # i.e. a relative error of 2 / (width) pixels.
    assert roi.width / cos == pytest.approx(0.5 * w0, abs=2.0 / cos)
    assert roi.height == pytest.approx(0.5 * h0, abs=2.0)
    # Centred on the image centre (256, 240) where the sample centre is imaged.
    assert roi.x0 + roi.width / 2 == 256.0 and roi.y0 + roi.height / 2 == 240.0
    assert roi_problem(INFO, view, roi) is None


def test_roi_is_refused_off_the_sample_and_at_grazing_views():
    big = Roi(118, 102, 276, 276)  # inside the 277.8-pixel image, but not 2 pixels in
    assert roi_problem(INFO, 0.0, big, margin_px=0.0) is None
    assert "not inside the sample's image" in roi_problem(INFO, 0.0, big, margin_px=2.0)
    with pytest.raises(GeometryError, match="not inside"):
        roi_for_view(INFO, 0.0, fraction=1.0)
    with pytest.raises(GeometryError, match="grazing|not inside"):
        roi_for_view(INFO, 89.9)
    with pytest.raises(ValueError, match="fraction"):
        roi_for_view(INFO, 0.0, fraction=0.0)
