"""The report drawn by worker processes (gonio.report.workers): the same files as in one
process, failures surfaced and the report then drawn in-process, the result untouched."""
from __future__ import annotations

import hashlib
import os
import signal

import pytest

from gonio.fitting import fit
from gonio.report import fit_report, workers
from gonio.report.fit_report import FIGURES, REPORT_FILES, write_report
from gonio.report.workers import (FIGURE_COST, ReportWorkerError, ReportWorkers, ReportWorkerWarning,
                                  finish_report, report_processes, share_figures, start_report_workers)

from .synthetic import synthetic_dataset

#: A worker started with fork runs the test process's (monkeypatched) code.
needs_fork = pytest.mark.skipif(workers.START_METHOD != "fork", reason="fault injection relies on fork")


@pytest.fixture(scope="module")
def saved_fit(tmp_path_factory):
    """A small Minnaert fit with MCMC, saved (result.json, chain.npz, posterior.nc)."""
    data = synthetic_dataset("minnaert", dict(rho=0.6, k=0.7), 0.005, seed=1)
    folder = tmp_path_factory.mktemp("fit")
    fit(data, "minnaert", n_walkers=8, tau_multiple=10.0, rhat_limit=1.05, seed=0).save(folder)
    return folder


def _contents(folder, names=REPORT_FILES) -> dict[str, bytes]:
    return {name: (folder / name).read_bytes() for name in names}


def _digests(folder) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir() if p.name not in REPORT_FILES}


@pytest.fixture(scope="module")
def in_process(saved_fit, tmp_path_factory):
    """The report drawn in this process: the reference every other path must equal."""
    out = tmp_path_factory.mktemp("in-process")
    write_report(saved_fit, out, processes=1)
    return _contents(out)


def test_figure_costs_name_every_figure_of_the_report():
    assert list(FIGURE_COST) == [name for name, *_ in FIGURES]


def test_shares_cover_every_figure_once_balanced_lightest_first():
    for count in (1, 2, 3, 7):
        shares = share_figures(count)
        assert len(shares) == count
        assert sorted(n for share in shares for n in share) == sorted(FIGURE_COST)
        costs = [sum(FIGURE_COST[n] for n in share) for share in shares]
        assert costs == sorted(costs)
    light, heavy = (sum(FIGURE_COST[n] for n in share) for share in share_figures(2))
    # Greedy longest-first: the two shares differ by at most the lightest figure's cost.
    assert heavy - light <= min(FIGURE_COST.values()) + 1e-12


def test_number_of_processes_from_the_environment():
    assert report_processes({"GONIO_REPORT_PROCESSES": "3"}) == 3
    assert report_processes({}) == min(2, os.cpu_count() or 1)
    for bad in ("0", "two", "-1", "1.5"):
        with pytest.raises(ValueError, match="GONIO_REPORT_PROCESSES.*whole number"):
            report_processes({"GONIO_REPORT_PROCESSES": bad})


def test_two_processes_write_the_same_files_as_one(saved_fit, in_process, tmp_path):
    write_report(saved_fit, tmp_path, processes=2)
    assert _contents(tmp_path) == in_process


def test_a_result_in_memory_is_sent_to_the_worker(tmp_path):
    # A fresh result caches its FitProblem (the model's prepared functions, which do not
    # pickle); the worker gets the result without it and rebuilds it.
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005)
    result = fit(data, "lambert", n_walkers=8, tau_multiple=10.0, rhat_limit=1.05, seed=0)
    result.problem()
    write_report(result, tmp_path / "one", processes=1)
    write_report(result, tmp_path / "two", processes=2)
    assert _contents(tmp_path / "two") == _contents(tmp_path / "one")
    assert "_problem" in result.__dict__  # the caller's result keeps its cache


def test_command_workers_write_the_same_files_and_keep_the_result(saved_fit, in_process, tmp_path):
    # gonio fit --report: one worker and its helper draw the report of the saved result.
    before = _digests(saved_fit)
    pool = start_report_workers(2)
    assert pool is not None
    path = finish_report(pool, saved_fit)
    assert path == saved_fit / "report.html"
    assert _contents(saved_fit) == in_process
    assert _digests(saved_fit) == before
    assert not any(process.is_alive() for process, _ in pool._workers)  # stopped after the report


def test_spawned_workers_write_the_same_files(saved_fit, in_process, tmp_path):
    # The start method of macOS and Windows: a fresh interpreter that imports numpy, gonio
    # and matplotlib itself (2-3 s here; one worker, no helper, to keep it to one).
    with ReportWorkers(1, "spawn") as pool:
        path, messages = pool.write_report(saved_fit, tmp_path)
    assert messages == []
    assert path == tmp_path / "report.html"
    assert _contents(tmp_path) == in_process


def _break_outside(monkeypatch, parent: int, how: str, figure: str = "fit-corner.png") -> None:
    """Make ``figure`` fail (raise, or end the process) in any process but ``parent``."""
    original = {name: f for name, _, f, _ in FIGURES}[figure]

    def make(result):
        if os.getpid() != parent:
            if how == "exit":
                os._exit(3)
            raise RuntimeError(f"{figure} broke in the worker")
        return original(result)

    figures = tuple((name, title, make if name == figure else f, caption) for name, title, f, caption in FIGURES)
    monkeypatch.setattr(fit_report, "FIGURES", figures)


@needs_fork
@pytest.mark.parametrize("how, message", [("raise", "RuntimeError: fit-corner.png broke in the worker"),
                                          ("exit", r"exited \(code 3\) before it replied")])
def test_a_failing_worker_is_reported_and_the_report_drawn_here(saved_fit, in_process, monkeypatch, capsys, how,
                                                                message):
    _break_outside(monkeypatch, os.getpid(), how)
    before = _digests(saved_fit)
    with ReportWorkers(1) as pool:
        pool.submit(0, ("figures", saved_fit, None, ("fit-corner.png",)))
        with pytest.raises(ReportWorkerError, match=message):
            pool.wait(0)
    for name in REPORT_FILES:
        (saved_fit / name).unlink(missing_ok=True)
    finish_report(start_report_workers(2), saved_fit)
    err = capsys.readouterr().err
    assert "gonio: warning:" in err and "drawing the report in this process instead" in err
    assert _contents(saved_fit) == in_process  # complete, and as the in-process report
    assert _digests(saved_fit) == before  # the saved result is untouched


@needs_fork
def test_a_failing_helper_is_a_warning_and_its_share_drawn_here(saved_fit, in_process, monkeypatch, tmp_path):
    helper_figure = share_figures(2)[1][0]  # the lightest share is drawn here, the other by the helper
    _break_outside(monkeypatch, os.getpid(), "raise", helper_figure)
    with pytest.warns(ReportWorkerWarning, match=f"{helper_figure} broke in the worker"):
        write_report(saved_fit, tmp_path, processes=2)
    assert _contents(tmp_path) == in_process


def test_workers_that_cannot_start_leave_the_report_to_this_process(saved_fit, in_process, monkeypatch, capsys,
                                                                   tmp_path):
    def refuse(*args, **kwargs):
        raise OSError("no processes left")

    monkeypatch.setattr(workers.ReportWorkers, "__init__", refuse)
    assert start_report_workers(2) is None
    assert "report workers could not start (OSError: no processes left)" in capsys.readouterr().err
    with pytest.warns(ReportWorkerWarning, match="could not start"):
        write_report(saved_fit, tmp_path, processes=2)
    assert _contents(tmp_path) == in_process


def test_one_process_starts_no_worker():
    assert start_report_workers(1) is None
    with pytest.raises(ValueError, match="processes = 0"):
        write_report("unused", processes=0)


def test_ctrl_c_is_left_to_the_command(saved_fit, in_process, tmp_path):
    # Ctrl-C reaches every process of the terminal's group: the command stops its workers;
    # a worker itself ignores it (no traceback of its own) and goes on answering.
    with ReportWorkers(1) as pool:
        process, _ = pool._workers[0]
        pool.submit(0, ("figures", saved_fit, tmp_path, ("fit-residuals.png",)))
        pool.wait(0)  # the worker is in its loop
        os.kill(process.pid, signal.SIGINT)
        pool.submit(0, ("figures", saved_fit, tmp_path, ("fit-geometry.png",)))
        assert pool.wait(0) == ("fit-geometry.png",)
    assert (tmp_path / "fit-geometry.png").read_bytes() == in_process["fit-geometry.png"]
