"""Figures and reports (the only part of gonio that imports matplotlib).

``gonio.report.write_report(result_or_folder, out)`` writes a fit's HTML report with its
figures (:func:`gonio.report.fit_report.write_report`); importing this package loads no
plotting code until it is called.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gonio.fitting.results import FitResult

__all__ = ["write_report"]


def write_report(source: str | Path | FitResult, out: str | Path | None = None) -> Path:
    """Write the HTML report of a fit (a :class:`~gonio.fitting.FitResult` or a result
    folder) into ``out`` (default: the result folder); see
    :func:`gonio.report.fit_report.write_report`."""
    from .fit_report import write_report as write

    return write(source, out)
