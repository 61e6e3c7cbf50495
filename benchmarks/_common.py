"""Helpers shared by the benchmark scripts: machine facts, timing, JSON output."""
from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "benchmarks"


def machine() -> dict:
    """Facts about the machine a benchmark ran on (so ratios can be read in context)."""
    info = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
    }
    try:
        cc = subprocess.run(["cc", "--version"], capture_output=True, text=True, check=True)
        info["cc"] = cc.stdout.splitlines()[0]
    except (OSError, subprocess.CalledProcessError):
        info["cc"] = None
    return info


def mcmc_design() -> str:
    """The MCMC ``gonio.fitting.fit`` runs by default, read from the code (move, walkers,
    stopping rule), for a benchmark's JSON and prose."""
    import inspect

    from gonio.fitting import fit
    from gonio.fitting.mcmc import DEFAULT_WALKERS, sample_posterior
    from gonio.fitting.moves import MOVES

    def parameters(function) -> dict:
        return {name: p.default for name, p in inspect.signature(function).parameters.items()
                if p.default is not inspect.Parameter.empty}

    # fit's own defaults (max_steps, tau_multiple, rhat_limit) win over those of the
    # sampler it calls; the rest (move, tau_rtol) fit leaves to sample_posterior
    defaults = {**parameters(sample_posterior), **parameters(fit)}
    return (f"gonio.fitting.fit defaults: moves '{defaults['moves']}' ({MOVES[defaults['moves']]}), "
            f"{DEFAULT_WALKERS} walkers, chain >= {defaults['tau_multiple']:g} tau with tau stable to "
            f"{defaults['tau_rtol']:.0%}, R-hat < {defaults['rhat_limit']:g}, max {defaults['max_steps']} steps; "
            "burn-in 2 max(tau), thinning min(tau)/2")


def best_time(function: Callable[[], object], repeats: int = 5, min_time: float = 0.05) -> float:
    """Best wall time of ``function()`` over ``repeats`` runs [s] (each run repeated until
    it lasts ``min_time`` to beat timer resolution)."""
    best = float("inf")
    for _ in range(repeats):
        loops, elapsed = 0, 0.0
        start = time.perf_counter()
        while elapsed < min_time or loops == 0:
            function()
            loops += 1
            elapsed = time.perf_counter() - start
        best = min(best, elapsed / loops)
    return best


def write_json(name: str, payload: dict) -> Path:
    """Write ``docs/benchmarks/<name>.json`` and return its path."""
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / f"{name}.json"
    path.write_text(json.dumps(payload, indent=2, default=float) + "\n")
    return path


def random_geometries(n: int, seed: int = 0, max_theta: float = 89.9) -> tuple[np.ndarray, ...]:
    """``n`` random (theta_i, phi_i, theta_r, phi_r) [deg], uniform in angle."""
    rng = np.random.default_rng(seed)
    return (
        rng.uniform(0.0, max_theta, n),
        rng.uniform(-180.0, 180.0, n),
        rng.uniform(0.0, max_theta, n),
        rng.uniform(-180.0, 180.0, n),
    )


def wilson(k: int, n: int) -> list[float]:
    """Wilson 95 % score interval of a proportion ``k / n`` (scipy.stats.binomtest), [nan, nan]
    for ``n = 0``."""
    if n == 0:
        return [float("nan"), float("nan")]
    from scipy import stats

    interval = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    return [float(interval.low), float(interval.high)]


def record_on_emulator(protocol, sample: str, seed: int, folder: Path, reflectance: float | None = None,
                       realism: str = "lab", name: str = "study", extend=None):
    """Run ``protocol`` (a :class:`gonio.protocols.Protocol`) on an in-process emulated rig
    with ``sample`` (a sample spec) and emulator seed ``seed``, recording into ``folder``;
    the reference standard, where the protocol swaps it in, has ``reflectance`` (default:
    the protocol's own). Returns the acquisition's run (``gonio.acquisition.run_protocol``)."""
    from gonio import acquisition
    from gonio.cli.run import emulated_rig

    if reflectance is None and protocol.reference is not None:
        reflectance = protocol.reference.reflectance
    with emulated_rig(sample, seed, name=f"{name}-{seed}", realism=realism) as (rig, _, change_sample, metadata):
        return acquisition.run_protocol(protocol, rig, folder, metadata=metadata, extend=extend,
                                        change_sample=lambda which, **how: change_sample(which, reflectance, **how))
