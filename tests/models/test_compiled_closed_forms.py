"""The compiled plain calls of the closed forms equal their numpy reference path.

A model with a compiled path (``Model.compiled``, :mod:`gonio.models._compiled`) uses it
for plain calls of at least ``COMPILED_MIN`` geometries once a process has evaluated
``COMPILED_AFTER`` geometries with numpy; below that, and for the fixed-geometry path of
fitting, the numpy formula runs.  DESIGN: one implementation per
formula, a faster path tested equal to the reference.  The compiled loops repeat the
numpy operations in the same order and take their tangents from the same ``numpy.tan``,
so the values are expected bit for bit equal; the assertion allows 4 ulp (rtol 1e-15) in
case a compiler contracts a multiply-add, far below the 1e-12 the closed forms are held
to against the C loops of benchmarks/closed_form_speed.py.
"""
from __future__ import annotations

import numpy as np
import pytest

import gonio
from gonio.models._core import COMPILED_MIN, _as_angles

#: (model, parameters and options) of every compiled path, with its parameter extremes.
CASES = [
    ("oren-nayar", {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0}),
    ("oren-nayar", {"rho": 0.2, "sigma": 90.0, "ir_weight": 0.0}),   # the floor at 0 acts
    ("oren-nayar", {"rho": 1.0, "sigma": 0.0, "ir_weight": 0.5}),    # Lambert
    ("oren-nayar-qualitative", {"rho": 0.9, "sigma": 30.0}),
    ("oren-nayar-qualitative", {"rho": 0.5, "sigma": 60.0, "variant": "footnote11"}),
    ("wolff", {"rho": 0.8, "n": 1.5}),
    ("wolff", {"rho": 0.3, "n": 1.0001}),                            # nearly no interface
    ("wolff", {"n": 2.4, "omega": 0.7, "scale": "physical"}),
    ("wolff", {"rho": 0.8, "n": 1.33, "fresnel": "polynomial"}),
    ("kvd", {"a_0_0_0": 1.6, "a_1_1_1": 0.1, "a_2_0_0": -0.2, "a_2_2_0": 0.05, "a_2_2_2": 0.03}),
    ("kvd", {}),                                                     # Lambert 0.8
]

#: The KvD paths take their cosines from different functions (numpy's cos there, the
#: half-angle tangent here), which differ by an ulp; sqrt(1 - cos theta) of the radial
#: polynomials amplifies that near the normal (d sqrt(q) = dq / 2 sqrt(q)) to some 1e-14
#: absolute for an order-2 series of values up to 0.4. Each path is as close to the exact
#: value (test_kvd_paths_against_extended_precision), so the paths are held to each other
#: at 5e-14 relative to the largest value.
KVD_TOLERANCE = 5e-14


def _geometries(n: int = COMPILED_MIN + 1234) -> tuple[np.ndarray, ...]:
    """Random geometries with the special cases in blocks: NaN in each angle, the horizon
    exactly and beyond, the normal, theta_i = theta_r, and the azimuths where cos(dphi)
    is 0 or -1 (where C2 switches branch and |cos dphi| folds)."""
    rng = np.random.default_rng(11)
    ti, tr = rng.uniform(0.0, 95.0, n), rng.uniform(0.0, 95.0, n)
    pi_, pr = rng.uniform(-180.0, 180.0, n), rng.uniform(-540.0, 540.0, n)
    ti[0:40], pi_[40:80], tr[80:120], pr[120:160] = np.nan, np.nan, np.nan, np.nan
    tr[160:200], ti[200:240] = 90.0, 90.0
    ti[240:280] = tr[240:280] = 90.0
    ti[280:320] = 0.0
    ti[320:360] = tr[320:360] = 0.0
    tr[360:400] = ti[360:400]
    pr[400:440] = pi_[400:440] + 90.0
    pr[440:480] = pi_[440:480] - 180.0
    pr[480:520] = pi_[480:520]
    return ti, pi_, tr, pr


@pytest.fixture(autouse=True)
def compiled_paths_due(monkeypatch):
    """The compiled paths at once (a process normally takes them only after
    COMPILED_AFTER geometries evaluated with numpy)."""
    import gonio.models._core as core

    monkeypatch.setattr(core, "COMPILED_AFTER", 0)


def _compiled_models() -> list[str]:
    return [name for name in gonio.models.available() if gonio.models.get(name).compiled is not None]


def test_every_compiled_model_is_tested_here():
    assert sorted(_compiled_models()) == sorted({name for name, _ in CASES})


@pytest.mark.parametrize(("name", "values"), CASES)
def test_compiled_plain_call_equals_the_numpy_path(name, values):
    model = gonio.models.get(name)
    geometry = _geometries()
    params, options = model.resolve(values)
    reference = model._call_in_chunks(*_as_angles(*geometry), params, options)
    fast = model(*geometry, **values)   # COMPILED_MIN geometries or more: the compiled path
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(reference))
    np.testing.assert_array_equal(fast == 0.0, reference == 0.0)
    # The polynomial Fresnel factor raises to the fifth power: numpy's power (vectorised
    # on some processors) and the C library's pow differ by an ulp or two of
    # (2 theta/pi)^5 <= 1, which 1 - F exposes near grazing as relative error: 1e-15
    # absolute there (5 ulp of 1; the BRDF is at most rho/pi).
    atol = 1e-15 if values.get("fresnel") == "polynomial" else 0.0
    if name == "kvd":
        atol = KVD_TOLERANCE * np.nanmax(np.abs(reference))
    np.testing.assert_allclose(fast, reference, rtol=1e-15, atol=atol, equal_nan=True)


def test_kvd_paths_against_extended_precision():
    """Both paths of the order-2 series within 1e-14 absolute (values up to 0.4) of the same
    closed form in long double (x87 extended, 64-bit mantissa): the closed form of
    benchmarks/c/closed_forms.c, written out from KvD eq 26-27."""
    values = {"a_0_0_0": 1.6, "a_1_1_1": 0.1, "a_2_0_0": -0.2, "a_2_2_0": 0.05, "a_2_2_2": 0.03}
    model = gonio.models.get("kvd")
    geometry = _geometries()
    ti, pi_, tr, pr = (np.asarray(a, float) for a in geometry)
    ok = np.isfinite(ti + pi_ + tr + pr) & (ti <= 90.0) & (tr <= 90.0)
    wide = np.longdouble
    degree = wide(np.pi) / wide(180.0)
    ci, cr = np.cos(ti[ok].astype(wide) * degree), np.cos(tr[ok].astype(wide) * degree)
    cd = np.cos((pr[ok].astype(wide) - pi_[ok].astype(wide)) * degree)
    s, qi, qr, zi, zr = 1.0 / (2.0 * wide(np.pi)), 1.0 - ci, 1.0 - cr, 1.0 - 2.0 * ci, 1.0 - 2.0 * cr
    exact = s * (wide(1.6) + wide(0.1) * 2.0 * np.sqrt(wide(2.0)) * np.sqrt(qi * qr) * cd
                 - wide(0.2) * np.sqrt(wide(1.5)) * (zi + zr) + wide(0.05) * 3.0 * zi * zr
                 + wide(0.03) * 2.0 * np.sqrt(wide(4.5)) * qi * qr * (2.0 * cd * cd - 1.0))
    params, options = model.resolve(values)
    for path in (model._call_in_chunks(*_as_angles(*geometry), params, options), model(*geometry, **values)):
        assert np.max(np.abs(path[ok] - exact)) < 1e-14


def test_kvd_series_of_high_order_equals_its_numpy_path():
    """A series of order 8 (55 modes, random amplitudes): the recurrence of the radial
    polynomials repeats numpy's; the values agree to 1e-12 of the largest (the radial
    polynomials of order 8 reach amplitudes of ~10, amplifying the cosines' ulp)."""
    from gonio.models.kvd import KvdCoefficients, series_model
    from gonio.models.kvd.basis import isotropic_indices

    modes = tuple(isotropic_indices(8))
    amplitudes = np.random.default_rng(5).normal(size=len(modes)) * 0.1
    amplitudes[0] = 1.6
    model = series_model(KvdCoefficients(modes, amplitudes))
    geometry = _geometries()
    params, options = model.resolve({})
    reference = model._call_in_chunks(*_as_angles(*geometry), params, options)
    fast = model(*geometry)
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(reference))
    np.testing.assert_allclose(fast, reference, rtol=0.0, atol=1e-12 * np.nanmax(np.abs(reference)), equal_nan=True)


def test_compiled_path_keeps_the_shape_and_broadcasts():
    model = gonio.models.get("oren-nayar")
    theta = np.linspace(0.0, 90.0, 181)
    phi = np.linspace(-180.0, 180.0, 361)
    out = model(theta[:, None], 0.0, 45.0, phi[None, :], rho=0.8, sigma=20.0)
    assert out.shape == (181, 361) and out.size >= COMPILED_MIN
    row = model(theta[[30]][:, None], 0.0, 45.0, phi[None, :], rho=0.8, sigma=20.0)  # numpy path
    np.testing.assert_allclose(out[30], row[0], rtol=1e-15, atol=0.0)


def test_compiled_path_is_taken_for_large_calls_only(monkeypatch):
    # The path must be able to fail: a compiled function that returns zeros is seen at
    # COMPILED_MIN geometries and not below.
    model = gonio.models.get("oren-nayar")
    calls = []

    def zeros(ti, pi_, tr, pr, params, options):
        calls.append(ti.size)
        return np.zeros(ti.size)

    monkeypatch.setattr(type(model), "compiled", property(lambda self: (lambda: zeros)))
    theta = np.full(COMPILED_MIN, 30.0)
    assert np.all(model(theta, 0.0, 45.0, 180.0, rho=0.9, sigma=30.0) == 0.0)
    assert np.all(model(theta[:-1], 0.0, 45.0, 180.0, rho=0.9, sigma=30.0) > 0.0)
    assert calls == [COMPILED_MIN]


def test_compiled_path_waits_until_numpy_has_cost_as_much(monkeypatch):
    # The rent-or-buy rule: the first COMPILED_AFTER geometries of a process go through
    # numpy (no numba load for a few moderate calls), the calls after that compiled.
    import gonio.models._core as core

    model = gonio.models.get("oren-nayar")
    calls = []
    monkeypatch.setattr(type(model), "compiled", property(lambda self: (lambda: lambda *a: calls.append(1) or
                                                                          np.zeros(a[0].size))))
    monkeypatch.setattr(core, "COMPILED_AFTER", 3 * COMPILED_MIN)
    monkeypatch.setattr(core, "_numpy_geometries", 0)
    theta = np.full(COMPILED_MIN, 30.0)
    values = [float(model(theta, 0.0, 45.0, 180.0, rho=0.9, sigma=30.0)[0]) for _ in range(5)]
    assert values[:3] == [values[0]] * 3 and values[0] > 0.0 and values[3:] == [0.0, 0.0]
    assert len(calls) == 2
