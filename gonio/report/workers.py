"""The report's figures drawn by worker processes, on the machine's other cores.

A report is five matplotlib figures (:data:`gonio.report.fit_html.FIGURES`), each drawn
and PNG-encoded on its own: they can be drawn side by side. The workers are a
:class:`concurrent.futures.ProcessPoolExecutor` (:class:`ReportPool`); each job draws
one figure (the dearest first, so that a free worker takes the next) and returns its PNG
bytes. Workers write no file: the calling process writes the PNG files and
``report.html`` from the bytes it received
(:func:`gonio.report.fit_html.write_report_files`), so a worker that is stopped or dies
leaves nothing behind, and the page embeds exactly the figures of this report.

Two uses:

* ``gonio fit ... --report`` opens a pool (:func:`report_pool`) once its input is checked
  and before it fits. With the ``forkserver`` start method the fork server is started at
  once with :data:`PRELOAD` (matplotlib, :mod:`gonio.report.rendering`, the scipy parts
  the figures use) and one BLAS thread (:data:`BLAS_THREAD_VARIABLES`): it imports them
  on another core while the command reads, fits and samples. Each figure is given to the
  workers as soon as what it shows is known (:class:`ReportDrawing`): the measurement
  geometry, which needs the measurements alone, before the fit starts (the submission
  waits for the server in a background thread, :meth:`ReportPool.submit_soon`, so the
  worker draws it during the MCMC); the others, one job each, as soon as the fit is done,
  while the command saves the result and prints its summary. The command then receives
  the PNG bytes and writes the files (:func:`finish_report`); its own process never
  imports matplotlib.
* ``write_report(..., processes=2)`` (and ``gonio report`` with
  ``$GONIO_REPORT_PROCESSES`` of 2 or more; :func:`write_report_shared`): the pool is
  opened first, so that the server imports while this process reads the result and
  imports matplotlib itself; this process then draws one share while a worker draws the
  other. The fork server stays up for later calls in the same process, whose workers
  then start at once; a cold server's imports compete with the caller's own, which is
  why ``gonio report`` draws in one process by default (:func:`report_processes`).

Start method (:data:`START_METHOD`): ``forkserver`` where the platform has it (Linux,
macOS), else ``spawn`` (Windows). A spawned worker is a fresh interpreter that imports
numpy, gonio and matplotlib itself, about a second of work: the pool starts its workers
at once so that this happens while ``gonio fit`` fits. Both methods import the calling
program's main module in the workers: a script calling ``write_report(...,
processes=2)`` needs the ``if __name__ == "__main__":`` guard (:mod:`multiprocessing`,
"Safe importing of main module").

Failures:

* an error in a figure (a bug, a result that cannot be drawn) is raised in the caller as
  the worker raised it (its traceback is the exception's cause): drawing it again here
  would fail the same way;
* a worker that dies (:class:`concurrent.futures.process.BrokenProcessPool`), a pool that
  cannot start, or a worker that has not answered within :data:`WORKER_TIMEOUT_S` is
  reported (:class:`ReportWorkerWarning`, or a ``gonio: warning:`` line from the
  command), the workers are ended, and the figures not received are drawn in the calling
  process;
* an exception in the caller while the pool is open (Ctrl-C included; SIGTERM, which is
  turned into ``SystemExit(143)`` while the pool is open) ends the workers at once
  (:meth:`ReportPool.terminate`); they ignore SIGINT themselves, which reaches every
  process of the terminal's group, so that the command alone reports it.

The number of processes is ``$GONIO_REPORT_PROCESSES`` when set (1: everything in the
calling process), else 2 where this pays (:func:`report_processes`).
"""
from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.forkserver
import os
import signal
import sys
import threading
import time
import warnings
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator, Sequence

from .fit_html import DATASET_FIGURES, FIGURE_NAMES, FIGURES, write_report_files

if TYPE_CHECKING:
    from gonio.fitting.dataset import Dataset
    from gonio.fitting.results import FitResult

__all__ = ["ReportPool", "ReportWorkerWarning", "ReportDrawing", "report_pool", "draw_figures_shared",
           "finish_report", "print_warning", "write_report_shared", "report_processes", "available_cores",
           "share_figures",
           "START_METHOD", "ENVIRONMENT_VARIABLE", "PRELOAD", "WORKER_TIMEOUT_S", "BLAS_THREAD_VARIABLES"]

#: Environment variable setting the number of report processes.
ENVIRONMENT_VARIABLE = "GONIO_REPORT_PROCESSES"

#: multiprocessing start method of the workers (see the module notes).
START_METHOD = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"

#: Modules a worker needs to draw a report, imported by the fork server before it forks
#: workers (by each worker with ``spawn``): the report with matplotlib; scipy.linalg (the
#: result's whitening) and scipy.ndimage (the corner plot).
PRELOAD: tuple[str, ...] = ("scipy.linalg", "scipy.ndimage", "gonio.report.rendering")

#: Longest wait [s] for the workers' figures once they are asked for. A report takes
#: about 1 s of CPU (0.75 to 1.35 s for 10,000 points, benchmarks/bench_report.py) and
#: does not grow with the data; a hundred times that allows for a heavily loaded machine.
#: Past it the workers are taken as hung: they are ended and the figures drawn here.
WORKER_TIMEOUT_S = 120.0

#: Seconds to wait for an ended worker to go before it is killed.
_END_SECONDS = 1.0


class ReportWorkerWarning(UserWarning):
    """A report worker died, hung or could not start; its figures were drawn in the calling process."""


def _warn(message: str) -> None:
    warnings.warn(message, ReportWorkerWarning, stacklevel=4)


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform has it)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def report_processes(environ: dict[str, str] | None = None, *, while_fitting: bool = False) -> int:
    """Processes drawing a report: ``$GONIO_REPORT_PROCESSES``, else 2 where that pays.

    Two processes pay when the workers start while a fit runs (``gonio fit --report``,
    ``while_fitting``) on more than one core: their imports (about 1 s of CPU: numpy,
    scipy, matplotlib, gonio, in the fork server or in each spawned worker) then overlap
    the fit. For a report drawn alone (``gonio report``) the workers' imports compete with
    the command's own and cost more than the second process saves (benchmarks/
    bench_report.py), so one process is the default there.

    Parameters
    ----------
    environ : dict, optional
        The environment (default ``os.environ``).
    while_fitting : bool
        Whether the workers are started before a fit (``gonio fit --report``).

    Returns
    -------
    int
        At least 1.

    Raises
    ------
    ValueError
        The variable is set but is not a whole number of at least 1.
    """
    text = (os.environ if environ is None else environ).get(ENVIRONMENT_VARIABLE)
    if text is None or not text.strip():
        return min(2, available_cores()) if while_fitting else 1
    try:
        count = int(text)
    except ValueError:
        count = 0
    if count < 1:
        raise ValueError(f"${ENVIRONMENT_VARIABLE} = {text!r}: expected a whole number of processes, 1 or more "
                         "(1 draws the report in the command's own process)")
    return count


def share_figures(count: int, filenames: Sequence[str] = FIGURE_NAMES) -> list[tuple[str, ...]]:
    """The figures split into ``count`` shares of about equal cost (:attr:`ReportFigure.cost`).

    Longest first, each to the share of least cost so far; the lightest share comes first
    (for the process that also writes the files). Each share keeps report order.

    Parameters
    ----------
    count : int
        Number of shares (processes), at least 1.
    filenames : sequence of str
        The figures' file names in report order.

    Returns
    -------
    list of tuple of str
        ``count`` shares (some empty when there are more shares than figures).
    """
    if count < 1:
        raise ValueError(f"share_figures: count = {count}; expected 1 or more")
    cost = {figure.file: figure.cost for figure in FIGURES}
    shares: list[list[str]] = [[] for _ in range(count)]
    totals = [0.0] * count
    for name in sorted(filenames, key=lambda n: -cost.get(n, 0.1)):
        k = totals.index(min(totals))
        shares[k].append(name)
        totals[k] += cost.get(name, 0.1)
    order = {name: i for i, name in enumerate(filenames)}
    by_cost = sorted(range(count), key=lambda k: totals[k])
    return [tuple(sorted(shares[k], key=order.__getitem__)) for k in by_cost]


# ------------------------------------------------------------------------- in the worker
def _prepare_worker(caller: int | None = None) -> None:
    """A worker's start: leave Ctrl-C to the command (it reaches the whole process group),
    end with the command (:func:`_end_with`), import what drawing needs (nothing left to do
    when forked from the fork server) and keep BLAS to one thread (each worker has a core;
    OpenBLAS's idle threads spin)."""
    from threadpoolctl import threadpool_limits

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if caller is not None:
        _end_with(caller)
    for module in PRELOAD:
        __import__(module)
    threadpool_limits(limits=1, user_api="blas")


#: How often a worker checks that the command that started it still runs [s].
CALLER_CHECK_INTERVAL = 0.5


def _end_with(caller: int) -> None:
    """End this worker when the process ``caller`` is gone.

    A worker's parent is the fork server, not the command: when the command is killed
    with ``kill -9`` nothing tells the workers, which lived on holding the command's pipes
    (three workers, 175 MB, for 19 minutes and more). A daemon thread checks every
    :data:`CALLER_CHECK_INTERVAL` that the caller exists (signal 0) and ends the worker
    at once when it does not.
    """
    def watch() -> None:
        while True:
            time.sleep(CALLER_CHECK_INTERVAL)
            try:
                os.kill(caller, 0)
            except ProcessLookupError:
                os._exit(0)
            except PermissionError:  # it exists, under another user: not ours to judge
                pass

    threading.Thread(target=watch, name="gonio-report-caller-watch", daemon=True).start()


#: Environment variables that set the number of threads of the BLAS libraries numpy and
#: scipy load (OpenBLAS, and MKL or OpenMP-based builds), read when a library loads.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")


@contextlib.contextmanager
def _single_thread_blas_environment() -> Iterator[None]:
    """``os.environ`` with one BLAS thread for the fork server started in the block.

    The fork server and the workers forked from it draw figures, whose matrix products are
    small: one BLAS thread each is what :func:`_prepare_worker` sets anyway. Set before the
    server imports numpy and scipy, it also spares their BLAS libraries (numpy's and
    scipy's OpenBLAS each) the thread pools they would start and spin up at load, which
    took about 0.3 s of CPU from the cores the command fits on (``gonio fit --report`` on
    2 cores, docs/fitting.md "Performance"). The variables are restored on leaving the
    block, so this process and later children keep the user's settings.
    """
    saved = {name: os.environ.get(name) for name in BLAS_THREAD_VARIABLES}
    os.environ.update({name: "1" for name in BLAS_THREAD_VARIABLES})
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _ready() -> None:
    """A job that only makes a spawned worker start (and import) now."""


def _render(result: FitResult, filenames: tuple[str, ...]) -> dict[str, bytes]:
    """The job: the PNG bytes of ``filenames`` (gonio.report.rendering.render_figures)."""
    from .rendering import render_figures

    return render_figures(result, filenames)


def _render_measurements(dataset: Dataset, filenames: tuple[str, ...]) -> dict[str, bytes]:
    """The job for figures of the measurements alone (gonio.report.rendering.render_dataset_figures)."""
    from .rendering import render_dataset_figures

    return render_dataset_figures(dataset, filenames)


# ------------------------------------------------------------------------- the pool
@dataclass
class ReportPool:
    """Running report workers: the executor and how many workers it has."""

    executor: ProcessPoolExecutor
    workers: int
    #: Threads of :meth:`submit_soon` (joined briefly by :meth:`terminate`).
    _submitting: list[threading.Thread] = field(default_factory=list, repr=False)

    @classmethod
    def start(cls, workers: int, method: str = START_METHOD) -> ReportPool:
        """Start ``workers`` workers; their imports begin now (see the module notes).

        Raises
        ------
        OSError, ValueError
            The pool cannot start.
        """
        if workers < 1:
            raise ValueError(f"ReportPool: workers = {workers}; expected 1 or more")
        context = multiprocessing.get_context(method)
        if method == "forkserver":
            context.set_forkserver_preload(list(PRELOAD))
            with _single_thread_blas_environment():
                multiprocessing.forkserver.ensure_running()  # starts importing; returns at once
        pool = cls(ProcessPoolExecutor(workers, mp_context=context, initializer=_prepare_worker,
                                       initargs=(os.getpid(),)), workers)
        for _ in range(workers):  # a worker starts on its first job: have them start as soon as they can
            pool.submit_soon(_ready)
        return pool

    def submit_soon(self, function: Callable, *args) -> Future:
        """Submit a job without waiting for the workers to start; returns its future at once.

        A job submitted to a pool whose workers do not exist yet makes the submitting
        thread start one, and a worker forked from the fork server starts only once the
        server has imported :data:`PRELOAD` (about a second). The submission is therefore
        made by a background thread, and the returned future takes the job's result or
        error. A job that cannot be submitted (the pool shut down or broken meanwhile)
        ends its future with :class:`BrokenProcessPool`, as a worker's death would.
        """
        outer: Future = Future()

        def submit() -> None:
            try:
                inner = self.executor.submit(function, *args)
            except Exception as error:  # the pool was shut down or broke meanwhile
                outer.set_exception(BrokenProcessPool(f"a job could not be given to the workers "
                                                      f"({type(error).__name__}: {error})"))
                return
            inner.add_done_callback(lambda done: _pass_on(done, outer))

        thread = threading.Thread(target=submit, name="gonio-report-submit", daemon=True)
        self._submitting.append(thread)
        thread.start()
        return outer

    def terminate(self) -> None:
        """End the workers now: pending jobs are cancelled and running ones abandoned
        (workers write no file, so nothing is left half written)."""
        # ProcessPoolExecutor ends its workers only after their running jobs; its
        # processes are read from the executor (Python 3.14 adds terminate_workers()),
        # once the workers being started by submit_soon exist.
        for thread in self._submitting:
            thread.join(_END_SECONDS)
        processes = list((getattr(self.executor, "_processes", None) or {}).values())
        self.executor.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive():
                process.terminate()
        for process in processes:
            process.join(_END_SECONDS)
            if process.is_alive():
                process.kill()
                process.join(_END_SECONDS)


@contextlib.contextmanager
def report_pool(workers: int, method: str = START_METHOD,
                warn: Callable[[str], None] = _warn) -> Iterator[ReportPool | None]:
    """A :class:`ReportPool` of ``workers`` workers for the ``with`` block, or None.

    None when ``workers`` is 0 or the pool cannot start (``warn`` says why; the figures
    are then drawn in the calling process). On leaving the block the pool is shut down;
    if the block raised (Ctrl-C included) its workers are ended at once.

    Parameters
    ----------
    workers : int
        Number of workers (0: none).
    method : str
        multiprocessing start method.
    warn : callable
        Called with a one-line message when the pool cannot start (default: a
        :class:`ReportWorkerWarning`).
    """
    pool = None
    if workers > 0:
        try:
            pool = ReportPool.start(workers, method)
        except Exception as error:  # the figures will be drawn in this process
            warn(f"report workers could not start ({type(error).__name__}: {error}); the figures are drawn in "
                 "this process")
    try:
        with _sigterm_as_exit(pool is not None):
            yield pool
    except BaseException:
        if pool is not None:
            pool.terminate()
        raise
    finally:
        if pool is not None:
            pool.executor.shutdown(wait=True, cancel_futures=True)


def _pass_on(done: Future, outer: Future) -> None:
    """Give ``outer`` the result or error of the finished job ``done`` (a cancelled job:
    :class:`BrokenProcessPool`, since only an ended pool cancels them)."""
    if done.cancelled():
        outer.set_exception(BrokenProcessPool("the job was cancelled: the report workers were ended"))
    elif done.exception() is not None:
        outer.set_exception(done.exception())
    else:
        outer.set_result(done.result())


def _exit_on_sigterm(signum: int, frame) -> None:
    raise SystemExit(128 + signum)


@contextlib.contextmanager
def _sigterm_as_exit(active: bool) -> Iterator[None]:
    """While workers run, SIGTERM ends this process by SystemExit (exit status 143), so
    that the workers are ended and the pool shut down on the way out (the default
    action would end this process alone, leaving them to finish and multiprocessing's
    resource tracker to warn of leaked semaphores). Only where this process still has
    the default action and only in the main thread (where Python runs signal handlers)."""

    install = (active and threading.current_thread() is threading.main_thread()
               and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL)
    if install:
        signal.signal(signal.SIGTERM, _exit_on_sigterm)
    try:
        yield
    finally:
        if install:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _submit(pool: ReportPool, function: Callable, first, shares: list[tuple[str, ...]],
            warn: Callable[[str], None]) -> list[Future]:
    """One job ``function(first, share)`` per non-empty share; none (after ``warn``) when the
    workers cannot take them."""
    futures = []
    try:
        for share in shares:
            if share:
                futures.append(pool.executor.submit(function, first, share))
    except Exception as error:  # a worker that cannot start, or a pool already broken
        warn(f"report workers cannot take the figures ({type(error).__name__}: {error}); drawing them in this "
             "process")
        for future in futures:
            future.cancel()
        pool.terminate()
        return []
    return futures


def _collect(pool: ReportPool, futures: list[Future], warn: Callable[[str], None]) -> dict[str, bytes]:
    """The PNG bytes the workers return within :data:`WORKER_TIMEOUT_S`. A worker that died
    or hung is reported and the pool ended (the figures not returned are missing); an
    error raised by a job is raised here."""
    pngs: dict[str, bytes] = {}
    deadline = time.monotonic() + WORKER_TIMEOUT_S
    try:
        for future in futures:
            pngs.update(future.result(timeout=max(0.0, deadline - time.monotonic())))
    except BrokenProcessPool as error:
        warn(f"a report worker died ({error}); drawing its figures in this process")
        pool.terminate()
    except TimeoutError:
        warn(f"the report workers did not answer within {WORKER_TIMEOUT_S:g} s; ending them and drawing their "
             "figures in this process")
        pool.terminate()
    return pngs


class ReportDrawing:
    """The figures of one report, given to the workers as soon as what they show is known.

    :meth:`draw_measurements` has the figures of the measurements alone
    (:data:`gonio.report.fit_html.DATASET_FIGURES`) drawn while the fit runs;
    :meth:`draw_fit` gives them the others once the fit is done;
    :meth:`receive` waits for them and draws here whatever the workers did not return
    (every figure, without a pool).

    Parameters
    ----------
    pool : ReportPool or None
        Running workers, or None (every figure is then drawn by :meth:`receive`).
    warn : callable
        Called with a one-line message when workers fail (default: a
        :class:`ReportWorkerWarning`).
    """

    def __init__(self, pool: ReportPool | None, warn: Callable[[str], None] = _warn):
        self.pool = pool
        self.warn = warn
        self._futures: list[Future] = []
        self._given: set[str] = set()

    def draw_measurements(self, dataset: Dataset) -> None:
        """Have the workers draw the figures of ``dataset`` alone; returns at once (the
        job is submitted by :meth:`ReportPool.submit_soon`). Nothing without a pool."""
        if self.pool is None:
            return
        names = tuple(DATASET_FIGURES)
        self._futures.append(self.pool.submit_soon(_render_measurements, dataset, names))
        self._given.update(names)

    def draw_fit(self, result: FitResult, draw_here: bool = False) -> dict[str, bytes]:
        """Give the workers the figures not yet given, one job per figure, dearest first
        (:attr:`ReportFigure.cost`): whichever worker is free takes the next, so the
        shares balance themselves, also while a worker still draws the measurements'
        figures. With ``draw_here`` this process draws the lightest share of
        :func:`share_figures` meanwhile and returns its PNG bytes."""
        remaining = tuple(name for name in FIGURE_NAMES if name not in self._given)
        if self.pool is None or not remaining:
            return {}
        from_here = share_figures(self.pool.workers + 1, remaining)[0] if draw_here else ()
        cost = {figure.file: figure.cost for figure in FIGURES}
        for_workers = sorted((name for name in remaining if name not in from_here), key=cost.__getitem__, reverse=True)
        self._futures += _submit(self.pool, _render, result, [(name,) for name in for_workers], self.warn)
        self._given.update(remaining)
        return _render_here(result, from_here)

    def receive(self, result: FitResult, drawn_here: dict[str, bytes] | None = None) -> dict[str, bytes]:
        """The PNG bytes of every figure: the workers' (waited for, within
        :data:`WORKER_TIMEOUT_S`), ``drawn_here``, and the figures missing from both drawn
        here now.

        Raises
        ------
        Exception
            What drawing a figure raised, here or in a worker (the worker's traceback is
            the exception's ``__cause__``).
        """
        pngs = dict(drawn_here or {})
        if self.pool is not None:
            pngs.update(_collect(self.pool, self._futures, self.warn))
        missing = tuple(name for name in FIGURE_NAMES if name not in pngs)
        pngs.update(_render_here(result, missing))
        return pngs


def draw_figures_shared(result: FitResult, pool: ReportPool | None, *, draw_here: bool,
                        warn: Callable[[str], None] = _warn) -> dict[str, bytes]:
    """The PNG bytes of every figure of the report, drawn by ``pool``'s workers and, when
    ``draw_here``, by this process (the lightest share, while the workers draw theirs).

    Figures the workers did not return (a worker died, hung or could not start) are drawn
    here after ``warn`` said why; without a pool every figure is drawn here.

    Parameters
    ----------
    result : FitResult
        The fit (sent to the workers by pickling).
    pool : ReportPool or None
        Running workers (left running unless they failed).
    draw_here : bool
        Whether this process draws a share itself.
    warn : callable
        Called with a one-line message when workers fail (default: a
        :class:`ReportWorkerWarning`).

    Returns
    -------
    dict of str to bytes
        PNG bytes by file name, every figure of :data:`gonio.report.fit_html.FIGURES`.

    Raises
    ------
    Exception
        What drawing a figure raised, here or in a worker (the worker's traceback is the
        exception's ``__cause__``).
    """
    drawing = ReportDrawing(pool, warn)
    return drawing.receive(result, drawing.draw_fit(result, draw_here))


def _render_here(result: FitResult, filenames: tuple[str, ...]) -> dict[str, bytes]:
    """``filenames`` drawn in this process (matplotlib is imported only when there are any)."""
    if not filenames:
        return {}
    from .rendering import render_figures

    return render_figures(result, filenames)


def print_warning(message: str) -> None:
    """Print ``message`` as the command line prints a warning (``gonio: warning: ...``)."""
    print(f"gonio: warning: {message}", file=sys.stderr)


def finish_report(pool: ReportPool | None, result: FitResult, out: str | Path,
                  drawing: ReportDrawing | None = None) -> Path:
    """Write the report of ``result`` (saved in ``out``) into ``out``, for ``gonio fit``:
    the workers draw every figure; without them (or when they fail, with ``gonio:
    warning:`` lines on stderr) this process draws them.

    Parameters
    ----------
    pool : ReportPool or None
        From :func:`report_pool`.
    result : FitResult
        The fit, as saved.
    out : path
        The result folder; the report goes into it.
    drawing : ReportDrawing, optional
        The figures already given to ``pool``'s workers (``gonio fit`` gives the
        measurements' figures before the fit and the rest before it saves the result);
        the figures not given yet are given now.

    Returns
    -------
    pathlib.Path
        The HTML file.
    """
    if drawing is None:
        drawing = ReportDrawing(pool, print_warning)
    drawing.draw_fit(result)
    return write_report_files(result, Path(out), drawing.receive(result))


def write_report_shared(source: str | Path | FitResult, out: str | Path | None = None, processes: int = 2,
                        method: str = START_METHOD) -> Path:
    """The report of ``source`` drawn by this process and ``processes - 1`` workers.

    The pool is started first, so that its imports run while this process reads the
    result (and imports matplotlib); the files are written here. See
    :func:`gonio.report.fit_report.write_report` for the parameters.

    Returns
    -------
    pathlib.Path
        The HTML file.
    """
    with report_pool(processes - 1, method) as pool:
        from .rendering import load_source

        result, folder = load_source(source, out)
        pngs = draw_figures_shared(result, pool, draw_here=True)
    return write_report_files(result, folder, pngs)
