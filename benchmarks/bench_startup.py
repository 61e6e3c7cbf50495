"""Start-up time: ``import gonio`` (and the entry points users start from) against ``import numpy``.

Every import is timed in a fresh interpreter (``time.perf_counter`` around the import
statement, interpreter start-up excluded), several times, and the median is reported
beside the median of ``import numpy`` measured the same way in the same run: gonio's
target (issue "Fast inference") is ``import gonio`` within 0.3 s, and the ratio to numpy,
which ``import gonio`` includes, is what stays comparable across machines.

Two settings of the bytecode cache are measured:

* ``cached`` (what users see): compiled bytecode is written on a first import and read
  afterwards (into a temporary ``PYTHONPYCACHEPREFIX``, so the source tree stays clean);
* ``uncompiled``: ``PYTHONDONTWRITEBYTECODE=1`` and no cache, so every gonio module is
  compiled from source on each import (installed packages keep their own bytecode).

Also listed: the heavy libraries each entry point leaves in ``sys.modules`` (the test
``tests/test_startup.py`` holds ``import gonio`` to none of them), and, as the previous
method, ``import gonio`` of an earlier revision (``--previous``, default
:data:`PREVIOUS_REVISION`, the last one before imports were deferred) checked out into a
temporary git worktree and timed in the same run with the same cache setting.

Writes docs/benchmarks/startup.json and docs/benchmarks/startup.png.
Run: ``python benchmarks/bench_startup.py [--repeats N]``.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, ROOT, machine, write_json  # noqa: E402

#: Statements timed, by label (each in a fresh interpreter).
STATEMENTS = {
    "import numpy": "import numpy",
    "import gonio": "import gonio",
    "gonio.brdf, first call": "import gonio; gonio.brdf('oren-nayar', 45, 0, 30, 180, rho=0.9, sigma=30)",
    "gonio command-line parser": "from gonio.cli import build_parser; build_parser()",
    "import gonio.fitting": "import gonio.fitting",
    "import gonio.report.fit_report": "import gonio.report.fit_report",
}
#: Libraries whose presence in sys.modules is recorded.
HEAVY = ("scipy", "matplotlib", "numba", "emcee", "arviz", "pandas", "xarray")
#: The revision before scipy and importlib.metadata were deferred (``--previous``).
PREVIOUS_REVISION = "6ee9730"
#: The target of issue "Fast inference" [s].
TARGET_SECONDS = 0.3

_PROBE = """
import time
start = time.perf_counter()
{statement}
elapsed = time.perf_counter() - start
import json, sys
print(json.dumps({{"seconds": elapsed, "heavy": sorted({{m.split('.')[0] for m in sys.modules}} & set({heavy!r}))}}))
"""


def _environment(cache: str, prefix: str) -> dict[str, str]:
    """The child environment for a bytecode-cache setting (``cached`` or ``uncompiled``)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONDONTWRITEBYTECODE", "PYTHONPYCACHEPREFIX")}
    if cache == "cached":
        env["PYTHONPYCACHEPREFIX"] = prefix
    else:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def time_statement(statement: str, env: dict[str, str], cwd: Path = ROOT) -> dict:
    """One fresh-interpreter timing of ``statement`` run in ``cwd`` (first on ``sys.path``):
    seconds [s] and the heavy libraries loaded."""
    code = _PROBE.format(statement=statement, heavy=list(HEAVY))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env, cwd=cwd)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _previous_worktree(revision: str, folder: Path) -> Path:
    """Check ``revision`` out into ``folder`` (a detached git worktree) and return it."""
    subprocess.run(["git", "worktree", "add", "--detach", "--quiet", str(folder), revision], cwd=ROOT, check=True)
    return folder


def measure(repeats: int, previous: str | None) -> dict:
    """Median import times [s] of every statement in both cache settings, interleaved so
    that a change of machine load affects all alike."""
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="gonio-pycache-") as prefix, \
            tempfile.TemporaryDirectory(prefix="gonio-previous-") as scratch:
        old = _previous_worktree(previous, Path(scratch) / "tree") if previous else None
        try:
            for cache in ("cached", "uncompiled"):
                out[cache] = _measure_setting(_environment(cache, prefix), repeats, old, previous)
        finally:
            if old is not None:
                subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=ROOT, check=True)
    return out


def _measure_setting(env: dict[str, str], repeats: int, old: Path | None, previous: str | None) -> dict:
    """Median, min and max [s] of every statement (and of the previous revision's import)."""
    runs = [(label, statement, ROOT) for label, statement in STATEMENTS.items()]
    if old is not None:
        runs.append((f"import gonio at {previous} (previous)", "import gonio", old))
    for _, statement, cwd in runs:  # warm the bytecode and the file cache
        time_statement(statement, env, cwd)
    samples: dict[str, list[float]] = {label: [] for label, _, _ in runs}
    heavy = {}
    for _ in range(repeats):
        for label, statement, cwd in runs:
            one = time_statement(statement, env, cwd)
            samples[label].append(one["seconds"])
            heavy[label] = one["heavy"]
    numpy = statistics.median(samples["import numpy"])
    return {
        label: {"median_s": statistics.median(values), "min_s": min(values), "max_s": max(values),
                "ratio_to_numpy": statistics.median(values) / numpy, "heavy_modules_loaded": heavy[label]}
        for label, values in samples.items()
    }


def chart(results: dict, path: Path) -> None:
    """Horizontal bars of the median times, both cache settings, with the target line."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    labels = list(results["cached"])
    fig = Figure(figsize=(7.5, 3.6), layout="constrained")
    ax = fig.add_subplot()
    y = range(len(labels))
    for shift, (cache, colour) in zip((-0.2, 0.2), (("cached", "C0"), ("uncompiled", "C1"))):
        values = [results[cache][label]["median_s"] for label in labels]
        ax.barh([k + shift for k in y], values, height=0.38, color=colour, label=f"bytecode {cache}")
    ax.axvline(TARGET_SECONDS, color="k", ls="--", lw=1, label=f"target for import gonio ({TARGET_SECONDS} s)")
    ax.set_yticks(list(y), labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("median wall time in a fresh interpreter [s]")
    ax.set_title("Start-up: import times (interpreter start-up excluded)", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    fig.savefig(path, dpi=110)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="fresh interpreters per statement (default 7)")
    parser.add_argument("--previous", default=PREVIOUS_REVISION,
                        help=f"git revision timed as the previous method (default {PREVIOUS_REVISION}; '' for none)")
    args = parser.parse_args()
    load_before = os.getloadavg()
    results = measure(args.repeats, args.previous or None)
    cached = results["cached"]
    payload = {
        # the machine is shared: 1-minute load averages before and after the run
        "load_average_before_after": [load_before[0], os.getloadavg()[0]],
        "benchmark": "start-up",
        "command": f"python benchmarks/bench_startup.py --repeats {args.repeats}",
        "previous_revision": args.previous or None,
        "machine": machine(),
        "repeats": args.repeats,
        "target_import_gonio_s": TARGET_SECONDS,
        "import_gonio_within_target": cached["import gonio"]["median_s"] <= TARGET_SECONDS,
        "results": results,
    }
    path = write_json("startup", payload)
    chart(results, OUT / "startup.png")
    for cache, rows in results.items():
        print(f"bytecode {cache}:")
        for label, row in rows.items():
            print(f"  {label:40s} {row['median_s'] * 1e3:7.1f} ms  ({row['ratio_to_numpy']:.2f} x numpy)  "
                  f"loads: {', '.join(row['heavy_modules_loaded']) or '-'}")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
