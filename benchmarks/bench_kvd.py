"""Koenderink-van Doorn series by order: speed and accuracy.

For orders 0-10 the Oren-Nayar model (rho = 0.8, sigma = 30 deg) is projected on the
isotropic KvD basis (KvD 1998 eq 29); each truncated series is then

* timed per geometry (plain call on random geometries, and the fixed-geometry path
  ``Model.at`` that fitting uses), as a ratio to the direct Oren-Nayar evaluation timed in
  the same run;
* compared with Oren-Nayar: relative L2 error over both hemispheres in the
  projected-solid-angle measure (cos theta_i cos theta_r dOmega_i dOmega_r) on a
  64 x 64 x 128 product quadrature, plus the error in the solid-angle measure of the
  paper's inner product and with Fejer damping, for the docs table.

It also draws the mirror/retroreflector truncations of KvD Figs 4-6 and, when the CUReT
files are present (gonio.curet.default_directory()), fits the named
samples by least squares (fit and held-out residuals per order).

Run:  python benchmarks/bench_kvd.py
Writes docs/benchmarks/kvd.json, kvd.png (time and error vs order) and kvd_lobes.png.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

# single-threaded BLAS: the series is a matrix-vector product per call, and on a shared
# machine thread start-up and contention dominated the timings of these small products.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from matplotlib.figure import Figure

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, best_time, machine, random_geometries, write_json  # noqa: E402

import gonio  # noqa: E402
from gonio.models import kvd  # noqa: E402
from gonio.curet import default_directory  # noqa: E402

ORDERS = list(range(11))
REFERENCE = ("oren-nayar", {"rho": 0.8, "sigma": 30.0})
N_GEOMETRIES = 20_000
QUADRATURE = {"n_theta": 64, "n_phi": 128}


def error_table(name: str, params: dict) -> dict:
    rows = {"orders": ORDERS, "projected": [], "solid_angle": [], "projected_fejer": [], "projection_seconds": []}
    for order in ORDERS:
        start = time.perf_counter()
        series = kvd.project(name, order, params, **QUADRATURE)
        rows["projection_seconds"].append(time.perf_counter() - start)
        rows["projected"].append(kvd.relative_l2_error(name, series, params, **QUADRATURE))
        rows["solid_angle"].append(kvd.relative_l2_error(name, series, params, measure="solid-angle", **QUADRATURE))
        rows["projected_fejer"].append(kvd.relative_l2_error(name, series.damped("fejer"), params, **QUADRATURE))
    return rows


def timing_records(errors: dict) -> list[dict]:
    name, params = REFERENCE
    ti, pi_, tr, pr = random_geometries(N_GEOMETRIES, seed=1)
    reference = gonio.models.get(name)
    t_ref = best_time(lambda: reference(ti, pi_, tr, pr, **params), repeats=3) / N_GEOMETRIES
    fixed_ref = reference.at(ti, pi_, tr, pr)
    t_ref_fixed = best_time(lambda: fixed_ref(**params), repeats=3) / N_GEOMETRIES
    records = [
        {
            "family": "kvd",
            "method": f"{name} direct",
            "seconds_per_evaluation": t_ref,
            "relative_error": 0.0,
            "reference_method": f"{name} direct",
            "notes": f"reference; fixed-geometry path {t_ref_fixed:.3g} s",
        }
    ]
    for order, error in zip(ORDERS, errors["projected"]):
        series = kvd.project(name, order, params, **QUADRATURE)
        model = series.model()
        t_call = best_time(lambda: model(ti, pi_, tr, pr), repeats=3) / N_GEOMETRIES
        fixed = model.at(ti, pi_, tr, pr)
        t_fixed = best_time(lambda: fixed(), repeats=3) / N_GEOMETRIES
        records.append(
            {
                "family": "kvd",
                "method": f"order {order}",
                "seconds_per_evaluation": t_call,
                "relative_error": error,
                "reference_method": f"{name} direct (rho=0.8, sigma=30 deg), projected-solid-angle L2 on a 64x64x128 grid",
                "notes": f"{len(series.modes)} modes; Model.at path {t_fixed:.3g} s/eval; time ratio to reference {t_call / t_ref:.3g}",
                "modes": len(series.modes),
                "seconds_per_evaluation_fixed_geometry": t_fixed,
                "time_ratio_to_reference": t_call / t_ref,
                "fixed_geometry_ratio_to_reference_fixed": t_fixed / t_ref_fixed,
            }
        )
    return records


def curet_fits() -> dict | None:
    from gonio.curet import read_curet

    folder = default_directory()
    if not (folder / "abrdf.dat").exists():
        return None
    data = read_curet(folder)
    rng = np.random.default_rng(0)
    permutation = rng.permutation(data.theta_i.size)
    test, train = permutation[:41], permutation[41:]
    table = {}
    for name in ("sandpaper", "velvet", "plaster_a", "plaster_b", "plaster_b zoomed"):
        s = data.sample(name)
        rows = []
        for order in (0, 2, 4, 6, 8):
            for lam in (0.0, 1e-5):
                full = kvd.fit_series(s.theta_i, s.phi_i, s.theta_r, s.phi_r, s.brdf, order, regularization=lam)
                part = kvd.fit_series(s.theta_i[train], s.phi_i[train], s.theta_r[train], s.phi_r[train], s.brdf[train], order, regularization=lam)
                predicted = part.coefficients.model()(s.theta_i[test], s.phi_i[test], s.theta_r[test], s.phi_r[test])
                held_out = float(np.sqrt(np.mean((predicted - s.brdf[test]) ** 2) / np.mean(s.brdf[test] ** 2)))
                rows.append({"order": order, "regularization": lam, "relative_rms_residual": full.relative_rms_residual,
                             "held_out_relative_rms": held_out})
        table[f"{s.number} {name}"] = rows
    return table


def lobes_figure() -> Path:
    theta = np.linspace(0.0, 90.0, 181)
    signed = np.concatenate([-theta[::-1], theta[1:]])  # forward (dphi = 180) negative

    def in_plane(series, theta_i):
        forward = series(theta_i, 0.0, theta[::-1], 180.0)
        backward = series(theta_i, 0.0, theta[1:], 0.0)
        return np.concatenate([forward, backward])

    lambert = kvd.lambert_coefficients(0.1)
    fig = Figure(figsize=(15, 4.2), layout="constrained")
    ax4, ax5, ax6 = fig.subplots(1, 3)
    for order in (0, 1, 2, 4, 6, 8):
        ax4.plot(signed, in_plane(kvd.mirror_coefficients(order) + lambert, 45.0), label=f"order {order}")
    ax4.plot(signed, in_plane(kvd.mirror_coefficients(8).damped("fejer") + lambert, 45.0), "k--", label="order 8, Fejer damped")
    ax4.set_title("Fig 4: mirror + Lambert 0.1, theta_i = 45 deg")
    for k, theta_i in enumerate((67.5, 45.0, 22.5)):
        ax5.plot(signed, in_plane(kvd.mirror_coefficients(8) + lambert, theta_i), f"C{k}", label=f"theta_i = {theta_i}")
        ax5.axvline(-theta_i, color=f"C{k}", lw=0.6, ls=":")
        ax6.plot(signed, in_plane(kvd.retroreflector_coefficients(8) + lambert, theta_i), f"C{k}", label=f"theta_i = {theta_i}")
        ax6.axvline(theta_i, color=f"C{k}", lw=0.6, ls=":")
    ax5.set_title("Fig 5: mirror + Lambert, order 8")
    ax6.set_title("Fig 6: retroreflector + Lambert, order 8")
    for ax in (ax4, ax5, ax6):
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_xlabel("signed viewing angle in the plane of incidence [deg] (+: source side)")
        ax.set_ylabel("truncated series [1/sr]")
        ax.legend(fontsize=7)
    fig.suptitle("Koenderink & van Doorn 1998, Figs 4-6 (in-plane sections of the truncated series)")
    path = OUT / "kvd_lobes.png"
    fig.savefig(path, dpi=100)
    return path


def summary_figure(records: list[dict], tables: dict) -> Path:
    fig = Figure(figsize=(11, 4.2), layout="constrained")
    ax_err, ax_time = fig.subplots(1, 2)
    for label, table in tables.items():
        ax_err.semilogy(table["orders"], table["projected"], "o-", label=f"{label}, projected-solid-angle L2")
        ax_err.semilogy(table["orders"], table["projected_fejer"], "s--", label=f"{label}, Fejer damped")
    ax_err.set_xlabel("series order N")
    ax_err.set_ylabel("relative L2 error vs the model [-]")
    ax_err.legend(fontsize=7)
    ax_err.grid(alpha=0.3, which="both")
    series_records = [r for r in records if r["method"].startswith("order")]
    orders = [int(r["method"].split()[1]) for r in series_records]
    ax_time.semilogy(orders, [r["seconds_per_evaluation"] for r in series_records], "o-", label="series, plain call")
    ax_time.semilogy(orders, [r["seconds_per_evaluation_fixed_geometry"] for r in series_records], "s-", label="series, Model.at path")
    ax_time.axhline(records[0]["seconds_per_evaluation"], color="k", ls="--", label="oren-nayar direct")
    ax_time.set_xlabel("series order N")
    ax_time.set_ylabel("time per evaluation [s]")
    ax_time.legend(fontsize=7)
    ax_time.grid(alpha=0.3, which="both")
    fig.suptitle("KvD series of Oren-Nayar: accuracy and cost by order")
    path = OUT / "kvd.png"
    fig.savefig(path, dpi=100)
    return path


def main() -> None:
    start = time.perf_counter()
    tables = {
        "oren-nayar rho=0.8 sigma=30": error_table(*REFERENCE),
        "oren-nayar rho=0.8 sigma=10": error_table("oren-nayar", {"rho": 0.8, "sigma": 10.0}),
        "minnaert rho=0.8 k=0.8": error_table("minnaert", {"rho": 0.8, "k": 0.8}),
    }
    records = timing_records(tables["oren-nayar rho=0.8 sigma=30"])
    payload = {
        "benchmark": "kvd",
        "command": "python benchmarks/bench_kvd.py",
        "machine": machine(),
        "records": records,
        "error_tables": tables,
        "curet_fits": curet_fits(),
        "n_geometries_timed": N_GEOMETRIES,
        "quadrature": QUADRATURE,
    }
    path = write_json("kvd", payload)
    print(f"wrote {path}, {summary_figure(records, tables)}, {lobes_figure()}")
    for label, table in tables.items():
        print(label)
        for order, e1, e2, e3 in zip(table["orders"], table["projected"], table["solid_angle"], table["projected_fejer"]):
            print(f"  order {order:2d}: projected {e1:.4f}  solid-angle {e2:.4f}  fejer {e3:.4f}")
    for r in records:
        print(f"{r['method']:>18s}: {r['seconds_per_evaluation']:.3g} s/eval, error {r['relative_error']:.4f}")
    print(f"total {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
