"""The figures of a fit report drawn as PNG bytes, and the result a report is drawn from.

:func:`render_figures` draws the figures of :data:`~gonio.report.fit_html.FIGURES` from a
fit (:mod:`gonio.report.fit_figures`, matplotlib) and :func:`render_dataset_figures` those
that need the measurements alone; :func:`load_source` reads the fit result a report is
drawn from. Nothing here writes a file or starts a process: :mod:`gonio.report.fit_report`
writes the report, in this process or with the worker processes of
:mod:`gonio.report.workers`, both of which draw with these functions.
"""
from __future__ import annotations

import io
from pathlib import Path

from matplotlib.figure import Figure

from gonio.fitting.dataset import Dataset
from gonio.fitting.results import FitResult

from . import fit_figures
from .fit_html import DATASET_FIGURES, FIGURE_NAMES, FIGURES

__all__ = ["render_figures", "render_dataset_figures", "load_source"]

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
