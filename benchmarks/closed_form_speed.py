"""Throughput of gonio's closed-form models against the same formulas as scalar C loops.

For each closed-form model: evaluations per second of ``gonio.brdf`` on 2e6 random
geometries (for models with a compiled plain call, ``gonio.models._compiled``, both as a
process runs it once its numpy work has paid for loading it, and through the numpy path
of its first calls; the first call's cost in a fresh interpreter is recorded too), of
the fixed-geometry path (``Model.at``, used by fitting), and of a scalar
C loop of the same formula (benchmarks/c/closed_forms.c) compiled twice, with ``cc -O2``
and with ``cc -O3 -march=native -ffast-math``, measured in the same run on the same
inputs.  The C results double as an independent implementation: the largest relative
difference to gonio is recorded (it must be at rounding level).

Targets (issue "Fast inference"): the plain call of ``oren-nayar`` at least 2.5 x the -O2
loop, agreement to 1e-12; the fixed-geometry path at least 0.5 x the -O3 fast-math loop.
Issue "Scale": a one-off call, the first large call of a fresh interpreter (2e6 random
geometries, ``gonio.brdf("oren-nayar", ...)`` timed alone after ``import gonio``; best of
:data:`ONE_OFF_REPEATS` interpreters), at least 2.5 x the -O2 loop; timed also for the
revision ``--previous`` (default ``HEAD``, extracted with ``git archive``) and with the
compiled path taken at once (numba loading from its on-disk cache in that call).

Run:  python benchmarks/closed_form_speed.py [--previous REV]
(writes docs/benchmarks/closed_forms.json)
"""
from __future__ import annotations

import argparse
import ctypes
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, best_time, machine, random_geometries, write_json  # noqa: E402
from bench_call_overhead import revision_tree  # noqa: E402

import gonio  # noqa: E402
import gonio.models._core as core  # noqa: E402

N = 2_000_000
#: The library's own rule for when a process loads the compiled paths (changed below).
DEFAULT_AFTER = core.COMPILED_AFTER
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


FIRST_CALL = """
import time, numpy as np
start = time.perf_counter()
import gonio
import gonio.models._core as core
core.COMPILED_AFTER = {after}
imported = time.perf_counter()
theta = np.linspace(0.0, 89.0, {n})
gonio.brdf("oren-nayar", theta, 0.0, theta[::-1], 180.0, rho=0.9, sigma=30.0)
first = time.perf_counter()
gonio.brdf("oren-nayar", theta, 0.0, theta[::-1], 180.0, rho=0.9, sigma=30.0)
print(imported - start, first - imported, time.perf_counter() - first)
"""


def first_call_seconds(compiled: bool, cold: bool = False) -> dict[str, float]:
    """``import gonio`` and the first and second plain call of ``oren-nayar`` on
    COMPILED_MIN geometries in a fresh interpreter [s]: through the numpy path (as a
    process's first calls run), or through the compiled path with numba's on-disk cache
    as it is or empty (``cold``: the compiled loops are compiled in that call)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="gonio-numba-") as cache:
        env = dict(os.environ, **({"NUMBA_CACHE_DIR": cache} if cold else {}))
        code = FIRST_CALL.format(n=core.COMPILED_MIN, after=0 if compiled else DEFAULT_AFTER)
        done = subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True)
    imported, first, second = (float(v) for v in done.stdout.split())
    return {"import_gonio_s": imported, "first_call_s": first, "second_call_s": second}


ONE_OFF = """
import sys, time
sys.path.insert(0, {benchmarks!r})
from _common import random_geometries
geometry = random_geometries({n})
import gonio
import gonio.models._core as core
core.COMPILED_AFTER = {after}
seconds = []
for _ in range(2):
    start = time.perf_counter()
    gonio.brdf("oren-nayar", *geometry, rho=0.9, sigma=30.0)
    seconds.append(time.perf_counter() - start)
print(*seconds, gonio.__file__)
"""
#: Fresh interpreters per one-off measurement (the best is kept).
ONE_OFF_REPEATS = 5


def one_off_seconds(pythonpath: Path | None = None, compiled: bool = False) -> tuple[list[float], list[float]]:
    """The first and the second plain call of ``oren-nayar`` on the N random geometries of
    this script in fresh interpreters [s], one interpreter per repeat: the process's own
    rule for the compiled path (``compiled`` False: the numpy path), or the compiled path
    at once (numba and the cached loops load in the first call); ``gonio`` imported from
    ``pythonpath`` when given."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), env.get("PYTHONPATH", "")])
    code = ONE_OFF.format(benchmarks=str(Path(__file__).resolve().parent), n=N,
                          after=0 if compiled else DEFAULT_AFTER)
    # run from the revision's tree (``python -c`` puts the working directory first on sys.path)
    cwd = str(pythonpath) if pythonpath is not None else None
    first, second = [], []
    for _ in range(ONE_OFF_REPEATS):
        done = subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd, check=True, capture_output=True,
                              text=True)
        one, two, source = done.stdout.split()
        assert pythonpath is None or Path(source).is_relative_to(pythonpath), source
        first.append(float(one))
        second.append(float(two))
    return first, second


def one_off(t_c: float, previous: str | None) -> dict:
    """One-off first calls of this revision (numpy path and compiled path) and of the
    revision ``previous``, with their ratios to the -O2 loop's best time ``t_c`` [s]."""
    runs = {"numpy_path": one_off_seconds(), "compiled_path_warm_cache": one_off_seconds(compiled=True)}
    if previous:
        with revision_tree(previous) as tree:
            runs[f"previous_revision_{previous}"] = one_off_seconds(tree)
    return {label: {"seconds": first, "best_s": min(first), "ratio_vs_c": t_c / min(first),
                    "second_call_seconds": second, "second_call_ratio_vs_c": t_c / min(second)}
            for label, (first, second) in runs.items()}


def main(previous: str | None = "HEAD") -> dict:
    load_before = os.getloadavg()[0]
    # the plain call as a process makes it once its numpy work has paid for loading the
    # compiled paths (gonio.models._core.COMPILED_AFTER); the numpy path is timed as well
    core.COMPILED_AFTER = 0
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
        t_c = best_time(run_c, repeats=5)
        t_fast = best_time(run_fast, repeats=5)
        t_gonio = best_time(lambda: model(*geometry, **params), repeats=5)
        t_fixed = best_time(lambda: fixed(**params), repeats=5)
        core.COMPILED_AFTER = math.inf  # the numpy path, as the first calls of a process take it
        t_numpy = best_time(lambda: model(*geometry, **params), repeats=5)
        core.COMPILED_AFTER = 0
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
            "compiled_plain_call": model.compiled is not None,
            "numpy_path_evaluations_per_second": N / t_numpy,
            "numpy_path_ratio_vs_c": t_c / t_numpy,
            "notes": "ratio > 1 means gonio is faster than the C loop",
        }
        records.append(record)
        print(
            f"{name:<24} gonio {N / t_gonio:11.3e}/s  fixed {N / t_fixed:11.3e}/s  C {N / t_c:11.3e}/s"
            f"  ratio {t_c / t_gonio:5.2f} (fixed {t_c / t_fixed:5.2f}; vs -O3 fast-math {t_fast / t_gonio:5.2f}, "
            f"fixed {t_fast / t_fixed:5.2f}; numpy path {t_c / t_numpy:5.2f})  max rel diff {max_rel:.1e}"
        )
    payload = {
        # the machine is shared: 1-minute load averages before and after the run
        "load_average_before_after": [load_before, os.getloadavg()[0]],
        "benchmark": "closed_forms",
        "command": f"python benchmarks/closed_form_speed.py --previous {previous or repr('')}",
        "geometries": N,
        "machine": machine(),
        "records": records,
        "skipped_not_registered": skipped,
        "c_flags": {k: " ".join(v) for k, v in FLAGS.items()},
    }
    # what a user sees of the compiled path: numba loads (and, with an empty cache, compiles)
    # on the first call of COMPILED_MIN geometries or more
    payload["oren_nayar_first_call"] = {"numpy_path": first_call_seconds(compiled=False),
                                        "compiled_warm_cache": first_call_seconds(compiled=True),
                                        "compiled_cold_cache": first_call_seconds(compiled=True, cold=True)}
    print(f"oren-nayar first call of 16384 geometries: {payload['oren_nayar_first_call']}")
    on = next((r for r in records if r["model"] == "oren-nayar"), None)
    if on is not None:
        t_c = N / on["c_evaluations_per_second"]
        payload["oren_nayar_one_off_call"] = one_off(t_c, previous)
        for label, row in payload["oren_nayar_one_off_call"].items():
            print(f"oren-nayar one-off call of {N} geometries, {label}: best {row['best_s'] * 1e3:.1f} ms "
                  f"({row['ratio_vs_c']:.2f} x the -O2 loop; all {[round(t * 1e3, 1) for t in row['seconds']]} ms; "
                  f"second call {row['second_call_ratio_vs_c']:.2f} x)")
        payload["targets"] = {
            "oren-nayar one-off first call >= 2.5 x the -O2 loop":
                payload["oren_nayar_one_off_call"]["numpy_path"]["ratio_vs_c"] >= 2.5,
            "oren-nayar plain call >= 2.5 x the -O2 loop": on["ratio_vs_c"] >= 2.5,
            "oren-nayar agrees with the C loop to 1e-12": on["relative_error"] <= 1e-12,
            "oren-nayar fixed geometry >= 0.5 x the -O3 fast-math loop": on["fixed_geometry_ratio_vs_c_fast_math"] >= 0.5,
        }
        print(f"targets: {payload['targets']}")
    print(f"wrote {write_json('closed_forms', payload)}")
    return payload


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--previous", default="HEAD",
                        help="git revision whose one-off call is timed in the same run ('' for none)")
    main(parser.parse_args().previous or None)
