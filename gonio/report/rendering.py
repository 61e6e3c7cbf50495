"""The figures of a fit report drawn as PNG bytes, and the result a report is drawn from.

:func:`render_figures` draws the figures of :data:`~gonio.report.fit_html.FIGURES` from a
fit (:mod:`gonio.report.fit_figures`, matplotlib); :func:`load_source` reads the fit result
a report is drawn from. Nothing here writes a file: :mod:`gonio.report.fit_report` writes
the report.
"""
from __future__ import annotations

import io
from pathlib import Path

from matplotlib.figure import Figure

from gonio.fitting.results import FitResult

from . import fit_figures
from .fit_html import FIGURE_NAMES, FIGURES

__all__ = ["render_figures", "load_source"]

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
    unknown = sorted(set(filenames) - set(functions))
    if unknown:
        raise ValueError(f"render_figures: unknown figure file(s) {unknown}; expected names of {list(functions)}")
    return {filename: _png(getattr(fit_figures, functions[filename])(result)) for filename in filenames}
