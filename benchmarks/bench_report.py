"""Speed of the fit report, and where the time of ``gonio fit ... --report`` goes.

1. **Report against the number of measurements.** Oren-Nayar (rho = 0.8, sigma = 25 deg,
   interreflection weight 1) is fitted, least squares then a 2000-step MCMC chain, to
   200, 1,000 and 10,000 BRDF values with 2 % noise at random geometries, every value at
   an incidence of its own (image-based data such as CUReT: the worst case for a figure
   that draws per incidence). For each fit: the wall time of
   :func:`gonio.report.fit_report.write_report` (the five figures as PNG plus the HTML),
   and of each figure (built and rendered to PNG). The previous method, the figure code of
   revision :data:`PREVIOUS_REVISION` (one artist per incidence, one posterior draw set per
   model band, a constrained layout pass) read from git, is timed in the same run on the
   same fits up to ``--previous-max`` measurements (default 1,000: at 10,000 it takes
   minutes). ``write_report`` is timed in this process, and so is the ``gonio report``
   command (a fresh process each time). Target (issue "Fast inference"): a 10,000-point
   fit's report within 2 s; the ratio to the 200-point report says whether the cost
   grows with the data.

2. **``gonio fit`` of the Fig 16 recording with ``--report``.** The shipped protocol is run
   on the embedded emulator (``gonio run protocols/oren-nayar-fig16-plaster.toml``), then
   ``gonio fit REC --model oren-nayar --fix ir_weight=1 --report --quiet`` is timed as a
   command (wall and CPU time of the process), and again phase by phase in a fresh interpreter
   (``--phases``, the same steps as ``gonio.cli.fit``): start-up of the command line, the
   heavy imports (scipy.optimize and emcee, which imports scipy.stats; ArviZ's numpy core
   arviz_stats.base with h5netcdf; matplotlib for the report), the reduction of the
   recording, least squares, MCMC, the result's summary, saving it (result.json,
   chain.npz, posterior.nc) and the report, each with its wall and CPU time (the CPU
   time is what other jobs on a shared machine inflate least). ``python -c pass`` and
   ``import numpy`` are timed the same way as the
   references, and so is a fixed pure-Python workload (:data:`PACE_REFERENCE`), whose
   time tells the machine's pace in the run (``ratio_to_pace_reference``). Target: at
   most 2.5 s wall.

   gonio's bytecode is compiled before the timings (``compileall``), as it is after a
   first run of any program that may write it, after a non-editable ``pip install`` and
   by the Makefile's install; what compiling the modules the command loads from source
   would add at every start (an editable install where ``PYTHONDONTWRITEBYTECODE`` is
   set) is measured on its own (``source_compile_s``). So is the interpreter's exit
   after the work, with the final garbage collection and after ``gc.freeze()`` (what
   ``gonio.cli.run`` does), in a process that has loaded what the command loads.

3. **The report workers** (``--workers-decision``): the fork-server report workers that
   ``gonio fit --report`` used by default (``gonio.report.workers``, removed since),
   against one process, on the default path, same run, alternating, on a quiet machine
   (:func:`default_path_decision`), timed on the code of :data:`WORKERS_REVISION`, the
   last revision that had them. The result is merged into report.json
   (``report_workers_decision``).

Medians of ``--repeats`` runs. Writes docs/benchmarks/report.json and report.png.
Run: ``python benchmarks/bench_report.py [--repeats N] [--previous-max N]``, or
``python benchmarks/bench_report.py --workers-decision [--repeats N]``.
"""
from __future__ import annotations

import argparse
import compileall
import io
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import types
import warnings
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, ROOT, machine, random_geometries, write_json  # noqa: E402

#: Sizes of the benchmark fits (measurements, each at its own incidence).
SIZES = (200, 1000, 10000)
#: The figure code timed as the previous method (before figures stopped growing with the
#: number of incidences).
PREVIOUS_REVISION = "f06a8d8"
#: Targets of issue "Fast inference" [s].
REPORT_TARGET_S = 2.0
FIT_TARGET_S = 2.5
#: The recording's protocol and the command timed.
PROTOCOL = ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"
FIT_ARGUMENTS = ("--model", "oren-nayar", "--fix", "ir_weight=1", "--report", "--quiet")
#: The machine's pace, timed between the commands in a fresh interpreter: pure Python
#: work of the kind the command's imports and sampling loop are made of (bytecode,
#: small objects), fixed from run to run. The command's wall time over this one's
#: compares runs made while the shared machine went at different speeds.
PACE_REFERENCE = "d = {}\nfor i in range(1_500_000):\n    d[i % 1000] = (i, str(i & 255))"
#: The PNG resolution of gonio.report.fit_report [dpi].
DPI = 110
GONIO = Path(sys.executable).with_name("gonio")


# ----------------------------------------------------------------------- report vs size
def benchmark_fit(n: int):
    """Oren-Nayar fitted to ``n`` noisy BRDF values at random geometries (2000 MCMC steps)."""
    import gonio
    from gonio.fitting import ConvergenceWarning, Dataset, fit

    geometry = random_geometries(n, seed=n, max_theta=85.0)
    truth = gonio.brdf("oren-nayar", *geometry, rho=0.8, sigma=25.0, ir_weight=1.0)
    sigma = 0.02 * truth + 1e-4
    rng = np.random.default_rng(1)
    data = Dataset(*geometry, truth + sigma * rng.standard_normal(n), sigma, label=f"{n} random geometries")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # the chain's length is fixed here
        warnings.simplefilter("ignore", UserWarning)  # ArviZ on ensembles of more walkers than steps
        return fit(data, "oren-nayar", fixed={"ir_weight": 1.0}, max_steps=2000, seed=0)


def previous_figures(revision: str) -> types.ModuleType:
    """The figure module ``gonio/report/fit_figures.py`` of ``revision``, read from git."""
    source = subprocess.run(["git", "show", f"{revision}:gonio/report/fit_figures.py"], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout
    module = types.ModuleType("previous_fit_figures")
    module.__file__ = f"{revision}:gonio/report/fit_figures.py"
    sys.modules[module.__name__] = module  # dataclasses look their module up there
    exec(compile(source, module.__file__, "exec"), module.__dict__)
    return module


def figure_seconds(make: Callable, result) -> float:
    """Wall time [s] to build one figure and render it to PNG as the report does."""
    start = time.perf_counter()
    make(result).savefig(io.BytesIO(), format="png", dpi=DPI)
    return time.perf_counter() - start


def time_figures(module, result, repeats: int) -> dict[str, float]:
    """Median seconds of each of the report's figures made by ``module``."""
    from gonio.report.fit_html import FIGURES

    return {figure.file: statistics.median(figure_seconds(getattr(module, figure.function), result)
                                           for _ in range(repeats))
            for figure in FIGURES}


def _cpu_with_children() -> float:
    """CPU time [s] of this process and its ended child processes (user + system)."""
    now = os.times()
    return now.user + now.system + now.children_user + now.children_system


def time_write_report(result, repeats: int) -> tuple[float, float, float]:
    """Median wall time, median CPU time and least wall time [s] of write_report (figures,
    PNG files and HTML) into a scratch folder. On a shared machine the CPU time and the
    least wall time are what other jobs inflate least."""
    from gonio.report.fit_report import write_report

    wall, cpu = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="gonio-report-") as folder:
            start, start_cpu = time.perf_counter(), _cpu_with_children()
            write_report(result, folder)
            wall.append(time.perf_counter() - start)
            cpu.append(_cpu_with_children() - start_cpu)
    return statistics.median(wall), statistics.median(cpu), min(wall)


def report_command(result, repeats: int) -> dict[str, float]:
    """``gonio report FOLDER --out OUT`` of the saved ``result`` as a command (a fresh
    process each time): medians of wall and CPU time [s]."""
    times, cpus = [], []
    with tempfile.TemporaryDirectory(prefix="gonio-report-command-") as scratch:
        folder = Path(scratch) / "fit"
        result.save(folder)
        for _ in range(repeats):
            out = Path(scratch) / "report"
            wall, cpu = command_times([str(GONIO), "report", str(folder), "--out", str(out)])
            times.append(wall)
            cpus.append(cpu)
            shutil.rmtree(out)
    return {"report_command_s": statistics.median(times), "report_command_cpu_s": statistics.median(cpus)}


def report_scaling(repeats: int, previous_max: int) -> list[dict]:
    """Report and figure times of the current and the previous code for every size."""
    from gonio.report import fit_figures

    previous = previous_figures(PREVIOUS_REVISION)
    rows = []
    for n in SIZES:
        start = time.perf_counter()
        result = benchmark_fit(n)
        fit_seconds = time.perf_counter() - start
        figures = time_figures(fit_figures, result, repeats)
        loads = [os.getloadavg()[0]]
        wall, cpu, least = time_write_report(result, repeats)
        command = report_command(result, repeats)
        loads.append(os.getloadavg()[0])
        row = {"n": n, "incidences": len(result.dataset.incidences()[0]), "walkers": result.mcmc.n_walkers,
               "steps": result.mcmc.n_steps, "fit_s": fit_seconds, "write_report_s": wall, "write_report_cpu_s": cpu,
               "write_report_min_s": least, **command,
               "load_average_before_after": loads,
               "figures_s": figures, "figures_total_s": sum(figures.values())}
        if n <= previous_max:
            old = time_figures(previous, result, repeats)
            row.update(previous_figures_s=old, previous_figures_total_s=sum(old.values()),
                       speed_up_of_figures=sum(old.values()) / sum(figures.values()))
        rows.append(row)
        print(f"  {n:6d} points: report {wall:.2f} s (CPU {cpu:.2f} s; figures {row['figures_total_s']:.2f} s); "
              f"gonio report {command['report_command_s']:.2f} s (CPU {command['report_command_cpu_s']:.2f} s; "
              f"load {loads[0]:.1f}-{loads[1]:.1f})"
              + (f", previous figures {row['previous_figures_total_s']:.2f} s" if "previous_figures_s" in row else ""),
              flush=True)
    for row in rows:
        row["ratio_to_smallest_report"] = row["write_report_s"] / rows[0]["write_report_s"]
    return rows


# --------------------------------------------------------------- gonio fit --report
#: The emulated sample of the timed recording: the model the command fits, so that the fit
#: is adequate and the command's work is the same in every run (``gonio run``'s default
#: sample is the exact V-cavity model, which the approximation does not fit).
SAMPLE = "oren-nayar:sigma=30,rho=0.9"


def make_recording(folder: Path) -> Path:
    """The Fig 16 protocol measured on the embedded emulator (seed 0, :data:`SAMPLE`) into
    ``folder/plaster``."""
    recording = folder / "plaster"
    subprocess.run([str(GONIO), "run", str(PROTOCOL), "--out", str(recording), "--sample", SAMPLE], check=True,
                   capture_output=True)
    return recording


def command_seconds(command: list[str]) -> float:
    """Wall time [s] of a process, from its start to its exit."""
    return command_times(command)[0]


def become_subreaper() -> bool:
    """Make this process adopt its orphaned descendants (Linux ``PR_SET_CHILD_SUBREAPER``),
    so that the CPU time of a command's fork server and of the report workers it forked
    (:data:`WORKERS_REVISION`), which outlive the command by a moment, is counted in
    :func:`command_times`."""
    import ctypes

    try:
        return ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) == 0  # PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):
        return False


def _reap_descendants(seconds: float = 5.0) -> None:
    """Wait for the adopted descendants of the last command (see become_subreaper)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            time.sleep(0.01)


def command_times(command: list[str], environment: dict[str, str] | None = None) -> tuple[float, float]:
    """Wall time and CPU time (user + system, of the process and its descendants) [s] of a
    process, from its start to its exit, with ``environment`` added to this one's."""
    before = os.times()
    start = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True, env={**os.environ, **(environment or {})})
    wall = time.perf_counter() - start
    _reap_descendants()
    after = os.times()
    return wall, (after.children_user - before.children_user) + (after.children_system - before.children_system)


def _timed(phases: dict[str, float], name: str, step: Callable):
    """Run ``step``; record its wall time under ``name`` and its CPU time under ``name + CPU``."""
    start, start_cpu = time.perf_counter(), time.process_time()
    value = step()
    phases[name] = time.perf_counter() - start
    phases[name + CPU] = time.process_time() - start_cpu
    return value


#: Suffix of the CPU-time entries of a phase table.
CPU = " [CPU]"


def run_phases(recording: str, out: str) -> dict:
    """``gonio fit RECORDING ... --report`` step by step: ``{"phases": {step: seconds},
    "points": number of values fitted}``.

    The steps are those of ``gonio.cli.fit`` (with its argument defaults); the heavy
    libraries are imported first, each on its own, so that the later steps are free of
    import time.
    """
    phases: dict[str, float] = {}
    args = _timed(phases, "command line (gonio.cli, parser)", lambda: _parse([recording, *FIT_ARGUMENTS, "--out", out]))
    _timed(phases, "import scipy.optimize, emcee (scipy.stats)", _import_sampler)
    _timed(phases, "import arviz_stats (ArviZ's R-hat and ESS), h5netcdf", _import_diagnostics)
    _timed(phases, "import matplotlib, gonio.report", lambda: __import__("gonio.report.fit_report"))
    from gonio.analysis import load_data
    from gonio.fitting import FitProblem, FitResult, fit_least_squares, sample_posterior
    from gonio.report.fit_report import write_report

    dataset, priors = _timed(phases, "reduce the recording", lambda: load_data(Path(recording)))
    problem = FitProblem("oren-nayar", dataset, {"ir_weight": 1.0}, {}, False)
    least = _timed(phases, "least squares", lambda: fit_least_squares(problem, seed=args.seed, priors=priors))
    chain, used = _timed(phases, "MCMC", lambda: sample_posterior(
        problem, least, priors=priors, n_walkers=args.walkers, max_steps=args.max_steps,
        rhat_limit=args.rhat_limit, seed=args.seed))
    result = _timed(phases, "result and summary", lambda: _summarised(FitResult.build(problem, least, chain, used)))
    _timed(phases, "save (result.json, chain.npz, posterior.nc)", lambda: result.save(out))
    _timed(phases, "report", lambda: write_report(out))
    compile_seconds, modules = source_compile_seconds()
    return {"phases": phases, "points": dataset.n, "source_compile_s": compile_seconds, "source_modules": modules}


def source_compile_seconds() -> tuple[float, int]:
    """CPU time [s] to compile from source the modules of gonio (and its drivers) loaded in
    this process, and how many: what every start of the command costs when their bytecode
    is not cached (an editable install run where PYTHONDONTWRITEBYTECODE is set and
    ``make`` did not compile it)."""
    files = sorted({Path(module.__file__) for name, module in list(sys.modules.items())
                    if name.split(".")[0] in ("gonio", "drivers") and getattr(module, "__file__", None)})
    start = time.process_time()
    for path in files:
        compile(path.read_bytes(), str(path), "exec")
    return time.process_time() - start, len(files)


#: What the command has loaded when it exits (the report drawn: matplotlib too).
_EXIT_PROBE = """
import gc, sys, time
import emcee, h5netcdf, scipy.optimize
import gonio.cli, gonio.cli.fit, gonio.fitting, gonio.report.fit_report
from gonio.fitting.diagnostics import array_stats
gonio.cli.build_parser()
array_stats()
if sys.argv[1] == "freeze":
    gc.freeze()
print(time.time(), flush=True)
"""


def exit_seconds(freeze: bool) -> float:
    """Wall time [s] from the last statement to the end of a process that has loaded what
    ``gonio fit`` loads, with or without :func:`gc.freeze` first (``gonio.cli.run``)."""
    probe = subprocess.Popen([sys.executable, "-c", _EXIT_PROBE, "freeze" if freeze else "collect"],
                             stdout=subprocess.PIPE, text=True)
    last = float(probe.stdout.readline())
    probe.wait()
    return time.time() - last


def _parse(arguments: list[str]) -> argparse.Namespace:
    from gonio.cli import build_parser

    return build_parser().parse_args(["fit", *arguments])


def _import_sampler() -> None:
    import emcee  # noqa: F401
    import scipy.optimize  # noqa: F401


def _import_diagnostics() -> None:
    import h5netcdf  # noqa: F401

    from gonio.fitting.diagnostics import array_stats

    array_stats()


def _summarised(result):
    result.summary()
    return result


def fit_command(repeats: int) -> dict:
    """Wall time of the command, its phases and the interpreter references (medians) [s]."""
    compileall.compile_dir(ROOT / "gonio", quiet=1)  # as after any first run, or a pip install
    compileall.compile_dir(ROOT / "drivers", quiet=1)
    with tempfile.TemporaryDirectory(prefix="gonio-fig16-") as scratch:
        folder = Path(scratch)
        recording = make_recording(folder)
        totals, cpus, loads, phase_runs, start_up, numpy, pace = [], [], [], [], [], [], []
        exits_frozen, exits_collected = [], []
        for k in range(repeats):
            out = folder / f"fit-{k}"
            loads.append(os.getloadavg()[0])
            wall, cpu = command_times([str(GONIO), "fit", str(recording), *FIT_ARGUMENTS, "--out", str(out)])
            totals.append(wall)
            cpus.append(cpu)
            shutil.rmtree(out)
            probe = subprocess.run([sys.executable, __file__, "--phases", str(recording), str(out)], check=True,
                                   capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
            phase_runs.append(json.loads(probe.stdout.strip().splitlines()[-1]))
            shutil.rmtree(out)
            start_up.append(command_seconds([sys.executable, "-c", "pass"]))
            numpy.append(command_seconds([sys.executable, "-c", "import numpy"]))
            pace.append(command_seconds([sys.executable, "-c", PACE_REFERENCE]))
            exits_frozen.append(exit_seconds(freeze=True))
            exits_collected.append(exit_seconds(freeze=False))
    every = {name: statistics.median(run["phases"][name] for run in phase_runs) for name in phase_runs[0]["phases"]}
    phases = {name: value for name, value in every.items() if not name.endswith(CPU)}
    phases_cpu = {name[: -len(CPU)]: value for name, value in every.items() if name.endswith(CPU)}
    total = statistics.median(totals)
    imports = sum(v for k, v in phases.items() if k.startswith(("command line", "import")))
    return {
        "command": f"gonio fit RECORDING {' '.join(FIT_ARGUMENTS)} --out FOLDER",
        "points": phase_runs[0]["points"],
        "wall_s": total,
        "wall_min_s": min(totals),
        "wall_runs_s": totals,
        "within_target": total <= FIT_TARGET_S,
        "phases_s": phases,
        "phases_sum_s": sum(phases.values()),
        "phases_cpu_s": phases_cpu,
        "phases_cpu_sum_s": sum(phases_cpu.values()),
        "command_cpu_s": statistics.median(cpus),
        "load_average_runs": loads,
        "imports_s": imports,
        "bytecode": "gonio's compiled before timing (compileall), as after a first run or by make",
        "source_compile_s": statistics.median(run["source_compile_s"] for run in phase_runs),
        "source_modules": phase_runs[0]["source_modules"],
        "exit_with_gc_freeze_s": statistics.median(exits_frozen),
        "exit_with_final_collection_s": statistics.median(exits_collected),
        "interpreter_start_s": statistics.median(start_up),
        "interpreter_with_numpy_s": statistics.median(numpy),
        "ratio_to_interpreter_with_numpy": total / statistics.median(numpy),
        "pace_reference_s": statistics.median(pace),
        "pace_reference_runs_s": pace,
        "ratio_to_pace_reference": total / statistics.median(pace),
    }


# ------------------------------------------------- the report workers on the default path
#: The last revision with the report workers (``gonio.report.workers``), whose code
#: ``--workers-decision`` times.
WORKERS_REVISION = "d552be7"
#: Largest 1-minute load average at which a timed run starts (a quiet 2-core machine).
QUIET_LOAD = 0.7
#: Longest wait for the machine to be that quiet before a run [s]; past it the run is
#: made anyway and its load recorded.
QUIET_WAIT_S = 240.0


def wait_until_quiet(limit: float = QUIET_LOAD, longest: float | None = None) -> float:
    """Wait until the 1-minute load average is below ``limit`` (at most ``longest`` s,
    default :data:`QUIET_WAIT_S`); returns the load average at the start of the run."""
    deadline = time.monotonic() + (QUIET_WAIT_S if longest is None else longest)
    while os.getloadavg()[0] >= limit and time.monotonic() < deadline:
        time.sleep(2.0)
    return os.getloadavg()[0]


def export_revision(revision: str, folder: Path) -> Path:
    """gonio, drivers and protocols of the git ``revision`` exported into ``folder``, to
    be run by this interpreter with ``PYTHONPATH=folder`` (the same dependencies)."""
    archive = subprocess.run(["git", "archive", revision, "gonio", "drivers", "protocols"], cwd=ROOT, check=True,
                             capture_output=True).stdout
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    compileall.compile_dir(folder / "gonio", quiet=1)
    compileall.compile_dir(folder / "drivers", quiet=1)
    return folder


def default_path_decision(repeats: int, quiet_wait: float = QUIET_WAIT_S, revision: str | None = WORKERS_REVISION) -> dict:
    """The default path with the report workers against one process, same run, alternating.

    ``gonio fit REC --model oren-nayar --fix ir_weight=1 --report --quiet`` on the Fig 16
    recording of :func:`make_recording` (the realistic rig), as it comes (the fork-server
    workers of ``gonio.report.workers`` draw the report) and with
    ``GONIO_REPORT_PROCESSES=1`` (one process), and ``gonio report FOLDER`` with
    ``GONIO_REPORT_PROCESSES`` 1 (its default) and 2; each pair in alternating order
    (ABBA), every run started when the 1-minute load is below :data:`QUIET_LOAD` (waiting
    at most ``quiet_wait`` s), ``python -c "import numpy"`` timed between them as the
    reference. The code is that of the git ``revision`` (``python -m gonio`` of an export
    of it; default :data:`WORKERS_REVISION`, the last with the workers), or with None the
    working tree's.
    """
    with tempfile.TemporaryDirectory(prefix="gonio-workers-") as scratch:
        folder = Path(scratch)
        if revision is None:
            compileall.compile_dir(ROOT / "gonio", quiet=1)
            compileall.compile_dir(ROOT / "drivers", quiet=1)
            gonio, code = [str(GONIO)], {}
        else:
            source = export_revision(revision, folder / "source")
            gonio, code = [sys.executable, "-m", "gonio"], {"PYTHONPATH": str(source)}
        runs: dict[str, dict[str, list[float]]] = {name: {"wall": [], "cpu": [], "load": []}
                                                   for name in ("fit_workers", "fit_one_process",
                                                                "report_one_process", "report_workers")}
        numpy_runs = []
        fit_env = {"fit_workers": {}, "fit_one_process": {"GONIO_REPORT_PROCESSES": "1"}}
        report_env = {"report_one_process": {"GONIO_REPORT_PROCESSES": "1"},
                      "report_workers": {"GONIO_REPORT_PROCESSES": "2"}}
        recording = folder / "plaster"
        subprocess.run([*gonio, "run", str(PROTOCOL), "--out", str(recording), "--sample", SAMPLE], check=True,
                       capture_output=True, env={**os.environ, **code})
        saved = folder / "saved"
        command_times([*gonio, "fit", str(recording), *FIT_ARGUMENTS, "--out", str(saved)],
                      {**code, "GONIO_REPORT_PROCESSES": "1"})  # the fit gonio report draws; warms the file cache
        for k in range(repeats):
            for group in (fit_env, report_env):
                order = list(group) if k % 2 == 0 else list(group)[::-1]
                for name in order:
                    out = folder / f"{name}-{k}"
                    if name.startswith("fit"):
                        command = [*gonio, "fit", str(recording), *FIT_ARGUMENTS, "--out", str(out)]
                    else:
                        command = [*gonio, "report", str(saved), "--out", str(out)]
                    runs[name]["load"].append(wait_until_quiet(longest=quiet_wait))
                    wall, cpu = command_times(command, {**code, **group[name]})
                    runs[name]["wall"].append(wall)
                    runs[name]["cpu"].append(cpu)
                    shutil.rmtree(out)
                    print(f"  {k + 1}/{repeats} {name:20s} {wall:6.2f} s wall, CPU {cpu:5.2f} s "
                          f"(load {runs[name]['load'][-1]:.2f})", flush=True)
            wait_until_quiet(longest=quiet_wait)
            numpy_runs.append(command_seconds([sys.executable, "-c", "import numpy"]))

    def summary(name: str) -> dict:
        wall = runs[name]["wall"]
        return {"wall_median_s": statistics.median(wall), "wall_min_s": min(wall), "wall_max_s": max(wall),
                "wall_stdev_s": statistics.stdev(wall) if len(wall) > 1 else 0.0, "wall_runs_s": wall,
                "cpu_median_s": statistics.median(runs[name]["cpu"]), "cpu_runs_s": runs[name]["cpu"],
                "load_average_at_start": runs[name]["load"]}

    result = {name: summary(name) for name in runs}
    numpy_s = statistics.median(numpy_runs)
    for name in runs:
        result[name]["ratio_to_import_numpy"] = result[name]["wall_median_s"] / numpy_s
    # paired differences (one process minus workers) of the runs made side by side
    pairs = [a - b for a, b in zip(runs["fit_one_process"]["wall"], runs["fit_workers"]["wall"])]
    report_pairs = [a - b for a, b in zip(runs["report_one_process"]["wall"], runs["report_workers"]["wall"])]
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout
    return {
        "fit_command": f"gonio fit RECORDING {' '.join(FIT_ARGUMENTS)} --out FOLDER",
        "report_command": "gonio report FOLDER --out OUT",
        "recording": f"{PROTOCOL.name} measured by gonio run --sample {SAMPLE} (default realism)",
        "code": f"git revision {revision}" if revision else f"working tree (HEAD {head.strip()})",
        "repeats": repeats, "quiet_load_limit": QUIET_LOAD, "runs": result,
        "import_numpy_s": numpy_s, "import_numpy_runs_s": numpy_runs,
        "fit_speed_up_of_workers": result["fit_one_process"]["wall_median_s"] / result["fit_workers"]["wall_median_s"],
        "fit_paired_gain_of_workers_s": pairs,
        "fit_paired_gain_median_s": statistics.median(pairs),
        "report_speed_up_of_workers": (result["report_one_process"]["wall_median_s"]
                                       / result["report_workers"]["wall_median_s"]),
        "report_paired_gain_of_workers_s": report_pairs,
        "report_paired_gain_median_s": statistics.median(report_pairs),
    }


# ------------------------------------------------------------------------------ chart
def chart(scaling: list[dict], command: dict, path: Path) -> None:
    """Report time against size (current and previous figures) and the command's phases."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    fig = Figure(figsize=(12.0, 4.4), layout="constrained")
    left, right = fig.subplots(1, 2, width_ratios=(1.0, 1.4))
    n = [row["n"] for row in scaling]
    left.plot(n, [row["write_report_s"] for row in scaling], "o-", color="C0", label="write_report (figures + HTML), wall")
    left.plot(n, [row["write_report_cpu_s"] for row in scaling], "o:", color="C0", label="write_report, CPU time")
    left.plot(n, [row["report_command_s"] for row in scaling], "D:", color="C1", label="gonio report command, wall")
    old = [(row["n"], row["previous_figures_total_s"]) for row in scaling if "previous_figures_total_s" in row]
    if old:
        left.plot(*zip(*old), "s--", color="C3", label=f"figures of {PREVIOUS_REVISION} (previous)")
    left.axhline(REPORT_TARGET_S, color="k", ls=":", lw=1, label=f"target {REPORT_TARGET_S:g} s at 10,000 points")
    left.set_xscale("log")
    left.set_yscale("log")
    top = max([row["write_report_s"] for row in scaling] + [row["report_command_s"] for row in scaling]
              + [t for _, t in old])
    left.set_yticks([t for t in (0.5, 1, 2, 5, 10, 20, 50, 100, 200) if t <= 2 * top])
    left.yaxis.set_major_formatter(ScalarFormatter())
    left.yaxis.set_minor_formatter(NullFormatter())
    left.set_xlabel("measurements, each at its own incidence")
    left.set_ylabel("wall time [s]")
    left.set_title("Fit report against the number of measurements", fontsize=10)
    left.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)
    left.grid(alpha=0.3, which="both")
    phases = command["phases_s"]
    start = 0.0
    for k, (name, seconds) in enumerate(phases.items()):
        right.barh(0, seconds, left=start, color=matplotlib.colormaps["tab20"](k % 20), label=f"{name}: {seconds:.2f} s")
        start += seconds
    right.barh(1, command["wall_s"], color="0.3", label=f"the command: {command['wall_s']:.2f} s")
    right.axvline(FIT_TARGET_S, color="k", ls=":", lw=1)
    right.set_yticks([0, 1], ["phases", "command"])
    right.set_xlabel("wall time [s]")
    right.set_title(f"gonio fit of the Fig 16 recording with --report (target {FIT_TARGET_S:g} s)", fontsize=10)
    right.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)
    fig.savefig(path, dpi=110)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs per measurement (default 3)")
    parser.add_argument("--previous-max", type=int, default=1000,
                        help="largest fit whose report the previous figure code draws (default 1000)")
    parser.add_argument("--phases", nargs=2, metavar=("RECORDING", "OUT"), help=argparse.SUPPRESS)
    parser.add_argument("--workers-decision", action="store_true",
                        help="only the default path with the report workers against one process (same run, "
                             "alternating, quiet machine); merged into report.json")
    parser.add_argument("--revision", default=WORKERS_REVISION,
                        help=f"--workers-decision: the git revision whose code is timed (default {WORKERS_REVISION}, "
                             "the last with the report workers)")
    parser.add_argument("--quiet-wait", type=float, default=QUIET_WAIT_S,
                        help=f"longest wait [s] for a 1-minute load below {QUIET_LOAD} before each run of "
                             f"--workers-decision (default {QUIET_WAIT_S:g})")
    args = parser.parse_args()
    if args.phases:  # child mode: one phase-by-phase run, JSON on stdout
        print(json.dumps(run_phases(*args.phases)))
        return 0
    if args.workers_decision:
        become_subreaper()
        decision = default_path_decision(args.repeats, args.quiet_wait, args.revision)
        decision["command"] = (f"python benchmarks/bench_report.py --workers-decision --repeats {args.repeats} "
                               f"--quiet-wait {args.quiet_wait:g}" + (f" --revision {args.revision}" if args.revision
                                                                       else ""))
        decision["quiet_wait_s"] = args.quiet_wait
        decision["machine"] = machine()
        path = OUT / "report.json"
        payload = json.loads(path.read_text()) if path.exists() else {"benchmark": "report"}
        payload["report_workers_decision"] = decision
        write_json("report", payload)
        print(json.dumps({k: v for k, v in decision.items() if k != "runs"}, indent=1))
        return 0
    load_before = os.getloadavg()
    print("report against the number of measurements:", flush=True)
    scaling = report_scaling(args.repeats, args.previous_max)
    print("gonio fit of the Fig 16 recording with --report:", flush=True)
    command = fit_command(args.repeats)
    payload = {
        # the machine is shared: 1-minute load averages before and after the run
        "load_average_before_after": [load_before[0], os.getloadavg()[0]],
        "benchmark": "report",
        "command": f"python benchmarks/bench_report.py --repeats {args.repeats} --previous-max {args.previous_max}",
        "machine": machine(),
        "previous_revision": PREVIOUS_REVISION,
        "report_target_s": REPORT_TARGET_S,
        "report_scaling": scaling,
        "report_of_10000_within_target": scaling[-1]["write_report_s"] <= REPORT_TARGET_S,
        "fit_command": command,
    }
    path = write_json("report", payload)
    chart(scaling, command, OUT / "report.png")
    for name, seconds in command["phases_s"].items():
        print(f"  {name:58s} {seconds:6.2f} s  (CPU {command['phases_cpu_s'][name]:.2f} s)")
    print(f"  {'phases together':58s} {command['phases_sum_s']:6.2f} s  (CPU {command['phases_cpu_sum_s']:.2f} s)")
    print(f"  {'the command':58s} {command['wall_s']:6.2f} s  (CPU {command['command_cpu_s']:.2f} s; "
          f"python -c pass {command['interpreter_start_s']:.2f} s; load {min(command['load_average_runs']):.1f}-"
          f"{max(command['load_average_runs']):.1f}); {command['ratio_to_pace_reference']:.2f} times the pace "
          f"reference ({command['pace_reference_s']:.2f} s)")
    print(f"  gonio's bytecode compiled first; compiling its {command['source_modules']} modules from source would "
          f"add {command['source_compile_s']:.2f} s of CPU; exit {command['exit_with_gc_freeze_s']:.2f} s after "
          f"gc.freeze, {command['exit_with_final_collection_s']:.2f} s with the final collection")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
