"""The fit report's page: the index of its figures and ``report.html``, without matplotlib.

The report (:func:`gonio.report.fit_report.write_report`) is ``report.html``, one
self-contained file with every figure embedded as a base64 PNG, plus the figures as
``fit-*.png``. The figures are drawn with matplotlib (:mod:`gonio.report.rendering`);
this module holds what needs no matplotlib: which figures there are (:data:`FIGURES`),
the file names (which ``gonio fit --overwrite`` reads to remove an earlier report), and
the writing of the page and the files from the figures' PNG bytes.

The page reads top to bottom: warnings first, then what was measured, data against the
posterior predictive band, residuals, the parameter table, the posterior (corner plot),
the chain (traces), sampler diagnostics, correlations and the plain-text summary.
"""
from __future__ import annotations

import base64
import html
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, NamedTuple

import numpy as np

from gonio.files import write_atomic
from gonio.models import get as get_model

if TYPE_CHECKING:
    from gonio.fitting.results import FitResult

__all__ = ["ReportFigure", "FIGURES", "FIGURE_NAMES", "REPORT_FILE", "REPORT_FILES", "write_html",
           "write_report_files"]


class ReportFigure(NamedTuple):
    """One figure of the report."""

    #: PNG file name in the report folder.
    file: str
    #: Title of its section of the page.
    title: str
    #: Name of the function of :mod:`gonio.report.fit_figures` that draws it from a FitResult.
    function: str
    #: Caption under it.
    caption: str


#: The HTML file of a report.
REPORT_FILE = "report.html"

#: The report's figures in report order.
FIGURES: tuple[ReportFigure, ...] = (
    ReportFigure("fit-geometry.png", "What was measured", "geometry_figure",
                 "Viewing directions (rings, one size per incidence: views shared by several incidences show as concentric rings) and source directions (stars) on the hemisphere."),
    ReportFigure("fit-data.png", "Data and model", "data_figure",
                 "Measurements with one-sigma error bars; the model's posterior median with its 68 % and 95 % "
                 "posterior predictive bands (spread of the model over posterior draws, measurement noise not "
                 "added)."),
    ReportFigure("fit-residuals.png", "Residuals", "residual_figure",
                 "Normalised residuals, one panel per incidence (about 68 % should fall in the dark band and 95 % "
                 "within the light one), and every measured value against the model's at its geometry with the "
                 "1:1 line: a misfit the data figure's scale hides shows here. For an approximate model (oren-nayar, "
                 "its qualitative and numerical forms, Wolff's polynomial Fresnel factor), red crosses: the "
                 "approximation's own departure from the exact model at each value, in its uncertainties "
                 "(docs/validity.md)."),
    ReportFigure("fit-corner.png", "Posterior", "corner_figure",
                 "One- and two-dimensional marginal posteriors of the free parameters."),
    ReportFigure("fit-traces.png", "Chain", "trace_figure",
                 "Every walker's position at every step; the shaded start is discarded as burn-in."),
)

#: The figures' file names in report order.
FIGURE_NAMES: tuple[str, ...] = tuple(figure.file for figure in FIGURES)

#: Every file a report writes into its output folder.
REPORT_FILES: tuple[str, ...] = (REPORT_FILE,) + FIGURE_NAMES

_STYLE = """
body { font-family: -apple-system, 'Segoe UI', Helvetica, Arial, sans-serif; max-width: 1100px;
       margin: 2em auto; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.8em; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }
th { background: #f2f2f2; } td.name, th.name { text-align: left; }
.flags { background: #fff3f0; border: 2px solid #d9534f; padding: 0.6em 1em; border-radius: 4px; }
.ok { background: #f0fff3; border: 1px solid #5cb85c; padding: 0.6em 1em; border-radius: 4px; }
.verdict { font-size: 1.1em; margin: 0.6em 0 1em 0; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.9em; color: #555; }
tr.chosen td { font-weight: bold; background: #eef6ee; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
.meta { color: #555; }
"""


def _number(x: Any, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "&ndash;"
    if isinstance(x, (int, np.integer)):
        return str(x)
    return f"{x:.{digits}g}"


def _parameter_table(result: FitResult) -> str:
    sampled = bool(result.posterior)
    head = ["parameter", "unit", "range", "least squares", "std. error"]
    if sampled:
        head += ["median", "&minus;1&sigma;", "+1&sigma;", "2.5 %", "97.5 %", "MAP", "prior"]
    rows = ["<tr>" + "".join(f"<th{' class=name' if i == 0 else ''}>{h}</th>" for i, h in enumerate(head)) + "</tr>"]
    for r in result.parameter_rows():
        lo, hi = r["bounds"]
        cells = [f"<td class=name><b>{html.escape(r['name'])}</b></td>", f"<td>{html.escape(r['unit'])}</td>",
                 f"<td>[{lo:g}, {hi:g}]</td>"]
        if r["fixed"]:
            cells += [f"<td>{_number(r['value'])}</td>", "<td>fixed</td>"]
            cells += ["<td></td>"] * (7 if sampled else 0)
        else:
            width = (r["p84"] - r["p16"]) / 2 if sampled and "p84" in r else r["stderr"]
            from gonio.fitting.text import digits_to_resolve

            digits = digits_to_resolve(r["value"], width)
            cells += [f"<td>{_number(r['value'], digits)}</td>", f"<td>{_number(r['stderr'], 3)}</td>"]
            if sampled:
                cells += [f"<td><b>{_number(r['median'], digits)}</b></td>",
                          f"<td>{_number(r['median'] - r['p16'], 3)}</td>",
                          f"<td>{_number(r['p84'] - r['median'], 3)}</td>", f"<td>{_number(r['p2_5'], digits)}</td>",
                          f"<td>{_number(r['p97_5'], digits)}</td>", f"<td>{_number(r['map'], digits)}</td>",
                          f"<td class=name>{html.escape(r['prior'])}</td>"]
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return "<table>" + "".join(rows) + "</table>"


def _diagnostics_table(result: FitResult) -> str:
    ls = result.least_squares
    info = result.information()
    items = [
        ("data points", result.dataset.n),
        ("free parameters", len(result.free)),
        ("chi-square", ls.chi2),
        ("reduced chi-square", ls.redchi),
        ("AIC / BIC", f"{_number(info['aic'])} / {_number(info['bic'])}"),
        ("least-squares status", html.escape(ls.message)),
    ]
    if result.mcmc is not None:
        m = result.mcmc
        items += [
            ("walkers &times; steps", f"{m.n_walkers} &times; {m.n_steps} (limit {m.max_steps})"),
            ("burn-in / thin", f"{m.burn_in} / {m.thin}"),
            ("converged", "yes (length &ge; %g &tau;, stable &tau;, R-hat &lt; %g)" % (m.tau_multiple, m.rhat_limit)
             if m.converged else "<b style='color:#d9534f'>NO: step limit reached</b>"),
            ("mean acceptance fraction", f"{float(m.acceptance_fraction.mean()):.3f} "
             f"(walkers {float(m.acceptance_fraction.min()):.2f}&ndash;{float(m.acceptance_fraction.max()):.2f})"),
            ("sampling time", f"{m.wall_seconds:.2f} s, of which model evaluation {m.model_seconds:.2f} s"),
        ]
    items += _adequacy_items(result)
    rows = "".join(f"<tr><th class=name>{k}</th><td>{v if isinstance(v, str) else _number(v)}</td></tr>" for k, v in items)
    table = f"<table>{rows}</table>"
    if result.mcmc is not None:
        table += _chain_table(result)
    return table


def _adequacy_items(result: FitResult) -> list[tuple[str, Any]]:
    """Goodness-of-fit rows of the diagnostics table (gonio.fitting.adequacy)."""
    a = result.adequacy
    if a is None:
        return []
    items = [("chi-square p-value (least-squares optimum)", _number(a.chi2_p, 3)),
             ("posterior predictive p-value", _number(a.ppc_p, 3))]
    if math.isfinite(a.extra_noise_ratio):
        items.append(("fitted extra noise / stated uncertainty", _number(a.extra_noise_ratio, 3)))
    if a.lack_of_fit is not None:
        lof = a.lack_of_fit
        items.append(("lack-of-fit p-value (against a flexible description, independent of the stated noise)",
                      f"{_number(lof.p, 3)} (F = {_number(lof.statistic, 3)} on {lof.dof[0]}, {lof.dof[1]} degrees "
                      f"of freedom, series order {lof.order})"))
        items.append(("scatter about model and description / stated uncertainty", _number(lof.noise_factor, 3)))
    verdict = a.verdict if a.adequate else f"<b style='color:#d9534f'>{a.verdict.upper()}</b>"
    items.append(("goodness of fit", f"{verdict} (limits: p &ge; {a.alpha:g}, extra noise &le; stated; "
                                     "docs/fitting.md, 'Three verdicts')"))
    return items


def _chain_table(result: FitResult) -> str:
    """Per parameter: autocorrelation time, chain length in tau, R-hat, bulk and tail ESS."""
    m = result.mcmc
    head = ("<tr><th class=name>parameter</th><th>&tau; [steps]</th><th>chain length / &tau;</th>"
            "<th>effective samples (emcee)</th><th>R-hat (rank, split)</th><th>ESS bulk</th><th>ESS tail</th></tr>")
    body = ""
    for name, tau, ess in zip(result.free, m.tau, m.ess):
        length = m.n_steps / tau if math.isfinite(tau) and tau > 0 else math.nan
        d = m.diagnostics.get(name, {})
        r_hat = d.get("r_hat", math.nan)
        style = " style='color:#d9534f;font-weight:bold'" if not r_hat < m.rhat_limit else ""
        body += (f"<tr><td class=name>{html.escape(name)}</td><td>{_number(float(tau), 3)}</td>"
                 f"<td>{_number(length, 3)}</td><td>{_number(float(ess), 4)}</td>"
                 f"<td{style}>{_number(r_hat, 4)}</td><td>{_number(d.get('ess_bulk'), 4)}</td>"
                 f"<td>{_number(d.get('ess_tail'), 4)}</td></tr>")
    return (f"<table>{head}{body}</table><p class=meta>R-hat and ESS (Vehtari et al. 2021) computed by ArviZ with "
            "each walker as one chain, after burn-in and thinning. The posterior is in posterior.nc (ArviZ "
            "InferenceData) for use in other tools.</p>")


def _verdict(result: FitResult) -> str:
    """The report's opening lines: goodness of fit and convergence."""
    parts, bad = [], False
    if result.adequacy is not None:
        parts.append(html.escape(result.adequacy.headline()))
        bad = not result.adequacy.adequate
    if result.mcmc is not None:
        if result.mcmc.converged:
            parts.append("chain converged (length &ge; %g &tau; and R-hat &lt; %g)"
                         % (result.mcmc.tau_multiple, result.mcmc.rhat_limit))
        else:
            parts.append("CHAIN NOT CONVERGED: posterior numbers are unreliable")
            bad = True
    if not parts:
        return ""
    return (f"<div class='{'flags' if bad else 'ok'} verdict'>" + "<br>".join(parts) + "</div>"
            f"<p class=meta><b>Model discrepancy.</b> {html.escape(result.discrepancy)}</p>")


def _truth_section(result: FitResult) -> str:
    """The fit against the emulated sample's truth, when the data come from the emulator."""
    truth = result.truth_comparison()
    if truth is None:
        return ""
    spec, lines, bias = truth
    box = ("<div class=flags>" + "<br>".join(html.escape(b) for b in bias) + "</div>") if bias else (
        "<div class=ok>Every true value lies inside its 95 % interval.</div>")
    return (f"<h2>Against the truth</h2><p class=meta>The data were measured on the emulated rig, whose sample is "
            f"<code>{html.escape(spec)}</code>.</p><pre>{html.escape(chr(10).join(lines))}</pre>{box}")


def _comparison_section(result: FitResult) -> str:
    """The model comparison that chose the fitted model, when there was one."""
    from gonio.fitting.selection import comparison_html

    if result.comparison is None:
        return ""
    return ("<h2>Model choice</h2>" + comparison_html(result.comparison)
            + "<p class=meta>Every candidate fitted by least squares with the same likelihood; chosen by evidence "
              "among those whose verdict is adequate (docs/fitting.md, 'Model selection'). The fit below is the "
              "chosen model's.</p>")


def _budget_table(result: FitResult) -> str:
    """The measurement's uncertainty budget (from the reduction of a recording), if any."""
    from gonio.uncertainty import COMPONENTS

    meta = result.dataset.metadata
    budget = meta.get("uncertainty_budget")
    if not isinstance(budget, dict) or not budget:
        return "<p>The data carry no uncertainty budget (they do not come from a reduced recording).</p>"
    rows = "".join(f"<tr><td class=name>{html.escape(name)}</td><td>{_number(value, 3)}</td>"
                   f"<td class=name>{html.escape(COMPONENTS.get(name, ''))}</td></tr>" for name, value in budget.items())
    table = ("<table><tr><th class=name>component</th><th>median relative size</th><th class=name>what it is</th></tr>"
             f"{rows}</table>")
    calibration = meta.get("calibration_budget")
    if isinstance(calibration, dict) and calibration:
        items = ", ".join(f"{html.escape(k)} {_number(v, 2)}" for k, v in calibration.items())
        table += f"<p class=meta>Calibration (relative, common to every value; the prior on the scale): {items}.</p>"
    notes = []
    excluded = meta.get("excluded")
    if isinstance(excluded, dict):
        notes += [f"{count} {html.escape(str(reason))} point(s) excluded from the fit" for reason, count in excluded.items()]
    warnings = meta.get("reduction_warnings")
    if isinstance(warnings, list):
        notes += [html.escape(str(w)) for w in warnings]
    if notes:
        table += "<ul>" + "".join(f"<li>{n}</li>" for n in notes) + "</ul>"
    return table + "<p class=meta>How each component is estimated: docs/acquisition.md.</p>"


def _correlation_table(result: FitResult) -> str:
    matrix = np.asarray(result.posterior["correlation"] if result.posterior else result.least_squares.correlation, float)
    names = list(result.free)
    if len(names) < 2:
        return "<p>One free parameter: no correlations.</p>"
    head = "<tr><th></th>" + "".join(f"<th>{html.escape(n)}</th>" for n in names) + "</tr>"
    body = ""
    for i, name in enumerate(names):
        cells = ""
        for j in range(len(names)):
            r = matrix[i, j]
            shade = "" if not math.isfinite(r) or i == j else f" style='background: rgba({'217,83,79' if r > 0 else '49,130,189'},{min(abs(r), 1) * 0.6:.2f})'"
            cells += f"<td{shade}>{_number(float(r), 3)}</td>"
        body += f"<tr><th class=name>{html.escape(name)}</th>{cells}</tr>"
    return f"<table>{head}{body}</table>"


def write_html(result: FitResult, out: Path, pngs: Mapping[str, bytes]) -> Path:
    """Write ``report.html`` with every figure embedded.

    Parameters
    ----------
    result : FitResult
        The fit reported.
    out : pathlib.Path
        Existing output folder.
    pngs : mapping of str to bytes
        The PNG bytes of every figure of :data:`FIGURES`, by file name (nothing is read
        from ``out``: the page embeds exactly the figures given).

    Returns
    -------
    pathlib.Path
        The HTML file.

    Raises
    ------
    ValueError
        A figure is missing from ``pngs``.
    """
    _require_every_figure(pngs)
    model = get_model(result.model)
    data = result.dataset
    sections = []
    for figure in FIGURES:
        encoded = base64.b64encode(pngs[figure.file]).decode("ascii")
        sections.append(
            (figure.title, f"<figure><img alt='{html.escape(figure.title)}' src='data:image/png;base64,{encoded}'>"
                           f"<figcaption>{html.escape(figure.caption)}</figcaption></figure>")
        )
    figures = dict(sections)
    if result.flags:
        flags = "<div class=flags><b>Warnings</b><ul>" + "".join(f"<li>{html.escape(f)}</li>" for f in result.flags) + "</ul></div>"
    else:
        flags = "<div class=ok>No warnings: parameters determined, none at a bound" + (
            ", chain converged." if result.mcmc is not None else " (least squares only, no MCMC).") + "</div>"
    fixed = ", ".join(f"{k} = {v:g}" for k, v in result.fixed.items()) or "none"
    title = f"Fit of {html.escape(result.model)} to {html.escape(data.label or 'data')}"
    body = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title><style>{_STYLE}</style></head><body>
<h1>{title}</h1>
{_verdict(result)}
<p class=meta>Model <b>{html.escape(model.name)}</b>: {html.escape(model.description)}.
Reference: {html.escape(model.reference)}.<br>
Data: {data.n} measurements of {html.escape(data.quantity)} [{html.escape(data.unit)}] at {len(data.incidences()[0])} incidences.
Fixed parameters: {html.escape(fixed)}. Created {html.escape(result.created)} with gonio {html.escape(result.gonio_version)}; result id {html.escape(result.result_id or "(none)")}.</p>
{flags}
{_truth_section(result)}
{_comparison_section(result)}
<h2>What was measured</h2>{figures['What was measured']}
<h2>Uncertainty budget of the data</h2>{_budget_table(result)}
<h2>Data and model</h2>{figures['Data and model']}
<h2>Residuals</h2>{figures['Residuals']}
<h2>Parameters</h2>{_parameter_table(result)}
<p class=meta>Least squares: weighted by the measurement uncertainties, bounded by the physical ranges; standard errors from the
Jacobian. Posterior: median with the 16th/84th percentiles (&plusmn;1&sigma;) and 2.5th/97.5th percentiles; MAP is the highest posterior
density found.</p>
<h2>Posterior</h2>{figures['Posterior']}
<h2>Chain</h2>{figures['Chain']}
<h2>Diagnostics</h2>{_diagnostics_table(result)}
<h2>Correlations</h2>{_correlation_table(result)}
<h2>Summary</h2><pre>{html.escape(result.summary())}</pre>
</body></html>
"""
    path = out / REPORT_FILE
    write_atomic(path, body)
    return path


def _require_every_figure(pngs: Mapping[str, bytes]) -> None:
    """Refuse a report without the PNG bytes of each of its figures (never taken from disk,
    where an earlier report's file could stand in for a missing one)."""
    missing = [name for name in FIGURE_NAMES if not pngs.get(name)]
    if missing:
        raise ValueError(f"report: no PNG for {', '.join(missing)}; expected the bytes of every figure of "
                         f"{list(FIGURE_NAMES)}")


def write_report_files(result: FitResult, out: Path, pngs: Mapping[str, bytes]) -> Path:
    """Write the report's files: each figure's PNG file, then ``report.html`` (last, so a
    report page present means its figures were written). Parameters, return value and
    errors as :func:`write_html`.
    """
    _require_every_figure(pngs)
    for name in FIGURE_NAMES:
        write_atomic(out / name, pngs[name])
    return write_html(result, out, pngs)
