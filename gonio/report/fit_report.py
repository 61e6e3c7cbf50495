"""The fit report: one self-contained HTML file plus the PNG figures.

:func:`write_report` reads a fit result folder (``result.json`` + ``chain.npz``, written
by :meth:`gonio.fitting.FitResult.save`) and writes, into the same folder or another one,
``report.html`` (every figure embedded as a base64 PNG, no external reference) and the
figures as ``fit-*.png``. The figures are drawn here (:func:`render_figures`, matplotlib);
the page and the files are written by :mod:`gonio.report.fit_html`, which holds the list
of figures (:data:`FIGURES`) and needs no matplotlib.
"""
from __future__ import annotations

import io
from pathlib import Path

from matplotlib.figure import Figure

from gonio.fitting.dataset import Dataset
from gonio.fitting.results import FitResult

from . import fit_figures
from .fit_html import DATASET_FIGURES, FIGURE_NAMES, FIGURES, REPORT_FILE, REPORT_FILES, write_html, write_report_files

__all__ = ["write_report", "render_figures", "render_dataset_figures", "write_html", "write_report_files",
           "load_source", "FIGURES", "FIGURE_NAMES", "DATASET_FIGURES", "REPORT_FILE", "REPORT_FILES"]

#: zlib level of the PNG files: 1 makes files 2 to 5 % larger than 3 or the default 6 in
#: 70 % (trace figure) to 90 % of the time of 3 and half that of 6 (measured on the
#: figures of a Fig 16 fit).
_PNG_COMPRESSION = 1

#: Resolution of the PNG files [dots per inch].
_DPI = 110


def _png(fig: Figure) -> bytes:
    """The figure encoded as PNG."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=_DPI, pil_kwargs={"compress_level": _PNG_COMPRESSION})
    return buffer.getvalue()


def load_source(source: str | Path | FitResult, out: str | Path | None = None) -> tuple[FitResult, Path]:
    """The fit result a report is drawn from and the folder it goes into (created).

    Parameters
    ----------
    source : path or FitResult
        A result folder (or its ``result.json``), or a result in memory.
    out : path, optional
        Output folder (default: the result folder; required for an in-memory result).

    Returns
    -------
    tuple of (FitResult, pathlib.Path)
        The result and the output folder.

    Raises
    ------
    FileNotFoundError, ValueError
        The result cannot be read, or an in-memory result has no output folder.
    """
    if isinstance(source, FitResult):
        if out is None:
            raise ValueError("write_report: give an output folder 'out' for an in-memory result")
        result = source
    else:
        source = Path(source)
        result = FitResult.load(source)
        if out is None:
            out = source if source.is_dir() else source.parent
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return result, out


def render_figures(result: FitResult, filenames: tuple[str, ...] = FIGURE_NAMES) -> dict[str, bytes]:
    """Draw figures of :data:`FIGURES` and encode them as PNG (nothing is written).

    Parameters
    ----------
    result : FitResult
        The fit drawn.
    filenames : tuple of str
        File names of the figures to draw (default: all, in report order).

    Returns
    -------
    dict of str to bytes
        The PNG bytes by file name.

    Raises
    ------
    ValueError
        A name is not one of the report's figures.
    """
    functions = {figure.file: figure.function for figure in FIGURES}
    return _render(result, filenames, functions, "render_figures: unknown figure file(s)")


def render_dataset_figures(dataset: Dataset, filenames: tuple[str, ...] = tuple(DATASET_FIGURES)) -> dict[str, bytes]:
    """Draw figures of :data:`DATASET_FIGURES` from the measurements alone and encode them
    as PNG: the same bytes :func:`render_figures` gives for a fit of ``dataset``
    (parameters, return value and errors as there; default: every such figure).
    """
    return _render(dataset, filenames, DATASET_FIGURES,
                   "render_dataset_figures: figure file(s) that cannot be drawn from the measurements alone:")


def _render(source: FitResult | Dataset, filenames: tuple[str, ...], functions: dict[str, str],
            refusal: str) -> dict[str, bytes]:
    """PNG bytes of ``filenames``, each drawn from ``source`` by its function of
    :mod:`gonio.report.fit_figures` (``functions``); ``refusal`` begins the error for names
    not among them."""
    unknown = sorted(set(filenames) - set(functions))
    if unknown:
        raise ValueError(f"{refusal} {unknown}; expected names of {list(functions)}")
    return {filename: _png(getattr(fit_figures, functions[filename])(source)) for filename in filenames}


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
