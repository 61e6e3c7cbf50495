"""The compiled radiance of a misaligned rig (gonio/fitting/compiled_rig.py) against the
numpy path it replaces in fits: misaligned_angles, the aperture-averaged model of
gonio.instrument, and RigPrediction's quantities."""
from __future__ import annotations

import numpy as np
import pytest

import gonio
from drivers.rig_geometry import ALIGNMENT_ERRORS, misaligned_angles
from gonio.fitting import Dataset, FitProblem
from gonio.fitting.compiled_rig import CompiledRigRadiance
from gonio.fitting.rig_errors import RigPrediction
from gonio.instrument import aperture_averaged

APERTURES = (0.003, 0.0009)
#: Both paths evaluate the same formulas through different (exact) trigonometric identities
#: and in another order; measured 2.2e-14 apart (relative). 1e-12 leaves room for cancellation near the
#: model's zero crossings while any error in a formula (a sign, a cosine weight, a sub-ray)
#: shows at 1e-4 or more.
RTOL = 1e-12
#: The tabulated model's zeta coordinate has a square root that vanishes at theta_i =
#: theta_r (gonio.models.tabulated.coordinates); there a rounding of 1e-16 in the angles,
#: which the two paths compute by different identities, moves it by 1e-8 or more and the value by
#: up to 2.1e-8 (measured, sigma = 20 deg). Any error in a formula still shows at 1e-4.
RTOL_TABLE = 1e-7
#: The specular lobe (eq 37) takes its half vector's slope and the V-cavity GAF from the
#: sub-rays' unit vectors where the numpy path takes them from angles; measured 8.1e-12
#: apart at one of 800 values (a lobe within a few degrees of its mirror direction, where
#: exp(-theta_a^2 / 2 sigma_s^2) and the GAF's min() amplify a rounding of the slope). Any
#: error in a formula still shows at 1e-4.
RTOL_LOBE = 1e-10


def _geometry() -> tuple[np.ndarray, ...]:
    """In-plane sweeps through the normal view, off-plane sweeps, a lamp 0.2 deg from the
    normal (pushed through it by the offsets), a lamp and a camera at 89.95 deg (pushed
    below the horizon by some alignments) and forward grazing views."""
    views = np.array([-89.95, -85.0, -60.0, -30.0, -10.0, 0.0, 0.0, 10.0, 45.0, 80.0])
    rows = [(ti, phi, v) for ti in (0.2, 30.0, 60.0, 85.0, 89.95) for phi in (0.0, -45.0) for v in views]
    ti, phi, view = (np.array(c, float) for c in zip(*rows))
    return ti, phi, np.abs(view), np.where(view >= 0, 0.0, 180.0)


def _alignments(rng, walkers: int) -> dict[str, np.ndarray]:
    out = {name: rng.normal(0.0, 0.3, (walkers, 1)) for name in ALIGNMENT_ERRORS}
    out["theta_i_offset"][0] = -0.5  # the 0.2 deg lamp through the normal
    out["view_offset"][1] = 0.0      # the normal view stays on the normal
    return out


def _numpy_path(model: str, geometry, params, alignment) -> np.ndarray:
    averaged = aperture_averaged(model, *APERTURES)
    true = misaligned_angles(*geometry, **alignment)
    return averaged(*true, **params) * np.clip(np.cos(np.radians(true[0])), 0.0, None)


@pytest.mark.parametrize("model, params", [
    ("oren-nayar", {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0}),
    ("oren-nayar", {"rho": 0.3, "sigma": 85.0, "ir_weight": 0.0}),  # eq 33's floor at 0 acts (forward grazing)
    ("lambert", {"rho": 0.7}),
    ("oren-nayar-qualitative", {"rho": 0.8, "sigma": 25.0}),  # eq 36's shape
    ("oren-nayar-tabulated", {"rho": 0.9, "sigma": 30.0}),  # the exact model's table
    ("oren-nayar-tabulated", {"rho": 0.5, "sigma": 60.0}),
    # eq 38: a narrow lobe (sharp near the mirror direction) and a broad one
    ("oren-nayar+torrance-sparrow", {"rho": 0.8, "sigma": 20.0, "kd": 0.9, "ks": 0.05, "sigma_s": 10.0, "n": 1.5}),
    ("oren-nayar+torrance-sparrow", {"rho": 0.6, "sigma": 5.0, "kd": 0.7, "ks": 0.3, "sigma_s": 35.0, "n": 1.5}),
])
def test_compiled_radiance_equals_the_numpy_path(model, params):
    rng = np.random.default_rng(3)
    geometry = _geometry()
    alignment = _alignments(rng, 8)
    columns = {k: v * (1.0 + 0.01 * rng.standard_normal((8, 1))) if k not in ("ir_weight", "n") else v
               for k, v in params.items()}
    expected = _numpy_path(model, geometry, columns, alignment)
    got = CompiledRigRadiance(gonio.models.get(model), geometry, APERTURES)(columns, alignment)
    assert got.shape == expected.shape == (8, geometry[0].size)
    rtol = RTOL_TABLE if "tabulated" in model else RTOL_LOBE if "torrance-sparrow" in model else RTOL
    np.testing.assert_allclose(got, expected, rtol=rtol, atol=1e-15)
    # the test can fail: some values are 0 (below the horizon), the rest differ between walkers
    assert (got == 0.0).any() and (got > 0.0).sum() > got.size // 2
    assert np.ptp(got[:, 30]) > 1e-4 * got[:, 30].mean()


def test_scalars_give_one_row_like_the_numpy_path():
    geometry = _geometry()
    rig = CompiledRigRadiance(gonio.models.get("oren-nayar"), geometry, APERTURES)
    values = {"rho": 0.8, "sigma": 20.0, "ir_weight": 1.0}
    got = rig(values, {"tilt_x": 0.3, "view_offset": -0.2})
    expected = _numpy_path("oren-nayar", geometry, values, {"tilt_x": 0.3, "view_offset": -0.2})
    assert got.shape == (geometry[0].size,)
    np.testing.assert_allclose(got, expected, rtol=RTOL, atol=1e-15)


def test_the_tabulated_model_at_sigma_zero_is_lambert_in_both_paths():
    """Footnote 10: sigma = 0 is Lambert exactly, in the table's model and in the loop."""
    geometry = _geometry()
    params = {"rho": np.array([[0.8], [0.8]]), "sigma": np.array([[0.0], [20.0]])}
    alignment = {"tilt_x": np.array([[0.1], [0.1]])}
    got = CompiledRigRadiance(gonio.models.get("oren-nayar-tabulated"), geometry, APERTURES)(params, alignment)
    lambert = _numpy_path("lambert", geometry, {"rho": 0.8}, {"tilt_x": 0.1})
    np.testing.assert_allclose(got[0], lambert, rtol=RTOL, atol=1e-15)
    np.testing.assert_allclose(got[1], _numpy_path("oren-nayar-tabulated", geometry, {"rho": 0.8, "sigma": 20.0},
                                                   {"tilt_x": 0.1}), rtol=RTOL_TABLE, atol=1e-15)


def test_other_models_are_refused():
    with pytest.raises(ValueError, match="minnaert"):
        CompiledRigRadiance(gonio.models.get("minnaert"), _geometry(), APERTURES)


def _dataset(quantity: str) -> Dataset:
    ti, phi, tr, pr = _geometry()
    keep = (ti < 89.0) & (tr < 89.0) & ~((quantity == "normalised_radiance") & (tr == 0.0))
    reference = {"geometry": [[30.0, 0.0, 10.0, 180.0], [60.0, 0.0, 10.0, 180.0]], "weights": [0.4, 0.6],
                 "reflectance": [0.99, 0.99]}
    value = np.ones(int(keep.sum()))
    return Dataset(ti[keep], phi[keep], tr[keep], pr[keep], value, 0.01, quantity=quantity,
                   metadata={"aperture_sr": list(APERTURES), "reference_standard": reference})


@pytest.mark.parametrize("quantity", ["radiance", "brdf", "normalised_radiance"])
def test_rig_prediction_compiled_equals_numpy(quantity):
    dataset = _dataset(quantity)
    model = aperture_averaged("oren-nayar", *APERTURES)
    rng = np.random.default_rng(5)
    values = {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0, "scale": 2.0, "stray_light": 0.002,
              **_alignments(rng, 4)}  # four walkers' alignments as columns
    predictions = [RigPrediction(model, quantity, dataset.geometry, {}, dataset.metadata, compiled=flag)
                   for flag in (True, False)]
    assert predictions[0]._kernel is not None and predictions[1]._kernel is None
    got, expected = (p.of_values(values) for p in predictions)
    assert got.shape == (4, dataset.n)
    np.testing.assert_allclose(got, expected, rtol=RTOL)


def test_fits_with_free_alignment_take_the_compiled_path_and_the_same_likelihood():
    dataset = _dataset("radiance")
    free = FitProblem("oren-nayar", dataset, {"ir_weight": 1.0}, alignment="view_offset,tilt_y")
    fixed = FitProblem("oren-nayar", dataset, {"ir_weight": 1.0, "view_offset": 0.1, "tilt_y": -0.2})
    assert free._rig._kernel is not None and fixed._rig._kernel is None  # a fixed alignment: numpy
    vector = [0.9, 30.0, 2.0, 0.1, -0.2]
    assert free.log_likelihood(vector) == pytest.approx(fixed.log_likelihood(vector[:3]), rel=1e-12)


def test_the_qualitative_model_takes_the_compiled_path_with_its_default_variant_only():
    """The loop knows eq 36 with its constant 0.33 (the default ``variant``); footnote 11's
    0.57 goes through the numpy path, and both give the fit's likelihood."""
    dataset = _dataset("radiance")
    default = FitProblem("oren-nayar-qualitative", dataset, alignment="tilt_x")
    footnote = FitProblem("oren-nayar-qualitative", dataset, alignment="tilt_x", options={"variant": "footnote11"})
    assert default._rig._kernel is not None and footnote._rig._kernel is None
    fixed = FitProblem("oren-nayar-qualitative", dataset, {"tilt_x": 0.3})
    vector = [0.8, 25.0, 2.0, 0.3]
    assert default.log_likelihood(vector) == pytest.approx(fixed.log_likelihood(vector[:3]), rel=1e-12)
    assert footnote.log_likelihood(vector) != pytest.approx(default.log_likelihood(vector), rel=1e-6)


def test_the_compiled_loop_chooses_the_aperture_rule_the_numpy_path_chooses():
    """Both paths take gonio.instrument.aperture_rule's cubature at each walker's true axes
    (the compact one away from the horizon and the retro-reflection, the full one there):
    the test geometry holds both, and the loop forced to the full rule everywhere differs
    from the numpy path by far more than RTOL_TABLE where the compact rule applies."""
    from gonio.instrument import aperture_rule

    geometry = _geometry()
    compact = aperture_rule(*geometry)
    assert compact.any() and (~compact).any()
    params = {"rho": np.array([[0.9]]), "sigma": np.array([[30.0]])}
    alignment = {"tilt_x": np.array([[0.1]])}
    expected = _numpy_path("oren-nayar-tabulated", geometry, params, alignment)
    rig = CompiledRigRadiance(gonio.models.get("oren-nayar-tabulated"), geometry, APERTURES)
    np.testing.assert_allclose(rig(params, alignment), expected, rtol=RTOL_TABLE, atol=1e-15)
    rig._compact = False  # the full rule everywhere
    full = rig(params, alignment)
    inside = compact & (expected[0] > 0)
    assert np.max(np.abs(full[0, inside] / expected[0, inside] - 1.0)) > 20 * RTOL_TABLE  # measured 6.8e-6
