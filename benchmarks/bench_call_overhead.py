"""Per-call cost of small plain calls: ``gonio.brdf("oren-nayar", ...)`` on 1 to 1000 geometries.

Each call is timed with :mod:`timeit` (best of several repeats of many calls) in fresh
interpreters (``--rounds``, alternated with those of the previous revision; the best of
each is kept), beside a reference timed the same way in the same interpreters: a trivial
numpy ufunc call, ``numpy.add(x, x)`` on two 10-element float64 arrays (the floor of any
numpy computation, which moves with the machine and its load as gonio's calls do).

Target (issue "Scale"): a call on scalar angles and a call on 10 geometries each under
10 us, at most :data:`TARGET_IN_REFERENCE_CALLS` reference calls in the same run (10 us
when the reference takes 0.345 us, as it did on the 2-core benchmark machine when the
target was set; the ratio is what a loaded or different machine can be checked against).

Also measured: the cost per call of the two paths for 8 to 128 geometries (the small call
in plain Python, ``Model.point``, and the numpy path), which places
:data:`gonio.models._core.POINT_MAX`; and, with ``--previous REV`` (default
``HEAD``), the same calls of an earlier revision of ``gonio`` (``git archive`` into a
temporary directory, imported from there) in the same run.

Writes docs/benchmarks/call_overhead.json and docs/benchmarks/call_overhead.png.
Run: ``python benchmarks/bench_call_overhead.py [--previous REV] [--rounds N]``.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import timeit
from pathlib import Path
from typing import Callable, Iterator

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import OUT, ROOT, machine, write_json  # noqa: E402

#: The target per call [us] and the same in reference calls (0.345 us each when set).
TARGET_US = 10.0
TARGET_IN_REFERENCE_CALLS = 29.0
#: Geometries per timed call.
SIZES = (1, 10, 64, 100, 1000)
#: Sizes of the comparison of the small call with the numpy path.
CROSSOVER_SIZES = (8, 16, 32, 48, 64, 96, 128)
PARAMS = {"sigma": 30.0, "rho": 0.9}


def best_us(function: Callable[[], object], number: int, repeat: int = 7) -> float:
    """Best time of one call of ``function`` over ``repeat`` runs of ``number`` calls [us]."""
    return min(timeit.repeat(function, number=number, repeat=repeat)) / number * 1e6


def _angles(n: int) -> tuple:
    """``n`` geometries [deg] above the horizon as float64 arrays, or floats for ``n = 1``."""
    import numpy as np

    if n == 1:
        return 30.0, 0.0, 40.0, 180.0
    rng = np.random.default_rng(n)
    return (rng.uniform(0.0, 89.0, n), rng.uniform(-180.0, 180.0, n),
            rng.uniform(0.0, 89.0, n), rng.uniform(-180.0, 180.0, n))


def measure(crossover: bool) -> dict:
    """The reference and the calls of :data:`SIZES` [us] in this interpreter (and the
    crossover of the two small-call paths when ``crossover``)."""
    import numpy as np

    import gonio

    x = np.linspace(0.0, 1.0, 10)
    reference = best_us(lambda: np.add(x, x), number=200_000)
    calls = {}
    for n in SIZES:
        angles = _angles(n)
        calls[str(n)] = best_us(lambda: gonio.brdf("oren-nayar", *angles, **PARAMS), number=max(200, 20_000 // n))
    result = {"reference_ufunc_us": reference, "calls_us": calls, "gonio_source": gonio.__file__}
    if crossover:
        import gonio.models._core as core

        default = core.POINT_MAX
        paths: dict[str, dict[str, float]] = {"small call (plain Python)": {}, "numpy path": {}}
        for n in CROSSOVER_SIZES:
            angles = _angles(n)
            for label, limit in zip(paths, (10**9, 0)):
                core.POINT_MAX = limit
                paths[label][str(n)] = best_us(lambda: gonio.brdf("oren-nayar", *angles, **PARAMS), number=2000)
        core.POINT_MAX = default
        result["crossover_us"] = paths
    return result


@contextlib.contextmanager
def revision_tree(revision: str) -> Iterator[Path]:
    """The ``gonio`` package of a git revision, extracted with ``git archive`` (read-only
    for the repository) into a temporary directory to put first on ``PYTHONPATH``."""
    with tempfile.TemporaryDirectory(prefix="gonio-revision-") as tree:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", revision, "gonio"],
                                 check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", tree], input=archive, check=True)
        yield Path(tree)


def measure_in_fresh_interpreter(pythonpath: Path | None, crossover: bool) -> dict:
    """:func:`measure` in a fresh interpreter, importing ``gonio`` from ``pythonpath``
    when given."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), env.get("PYTHONPATH", "")])
    command = [sys.executable, __file__, "--measure"] + (["--crossover"] if crossover else [])
    done = subprocess.run(command, env=env, check=True, capture_output=True, text=True)
    result = json.loads(done.stdout)
    assert pythonpath is None or Path(result["gonio_source"]).is_relative_to(pythonpath), result["gonio_source"]
    return result


def best_of(old: dict | None, new: dict) -> dict:
    """The element-wise smaller times of two :func:`measure` results (``old`` may be None)."""
    if old is None:
        return new
    merged = {}
    for key, value in new.items():
        if isinstance(value, dict):
            merged[key] = best_of(old[key], value)
        elif isinstance(value, float):
            merged[key] = min(old[key], value)
        else:
            merged[key] = value
    return merged


def chart(current: dict, previous: dict | None, path: Path) -> None:
    """Time per call against geometries per call (log-log): this revision, the previous
    one, the two small-call paths, and the target."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    sizes = [int(n) for n in current["calls_us"]]
    ax.plot(sizes, list(current["calls_us"].values()), "o-", color="C0", label="gonio.brdf, this revision")
    if previous is not None:
        ax.plot(sizes, list(previous["calls_us"].values()), "s--", color="C3", label="gonio.brdf, previous revision")
    for (label, values), style in zip(current["crossover_us"].items(), (":", "-.")):
        ax.plot([int(n) for n in values], list(values.values()), style, color="0.4", lw=1, label=label)
    ax.axhline(TARGET_US, color="k", ls="--", lw=1, label=f"target ({TARGET_US:g} us)")
    ax.axhline(current["reference_ufunc_us"], color="C2", lw=1, label="numpy.add, 10 elements (reference)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("geometries per call")
    ax.set_ylabel("time per call [us] (best of 7)")
    ax.set_title('gonio.brdf("oren-nayar", ...): cost per call', fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")
    fig.savefig(path, dpi=110)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--previous", default="HEAD", help="git revision timed in the same run ('' for none)")
    parser.add_argument("--rounds", type=int, default=3,
                        help="fresh interpreters per revision, alternated; the best time of each call is kept")
    parser.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--crossover", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure(args.crossover)))
        return 0
    load_before = os.getloadavg()[0]
    previous, current = None, None
    with contextlib.ExitStack() as stack:
        tree = stack.enter_context(revision_tree(args.previous)) if args.previous else None
        for _ in range(args.rounds):  # alternated, so that a burst of load hits both
            if tree is not None:
                previous = best_of(previous, measure_in_fresh_interpreter(tree, crossover=False))
            current = best_of(current, measure_in_fresh_interpreter(None, crossover=True))
    reference = current["reference_ufunc_us"]
    targets = {}
    for n in ("1", "10"):
        ratio = current["calls_us"][n] / reference
        targets[f"{n} geometr{'y' if n == '1' else 'ies'}: <= {TARGET_IN_REFERENCE_CALLS:g} reference calls"] = (
            ratio <= TARGET_IN_REFERENCE_CALLS)
    payload = {
        # the machine is shared: 1-minute load averages before and after the run
        "load_average_before_after": [load_before, os.getloadavg()[0]],
        "benchmark": "call_overhead",
        "command": f"python benchmarks/bench_call_overhead.py --previous {args.previous or repr('')} "
                   f"--rounds {args.rounds}",
        "machine": machine(),
        "call": 'gonio.brdf("oren-nayar", theta_i, phi_i, theta_r, phi_r, sigma=30.0, rho=0.9)',
        "reference": "numpy.add(x, x), x of 10 float64 [us]",
        "target_us": TARGET_US,
        "target_in_reference_calls": TARGET_IN_REFERENCE_CALLS,
        "current": current,
        "current_in_reference_calls": {n: t / reference for n, t in current["calls_us"].items()},
        "previous_revision": args.previous or None,
        "previous": previous,
        "targets": targets,
    }
    if previous is not None:
        payload["previous_in_reference_calls"] = {n: t / previous["reference_ufunc_us"]
                                                  for n, t in previous["calls_us"].items()}
    path = write_json("call_overhead", payload)
    chart(current, previous, OUT / "call_overhead.png")
    print(f"reference numpy.add: {reference:.3f} us")
    for n, t in current["calls_us"].items():
        before = f"   previous {previous['calls_us'][n]:8.2f} us" if previous else ""
        print(f"{n:>5} geometries: {t:8.2f} us ({t / reference:6.1f} reference calls){before}")
    print(f"crossover: {json.dumps(current['crossover_us'])}")
    print(f"targets: {targets}")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
