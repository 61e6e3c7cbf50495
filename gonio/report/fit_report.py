"""The fit report: one self-contained HTML file plus the PNG figures.

:func:`write_report` reads a fit result folder (``result.json`` + ``chain.npz``, written
by :meth:`gonio.fitting.FitResult.save`) and writes, into the same folder or another one,
``report.html`` (every figure embedded as a base64 PNG, no external reference) and the
figures as ``fit-*.png``. The figures are drawn by :mod:`gonio.report.rendering`
(matplotlib), here or in worker processes (:mod:`gonio.report.workers`); the page and the
files are written by :mod:`gonio.report.fit_html`, which holds the list of figures
(:data:`FIGURES`) and needs no matplotlib.
"""
from __future__ import annotations

from pathlib import Path

from gonio.fitting.results import FitResult

from .fit_html import DATASET_FIGURES, FIGURE_NAMES, FIGURES, REPORT_FILE, REPORT_FILES, write_html, write_report_files
from .rendering import load_source, render_dataset_figures, render_figures

__all__ = ["write_report", "render_figures", "render_dataset_figures", "write_html", "write_report_files",
           "load_source", "FIGURES", "FIGURE_NAMES", "DATASET_FIGURES", "REPORT_FILE", "REPORT_FILES"]


def write_report(source: str | Path | FitResult, out: str | Path | None = None, *, processes: int = 1) -> Path:
    """Write ``report.html`` and the PNG figures of a fit.

    Parameters
    ----------
    source : path or FitResult
        A result folder (or its ``result.json``), or a result in memory.
    out : path, optional
        Output folder (default: the result folder; required for an in-memory result).
    processes : int
        Processes drawing the figures: 1 draws them all here; more start
        ``processes - 1`` worker processes (:func:`gonio.report.workers.write_report_shared`)
        that draw their share while this process draws its own. The files are the same
        either way. A worker that dies or cannot start is reported by a
        :class:`gonio.report.workers.ReportWorkerWarning` and its figures are drawn here;
        an error in a figure is raised as it would be here. With more than one process the
        calling script needs the ``if __name__ == "__main__":`` guard of
        :mod:`multiprocessing` (the workers import the main module).

    Returns
    -------
    pathlib.Path
        The HTML file.

    Raises
    ------
    FileNotFoundError, ValueError
        The result cannot be read; ``processes`` is below 1.
    """
    if processes < 1:
        raise ValueError(f"write_report: processes = {processes}; expected 1 or more")
    if processes == 1:
        result, out = load_source(source, out)
        return write_report_files(result, out, render_figures(result))
    from .workers import write_report_shared

    return write_report_shared(source, out, processes)
