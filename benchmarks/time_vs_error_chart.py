"""Combined chart: time per evaluation against relative error, every method of every family.

Reads the model-evaluation benchmarks' JSON in docs/benchmarks/ (:data:`MODEL_BENCHMARKS`;
records with ``family``, ``method``, ``seconds_per_evaluation`` and ``relative_error``) and
draws one panel per model family: what accuracy each method buys at what cost.

Run:  python benchmarks/time_vs_error_chart.py   (writes docs/benchmarks/time_vs_error.png)
"""
from __future__ import annotations

import json
import math
import sys
from collections import defaultdict
from pathlib import Path

from matplotlib.figure import Figure

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT  # noqa: E402

#: Errors below this are drawn at the floor (rounding-level agreement).
ERROR_FLOOR = 1e-16
#: Benchmarks whose records are methods of evaluating a model (speed against accuracy of
#: the same quantity).  Rig throughput, fitting and real-data fits write their own charts.
MODEL_BENCHMARKS = ("closed_forms", "oren_nayar", "tabulated", "wolff", "pitted", "kvd")


def load_records() -> dict[str, list[dict]]:
    families: dict[str, list[dict]] = defaultdict(list)
    for name in MODEL_BENCHMARKS:
        path = OUT / f"{name}.json"
        if not path.exists():
            print(f"note: {path.name} missing (run its benchmark); left off the chart")
            continue
        payload = json.loads(path.read_text())
        for record in payload.get("records", []):
            if {"family", "method", "seconds_per_evaluation", "relative_error"} <= set(record):
                families[record["family"]].append(record)
    return families


def main() -> Path:
    families = load_records()
    if not families:
        raise SystemExit("no benchmark records in docs/benchmarks/: run the benchmarks first")
    n = len(families)
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(5.4 * cols, 4.4 * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax, (family, records) in zip(axes, sorted(families.items())):
        for k, r in enumerate(records):
            err = max(float(r["relative_error"]), ERROR_FLOOR)
            ax.loglog(r["seconds_per_evaluation"], err, "o", color=f"C{k % 10}", ms=7)
            ax.annotate(r["method"], (r["seconds_per_evaluation"], err), fontsize=6,
                        xytext=(4, 3), textcoords="offset points")
        ax.set_title(family)
        ax.set_xlabel("time per evaluation [s]")
        ax.set_ylabel("relative error vs reference [-]")
        ax.grid(alpha=0.3, which="both")
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.suptitle("Speed vs accuracy of every method (lower left is better)")
    path = OUT / "time_vs_error.png"
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
