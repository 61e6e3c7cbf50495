"""One V-cavity of Lambertian facets: Oren & Nayar (1995) section 4.1, eq 10-26, Table 1."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate

from gonio.models.oren_nayar.vcavity import (
    direct_projected_radiance,
    facet_brdf_terms,
    geometric_attenuation,
    interreflected_projected_radiance,
    interreflection_factor,
    interreflection_kernel,
    masked_width,
    projected_radiance,
    shadowed_width,
)

polar = st.floats(0.0, np.pi / 2 - 1e-6)
azimuth = st.floats(-np.pi, 2 * np.pi)
slope = st.floats(0.0, np.pi / 2 - 1e-3)


def _unit(theta, phi):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def test_projected_radiance_eq10_equals_dot_product_form():
    """Eq 10: the trigonometric form equals rho/pi E0 <s,a><v,a>/(<a,n><v,n>)."""
    ti, pi_, tr, pr, ta, pa = 0.7, 0.3, 0.5, 2.0, 0.4, 1.1
    s, v, a = _unit(ti, pi_), _unit(tr, pr), _unit(ta, pa)
    expected = 0.8 / np.pi * 2.0 * (s @ a) * (v @ a) / (a[2] * v[2])
    trig = 0.8 / np.pi * 2.0 * np.cos(ti) * np.cos(ta) * (1 + np.tan(ti) * np.tan(ta) * np.cos(pi_ - pa)) * (
        1 + np.tan(tr) * np.tan(ta) * np.cos(pr - pa))
    got = projected_radiance(ti, pi_, tr, pr, ta, pa, rho=0.8, e0=2.0)
    # pure rounding: both are the same product evaluated differently
    assert got == pytest.approx(expected, rel=1e-13)
    assert got == pytest.approx(trig, rel=1e-13)


def test_gaf_table1_no_masking_or_shadowing():
    """Table 1 row 1: light and view along the normal, every facet fully lit and seen."""
    assert geometric_attenuation(0.0, 0.0, 0.0, 0.0, np.radians(40), 0.3) == 1.0


def test_gaf_eq14_shadowing_of_a_perpendicular_cavity():
    """Eq 14: in-plane source at 80 deg, viewer at the normal, facet tilted 30 deg toward it."""
    ti, ta = np.radians(80), np.radians(30)
    expected = 2 * np.cos(ti) * np.cos(ta) / np.cos(ti - ta)
    assert geometric_attenuation(ti, 0.0, 0.0, 0.0, ta, 0.0) == pytest.approx(expected, rel=1e-14)


def test_gaf_eq14_masking_of_a_perpendicular_cavity():
    """Eq 14 / Table 1 row 2: masking is the same expression with the viewer."""
    tr, ta = np.radians(70), np.radians(35)
    expected = 2 * np.cos(tr) * np.cos(ta) / np.cos(tr - ta)
    assert geometric_attenuation(0.0, 0.0, tr, np.pi, ta, np.pi) == pytest.approx(expected, rel=1e-14)


def test_gaf_is_zero_for_a_facet_turned_away():
    """Eq 15: a facet whose normal points away from the source is not lit at all."""
    assert geometric_attenuation(np.radians(80), 0.0, 0.0, 0.0, np.radians(30), np.pi) == 0.0


@settings(max_examples=200, deadline=None)
@given(polar, azimuth, polar, azimuth, slope, azimuth)
def test_gaf_range_symmetry_and_vector_form(ti, pi_, tr, pr, ta, pa):
    """Eq 15 = eq 16, GAF in [0, 1] and symmetric in source and viewer (section 4.1.1)."""
    gaf = geometric_attenuation(ti, pi_, tr, pr, ta, pa)
    assert 0.0 <= gaf <= 1.0
    assert gaf == geometric_attenuation(tr, pr, ti, pi_, ta, pa)
    s, v, a = _unit(ti, pi_), _unit(tr, pr), _unit(ta, pa)
    if s @ a > 1e-9 and v @ a > 1e-9:
        vector = max(0.0, min(1.0, 2 * s[2] * a[2] / (s @ a), 2 * v[2] * a[2] / (v @ a)))
        # the two forms differ only by rounding of the dot products
        assert gaf == pytest.approx(vector, rel=1e-9, abs=1e-12)


@settings(max_examples=200, deadline=None)
@given(polar, azimuth, st.floats(0.0, 1.5), azimuth, slope, azimuth)
def test_direct_radiance_is_table1(ti, pi_, tr, pr, ta, pa):
    """Table 1: L_rp^1 = GAF x eq 10, and the three closed forms of its rows."""
    got = direct_projected_radiance(ti, pi_, tr, pr, ta, pa, rho=0.7)
    gaf = geometric_attenuation(ti, pi_, tr, pr, ta, pa)
    free = projected_radiance(ti, pi_, tr, pr, ta, pa, rho=0.7)
    assert got >= 0.0
    assert got == pytest.approx(gaf * free, rel=1e-9, abs=1e-12)


def test_table1_masking_and_shadowing_rows():
    """Table 1 rows 2 and 3: rho/pi E0 2<s,a> (masking) and rho/pi E0 2<s,n><v,a>/<v,n>."""
    # masking: source at the normal, viewer grazing on the far side of a steep facet
    ti, pi_, tr, pr, ta, pa = 0.0, 0.0, np.radians(75), np.pi, np.radians(40), np.pi
    s, a = _unit(ti, pi_), _unit(ta, pa)
    assert direct_projected_radiance(ti, pi_, tr, pr, ta, pa) == pytest.approx(2 * (s @ a) / np.pi, rel=1e-12)
    # shadowing: the mirror situation
    ti, pi_, tr, pr = np.radians(75), np.pi, 0.0, 0.0
    s, v = _unit(ti, pi_), _unit(tr, pr)
    expected = 2 * s[2] * (v @ a) / v[2] / np.pi
    assert direct_projected_radiance(ti, pi_, tr, pr, ta, pa) == pytest.approx(expected, rel=1e-12)


@settings(max_examples=100, deadline=None)
@given(polar, azimuth, slope, azimuth)
def test_masked_width_eq20_is_one_minus_masking_gaf(tr, pr, ta, pa):
    """Eq 20 vs eq 13/16: where only masking acts, GAF = 1 - m_v/w."""
    m_v = masked_width(tr, pr, ta, pa)
    assert 0.0 <= m_v <= 1.0
    v, a = _unit(tr, pr), _unit(ta, pa)
    if v @ a > 1e-6:
        gaf = geometric_attenuation(0.0, 0.0, tr, pr, ta, pa)  # source at the normal: no shadow
        assert gaf == pytest.approx(1.0 - m_v, abs=1e-9)


def test_shadowed_width_eq21_mirrors_masked_width():
    """Eq 20-21 are the same construction: the neighbour's shadow seen from the source."""
    ti, pi_, ta, pa = 1.2, 0.4, 0.7, 0.4 + np.pi
    assert shadowed_width(ti, pi_, ta, pa) == pytest.approx(masked_width(ti, pi_, ta, pa + np.pi), rel=1e-14)


@pytest.mark.parametrize(
    "m_v, m_s, theta_a",
    [(0.0, 0.0, 0.3), (0.2, 0.5, 0.6), (0.7, 0.1, 1.0), (0.45, 0.45, 1.3), (0.9, 0.95, 0.2)],
)
def test_interreflection_factor_eq24_equals_kernel_integral_eq19(m_v, m_s, theta_a):
    """Eq 24 (closed form) = double integral of the kernel eq 19 over the lit/seen widths."""
    numeric, error = integrate.dblquad(
        lambda r, t: interreflection_kernel(t, r, theta_a), m_v, 1.0, m_s, 1.0, epsabs=1e-12, epsrel=1e-11
    )
    # quad's own error estimate is ~1e-11; the closed form is exact
    assert interreflection_factor(m_v, m_s, theta_a) == pytest.approx(numeric, rel=1e-8, abs=1e-11)


def test_interreflection_factor_without_masking_is_eq48_limit():
    """Eq 24 at m_v = m^s = 0 is pi (1 - cos theta_a), the value approximation eq 48 keeps."""
    theta_a = np.linspace(0.0, 1.5, 7)
    np.testing.assert_allclose(interreflection_factor(0.0, 0.0, theta_a), np.pi * (1 - np.cos(theta_a)),
                               rtol=1e-13, atol=1e-15)


def test_interreflection_kernel_eq19_is_pi_times_strip_view_factor():
    """Eq 19: for theta_a = 45 deg (a right-angled cavity) the whole neighbour subtends the
    2-D view factor (1 - t / sqrt(1 + t^2)) / 2 from a strip at distance t from the corner
    (differential strip to finite strip: (sin b1 - sin b2)/2, b from the strip's normal)."""
    t = 0.6
    numeric, _ = integrate.quad(lambda r: interreflection_kernel(t, r, np.pi / 4), 0.0, 1.0, epsabs=1e-13)
    view_factor = (1 - t / np.sqrt(1 + t * t)) / 2
    assert numeric == pytest.approx(np.pi * view_factor, rel=1e-10)


def test_interreflected_radiance_eq26():
    """Eq 26 = (rho/pi)^2 E0 <a',s><a,v>/(<a,n><v,n>) IF at a partly shadowed and masked facet."""
    ti, pi_, tr, pr, ta, pa = 1.3, 0.0, 1.2, np.pi, 0.6, np.pi
    s, v, a, b = _unit(ti, pi_), _unit(tr, pr), _unit(ta, pa), _unit(ta, pa + np.pi)
    m_v = masked_width(tr, pr, ta, pa)
    m_s = shadowed_width(ti, pi_, ta, pa)
    assert 0 < m_v < 1 and 0 < m_s < 1
    expected = (0.9 / np.pi) ** 2 * (b @ s) * (a @ v) / (a[2] * v[2]) * interreflection_factor(m_v, m_s, ta)
    assert interreflected_projected_radiance(ti, pi_, tr, pr, ta, pa, rho=0.9) == pytest.approx(expected, rel=1e-12)


def test_no_warnings_at_normal_grazing_and_equal_angles():
    """DESIGN 'Bad input': no numpy warnings at theta = 0, 90 deg and theta_i == theta_r
    (pytest turns RuntimeWarning into errors)."""
    theta = np.array([0.0, np.pi / 2, 1.0, np.pi / 2])
    phi_a = np.linspace(0, 2 * np.pi, 9)[:, None]
    for ta in (0.0, 0.5, np.pi / 2 - 1e-12):
        gaf = geometric_attenuation(theta, 0.0, theta[::-1], np.pi, ta, phi_a)
        assert np.all(np.isfinite(gaf))
        g1, g2 = facet_brdf_terms(np.cos(1.0), np.sin(1.0), np.cos(1.0), np.sin(1.0), np.cos(ta), np.sin(ta),
                                  np.cos(phi_a), np.cos(phi_a))
        assert np.all(np.isfinite(g1)) and np.all(np.isfinite(g2))
    # grazing viewer: the neighbour hides all of a facet facing the viewer (eq 20)
    assert masked_width(np.pi / 2, 0.0, 0.5, 0.0) == pytest.approx(1.0, abs=1e-12)
