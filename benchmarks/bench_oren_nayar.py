"""Oren-Nayar family: time per geometry against relative error, every method.

Methods:

* ``oren-nayar-exact`` at every accuracy setting ``rtol`` (eq 8 integrated over facet
  normals with the exact GAF and two-bounce interreflection);
* ``oren-nayar-numerical`` (eq 31 as the paper evaluated it);
* ``oren-nayar`` (functional approximation eq 33-35) and ``oren-nayar-qualitative``
  (eq 36).

Reference: ``oren-nayar-exact`` at its tightest setting (rtol = 1e-7), computed in the
same run on the same geometries.  Error = largest |model / reference - 1| over 300 random
geometries (theta up to 89.9 deg, random azimuths) and sigma in {10, 30} deg, rho = 0.9;
the RMS is in the notes.  Time = best of 3 wall-clock runs over all geometries, per
geometry, single thread.

Run:  python benchmarks/bench_oren_nayar.py
Writes docs/benchmarks/oren_nayar.json and docs/benchmarks/oren_nayar.png.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, best_time, machine, random_geometries, write_json  # noqa: E402

import gonio  # noqa: E402
from gonio.models.oren_nayar.exact import RTOL_CHOICES  # noqa: E402

N_GEOMETRIES = 300
SIGMAS = [10.0, 30.0]
RHO = 0.9
TIGHTEST = min(RTOL_CHOICES)
REFERENCE = f"oren-nayar-exact rtol={TIGHTEST:g}"


def evaluate(method: str, angles, sigma: float, **options) -> np.ndarray:
    return gonio.brdf(method, *angles, rho=RHO, sigma=sigma, **options)


def measure(method: str, label: str, angles, references, notes: str, **options) -> dict:
    errors, seconds = [], 0.0
    for sigma, reference in zip(SIGMAS, references):
        seconds += best_time(lambda: evaluate(method, angles, sigma, **options), repeats=3, min_time=0.0)
        errors.append(evaluate(method, angles, sigma, **options) / reference - 1.0)
    error = np.concatenate(errors)
    per_geometry = seconds / (len(SIGMAS) * angles[0].size)
    rms = float(np.sqrt(np.mean(error**2)))
    print(f"{label:34s} {per_geometry * 1e3:9.4f} ms/geometry   max rel err {np.max(np.abs(error)):.2e}"
          f"   rms {rms:.2e}", flush=True)
    return {
        "family": "oren-nayar",
        "method": label,
        "seconds_per_evaluation": per_geometry,
        "relative_error": float(np.max(np.abs(error))),
        "rms_relative_error": rms,
        "reference_method": REFERENCE,
        "notes": notes,
    }


def chart(records: list[dict], path: Path) -> None:
    figure = Figure(figsize=(7.0, 4.8), constrained_layout=True)
    axes = figure.add_subplot()
    for record in records:
        exact = record["method"].startswith("oren-nayar-exact")
        if record["relative_error"] == 0.0:  # the reference itself: show its cost only
            axes.axvline(record["seconds_per_evaluation"], color="C0", ls="--", lw=0.8)
            axes.annotate(f"reference ({record['method']})", (record["seconds_per_evaluation"], 1e-7),
                          rotation=90, fontsize=7, ha="right")
            continue
        error = record["relative_error"]
        axes.loglog(record["seconds_per_evaluation"], error, "o" if exact else "s",
                    color="C0" if exact else "C1")
        axes.annotate(record["method"].replace("oren-nayar-exact ", ""), (record["seconds_per_evaluation"], error),
                      textcoords="offset points", xytext=(4, 3), fontsize=7)
    axes.set_xlabel("time per geometry [s]")
    axes.set_ylabel(f"max relative error vs {REFERENCE}")
    axes.set_title(f"Oren-Nayar: {N_GEOMETRIES} random geometries, sigma in {SIGMAS} deg, rho = {RHO}")
    axes.grid(True, which="both", alpha=0.3)
    figure.savefig(path, dpi=120)


def main() -> None:
    start = time.perf_counter()
    angles = random_geometries(N_GEOMETRIES, seed=2024)
    references = [evaluate("oren-nayar-exact", angles, sigma, rtol=TIGHTEST) for sigma in SIGMAS]
    records = []
    for rtol in sorted(RTOL_CHOICES, reverse=True):
        records.append(measure(
            "oren-nayar-exact", f"oren-nayar-exact rtol={rtol:g}", angles, references,
            "V-cavity model, eq 8 with exact GAF (eq 15) and interreflection (eq 22-24); "
            "panels between critical angles (eq 39), Gauss-Legendre, vectorised over geometries"
            + ("; this is the reference itself (timing only)" if rtol == TIGHTEST else ""),
            rtol=rtol,
        ))
    records.append(measure("oren-nayar-numerical", "oren-nayar-numerical", angles, references,
                           "eq 31 with closed form eq 45 (eq 44 interpolation) and eq 49"))
    records.append(measure("oren-nayar", "oren-nayar", angles, references, "functional approximation eq 33-35"))
    records.append(measure("oren-nayar-qualitative", "oren-nayar-qualitative", angles, references,
                           "qualitative model eq 36 (no C3, no interreflection)"))
    seconds = time.perf_counter() - start
    payload = {
        "benchmark": "oren_nayar",
        "command": "python benchmarks/bench_oren_nayar.py",
        "machine": machine(),
        "records": records,
        "n_geometries": N_GEOMETRIES,
        "sigma_deg": SIGMAS,
        "rho": RHO,
        "seconds": seconds,
    }
    write_json("oren_nayar", payload)
    chart(records, OUT / "oren_nayar.png")
    print(f"wrote docs/benchmarks/oren_nayar.json and .png in {seconds:.0f} s")


if __name__ == "__main__":
    main()
