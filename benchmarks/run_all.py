"""Run every benchmark script, then draw the combined time-vs-error chart.

Run:  python benchmarks/run_all.py   (or ``make bench``)

Each script writes docs/benchmarks/<name>.json (and its own chart); this runner then calls
time_vs_error_chart.py, which puts every method of every model family on one chart:
docs/benchmarks/time_vs_error.png.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
NOT_BENCHMARKS = {"run_all.py", "time_vs_error_chart.py"}


def main() -> int:
    scripts = sorted(p for p in HERE.glob("*.py") if not p.name.startswith("_") and p.name not in NOT_BENCHMARKS)
    failed = []
    for script in scripts:
        print(f"== {script.name}", flush=True)
        start = time.perf_counter()
        result = subprocess.run([sys.executable, str(script)], cwd=HERE.parent)
        print(f"   ({time.perf_counter() - start:.1f} s, exit {result.returncode})", flush=True)
        if result.returncode:
            failed.append(script.name)
    subprocess.run([sys.executable, str(HERE / "time_vs_error_chart.py")], cwd=HERE.parent, check=True)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
