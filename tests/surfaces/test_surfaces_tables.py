"""Rendered BRDF tables: coordinates, interpolation, the cache, specs and ``gonio tables``."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import gonio
from gonio.cli import main
from gonio.models.tabulated import store
from gonio.surfaces import VGrooveField
from gonio.surfaces import table as tables
from gonio.surfaces.spec import DEFAULT_PATHS, parse_surface_spec
from gonio.surfaces.table import (
    EXACT_GRIDS,
    FLOOR,
    GRIDS,
    THETA_MAX,
    SurfaceGrid,
    SurfaceTable,
    TabulatedSurface,
    grid_for,
    node_geometries,
    node_values,
    render_table,
    table_coordinates,
    table_key,
    table_path,
)

SMALL = SurfaceGrid(6, 5, 6)  # 180 nodes: a table in a fraction of a second at 200 paths


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_TABLE_DIR", str(tmp_path))
    return tmp_path


def _random_geometries(n, seed=1, top=THETA_MAX):
    rng = np.random.default_rng(seed)
    polar = lambda: np.minimum(np.degrees(np.arccos(rng.random(n))), top)  # noqa: E731 (uniform in solid angle)
    return polar(), rng.uniform(-180, 180, n), polar(), rng.uniform(-180, 180, n)


def test_nodes_sit_on_the_grid_coordinates():
    # the inverse map of the nodes and the forward map agree (the row beta = THETA_MAX,
    # where every zeta is the same geometry, aside); zeta = 1 is alpha = beta
    grid = GRIDS["vgrooves"]
    alpha, beta, dphi = node_geometries(grid)
    y, zeta, t = table_coordinates(alpha, beta, dphi)
    axes = grid.axes()
    nodes = np.meshgrid(*(axis.nodes() for axis in axes), indexing="ij")
    assert np.max(np.abs(y - nodes[0])) < 1e-12
    assert np.max(np.abs(zeta - nodes[1])[1:]) < 1e-9
    assert np.max(np.abs(t - nodes[2])) < 1e-3  # the phase angle's arcsine near 180 deg
    assert np.all(alpha >= beta) and np.allclose(alpha[:, -1], beta[:, -1])
    assert np.degrees(alpha).max() <= THETA_MAX + 1e-9


def test_coordinates_are_symmetric_in_source_and_viewer():
    ti, pi_, tr, pr = _random_geometries(200)
    one = table_coordinates(np.radians(ti), np.radians(tr), np.radians(pr - pi_))
    other = table_coordinates(np.radians(tr), np.radians(ti), np.radians(pi_ - pr))
    for a, b in zip(one, other):
        assert np.allclose(a, b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("model,params,grid,median,p99", [
    # the paper's rough-surface approximation (eq 33-35, kinked where its max/min switch)
    # and the pitted surface (Koenderink et al. eq 28 ends at theta_i + theta_r = 90 deg),
    # on the grids of sampled tables and on the finer ones of exact tables; bounds 1.5x
    # the measured median (1.0e-4, 1.7e-4; 1.1e-5, 1.7e-5) and 99th percentile (5.2e-3,
    # 7.0e-3; 1.6e-3, 1.9e-3)
    ("oren-nayar", {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0}, GRIDS["vgrooves"], 1.5e-4, 8e-3),
    ("pitted", {"rho": 0.9, "psi": 90.0, "coverage": 0.7}, GRIDS["pits"], 2.6e-4, 1.1e-2),
    ("oren-nayar", {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0}, EXACT_GRIDS["vgrooves"], 1.6e-5, 2.5e-3),
    ("pitted", {"rho": 0.9, "psi": 90.0, "coverage": 0.7}, EXACT_GRIDS["pits"], 2.6e-5, 2.9e-3),
])
def test_interpolation_error_between_the_nodes(model, params, grid, median, p99):
    # the grid and the cubic rule alone: a deterministic function tabulated at the nodes
    alpha, beta, dphi = (np.degrees(a) for a in node_geometries(grid))
    table = SurfaceTable(np.log(gonio.brdf(model, beta, 0.0, alpha, dphi, **params) + FLOOR))
    geometries = _random_geometries(3000)
    exact = gonio.brdf(model, *geometries, **params)
    error = np.abs(table(*geometries) / exact - 1.0)
    assert np.median(error) < median and np.percentile(error, 99) < p99


def test_exact_tables_get_the_finer_grids():
    assert grid_for(parse_surface_spec("kind=pits,psi=60,coverage=1,rho=0.9")) == EXACT_GRIDS["pits"]
    assert grid_for(parse_surface_spec("kind=vgrooves,sigma=30,rho=0.9,bounces=2")) == EXACT_GRIDS["vgrooves"]
    assert grid_for(parse_surface_spec("kind=vgroove,theta_a=40,rho=0.9,bounces=1")) == EXACT_GRIDS["vgroove"]
    assert grid_for(parse_surface_spec("kind=vgrooves,sigma=30,rho=0.9")) == GRIDS["vgrooves"]
    assert grid_for(parse_surface_spec("kind=vgrooves,sigma=30,rho=0.9,bounces=3")) == GRIDS["vgrooves"]
    assert grid_for(parse_surface_spec("kind=heightfield,sigma=30,rho=0.9,bounces=1")) == GRIDS["heightfield"]


def test_table_holds_its_node_values_and_threads_change_nothing():
    # every node is node_values of its geometry alone (common random numbers: a node's
    # paths do not depend on the other nodes), whatever the threads
    spec = parse_surface_spec("kind=vgrooves,sigma=25,rho=0.8,paths=200,seed=3")
    arrays = render_table(spec, SMALL, workers=1)
    assert np.array_equal(arrays["log_brdf"], render_table(spec, SMALL, workers=2)["log_brdf"])
    alpha, beta, dphi = (np.degrees(a) for a in node_geometries(SMALL))
    index = (2, 3, 4)
    value, error = node_values(spec, beta[index][None], alpha[index][None], dphi[index][None])
    assert math.exp(arrays["log_brdf"][index]) - FLOOR == pytest.approx(float(value[0]), rel=1e-12)
    assert arrays["relative_error"][index] == pytest.approx(float(error[0] / value[0]), rel=1e-12)
    table = SurfaceTable(arrays["log_brdf"])
    # cubic Lagrange interpolation passes through the nodes, from either side (reciprocity)
    assert table(beta[index], 0.0, alpha[index], dphi[index]) == pytest.approx(float(value[0]), rel=1e-12)
    assert table(alpha[index], 30.0, beta[index], 30.0 - dphi[index]) == pytest.approx(float(value[0]), rel=1e-12)


def test_table_values_below_the_horizon_nan_and_beyond_theta_max():
    spec = parse_surface_spec("kind=vgrooves,sigma=25,rho=0.8,paths=200")
    table = SurfaceTable(render_table(spec, SMALL, workers=1)["log_brdf"])
    values = table([95.0, np.nan, 89.5, 30.0], 0.0, [30.0, 30.0, 40.0, 95.0], 180.0)
    assert values[0] == 0.0 and np.isnan(values[1]) and values[3] == 0.0
    assert values[2] == table(THETA_MAX, 0.0, 40.0, 180.0)


def test_first_use_renders_and_caches_later_uses_load(cache, monkeypatch):
    spec = parse_surface_spec("kind=pits,psi=60,coverage=0.5,rho=0.7,paths=100")
    calls = []
    progress = lambda done, total, left: calls.append((done, total, left))  # noqa: E731
    first = TabulatedSurface(spec, SMALL, progress=progress, workers=1)
    value = first(40.0, 0.0, 30.0, 180.0)
    assert first.rendered and first.path.is_file() and first.path.parent == cache
    assert calls[0] == (0, 180, None) and calls[-1][:2] == (180, 180) and calls[-1][2] == 0.0
    assert store.RENDERED_NAME.fullmatch(first.path.name)

    def no_rendering(*args, **kwargs):
        raise AssertionError("a cached table was rendered again")

    monkeypatch.setattr(tables, "render_table", no_rendering)
    second = TabulatedSurface(spec, SMALL, workers=1)
    assert second(40.0, 0.0, 30.0, 180.0) == value and not second.rendered
    changed = TabulatedSurface(parse_surface_spec("kind=pits,psi=61,coverage=0.5,rho=0.7,paths=100"), SMALL)
    assert changed.path != first.path
    with pytest.raises(AssertionError, match="rendered again"):
        changed.load()


def test_the_key_holds_everything_that_changes_the_numbers():
    base = "kind=heightfield,sigma=20,rho=0.5,cells=64,correlation=4"
    spec = parse_surface_spec(base)
    key = table_key(spec)
    assert key["parameters"] == {"sigma": 20.0, "rho": 0.5, "cells": 64, "correlation": 4.0, "seed": 0}
    assert {"renderer", "coordinates", "format", "paths", "seed", "bounces", "grid", "theta_max", "floor"} <= set(key)
    variants = [base, base + ",paths=1000", base + ",seed=1", base + ",bounces=2", base.replace("cells=64", "cells=65"),
                base.replace("rho=0.5", "rho=0.6"), base.replace("correlation=4", "correlation=5")]
    assert len({table_path(parse_surface_spec(text)) for text in variants}) == len(variants)
    assert table_path(spec, SurfaceGrid(6, 5, 7)) != table_path(spec)
    # the same surface written in another order is the same table
    assert table_path(parse_surface_spec("rho=0.5,kind=heightfield,correlation=4,cells=64,sigma=20")) == \
        table_path(spec)


def test_a_cached_file_with_another_key_is_refused(cache):
    spec = parse_surface_spec("kind=vgrooves,sigma=10,rho=0.5,paths=100")
    surface = TabulatedSurface(spec, SMALL, workers=1)
    surface.load()
    arrays = dict(np.load(surface.path))
    arrays["key"] = np.array(json.dumps({"kind": "vgrooves", "other": 1}))
    store.save(surface.path, arrays)
    with pytest.raises(store.TableError, match="holds another surface's numbers"):
        TabulatedSurface(spec, SMALL).load()


def test_tables_clear_removes_surface_tables_and_keeps_look_alikes(cache, capsys):
    spec = parse_surface_spec("kind=vgrooves,sigma=10,rho=0.5,paths=100")
    surface = TabulatedSurface(spec, SMALL, workers=1)
    surface.load()
    look_alike = cache / "surface-vgrooves-0123456789abcdef.npz"
    np.savez(look_alike, data=np.zeros(2))  # named like a surface table, not written by gonio
    assert main(["tables", "info"]) == 0
    out = capsys.readouterr().out
    assert "rendered surfaces (gonio.surfaces): 1 table" in out and surface.path.name in out
    assert "surface:kind=vgrooves,sigma=10,rho=0.5,paths=100,seed=0,bounces=all" in out
    assert main(["tables", "clear"]) == 0
    out = capsys.readouterr().out
    assert f"removed {surface.path}" in out and f"kept {look_alike}" in out
    assert not surface.path.exists() and look_alike.exists()


def test_tables_info_says_which_tables_sample_nothing(cache, capsys, monkeypatch):
    monkeypatch.setitem(EXACT_GRIDS, "pits", SMALL)
    TabulatedSurface(parse_surface_spec("kind=pits,psi=60,coverage=0.5,rho=0.7")).load()
    TabulatedSurface(parse_surface_spec("kind=vgrooves,sigma=10,rho=0.5,paths=100"), SMALL, workers=1).load()
    assert main(["tables", "info"]) == 0
    out = capsys.readouterr().out
    assert "surface:kind=pits,psi=60,coverage=0.5,rho=0.7,paths=20000,seed=0,bounces=all\n" \
           f"        {SMALL.y * SMALL.zeta * SMALL.t} nodes, every order exact, nothing sampled" in out
    assert "180 nodes, Monte Carlo error per node median" in out


def test_tables_build_renders_a_surface_once(cache, capsys, monkeypatch):
    monkeypatch.setitem(GRIDS, "vgrooves", SMALL)
    assert main(["tables", "build", "surface:kind=vgrooves,sigma=10,rho=0.5,paths=100", "--workers", "1"]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("rendered: ") and "table nodes" in captured.err
    assert "rendering the BRDF table of surface:kind=vgrooves" in captured.err
    assert main(["tables", "build", "surface:kind=vgrooves,sigma=10,rho=0.5,paths=100"]) == 0
    assert capsys.readouterr().out.startswith("already cached: ")
    assert main(["tables", "build", "surface:kind=vgrooves,sigma=10"]) == 2
    assert "kind vgrooves needs rho" in capsys.readouterr().err


@pytest.mark.parametrize("spec,message", [
    ("sigma=30,rho=0.9", "no kind; expected kind= one of heightfield, pits, vgroove, vgrooves"),
    ("kind=grooves,sigma=30", "unknown kind 'grooves'"),
    ("kind=vgrooves,sigma=30,rho=0.9,psi=3", "unknown key 'psi' for kind vgrooves; accepted: sigma [deg], rho [-]"),
    ("kind=vgrooves,rho=0.9", "kind vgrooves needs sigma [deg]"),
    ("kind=vgrooves,sigma=95,rho=0.9", r"sigma [deg] = 95 is outside its valid range [0, 90]"),
    ("kind=vgrooves,sigma=thirty,rho=0.9", "sigma = 'thirty' is not a number"),
    ("kind=vgrooves,sigma=30,rho=0.9,paths=10", "paths = '10'; expected paths per table node, an integer >= 100"),
    ("kind=vgrooves,sigma=30,rho=0.9,bounces=0", "bounces = '0'; expected 'all' or the number of scattering events"),
    ("kind=vgrooves,sigma=30,sigma=20,rho=0.9", "sigma is given twice"),
    ("kind=heightfield,sigma=70,rho=0.9", r"sigma [deg] = 70 is outside its valid range [0, 60]"),
    ("kind=heightfield,sigma=30,rho=0.9,cells=64,correlation=9", r"correlation [cells] = 9 is outside"),
    ("kind=pits,psi=0,coverage=0.5,rho=0.5", r"psi [deg] = 0 is outside its valid range (0, 90]"),
])
def test_surface_spec_errors_name_the_key(spec, message):
    with pytest.raises(ValueError, match=None) as error:
        parse_surface_spec(spec)
    assert message in str(error.value) and repr(spec) in str(error.value)


def test_surface_spec_defaults_and_canonical_text():
    spec = parse_surface_spec("kind=vgroove,theta_a=40,rho=0.5,bounces=2")
    assert spec.surface.phi_a is None and spec.surface.isotropic and spec.bounces == 2
    assert spec.paths == DEFAULT_PATHS and spec.seed == 0
    assert spec.text() == "kind=vgroove,theta_a=40,rho=0.5,paths=20000,seed=0,bounces=2"
    assert not parse_surface_spec("kind=vgroove,theta_a=40,phi_a=10,rho=0.5").surface.isotropic
    field = parse_surface_spec("kind=heightfield,sigma=20,rho=0.5,seed=4").surface
    assert field.seed == 4 and field.cells == 256 and field.correlation == 8.0
    assert isinstance(parse_surface_spec("kind=vgrooves,sigma=0,rho=1").surface, VGrooveField)
