"""Shared fixtures: geometry sets used by the model-independent tests, and the benchmark
scripts loaded as modules for the tests of their core functions."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

import gonio


def special_geometries() -> tuple[np.ndarray, ...]:
    """Grazing, normal and theta_i == theta_r geometries (DESIGN.md, "Bad input").

    These are the legitimate geometries where closed forms divide by sines and cosines
    that vanish; models must give finite values there without numpy warnings.
    """
    thetas = [0.0, 1e-9, 30.0, 45.0, 60.0, 89.999, 90.0]
    phis = [0.0, 90.0, 180.0, 270.0, 45.0]
    rows = []
    for ti in thetas:
        for tr in thetas:
            for dphi in phis:
                rows.append((ti, 0.0, tr, dphi))
    for t in thetas:  # theta_i == theta_r, retro and mirror directions
        rows.append((t, 10.0, t, 10.0))
        rows.append((t, 10.0, t, 190.0))
    return tuple(np.array(rows).T)


def fast_models() -> list[str]:
    """Registered models cheap enough to evaluate on hundreds of geometries in a test."""
    return [name for name in gonio.models.available() if not name.endswith("-exact")]


@pytest.fixture(params=gonio.models.available())
def model_name(request) -> str:
    return request.param


def benchmark_script(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` imported as the module ``name`` (registered in
    ``sys.modules`` while it runs, which dataclasses need)."""
    root = Path(__file__).resolve().parents[1] / "benchmarks"
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))  # the scripts import their _common
    spec = importlib.util.spec_from_file_location(name, root / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
