"""The overview page of a fit batch (:func:`gonio.batch.fit_many`): ``overview.md`` and its chart.

The page says first how many fits finished, failed and were found adequate, then shows
one chart (each parameter's posterior median with its 95 % interval, one row per fit)
and a table of every fit with its verdict, chi-square, convergence and wall time; failed
fits are listed with their reasons. Matplotlib's Figure API only (no pyplot state).
"""
from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from typing import Any, Mapping, Sequence

__all__ = ["OVERVIEW_FILE", "CHART_FILE", "parameter_figure", "overview_markdown", "write_overview"]

OVERVIEW_FILE = "overview.md"
CHART_FILE = "overview.png"
#: Panels of the chart at most (one per parameter, in the order the fits name them).
MAX_PANELS = 6
#: Marker colour of a fit by its verdict.
VERDICT_COLOURS = {"adequate": "C0", "noise understated": "C1", "inadequate": "C3"}


def _names(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    names: list[str] = []
    for row in rows:
        names += [name for name in row.get("parameters", {}) if name not in names]
    return names


def parameter_figure(rows: Sequence[Mapping[str, Any]]):
    """One panel per parameter: the median and 95 % interval of each finished fit,
    coloured by its verdict.

    Parameters
    ----------
    rows : sequence of dict
        The batch's rows (:attr:`gonio.batch.BatchResult.rows`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    done = [row for row in rows if row.get("status") == "ok"]
    names = _names(done)[:MAX_PANELS] or ["(no finished fit)"]
    height = max(2.5, 0.28 * len(done) + 1.2)
    fig = Figure(figsize=(3.0 * len(names) + 1.8, height), layout="constrained")
    axes = fig.subplots(1, len(names), sharey=True, squeeze=False)[0]
    labels = [row["task_id"] for row in done]
    for ax, name in zip(axes, names):
        for y, row in enumerate(done):
            stats = row["parameters"].get(name)
            if stats is None or math.isnan(stats["median"]):
                continue
            low, high = stats["p2_5"], stats["p97_5"]
            error = [[stats["median"] - low], [high - stats["median"]]] if not math.isnan(low) else None
            ax.errorbar(stats["median"], y, xerr=error, fmt="o", ms=4, capsize=2,
                        color=VERDICT_COLOURS.get(row.get("verdict"), "0.4"))
        ax.set_xlabel(name)
        ax.grid(axis="x", alpha=0.3)
    shown = {row.get("verdict") for row in done}
    handles = [Line2D([], [], marker="o", ls="", color=colour, label=verdict)
               for verdict, colour in VERDICT_COLOURS.items() if verdict in shown]
    if handles:
        axes[-1].legend(handles=handles, fontsize=7, loc="best", title="verdict", title_fontsize=7)
    axes[0].set_yticks(range(len(labels)), labels, fontsize=7)
    axes[0].set_ylim(len(labels) - 0.5, -0.5)
    fig.suptitle("Posterior median and 95 % interval per fit", fontsize=10)
    return fig


def _cell(value: Any, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value).replace("|", "\\|")


def overview_markdown(rows: Sequence[Mapping[str, Any]], chart: str | None = CHART_FILE) -> str:
    """The text of ``overview.md``: counts, verdicts, the chart, a table of every fit, failures.

    >>> print(overview_markdown([], chart=None).splitlines()[0])
    # Fit batch: 0 fits
    """
    status = Counter(row.get("status") for row in rows)
    verdicts = Counter(row.get("verdict") for row in rows if row.get("status") == "ok")
    lines = [f"# Fit batch: {len(rows)} fits", "",
             f"{status.get('ok', 0)} finished, {status.get('failed', 0)} failed. Verdicts: "
             + (", ".join(f"{count} {verdict}" for verdict, count in verdicts.most_common()) or "none") + ".", "",
             "The full table is fits.csv (and fits.nc); each fit's folder holds its result and summary.txt.", ""]
    if chart:
        lines += [f"![Posterior median and 95 % interval per fit]({chart})", ""]
    lines += ["| task | model | verdict | chi2 / dof | converged | R-hat max | ESS min | wall [s] |",
              "|---|---|---|---|---|---|---|---|"]
    for row in rows:
        redchi = "" if row.get("status") != "ok" else f"{_cell(row.get('chi2'))} / {_cell(row.get('dof'))}"
        lines.append(f"| {_cell(row['task_id'])} | {_cell(row['model'])} | {_cell(row.get('verdict')) or 'FAILED'} | "
                     f"{redchi} | {_cell(row.get('converged'))} | {_cell(row.get('r_hat_max'))} | "
                     f"{_cell(row.get('ess_bulk_min'), 3)} | {_cell(row.get('wall_seconds'), 3)} |")
    failed = [row for row in rows if row.get("status") != "ok"]
    if failed:
        lines += ["", "## Failed fits", ""] + [f"- {row['task_id']}: {row.get('failure')}" for row in failed]
    return "\n".join(lines) + "\n"


def write_overview(rows: Sequence[Mapping[str, Any]], out: str | Path) -> Path:
    """Write ``overview.md`` and ``overview.png`` into the batch folder ``out``.

    Parameters
    ----------
    rows : sequence of dict
        The batch's rows.
    out : path
        The batch folder.

    Returns
    -------
    pathlib.Path
        The path of ``overview.md``.
    """
    import io

    from gonio.files import write_atomic

    out = Path(out)
    buffer = io.BytesIO()
    parameter_figure(rows).savefig(buffer, format="png", dpi=110)
    write_atomic(out / CHART_FILE, buffer.getvalue())
    return write_atomic(out / OVERVIEW_FILE, overview_markdown(rows))
