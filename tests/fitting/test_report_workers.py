"""The report drawn by worker processes (gonio.report.workers): the same files as in one
process; an error in a figure raised as it is; a worker that dies, hangs or cannot start
reported, ended and its figures drawn here; workers ended at once on Ctrl-C; the result
untouched. Faults are injected through the pickled result (objects whose unpickling in
the worker ends or stalls it), since workers forked from the fork server do not run this
process's (monkeypatched) code."""
from __future__ import annotations

import base64
import copy
import hashlib
import multiprocessing
import os
import pickle
import signal
import subprocess
import sys
import time
import warnings
from concurrent.futures.process import BrokenProcessPool

import pytest

from gonio.cli import main
from gonio.fitting import fit
from gonio.fitting.results import FitResult
from gonio.report import rendering, workers
from gonio.report.fit_html import DATASET_FIGURES, FIGURE_NAMES, FIGURES, REPORT_FILES, write_html, write_report_files
from gonio.report.fit_report import write_report
from gonio.report.workers import (ReportDrawing, ReportPool, ReportWorkerWarning, draw_figures_shared,
                                  finish_report, report_pool, report_processes, share_figures, write_report_shared)

from .synthetic import synthetic_dataset


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


@pytest.fixture
def strict():
    """A worker failure (a ReportWorkerWarning) is an error: the workers really drew."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", ReportWorkerWarning)
        yield


def _new_children(before) -> list:
    return [p for p in multiprocessing.active_children() if p not in before]


# A worker ended by the pool has a nonzero exit code: -SIGTERM, or 255 when two threads
# read its status from the fork server at once (multiprocessing.popen_forkserver); one
# left to finish its stalled job would exit with 0 after a minute.


class _EndOnArrival:
    """Unpickled in a worker, ends it (as a crash would) with exit code 3."""

    def __reduce__(self):
        return os._exit, (3,)


class _StallOnArrival:
    """Unpickled in a worker, stalls it for a minute (as a hang would)."""

    def __reduce__(self):
        return time.sleep, (60.0,)


def _with(result: FitResult, poison) -> FitResult:
    clone = copy.copy(result)
    clone.__dict__["poison"] = poison  # harmless here; acts when a worker unpickles it
    return clone


# ----------------------------------------------------------------------------- plumbing
def test_figure_costs_are_positive_and_names_unique():
    assert all(figure.cost > 0 for figure in FIGURES)
    assert len(set(FIGURE_NAMES)) == len(FIGURES) == 5


def test_shares_cover_every_figure_once_balanced_lightest_first():
    cost = {figure.file: figure.cost for figure in FIGURES}
    for count in (1, 2, 3, 7):
        shares = share_figures(count)
        assert len(shares) == count
        assert sorted(n for share in shares for n in share) == sorted(FIGURE_NAMES)
        costs = [sum(cost[n] for n in share) for share in shares]
        assert costs == sorted(costs)
    light, heavy = (sum(cost[n] for n in share) for share in share_figures(2))
    # Greedy longest-first: the two shares differ by at most the lightest figure's cost.
    assert heavy - light <= min(cost.values()) + 1e-12


def test_number_of_processes_from_the_environment_and_the_cores(monkeypatch):
    assert report_processes({"GONIO_REPORT_PROCESSES": "3"}) == 3
    for bad in ("0", "two", "-1", "1.5"):
        with pytest.raises(ValueError, match="GONIO_REPORT_PROCESSES.*whole number"):
            report_processes({"GONIO_REPORT_PROCESSES": bad})
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    # Two processes by default only where the workers start while a fit runs.
    assert report_processes({}, while_fitting=True) == 2
    assert report_processes({}) == 1
    assert report_processes({"GONIO_REPORT_PROCESSES": "2"}) == 2
    # A process allowed on one core only (taskset, a container's CPU set) draws alone.
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {5}, raising=False)
    assert report_processes({}, while_fitting=True) == 1


def test_a_pickled_result_leaves_its_cached_problem_behind():
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005)
    result = fit(data, "lambert", mcmc=False)
    result.problem()
    clone = pickle.loads(pickle.dumps(result))
    assert "_problem" in result.__dict__ and "_problem" not in clone.__dict__
    assert clone.problem().free == result.problem().free


def test_the_page_embeds_exactly_the_figures_given_and_needs_all_five(saved_fit, tmp_path):
    result = FitResult.load(saved_fit)
    pngs = {name: f"not really {name}".encode() for name in FIGURE_NAMES}
    (tmp_path / "fit-corner.png").write_bytes(b"an earlier fit's corner plot")
    with pytest.raises(ValueError, match="no PNG for fit-corner.png"):
        write_html(result, tmp_path, {k: v for k, v in pngs.items() if k != "fit-corner.png"})
    assert not (tmp_path / "report.html").exists()
    text = write_html(result, tmp_path, pngs).read_text()
    embedded = [base64.b64decode(s) for s in text.split("data:image/png;base64,")[1:] for s in [s.split("'")[0]]]
    assert embedded == [pngs[name] for name in FIGURE_NAMES]


# ----------------------------------------------------------------------------- same files
def test_two_processes_write_the_same_files_as_one(saved_fit, in_process, tmp_path, strict):
    write_report(saved_fit, tmp_path, processes=2)
    assert _contents(tmp_path) == in_process


def test_a_result_in_memory_is_sent_to_the_worker(tmp_path, strict):
    # A fresh result caches its FitProblem (the model's prepared functions, which do not
    # pickle); the worker gets the result without it and rebuilds it.
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005)
    result = fit(data, "lambert", n_walkers=8, tau_multiple=10.0, rhat_limit=1.05, seed=0)
    result.problem()
    write_report(result, tmp_path / "one", processes=1)
    write_report(result, tmp_path / "two", processes=2)
    assert _contents(tmp_path / "two") == _contents(tmp_path / "one")
    assert "_problem" in result.__dict__  # the caller's result keeps its cache


def test_command_workers_write_the_same_files_keep_the_result_and_end(saved_fit, in_process, tmp_path, strict):
    # gonio fit --report: two workers draw every figure of the saved result; this process
    # writes the files; the workers are gone when the pool's block ends.
    before, children = _digests(saved_fit), multiprocessing.active_children()
    with report_pool(2) as pool:
        path = finish_report(pool, FitResult.load(saved_fit), saved_fit)
        started = _new_children(children)
    assert path == saved_fit / "report.html"
    assert _contents(saved_fit) == in_process
    assert _digests(saved_fit) == before
    assert started and not any(process.is_alive() for process in started)


def test_the_measurements_figure_drawn_from_the_dataset_is_the_fits(saved_fit, in_process):
    result = FitResult.load(saved_fit)
    pngs = rendering.render_dataset_figures(result.dataset)
    assert list(pngs) == list(DATASET_FIGURES) == ["fit-geometry.png"]
    assert pngs["fit-geometry.png"] == in_process["fit-geometry.png"]
    with pytest.raises(ValueError, match=r"cannot be drawn from the measurements alone: \['fit-corner\.png'\]"):
        rendering.render_dataset_figures(result.dataset, ("fit-corner.png",))


def test_figures_given_while_fitting_and_after_make_the_same_report(saved_fit, in_process, tmp_path, strict):
    # gonio fit --report: the geometry is given to the workers before the fit (its job
    # waits for the fork server in a background thread), the rest once the fit is done.
    result = FitResult.load(saved_fit)
    with report_pool(2) as pool:
        drawing = ReportDrawing(pool)
        drawing.draw_measurements(result.dataset)
        drawing.draw_fit(result)
        path = finish_report(pool, result, tmp_path, drawing)
    assert path == tmp_path / "report.html"
    assert _contents(tmp_path) == in_process


def test_a_job_given_before_the_workers_exist_returns_its_result_there():
    with report_pool(1) as pool:
        future = pool.submit_soon(os.getpid)  # returns at once; the worker may still be starting
        assert future.result(timeout=60) != os.getpid()


def test_the_single_thread_blas_environment_is_restored(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    with workers._single_thread_blas_environment():
        assert all(os.environ[name] == "1" for name in workers.BLAS_THREAD_VARIABLES)
    assert os.environ["OPENBLAS_NUM_THREADS"] == "3" and "MKL_NUM_THREADS" not in os.environ


@pytest.mark.skipif(workers.START_METHOD != "forkserver", reason="the fork server's environment")
def test_the_fork_server_has_one_blas_thread_and_this_process_keeps_its_setting():
    # a fresh interpreter: this process's fork server may already run, started by another test
    code = (
        "import os\n"
        "os.environ['OPENBLAS_NUM_THREADS'] = '3'\n"
        "from gonio.report.workers import ReportPool\n"
        "pool = ReportPool.start(1)\n"
        "seen = pool.submit_soon(os.getenv, 'OPENBLAS_NUM_THREADS').result(timeout=120)\n"
        "from threadpoolctl import threadpool_info\n"
        "blas = pool.executor.submit(threadpool_info).result(timeout=120)\n"
        "pool.executor.shutdown()\n"
        "print(seen, os.environ['OPENBLAS_NUM_THREADS'], sorted({p['num_threads'] for p in blas if p['user_api'] == 'blas'}))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["1", "3", "[1]"]


def test_a_job_the_workers_cannot_take_ends_as_a_broken_pool():
    pool = ReportPool.start(1)
    pool.executor.shutdown(wait=True)
    with pytest.raises(BrokenProcessPool, match="could not be given to the workers.*RuntimeError"):
        pool.submit_soon(os.getpid).result(timeout=60)


def test_a_worker_that_dies_on_the_measurements_figure_leaves_every_figure_to_this_process(saved_fit, in_process,
                                                                                           tmp_path):
    result = FitResult.load(saved_fit)
    dying = copy.copy(result.dataset)
    object.__setattr__(dying, "poison", _EndOnArrival())  # a frozen dataclass; acts when a worker unpickles it
    with pytest.warns(ReportWorkerWarning, match="report worker"):
        with report_pool(2) as pool:
            drawing = ReportDrawing(pool)
            drawing.draw_measurements(dying)
            finish_report(pool, result, tmp_path, drawing)
    assert _contents(tmp_path) == in_process


def test_spawned_workers_write_the_same_files(saved_fit, in_process, tmp_path, strict):
    # The start method of Windows: a fresh interpreter that imports numpy, gonio and
    # matplotlib itself (2-3 s here; one worker to keep it to one).
    path = write_report_shared(saved_fit, tmp_path, processes=2, method="spawn")
    assert path == tmp_path / "report.html"
    assert _contents(tmp_path) == in_process


# ----------------------------------------------------------------------------- failures
def test_an_error_in_a_figure_is_raised_with_the_workers_traceback_not_drawn_again(saved_fit, tmp_path,
                                                                                  monkeypatch, strict):
    broken = copy.copy(FitResult.load(saved_fit))
    broken.dataset = "not a dataset"  # every figure fails on it, in any process

    def drawn_here(*args, **kwargs):
        raise AssertionError("the figures were drawn again in the calling process")

    monkeypatch.setattr(rendering, "render_figures", drawn_here)  # this process only: workers keep theirs
    with pytest.raises(AttributeError, match="'str' object has no attribute") as raised:
        with report_pool(2) as pool:
            finish_report(pool, broken, tmp_path)
    assert "Traceback" in str(raised.value.__cause__)  # the worker's traceback, shown by --debug
    assert list(tmp_path.iterdir()) == []


def test_a_worker_that_dies_is_reported_ended_with_the_others_and_its_figures_drawn_here(saved_fit, in_process,
                                                                                          tmp_path, capsys):
    before, children = _digests(saved_fit), multiprocessing.active_children()
    dying = _with(FitResult.load(saved_fit), _EndOnArrival())
    with report_pool(2) as pool:
        for future in [pool.executor.submit(time.sleep, 0.2) for _ in range(2)]:  # both workers started
            future.result()
        started = _new_children(children)
        path = finish_report(pool, dying, tmp_path)
        assert len(started) == 2 and not any(process.is_alive() for process in started)  # the other one too
    # The worker dies as the first share arrives: while this process waits for it ("a report
    # worker died"), or, if it dies before the second share is submitted, at that submission
    # (the pool is broken: "cannot take the figures"). Both are the same event, reported.
    err = capsys.readouterr().err
    assert ("gonio: warning: a report worker died" in err
            or "gonio: warning: report workers cannot take the figures (BrokenProcessPool" in err), err
    assert path == tmp_path / "report.html"
    assert _contents(tmp_path) == in_process
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(REPORT_FILES)  # no stray or temporary file
    assert _digests(saved_fit) == before


def test_a_worker_that_hangs_is_ended_after_the_timeout_and_its_figures_drawn_here(saved_fit, in_process, tmp_path,
                                                                                   monkeypatch):
    monkeypatch.setattr(workers, "WORKER_TIMEOUT_S", 0.5)
    children = multiprocessing.active_children()
    stalled = _with(FitResult.load(saved_fit), _StallOnArrival())
    with pytest.warns(ReportWorkerWarning, match=r"did not answer within 0\.5 s"):
        with report_pool(1) as pool:
            pool.executor.submit(os.getpid).result()  # the worker started
            started = _new_children(children)
            write_report_files(stalled, tmp_path, draw_figures_shared(stalled, pool, draw_here=False))
    assert _contents(tmp_path) == in_process
    assert started and all(process.exitcode not in (None, 0) for process in started)  # ended, not finished


def test_workers_that_cannot_start_leave_the_figures_to_this_process(saved_fit, in_process, monkeypatch, capsys,
                                                                    tmp_path):
    def refuse(*args, **kwargs):
        raise OSError("no processes left")

    monkeypatch.setattr(workers.ReportPool, "start", refuse)
    with pytest.warns(ReportWorkerWarning, match=r"could not start \(OSError: no processes left\)"):
        write_report(saved_fit, tmp_path, processes=2)
    assert _contents(tmp_path) == in_process


def test_ctrl_c_ends_the_workers_at_once(saved_fit, tmp_path):
    # Ctrl-C while the command waits for a stalled worker: the workers are ended (SIGTERM)
    # when the exception leaves the pool's block, not waited for.
    stalled = _with(FitResult.load(saved_fit), _StallOnArrival())
    children, started = multiprocessing.active_children(), []

    def interrupt(signum, frame):
        started.extend(_new_children(children))
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGALRM, interrupt)
    try:
        with pytest.raises(KeyboardInterrupt):
            with report_pool(1) as pool:
                pool.executor.submit(os.getpid).result()  # the worker started
                signal.setitimer(signal.ITIMER_REAL, 0.5)
                finish_report(pool, stalled, tmp_path)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert started and all(process.exitcode not in (None, 0) for process in started)  # ended, not finished
    assert list(tmp_path.iterdir()) == []


def test_sigterm_ends_the_workers_and_the_process_by_exit_status_143(saved_fit, tmp_path):
    # SIGTERM to the command while its pool is open: SystemExit(143) on the way out of
    # the block, the workers ended; the default action is back afterwards.
    stalled = _with(FitResult.load(saved_fit), _StallOnArrival())
    children = multiprocessing.active_children()
    with pytest.raises(SystemExit) as raised:
        with report_pool(1) as pool:
            pool.executor.submit(os.getpid).result()
            started = _new_children(children)
            future = pool.executor.submit(workers._render, stalled, ("fit-geometry.png",))
            os.kill(os.getpid(), signal.SIGTERM)
            future.result()
    assert raised.value.code == 143
    assert started and all(process.exitcode not in (None, 0) for process in started)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_a_worker_ignores_ctrl_c_and_goes_on(saved_fit, in_process, strict):
    # Ctrl-C reaches every process of the terminal's group: a worker leaves it to the
    # command (no traceback of its own) and goes on answering.
    with report_pool(1) as pool:
        pid = pool.executor.submit(os.getpid).result()
        os.kill(pid, signal.SIGINT)
        pngs = draw_figures_shared(FitResult.load(saved_fit), pool, draw_here=False)
        assert pool.executor.submit(os.getpid).result() == pid
    assert pngs["fit-geometry.png"] == in_process["fit-geometry.png"]


def test_a_reused_pool_never_returns_an_earlier_reports_figures(saved_fit, in_process, monkeypatch):
    # The first report fails in this process while the worker draws its share of another
    # fit; the next report on the same pool gets its own figures.
    other = fit(synthetic_dataset("lambert", dict(rho=0.5), 0.005), "lambert", n_walkers=8, tau_multiple=10.0,
                rhat_limit=1.05, seed=0)
    original = rendering.render_figures

    def fail(*args, **kwargs):
        raise RuntimeError("this process's share failed")

    with report_pool(1) as pool:
        monkeypatch.setattr(rendering, "render_figures", fail)
        with pytest.raises(RuntimeError, match="share failed"):
            draw_figures_shared(other, pool, draw_here=True)
        monkeypatch.setattr(rendering, "render_figures", original)
        pngs = draw_figures_shared(FitResult.load(saved_fit), pool, draw_here=True)
    assert pngs == {name: in_process[name] for name in FIGURE_NAMES}


def test_one_process_starts_no_worker():
    with report_pool(0) as pool:
        assert pool is None
    with pytest.raises(ValueError, match="processes = 0"):
        write_report("unused", processes=0)


# ----------------------------------------------------------------------------- the command
@pytest.fixture
def small_csv(tmp_path):
    data = synthetic_dataset("lambert", dict(rho=0.5), 0.005)
    return data.to_csv(tmp_path / "d.csv")


FIT = ["--model", "lambert", "--walkers", "8", "--max-steps", "300", "--rhat-limit", "1.2", "--quiet", "--report"]


def test_fit_starts_no_worker_before_its_input_is_checked(small_csv, tmp_path, monkeypatch):
    started = []
    monkeypatch.setattr(workers, "report_pool", lambda *a, **k: started.append(a))
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "notes.txt").write_text("mine")
    assert main(["fit", str(small_csv), *FIT, "--out", str(taken)]) == 2  # folder in use, no --overwrite
    assert main(["fit", str(tmp_path / "missing.csv"), *FIT]) == 2  # unreadable data
    assert main(["fit", str(small_csv), *FIT, "--out", " "]) == 2  # no folder name
    assert started == []


def test_overwrite_removes_the_earlier_report_before_drawing(small_csv, tmp_path, monkeypatch, capsys):
    out = tmp_path / "fit"
    monkeypatch.setenv("GONIO_REPORT_PROCESSES", "1")
    main(["fit", str(small_csv), *FIT, "--out", str(out)])
    assert (out / "report.html").exists()
    earlier = (out / "result.json").read_bytes()

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(workers, "finish_report", disk_full)
    assert main(["fit", str(small_csv), *FIT, "--out", str(out), "--overwrite", "--seed", "1"]) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert (out / "result.json").read_bytes() != earlier  # the new result
    assert not any((out / name).exists() for name in REPORT_FILES)  # and no report of the earlier fit


def test_fit_report_by_workers_equals_the_report_command(small_csv, tmp_path, monkeypatch, strict):
    monkeypatch.setenv("GONIO_REPORT_PROCESSES", "2")
    main(["fit", str(small_csv), *FIT, "--out", str(tmp_path / "fit")])
    assert main(["report", str(tmp_path / "fit"), "--out", str(tmp_path / "again")]) == 0
    assert _contents(tmp_path / "fit") == _contents(tmp_path / "again")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.skipif(workers.START_METHOD != "forkserver", reason="the orphaning case is the fork server's")
def test_workers_end_when_the_command_is_killed():
    """kill -9 of 'gonio fit --report' used to orphan its workers (their parent is the fork
    server), holding the caller's pipes for 19 minutes and more: they now end within a
    second or two of the command."""
    script = ("import os, sys\n"
              "from gonio.report import workers\n"
              "pool = workers.ReportPool.start(2)\n"
              "pids = sorted({pool.executor.submit(os.getpid).result(timeout=120) for _ in range(8)})\n"
              "print(' '.join(map(str, pids)), flush=True)\n"
              "import time; time.sleep(120)\n")
    command = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        pids = [int(p) for p in command.stdout.readline().split()]
        assert pids and all(_alive(p) for p in pids)
    finally:
        command.send_signal(signal.SIGKILL)
        command.wait(timeout=30)
    deadline = time.monotonic() + 10
    while any(_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_alive(p) for p in pids), "report workers outlived the command"
