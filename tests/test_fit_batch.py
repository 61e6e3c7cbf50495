"""Batch fits (gonio.batch, ``gonio fit-batch``): seeds per task, parallel runs equal to the
serial one, resume, failures as rows, the Dask path, the tables and the overview."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import gonio
from gonio.batch import BatchSettings, fit_many, plan_tasks, task_seed
from gonio.cli import main
from gonio.fitting import Dataset

#: Small chains: a fit takes 0.1-0.3 s, enough to run the whole path (least squares, MCMC,
#: verdict, save); the numbers need only be the same between runs, not converged.
SETTINGS = BatchSettings(n_walkers=8, max_steps=300, tau_multiple=5.0, rhat_limit=1.5)
MODELS = ["minnaert", "lambert"]
TRUTH = {"s0": (0.5, 0.6), "s1": (0.7, 0.8), "s2": (0.3, 0.5)}
SMALL = ["--walkers", "8", "--max-steps", "300", "--tau-multiple", "5", "--rhat-limit", "1.5"]


def _dataset(name: str) -> Dataset:
    rho, k = TRUTH[name]
    theta_r = np.arange(0.0, 80.0, 5.0)
    value = gonio.brdf("minnaert", 30, 0, theta_r, 0, rho=rho, k=k)
    noise = 1 + 0.02 * np.random.default_rng(int(name[1])).standard_normal(theta_r.size)
    return Dataset(30, 0, theta_r, 0, value * noise, 0.02 * value, label=name)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("inputs")
    for name in TRUTH:
        _dataset(name).to_csv(folder / f"{name}.csv")
    (folder / "broken.csv").write_text("theta_i,phi_i,theta_r,phi_r,value\n1,2,3\n")
    return folder


@pytest.fixture(scope="module")
def serial(inputs, tmp_path_factory):
    """The reference: every fit in this process, one after the other."""
    return fit_many(inputs, MODELS, tmp_path_factory.mktemp("serial") / "out", workers=1, settings=SETTINGS, seed=3)


def _numbers(rows):
    """The rows without wall times, NaN as None (NaN != NaN), for exact comparison."""
    def clean(value):
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items() if k not in ("wall_seconds", "result_id")}
        return None if isinstance(value, float) and math.isnan(value) else value
    return [clean(row) for row in rows]


def test_task_seed_follows_the_task_not_the_order(tmp_path):
    tasks = plan_tasks({"a": "a.csv", "b": "b.csv"}, MODELS, tmp_path, seed=7)
    reordered = plan_tasks({"b": "b.csv", "a": "a.csv"}, MODELS[::-1], tmp_path, seed=7)
    assert {t.task_id: t.seed for t in tasks} == {t.task_id: t.seed for t in reordered}
    assert len({t.seed for t in tasks}) == len(tasks)  # every task its own stream
    assert tasks[0].seed == task_seed(7, "a--minnaert") != task_seed(8, "a--minnaert")


def test_serial_batch_fits_every_input_and_model(serial, inputs):
    assert [row["task_id"] for row in serial.rows] == [f"{name}--{model}" for name in ("broken", "s0", "s1", "s2")
                                                      for model in MODELS]
    for row in serial.rows[2:]:
        assert row["status"] == "ok" and row["n_data"] == 16
        assert Path(serial.out, row["task_id"], "result.json").is_file()
    for name, (rho, k) in TRUTH.items():
        row = next(r for r in serial.rows if r["task_id"] == f"{name}--minnaert")
        p = row["parameters"]
        # 2 % noise on 16 values: rho and k known to ~1 % and ~4 %; the 95 % interval holds the truth
        assert p["rho"]["p2_5"] < rho < p["rho"]["p97_5"] and p["k"]["p2_5"] < k < p["k"]["p97_5"]
        assert row["verdict"] == "adequate"
        lambert = next(r for r in serial.rows if r["task_id"] == f"{name}--lambert")
        assert lambert["verdict"] == "inadequate"  # k != 1: Lambert cannot follow the limb darkening


def test_two_joblib_workers_give_the_serial_numbers(serial, inputs, tmp_path):
    parallel = fit_many(inputs, MODELS, tmp_path / "out", workers=2, settings=SETTINGS, seed=3)
    assert _numbers(parallel.rows) == _numbers(serial.rows)
    other_seed = fit_many({"s0": inputs / "s0.csv"}, ["minnaert"], tmp_path / "other", settings=SETTINGS, seed=4)
    assert other_seed.rows[0]["parameters"] != serial.rows[2]["parameters"]  # the comparison can fail


def test_broken_input_is_a_failure_row(serial):
    for row in serial.rows[:2]:
        assert row["status"] == "failed" and "broken.csv" in row["failure"] and "missing value" in row["failure"]
        record = json.loads((serial.out / row["task_id"] / "task.json").read_text())
        assert record["status"] == "failed" and record["failure"] == row["failure"]
    assert serial.failed == ["broken--minnaert", "broken--lambert"]
    overview = serial.files["overview"].read_text()
    assert "2 failed" in overview and "broken--lambert: ValueError" in overview


def test_resume_skips_finished_fits(serial, inputs, tmp_path):
    import shutil

    out = tmp_path / "out"
    shutil.copytree(serial.out, out)
    shutil.rmtree(out / "s1--lambert")
    before = (out / "s0--minnaert" / "result.json").stat().st_mtime_ns
    said = []
    again = fit_many(inputs, MODELS, out, workers=1, settings=SETTINGS, seed=3, announce=said.append)
    assert sorted(again.skipped) == sorted(r["task_id"] for r in serial.rows[2:] if r["task_id"] != "s1--lambert")
    assert any(line.startswith("skipping 5 finished fit(s)") for line in said)
    assert (out / "s0--minnaert" / "result.json").stat().st_mtime_ns == before  # not fitted again
    assert _numbers(again.rows) == _numbers(serial.rows)  # the refitted task too: its seed is its own
    with pytest.raises(ValueError, match="n_walkers: recorded 8, now 16"):
        fit_many(inputs, MODELS, out, settings=BatchSettings(n_walkers=16, max_steps=300, tau_multiple=5.0,
                                                             rhat_limit=1.5), seed=3)


def test_tables_hold_every_fit(serial):
    import csv

    import xarray as xr

    with open(serial.files["csv"], newline="") as handle:
        table = list(csv.DictReader(handle))
    assert [r["task_id"] for r in table] == [r["task_id"] for r in serial.rows]
    row = serial.rows[2]
    assert float(table[2]["rho_median"]) == row["parameters"]["rho"]["median"]
    assert float(table[2]["chi2"]) == row["chi2"] and table[2]["verdict"] == row["verdict"]
    assert table[3]["k_median"] == ""  # lambert has no k
    with xr.open_dataset(serial.files["netcdf"], engine="h5netcdf") as data:
        assert list(data["task"].values) == [r["task_id"] for r in serial.rows]
        assert float(data["p97_5"].sel(task="s0--minnaert", parameter="k")) == row["parameters"]["k"]["p97_5"]
        assert float(data["r_hat"].sel(task="s0--minnaert", parameter="rho")) == row["parameters"]["rho"]["r_hat"]
        assert str(data["failure"].values[0]).startswith("ValueError")
    assert (serial.out / "overview.png").stat().st_size > 1000


def test_dask_local_cluster_gives_the_same_table(serial, inputs, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            batch = fit_many(inputs, MODELS, tmp_path / "out", scheduler=client, settings=SETTINGS, seed=3)
    assert _numbers(batch.rows) == _numbers(serial.rows)


def test_datasets_and_loaders_as_inputs_with_one_blas_thread(tmp_path):
    from threadpoolctl import threadpool_info

    threads = []

    def load():  # runs inside the task, as the fit and the save do
        threads.extend(info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas")
        return _dataset("s1")

    batch = fit_many({"one": _dataset("s0"), "two": load}, "minnaert", tmp_path / "out", settings=SETTINGS, seed=3,
                     overview=False)
    assert [row["task_id"] for row in batch.rows] == ["one--minnaert", "two--minnaert"]
    assert all(row["status"] == "ok" for row in batch.rows) and "overview" not in batch.files
    assert threads and set(threads) == {1}  # this process has one per core otherwise


def test_command_line(inputs, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["fit-batch", str(inputs / "s0.csv"), str(inputs / "broken.csv"), "--model", "minnaert",
                 "--out", str(out), "--workers", "1", "--quiet", *SMALL])
    assert code == 6  # a fit failed
    assert "2 fits: 1 fitted, 0 skipped (finished earlier), 1 failed" in capsys.readouterr().out
    code = main(["fit-batch", str(inputs / "s0.csv"), "--model", "minnaert", "--out", str(out), "--quiet", *SMALL])
    assert code == 0 and "1 fits: 0 fitted, 1 skipped" in capsys.readouterr().out
    assert main(["fit-batch", str(inputs / "s0.csv"), "--model", "nonesuch", "--out", str(tmp_path / "x")]) == 2
    assert main(["fit-batch", "--model", "minnaert", "--out", str(tmp_path / "x")]) == 2
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "notes.txt").write_text("mine")
    assert main(["fit-batch", str(inputs / "s0.csv"), "--model", "lambert", "--out", str(tmp_path / "foreign")]) == 2
    assert "holds files but no fit batch" in capsys.readouterr().err
