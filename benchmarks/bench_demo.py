"""Wall time of ``gonio demo``, the README's first quick-start command, in its own process.

``gonio demo --out FOLDER --quiet`` (what ``make demo`` runs, without the progress lines)
is timed as a command: wall time from its start to its exit, and CPU time (user +
system) of it and of every process it started. ``python -c "import numpy"`` is timed the
same way in the same run, before and after every demo, as the reference the demo's time
is given against (``ratio_to_import_numpy``). Every run starts when the 1-minute load
average is below :data:`QUIET_LOAD` (waiting at most :data:`QUIET_WAIT_S`), and the load
at its start is recorded. Target (issue "Scale"): the demo within
:data:`TARGET_S` of wall time on a quiet 2-core machine.

``--profile`` also runs the demo once under :mod:`cProfile` (in a separate process, not
timed) and records the functions of most cumulative time.

Writes docs/benchmarks/demo.json.
Run: ``python benchmarks/bench_demo.py [--repeats N] [--profile]``.
"""
from __future__ import annotations

import argparse
import os
import pstats
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, write_json  # noqa: E402

#: Target of issue "Scale" [s of wall time, quiet 2-core machine].
TARGET_S = 20.0
#: Largest 1-minute load average at which a timed run starts.
QUIET_LOAD = 0.7
#: Longest wait for that [s]; past it the run is made anyway, its load recorded.
QUIET_WAIT_S = 300.0
#: Rows of the profile kept (by cumulative time).
PROFILE_ROWS = 25
#: The demo's phases, by the function that runs each (file name, function name).
PHASES = {
    "measure (emulated rig, both protocols)": ("demo.py", "measure_demo"),
    "compare the candidates (least squares)": ("selection.py", "compare_models"),
    "MCMC of the chosen model": ("mcmc.py", "sample_posterior"),
    "save (result.json, chain.npz, posterior.nc)": ("results.py", "save"),
    "report (figures, report.html)": ("fit_report.py", "write_report"),
    "the rig's compiled radiance of the tabulated model (every caller)": ("compiled_rig.py", "rig_radiance_table"),
    "the table's error against the exact model (polish, every caller)": ("polish.py", "table_error"),
    "the aperture average's numpy path, model at the sub-rays (every caller)": ("instrument.py", "average"),
}


def wait_until_quiet(limit: float = QUIET_LOAD, longest: float = QUIET_WAIT_S) -> float:
    """Wait until the 1-minute load average is below ``limit`` (at most ``longest`` s);
    returns the load average then."""
    deadline = time.monotonic() + longest
    while os.getloadavg()[0] >= limit and time.monotonic() < deadline:
        time.sleep(2.0)
    return os.getloadavg()[0]


def command_times(command: list[str]) -> tuple[float, float, int]:
    """Wall time, CPU time of the process and its children [s], and its exit status."""
    before = os.times()
    start = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - start
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return wall, cpu, done.returncode


def demo_command(out: Path) -> list[str]:
    """The demo as ``make demo`` runs it (``python -m gonio``: the console script's code)."""
    return [sys.executable, "-m", "gonio", "demo", "--out", str(out), "--quiet"]


def profile(out: Path, rows: int = PROFILE_ROWS) -> tuple[list[dict], dict[str, float]]:
    """The demo once under cProfile: the ``rows`` functions of most cumulative time, and
    the cumulative time [s] of each of :data:`PHASES`."""
    stats_file = out.with_suffix(".prof")
    subprocess.run([sys.executable, "-m", "cProfile", "-o", str(stats_file), "-m", "gonio", "demo", "--out",
                    str(out), "--quiet"], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    stats = pstats.Stats(str(stats_file))
    entries, phases = [], {}
    for (filename, line, function), (_, calls, own, cumulative, _) in stats.stats.items():
        entries.append({"function": f"{Path(filename).name}:{line}({function})", "calls": calls,
                        "own_s": own, "cumulative_s": cumulative})
        for phase, where in PHASES.items():
            if where == (Path(filename).name, function):
                phases[phase] = phases.get(phase, 0.0) + cumulative
    entries.sort(key=lambda e: -e["cumulative_s"])
    phases["the whole demo (profiled)"] = stats.total_tt
    return entries[:rows], phases


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="demo runs (default 3)")
    parser.add_argument("--profile", action="store_true", help="also profile one demo run (cProfile)")
    args = parser.parse_args()
    walls, cpus, loads, numpy_runs, statuses = [], [], [], [], []
    with tempfile.TemporaryDirectory(prefix="gonio-demo-bench-") as scratch:
        for k in range(args.repeats):
            wait_until_quiet()
            numpy_runs.append(command_times([sys.executable, "-c", "import numpy"])[0])
            out = Path(scratch) / f"demo-{k}"
            loads.append(wait_until_quiet())
            wall, cpu, status = command_times(demo_command(out))
            walls.append(wall)
            cpus.append(cpu)
            statuses.append(status)
            shutil.rmtree(out, ignore_errors=True)
            numpy_runs.append(command_times([sys.executable, "-c", "import numpy"])[0])
            print(f"  demo {k + 1}/{args.repeats}: {wall:.1f} s wall, CPU {cpu:.1f} s, exit {status} "
                  f"(load {loads[-1]:.2f} at start)", flush=True)
        top, phases = profile(Path(scratch) / "profiled") if args.profile else (None, None)
    numpy_s = statistics.median(numpy_runs)
    wall = statistics.median(walls)
    payload = {
        "benchmark": "demo",
        "command": f"python benchmarks/bench_demo.py --repeats {args.repeats}" + (" --profile" if args.profile else ""),
        "demo_command": "python -m gonio demo --out FOLDER --quiet",
        "machine": machine(),
        "target_s": TARGET_S,
        "quiet_load_limit": QUIET_LOAD,
        "wall_s": wall,
        "wall_runs_s": walls,
        "cpu_s": statistics.median(cpus),
        "cpu_runs_s": cpus,
        "exit_status_runs": statuses,
        "load_average_at_start": loads,
        "import_numpy_s": numpy_s,
        "import_numpy_runs_s": numpy_runs,
        "ratio_to_import_numpy": wall / numpy_s,
        "within_target": wall <= TARGET_S,
    }
    if top is not None:
        payload["profile_phases_s"] = phases
        payload["profile_top_cumulative"] = top
        for phase, seconds in phases.items():
            print(f"  profile: {phase:66s} {seconds:6.1f} s")
    path = write_json("demo", payload)
    print(f"gonio demo: {wall:.1f} s wall (median of {args.repeats}), CPU {payload['cpu_s']:.1f} s; "
          f"python -c 'import numpy' {numpy_s:.3f} s; ratio {payload['ratio_to_import_numpy']:.0f}; "
          f"load at start {min(loads):.2f}-{max(loads):.2f}; target {TARGET_S:g} s: "
          f"{'met' if payload['within_target'] else 'NOT met'}")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
