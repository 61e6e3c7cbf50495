"""The report's figures drawn by worker processes, on the machine's other cores.

A report is five matplotlib figures (:data:`gonio.report.fit_report.FIGURES`), each
drawn and PNG-encoded on its own: they can be drawn side by side. Two uses:

* :func:`start_report_workers` is called at the start of ``gonio fit ... --report``:
  the workers import matplotlib, :mod:`gonio.report` and the scipy parts the figures use
  while the command's own process reads, fits and samples; once the result is saved,
  :meth:`ReportWorkers.write_report` has them draw their shares of the figures from the
  saved result and one of them write ``report.html`` (:func:`finish_report`). The
  command's process never imports matplotlib.
* ``write_report(..., processes=2)`` (:func:`write_report_shared`) draws part of the
  figures in a worker started for the purpose while the calling process draws the rest.

The files are the same whichever process draws them (one implementation,
:func:`gonio.report.fit_report.write_figures` and ``write_html``; tested byte for byte).

Start method: ``fork`` on Linux (the worker starts with the parent's modules already
imported and costs a few milliseconds to start), ``spawn`` elsewhere (macOS, where
``fork`` is unsafe with the system's frameworks, and Windows, which has no ``fork``): a
spawned worker starts a fresh interpreter and imports numpy and gonio itself, which adds
about a second of work on another core; that pays for ``gonio fit --report``, whose fit
takes longer, but hardly for ``write_report(..., processes=2)`` of a small report.

Failures: an exception in a worker comes back as :class:`ReportWorkerError` with the
worker's traceback; a worker that dies or cannot be started is an error too. Callers
fall back to drawing the figures in their own process and say so
(:class:`ReportWorkerWarning`, or a ``gonio: warning:`` line from the command): the
report is never silently missing, and the result files, saved before the report is
drawn, are never touched by the workers (they write only the report's files, each
atomically).

The number of processes is ``$GONIO_REPORT_PROCESSES`` when set (1: everything in the
calling process), else 2 on a machine with more than one core (:func:`report_processes`).
"""
from __future__ import annotations

import atexit
import copy
import multiprocessing
import multiprocessing.util  # noqa: F401 - its exit hook must be registered before ours
import os
import signal
import sys
import traceback
import warnings
import weakref
from pathlib import Path
from typing import Any, Sequence

__all__ = ["ReportWorkers", "ReportWorkerError", "ReportWorkerWarning", "start_report_workers", "finish_report",
           "write_report_shared", "report_processes", "share_figures", "START_METHOD", "ENVIRONMENT_VARIABLE",
           "FIGURE_COST"]

#: Environment variable setting the number of report processes.
ENVIRONMENT_VARIABLE = "GONIO_REPORT_PROCESSES"

#: multiprocessing start method of the workers (see the module notes).
START_METHOD = "fork" if sys.platform.startswith("linux") else "spawn"

#: Relative cost of each figure (CPU seconds to draw and encode it for the Fig 16 fit
#: after the imports, benchmarks/bench_report.py): the shares are balanced with these.
FIGURE_COST = {"fit-geometry.png": 0.09, "fit-data.png": 0.15, "fit-residuals.png": 0.08,
               "fit-corner.png": 0.18, "fit-traces.png": 0.24}

#: Seconds between checks that a worker being waited for is still alive.
_POLL_SECONDS = 0.2


class ReportWorkerError(RuntimeError):
    """A report worker failed: its exception (with the worker's traceback), or its death."""


class ReportWorkerWarning(UserWarning):
    """A report worker failed and its figures were drawn in the calling process."""


def report_processes(environ: dict[str, str] | None = None) -> int:
    """Processes drawing a report: ``$GONIO_REPORT_PROCESSES``, else 2 with more than one core.

    Parameters
    ----------
    environ : dict, optional
        The environment (default ``os.environ``).

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
        return min(2, os.cpu_count() or 1)
    try:
        count = int(text)
    except ValueError:
        count = 0
    if count < 1:
        raise ValueError(f"${ENVIRONMENT_VARIABLE} = {text!r}: expected a whole number of processes, 1 or more "
                         "(1 draws the report in the command's own process)")
    return count


def share_figures(count: int, filenames: Sequence[str] = tuple(FIGURE_COST)) -> list[tuple[str, ...]]:
    """The figures split into ``count`` shares of about equal cost (:data:`FIGURE_COST`).

    Longest first, each to the share of least cost so far; the lightest share comes first
    (for the process that also writes the HTML). Each share keeps report order.

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
    shares: list[list[str]] = [[] for _ in range(count)]
    costs = [0.0] * count
    for name in sorted(filenames, key=lambda n: -FIGURE_COST.get(n, 0.1)):
        k = costs.index(min(costs))
        shares[k].append(name)
        costs[k] += FIGURE_COST.get(name, 0.1)
    order = {name: i for i, name in enumerate(filenames)}
    by_cost = sorted(range(count), key=lambda k: costs[k])
    return [tuple(sorted(shares[k], key=order.__getitem__)) for k in by_cost]


# ------------------------------------------------------------------------- the worker
def _preload() -> None:
    """Import what drawing a report needs: matplotlib, the report, the scipy parts the
    figures use (scipy.linalg: the result's whitening; scipy.ndimage: the corner plot)."""
    import scipy.linalg  # noqa: F401
    import scipy.ndimage  # noqa: F401

    from gonio.report import fit_report  # noqa: F401


def _do(job: tuple, helpers: ReportWorkers | None, notes: list[str]) -> Any:
    """Carry out one job: ``("figures", source, out, filenames)`` (draw those figures) or
    ``("report", source, out)`` (the whole report, shared with this worker's helpers;
    returns the HTML file and ``notes`` plus the texts of the warnings raised on the way)."""
    from gonio.report.fit_report import load_source, write_figures

    kind, source, out, *rest = job
    result, out = load_source(source, out)
    if kind == "figures":
        return tuple(write_figures(result, out, tuple(rest[0])))
    if kind == "report":
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ReportWorkerWarning)
            path = write_report_shared(result, out, helpers)
        return path, notes + [str(w.message) for w in caught if issubclass(w.category, ReportWorkerWarning)]
    raise ValueError(f"report worker: unknown job {kind!r}; expected 'figures' or 'report'")


def _serve(connection, inherited=None, helpers: int = 0, method: str = START_METHOD) -> None:
    """A worker's loop: preload, start ``helpers`` workers of its own (after the preload,
    so that forked helpers inherit it), then answer jobs until told to stop (None) or the
    parent goes away. Every reply is ``("done", value)`` or ``("error", traceback text)``."""
    if inherited is not None:  # the parent's end of the pipe, inherited through fork
        inherited.close()
    # Ctrl-C in a terminal reaches the whole process group: the command handles it and
    # stops its workers, which would otherwise each print a KeyboardInterrupt traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    pool, preload_error, notes = None, None, []
    try:
        _preload()
    except Exception:
        preload_error = traceback.format_exc()
    if helpers and preload_error is None:
        try:
            pool = ReportWorkers(helpers, method)
        except Exception as error:  # reported with the report; this worker draws everything
            notes.append(f"report helpers could not start ({type(error).__name__}: {error}); one worker drew "
                         "every figure")
    try:
        while True:
            try:
                job = connection.recv()
            except (EOFError, OSError):
                return
            if job is None:
                return
            try:
                if preload_error is not None:
                    raise RuntimeError(f"the worker could not import the report's modules:\n{preload_error}")
                reply = ("done", _do(job, pool, notes))
            except BaseException:  # noqa: B036 - everything goes back to the parent, nothing is lost here
                reply = ("error", traceback.format_exc())
            connection.send(reply)
    finally:
        if pool is not None:
            pool.close()


# ------------------------------------------------------------------------- the parent
def _shutdown(workers: list) -> None:
    """Tell every worker to stop, wait briefly, then end those still running."""
    for process, connection in workers:
        try:
            connection.send(None)
        except (OSError, ValueError):
            pass
    for process, connection in workers:
        process.join(timeout=5.0)
        if process.is_alive():
            process.terminate()
            process.join(timeout=5.0)
        connection.close()
    workers.clear()


#: Every pool not yet closed, stopped at exit before multiprocessing joins its
#: non-daemonic children (atexit runs the last registered first; this module registers
#: after importing multiprocessing.util, which registers that join).
_OPEN: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _close_open_pools() -> None:
    for pool in list(_OPEN):
        pool.close()


class ReportWorkers:
    """Worker processes that draw report figures; started at once, preloading their imports.

    Parameters
    ----------
    count : int
        Number of workers, at least 1.
    method : str
        multiprocessing start method (default :data:`START_METHOD`).
    helpers : int
        Workers each worker starts for itself after its preload, with which it shares a
        ``("report", ...)`` job (forked helpers then inherit the imports instead of
        repeating them). A worker with helpers is not daemonic (multiprocessing forbids
        children of daemonic processes); :meth:`close`, the pool's garbage collection
        and an exit hook stop it, and it stops by itself when its parent goes away.

    Raises
    ------
    OSError, ValueError
        A worker cannot be started (the started ones are stopped).
    """

    def __init__(self, count: int, method: str = START_METHOD, helpers: int = 0):
        if count < 1 or helpers < 0:
            raise ValueError(f"ReportWorkers: count = {count}, helpers = {helpers}; expected count >= 1, "
                             "helpers >= 0")
        context = multiprocessing.get_context(method)
        self.method = method
        self._workers: list = []
        self._finalizer = weakref.finalize(self, _shutdown, self._workers)
        _OPEN.add(self)
        try:
            for _ in range(count):
                parent_end, child_end = context.Pipe()
                inherited = parent_end if method == "fork" else None
                process = context.Process(target=_serve, args=(child_end, inherited, helpers, method),
                                          daemon=helpers == 0, name="gonio-report-worker")
                process.start()
                child_end.close()
                self._workers.append((process, parent_end))
        except BaseException:
            self.close()
            raise

    def __len__(self) -> int:
        return len(self._workers)

    def __enter__(self) -> ReportWorkers:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        self._finalizer()

    def submit(self, index: int, job: tuple) -> None:
        """Send ``job`` to worker ``index``; a worker that is gone raises ReportWorkerError."""
        process, connection = self._workers[index]
        try:
            connection.send(job)
        except (OSError, ValueError) as error:
            raise ReportWorkerError(f"report worker {process.pid} cannot take a job ({error}); "
                                    f"exit code {process.exitcode}") from error

    def wait(self, index: int) -> Any:
        """The reply of worker ``index`` to its last job.

        Raises
        ------
        ReportWorkerError
            The job raised in the worker (its traceback in the message), or the worker
            died before replying.
        """
        process, connection = self._workers[index]
        while not connection.poll(_POLL_SECONDS):
            if not process.is_alive() and not connection.poll(0):
                raise ReportWorkerError(f"report worker {process.pid} exited (code {process.exitcode}) before "
                                        "it replied")
        try:
            status, value = connection.recv()
        except (EOFError, OSError) as error:
            process.join(timeout=2.0)  # its exit code, when it is ending
            raise ReportWorkerError(f"report worker {process.pid} exited (code {process.exitcode}) before it "
                                    "replied") from error
        if status != "done":
            raise ReportWorkerError(f"report worker {process.pid} failed:\n{value}")
        return value

    def write_report(self, source: str | Path, out: str | Path | None = None) -> tuple[Path, list[str]]:
        """Draw the report of a saved result in worker 0 and its helpers.

        Parameters
        ----------
        source : path
            A result folder written by :meth:`gonio.fitting.FitResult.save`.
        out : path, optional
            Output folder (default: the result folder).

        Returns
        -------
        path : pathlib.Path
            The HTML file.
        warnings : list of str
            What went wrong with the helpers on the way (their figures were then drawn
            by worker 0).

        Raises
        ------
        ReportWorkerError
            The worker failed (the report may then be incomplete: draw it again in-process).
        """
        self.submit(0, ("report", Path(source), out))
        path, messages = self.wait(0)
        return Path(path), messages


def start_report_workers(processes: int | None = None, method: str = START_METHOD) -> ReportWorkers | None:
    """Workers for a report drawn later (``gonio fit --report``), or None to draw it here.

    One worker is started now; after importing matplotlib and the report it starts
    ``processes - 1`` helpers of its own, with which it shares the figures.

    Parameters
    ----------
    processes : int, optional
        Processes drawing the report (default :func:`report_processes`); below 2: none.
    method : str
        multiprocessing start method.

    Returns
    -------
    ReportWorkers or None
        None when one process is asked for or the worker cannot start (a
        ``gonio: warning:`` line on stderr says why; the report is then drawn in-process).
    """
    count = report_processes() if processes is None else processes
    if count < 2:
        return None
    try:
        return ReportWorkers(1, method, helpers=count - 1)
    except Exception as error:  # the report will be drawn in this process instead
        print(f"gonio: warning: report workers could not start ({type(error).__name__}: {error}); "
              "the report will be drawn in this process", file=sys.stderr)
        return None


def finish_report(workers: ReportWorkers | None, folder: str | Path) -> Path:
    """Write the report of the saved result in ``folder``: by ``workers`` when given,
    else (or when they fail, with ``gonio: warning:`` lines on stderr) in this process.
    The workers are stopped in any case.

    Parameters
    ----------
    workers : ReportWorkers or None
        From :func:`start_report_workers`.
    folder : path
        The result folder (FitResult.save); the report goes into it.

    Returns
    -------
    pathlib.Path
        The HTML file.
    """
    if workers is not None:
        try:
            path, messages = workers.write_report(folder)
            for message in messages:
                print(f"gonio: warning: {message}", file=sys.stderr)
            return path
        except ReportWorkerError as error:
            print(f"gonio: warning: {error}\ngonio: warning: drawing the report in this process instead",
                  file=sys.stderr)
        finally:
            workers.close()
    from .fit_report import write_report

    return write_report(folder)


def write_report_shared(result, out: Path, workers: ReportWorkers | int | None,
                        method: str = START_METHOD) -> Path:
    """The figures of ``result`` drawn by this process and by workers; the HTML written here.

    A worker that cannot start or fails is reported by a :class:`ReportWorkerWarning`
    and its share drawn here.

    Parameters
    ----------
    result : FitResult
        The fit (sent to the workers by pickling).
    out : pathlib.Path
        Existing output folder.
    workers : ReportWorkers, int or None
        Running workers (left running), or the number of processes in all: workers are
        started for ``workers - 1`` of them and stopped at the end. None or 1: none.
    method : str
        multiprocessing start method of workers started here.

    Returns
    -------
    pathlib.Path
        The HTML file.
    """
    from .fit_report import write_figures, write_html

    pool = workers
    if isinstance(workers, int):
        pool = None
        if workers > 1:
            try:
                pool = ReportWorkers(workers - 1, method)
            except Exception as error:
                warnings.warn(f"report workers could not start ({type(error).__name__}: {error}); drawing every "
                              "figure in this process", ReportWorkerWarning, stacklevel=3)
    shares = share_figures(1 + (len(pool) if pool is not None else 0))
    submitted = []
    try:
        for k, share in enumerate(shares[1:]):
            if share:
                try:
                    pool.submit(k, ("figures", _portable(result), out, share))
                    submitted.append((k, share))
                except ReportWorkerError as error:
                    _drawn_here(error, result, out, share)
        pngs = write_figures(result, out, shares[0])
        for k, share in submitted:
            try:
                pool.wait(k)
            except ReportWorkerError as error:
                pngs.update(_drawn_here(error, result, out, share))
    finally:
        if pool is not None and pool is not workers:
            pool.close()
    return write_html(result, out, pngs)


def _portable(result):
    """``result`` without what a process rebuilds on demand and cannot pickle (the cached
    FitProblem of :meth:`gonio.fitting.FitResult.problem`, which holds the model's
    prepared functions): a shallow copy, the result itself is left as it is."""
    clone = copy.copy(result)
    clone.__dict__.pop("_problem", None)
    return clone


def _drawn_here(error: ReportWorkerError, result, out: Path, share: tuple[str, ...]) -> dict[str, bytes]:
    """Warn about a failed worker and draw its share in this process."""
    from .fit_report import write_figures

    warnings.warn(f"{error}\ndrawing {', '.join(share)} in this process instead", ReportWorkerWarning, stacklevel=4)
    return write_figures(result, out, share)
