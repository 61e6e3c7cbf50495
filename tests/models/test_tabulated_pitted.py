"""``pitted-tabulated`` (gonio.models.tabulated.pitted): the single-scattering factor F1 of
Koenderink et al. (1999), eq 14-15, read from a table of F1 / G (G: the same quadrature
with a coarse rule), combined with the closed-form interreflection (eq 12).

The machinery is checked on a tiny table built here; the shipped table is compared with
the registered ``pitted`` model (deterministic quadrature, ~1e-9) on a modest sample.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import gonio
from gonio.models.pitted.model import pitted_terms
from gonio.models.pitted.quadrature import single_scattering_factor
from gonio.models.tabulated import store
from gonio.models.tabulated.coordinates import geometry_from_coordinates
from gonio.models.tabulated.lookup import TableGrid
from gonio.models.tabulated.pitted_table import (
    DIVISOR_ORDER,
    PSI_MAP,
    PittedTable,
    _fill_undefined,
    build_pitted_table,
    coarse_factor,
)

TINY = TableGrid(4, 4, 4, 4)


@pytest.fixture(scope="module")
def tiny_table() -> PittedTable:
    """A 4x4x4x4 table (256 nodes, well under a second)."""
    return PittedTable(build_pitted_table(TINY, workers=1))


def _random_geometries(rng, n, lowest=0.0):
    return rng.uniform(lowest, 90.0, n), rng.uniform(lowest, 90.0, n), rng.uniform(0.0, 360.0, n)


# ------------------------------------------------------------------ table machinery
def test_tiny_table_reproduces_the_single_scattering_factor_at_its_nodes(tiny_table):
    """Eq 14-15: at the nodes, interpolated F1/G times G is the exact F1."""
    ay, az, at, as_ = TINY.axes()
    y, zeta, t = np.meshgrid(ay.nodes()[1:], az.nodes(), at.nodes(), indexing="ij")
    alpha, beta, dphi = geometry_from_coordinates(y.ravel(), zeta.ravel(), t.ravel())
    for node in (1, 2, 3):
        psi = float(PSI_MAP.value(as_.nodes()[node]))
        exact = pitted_terms(np.degrees(alpha), 0.0, np.degrees(beta), np.degrees(dphi), psi).single_scattering
        # 1e-9: only the coordinate round trip (~1e-15 rad) separates the evaluation from
        # the node; F1/G is smooth, so that moves it by rounding only.  atol 1e-15: where
        # the lit and visible regions vanish both quadratures give 0 or rounding (~1e-23)
        np.testing.assert_allclose(tiny_table.prepare(alpha, 0.0, beta, dphi)(psi), exact, rtol=1e-9, atol=1e-15)


def test_flat_pit_limit_is_lambertian(tiny_table):
    """psi -> 0 (Koenderink et al. section 5): the pit is the flat plane, F1 = 1/pi."""
    flat = tiny_table.prepare(np.radians([10.0, 70.0]), 0.0, np.radians([40.0, 5.0]), np.radians([30.0, 150.0]))(0.0)
    np.testing.assert_allclose(flat * np.pi, 1.0, rtol=1e-12)


def test_coarse_divisor_tracks_the_exact_factor():
    """G (eq 14-15 with DIVISOR_ORDER nodes per panel) is within 1e-3 of F1 for psi = 70 deg,
    so F1/G stays near 1 (the panels end at the same kinks; 16 nodes give ~1e-9)."""
    rng = np.random.default_rng(5)
    ti, tr, dphi = (np.radians(a) for a in _random_geometries(rng, 400))
    exact = single_scattering_factor(ti, tr, dphi, math.radians(70.0))
    coarse = coarse_factor(ti, tr, dphi, 70.0)
    assert DIVISOR_ORDER < 16
    # 1e-4: the 10-node rule's measured maximum is 4e-6 (psi = 69 deg, 2e4 geometries);
    # a divisor of order 4 (3e-2) would fail, and with it the table's accuracy
    np.testing.assert_allclose(coarse, exact, rtol=1e-4, atol=1e-15)


def test_undefined_ratios_are_copied_from_the_nearest_defined_node():
    values = np.arange(2 * 1 * 5, dtype=float).reshape(2, 1, 5)
    defined = np.array([[[True, False, False, True, False]], [[False, False, False, False, False]]])
    filled = _fill_undefined(values, defined)
    np.testing.assert_array_equal(filled[0, 0], [0.0, 0.0, 3.0, 3.0, 3.0])  # ties go to the lower node
    np.testing.assert_array_equal(filled[1, 0], 0.0)  # nothing defined: ratio 1 (log 0)


def test_table_built_with_another_divisor_is_refused():
    arrays = build_pitted_table(TINY, workers=1)
    arrays["divisor_order"] = np.array(DIVISOR_ORDER + 1)
    with pytest.raises(store.TableError, match="divisor_order"):
        PittedTable(arrays)


# ------------------------------------------------------------------ the registered model
def test_model_is_registered_with_the_parameters_of_pitted():
    fast, exact = gonio.models.get("pitted-tabulated"), gonio.models.get("pitted")
    assert [(p.name, p.unit, p.default, p.bounds) for p in fast.params] == [
        (p.name, p.unit, p.default, p.bounds) for p in exact.params
    ]


def test_shipped_table_matches_the_exact_model_on_a_random_sample():
    """Eq 12 + eq 14-15: the BRDF of the table against ``pitted`` (quadrature ~1e-9) on 12
    apertures x 30 geometries with random rho and coverage.  docs/tabulated.md: 99th
    percentile 2.3e-7 and maximum 1.2e-4 on 18000 evaluations; 1e-4 and 1e-3 leave room
    for a different sample, not for a broken table (an order-4 divisor gives 9e-4, 4e-3)."""
    rng = np.random.default_rng(11)
    errors = []
    model, reference = gonio.models.get("pitted-tabulated"), gonio.models.get("pitted")
    for psi in rng.uniform(0.5, 90.0, 12):
        ti, tr, dphi = _random_geometries(rng, 30)
        rho, coverage = rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0)
        kwargs = dict(rho=rho, psi=float(psi), coverage=coverage)
        exact = reference(ti, 0.0, tr, dphi, **kwargs)
        errors.append(np.abs(model(ti, 0.0, tr, dphi, **kwargs) / exact - 1.0))
    errors = np.concatenate(errors)
    assert np.percentile(errors, 99) < 1e-4
    assert errors.max() < 1e-3


def test_shipped_table_near_grazing():
    """Both directions in 85-90 deg (grazing retro-reflection grows like 1/cos, Fig 4):
    measured maximum 2e-6 on 6000 evaluations; 1e-4 leaves room for the sample."""
    rng = np.random.default_rng(12)
    model, reference = gonio.models.get("pitted-tabulated"), gonio.models.get("pitted")
    for psi in (5.0, 45.0, 89.0):
        ti, tr, dphi = _random_geometries(rng, 40, lowest=85.0)
        fast = model(ti, 0.0, tr, dphi, rho=0.5, psi=psi, coverage=1.0)
        exact = reference(ti, 0.0, tr, dphi, rho=0.5, psi=psi, coverage=1.0)
        np.testing.assert_allclose(fast, exact, rtol=1e-4)


def test_fixed_geometry_path_equals_plain_call():
    """Model.at (what fitting uses) and the plain call share one implementation."""
    rng = np.random.default_rng(13)
    ti, tr, dphi = _random_geometries(rng, 50)
    model = gonio.models.get("pitted-tabulated")
    fixed = model.at(ti, 0.0, tr, dphi)
    for psi, rho, coverage in ((30.0, 0.3, 0.5), (80.0, 0.9, 1.0), (30.0, 0.7, 0.2)):
        # 1e-12: the same weights on the same values; only summation order may differ
        np.testing.assert_allclose(fixed(rho=rho, psi=psi, coverage=coverage),
                                   model(ti, 0.0, tr, dphi, rho=rho, psi=psi, coverage=coverage), rtol=1e-12)


angle = st.floats(0.0, 89.9)
azimuth = st.floats(0.0, 360.0)


@settings(max_examples=25, deadline=None)
@given(angle, azimuth, angle, azimuth, st.floats(0.5, 90.0))
def test_reciprocity(ti, pi_, tr, pr, psi):
    """The pitted model is reciprocal (F1 symmetric, F2 constant); the table coordinates are
    symmetric in the two directions and G is the same quadrature, so the swap changes
    rounding only (1e-9)."""
    model = gonio.models.get("pitted-tabulated")
    forward = model(ti, pi_, tr, pr, rho=0.6, psi=psi, coverage=0.7)
    backward = model(tr, pr, ti, pi_, rho=0.6, psi=psi, coverage=0.7)
    np.testing.assert_allclose(forward, backward, rtol=1e-9)


def test_below_horizon_is_zero_and_nan_propagates():
    model = gonio.models.get("pitted-tabulated")
    values = model(np.array([95.0, np.nan, 30.0]), 0.0, 30.0, 180.0, rho=0.5, psi=60.0, coverage=0.5)
    assert values[0] == 0.0 and np.isnan(values[1]) and values[2] > 0.0


def test_bad_aperture_raises_value_error_naming_it():
    with pytest.raises(ValueError, match="psi"):
        gonio.models.get("pitted-tabulated")(30.0, 0.0, 30.0, 0.0, rho=0.5, psi=0.0, coverage=0.5)
