"""One BLAS thread in a fit against the library's default threads.

``gonio.fitting.fit`` limits the BLAS library to one thread while it fits
(``blas_threads=1``, threadpoolctl). This script measures what that buys on a fit whose
likelihood whitens correlated data (a Cholesky solve per walker and step): 947 values of
``oren-nayar`` at random geometries with 0.3 % independent noise and a 0.5 % common-mode
error (the shape of a rig recording's covariance), fitted with MCMC from the same seed,
``blas_threads=1`` against ``blas_threads=None`` (OpenBLAS's default: one thread per
core), alternated, three times each, while a busy-loop process keeps one core occupied
as other work on a shared 2-core machine does (``--quiet-machine`` leaves it out). Wall
and CPU time per fit (ratios of the medians), and the MCMC steps to convergence of every
run: with one thread they must not depend on anything but the seed.

Writes docs/benchmarks/blas_threads.json. Run: ``python benchmarks/bench_blas_threads.py``
(about three minutes).
"""
from __future__ import annotations

import argparse
import multiprocessing
import statistics
import time

import numpy as np

from _common import machine, write_json

import gonio
from gonio.fitting import Dataset, fit

N_VALUES = 947
REPEATS = 3


def correlated_dataset(seed: int = 0) -> Dataset:
    """947 values with independent and common-mode errors (module notes)."""
    rng = np.random.default_rng(seed)
    theta_i, theta_r = rng.uniform(0, 75, N_VALUES), rng.uniform(0, 75, N_VALUES)
    phi_r = rng.uniform(-180, 180, N_VALUES)
    truth = gonio.brdf("oren-nayar", theta_i, 0.0, theta_r, phi_r, rho=0.8, sigma=25.0, ir_weight=1.0)
    independent, common = 0.003 * truth, 0.005 * truth
    covariance = np.diag(independent**2) + np.outer(common, common)
    value = truth + np.linalg.cholesky(covariance) @ rng.standard_normal(N_VALUES)
    return Dataset(theta_i, 0.0, theta_r, phi_r, value, np.sqrt(np.diag(covariance)), covariance=covariance)


def _spin(stop) -> None:
    while not stop.is_set():
        sum(range(10_000))


def timed_fit(data: Dataset, threads: int | None) -> dict:
    wall, cpu = time.perf_counter(), time.process_time()
    result = fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, seed=7, blas_threads=threads)
    return {"threads": "default" if threads is None else threads, "wall_s": time.perf_counter() - wall,
            "cpu_s": time.process_time() - cpu, "steps": result.mcmc.n_steps,
            "converged": result.mcmc.converged, "sigma_median": result.posterior["median"]["sigma"]}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quiet-machine", action="store_true", help="no busy-loop process")
    args = parser.parse_args(argv)
    data = correlated_dataset()
    fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False)  # imports, compilation
    stop = multiprocessing.Event()
    busy = None if args.quiet_machine else multiprocessing.Process(target=_spin, args=(stop,), daemon=True)
    if busy is not None:
        busy.start()
    try:
        runs = []
        for _ in range(REPEATS):
            for threads in (1, None):
                runs.append(timed_fit(data, threads))
                print(runs[-1], flush=True)
    finally:
        stop.set()
        if busy is not None:
            busy.join()
    one = [r for r in runs if r["threads"] == 1]
    default = [r for r in runs if r["threads"] == "default"]
    payload = {
        "description": __doc__.split("\n\n")[0],
        "command": "python benchmarks/bench_blas_threads.py" + (" --quiet-machine" if args.quiet_machine else ""),
        "machine": machine(),
        "busy_core": not args.quiet_machine,
        "n_values": N_VALUES,
        "runs": runs,
        "wall_ratio_default_to_one": statistics.median(r["wall_s"] for r in default)
        / statistics.median(r["wall_s"] for r in one),
        "cpu_ratio_default_to_one": statistics.median(r["cpu_s"] for r in default)
        / statistics.median(r["cpu_s"] for r in one),
        "steps_one_thread": sorted({r["steps"] for r in one}),
        "steps_default_threads": sorted({r["steps"] for r in default}),
    }
    print({k: v for k, v in payload.items() if k.endswith(("ratio_default_to_one", "thread", "threads"))})
    print(write_json("blas_threads", payload))


if __name__ == "__main__":
    main()
