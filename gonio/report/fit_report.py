"""The fit report: one self-contained HTML file plus the PNG figures.

:func:`write_report` reads a fit result folder (``result.json`` + ``chain.npz``, written
by :meth:`gonio.fitting.FitResult.save`) and writes, into the same folder or another one,
``report.html`` (every figure embedded as a base64 PNG, no external reference) and the
figures as ``fit-*.png``. The figures are drawn by :mod:`gonio.report.rendering`
(matplotlib); the page and the files are written by :mod:`gonio.report.fit_html`, which
holds the list of figures (:data:`FIGURES`) and needs no matplotlib.
"""
from __future__ import annotations

from pathlib import Path

from gonio.fitting.results import FitResult

from .fit_html import FIGURE_NAMES, FIGURES, REPORT_FILE, REPORT_FILES, write_html, write_report_files
from .rendering import load_source, render_figures

__all__ = ["write_report", "render_figures", "write_html", "write_report_files", "load_source", "FIGURES",
           "FIGURE_NAMES", "REPORT_FILE", "REPORT_FILES"]


def write_report(source: str | Path | FitResult, out: str | Path | None = None) -> Path:
    """Write ``report.html`` and the PNG figures of a fit.

    Parameters
    ----------
    source : path or FitResult
        A result folder (or its ``result.json``), or a result in memory.
    out : path, optional
        Output folder (default: the result folder; required for an in-memory result).

    Returns
    -------
    pathlib.Path
        The HTML file.

    Raises
    ------
    FileNotFoundError, ValueError
        The result cannot be read.
    """
    result, out = load_source(source, out)
    return write_report_files(result, out, render_figures(result))
