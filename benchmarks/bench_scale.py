"""How ``gonio fit`` scales with the number of values: time, peak memory and output size.

Synthetic data: the functional Oren-Nayar model (eq 33-35, rho 0.8, sigma 25 deg) at N
random geometries (theta_i, theta_r uniform in 0-80 deg, azimuth difference in 0-180 deg)
with 1 % Gaussian noise, written as a CSV; then ``gonio fit DATA.csv --model oren-nayar
--out FOLDER --quiet`` in its own process (least squares, MCMC to convergence, the
posterior predictive check, the validity check, ``posterior.nc``), as a user runs it. For
each N: wall time, CPU time and peak resident memory of that process (``os.wait4``), and
the size of the result folder. The ratio of interest is the time at 1e5 values over the
time at 1e4, measured in the same run (the target: at most 12, under 2 GB).

``--correlated`` fits data whose errors are correlated as a reduced recording's are
(:func:`write_correlated_data`: a diagonal plus 28 shared sources, the covariance written
beside the CSV as the factors a reduction gives, gonio.fitting.covariance), and the same
data with the covariance as a dense n x n matrix at the sizes where that is possible
(``DENSE_SIZES``), as the reference the structured covariance replaces; the parameters of
the two fits are compared.

Writes docs/benchmarks/scale.json and scale.png (``--correlated``: scale-correlated.json
and scale-correlated.png). Run: ``python benchmarks/bench_scale.py [--correlated]``
(about 1 minute; ``--million`` adds 1e6 values, several minutes more).
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import OUT, ROOT, machine, write_json

import gonio

SIZES = (1_000, 10_000, 100_000)
TRUTH = {"rho": 0.8, "sigma": 25.0}
NOISE = 0.01
#: Sizes at which ``--correlated`` also fits the dense matrix (n^2 doubles: 200 MB at 5e3).
DENSE_SIZES = (1_000, 3_000)
#: The shared sources of ``--correlated``, as fractions of each value (a lab rig's budget,
#: docs/emulator.md): the independent part, the texture, PRNU over nested windows (20
#: distinct window sizes), three mountings, two linearity coefficients, the calibration.
SHARED = {"independent": 0.003, "texture": 0.003, "prnu": 0.002, "windows": 20, "mounting": 0.002,
          "mountings": 3, "linearity": 0.001, "calibration": 0.005}


def write_data(n: int, path: Path, seed: int = 0) -> None:
    """N synthetic values with their uncertainty as a gonio fit CSV."""
    rng = np.random.default_rng(seed)
    ti, tr, dphi = rng.uniform(0.0, 80.0, n), rng.uniform(0.0, 80.0, n), rng.uniform(0.0, 180.0, n)
    value = gonio.brdf("oren-nayar", ti, 0.0, tr, dphi, **TRUTH)
    noisy = value * (1.0 + NOISE * rng.standard_normal(n))
    table = np.column_stack([ti, np.zeros(n), tr, dphi, noisy, NOISE * value])
    np.savetxt(path, table, delimiter=",", fmt="%.9g", header="theta_i,phi_i,theta_r,phi_r,value,sigma",
               comments="")


def correlated_covariance(value: np.ndarray, theta_r: np.ndarray, rng: np.random.Generator):
    """A reduction-like covariance of ``value`` (:data:`SHARED`) as a LowRankCovariance."""
    from gonio.fitting import LowRankCovariance

    s = SHARED
    window = np.minimum((theta_r / 80.0 * s["windows"]).astype(int), s["windows"] - 1)  # window grows with the view
    levels = np.arange(s["windows"])
    prnu = np.where(window[:, None] >= levels[None, :], 1.0, 0.0) * s["prnu"] / np.sqrt(s["windows"])
    mounting = rng.normal(0.0, s["mounting"], (value.size, s["mountings"])) / np.sqrt(s["mountings"])
    linearity = np.column_stack([np.ones_like(value), value / value.max()]) * s["linearity"]
    shared = np.hstack([np.full((value.size, 1), s["texture"]), prnu, mounting, linearity,
                        np.full((value.size, 1), s["calibration"])]) * value[:, None]
    return LowRankCovariance((s["independent"] * value) ** 2, shared)


def write_correlated_data(n: int, path: Path, dense: bool, seed: int = 0) -> None:
    """N values with correlated errors drawn from :func:`correlated_covariance`, as a CSV
    with the covariance beside it (the factors, or the dense matrix with ``dense``)."""
    from gonio.fitting import Dataset
    from gonio.fitting.covariance import LowRankNoise

    rng = np.random.default_rng(seed)
    ti, tr, dphi = rng.uniform(0.0, 80.0, n), rng.uniform(0.0, 80.0, n), rng.uniform(0.0, 180.0, n)
    value = gonio.brdf("oren-nayar", ti, 0.0, tr, dphi, **TRUTH)
    covariance = correlated_covariance(value, tr, rng)
    noisy = value + LowRankNoise(covariance).draw(rng, 1)[0]
    Dataset(ti, 0.0, tr, dphi, noisy, np.sqrt(covariance.variance()), label=f"correlated-{n}",
            covariance=covariance.dense() if dense else covariance).to_csv(path)


def fitted(out: Path) -> dict:
    """sigma and rho of a result folder: median and 95 % interval."""
    import json

    posterior = json.loads((out / "result.json").read_text())["posterior"] or {}
    return {name: {key: posterior[key][name] for key in ("median", "p2_5", "p97_5")}
            for name in TRUTH if name in posterior.get("median", {})}


def run_fit(data: Path, out: Path) -> dict:
    """``gonio fit`` in its own process: wall, CPU [s], peak memory [MB], exit status."""
    command = [sys.executable, "-m", "gonio", "fit", str(data), "--model", "oren-nayar", "--out", str(out), "--quiet"]
    start = time.perf_counter()
    process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    process.returncode = os.waitstatus_to_exitcode(status)
    stderr = process.stderr.read().decode(errors="replace") if process.stderr else ""
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime, "peak_mb": usage.ru_maxrss / 1024.0,
            "exit_status": process.returncode, "stderr_tail": stderr.strip().splitlines()[-1:] if stderr else [],
            "output_mb": sum(p.stat().st_size for p in out.iterdir()) / 1e6 if out.is_dir() else None,
            "files_mb": {p.name: round(p.stat().st_size / 1e6, 3) for p in out.iterdir()} if out.is_dir() else {}}


def chart(rows: list[dict], path: Path,
          title: str = "gonio fit DATA.csv --model oren-nayar: time, memory and output against the number of values"
          ) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 3.6))
    axes = fig.subplots(1, 3)
    n = np.array([r["n"] for r in rows], float)
    for ax, key, label in ((axes[0], "wall_s", "wall time [s]"), (axes[1], "peak_mb", "peak memory [MB]"),
                           (axes[2], "output_mb", "result folder [MB]")):
        ax.loglog(n, [r[key] for r in rows], "o-")
        ax.loglog(n, rows[1][key] * n / n[1], ":", color="grey", label="linear from 1e4")
        ax.set_xlabel("values fitted")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    axes[1].axhline(2048, color="tab:red", lw=0.8, label="2 GB")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main_correlated(million: bool) -> None:
    """``--correlated``: structured against dense covariance (module notes)."""
    sizes = tuple(sorted(set(SIZES) | set(DENSE_SIZES))) + ((1_000_000,) if million else ())
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            for dense in ((False, True) if n in DENSE_SIZES else (False,)):
                kind = "dense" if dense else "factors"
                data = Path(tmp) / f"data-{n}-{kind}.csv"
                write_correlated_data(n, data, dense)
                out = Path(tmp) / f"fit-{n}-{kind}"
                row = {"n": n, "covariance": kind, **run_fit(data, out)}
                if row["exit_status"] == 0:
                    row["parameters"] = fitted(out)
                shutil.rmtree(out, ignore_errors=True)
                rows.append(row)
                print(f"{n:>9,} values, {kind:>7}: {row['wall_s']:.1f} s wall, {row['cpu_s']:.1f} s CPU, "
                      f"{row['peak_mb']:.0f} MB peak, {row['output_mb'] or 0:.0f} MB written, exit {row['exit_status']}",
                      flush=True)
    structured = {r["n"]: r for r in rows if r["covariance"] == "factors"}
    record = {"machine": machine(), "command": "gonio fit DATA.csv --model oren-nayar --out FOLDER --quiet",
              "load_average": os.getloadavg(), "truth": TRUTH, "shared_sources": SHARED, "rows": rows,
              "time_1e5_over_1e4": structured[100_000]["wall_s"] / structured[10_000]["wall_s"],
              "cpu_1e5_over_1e4": structured[100_000]["cpu_s"] / structured[10_000]["cpu_s"],
              "dense_over_factors_wall": {n: next(r["wall_s"] for r in rows if r["n"] == n and r["covariance"] == "dense")
                                          / structured[n]["wall_s"] for n in DENSE_SIZES},
              "target_time_ratio": 12.0, "target_peak_mb": 2048.0}
    write_json("scale-correlated", record)
    chart([structured[n] for n in sizes], OUT / "scale-correlated.png",
          "gonio fit of correlated data (a diagonal plus 28 shared sources): time, memory and output")
    print(f"1e5 over 1e4: {record['time_1e5_over_1e4']:.2f}x wall, {record['cpu_1e5_over_1e4']:.2f}x CPU; dense over "
          f"factors: {record['dense_over_factors_wall']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--million", action="store_true", help="also fit 1e6 values")
    parser.add_argument("--correlated", action="store_true",
                        help="correlated errors: the covariance as factors against the dense matrix")
    args = parser.parse_args()
    if args.correlated:
        return main_correlated(args.million)
    sizes = SIZES + ((1_000_000,) if args.million else ())
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            data = Path(tmp) / f"data-{n}.csv"
            write_data(n, data)
            row = {"n": n, **run_fit(data, Path(tmp) / f"fit-{n}")}
            shutil.rmtree(Path(tmp) / f"fit-{n}", ignore_errors=True)
            rows.append(row)
            print(f"{n:>9,} values: {row['wall_s']:.1f} s wall, {row['cpu_s']:.1f} s CPU, {row['peak_mb']:.0f} MB peak, "
                  f"{row['output_mb']:.0f} MB written, exit {row['exit_status']}", flush=True)
    by_n = {r["n"]: r for r in rows}
    record = {"machine": machine(), "command": "gonio fit DATA.csv --model oren-nayar --out FOLDER --quiet",
              "truth": TRUTH, "noise": NOISE, "rows": rows,
              "time_1e5_over_1e4": by_n[100_000]["wall_s"] / by_n[10_000]["wall_s"],
              "cpu_1e5_over_1e4": by_n[100_000]["cpu_s"] / by_n[10_000]["cpu_s"],
              "target_time_ratio": 12.0, "target_peak_mb": 2048.0}
    write_json("scale", record)
    chart(rows, OUT / "scale.png")
    print(f"1e5 over 1e4: {record['time_1e5_over_1e4']:.2f}x wall, {record['cpu_1e5_over_1e4']:.2f}x CPU")


if __name__ == "__main__":
    main()
