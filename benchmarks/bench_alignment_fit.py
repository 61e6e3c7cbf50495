"""Speed of fits with free alignment parameters, against the plain fit in the same run.

A fit with ``--alignment`` gives every walker its own true geometry
(gonio.fitting.rig_errors), so the model cannot be prepared once at the recorded
geometry; gonio.fitting.compiled_rig evaluates the misaligned rig through its apertures
in one compiled loop.  Measured here, on the shipped Fig 16 protocol run on the embedded
emulator (sample ``oren-nayar``, sigma = 30 deg, rho = 0.9, seed 0; 90 values):

1. **One likelihood evaluation** of W walkers (W = 16, half of gonio's 32-walker ensemble,
   as emcee's stretch move evaluates it, and W = 32) with ``view_offset`` and
   ``theta_i_offset`` free: the compiled path (``FitProblem``), the numpy path it replaced
   (``RigPrediction(compiled=False)``: misaligned_angles, cone_quadrature and the
   aperture-averaged model over W x N x 49 sub-rays) and the plain fit without alignment
   (the sufficient statistics of the linear Oren-Nayar form). Best of ``--repeats``
   (at least 7).
   The whitening of the residuals is timed both ways too: a triangular solve per batch (as
   before) and the product with L^-1 computed once.
2. **``gonio fit``** of the recording as a command (wall time of the process, median of
   ``--repeats``): ``--model oren-nayar --fix ir_weight=1`` (plain) and the same with
   ``--alignment view_offset,theta_i_offset`` (32 walkers, MCMC to 50 tau and R-hat <
   1.01), after one untimed aligned fit that fills numba's cache; and, unless
   ``--no-previous``, the aligned fit once with the code of revision
   :data:`PREVIOUS_REVISION` (the numpy path), read from git.

Writes docs/benchmarks/alignment_fit.json.
Run: ``python benchmarks/bench_alignment_fit.py [--repeats N] [--no-previous]``.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, best_time, machine, write_json  # noqa: E402

#: The revision before the compiled rig radiance (main's merge of the rig's systematics).
PREVIOUS_REVISION = "4d3d6ba"
PROTOCOL = ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"
SAMPLE = "oren-nayar:sigma=30,rho=0.9,ir_weight=1"
PLAIN = ("--model", "oren-nayar", "--fix", "ir_weight=1", "--quiet")
ALIGNED = PLAIN + ("--alignment", "view_offset,theta_i_offset")
FREE = ("view_offset", "theta_i_offset")


def record(folder: Path) -> Path:
    """The Fig 16 protocol on the embedded emulator (``gonio run``, seed 0)."""
    subprocess.run([sys.executable, "-m", "gonio", "run", str(PROTOCOL), "--out", str(folder), "--sample", SAMPLE],
                   check=True, capture_output=True, env=_env(ROOT), cwd=ROOT)
    return folder


def _env(root: Path) -> dict[str, str]:
    """The environment of a command run with the code at ``root`` (also its working
    folder: ``python -m`` puts the working folder first on the path)."""
    return {**os.environ, "PYTHONPATH": str(root)}


# --------------------------------------------------------------------------- likelihood
def likelihood(folder: Path, repeats: int) -> dict:
    """Seconds per likelihood evaluation of W walkers: compiled, numpy, plain; whitening."""
    from scipy.linalg import solve_triangular

    from gonio.acquisition import reduce_recording
    from gonio.fitting import FitProblem
    from gonio.fitting.rig_errors import RigPrediction

    dataset, priors = reduce_recording(folder).fit_inputs()
    aligned = FitProblem("oren-nayar", dataset, {"ir_weight": 1.0}, alignment=FREE)
    plain = FitProblem("oren-nayar", dataset, {"ir_weight": 1.0})
    numpy_path = RigPrediction(aligned.model, dataset.quantity, dataset.geometry, aligned.options, dataset.metadata)
    rng = np.random.default_rng(0)
    out = {"n_data": dataset.n}
    for walkers in (16, 32):
        centre = np.array([0.9, 30.0, priors["scale"].mean])
        vectors = np.column_stack([centre * (1 + 1e-4 * rng.standard_normal((walkers, 3))),
                                   rng.normal(0.0, 0.2, (walkers, 2))])
        values = aligned.batch_values(vectors)
        difference = aligned._rig.of_values(values) - dataset.value
        assert np.allclose(numpy_path.of_values(values), aligned._rig.of_values(values), rtol=1e-12, atol=0)
        factor = np.linalg.cholesky(dataset.covariance)
        whitener = solve_triangular(factor, np.eye(dataset.n), lower=True)
        out[f"walkers_{walkers}"] = row = {
            "compiled_seconds": best_time(lambda: aligned.log_likelihood_batch(vectors), repeats),
            "numpy_prediction_seconds": best_time(lambda: numpy_path.of_values(values), repeats),
            "compiled_prediction_seconds": best_time(lambda: aligned._rig.of_values(values), repeats),
            "plain_seconds": best_time(lambda: plain.log_likelihood_batch(vectors[:, :3]), repeats),
            "triangular_solve_seconds": best_time(
                lambda: solve_triangular(factor, difference.T, lower=True, check_finite=False), repeats),
            "whitening_product_seconds": best_time(lambda: whitener @ difference.T, repeats),
        }
        row["prediction_numpy_over_compiled"] = row["numpy_prediction_seconds"] / row["compiled_prediction_seconds"]
        row["compiled_over_plain"] = row["compiled_seconds"] / row["plain_seconds"]
        print(f"{walkers} walkers: likelihood {row['compiled_seconds'] * 1e3:.2f} ms (plain "
              f"{row['plain_seconds'] * 1e3:.3f} ms); prediction numpy/compiled "
              f"{row['prediction_numpy_over_compiled']:.1f}", flush=True)
    return out


# --------------------------------------------------------------------------- gonio fit
def time_fit(root: Path, folder: Path, arguments: tuple[str, ...], out: Path) -> dict:
    """Wall time of one ``gonio fit`` process with the code at ``root``, and its chain."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "gonio", "fit", str(folder), *arguments, "--out", str(out),
                           "--overwrite"], capture_output=True, text=True, env=_env(root), cwd=root)
    seconds = time.perf_counter() - start
    if done.returncode not in (0, 3, 4):
        raise RuntimeError(f"gonio fit failed ({done.returncode}): {done.stderr[-2000:]}")
    result = json.loads((out / "result.json").read_text())
    mcmc = result.get("mcmc") or {}
    steps, mcmc_seconds = mcmc.get("n_steps"), mcmc.get("wall_seconds")
    return {"seconds": seconds, "exit": done.returncode, "walkers": mcmc.get("n_walkers"), "steps": steps,
            "converged": mcmc.get("converged"), "mcmc_seconds": mcmc_seconds,
            "mcmc_seconds_per_step": mcmc_seconds / steps if steps else None}


def commands(folder: Path, repeats: int, previous: bool, scratch: Path) -> dict:
    """The plain and the aligned ``gonio fit`` (medians), and the previous revision's aligned fit."""
    time_fit(ROOT, folder, ALIGNED, scratch / "warm")  # numba's cache for this source tree
    out: dict = {}
    for name, arguments in (("plain", PLAIN), ("aligned", ALIGNED)):
        runs = [time_fit(ROOT, folder, arguments, scratch / name) for _ in range(repeats)]
        out[name] = {"seconds": statistics.median(r["seconds"] for r in runs), "runs": runs}
        print(f"gonio fit {name}: {out[name]['seconds']:.1f} s (median of {repeats}; "
              f"{runs[0]['walkers']} walkers x {runs[0]['steps']} steps)", flush=True)
    out["aligned_over_plain"] = out["aligned"]["seconds"] / out["plain"]["seconds"]
    for name in ("plain", "aligned"):
        out[name]["mcmc_seconds_per_step"] = statistics.median(r["mcmc_seconds_per_step"] for r in out[name]["runs"])
    if previous:
        source = scratch / "previous"
        source.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", PREVIOUS_REVISION], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(source)], input=archive, check=True)
        run = time_fit(source, folder, ALIGNED, scratch / "aligned-previous")
        out["aligned_previous"] = {"revision": PREVIOUS_REVISION, **run}
        out["previous_over_aligned"] = run["seconds"] / out["aligned"]["seconds"]
        # the chains stop after different numbers of steps (their convergence checks see
        # other draws): the cost of one step compares the two paths
        out["previous_over_aligned_per_step"] = run["mcmc_seconds_per_step"] / out["aligned"]["mcmc_seconds_per_step"]
        print(f"gonio fit aligned at {PREVIOUS_REVISION}: {run['seconds']:.1f} s "
              f"({run['walkers']} walkers x {run['steps']} steps)", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs per timing (default 3)")
    parser.add_argument("--no-previous", action="store_true", help="skip the previous revision's aligned fit")
    args = parser.parse_args(argv)
    began, load_before = time.perf_counter(), os.getloadavg()
    scratch = Path(tempfile.mkdtemp(prefix="gonio-alignment-"))
    try:
        folder = record(scratch / "fig16")
        speed = likelihood(folder, max(args.repeats, 7))  # cheap: more repeats against the machine's load
        fits = commands(folder, args.repeats, not args.no_previous, scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    payload = {"benchmark": "bench_alignment_fit",
               "command": "python benchmarks/bench_alignment_fit.py " + " ".join(argv if argv is not None else sys.argv[1:]),
               "protocol": PROTOCOL.name, "sample": SAMPLE, "free_alignment": list(FREE),
               "likelihood": speed, "gonio_fit": fits, "wall_seconds": time.perf_counter() - began,
               "load_average_before_after": [load_before[0], os.getloadavg()[0]], "machine": machine()}
    path = write_json("alignment_fit", payload)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
