"""The sampled evidence (sequential Monte Carlo) against quadrature, nested sampling and Laplace.

``compare_models`` computes a candidate's evidence by sequential Monte Carlo
(:func:`gonio.fitting.evidence.tempered_evidence`) where Laplace's approximation is
undefined. This script measures it where the truth is known: on every case of
``benchmarks/bench_evidence.py`` (the same seeded data, the same likelihood and priors),
against the grid quadrature and the nested sampling that benchmark recorded in
``docs/benchmarks/evidence.json``; and on real data where Laplace fails, CUReT sample 10
(plaster_a) with the Oren-Nayar + Torrance-Sparrow candidate of ``gonio curet fit``,
against nested sampling run here (dynesty, ``pip install gonio[nested]``; skipped without
it or without the CUReT data). Each SMC estimate is timed (wall, this machine).

Run::

    python benchmarks/bench_smc_evidence.py      # docs/benchmarks/smc_evidence.json
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine, write_json  # noqa: E402
from bench_evidence import cases, laplace, nested_run  # noqa: E402

from gonio.fitting.evidence import tempered_evidence  # noqa: E402

COMMAND = "python benchmarks/bench_smc_evidence.py"


def synthetic_cases(recorded: dict[str, Any]) -> list[dict[str, Any]]:
    """SMC on every case of bench_evidence, beside its recorded quadrature and nested values."""
    rows = []
    for case in cases():
        problem = case.problem()
        lap = laplace(problem, case.priors)
        start = time.perf_counter()
        smc = tempered_evidence(problem, lap["_priors"])
        seconds = time.perf_counter() - start
        old = recorded.get(case.key, {})
        quadrature = (old.get("quadrature") or {}).get("log_evidence")
        nested = (old.get("nested") or {}).get("log_evidence")
        reference = quadrature if quadrature is not None else nested
        row = {"key": case.key, "title": case.title, "k": problem.ndim, "laplace": lap["log_evidence"],
               "smc": smc.log_evidence, "smc_error": smc.error, "stages": smc.stages,
               "evaluations": smc.evaluations, "seconds": seconds, "quadrature": quadrature, "nested": nested,
               "smc_minus_reference": smc.log_evidence - reference if reference is not None else None}
        print(f"{case.key:<36} k={problem.ndim}  SMC {smc.log_evidence:10.3f} +- {smc.error:.3f}  "
              f"reference {reference if reference is not None else math.nan:10.3f}  Laplace {lap['log_evidence']:10.3f}"
              f"  {seconds:5.1f} s", flush=True)
        rows.append(row)
    return rows


def curet_case() -> dict[str, Any] | None:
    """CUReT 10 with oren-nayar+torrance-sparrow and a jitter: Laplace undefined."""
    try:
        import dynesty  # noqa: F401

        from gonio.cli.curet import curet_dataset, load_curet
        from gonio.fitting.least_squares import fit_least_squares
        from gonio.fitting.mcmc import resolve_priors
        from gonio.fitting.problem import FitProblem
        from gonio.fitting.evidence import laplace_evidence

        dataset, _ = curet_dataset(load_curet(), 10)
    except (ImportError, OSError, ValueError) as error:
        print(f"CUReT case skipped: {error}")
        return None
    out: dict[str, Any] = {"key": "curet-10-oren-nayar+torrance-sparrow", "candidates": []}
    for model, fixed in (("oren-nayar", {"ir_weight": 1.0}), ("oren-nayar+torrance-sparrow", {})):
        problem = FitProblem(model, dataset, fixed, jitter=True)
        given = {k: v for k, v in problem.priors_with_defaults(None).items() if k in problem.free}
        ls = fit_least_squares(problem, n_starts=6, priors=given)
        priors = resolve_priors(problem, ls.values, given)
        start = time.perf_counter()
        smc = tempered_evidence(problem, priors)
        seconds = time.perf_counter() - start
        nested = nested_run(problem, priors, 0)
        row = {"model": model, "k": problem.ndim, "laplace": laplace_evidence(problem, ls, priors).log_evidence,
               "smc": smc.log_evidence, "smc_error": smc.error, "seconds": seconds,
               "nested": nested["log_evidence"], "nested_error": nested["error"], "nested_seconds": nested["seconds"]}
        print(f"CUReT 10 {model:<30} SMC {smc.log_evidence:.3f} +- {smc.error:.3f} ({seconds:.0f} s)  nested "
              f"{nested['log_evidence']:.3f} +- {nested['error']:.3f} ({nested['seconds']:.0f} s)  Laplace "
              f"{row['laplace']:.3f}", flush=True)
        out["candidates"].append(row)
    return out


def main() -> int:
    start = time.perf_counter()
    recorded = {c["key"]: c for c in json.loads((OUT / "evidence.json").read_text())["cases"]}
    payload = {"benchmark": "smc_evidence", "command": COMMAND, "machine": machine(),
               "cases": synthetic_cases(recorded), "curet": curet_case()}
    payload["wall_seconds"] = time.perf_counter() - start
    write_json("smc_evidence", payload)
    print(f"wrote {OUT / 'smc_evidence.json'} in {payload['wall_seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
