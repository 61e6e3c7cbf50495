"""Every registered model honours the public contract of DESIGN.md.

These tests run over ``gonio.models.available()``, so a model registered later is checked
without anyone writing a test for it: parameter specs, bad input, horizon, NaN, warning-free
special geometries, the fixed-geometry path, non-negativity and reciprocity.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import gonio
from gonio.radiometry import reciprocity_violation

from .conftest import special_geometries

NAMES = gonio.models.available()


def test_public_api_names():
    assert isinstance(gonio.__version__, str) and gonio.__version__
    assert {"lambert", "minnaert", "phong", "lambert+phong"} <= set(NAMES)
    for name in NAMES:
        model = gonio.models.get(name)
        assert model.name == name
        assert model.reference and model.description


@pytest.mark.parametrize("name", NAMES)
def test_param_specs_are_complete(name):
    model = gonio.models.get(name)
    for p in model.params:
        assert p.unit, f"{name}.{p.name} has no unit"
        assert p.description, f"{name}.{p.name} has no description"
        assert p.contains(p.default), f"{name}.{p.name} default {p.default} outside {p.range_text()}"
        assert p.bounds[0] <= p.bounds[1]


@pytest.mark.parametrize("name", NAMES)
def test_out_of_range_parameter_names_parameter_value_and_range(name):
    model = gonio.models.get(name)
    finite = [p for p in model.params if not math.isinf(p.bounds[1])]
    if not finite:
        pytest.skip("no parameter with a finite upper bound")
    p = finite[0]
    bad = p.bounds[1] + 1.0
    with pytest.raises(ValueError) as info:
        gonio.brdf(name, 30, 0, 30, 180, **{p.name: bad})
    message = str(info.value)
    assert p.name in message and f"{bad:g}" in message and p.range_text() in message


def test_unknown_model_and_parameter_are_named():
    with pytest.raises(ValueError, match="unknown model 'oren_nayar'"):
        gonio.brdf("oren_nayar", 30, 0, 30, 0)
    with pytest.raises(ValueError, match="no parameter 'albedo'"):
        gonio.brdf("lambert", 30, 0, 30, 0, albedo=0.5)
    with pytest.raises(ValueError, match="rho = -0.1"):
        gonio.brdf("lambert", 30, 0, 30, 0, rho=-0.1)
    with pytest.raises(ValueError, match="real number"):
        gonio.brdf("lambert", 30, 0, 30, 0, rho="bright")


def test_negative_polar_angle_is_rejected_with_a_hint():
    with pytest.raises(ValueError, match="theta_r = -30 deg is negative"):
        gonio.brdf("lambert", 30, 0, -30, 0)


@pytest.mark.parametrize("name", NAMES)
def test_below_horizon_is_zero_and_nan_propagates(name):
    values = gonio.brdf(name, [95.0, 30.0, np.nan, 30.0, 120.0], 0.0, [30.0, 91.0, 30.0, np.nan, 100.0], 180.0)
    assert values[0] == 0.0 and values[1] == 0.0 and values[4] == 0.0
    assert np.isnan(values[2]) and np.isnan(values[3])


@pytest.mark.parametrize("name", NAMES)
def test_special_geometries_are_finite_non_negative_and_warning_free(name):
    ti, pi_, tr, pr = special_geometries()
    if name.endswith("-exact"):
        ti, pi_, tr, pr = (a[::7] for a in (ti, pi_, tr, pr))  # the reference is slow
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        values = gonio.brdf(name, ti, pi_, tr, pr)
    assert values.shape == ti.shape
    # Minnaert diverges on the horizon by construction (cos^(k-1) with k < 1).
    finite = np.isfinite(values) | ((name == "minnaert") & ((ti == 90) | (tr == 90)))
    assert finite.all(), f"{name}: non-finite values at {np.argwhere(~finite).ravel()[:5]}"
    assert (values[np.isfinite(values)] >= 0.0).all()


@pytest.mark.parametrize("name", NAMES)
def test_broadcasting_and_scalar_shapes(name):
    assert gonio.brdf(name, 30.0, 0.0, 20.0, 180.0).shape == ()
    grid = gonio.brdf(name, np.array([10.0, 40.0])[:, None], 0.0, np.array([0.0, 20.0, 60.0]), 180.0)
    assert grid.shape == (2, 3)


@pytest.mark.parametrize("name", NAMES)
def test_fixed_geometry_path_equals_direct_path(name):
    """Model.at() is the fitting path; it must agree with the plain call (one formula)."""
    model = gonio.models.get(name)
    rng = np.random.default_rng(7)
    n = 12 if name.endswith("-exact") else 200
    ti, tr = rng.uniform(0, 89, n), rng.uniform(0, 89, n)
    pi_, pr = rng.uniform(-180, 180, n), rng.uniform(-180, 180, n)
    tr[:3] = [95.0, 30.0, np.nan]  # horizon and NaN handling on the fast path too
    fixed = model.at(ti, pi_, tr, pr)
    for values in (model.defaults, {p.name: 0.5 * (p.default + p.bounds[0]) if math.isfinite(p.bounds[0]) else p.default for p in model.params}):
        direct = model(ti, pi_, tr, pr, **values)
        np.testing.assert_allclose(fixed(**values), direct, rtol=1e-12, atol=0)
        vector = [values[k] for k in model.param_names]
        np.testing.assert_allclose(fixed.evaluate(vector), direct, rtol=1e-12, atol=0)


angle = st.floats(0.0, 89.5)
azimuth = st.floats(-180.0, 180.0)


@pytest.mark.parametrize("name", [n for n in NAMES if gonio.models.get(n).reciprocal])
@settings(max_examples=25, deadline=None)
@given(ti=angle, pi_=azimuth, tr=angle, pr=azimuth)
def test_reciprocity_of_every_reciprocal_model(name, ti, pi_, tr, pr):
    """Helmholtz reciprocity, f(i, r) = f(r, i) (Forsyth & Ponce section 2.2.2)."""
    violation = reciprocity_violation(name, ti, pi_, tr, pr)
    # 1e-9: exact formulas differ only by rounding; quadrature-based references are
    # symmetric by construction of their quadrature, so the same bound applies.
    assert violation.worst < 1e-9, violation


@pytest.mark.parametrize("name", NAMES)
def test_unchecked_fixed_geometry_path_equals_checked_path(name):
    """FixedGeometryModel.unchecked (fitting's inner loop) is the checked call minus the checks."""
    model = gonio.models.get(name)
    rng = np.random.default_rng(11)
    shape = (2, 3) if name.endswith("-exact") else (4, 25)
    ti, tr = rng.uniform(0, 89, shape), rng.uniform(0, 89, shape)
    pi_, pr = rng.uniform(-180, 180, shape), rng.uniform(-180, 180, shape)
    fixed = model.at(ti, pi_, tr, pr)  # every direction above the horizon: the reshape branch
    params, _ = model.resolve(model.defaults)
    unchecked = fixed.unchecked(**params)
    assert unchecked.shape == shape
    # Same code after validation: equal to the last bit.
    np.testing.assert_array_equal(unchecked, fixed(**params))
    # Against the plain path: rounding only, as in the fixed-geometry test above.
    np.testing.assert_allclose(unchecked, model(ti, pi_, tr, pr, **params), rtol=1e-12, atol=0)


def _walker_values(model, n_walkers: int) -> dict[str, np.ndarray]:
    """Distinct in-range values per walker: from the default towards a bound, shape (W, 1)."""
    out = {}
    for p in model.params:
        lo, hi = p.bounds
        target = 0.5 * (p.default + lo) if math.isfinite(lo) else p.default - 1.0
        if math.isfinite(hi) and p.default == lo:
            target = 0.5 * (lo + hi) if hi - lo < 10 else lo + 1.0
        out[p.name] = np.linspace(p.default, target, n_walkers)[:, None]
    return out


def _walker_geometry(name: str):
    rng = np.random.default_rng(5)
    n = 5 if name.endswith(("-exact", "-numerical")) else 40
    ti, tr = rng.uniform(0, 89, n), rng.uniform(0, 89, n)
    pi_, pr = rng.uniform(-180, 180, n), rng.uniform(-180, 180, n)
    tr[:2] = [95.0, np.nan]  # horizon and NaN rules with array parameters too
    return ti, pi_, tr, pr


@pytest.mark.parametrize("name", NAMES)
def test_array_parameters_equal_one_call_per_value(name):
    """Parameters broadcast like angles: W walkers x N geometries in one call, on the plain
    path and the fixed-geometry path, equal the W scalar calls."""
    model = gonio.models.get(name)
    walkers = _walker_values(model, 3)
    geometry = _walker_geometry(name)
    one_by_one = np.stack([model(*geometry, **{k: float(v[w, 0]) for k, v in walkers.items()}) for w in range(3)])
    assert np.isnan(one_by_one[:, 1]).all() and (one_by_one[:, 0] == 0).all()
    np.testing.assert_allclose(model(*geometry, **walkers), one_by_one, rtol=1e-12, atol=0)
    fixed = model.at(*geometry)
    np.testing.assert_allclose(fixed(**walkers), one_by_one, rtol=1e-12, atol=0)
    params, _ = model.resolve(walkers)
    np.testing.assert_allclose(fixed.unchecked(**params), one_by_one, rtol=1e-12, atol=0)


@pytest.mark.parametrize("name", NAMES)
def test_array_parameters_along_the_geometry(name):
    """A parameter that varies point by point (an albedo map) on both paths."""
    model = gonio.models.get(name)
    geometry = _walker_geometry(name)
    n = geometry[0].size
    first = model.params[0]
    lo = first.bounds[0] if math.isfinite(first.bounds[0]) else first.default - 1.0
    values = np.linspace(first.default, 0.5 * (first.default + lo), n)
    point = np.array([model(*(g[j] for g in geometry), **{first.name: float(values[j])}) for j in range(n)])
    np.testing.assert_allclose(model(*geometry, **{first.name: values}), point, rtol=1e-12, atol=0, equal_nan=True)
    np.testing.assert_allclose(model.at(*geometry)(**{first.name: values}), point, rtol=1e-12, atol=0, equal_nan=True)


@pytest.mark.parametrize("name", NAMES)
def test_array_parameter_out_of_range_names_the_element(name):
    model = gonio.models.get(name)
    p = next((q for q in model.params if math.isfinite(q.bounds[1])), None)
    if p is None:
        pytest.skip("no parameter with a finite upper bound")
    values = np.full((2, 3), p.default)
    values[1, 2] = p.bounds[1] + 1.0
    with pytest.raises(ValueError, match=rf"{p.name}\[1, 2\] = .* outside its valid range"):
        model(30.0, 0.0, 20.0, 180.0, **{p.name: values})
    with pytest.raises(ValueError, match=rf"{p.name}\[1, 2\]"):
        model.at(30.0, 0.0, 20.0, 180.0)(**{p.name: values})
    with pytest.raises(ValueError, match="must be a real number"):
        model(30.0, 0.0, 20.0, 180.0, **{p.name: ["a", "b"]})


@pytest.mark.parametrize("name", ["lambert", "oren-nayar", "oren-nayar-qualitative", "oren-nayar-tabulated"])
def test_array_parameters_through_the_apertures(name):
    """The aperture average (what rig fits evaluate) broadcasts parameters too."""
    from gonio.instrument import aperture_averaged

    model = aperture_averaged(name)
    walkers = _walker_values(model, 3)
    geometry = _walker_geometry(name)
    one_by_one = np.stack([model(*geometry, **{k: float(v[w, 0]) for k, v in walkers.items()}) for w in range(3)])
    np.testing.assert_allclose(model.at(*geometry)(**walkers), one_by_one, rtol=1e-12, atol=0)
    np.testing.assert_allclose(model(*geometry, **walkers), one_by_one, rtol=1e-12, atol=0)


def test_degree_conversion_is_numpys():
    """The hot path multiplies by pi/180: bit for bit what np.radians gives."""
    from gonio.models._core import _radians

    x = np.random.default_rng(2).uniform(-720.0, 720.0, 10_000)
    np.testing.assert_array_equal(_radians(x)[0], np.radians(x))


@pytest.mark.parametrize("name", NAMES)
def test_large_inputs_evaluated_in_chunks_equal_one_pass(name, monkeypatch):
    """The plain call evaluates large inputs CHUNK geometries at a time (cache-sized);
    the values, the horizon and NaN rules and the shape equal those of one pass."""
    import gonio.models._core as core

    model = gonio.models.get(name)
    rng = np.random.default_rng(3)
    shape = (3, 7) if name.endswith(("-exact", "-numerical")) else (6, 25)
    ti, tr = rng.uniform(0, 89, shape), rng.uniform(0, 89, shape)
    pi_, pr = rng.uniform(-180, 180, shape), rng.uniform(-180, 180, shape)
    tr[0, 0], tr[-1, -1], ti[1, 3] = 95.0, np.nan, 90.0
    one_pass = model(ti, pi_, tr, pr)
    monkeypatch.setattr(core, "CHUNK", 4)
    chunked = model(ti, pi_, tr, pr)
    assert chunked.shape == shape
    np.testing.assert_array_equal(chunked, one_pass)
