"""Many least-squares fits at once: gonio.fitting.least_squares_many against xarray's curvefit.

The anchor problem of the "Scale" issue: 900 independent fits (pixels) of 110 points each,
with xarray ``DataArray.curvefit`` (scipy's ``curve_fit`` once per fit through
``apply_ufunc``) on the same model written as a plain numpy function, side by side in the
same process, on one core (one BLAS/OpenMP thread). Two models with the free parameters
rho and sigma: ``oren-nayar-qualitative`` (eq 36: rho is linear, so least_squares_many
projects it out) and ``oren-nayar`` with ``ir_weight`` fixed at 1 (eq 33-35: rho enters
with its square, both parameters iterate). Both sides fit unweighted data within the
physical bounds from the same start; curvefit is timed bounded (scipy's ``trf``, the same
problem) and unbounded (MINPACK's ``lm``, its fastest). Reports fits per second, their
ratio, and the agreement of the parameters and standard errors (both without stated
uncertainties: covariance scaled by the reduced chi-square, curve_fit's default).

Run: ``.venv/bin/python benchmarks/bench_least_squares_many.py`` (about a minute). Writes
docs/benchmarks/least_squares_many.json and .png. The machine's load average before and
after is recorded: a ratio measured while other work holds the cores is not the rate.
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core: before numpy loads its BLAS
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine  # noqa: E402

import gonio  # noqa: E402
from gonio.fitting import least_squares_many  # noqa: E402

FITS, POINTS, NOISE, REPEATS = 900, 110, 0.004, 3
#: Runs of least_squares_many (each ~50 ms, so more of them to see past the shared machine's noise).
FAST_REPEATS = 9
START = {"rho": 0.5, "sigma": 20.0}
BOUNDS = {"rho": (0.0, 1.0), "sigma": (0.0, 90.0)}


def geometry(seed: int = 0) -> tuple[np.ndarray, ...]:
    """110 lighting/viewing geometries [deg]: 10 incidences x 11 views, half of the views in
    the plane (backward and forward), the others at random azimuths."""
    rng = np.random.default_rng(seed)
    theta_i = np.repeat(np.linspace(5.0, 75.0, 10), 11)
    theta_r = rng.uniform(0.0, 80.0, POINTS)
    phi_r = np.where(rng.random(POINTS) < 0.5, rng.choice([0.0, 180.0], POINTS), rng.uniform(0.0, 360.0, POINTS))
    return theta_i, np.zeros(POINTS), theta_r, phi_r


def _angles(x: np.ndarray) -> tuple[np.ndarray, ...]:
    """alpha, beta [rad] and cos(phi_r - phi_i) from xarray's stacked coordinates (4, N) [deg]."""
    ti, pi_, tr, pr = np.radians(x)
    return np.maximum(ti, tr), np.minimum(ti, tr), np.cos(pr - pi_)


def qualitative_numpy(x: np.ndarray, rho: float, sigma: float) -> np.ndarray:
    """Oren & Nayar 1995 eq 36 as a plain numpy function of xarray's coordinates [1/sr]."""
    alpha, beta, cos_dphi = _angles(x)
    s2 = np.radians(sigma) ** 2
    a = 1.0 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    return rho / math.pi * (a + b * np.maximum(0.0, cos_dphi) * np.sin(alpha) * np.tan(beta))


def functional_numpy(x: np.ndarray, rho: float, sigma: float) -> np.ndarray:
    """Oren & Nayar 1995 eq 33-35 (interreflection weight 1, floored at 0) as a plain numpy
    function of xarray's coordinates [1/sr]."""
    alpha, beta, cos_dphi = _angles(x)
    s2 = np.radians(sigma) ** 2
    c1 = 1.0 - 0.5 * s2 / (s2 + 0.33)
    c2 = 0.45 * s2 / (s2 + 0.09) * np.where(cos_dphi >= 0.0, np.sin(alpha),
                                           np.sin(alpha) - (2.0 * beta / math.pi) ** 3)
    c3 = 0.125 * s2 / (s2 + 0.09) * (4.0 * alpha * beta / math.pi**2) ** 2
    direct = rho / math.pi * (c1 + cos_dphi * c2 * np.tan(beta)
                              + (1.0 - np.abs(cos_dphi)) * c3 * np.tan(0.5 * (alpha + beta)))
    inter = 0.17 * rho**2 / math.pi * s2 / (s2 + 0.13) * (1.0 - cos_dphi * (2.0 * beta / math.pi) ** 2)
    return np.maximum(direct + inter, 0.0)


CASES = {
    "oren-nayar-qualitative": {"numpy": qualitative_numpy, "fixed": {}},
    "oren-nayar (ir_weight=1 fixed)": {"numpy": functional_numpy, "fixed": {"ir_weight": 1.0}, "model": "oren-nayar"},
}


def data(case: dict, geo: tuple[np.ndarray, ...], seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Noisy BRDF values (FITS, POINTS) of random rho, sigma, and the truths (FITS, 2)."""
    rng = np.random.default_rng(seed)
    truth = np.column_stack([rng.uniform(0.15, 0.95, FITS), rng.uniform(5.0, 50.0, FITS)])
    model = case.get("model", "oren-nayar-qualitative")
    clean = gonio.brdf(model, *geo, rho=truth[:, :1], sigma=truth[:, 1:], **case["fixed"])
    return clean + rng.normal(0.0, NOISE, clean.shape), truth


def check_numpy_model(case: dict, geo: tuple[np.ndarray, ...]) -> float:
    """Largest relative difference of the numpy function from gonio's model (must be
    rounding: the two sides fit the same formula)."""
    model = case.get("model", "oren-nayar-qualitative")
    worst = 0.0
    for rho, sigma in ((0.3, 5.0), (0.8, 30.0), (0.5, 60.0)):
        reference = gonio.brdf(model, *geo, rho=rho, sigma=sigma, **case["fixed"])
        mine = case["numpy"](np.stack(geo), rho, sigma)
        worst = max(worst, float(np.max(np.abs(mine - reference) / np.maximum(np.abs(reference), 1e-300))))
    return worst


def run_xarray(case: dict, geo: tuple[np.ndarray, ...], values: np.ndarray, bounded: bool):
    """xarray curvefit of every pixel: (coefficients (FITS, 2), stderr (FITS, 2))."""
    import xarray as xr

    coords = {name: ("geometry", a) for name, a in zip(("theta_i", "phi_i", "theta_r", "phi_r"), geo)}
    array = xr.DataArray(values, dims=("pixel", "geometry"), coords=coords)
    fitted = array.curvefit(list(coords), case["numpy"], reduce_dims="geometry", p0=START,
                            bounds=BOUNDS if bounded else None, param_names=["rho", "sigma"])
    coefficients = fitted["curvefit_coefficients"].values.copy()
    coefficients[:, 1] = np.abs(coefficients[:, 1])  # sigma enters as sigma^2: unbounded fits may end at -sigma
    stderr = np.sqrt(np.einsum("mii->mi", fitted["curvefit_covariance"].values))
    return coefficients, stderr


def run_gonio(case: dict, geo: tuple[np.ndarray, ...], values: np.ndarray):
    """least_squares_many of every pixel: the result."""
    return least_squares_many(case.get("model", "oren-nayar-qualitative"), *geo, values, fixed=case["fixed"],
                              start=START)


def best_of(function: Callable[[], object], repeats: int = REPEATS) -> tuple[float, object]:
    """Best wall time of ``repeats`` runs [s] and the last result."""
    best, result = math.inf, None
    for _ in range(repeats):
        began = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - began)
    return best, result


def measure(name: str, case: dict, geo: tuple[np.ndarray, ...]) -> dict:
    """Rates and agreement of one model."""
    values, truth = data(case, geo)
    mine_time, mine = best_of(lambda: run_gonio(case, geo, values), FAST_REPEATS)
    ours = mine.values[:, [mine.free.index("rho"), mine.free.index("sigma")]]
    our_se = mine.stderr[:, [mine.free.index("rho"), mine.free.index("sigma")]]
    row = {"model": name, "numpy_function_vs_gonio_max_rel": check_numpy_model(case, geo),
           "least_squares_many": {"seconds": mine_time, "fits_per_second": FITS / mine_time,
                                  "converged": int(mine.converged.sum()),
                                  "median_iterations": float(np.median(mine.iterations))}}
    for label, bounded in (("xarray_curvefit_bounded_trf", True), ("xarray_curvefit_unbounded_lm", False)):
        seconds, (theirs, their_se) = best_of(lambda: run_xarray(case, geo, values, bounded))
        chi_ours = _chi2(case, geo, values, ours)
        chi_theirs = _chi2(case, geo, values, theirs)
        row[label] = {
            "seconds": seconds, "fits_per_second": FITS / seconds, "ratio_gonio_over_xarray": seconds / mine_time,
            "max_abs_diff": {"rho": float(np.max(np.abs(ours[:, 0] - theirs[:, 0]))),
                             "sigma_deg": float(np.max(np.abs(ours[:, 1] - theirs[:, 1])))},
            "max_rel_diff_stderr": float(np.nanmax(np.abs(our_se / their_se - 1.0))),
            "fits_where_gonio_chi2_lower": int(np.sum(chi_ours < chi_theirs * (1 - 1e-9))),
            "fits_where_xarray_chi2_lower": int(np.sum(chi_theirs < chi_ours * (1 - 1e-9))),
        }
    row["rms_error_vs_truth"] = {"rho": float(np.sqrt(np.mean((ours[:, 0] - truth[:, 0]) ** 2))),
                                 "sigma_deg": float(np.sqrt(np.mean((ours[:, 1] - truth[:, 1]) ** 2)))}
    return row


def _chi2(case: dict, geo, values: np.ndarray, parameters: np.ndarray) -> np.ndarray:
    """Unweighted sum of squared residuals of each pixel at ``parameters`` (FITS, 2)."""
    stacked = np.stack(geo)
    return np.array([np.sum((case["numpy"](stacked, *p) - v) ** 2) for p, v in zip(parameters, values)])


def scaling(geo: tuple[np.ndarray, ...]) -> list[dict]:
    """least_squares_many's rate at more fits (an image of 90,000 pixels), oren-nayar-qualitative."""
    out = []
    case = CASES["oren-nayar-qualitative"]
    for repeat in (10, 100):
        values = np.concatenate([data(case, geo, seed)[0] for seed in range(repeat)])
        began = time.perf_counter()
        result = run_gonio(case, geo, values)
        seconds = time.perf_counter() - began
        out.append({"fits": len(values), "seconds": seconds, "fits_per_second": len(values) / seconds,
                    "converged": int(result.converged.sum())})
    return out


def chart(rows: list[dict], path: Path) -> None:
    """Bar chart of fits per second (log scale), one group per model."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(7.0, 3.6), layout="constrained")
    axes = figure.add_subplot()
    labels = [("least_squares_many", "gonio least_squares_many"),
              ("xarray_curvefit_bounded_trf", "xarray curvefit (bounded, trf)"),
              ("xarray_curvefit_unbounded_lm", "xarray curvefit (unbounded, lm)")]
    width = 0.26
    for j, (key, label) in enumerate(labels):
        rates = [row[key]["fits_per_second"] for row in rows]
        bars = axes.bar(np.arange(len(rows)) + (j - 1) * width, rates, width, label=label)
        axes.bar_label(bars, fmt="%.0f", fontsize=7)
    axes.set_xticks(np.arange(len(rows)), [row["model"] for row in rows])
    axes.set_yscale("log")
    axes.set_ylabel("fits per second (one core)")
    axes.set_title(f"{FITS} fits of {POINTS} points, same process", fontsize=10)
    axes.legend(fontsize=8, loc="upper right")
    figure.savefig(path, dpi=120)


def main() -> None:
    from threadpoolctl import threadpool_limits

    load_before = os.getloadavg()
    geo = geometry()
    with threadpool_limits(limits=1):
        run_gonio(CASES["oren-nayar-qualitative"], geo, data(CASES["oren-nayar-qualitative"], geo)[0])  # warm-up
        rows = [dict(measure(name, case, geo)) for name, case in CASES.items()]
        larger = scaling(geo)
    load_after = os.getloadavg()
    import scipy
    import xarray

    result = {
        "problem": f"{FITS} fits of {POINTS} BRDF values (unweighted, noise sd {NOISE} 1/sr), free rho and sigma "
                   f"within their physical bounds, start {START}; best of {FAST_REPEATS} runs (least_squares_many) "
                   f"and {REPEATS} (curvefit); one thread",
        "command": ".venv/bin/python benchmarks/bench_least_squares_many.py",
        "load_average_before": list(load_before), "load_average_after": list(load_after),
        "versions": {"gonio": gonio.__version__, "xarray": xarray.__version__, "scipy": scipy.__version__},
        "machine": machine(),
        "rows": rows,
        "least_squares_many_at_more_fits": larger,
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "least_squares_many.json").write_text(json.dumps(result, indent=2) + "\n")
    chart(rows, OUT / "least_squares_many.png")
    for row in rows:
        ours = row["least_squares_many"]
        print(f"{row['model']}: gonio {ours['fits_per_second']:.0f} fits/s ({ours['converged']}/{FITS} converged)")
        for key in ("xarray_curvefit_bounded_trf", "xarray_curvefit_unbounded_lm"):
            r = row[key]
            print(f"  {key}: {r['fits_per_second']:.0f} fits/s, gonio {r['ratio_gonio_over_xarray']:.1f}x faster, "
                  f"max |d rho| {r['max_abs_diff']['rho']:.2g}, max |d sigma| {r['max_abs_diff']['sigma_deg']:.2g} deg, "
                  f"stderr rel diff {r['max_rel_diff_stderr']:.2g}")
    for row in larger:
        print(f"least_squares_many, {row['fits']} fits: {row['fits_per_second']:.0f} fits/s")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")


if __name__ == "__main__":
    main()
