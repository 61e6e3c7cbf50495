"""The demo sample on the idealised rig: the table alone against the table polished with the
exact model (gonio.fitting.polish), over 20 seeds.

Each seed measures the demo's protocols (Fig 16 and Fig 19 with the reflectance standard)
on the idealised emulated rig (``--realism ideal``: precision about 1e-4, no rig errors)
with the paper's wall plaster as the sample, the exact V-cavity model itself
(``oren-nayar-exact``, rho = 0.9, sigma = 30 deg), reduces the recordings as ``gonio demo``
does and fits ``oren-nayar-tabulated`` by least squares twice: with the polish switched
off, and as ``gonio fit`` does. Recorded per seed: the table's error at the data's
geometries in units of their uncertainties, and each fit's z-scores of rho and sigma
against the truth (least-squares standard errors); summarised as the share of 95 %
intervals (1.96 standard errors) holding the truth, with Wilson intervals.

Run::

    python benchmarks/bench_polish.py             # docs/benchmarks/polish.{json,png}
    python benchmarks/bench_polish.py --seeds 3   # a quick look
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, machine, wilson, write_json  # noqa: E402

from gonio.cli.demo import TRUTH, measure_demo  # noqa: E402
from gonio.fitting import fit  # noqa: E402
from gonio.fitting import polish as polish_module  # noqa: E402
from gonio.fitting.polish import table_error  # noqa: E402
from gonio.fitting.problem import FitProblem  # noqa: E402

COMMAND = "python benchmarks/bench_polish.py"


def z_scores(result) -> dict[str, float]:
    """(fitted - truth) / standard error of rho and sigma."""
    values, errors = result.least_squares.values, result.least_squares.stderr
    return {name: (values[name] - truth) / errors[name] for name, truth in TRUTH.items()}


def one_seed(seed: int, scratch: Path) -> dict[str, Any]:
    """Measure, reduce, and fit with and without the polish."""
    reduced = measure_demo(scratch / f"seed{seed}", seed, True, realism="ideal")
    dataset, priors = reduced.fit_inputs("common")
    limit = polish_module.POLISH_LIMIT
    polish_module.POLISH_LIMIT = float("inf")
    try:
        table = fit(dataset, "oren-nayar-tabulated", priors=priors, mcmc=False, jitter=False)
    finally:
        polish_module.POLISH_LIMIT = limit
    polished = fit(dataset, "oren-nayar-tabulated", priors=priors, mcmc=False, jitter=False)
    error = table_error(FitProblem("oren-nayar-tabulated", dataset), FitProblem("oren-nayar-exact", dataset),
                        table.least_squares.values)
    row = {"seed": seed, "table_error_in_sigma": error, "table": z_scores(table), "polished": z_scores(polished),
           "polished_flag": next((f for f in polished.flags if f.startswith("polished")), None)}
    print(f"seed {seed:2d}: table error {error:.2f} sigma; z table rho {row['table']['rho']:+.2f} sigma "
          f"{row['table']['sigma']:+.2f}; polished rho {row['polished']['rho']:+.2f} sigma "
          f"{row['polished']['sigma']:+.2f}", flush=True)
    return row



def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out = {}
    for fit_kind in ("table", "polished"):
        out[fit_kind] = {}
        for name in TRUTH:
            z = np.array([r[fit_kind][name] for r in rows])
            inside = int(np.sum(np.abs(z) < 1.96))
            out[fit_kind][name] = {"covered_95": inside, "seeds": len(z), "wilson": wilson(inside, len(z)),
                                   "z_mean": float(z.mean()), "z_sd": float(z.std(ddof=1)) if len(z) > 1 else None}
    out["median_table_error_in_sigma"] = float(np.median([r["table_error_in_sigma"] for r in rows]))
    return out


def chart(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), sharey=True)
    for ax, name in zip(axes, TRUTH):
        for offset, kind, colour in ((-0.12, "table", "#d9534f"), (0.12, "polished", "#5cb85c")):
            z = [r[kind][name] for r in rows]
            ax.scatter(np.arange(len(z)) + offset, z, s=14, color=colour, label=kind)
        ax.axhspan(-1.96, 1.96, color="0.9", zorder=0)
        ax.set_title(f"{name}: (fitted - truth) / standard error", fontsize=9)
        ax.set_xlabel("seed")
    axes[0].legend(fontsize=8)
    fig.suptitle("Demo sample on the idealised rig: oren-nayar-tabulated alone and polished with the exact model",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--summary-only", action="store_true",
                        help="recompute the summary and the chart from the seeds in docs/benchmarks/polish.json")
    args = parser.parse_args(argv)
    if args.summary_only:
        import json

        payload = json.loads((OUT / "polish.json").read_text())
        payload["summary"] = summarise(payload["seeds"])
        write_json("polish", payload)
        chart(payload["seeds"], OUT / "polish.png")
        return 0
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        rows = [one_seed(seed, Path(scratch)) for seed in range(args.seeds)]
    payload = {"benchmark": "polish", "command": COMMAND, "machine": machine(), "truth": TRUTH,
               "summary": summarise(rows), "seeds": rows, "wall_seconds": time.perf_counter() - start}
    write_json("polish", payload)
    chart(rows, OUT / "polish.png")
    for kind in ("table", "polished"):
        print(kind, {name: f"{s['covered_95']}/{s['seeds']}" for name, s in payload["summary"][kind].items()})
    print(f"wrote {OUT / 'polish.json'} and polish.png in {payload['wall_seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
