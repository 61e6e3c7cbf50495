"""MCMC of the Fig 16 recording: steps and wall time to convergence against ensemble size.

``gonio fit`` stops when the chain is 50 autocorrelation times long and every
rank-normalised split R-hat (each walker a chain, after burn-in) is below 1.01.  This
script runs the same ``sample_posterior`` as ``gonio fit REC --model oren-nayar --fix
ir_weight=1`` on the shipped Fig 16 protocol measured on the embedded emulator, for
16 to 256 walkers and three seeds each, in one process (ArviZ imported first, so no
import time is counted), and records per run: steps to convergence, wall time, the
largest tau, the smallest bulk ESS, and the posterior median and sd of sigma.

Question (issue "Fast inference"): what sets the 3.9 s of MCMC of ``gonio fit``, and is
the default ensemble (256 walkers) right for the time to convergence?

Writes docs/benchmarks/walkers.json.  Run: ``python benchmarks/bench_walkers.py``.
"""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, write_json  # noqa: E402

PROTOCOL = ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"
GONIO = Path(sys.executable).with_name("gonio")
WALKERS = (16, 32, 64, 128, 256)
SEEDS = (0, 1, 2)


def run(recording: Path) -> list[dict]:
    from gonio.cli.fit import _load
    from gonio.fitting import FitProblem, fit_least_squares, sample_posterior
    from gonio.fitting.diagnostics import arviz

    arviz()
    dataset, priors = _load(recording, None)
    problem = FitProblem("oren-nayar", dataset, {"ir_weight": 1.0}, {}, False)
    least = fit_least_squares(problem, seed=0, priors=priors)
    sigma = problem.free.index("sigma")
    rows = []
    for walkers in WALKERS:
        for seed in SEEDS:
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # ArviZ on ensembles of more walkers than draws
                chain, _ = sample_posterior(problem, least, priors=priors, n_walkers=walkers, seed=seed)
            samples = chain.samples()[:, sigma]
            rows.append({"walkers": walkers, "seed": seed, "wall_s": time.perf_counter() - start,
                         "steps": chain.n_steps, "converged": chain.converged, "max_tau": float(np.max(chain.tau)),
                         "min_ess_bulk": min(d["ess_bulk"] for d in chain.diagnostics.values()),
                         "max_r_hat": max(d["r_hat"] for d in chain.diagnostics.values()),
                         "sigma_median": float(np.median(samples)), "sigma_sd": float(np.std(samples))})
            print(f"  {walkers:4d} walkers, seed {seed}: {rows[-1]['steps']} steps, {rows[-1]['wall_s']:.2f} s, "
                  f"tau {rows[-1]['max_tau']:.1f}, ESS {rows[-1]['min_ess_bulk']:.0f}", flush=True)
    return rows


def main() -> int:
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="gonio-walkers-") as scratch:
        recording = Path(scratch) / "plaster"
        subprocess.run([str(GONIO), "run", str(PROTOCOL), "--out", str(recording)], check=True, capture_output=True)
        rows = run(recording)
    summary = {}
    for walkers in WALKERS:
        mine = [r for r in rows if r["walkers"] == walkers]
        summary[str(walkers)] = {"median_wall_s": statistics.median(r["wall_s"] for r in mine),
                                 "median_steps": statistics.median(r["steps"] for r in mine),
                                 "seconds_per_step": statistics.median(r["wall_s"] / r["steps"] for r in mine),
                                 "median_min_ess_bulk": statistics.median(r["min_ess_bulk"] for r in mine),
                                 "steps_over_max_tau": statistics.median(r["steps"] / r["max_tau"] for r in mine)}
        print(f"{walkers:4d} walkers: {summary[str(walkers)]}")
    path = write_json("walkers", {
        "load_average_before_after": [load_before, os.getloadavg()[0]],
        "benchmark": "walkers",
        "command": "python benchmarks/bench_walkers.py",
        "machine": machine(),
        "fit": "gonio fit of the Fig 16 recording, --model oren-nayar --fix ir_weight=1 (90 values, 3 free parameters)",
        "runs": rows,
        "by_walkers": summary,
    })
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
