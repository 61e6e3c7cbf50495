"""Wolff smooth-dielectric model: exact vs polynomial Fresnel, and the H-function by order.

Three studies, each timed against a reference measured in the same run:

* ``wolff``: the ``wolff`` model with the exact Fresnel factor (eq 2, the reference) and
  with the polynomial approximation after eq 7, on random geometries (plain call and the
  fixed-geometry path ``Model.at`` used by fitting).  Error: the largest relative BRDF
  error against the exact-Fresnel model for theta_i, theta_r <= 50 deg (the range of
  the section 4 Lambert statement), n in [1.3, 2.0]; the error over all angles up to
  80 deg is stored too.
* ``chandrasekhar-h``: the N-th order H-function (after eq 8) for N = 1 ... 64 against
  the solution of the integral equation (Newton on a 400-node Gauss grid): time for a
  fresh albedo (root finding included) and largest relative error over mu in [0, 1],
  omega in {0.01, 0.5, 0.9, 0.99, 1}.
* ``wolff-eq8``: the physical albedo factor of eq 8 built on the N-th order H-function,
  against eq 8 with the exact H and adaptive quadrature for K.

Run:  python benchmarks/bench_wolff.py
Writes docs/benchmarks/wolff.json and docs/benchmarks/wolff.png.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from matplotlib.figure import Figure
from scipy.integrate import quad

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, best_time, machine, random_geometries, write_json  # noqa: E402

import gonio  # noqa: E402
from gonio.models import chandrasekhar, wolff  # noqa: E402
from gonio.models.fresnel import fresnel_polynomial, fresnel_reflectance, polynomial_epsilon  # noqa: E402

N_GEOMETRIES = 50_000
DIELECTRICS = np.linspace(1.3, 2.0, 8)
ORDERS = [1, 2, 4, 8, 16, 32, 64]
ALBEDOS = [0.01, 0.5, 0.9, 0.99, 1.0]
EQ8_CASES = [(n, omega) for n in (1.3, 1.5, 2.0) for omega in (0.5, 0.9, 1.0)]


# ---------------------------------------------------------------------- Fresnel study
def brdf_error(limit_deg: float) -> tuple[float, float]:
    """Largest relative error of the polynomial-Fresnel BRDF, and the n where it occurs."""
    t = np.linspace(0.0, limit_deg, 101)
    ti, tr = np.meshgrid(t, t)
    worst, worst_n = 0.0, float("nan")
    for n in DIELECTRICS:
        exact = gonio.brdf("wolff", ti, 0, tr, 0, n=n)
        approx = gonio.brdf("wolff", ti, 0, tr, 0, n=n, fresnel="polynomial")
        error = float(np.max(np.abs(approx / exact - 1.0)))
        if error > worst:
            worst, worst_n = error, float(n)
    return worst, worst_n


def fresnel_records() -> tuple[list[dict], dict]:
    model = gonio.models.get("wolff")
    ti, pi_, tr, pr = random_geometries(N_GEOMETRIES, seed=3)
    timings = {}
    for fresnel in ("exact", "polynomial"):
        timings[fresnel] = best_time(lambda: model(ti, pi_, tr, pr, fresnel=fresnel), repeats=5) / N_GEOMETRIES
        fixed = model.at(ti, pi_, tr, pr, fresnel=fresnel)
        timings[fresnel + "-fixed"] = best_time(lambda: fixed(n=1.5), repeats=5) / N_GEOMETRIES
    error_50, n_50 = brdf_error(50.0)
    error_80, n_80 = brdf_error(80.0)
    # reflectance itself: largest absolute error of the polynomial for n in [1.3, 2.0]
    theta = np.linspace(0.0, np.pi / 2, 9001)
    fresnel_error = {
        f"{n:.1f}": float(np.max(np.abs(fresnel_polynomial(theta, polynomial_epsilon(n)) - fresnel_reflectance(np.cos(theta), n))))
        for n in DIELECTRICS
    }
    reference = "wolff, exact Fresnel (eq 2)"
    records = [
        {
            "family": "wolff",
            "method": "exact Fresnel (eq 2)",
            "seconds_per_evaluation": timings["exact"],
            "relative_error": 0.0,
            "reference_method": reference,
            "notes": f"reference; fixed-geometry path (Model.at) {timings['exact-fixed']:.3g} s/eval",
            "seconds_per_evaluation_fixed_geometry": timings["exact-fixed"],
        },
        {
            "family": "wolff",
            "method": "polynomial Fresnel (after eq 7)",
            "seconds_per_evaluation": timings["polynomial"],
            "relative_error": error_50,
            "reference_method": reference + ", theta_i, theta_r <= 50 deg, n in [1.3, 2.0]",
            "notes": (
                f"time ratio to exact {timings['polynomial'] / timings['exact']:.2f} (plain call), "
                f"{timings['polynomial-fixed'] / timings['exact-fixed']:.2f} (Model.at); "
                f"worst at n = {n_50:.1f}; up to 80 deg the error is {error_80:.2f} (n = {n_80:.1f})"
            ),
            "seconds_per_evaluation_fixed_geometry": timings["polynomial-fixed"],
            "time_ratio_to_reference": timings["polynomial"] / timings["exact"],
            "relative_error_up_to_80_deg": error_80,
        },
    ]
    return records, {"max_abs_reflectance_error_by_n": fresnel_error}


# ---------------------------------------------------------------------- H-function study
def h_error(order: int) -> float:
    mu = np.linspace(0.0, 1.0, 201)
    return max(
        float(np.max(np.abs(chandrasekhar.h_function(mu, omega, order) / chandrasekhar.h_function_numerical(mu, omega) - 1.0)))
        for omega in ALBEDOS
    )


def time_fresh(function) -> float:
    """Best time of ``function()`` with every cache emptied first (a new albedo each call)."""
    best = float("inf")
    for _ in range(5):
        chandrasekhar._roots.cache_clear()
        chandrasekhar._numerical_solution.cache_clear()
        wolff._physical_scale_normal.cache_clear()
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def h_records() -> tuple[list[dict], dict]:
    mu = np.linspace(0.0, 1.0, 201)
    t_reference = time_fresh(lambda: chandrasekhar.h_function_numerical(mu, 0.9)) / mu.size
    reference = "H from the integral equation (Newton, 400 Gauss nodes), mu in [0, 1], omega in {0.01, 0.5, 0.9, 0.99, 1}"
    records = [
        {
            "family": "chandrasekhar-h",
            "method": "integral equation (400 nodes)",
            "seconds_per_evaluation": t_reference,
            "relative_error": 0.0,
            "reference_method": reference,
            "notes": "reference: agrees with the exact integral representation to 1e-14 (tests); time per mu for 201 values, solve included",
        }
    ]
    table = {"orders": ORDERS, "max_relative_error": [], "by_albedo": {}}
    for order in ORDERS:
        error = h_error(order)
        table["max_relative_error"].append(error)
        t = time_fresh(lambda: chandrasekhar.h_function(mu, 0.9, order)) / mu.size
        records.append(
            {
                "family": "chandrasekhar-h",
                "method": f"N = {order}",
                "seconds_per_evaluation": t,
                "relative_error": error,
                "reference_method": reference,
                "notes": f"time ratio to reference {t / t_reference:.3g}; time per mu for 201 values, root finding included",
                "order": order,
            }
        )
    for omega in ALBEDOS:
        m = np.linspace(0.0, 1.0, 201)
        exact = chandrasekhar.h_function_numerical(m, omega)
        table["by_albedo"][f"{omega:g}"] = [
            float(np.max(np.abs(chandrasekhar.h_function(m, omega, order) / exact - 1.0))) for order in ORDERS
        ]
    return records, table


# ---------------------------------------------------------------------- eq 8 study
def eq8_reference(n: float, omega: float) -> float:
    def h(x):
        return float(chandrasekhar.h_function_numerical(x, omega))

    rho_1 = omega / (4.0 * np.pi * n**2) * h(1.0) ** 2 / 2.0
    critical = np.sqrt(1.0 - 1.0 / n**2)

    def integrand(x):
        return float(fresnel_reflectance(x, 1.0 / n)) * x * h(x) / (x + 1.0)

    k = 0.5 * omega * h(1.0) * (quad(integrand, 0.0, critical, epsabs=1e-13)[0] + quad(integrand, critical, 1.0, epsabs=1e-13, limit=200)[0])
    return rho_1 / (1.0 - k)


def eq8_records() -> tuple[list[dict], dict]:
    references = {case: eq8_reference(*case) for case in EQ8_CASES}
    t_reference = time_fresh(lambda: eq8_reference(1.5, 0.9))
    reference = "eq 8 with exact H (integral equation) and adaptive quadrature for K; n in {1.3, 1.5, 2}, omega in {0.5, 0.9, 1}"
    records = [
        {
            "family": "wolff-eq8",
            "method": "exact H + adaptive K",
            "seconds_per_evaluation": t_reference,
            "relative_error": 0.0,
            "reference_method": reference,
            "notes": "reference; time for one (n, omega)",
        }
    ]
    table = {"orders": ORDERS[2:], "max_relative_error": [], "values": {f"n={n},omega={w}": v for (n, w), v in references.items()}}
    for order in ORDERS[2:]:
        error = max(abs(float(wolff.physical_scale(n, w, order=order)) / references[(n, w)] - 1.0) for n, w in EQ8_CASES)
        table["max_relative_error"].append(error)
        t = time_fresh(lambda: wolff.physical_scale(1.5, 0.9, order=order))
        records.append(
            {
                "family": "wolff-eq8",
                "method": f"H order N = {order}" + (" (model default)" if order == chandrasekhar.DEFAULT_ORDER else ""),
                "seconds_per_evaluation": t,
                "relative_error": error,
                "reference_method": reference,
                "notes": f"time for one new (n, omega), root finding and 96-node K rule included; ratio to reference {t / t_reference:.3g}",
                "order": order,
            }
        )
    return records, table


# ---------------------------------------------------------------------- chart
def chart(records: list[dict], h_table: dict, extras: dict) -> Path:
    fig = Figure(figsize=(12, 9), layout="constrained")
    (ax_time, ax_h), (ax_f, ax_cyl) = fig.subplots(2, 2)

    for k, family in enumerate(("wolff", "chandrasekhar-h", "wolff-eq8")):
        rows = [r for r in records if r["family"] == family]
        methods, references = [r for r in rows if r["relative_error"] > 0], [r for r in rows if r["relative_error"] == 0]
        ax_time.loglog([r["seconds_per_evaluation"] for r in methods], [r["relative_error"] for r in methods],
                       "o-", color=f"C{k}", label=family)
        ax_time.loglog([r["seconds_per_evaluation"] for r in references], [1e-16] * len(references), "s", color=f"C{k}")
        for r in rows:
            ax_time.annotate(r["method"], (r["seconds_per_evaluation"], max(r["relative_error"], 1e-16)), fontsize=6,
                             xytext=(3, 2), textcoords="offset points")
    ax_time.set_xlabel("time per evaluation [s]")
    ax_time.set_ylabel("relative error vs reference [-] (squares: references)")
    ax_time.set_title("speed vs accuracy")
    ax_time.legend(fontsize=8)
    ax_time.grid(alpha=0.3, which="both")

    for omega, errors in h_table["by_albedo"].items():
        ax_h.loglog(h_table["orders"], errors, "o-", label=f"omega = {omega}")
    ax_h.loglog(h_table["orders"], 0.075 / np.asarray(h_table["orders"], float), "k--", lw=0.8, label="0.075 / N")
    ax_h.set_xlabel("order N")
    ax_h.set_ylabel("max relative error of H over mu in [0, 1]")
    ax_h.set_title("N-th order H-function vs integral equation")
    ax_h.legend(fontsize=8)
    ax_h.grid(alpha=0.3, which="both")

    theta = np.linspace(0.0, 90.0, 901)
    for k, n in enumerate((1.3, 1.5, 2.0)):
        exact = fresnel_reflectance(np.cos(np.radians(theta)), n)
        approx = fresnel_polynomial(np.radians(theta), polynomial_epsilon(n))
        ax_f.plot(theta, exact, color=f"C{k}", label=f"eq 2, n = {n}")
        ax_f.plot(theta, approx, "--", color=f"C{k}", label=f"polynomial, n = {n}")
    ax_f.set_xlabel("incidence angle [deg]")
    ax_f.set_ylabel("Fresnel reflectance F [-]")
    ax_f.set_title("exact vs polynomial Fresnel (eps = F0/(1 - F0))")
    ax_f.legend(fontsize=7)
    ax_f.grid(alpha=0.3)

    psi = np.linspace(0.0, 90.0, 901)
    for style, fresnel in (("-", "exact"), ("--", "polynomial")):
        radiance = gonio.brdf("wolff", 90.0 - psi, 0.0, psi, 180.0, n=1.5, fresnel=fresnel) * np.sin(np.radians(psi))
        ax_cyl.plot(psi, radiance / radiance.max(), style, label=f"Wolff, {fresnel} Fresnel (peak {psi[np.argmax(radiance)]:.1f} deg)")
    ax_cyl.plot(psi, np.sin(np.radians(psi)), ":", color="k", label="Lambert")
    ax_cyl.set_xlabel("relative orientation psi [deg] (normal vs viewer)")
    ax_cyl.set_ylabel("radiance / max [-]")
    ax_cyl.set_title("cylinder lit at 90 deg to the viewer (Figs 8-9), n = 1.5")
    ax_cyl.legend(fontsize=7)
    ax_cyl.grid(alpha=0.3)

    fig.suptitle("Wolff model (Wolff, Nayar & Oren 1998, eq 2, 7, 8)")
    path = OUT / "wolff.png"
    fig.savefig(path, dpi=110)
    return path


def main() -> None:
    start = time.perf_counter()
    fresnel, fresnel_extra = fresnel_records()
    h, h_table = h_records()
    eq8, eq8_table = eq8_records()
    records = fresnel + h + eq8
    payload = {
        "benchmark": "wolff",
        "command": "python benchmarks/bench_wolff.py",
        "machine": machine(),
        "records": records,
        "fresnel_polynomial": fresnel_extra,
        "h_function_error_vs_order": h_table,
        "eq8_error_vs_order": eq8_table,
        "geometries": N_GEOMETRIES,
    }
    path = write_json("wolff", payload)
    png = chart(records, h_table, fresnel_extra)
    for r in records:
        print(f"{r['family']:16s} {r['method']:34s} {r['seconds_per_evaluation']:.3e} s  rel.err {r['relative_error']:.3e}")
    print(f"wrote {path} and {png} in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
