"""Direction conventions of gonio.geometry (DESIGN.md: degrees, signed in-plane angle)."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio import geometry


@settings(max_examples=50, deadline=None)
@given(theta=st.floats(0.5, 179.5), phi=st.floats(-179.0, 179.0))
def test_direction_round_trip(theta, phi):
    t, p = geometry.angles(geometry.direction(theta, phi))
    # 1e-9 deg: a handful of ulps of the trig functions; the azimuth is only defined off
    # the pole, hence theta away from 0 and 180.
    assert abs(t - theta) < 1e-9 and abs(p - phi) < 1e-9


def test_direction_is_unit_and_normal_is_z():
    v = geometry.direction(np.linspace(0, 90, 7), np.linspace(-180, 180, 7))
    np.testing.assert_allclose(np.linalg.norm(v, axis=-1), 1.0, rtol=1e-15)
    np.testing.assert_allclose(geometry.direction(0.0, 37.0), [0.0, 0.0, 1.0], atol=1e-16)


def test_azimuth_difference_wraps_to_half_open_interval():
    d = geometry.azimuth_difference([0, 0, 350, 10, 0], [180, -180, 10, 350, 540])
    np.testing.assert_allclose(d, [180, 180, 20, -20, 180])


def test_signed_viewing_angle_positive_on_source_side():
    # backward scattering (viewer on the source side) is positive, forward is negative
    assert geometry.signed_viewing_angle(30.0, 0.0, phi_i=0.0) == 30.0
    assert geometry.signed_viewing_angle(30.0, 180.0, phi_i=0.0) == -30.0
    assert geometry.signed_viewing_angle(30.0, 100.0, phi_i=90.0) == 30.0


def test_in_plane_angles_inverts_signed_viewing_angle():
    view = np.array([-80.0, -10.0, 0.0, 25.0, 89.0])
    ti, pi_, tr, pr = geometry.in_plane_angles(45.0, view, phi_i=30.0)
    np.testing.assert_allclose(geometry.signed_viewing_angle(tr, pr, pi_), view)
    np.testing.assert_allclose(tr, np.abs(view))


def test_half_vector_of_specular_pair_is_the_normal():
    th, _ = geometry.half_vector(40.0, 0.0, 40.0, 180.0)
    assert abs(th) < 1e-12
    th, ph = geometry.half_vector(60.0, 0.0, 0.0, 0.0)
    assert abs(th - 30.0) < 1e-12 and abs(ph) < 1e-12


def test_angle_between_is_accurate_for_nearby_directions():
    assert abs(geometry.angle_between(30.0, 0.0, 30.0 + 1e-7, 0.0) - 1e-7) < 1e-13
    assert abs(geometry.angle_between(0.0, 0.0, 90.0, 123.0) - 90.0) < 1e-12
