"""Batch fits on one worker against two: the speed-up of ``gonio fit-batch``.

The same batch, 8 synthetic samples x 3 models = 24 fits (``oren-nayar`` with
``ir_weight`` free and fixed at 1, ``minnaert``; 800 values per sample at random
geometries, 3 % noise; least squares and MCMC at gonio's defaults), is run by
:func:`gonio.batch.fit_many` with ``workers=1`` (every fit in this process, one after the
other) and with ``workers=2`` (two joblib/loky processes, each paying its start-up: the
interpreter, gonio's imports, numba's cache), each into a fresh folder. Reported: the wall
time of each run, their ratio, the summed wall time of the fits themselves, and whether
the two tables hold the same numbers (they must: one seed per task, one BLAS thread), and
the machine's one-minute load average before and after each run (on a shared machine,
other processes take part of the cores).

Writes docs/benchmarks/fit_batch.json and fit_batch.png. Run:
``python benchmarks/bench_fit_batch.py`` (about two minutes on 2 cores).
"""
from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import OUT, machine, write_json

import gonio
from gonio.batch import BatchSettings, fit_many
from gonio.fitting import Dataset

MODELS = ["oren-nayar", "oren-nayar:ir_weight=1", "minnaert"]
N_SAMPLES = 8
N_VALUES = 800
NOISE = 0.03


def sample(index: int) -> Dataset:
    """One synthetic Oren-Nayar sample (module notes)."""
    rng = np.random.default_rng(index)
    theta_i, theta_r = rng.uniform(0, 70, N_VALUES), rng.uniform(0, 70, N_VALUES)
    phi_r = rng.uniform(-180, 180, N_VALUES)
    rho, sigma = 0.5 + 0.05 * index, 10.0 + 4.0 * index
    truth = gonio.brdf("oren-nayar", theta_i, 0.0, theta_r, phi_r, rho=rho, sigma=sigma, ir_weight=1.0)
    value = truth * (1 + NOISE * rng.standard_normal(N_VALUES))
    return Dataset(theta_i, 0.0, theta_r, phi_r, value, NOISE * truth, label=f"sample-{index}")


def _numbers(rows: list[dict]) -> list:
    def clean(value):
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items() if k not in ("wall_seconds", "result_id")}
        return None if isinstance(value, float) and math.isnan(value) else value
    return [clean(row) for row in rows]


def run(workers: int, folder: Path) -> tuple[float, list[dict]]:
    """Wall time [s] and rows of the batch on ``workers`` processes."""
    inputs = {f"sample-{i}": sample(i) for i in range(N_SAMPLES)}
    start = time.perf_counter()
    batch = fit_many(inputs, MODELS, folder, workers=workers, settings=BatchSettings(), seed=0, overview=False)
    return time.perf_counter() - start, batch.rows


def chart(payload: dict, path: Path) -> None:
    """Wall time per run, and each fit's time, as a PNG."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.0, 3.2), layout="constrained")
    left, right = fig.subplots(1, 2)
    runs = payload["runs"]
    labels = [f"{r['workers']} worker{'s' if r['workers'] > 1 else ''}" for r in runs]
    left.bar(labels, [r["wall_seconds"] for r in runs], color=["C0", "C1"])
    for x, r in enumerate(runs):
        left.text(x, r["wall_seconds"], f"{r['wall_seconds']:.1f} s", ha="center", va="bottom")
    left.set_ylabel("batch wall time [s]")
    left.set_title(f"{payload['fits']} fits: speed-up {payload['speedup']:.2f}x", fontsize=10)
    for r, colour in zip(runs, ["C0", "C1"]):
        right.plot(sorted(r["fit_seconds"]), "o", ms=3, color=colour, label=f"{r['workers']} worker(s)")
    right.set_xlabel("fit (sorted)")
    right.set_ylabel("fit wall time [s]")
    right.legend(fontsize=8)
    fig.savefig(path, dpi=110)


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    runs, tables = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for workers in (1, 2):
            load = os.getloadavg()[0]  # other work on the machine shares its cores
            seconds, rows = run(workers, Path(tmp) / f"workers-{workers}")
            tables.append(_numbers(rows))
            fit_seconds = [row["wall_seconds"] for row in rows]
            runs.append({"workers": workers, "wall_seconds": seconds, "fit_seconds": fit_seconds,
                         "sum_fit_seconds": sum(fit_seconds), "failed": sum(r["status"] != "ok" for r in rows),
                         "load_average_before": load, "load_average_after": os.getloadavg()[0]})
            print(f"{workers} worker(s): {seconds:.1f} s wall, {sum(fit_seconds):.1f} s in fits")
    payload = {
        "description": __doc__.splitlines()[0],
        "command": "python benchmarks/bench_fit_batch.py",
        "fits": N_SAMPLES * len(MODELS), "models": MODELS, "values_per_fit": N_VALUES,
        "runs": runs, "speedup": runs[0]["wall_seconds"] / runs[1]["wall_seconds"],
        "same_numbers": tables[0] == tables[1], "target_speedup": 1.7, "machine": machine(),
    }
    print(f"speed-up {payload['speedup']:.2f}x (target 1.7x); same numbers: {payload['same_numbers']}")
    print(f"written: {write_json('fit_batch', payload)}")
    chart(payload, OUT / "fit_batch.png")


if __name__ == "__main__":
    main()
