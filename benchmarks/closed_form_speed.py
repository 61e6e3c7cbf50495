"""Throughput of gonio's closed-form models against the same formulas as scalar C loops.

For each closed-form model: evaluations per second of ``gonio.brdf`` on 2e6 random
geometries, of the fixed-geometry path (``Model.at``, used by fitting), and of a scalar
C loop of the same formula (benchmarks/c/closed_forms.c) compiled twice, with ``cc -O2``
and with ``cc -O3 -march=native -ffast-math``, measured in the same run on the same
inputs.  The C results double as an independent implementation: the largest relative
difference to gonio is recorded (it must be at rounding level).

Targets (issue "Fast inference"): the plain call of ``oren-nayar`` at least 2.5 x the -O2
loop, agreement to 1e-12; the fixed-geometry path at least 0.5 x the -O3 fast-math loop.

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

N = 2_000_000
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
    "wolff": ("wolff", {"rho": 0.8, "n": 1.5}, lambda p: [p["rho"], p["n"]]),
    "kvd": (
        "kvd2", {"a_0_0_0": 1.6, "a_1_1_1": 0.1, "a_2_0_0": -0.2, "a_2_2_0": 0.05, "a_2_2_2": 0.03},
        lambda p: [p["a_0_0_0"], p["a_1_1_1"], p["a_2_0_0"], p["a_2_2_0"], p["a_2_2_2"]],
    ),
}


#: Compiler flags of the two C references.
FLAGS = {"O2": ["-O2"], "O3_native_fast_math": ["-O3", "-march=native", "-ffast-math"]}


def compile_library(key: str) -> ctypes.CDLL:
    """Compile the C loops with the flags ``FLAGS[key]`` into a shared library and load it."""
    BUILD.mkdir(parents=True, exist_ok=True)
    library = BUILD / f"closed_forms_{key}.so"
    subprocess.run(
        ["cc", *FLAGS[key], "-shared", "-fPIC", "-o", str(library), str(SOURCE), "-lm"], check=True
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
    lib = compile_library("O2")
    fast_lib = compile_library("O3_native_fast_math")
    geometry = random_geometries(N)
    radians = tuple(np.ascontiguousarray(np.radians(a)) for a in geometry)
    records, skipped = [], []
    for name, (function, params, scalars) in CASES.items():
        if name not in gonio.models.available():
            skipped.append(name)
            continue
        model = gonio.models.get(name)
        run_c = c_caller(lib, function, radians, scalars(params))
        run_fast = c_caller(fast_lib, function, radians, scalars(params))
        reference = run_c().copy()
        ours = model(*geometry, **params)
        scale = np.maximum(np.abs(reference), 1e-300)
        finite = np.isfinite(reference) & np.isfinite(ours)
        max_rel = float(np.max(np.abs(ours[finite] - reference[finite]) / scale[finite]))
        fixed = model.at(*geometry)
        t_c = best_time(run_c, repeats=3)
        t_fast = best_time(run_fast, repeats=3)
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
            "c_fast_math_evaluations_per_second": N / t_fast,
            "ratio_vs_c_fast_math": t_fast / t_gonio,
            "fixed_geometry_ratio_vs_c_fast_math": t_fast / t_fixed,
            "notes": "ratio > 1 means gonio is faster than the C loop",
        }
        records.append(record)
        print(
            f"{name:<24} gonio {N / t_gonio:11.3e}/s  fixed {N / t_fixed:11.3e}/s  C {N / t_c:11.3e}/s"
            f"  ratio {t_c / t_gonio:5.2f} (fixed {t_c / t_fixed:5.2f}; vs -O3 fast-math {t_fast / t_gonio:5.2f}, "
            f"fixed {t_fast / t_fixed:5.2f})  max rel diff {max_rel:.1e}"
        )
    payload = {
        "benchmark": "closed_forms",
        "command": "python benchmarks/closed_form_speed.py",
        "geometries": N,
        "machine": machine(),
        "records": records,
        "skipped_not_registered": skipped,
        "c_flags": {k: " ".join(v) for k, v in FLAGS.items()},
    }
    on = next((r for r in records if r["model"] == "oren-nayar"), None)
    if on is not None:
        payload["targets"] = {
            "oren-nayar plain call >= 2.5 x the -O2 loop": on["ratio_vs_c"] >= 2.5,
            "oren-nayar agrees with the C loop to 1e-12": on["relative_error"] <= 1e-12,
            "oren-nayar fixed geometry >= 0.5 x the -O3 fast-math loop": on["fixed_geometry_ratio_vs_c_fast_math"] >= 0.5,
        }
        print(f"targets: {payload['targets']}")
    print(f"wrote {write_json('closed_forms', payload)}")
    return payload


if __name__ == "__main__":
    main()
