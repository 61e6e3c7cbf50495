"""The tabulated model's MCMC with every walker in one evaluation against one walker at a
time, in one run.

``oren-nayar-tabulated`` interpolates f1 and f2 in the table's roughness coordinate from
geometry columns it keeps per roughness node (gonio/models/tabulated/lookup.py). A walker
needs four such columns; the whole ensemble's rows are now combined in one call
(``rows``), the same columns summed in the same order, where the sampler once called the
model once per walker (``Model.broadcasts_params`` False: one evaluation per distinct
parameter combination).

Problem: the demo's kind of fit, ``oren-nayar-tabulated`` (rho 0.9, sigma 30 deg) on 126
BRDF values at the Fig 16 incidences (30, 45, 60 deg, 42 views each) with 1 % noise,
through the rig's source and camera apertures (the aperture average of docs/fitting.md),
and the same without apertures. For each: ``gonio.fitting.fit`` (least squares, MCMC with
its defaults), 3 seeds, alternating the two paths; MCMC wall time and the posterior
medians of both (they must agree).

Writes docs/benchmarks/tabulated_walkers.json. Run:
``python benchmarks/bench_tabulated_walkers.py`` (about a minute).
"""
from __future__ import annotations

import contextlib
import time
import warnings

import numpy as np

from _common import write_json

from gonio import models
from gonio.fitting import Dataset, fit
from gonio.fitting.problem import predict_quantity
from gonio.geometry import in_plane_angles

TRUTH = {"rho": 0.9, "sigma": 30.0}
SEEDS = (1, 2, 3)
APERTURES_SR = [0.003, 0.0009]


def dataset(apertures: bool) -> Dataset:
    views = np.linspace(-80.0, 80.0, 42)
    geometry = in_plane_angles(np.repeat([30.0, 45.0, 60.0], views.size), np.tile(views, 3))
    exact = predict_quantity("oren-nayar-tabulated", "brdf", *geometry, TRUTH)
    value = exact * (1 + 0.01 * np.random.default_rng(30).standard_normal(exact.shape))
    metadata = {"aperture_sr": APERTURES_SR} if apertures else {}
    return Dataset(*geometry, value, 0.01 * exact, metadata=metadata)


@contextlib.contextmanager
def one_walker_at_a_time():
    """The model evaluated once per parameter combination, as before ``rows``."""
    model = models.get("oren-nayar-tabulated")
    object.__setattr__(model, "broadcasts_params", False)
    try:
        yield
    finally:
        object.__setattr__(model, "broadcasts_params", True)


def run(data: Dataset, seed: int, together: bool) -> dict:
    context = contextlib.nullcontext() if together else one_walker_at_a_time()
    with context, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        began = time.perf_counter()
        result = fit(data, "oren-nayar-tabulated", seed=seed, polish_table=False)
        total = time.perf_counter() - began
    return {"seed": seed, "mcmc_s": result.mcmc.wall_seconds, "total_s": total, "steps": result.mcmc.n_steps,
            "medians": {k: float(v) for k, v in result.best_values().items()}}


def main() -> None:
    record = {"command": "python benchmarks/bench_tabulated_walkers.py", "truth": TRUTH, "cases": {}}
    for apertures in (False, True):
        data = dataset(apertures)
        fit(data, "oren-nayar-tabulated", seed=0, polish_table=False)  # warm: table, compiled code
        rows = {"together": [], "one_at_a_time": []}
        for seed in SEEDS:
            rows["together"].append(run(data, seed, True))
            rows["one_at_a_time"].append(run(data, seed, False))
        median = {k: float(np.median([r["mcmc_s"] for r in v])) for k, v in rows.items()}
        name = "through the apertures" if apertures else "point geometry"
        record["cases"][name] = {"n_data": data.n, "runs": rows, "median_mcmc_s": median,
                                 "speedup": median["one_at_a_time"] / median["together"]}
        print(f"{name}: MCMC {median['together']:.2f} s together, {median['one_at_a_time']:.2f} s one walker at a "
              f"time: {record['cases'][name]['speedup']:.1f}x", flush=True)
    write_json("tabulated_walkers", record)


if __name__ == "__main__":
    main()
