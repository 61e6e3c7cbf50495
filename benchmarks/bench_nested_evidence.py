"""The evidence of a nested candidate near its nesting point: Laplace, quadrature, sampling.

``pitted`` fitted to Lambertian data (relative radiance, 0.3 % noise, the draws of
``tests/fitting/test_adequacy.py``) is the case model choice meets on every smooth sample:
the data say the pits are shallow or few, not how shallow. Per draw: the least-squares
optimum, Laplace's corrected evidence as it stands (``conditional=False``: undefined where
the curvature is indefinite), the evidence a comparison uses (quadrature over the least
determined parameter where Laplace's Gaussian is missing or no description,
:func:`gonio.fitting.evidence.laplace_evidence`), and sequential Monte Carlo of the same
integrand as the reference, with the time of each.

Run: ``python benchmarks/bench_nested_evidence.py`` (about 5 minutes on one core); writes
``docs/benchmarks/bench_nested_evidence.json``.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings

from _common import ROOT, machine, write_json

sys.path.insert(0, str(ROOT))


def one_draw(seed: int, particles: int) -> dict:
    """Laplace, quadrature and sampling on ``pitted`` fitted to Lambertian draw ``seed``."""
    from gonio.fitting import FitProblem, fit_least_squares
    from gonio.fitting.evidence import laplace_evidence, tempered_evidence
    from gonio.fitting.mcmc import resolve_priors
    from tests.fitting.synthetic import synthetic_dataset

    data = synthetic_dataset("lambert", {"rho": 0.8}, noise=0.003, seed=seed, relative=True)
    problem = FitProblem("pitted", data)
    least_squares = fit_least_squares(problem)
    priors = resolve_priors(problem, least_squares.values, problem.priors_with_defaults(None))
    start = time.perf_counter()
    laplace = laplace_evidence(problem, least_squares, priors, conditional=False)
    laplace_seconds = time.perf_counter() - start
    start = time.perf_counter()
    used = laplace_evidence(problem, least_squares, priors)
    used_seconds = time.perf_counter() - start
    start = time.perf_counter()
    sampled = tempered_evidence(problem, priors, particles=particles)
    return {"seed": seed, "optimum": {n: least_squares.values[n] for n in ("rho", "psi", "coverage")},
            "stderr": {n: least_squares.stderr[n] for n in ("psi", "coverage")},
            "laplace": laplace.log_evidence, "laplace_seconds": laplace_seconds,
            "used": used.log_evidence, "quadrature_over": used.quadrature_over, "used_seconds": used_seconds,
            "smc": sampled.log_evidence, "smc_error": sampled.error, "smc_seconds": time.perf_counter() - start}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=7, help="draws 0 .. SEEDS-1 (default 7)")
    parser.add_argument("--particles", type=int, default=2000, help="sequential Monte Carlo particles")
    args = parser.parse_args()
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed in range(args.seeds):
            rows.append(one_draw(seed, args.particles))
            r = rows[-1]
            print(f"seed {seed}: psi {r['optimum']['psi']:.3g} coverage {r['optimum']['coverage']:.3g}: "
                  f"Laplace {r['laplace']:.3f}, used {r['used']:.3f} (over {r['quadrature_over']}, "
                  f"{r['used_seconds']:.1f} s), SMC {r['smc']:.3f} +- {r['smc_error']:.3f} ({r['smc_seconds']:.0f} s)",
                  flush=True)
    worst = max(abs(r["used"] - r["smc"]) for r in rows)
    print(f"largest |used - SMC|: {worst:.3f}")
    write_json("bench_nested_evidence", {"rows": rows, "largest_difference": worst, "machine": machine()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
