"""Throughput of gonio's closed-form models against the same formulas as scalar C loops.

For each closed-form model: evaluations per second of ``gonio.brdf`` on 1e6 random
geometries, of the fixed-geometry path (``Model.at``, used by fitting), and of a scalar
C loop of the same formula compiled with ``cc -O2`` (benchmarks/c/closed_forms.c),
measured in the same run on the same inputs.  The C results double as an independent
implementation: the largest relative difference to gonio is recorded (it must be at
rounding level).

Run:  python benchmarks/closed_form_speed.py   (writes docs/benchmarks/closed_forms.json)
"""
from __future__ import annotations

import ctypes
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, best_time, machine, random_geometries, write_json  # noqa: E402

import gonio  # noqa: E402

N = 1_000_000
BUILD = ROOT / "benchmarks" / "_build"
SOURCE = ROOT / "benchmarks" / "c" / "closed_forms.c"

#: model name -> (C function, parameters for gonio, C scalar arguments after the arrays)
CASES = {
    "lambert": ("lambert", {"rho": 0.8}, lambda p: [p["rho"]]),
    "minnaert": ("minnaert", {"rho": 0.8, "k": 0.7}, lambda p: [p["rho"], p["k"]]),
    "phong": ("phong", {"rho_s": 0.3, "exponent": 20.0}, lambda p: [p["rho_s"], p["exponent"]]),
    "lambert+phong": (
        "lambert_phong", {"rho": 0.6, "rho_s": 0.3, "exponent": 20.0},
        lambda p: [p["rho"], p["rho_s"], p["exponent"]],
    ),
    "oren-nayar": (
        "oren_nayar", {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0},
        lambda p: [p["rho"], math.radians(p["sigma"]), p["ir_weight"]],
    ),
    "oren-nayar-qualitative": (
        "oren_nayar_qualitative", {"rho": 0.9, "sigma": 30.0},
        lambda p: [p["rho"], math.radians(p["sigma"]), 0.33],
    ),
}


def compile_library() -> ctypes.CDLL:
    """Compile the C loops with -O2 into a shared library and load it."""
    BUILD.mkdir(parents=True, exist_ok=True)
    library = BUILD / "closed_forms.so"
    subprocess.run(
        ["cc", "-O2", "-shared", "-fPIC", "-o", str(library), str(SOURCE), "-lm"], check=True
    )
    return ctypes.CDLL(str(library))


def c_caller(lib: ctypes.CDLL, function: str, radians: tuple[np.ndarray, ...], scalars: list[float]):
    """A zero-argument function running the C loop on the given geometry."""
    out = np.empty_like(radians[0])
    pointer = ctypes.POINTER(ctypes.c_double)
    arrays = [a.ctypes.data_as(pointer) for a in radians]
    c_function = getattr(lib, function)
    args = [ctypes.c_size_t(out.size), *arrays, *[ctypes.c_double(s) for s in scalars], out.ctypes.data_as(pointer)]

    def run() -> np.ndarray:
        c_function(*args)
        return out

    return run


def main() -> dict:
    lib = compile_library()
    geometry = random_geometries(N)
    radians = tuple(np.ascontiguousarray(np.radians(a)) for a in geometry)
    records, skipped = [], []
    for name, (function, params, scalars) in CASES.items():
        if name not in gonio.models.available():
            skipped.append(name)
            continue
        model = gonio.models.get(name)
        run_c = c_caller(lib, function, radians, scalars(params))
        reference = run_c().copy()
        ours = model(*geometry, **params)
        scale = np.maximum(np.abs(reference), 1e-300)
        finite = np.isfinite(reference) & np.isfinite(ours)
        max_rel = float(np.max(np.abs(ours[finite] - reference[finite]) / scale[finite]))
        fixed = model.at(*geometry)
        t_c = best_time(run_c, repeats=3)
        t_gonio = best_time(lambda: model(*geometry, **params), repeats=3)
        t_fixed = best_time(lambda: fixed(**params), repeats=3)
        record = {
            "family": "closed form",
            "model": name,
            "method": name,
            "seconds_per_evaluation": t_gonio / N,
            "relative_error": max_rel,
            "reference_method": "scalar C loop (cc -O2) of the same formula",
            "evaluations_per_second": N / t_gonio,
            "fixed_geometry_evaluations_per_second": N / t_fixed,
            "c_evaluations_per_second": N / t_c,
            "ratio_vs_c": t_c / t_gonio,
            "fixed_geometry_ratio_vs_c": t_c / t_fixed,
            "notes": "ratio > 1 means gonio is faster than the C loop",
        }
        records.append(record)
        print(
            f"{name:<24} gonio {N / t_gonio:11.3e}/s  fixed {N / t_fixed:11.3e}/s  C {N / t_c:11.3e}/s"
            f"  ratio {t_c / t_gonio:5.2f} (fixed {t_c / t_fixed:5.2f})  max rel diff {max_rel:.1e}"
        )
    payload = {
        "benchmark": "closed_forms",
        "command": "python benchmarks/closed_form_speed.py",
        "geometries": N,
        "machine": machine(),
        "records": records,
        "skipped_not_registered": skipped,
    }
    print(f"wrote {write_json('closed_forms', payload)}")
    return payload


if __name__ == "__main__":
    main()
