"""The fast plain calls of a model: the small call in plain Python (``Model.point``, at most
``POINT_MAX`` geometries) and the allocation-free call in chunks (``Model.fill``).

Both must give the values of the general path (``prepare`` through
``Model._call_scalar_params`` and ``Model._call_in_chunks``) with its horizon, NaN and
broadcasting rules, and leave every error to it, with the same messages.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import gonio
import gonio.models._core as core
from gonio.models._core import _as_angles

FAST = [name for name in gonio.models.available()
        if gonio.models.get(name).point is not None or gonio.models.get(name).fill is not None]
PARAMS = [
    {"rho": 0.9, "sigma": 30.0},
    {"rho": 0.3, "sigma": 85.0, "ir_weight": 0.0},   # eq 33's floor at 0 acts (forward grazing)
    {"rho": 1.0, "sigma": 90.0, "ir_weight": 1.0},
    {"rho": 0.5, "sigma": 0.0},                      # rho/pi exactly
    {"rho": 0.0, "sigma": 20.0, "ir_weight": 0.5},
]


@pytest.fixture(autouse=True)
def numpy_paths(monkeypatch):
    """The numpy paths only: the compiled paths have their own tests."""
    monkeypatch.setattr(core, "COMPILED_AFTER", math.inf)


def _reference(model, geometry, values) -> np.ndarray:
    """The general path's values (the models' ``prepare``, all geometries at once)."""
    params, options = model.resolve(values)
    return model._call_scalar_params(*_as_angles(*geometry), params, options)


def _geometries(n: int, seed: int = 0) -> tuple[np.ndarray, ...]:
    """Random geometries [deg] with the horizon, NaN, the normal, theta_i = theta_r and
    the azimuth differences where cos(dphi) is 0 or -1 placed among them."""
    rng = np.random.default_rng(seed)
    ti, tr = rng.uniform(0.0, 90.0, n), rng.uniform(0.0, 90.0, n)
    pi_, pr = rng.uniform(-360.0, 360.0, n), rng.uniform(-360.0, 360.0, n)
    ti[1], tr[2], pi_[3], pr[4] = 95.0, np.nan, np.nan, np.nan   # below the horizon, NaN
    ti[5] = tr[5] = 90.0                                          # both at the horizon
    ti[6], tr[7] = 0.0, 0.0                                       # the normal
    tr[8] = ti[8]
    pr[9], pr[10], pr[11] = pi_[9] + 90.0, pi_[10] + 180.0, pi_[11] - 90.0
    return ti, pi_, tr, pr


@pytest.mark.parametrize("name", FAST)
@pytest.mark.parametrize("values", PARAMS)
def test_small_call_equals_the_general_path(name, values):
    """Every size up to POINT_MAX, float64 arrays of one shape: equal to 1e-14 (relative
    to the largest value; the C library's cos, sin and tan against numpy's path of
    half-angle tangents), the same NaN and the same zeros."""
    model = gonio.models.get(name)
    values = {k: v for k, v in values.items() if k in model.param_names}
    geometry = _geometries(core.POINT_MAX)
    for n in (12, core.POINT_MAX):
        part = tuple(a[:n] for a in geometry)
        fast, reference = model(*part, **values), _reference(model, part, values)
        np.testing.assert_array_equal(np.isnan(fast), np.isnan(reference))
        np.testing.assert_array_equal(fast == 0.0, reference == 0.0)
        np.testing.assert_allclose(fast, reference, rtol=1e-14, atol=1e-14 * np.nanmax(reference), equal_nan=True)


@pytest.mark.parametrize("name", FAST)
def test_small_call_many_random_geometries(name):
    """2000 random geometries one at a time (scalar angles) against the general path."""
    model = gonio.models.get(name)
    ti, pi_, tr, pr = (a.tolist() for a in _geometries(2000, seed=1))
    fast = np.array([model(*g, rho=0.7, sigma=40.0) for g in zip(ti, pi_, tr, pr)])
    reference = _reference(model, (ti, pi_, tr, pr), {"rho": 0.7, "sigma": 40.0})
    np.testing.assert_allclose(fast, reference, rtol=1e-14, atol=1e-14 * np.nanmax(reference), equal_nan=True)


def test_small_call_is_taken_up_to_point_max_only():
    """A spy on ``point``: called for calls of 1 and POINT_MAX geometries, not for
    POINT_MAX + 1, nor for lists, integer arrays, array parameters or mixed shapes."""
    calls = []

    def spy(params, options):
        calls.append(params)
        return gonio.models.get("oren-nayar").point(params, options)

    model = dataclasses.replace(gonio.models.get("oren-nayar"), point=spy)
    theta = np.full(core.POINT_MAX, 30.0)
    model(30.0, 0.0, 40, np.float64(180.0), rho=0.5, sigma=10)
    model(theta, 0.0, theta, 180.0)
    assert len(calls) == 2
    assert calls[0] == {"rho": 0.5, "sigma": 10.0, "ir_weight": 1.0}
    model(np.full(core.POINT_MAX + 1, 30.0), 0.0, 30.0, 180.0)
    model([30.0, 40.0], 0.0, 30.0, 180.0)
    model(np.array([30, 40]), 0.0, 30.0, 180.0)
    model(theta, 0.0, theta, 180.0, rho=np.full(core.POINT_MAX, 0.5))
    model(theta[:, None], 0.0, theta[None, :3], 180.0)
    assert len(calls) == 2


@pytest.mark.parametrize("name", FAST)
def test_small_call_shapes_and_fallbacks(name):
    """Scalars give a 0-d array, arrays their shape, scalars mixed with arrays broadcast;
    what the small call leaves to the general path (lists, integer and float32 arrays,
    mixed shapes, array parameters, infinite azimuths) gives the general path's values."""
    model = gonio.models.get(name)
    scalar = model(30.0, 0.0, 40.0, 180.0, rho=0.5)
    assert isinstance(scalar, np.ndarray) and scalar.shape == () and scalar.dtype == np.float64
    grid = np.linspace(0.0, 80.0, 12).reshape(3, 4)
    out = model(grid, 10.0, grid.T.copy().reshape(3, 4), 200)
    assert out.shape == (3, 4)
    np.testing.assert_allclose(out, _reference(model, (grid, 10.0, grid.T.copy().reshape(3, 4), 200), {}),
                               rtol=1e-14, atol=1e-16)
    reference = model(np.array([30.0, 50.0]), 0.0, np.array([40.0, 10.0]), 180.0)
    for angles in (([30.0, 50.0], 0, [40.0, 10.0], 180),
                   (np.array([30, 50]), 0.0, np.array([40, 10]), 180.0),
                   (np.array([30.0, 50.0], np.float32), 0.0, np.array([40.0, 10.0], np.float32), 180.0)):
        np.testing.assert_allclose(model(*angles), reference, rtol=1e-14)
    np.testing.assert_allclose(model(np.array([30.0, 50.0]), 0.0, np.array([40.0, 10.0]), 180.0,
                                     rho=np.array([0.8, 0.8])), reference, rtol=1e-14)
    column = model(np.array([[30.0], [50.0]]), 0.0, np.array([40.0, 10.0, 20.0]), 180.0)
    assert column.shape == (2, 3)
    with np.errstate(invalid="ignore"):
        infinite = (30.0, math.inf, 40.0, 180.0)
        assert np.isnan(model(*infinite)) and np.isnan(_reference(model, infinite, {}))


@pytest.mark.parametrize("name", FAST)
def test_small_call_horizon_and_nan(name):
    model = gonio.models.get(name)
    assert model(95.0, 0.0, 30.0, 0.0) == 0.0
    assert model(30.0, 0.0, 90.0 + 1e-9, 0.0) == 0.0
    assert model(90.0, 0.0, 90.0, 180.0) >= 0.0
    for angles in ((math.nan, 0.0, 30.0, 0.0), (30.0, math.nan, 30.0, 0.0),
                   (30.0, 0.0, math.nan, 0.0), (30.0, 0.0, 30.0, math.nan), (95.0, 0.0, 30.0, math.nan)):
        assert np.isnan(model(*angles))
    out = model(np.array([30.0, 95.0, np.nan]), 0.0, 40.0, 180.0)
    assert out[0] > 0.0 and out[1] == 0.0 and np.isnan(out[2])


def _message(call) -> str:
    with pytest.raises(ValueError) as error:
        call()
    return str(error.value)


@pytest.mark.parametrize("values", [
    {"sigma": 91.0}, {"sigma": -1.0}, {"rho": math.nan}, {"rho": 1.5}, {"sigm": 30.0},
    {"ir_weight": "0.5x"}, {"rho": True, "sigma": 91},
])
def test_small_call_errors_are_those_of_the_general_path(values):
    """Bad parameters raise on small calls with the general path's message (the same call
    on POINT_MAX + 1 geometries goes through the general path)."""
    big = np.full(core.POINT_MAX + 1, 30.0)
    small = _message(lambda: gonio.brdf("oren-nayar", 30.0, 0.0, 40.0, 180.0, **values))
    general = _message(lambda: gonio.brdf("oren-nayar", big, 0.0, big, 180.0, **values))
    assert small == general
    assert ("valid range" in small) or ("no parameter" in small) or ("real number" in small)


def test_small_call_negative_angles_and_unknown_model():
    for angles in ((-1.0, 0.0, 30.0, 0.0), (30.0, 0.0, -1e-9, 0.0), (95.0, 0.0, -1.0, 0.0),
                   (np.array([30.0, -2.0]), 0.0, 30.0, 0.0), (np.array([np.nan, -2.0]), 0.0, 30.0, 0.0)):
        assert "is negative" in _message(lambda: gonio.brdf("oren-nayar", *angles))
    assert "did you mean 'oren-nayar'" in _message(lambda: gonio.brdf("oren-nayer", 30.0, 0.0, 30.0, 0.0))
    assert "has no parameter 'sigm'" in _message(lambda: gonio.brdf("oren-nayar", 30.0, 0.0, 30.0, 0.0, sigm=3))


@pytest.mark.parametrize("name", FAST)
@pytest.mark.parametrize("values", PARAMS[:3])
def test_call_in_chunks_without_allocation_equals_the_general_path(name, values, monkeypatch):
    """``fill`` on chunks of all-valid geometries, the general path on chunks with a NaN or
    a geometry below the horizon: bit for bit the values of ``_call_in_chunks`` (the same
    operations in the same order), over several chunks and a short last one."""
    model = gonio.models.get(name)
    values = {k: v for k, v in values.items() if k in model.param_names}
    monkeypatch.setattr(core, "CHUNK", 64)
    monkeypatch.setattr(core, "FILL_CHUNK", 64)
    rng = np.random.default_rng(4)
    n = 64 * 5 + 17
    ti, tr = rng.uniform(0.0, 90.0, n), rng.uniform(0.0, 90.0, n)
    pi_, pr = rng.uniform(-180.0, 180.0, n), rng.uniform(-180.0, 180.0, n)
    ti[70], pr[200], tr[330] = 100.0, np.nan, np.inf   # chunks 1, 3 and the last
    pi_[150] = np.inf                                  # chunk 2: an infinite azimuth
    geometry = (ti.reshape(-1, 1), pi_.reshape(-1, 1), tr.reshape(-1, 1), pr.reshape(-1, 1))
    params, options = model.resolve(values)
    with np.errstate(invalid="ignore"):
        reference = model._call_in_chunks(*_as_angles(*geometry), params, options)
        out = model(*geometry, **values)
    assert out.shape == (n, 1)
    np.testing.assert_array_equal(out, reference)
    assert np.isnan(out[200, 0]) and out[70, 0] == 0.0 and out[330, 0] == 0.0 and np.isnan(out[150, 0])


@pytest.mark.parametrize("name", FAST)
def test_fill_allocates_its_temporaries_once(name, monkeypatch):
    """The large call builds its ``fill`` (and its temporaries) once per call, not per chunk."""
    model = gonio.models.get(name)
    built = []

    def counting(params, options, size):
        built.append(size)
        return model.fill(params, options, size)

    monkeypatch.setattr(core, "CHUNK", 64)
    monkeypatch.setattr(core, "FILL_CHUNK", 64)
    spied = dataclasses.replace(model, fill=counting)
    theta = np.linspace(0.0, 89.0, 64 * 3 + 5)
    np.testing.assert_array_equal(spied(theta, 0.0, theta[::-1], 180.0), model(theta, 0.0, theta[::-1], 180.0))
    assert built == [64]
