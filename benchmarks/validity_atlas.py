"""Validity atlas of the reflectance models: where each approximation fails.

Every approximate method is compared with the exact reference gonio defines for it, on a
grid of (theta_i, theta_r, phi_r - phi_i) that runs into grazing angles (85, 87, 88, 89,
89.5, 89.9, 89.99 deg) and at several roughness values including the smooth limit:

* ``oren-nayar`` (eq 33-35), ``oren-nayar-qualitative`` (eq 36, option ``variant="eq36"``),
  its footnote-11 constant (``variant="footnote11"``), ``oren-nayar-tabulated`` and
  ``oren-nayar-numerical`` (the paper's eq 31 with the shortcuts eq 44, 48-49) against
  ``oren-nayar-exact`` (rtol 1e-6), rho = 0.9, sigma = 0.1 ... 90 deg; eq 36, which
  leaves out interreflection by design, also against ``oren-nayar-exact`` with
  ``interreflection=False``;
* ``wolff`` with the polynomial Fresnel factor (``fresnel="polynomial"``) against ``wolff``
  with eq 2 (``fresnel="exact"``), rho = 0.9, n = 1.05 ... 2.0;
* the Monte Carlo estimator of section 4.1 of Koenderink et al. 1999
  (``gonio.models.pitted.shallow.monte_carlo_brdf``) against the registered ``pitted``
  closed form (coverage 1, rho = 0.9), psi = 1 ... 90 deg;
* the Koenderink-van Doorn series truncated at order N (projection on the isotropic basis,
  ``gonio.models.kvd.project``, 64 x 64 x 128 quadrature) against the model it expands
  (``oren-nayar``, rho = 0.8, as docs/kvd.md);
* ``torrance-sparrow`` (F = 1): gonio has no independent reference for its V-cavity
  shadowing (eq 15-16 is the exact attenuation of the V-cavity geometry it assumes), so it
  gets the checks below only.

For each method and parameter value: relative error model / reference - 1 (0 where both
are 0, inf where only the reference is), its maximum, RMS and worst geometry, the largest
max(theta_i, theta_r) on the grid below which |error| stays within 1, 5 and 10 % (all
azimuths, in the plane of incidence, out of it), the error envelope against
max(theta_i, theta_r), and checks: NaN/inf values, negative values, numpy warnings, the
largest value (overflow), reciprocity (the call with source and viewer swapped) and, where
cheap, the directional-hemispherical reflectance (rho = 1, ks = 1) against the bound 1.

Run:  python benchmarks/validity_atlas.py [--quick]   (about 4 min on two shared cores)
      python benchmarks/validity_atlas.py --table docs/benchmarks/validity_models.json
      (prints the markdown table of the regions from a written JSON)
Writes docs/benchmarks/validity_models.json and docs/benchmarks/validity_models_<method>.png
(``--quick``: a coarse smoke run in a few seconds, no figures, JSON written to the
system's temporary directory so that it never replaces the full run's).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine, write_json  # noqa: E402

import gonio  # noqa: E402
from gonio.models import kvd  # noqa: E402
from gonio.models.pitted.shallow import monte_carlo_brdf  # noqa: E402
from gonio.radiometry import directional_hemispherical_reflectance  # noqa: E402

TOLERANCES = (0.01, 0.05, 0.10)
IN_PLANE = (0.0, 180.0)

# ------------------------------------------------------------------ grids
THETAS = np.array([*np.arange(0.0, 86.0, 5.0), 87.0, 88.0, 89.0, 89.5, 89.9, 89.99])
DELTA_PHI = np.array([0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0])
#: the Monte Carlo estimator costs ~2 ms per geometry at 1e4 samples: a coarser grid
MC_THETAS = np.array([0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 80.0, 85.0, 88.0, 89.0, 89.9, 89.99])
MC_DELTA_PHI = np.array([0.0, 45.0, 90.0, 135.0, 180.0])
MC_SAMPLES = 10_000
ENERGY_THETAS = [0.0, 30.0, 60.0, 80.0, 85.0, 89.0, 89.9, 89.99]
ENERGY_ORDER = 24

QUICK_THETAS = np.array([0.0, 30.0, 60.0, 80.0, 89.0, 89.99])
QUICK_DELTA_PHI = np.array([0.0, 90.0, 180.0])

ON_SIGMAS = [0.1, 0.5, 2.0, 5.0, 10.0, 20.0, 30.0, 40.0, 60.0, 90.0]
WOLFF_N = [1.05, 1.3, 1.5, 2.0]
PSIS = [1.0, 5.0, 20.0, 45.0, 70.0, 90.0]
KVD_ORDERS = [0, 2, 4, 6, 8, 10]
KVD_SIGMAS = [2.0, 10.0, 30.0]
TS_SIGMAS = [0.5, 2.0, 5.0, 10.0, 20.0, 30.0, 45.0]
RHO_ON = 0.9
RHO_KVD = 0.8


# ------------------------------------------------------------------ core: error and regions
def relative_error(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """model / reference - 1; 0 where both are 0, inf where only the reference is 0, NaN
    wherever either value is not finite (a failure, never within a tolerance)."""
    values = np.asarray(values, float)
    reference = np.asarray(reference, float)
    error = np.full(np.broadcast(values, reference).shape, np.nan)
    ok = np.isfinite(values) & np.isfinite(reference)
    nonzero = ok & (reference != 0.0)
    np.divide(values, reference, out=error, where=nonzero)
    error[nonzero] -= 1.0
    zero = ok & (reference == 0.0)
    error[zero] = np.where(values[zero] == 0.0, 0.0, np.inf)
    return error


def validity_regions(error: np.ndarray, thetas: np.ndarray, delta_phi: np.ndarray,
                     tolerances=TOLERANCES) -> dict:
    """Largest grid value T such that |error| <= tol at every grid point with
    max(theta_i, theta_r) <= T, for all azimuths, in the plane of incidence
    (dphi = 0 or 180 deg) and out of it.  ``error`` has shape (theta_i, theta_r, dphi)
    on ``thetas`` x ``thetas`` x ``delta_phi``; NaN counts as a failure.  None: even
    theta_i = theta_r = 0 fails; the last grid value: never fails on the grid.

    Also returns, per tolerance and subset, the first failing level (the next grid value)
    so that the bound is known to lie between the two."""
    thetas = np.asarray(thetas, float)
    level = np.maximum(thetas[:, None], thetas[None, :])  # (ti, tr)
    in_plane = np.isin(delta_phi, IN_PLANE)
    subsets = {"all": np.ones(len(delta_phi), bool), "in_plane": in_plane, "out_of_plane": ~in_plane}
    bad_abs = np.where(np.isnan(error), np.inf, np.abs(error))
    out = {}
    for tol in tolerances:
        row = {}
        for name, mask in subsets.items():
            if not mask.any():
                row[name] = {"theta_max_deg": None, "first_failure_deg": None}
                continue
            worst_at_level = np.array([bad_abs[..., mask][level == t].max() for t in thetas])
            failing = np.nonzero(worst_at_level > tol)[0]
            if failing.size == 0:
                row[name] = {"theta_max_deg": float(thetas[-1]), "first_failure_deg": None}
            else:
                k = int(failing[0])
                row[name] = {"theta_max_deg": float(thetas[k - 1]) if k > 0 else None,
                             "first_failure_deg": float(thetas[k])}
        out[f"{tol:g}"] = row
    return out


def envelope(error: np.ndarray, thetas: np.ndarray, delta_phi: np.ndarray) -> dict:
    """max |error| over the grid points with max(theta_i, theta_r) equal to each grid value,
    in and out of the plane of incidence (NaN reported as None)."""
    level = np.maximum(thetas[:, None], thetas[None, :])
    in_plane = np.isin(delta_phi, IN_PLANE)
    a = np.where(np.isnan(error), np.inf, np.abs(error))

    def curve(mask):
        if not mask.any():
            return None
        return [float(a[..., mask][level == t].max()) for t in thetas]

    return {"theta_deg": [float(t) for t in thetas], "in_plane": curve(in_plane), "out_of_plane": curve(~in_plane)}


def value_checks(values: np.ndarray, swapped: np.ndarray | None, geometry: tuple, caught: list[str]) -> dict:
    """NaN/inf, negative values, the largest value, numpy warnings and reciprocity."""
    ti, tr, dphi = geometry
    finite = np.isfinite(values)
    neg = finite & (values < 0.0)

    def where(mask, limit=5):
        idx = np.argwhere(mask)[:limit]
        return [[float(ti[tuple(i)]), float(tr[tuple(i)]), float(dphi[tuple(i)])] for i in idx]

    checks = {
        "n_values": int(values.size),
        "n_nonfinite": int((~finite).sum()),
        "nonfinite_at_deg": where(~finite),
        "n_negative": int(neg.sum()),
        "most_negative": float(values[neg].min()) if neg.any() else None,
        "negative_at_deg": where(neg),
        "max_value": float(np.nanmax(np.where(finite, values, np.nan))) if finite.any() else None,
        "max_value_at_deg": where(values == np.nanmax(np.where(finite, values, np.nan)), 1) if finite.any() else [],
        "warnings": sorted(set(caught)),
    }
    if swapped is not None:
        scale = np.maximum(np.abs(values), np.abs(swapped))
        diff = np.zeros(values.shape)
        both = np.isfinite(values) & np.isfinite(swapped) & (scale > 0)
        diff[both] = np.abs(values[both] - swapped[both]) / scale[both]
        at = np.unravel_index(int(np.argmax(diff)), diff.shape)
        checks["reciprocity_max_relative_difference"] = float(diff.max())
        checks["reciprocity_worst_at_deg"] = [float(ti[at]), float(tr[at]), float(dphi[at])]
    return checks


def summarise(error: np.ndarray, thetas: np.ndarray, delta_phi: np.ndarray) -> dict:
    """Maximum/RMS error, worst geometry, regions and envelope of one error array."""
    ti, tr, dphi = np.meshgrid(thetas, thetas, delta_phi, indexing="ij")
    a = np.where(np.isnan(error), np.inf, np.abs(error))
    at = np.unravel_index(int(np.argmax(a)), a.shape)
    finite = np.isfinite(error)
    moderate = (ti <= 80.0) & (tr <= 80.0)
    in_plane = np.isin(dphi, IN_PLANE)
    return {
        "max_abs_error": float(a.max()),
        "signed_error_at_worst": float(error[at]),
        "worst_at_deg": [float(ti[at]), float(tr[at]), float(dphi[at])],
        "rms_error": float(np.sqrt(np.mean(error[finite] ** 2))) if finite.any() else None,
        "max_abs_error_in_plane": float(a[in_plane].max()),
        "max_abs_error_out_of_plane": float(a[~in_plane].max()) if (~in_plane).any() else None,
        "max_abs_error_theta_le_80": float(a[moderate].max()),
        "n_error_nonfinite": int((~finite).sum()),
        "regions": validity_regions(error, thetas, delta_phi),
        "envelope": envelope(error, thetas, delta_phi),
    }


# ------------------------------------------------------------------ evaluation
def _call(function: Callable[[], np.ndarray]) -> tuple[np.ndarray, list[str]]:
    # numpy's default error state (what a user's call sees); warnings are recorded
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        values = np.asarray(function(), float)
    return values, [f"{w.category.__name__}: {w.message}" for w in caught]


@dataclass
class Case:
    """One method at one parameter value on one grid, with its error array."""
    method: str
    label: str
    param: dict
    thetas: np.ndarray
    delta_phi: np.ndarray
    error: np.ndarray | None
    summary: dict = field(default_factory=dict)
    checks: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    def error_at(self, theta_i: float, theta_r: float, delta_phi: float) -> float:
        i = int(np.argmin(np.abs(self.thetas - theta_i)))
        j = int(np.argmin(np.abs(self.thetas - theta_r)))
        k = int(np.argmin(np.abs(self.delta_phi - delta_phi)))
        return float(self.error[i, j, k])

    def record(self) -> dict:
        return {"method": self.method, "label": self.label, "param": self.param,
                **self.summary, "checks": self.checks, **self.extra}


def _grid(thetas, delta_phi):
    ti, tr, dphi = np.meshgrid(thetas, thetas, delta_phi, indexing="ij")
    return ti, tr, dphi


def _registered(name: str, params: dict, options: dict, thetas, delta_phi):
    """Values, swapped values and warnings of a registered model on the grid."""
    ti, tr, dphi = _grid(thetas, delta_phi)
    values, w1 = _call(lambda: gonio.brdf(name, ti, 0.0, tr, dphi, **params, **options))
    swapped, w2 = _call(lambda: gonio.brdf(name, tr, dphi, ti, 0.0, **params, **options))
    return values, swapped, w1 + w2


OREN_NAYAR_METHODS = {
    "oren-nayar": ("oren-nayar", {}),
    "oren-nayar-qualitative": ("oren-nayar-qualitative", {"variant": "eq36"}),
    "oren-nayar-qualitative-footnote11": ("oren-nayar-qualitative", {"variant": "footnote11"}),
    "oren-nayar-tabulated": ("oren-nayar-tabulated", {}),
    "oren-nayar-numerical": ("oren-nayar-numerical", {}),
    # eq 36 leaves out interreflection by design: also compared with the exact model
    # without it (option interreflection=False of oren-nayar-exact, the thin line of Fig 10)
    "oren-nayar-qualitative-vs-direct-exact": ("oren-nayar-qualitative", {"variant": "eq36"}),
}
DIRECT_ONLY = "oren-nayar-qualitative-vs-direct-exact"


def oren_nayar_family(sigmas, thetas, delta_phi, methods=None, energy=True, log=print) -> dict:
    """All Oren-Nayar approximations against ``oren-nayar-exact`` (rho = 0.9)."""
    methods = list(OREN_NAYAR_METHODS) if methods is None else methods
    geometry = _grid(thetas, delta_phi)
    cases, reference_checks = [], []
    for sigma in sigmas:
        params = {"rho": RHO_ON, "sigma": float(sigma)}
        start = time.perf_counter()
        exact, caught = _call(lambda: gonio.brdf("oren-nayar-exact", geometry[0], 0.0, geometry[1], geometry[2], **params))
        seconds = time.perf_counter() - start
        # the grid is symmetric in theta_i, theta_r: the swapped call is the transpose
        # (isotropy: the exact model depends on cos(dphi) only)
        reference_checks.append({"sigma_deg": float(sigma), "seconds": seconds,
                                 **value_checks(exact, np.swapaxes(exact, 0, 1), geometry, caught)})
        log(f"  oren-nayar-exact sigma = {sigma:g} deg: {exact.size} geometries in {seconds:.1f} s")
        direct = None
        if DIRECT_ONLY in methods:
            direct, _ = _call(lambda: gonio.brdf("oren-nayar-exact", geometry[0], 0.0, geometry[1], geometry[2],
                                                 interreflection=False, **params))
        for method in methods:
            name, options = OREN_NAYAR_METHODS[method]
            values, swapped, caught = _registered(name, params, options, thetas, delta_phi)
            reference = direct if method == DIRECT_ONLY else exact
            case = Case(method, f"sigma = {sigma:g} deg", {"sigma_deg": float(sigma)}, thetas, delta_phi,
                        relative_error(values, reference))
            case.summary = summarise(case.error, thetas, delta_phi)
            case.checks = value_checks(values, swapped, geometry, caught)
            if energy:
                case.extra["energy"] = _energy(name, {"rho": 1.0, "sigma": float(sigma)}, options)
            cases.append(case)
    return {"family": "oren-nayar", "reference": "oren-nayar-exact (rtol 1e-6)", "parameter": "sigma [deg]",
            "fixed": {"rho": RHO_ON}, "cases": cases, "reference_checks": reference_checks,
            "grid": _grid_record(thetas, delta_phi)}


def wolff_family(ns, thetas, delta_phi, energy=True, log=print) -> dict:
    """``wolff`` with the polynomial Fresnel factor against eq 2 (rho = 0.9)."""
    geometry = _grid(thetas, delta_phi)
    cases, reference_checks = [], []
    for n in ns:
        params = {"rho": RHO_ON, "n": float(n)}
        exact, ex_swapped, caught = _registered("wolff", params, {"fresnel": "exact"}, thetas, delta_phi)
        reference_checks.append({"n": float(n), **value_checks(exact, ex_swapped, geometry, caught)})
        values, swapped, caught = _registered("wolff", params, {"fresnel": "polynomial"}, thetas, delta_phi)
        case = Case("wolff-polynomial-fresnel", f"n = {n:g}", {"n": float(n)}, thetas, delta_phi,
                    relative_error(values, exact))
        case.summary = summarise(case.error, thetas, delta_phi)
        case.checks = value_checks(values, swapped, geometry, caught)
        if energy:
            case.extra["energy"] = _energy("wolff", {"rho": 1.0, "n": float(n)}, {"fresnel": "polynomial"})
            case.extra["energy_reference"] = _energy("wolff", {"rho": 1.0, "n": float(n)}, {"fresnel": "exact"})
        cases.append(case)
        log(f"  wolff n = {n:g}: max |error| {case.summary['max_abs_error']:.3g}")
    return {"family": "wolff", "reference": "wolff, fresnel='exact' (eq 2)", "parameter": "n [-]",
            "fixed": {"rho": RHO_ON}, "cases": cases, "reference_checks": reference_checks,
            "grid": _grid_record(thetas, delta_phi)}


def pitted_family(psis, thetas, delta_phi, samples=MC_SAMPLES, log=print) -> dict:
    """Monte Carlo over the orifice (section 4.1) against the closed-form ``pitted``
    (coverage 1: the pit alone; rho = 0.9).  One seed per geometry."""
    geometry = _grid(thetas, delta_phi)
    ti, tr, dphi = geometry
    cases, reference_checks = [], []
    for psi in psis:
        params = {"rho": RHO_ON, "psi": float(psi), "coverage": 1.0}
        exact, ex_swapped, caught = _registered("pitted", params, {}, thetas, delta_phi)
        reference_checks.append({"psi_deg": float(psi), **value_checks(exact, ex_swapped, geometry, caught)})
        start = time.perf_counter()
        values, se, swapped, se_swapped = (np.empty(ti.shape) for _ in range(4))
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            for seed, idx in enumerate(np.ndindex(ti.shape)):
                est = monte_carlo_brdf(ti[idx], tr[idx], dphi[idx], rho=RHO_ON, psi=float(psi), coverage=1.0,
                                       samples=samples, seed=seed)
                values[idx], se[idx] = est.value, est.standard_error
                est = monte_carlo_brdf(tr[idx], ti[idx], dphi[idx], rho=RHO_ON, psi=float(psi), coverage=1.0,
                                       samples=samples, seed=seed + 1_000_003)
                swapped[idx], se_swapped[idx] = est.value, est.standard_error
        caught = [f"{x.category.__name__}: {x.message}" for x in w]
        case = Case("pitted-monte-carlo", f"psi = {psi:g} deg", {"psi_deg": float(psi)}, thetas, delta_phi,
                    relative_error(values, exact))
        case.summary = summarise(case.error, thetas, delta_phi)
        case.checks = value_checks(values, swapped, geometry, caught)
        # the estimator is unbiased: |error| in units of its own standard error tells bias from noise
        # a standard error at rounding level (every sample equal) is a zero standard error
        zero_se = se <= 1e-9 * np.abs(values)
        z = np.abs(values - exact) / np.where(zero_se, np.nan, se)
        zero_se_swapped = se_swapped <= 1e-9 * np.abs(swapped)
        z_swap = np.abs(values - swapped) / np.where(zero_se | zero_se_swapped, np.nan,
                                                     np.sqrt(se**2 + se_swapped**2))
        exact_zero_se = zero_se & (np.abs(values - exact) > 1e-9 * np.abs(exact))
        case.extra.update({
            "samples": samples,
            "median_relative_standard_error": float(np.median(se / exact)),
            "max_relative_standard_error": float(np.max(se / exact)),
            "max_abs_z": float(np.nanmax(z)),
            "max_abs_z_at_deg": [float(g[np.unravel_index(int(np.nanargmax(z)), z.shape)]) for g in geometry],
            "fraction_abs_z_gt_4": float(np.nanmean(z > 4.0)),
            "n_zero_standard_error_but_different": int(exact_zero_se.sum()),
            "zero_standard_error_but_different_at_deg": [
                [float(g[tuple(i)]) for g in geometry] for i in np.argwhere(exact_zero_se)[:5]],
            "max_abs_error_where_zero_standard_error": float(np.max(np.abs(case.error[zero_se]))) if zero_se.any() else None,
            "reciprocity_max_abs_z": float(np.nanmax(z_swap)),
            "reciprocity_max_abs_z_note": "over the geometries where both estimates have a non-zero standard error",
            "seconds": time.perf_counter() - start,
        })
        cases.append(case)
        log(f"  pitted Monte Carlo psi = {psi:g} deg: max |error| {case.summary['max_abs_error']:.3g}, "
            f"max |z| {case.extra['max_abs_z']:.2f} ({case.extra['seconds']:.0f} s)")
    return {"family": "pitted", "reference": "pitted (closed form of F1, coverage 1)",
            "parameter": "psi [deg]", "fixed": {"rho": RHO_ON, "coverage": 1.0, "samples": samples},
            "cases": cases, "reference_checks": reference_checks, "grid": _grid_record(thetas, delta_phi)}


def kvd_family(sigmas, orders, thetas, delta_phi, energy=True, log=print) -> dict:
    """Truncated KvD projections of ``oren-nayar`` (rho = 0.8) against the model itself."""
    geometry = _grid(thetas, delta_phi)
    cases = []
    for sigma in sigmas:
        params = {"rho": RHO_KVD, "sigma": float(sigma)}
        reference, _, _ = _registered("oren-nayar", params, {}, thetas, delta_phi)
        ref_energy = _energy("oren-nayar", params, {}) if energy else None
        for order in orders:
            series = kvd.project("oren-nayar", order, params).model()
            values, w1 = _call(lambda: series(geometry[0], 0.0, geometry[1], geometry[2]))
            swapped, w2 = _call(lambda: series(geometry[1], geometry[2], geometry[0], 0.0))
            case = Case(f"kvd-order-{order}", f"sigma = {sigma:g} deg", {"sigma_deg": float(sigma), "order": order},
                        thetas, delta_phi, relative_error(values, reference))
            case.summary = summarise(case.error, thetas, delta_phi)
            case.checks = value_checks(values, swapped, geometry, w1 + w2)
            if energy:
                case.extra["energy"] = _energy(series, {}, {})
                case.extra["energy_reference"] = ref_energy
            cases.append(case)
        log(f"  kvd sigma = {sigma:g} deg: orders {orders} done")
    return {"family": "kvd", "reference": "oren-nayar (the expanded model; docs/kvd.md)",
            "parameter": "sigma [deg] of the expanded oren-nayar", "fixed": {"rho": RHO_KVD,
            "projection": "gonio.models.kvd.project, 64 x 64 x 128 product quadrature"},
            "cases": cases, "reference_checks": [], "grid": _grid_record(thetas, delta_phi)}


def torrance_sparrow_family(sigmas, thetas, delta_phi, energy=True, log=print) -> dict:
    """Checks of ``torrance-sparrow`` (ks = 1, F = 1); no reference to compare with."""
    geometry = _grid(thetas, delta_phi)
    cases = []
    for sigma_s in sigmas:
        params = {"ks": 1.0, "sigma_s": float(sigma_s)}
        values, swapped, caught = _registered("torrance-sparrow", params, {"fresnel": "unity"}, thetas, delta_phi)
        case = Case("torrance-sparrow", f"sigma_s = {sigma_s:g} deg", {"sigma_s_deg": float(sigma_s)},
                    thetas, delta_phi, None)
        case.checks = value_checks(values, swapped, geometry, caught)
        if energy:
            # narrow lobes need more nodes per panel (docs/models.md: 48, 96 below 20 deg,
            # 200 below 5 deg; 400 below 1 deg, where order 200 still overshoots 1 near grazing)
            order = 400 if sigma_s < 1.0 else 200 if sigma_s < 5.0 else 96 if sigma_s < 20.0 else 48
            case.extra["energy"] = _energy("torrance-sparrow", params, {"fresnel": "unity"}, order=order)
        cases.append(case)
    log("  torrance-sparrow checks done")
    return {"family": "torrance-sparrow", "reference": None,
            "reference_note": "no independent reference in gonio: the V-cavity GAF (eq 15-16) is exact for "
                              "the geometry the model assumes; checks only",
            "parameter": "sigma_s [deg]", "fixed": {"ks": 1.0, "fresnel": "unity"}, "cases": cases,
            "reference_checks": [], "grid": _grid_record(thetas, delta_phi)}


def _energy(model, params: dict, options: dict, order: int = ENERGY_ORDER) -> dict:
    """rho_dh on ENERGY_THETAS (albedo 1 where the model has one) and its excess over 1."""
    values, caught = _call(lambda: directional_hemispherical_reflectance(
        model, ENERGY_THETAS, order=order, **params, **options))
    return {"theta_i_deg": ENERGY_THETAS, "rho_dh": [float(v) for v in values],
            "max_excess_over_1": float(max(0.0, np.nanmax(values) - 1.0)),
            "order": order, "warnings": sorted(set(caught))}


def _grid_record(thetas, delta_phi) -> dict:
    return {"theta_deg": [float(t) for t in thetas], "delta_phi_deg": [float(d) for d in delta_phi],
            "n_geometries": int(len(thetas) ** 2 * len(delta_phi)), "phi_i_deg": 0.0}


# ------------------------------------------------------------------ overall regions
def overall_regions(cases: list[Case], keys=("all", "in_plane", "out_of_plane")) -> dict:
    """Per tolerance and subset: the smallest theta_max over the parameter values (None if
    any is None), i.e. the region valid at every roughness measured."""
    out = {}
    for tol in TOLERANCES:
        row = {}
        for key in keys:
            values = [c.summary["regions"][f"{tol:g}"][key]["theta_max_deg"] for c in cases]
            row[key] = None if any(v is None for v in values) else min(values)
        out[f"{tol:g}"] = row
    return out


# ------------------------------------------------------------------ figures
def heat_map(method: str, cases: list[Case], path: Path) -> None:
    """log10 |error| over theta_i x theta_r, one row per parameter value, one column per
    delta_phi, with the 1/5/10 % contours."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    cmap = colormaps["viridis"].copy()
    cmap.set_bad("0.6")

    thetas, delta_phi = cases[0].thetas, cases[0].delta_phi
    rows, cols = len(cases), len(delta_phi)
    fig = Figure(figsize=(1.75 * cols + 1.2, 1.6 * rows + 0.9), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True, sharey=True)
    norm = Normalize(-4.0, 1.0)
    index = np.arange(len(thetas))
    ticks = [k for k, t in enumerate(thetas) if t in (0, 30, 60, 80, 89, 89.99)]
    mesh = None
    for r, case in enumerate(cases):
        with np.errstate(divide="ignore"):
            log_err = np.log10(np.abs(case.error))
        log_err = np.where(np.isnan(case.error), np.nan, np.clip(log_err, -6.0, 3.0))
        for c, dphi in enumerate(delta_phi):
            ax = axes[r, c]
            z = np.ma.masked_invalid(log_err[:, :, c].T)  # rows theta_r, columns theta_i
            mesh = ax.pcolormesh(index, index, z, norm=norm, cmap=cmap, shading="nearest")
            if np.isfinite(log_err[:, :, c]).any():
                ax.contour(index, index, np.nan_to_num(log_err[:, :, c].T, nan=3.0),
                           levels=np.log10(TOLERANCES), colors=["w", "orange", "r"], linewidths=0.8)
            ax.set_xticks(ticks, [f"{thetas[k]:g}" for k in ticks], fontsize=5, rotation=90)
            ax.set_yticks(ticks, [f"{thetas[k]:g}" for k in ticks], fontsize=5)
            if r == 0:
                ax.set_title(f"dphi = {dphi:g} deg", fontsize=7)
            if c == 0:
                ax.set_ylabel(f"{case.label}\ntheta_r [deg]", fontsize=6)
            if r == rows - 1:
                ax.set_xlabel("theta_i [deg]", fontsize=6)
    fig.colorbar(mesh, ax=axes, shrink=0.5,
                 label="log10 |model / reference - 1|  (contours: white 1 %, orange 5 %, red 10 %; grey: NaN)")
    fig.suptitle(f"{method}: relative error against the reference (grid axes by index; grazing "
                 "values 87-89.99 deg stretched)", fontsize=8)
    fig.savefig(path, dpi=64)


# ------------------------------------------------------------------ tables from the JSON
def _region_text(value) -> str:
    return "none" if value is None else f"{value:g}"


def region_table(data: dict) -> str:
    """Markdown table of the regions within 1/5/10 % per method and parameter value, read
    from a payload written by this script (all / in plane / out of plane)."""
    lines = ["| method | parameter | within 1 % | within 5 % | within 10 % | max abs error at (theta_i, theta_r, dphi) |",
             "|---|---|---|---|---|---|"]
    for fam in data["families"].values():
        for method, entry in fam["methods"].items():
            if entry["overall_regions"] is None:
                continue
            rows = [(c["label"], c["regions"], c) for c in entry["cases"]]
            rows.append(("all values", entry["overall_regions"], None))
            for label, regions, case in rows:
                cells = []
                for tol in TOLERANCES:
                    r = regions[f"{tol:g}"]
                    pick = (lambda k: r[k]["theta_max_deg"]) if case is not None else (lambda k: r[k])
                    cells.append(" / ".join(_region_text(pick(k)) for k in ("all", "in_plane", "out_of_plane")))
                worst = "" if case is None else (
                    f"{case['max_abs_error']:.3g} at ({', '.join(f'{v:g}' for v in case['worst_at_deg'])})")
                lines.append(f"| `{method}` | {label} | " + " | ".join(cells) + f" | {worst} |")
    return "\n".join(lines)


# ------------------------------------------------------------------ driver
def run(quick: bool = False, log=print) -> dict:
    """Evaluate every family; returns {family: result with Case objects}."""
    thetas, dphi = (QUICK_THETAS, QUICK_DELTA_PHI) if quick else (THETAS, DELTA_PHI)
    mc_thetas, mc_dphi = (QUICK_THETAS, QUICK_DELTA_PHI) if quick else (MC_THETAS, MC_DELTA_PHI)
    families = {}
    start = time.perf_counter()
    families["oren-nayar"] = oren_nayar_family([0.5, 10.0, 30.0] if quick else ON_SIGMAS, thetas, dphi,
                                               energy=not quick, log=log)
    log(f"oren-nayar family: {time.perf_counter() - start:.0f} s")
    families["wolff"] = wolff_family([1.05, 1.5] if quick else WOLFF_N, thetas, dphi, energy=not quick, log=log)
    families["pitted"] = pitted_family([1.0, 45.0] if quick else PSIS, mc_thetas, mc_dphi,
                                       samples=1000 if quick else MC_SAMPLES, log=log)
    log(f"pitted family: {time.perf_counter() - start:.0f} s")
    families["kvd"] = kvd_family([10.0] if quick else KVD_SIGMAS, [0, 2] if quick else KVD_ORDERS, thetas, dphi,
                                 energy=not quick, log=log)
    families["torrance-sparrow"] = torrance_sparrow_family([2.0, 20.0] if quick else TS_SIGMAS, thetas, dphi,
                                                           energy=not quick, log=log)
    return families


def payload(families: dict, seconds: float, quick: bool) -> dict:
    out = {}
    for key, fam in families.items():
        methods = {}
        for case in fam["cases"]:
            methods.setdefault(case.method, []).append(case)
        out[key] = {k: v for k, v in fam.items() if k != "cases"}
        out[key]["methods"] = {
            method: {"cases": [c.record() for c in cases],
                     "overall_regions": overall_regions(cases) if cases[0].error is not None else None}
            for method, cases in methods.items()
        }
    return {
        "benchmark": "validity_models",
        "command": "python benchmarks/validity_atlas.py" + (" --quick" if quick else ""),
        "machine": machine(),
        "quick": quick,
        "definitions": {
            "relative_error": "model / reference - 1 (0 where both are 0, inf where only the reference is, "
                              "NaN where either is not finite; NaN and inf count as failures)",
            "region": "theta_max_deg: the largest grid value T with |error| <= tol at every grid point with "
                      "max(theta_i, theta_r) <= T (all azimuths of the subset); first_failure_deg: the next grid "
                      "value, where it fails; None: fails already at theta_i = theta_r = 0",
            "in_plane": "delta_phi = 0 or 180 deg", "out_of_plane": "the other delta_phi of the grid",
            "overall_regions": "the smallest theta_max over the parameter values of the method",
            "reciprocity": "max |f(i, r) - f(r, i)| / max(|f(i, r)|, |f(r, i)|) over the grid, f(r, i) a second "
                           "call with source and viewer exchanged (for oren-nayar-exact: the transpose of the "
                           "symmetric grid)",
            "energy": "gonio.radiometry.directional_hemispherical_reflectance, albedo 1 (ks = 1; kvd: the "
                      f"series of rho = {RHO_KVD}), order {ENERGY_ORDER} unless the record says otherwise; "
                      f"max_excess_over_1 over theta_i = {ENERGY_THETAS}",
        },
        "families": out,
        "seconds": seconds,
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="coarse smoke run (no figures)")
    parser.add_argument("--table", metavar="JSON", help="print the region table of a written JSON and stop")
    args = parser.parse_args(argv)
    if args.table:
        import json

        print(region_table(json.loads(Path(args.table).read_text())))
        return
    start = time.perf_counter()
    families = run(quick=args.quick)
    seconds_eval = time.perf_counter() - start
    written = []
    if not args.quick:
        by_method = {}
        for fam in families.values():
            for case in fam["cases"]:
                if case.error is not None:
                    by_method.setdefault(case.method, []).append(case)
        for method, cases in by_method.items():
            path = OUT / f"validity_models_{method}.png"
            heat_map(method, cases, path)
            written.append(path.name)
    seconds = time.perf_counter() - start
    data = payload(families, seconds, args.quick)
    data["seconds_evaluation"] = seconds_eval
    data["figures"] = written
    if args.quick:
        import json
        import tempfile

        path = Path(tempfile.gettempdir()) / "validity_models_quick.json"
        path.write_text(json.dumps(data, indent=2, default=float) + "\n")
    else:
        path = write_json("validity_models", data)
    print(f"wrote {path} and {len(written)} figures ({seconds:.0f} s)")


if __name__ == "__main__":
    main()
