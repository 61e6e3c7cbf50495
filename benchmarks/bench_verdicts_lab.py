"""The three verdicts on the emulated rig at a real lab's precision (the default realism).

Each seed measures the calibration study's coverage protocol (benchmarks/calibration.py:
the Fig 16 sweep with the reflectance standard, one mounting) on the emulated rig with the
``lab`` realism (texture, a monitor that does not see the sample's beam exactly, misaligned
axes, stray light: docs/emulator.md), reduces it with its uncertainty budget and fits by
least squares with the rig's errors as parameters, as ``gonio fit --alignment all
--stray-light`` does, then records the verdict (gonio.fitting.adequacy). Scenes:

- ``formula``: sample ``oren-nayar`` (eq 33-35, rho 0.9, sigma 30 deg, ir_weight 1), fitted
  with ``oren-nayar``: the true model, its budget that of the rig (the one-mounting
  chi-square the calibration study found inflated: docs/calibration.md, section 3);
- ``exact``: sample ``oren-nayar-exact`` fitted with ``oren-nayar``: the paper's
  approximation of the true model, 5 % rms off at sigma = 30 deg;
- ``vgrooves``: a V-groove field rendered with every bounce fitted with
  ``oren-nayar-tabulated`` (the two-bounce V-cavity model).

Run::

    python benchmarks/bench_verdicts_lab.py             # docs/benchmarks/verdicts_lab.json
    python benchmarks/bench_verdicts_lab.py --seeds 3   # a quick look
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibration as study  # noqa: E402
from _common import machine, write_json  # noqa: E402

from gonio.fitting.adequacy import VERDICTS, assess  # noqa: E402
from gonio.fitting.least_squares import fit_least_squares  # noqa: E402
from gonio.fitting.problem import FitProblem  # noqa: E402

COMMAND = "python benchmarks/bench_verdicts_lab.py"
#: (key, sample spec, fitted model, fixed parameters).
SCENES = (
    ("formula", "oren-nayar:rho=0.9,sigma=30,ir_weight=1", "oren-nayar", {"ir_weight": 1.0}),
    ("exact", "oren-nayar-exact:rho=0.9,sigma=30", "oren-nayar", {"ir_weight": 1.0}),
    ("vgrooves", "surface:kind=vgrooves,sigma=30,rho=0.9", "oren-nayar-tabulated", {}),
)


def one_run(sample: str, model: str, fixed: dict, seed: int, scratch: Path) -> dict[str, Any]:
    """Measure, reduce, fit by least squares with the rig's errors, and judge."""
    from gonio.reduction import reduce_recording

    folder = scratch / f"run-{seed}"
    shutil.rmtree(folder, ignore_errors=True)
    study.measure(study.coverage_protocol_text(), sample, seed, folder)
    dataset, priors = reduce_recording(folder).fit_inputs(study.calibration())
    shutil.rmtree(folder, ignore_errors=True)
    problem = FitProblem(model, dataset, fixed, **study.rig_errors())
    given = {k: v for k, v in problem.priors_with_defaults(priors).items() if k in problem.free}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        least_squares = fit_least_squares(problem, priors=given, seed=seed)
    verdict = assess(problem, least_squares)
    lof = verdict.lack_of_fit
    return {"seed": seed, "verdict": verdict.verdict, "redchi": least_squares.redchi, "chi2_p": verdict.chi2_p,
            "lack_of_fit_p": lof.p if lof else None, "noise_factor": verdict.noise_factor,
            "values": {k: least_squares.values[k] for k in ("rho", "sigma")}}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args(argv)
    study.REALISM["spec"] = "lab"
    study.warm_up()
    start = time.perf_counter()
    scenes = []
    with tempfile.TemporaryDirectory() as scratch:
        for key, sample, model, fixed in SCENES:
            runs = [one_run(sample, model, fixed, seed, Path(scratch)) for seed in range(1, args.seeds + 1)]
            shares = {v: sum(r["verdict"] == v for r in runs) / len(runs) for v in VERDICTS}
            scenes.append({"key": key, "sample": sample, "model": model, "fixed": fixed, "shares": shares,
                           "median_redchi": float(np.median([r["redchi"] for r in runs])),
                           "median_noise_factor": float(np.nanmedian([r["noise_factor"] for r in runs])),
                           "runs": runs})
            print(f"{key:<10} {model:<22} " + "  ".join(f"{v} {shares[v]:.2f}" for v in VERDICTS)
                  + f"  median redchi {scenes[-1]['median_redchi']:.2f}", flush=True)
    payload = {"benchmark": "verdicts_lab", "command": COMMAND, "machine": machine(), "realism": "lab",
               "seeds": args.seeds, "scenes": scenes, "wall_seconds": time.perf_counter() - start}
    write_json("verdicts_lab", payload)
    print(f"wrote docs/benchmarks/verdicts_lab.json in {payload['wall_seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
