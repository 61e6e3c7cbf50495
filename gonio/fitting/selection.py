"""Model comparison: use no more model than the data need.

Two families of criteria, both computed from the weighted least-squares optimum:

* information criteria from the maximum log-likelihood ln L, with k free parameters and n
  measurements: AIC = -2 ln L + 2k (Akaike 1974), AICc = AIC + 2k(k+1)/(n-k-1) (small-sample
  correction), BIC = -2 ln L + k ln n (Schwarz 1978);
* the Bayesian evidence Z = integral of likelihood x prior, in the Laplace approximation
  around the optimum: ln Z ~ ln L + ln prior(theta*) + (k/2) ln(2 pi) + (1/2) ln det C,
  with C the covariance of the posterior at its mode.  Unlike the information criteria it
  charges each parameter for the prior range it could have taken (Occam factor).  The
  likelihood and the priors are exactly those of :func:`gonio.fitting.fit` (the calibration
  prior on ``scale``, the extra-noise term, the aperture averaging of the dataset), so the
  comparison and the fit speak of the same posterior.  Laplace's formula is corrected for
  the supports' truncation of the Gaussian and for a profile that is not Gaussian near a
  bound (:mod:`gonio.fitting.evidence`); docs/evidence.md measures the result against nested
  sampling and quadrature.

:func:`compare_models` fits each candidate (a tabulated one whose table's error matters at
these data's precision by its exact model from the table's optimum,
:mod:`gonio.fitting.polish`), tests its goodness of fit
(:func:`gonio.fitting.adequacy.assess` at the optimum) and chooses by this rule:

1. only candidates that pass the goodness-of-fit test are *adequate*; a model that fails
   it is never chosen while another passes. With ``jitter="auto"`` (``gonio fit``'s
   default), when no candidate is adequate but some follow the data within an understated
   noise (verdict "noise understated", :mod:`gonio.fitting.adequacy`), every candidate is
   fitted again with a relative extra-noise term: the comparison still chooses a model,
   under the noise the data show. Whenever the candidates carry an extra-noise term (so
   added, or given), those judged "noise understated" join the adequate ones;
2. among the adequate ones, those whose evidence is within ``threshold`` (natural-log
   units; default 1, "not worth more than a bare mention" on the scale of Kass & Raftery
   1995, 2 ln B < 2) of the best adequate evidence compete, and the one with the fewest
   free parameters wins (the higher evidence breaks a tie);
3. if no candidate is adequate, the best by evidence is reported with the statement that
   none explains the data.

Every candidate that can be chosen is judged by its evidence. Where Laplace's
approximation is undefined for a candidate (a Hessian not positive definite, a mode least
squares did not reach), that candidate's evidence is computed by sequential Monte Carlo from
its priors to its posterior (:func:`gonio.fitting.evidence.tempered_evidence`) and the
table says so ("lnZ by"). A candidate that fails the goodness-of-fit test cannot be chosen
while another passes, so its evidence cannot change the choice: where its Laplace
approximation is undefined its evidence is not sampled (``evidence_method`` "not needed",
"-" in the table; on the lab rig's demo the qualitative model's sequential Monte Carlo,
through the numpy aperture path at a reduced chi-square near 1,400, took more than twenty
minutes of a comparison that is otherwise about fifteen seconds), and where it would need
the profiles of its shape corrections (a parameter near a bound: about 30 least-squares
fits each: 1.6-1.8 s for each of two failing candidates of the demo's comparison, which
took 6.8 s) it is not computed either. Only when no candidate passes, and the best by evidence is shown, are
those evidences computed in full. No evidence is sampled that cannot reach what it would need
to change the choice (within ``threshold`` of the best passing candidate's evidence computed,
or the best of all when none passes): a normalised prior gives Z <= max L, so a candidate
whose maximum likelihood is below that need not be sampled (``evidence_method`` "not
needed", ``evidence_bound`` its maximum ln likelihood and ``evidence_needed`` the mark; where
Gaussian priors entered its least squares the likelihood is maximised again without them).
On the lab rig's glossy samples no candidate passed in about a third of the seeds, and the
sampling of the failing candidates, at reduced chi-squares near 1,000, was most of an
18-minute comparison. Nor is a candidate's evidence sampled where it nests an
adequate candidate of the comparison and sits at the nesting point (:data:`NESTINGS`: the
Oren-Nayar + Torrance-Sparrow sum with ``kd = 1`` and ``ks = 0`` is ``oren-nayar`` with
``ir_weight = 1``; ``evidence_method`` "not needed", ``nested_in`` that candidate): its
nesting parameter at the nesting value within two standard errors, and its standard error
below a tenth of the prior's width, so that the posterior's density there exceeds the
prior's, and by the Savage-Dickey ratio (Dickey 1971; Verdinelli & Wasserman 1995, the
priors of the shared parameters being the same) its evidence is below the nested one's,
which has fewer parameters: it can be neither chosen nor the best. On the lab rig's smooth
samples that sampling (``ks`` held on 0, ``sigma_s`` without effect) was four to eight
minutes of a comparison. Only where sampling fails as well does the rule use Delta BIC / 2,
which approximates -Delta ln Z for large n, naming the candidate.

References
----------
R. E. Kass, A. E. Raftery, "Bayes factors", J. Am. Stat. Assoc. 90, 773 (1995), section 3
(interpretation scale) and 4.1.1 (Laplace's method).
J. M. Dickey, "The weighted likelihood ratio, linear hypotheses on normal location
parameters", Ann. Math. Stat. 42, 204 (1971); I. Verdinelli, L. Wasserman, "Computing Bayes
factors using a generalization of the Savage-Dickey density ratio", J. Am. Stat. Assoc. 90,
614 (1995).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np

from .dataset import Dataset
from .evidence import _support, laplace_evidence, log_posterior, tempered_evidence, laplace_log_evidence, \
    scale_degenerate_factor
from .csv_table import ASSUMED_SIGMA
from .problem import jitter_mode

__all__ = ["information_criteria", "laplace_log_evidence", "ModelComparison", "compare_models", "candidate_label",
           "comparison_text", "comparison_html", "COMPARISON_FILE", "COMPARISON_TEXT",
           "compare_loo", "loo_summary"]


def information_criteria(log_likelihood: float, k: int, n: int) -> dict[str, float]:
    """AIC, AICc and BIC from the maximum log-likelihood.

    Examples
    --------
    >>> information_criteria(-10.0, 2, 20)["bic"] == 20.0 + 2 * math.log(20)
    True
    """
    aic = -2.0 * log_likelihood + 2.0 * k
    aicc = aic + 2.0 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else math.inf
    bic = -2.0 * log_likelihood + k * math.log(n)
    return {"aic": aic, "aicc": aicc, "bic": bic}


#: The comparison's files in a result folder (``gonio fit --model A --model B``).
COMPARISON_FILE, COMPARISON_TEXT = "comparison.json", "comparison.txt"


@dataclass
class ModelComparison:
    """Result of :func:`compare_models`.

    Attributes
    ----------
    rows : list of dict
        Per candidate: ``label``, ``model``, ``fixed``, ``k``, ``chi2``, ``redchi``,
        ``chi2_p`` (goodness-of-fit p-value), ``lack_of_fit_p``, ``verdict`` (one of
        :data:`gonio.fitting.adequacy.VERDICTS`), ``adequate``, ``adequacy`` (the verdict's
        headline), ``aic``, ``aicc``, ``bic``, ``delta_bic``, ``log_evidence`` with
        ``evidence_method`` ("laplace", "sequential monte carlo", "not needed" (a
        candidate that fails the goodness-of-fit test, whose evidence could not change the
        choice and was not computed: ``log_evidence`` NaN) or "undefined") and
        ``evidence_error`` (the Laplace terms ``log_evidence_laplace``,
        ``evidence_truncation`` and ``evidence_shape``,
        :class:`gonio.fitting.evidence.LaplaceEvidence`), ``delta_log_evidence``,
        ``values``, ``warnings``, ``nested_in`` and ``evidence_bound`` with
        ``evidence_needed`` (why an evidence was not needed, module docstring),
        ``undetermined`` (a parameter only
        its product with ``scale`` determines, see :func:`scale_degenerate_factor`).
    chosen : str
        The selected model.
    reason : str
        Why.
    jitter : str or None
        The extra-noise term every candidate was compared with.
    fits : dict
        Per label, the candidate's own least-squares fit (its model's, before any polish
        with the exact model; with the table's error measured where it has one), which
        :func:`gonio.fitting.fit` takes as ``least_squares`` instead of fitting again.
    """

    rows: list[dict[str, Any]]
    chosen: str
    reason: str
    threshold: float = 1.0
    fits: dict[str, Any] = field(default_factory=dict, repr=False)
    jitter: str | None = None

    @property
    def chosen_adequate(self) -> bool:
        """True when the chosen model passed its goodness-of-fit test."""
        return self.row(self.chosen)["adequate"]

    def row(self, label: str) -> dict[str, Any]:
        """The row of the candidate ``label``."""
        for row in self.rows:
            if row["label"] == label:
                return row
        raise KeyError(f"no candidate {label!r}; candidates are {[r['label'] for r in self.rows]}")

    @property
    def chosen_verdict(self) -> str:
        """The goodness-of-fit verdict of the chosen model (:data:`gonio.fitting.adequacy.VERDICTS`)."""
        return self.row(self.chosen)["verdict"]

    def summary(self) -> str:
        """A plain-text table, best first (:func:`comparison_text`)."""
        return comparison_text(self.to_dict())

    def __repr__(self) -> str:
        return (f"<ModelComparison of {len(self.rows)} candidates: chosen {self.chosen} ({self.chosen_verdict}); "
                "summary() for the table>")

    def _repr_html_(self) -> str:
        """The table as HTML (notebooks)."""
        return comparison_html(self.to_dict())

    def to_dict(self) -> dict[str, Any]:
        """The comparison as JSON-ready data (the fits left out)."""
        keep = ("label", "model", "fixed", "k", "chi2", "redchi", "chi2_p", "lack_of_fit_p", "verdict", "adequate",
                "adequacy", "aic", "aicc", "bic", "delta_bic", "log_evidence", "evidence_method", "evidence_error",
                "log_evidence_laplace", "evidence_truncation", "evidence_shape", "delta_log_evidence", "values",
                "undetermined", "nested_in", "evidence_bound", "evidence_needed")
        rows = [{k: row.get(k) for k in keep} for row in self.rows]
        return {"chosen": self.chosen, "chosen_adequate": self.chosen_adequate, "chosen_verdict": self.chosen_verdict,
                "reason": self.reason, "threshold": self.threshold, "jitter": self.jitter, "rows": rows}


def comparison_text(comparison: Mapping[str, Any]) -> str:
    """The plain-text table of a comparison in its JSON form (:meth:`ModelComparison.to_dict`),
    best first, with the notes and the choice."""
    header = (f"{'model':<34} {'k':>2} {'redchi':>8} {'p(chi2)':>8} {'p(lof)':>8} {'verdict':>17} {'BIC':>10} "
              f"{'dBIC':>8} {'lnZ':>10} {'dlnZ':>7} {'lnZ by':>8}")
    lines = [header, "-" * len(header)]
    chosen = comparison["chosen"]
    for row in comparison["rows"]:
        mark = " <- chosen" if row["label"] == chosen else ""
        verdict = row["verdict"] if row["verdict"] == "adequate" else row["verdict"].upper()
        lines.append(
            f"{row['label']:<34} {row['k']:>2} {_number(row['redchi']):>8.3g} {_format_p(_number(row['chi2_p'])):>8} "
            f"{_format_p(_number(row['lack_of_fit_p'])):>8} {verdict:>17} {_number(row['bic']):>10.4g} "
            f"{_number(row['delta_bic']):>8.3g} {_evidence_text(row, 'log_evidence', '.4g'):>10} "
            f"{_evidence_text(row, 'delta_log_evidence', '.3g'):>7} {_evidence_method_text(row):>8}{mark}"
        )
    for row in comparison["rows"]:
        for name in row.get("undetermined", ()):
            lines.append(f"note: {row['label']}: {name} is undetermined, only {name} x scale is (relative radiance "
                         f"without a calibration prior); its evidence integrates over the product")
    quadrature = [f"{r['label']}: {r['evidence_method'].rpartition(' ')[2]}" for r in comparison["rows"]
                  if str(r["evidence_method"]).startswith("laplace, quadrature over ")]
    lines.append("lnZ by: Laplace = corrected Laplace approximation; " + (
                 f"Laplace+quad = quadrature over the parameter the data leave undetermined ({', '.join(quadrature)}), "
                 "Laplace for the others; " if quadrature else "") + "SMC+-error = sequential Monte Carlo, where "
                 "Laplace has no Gaussian to expand" + ("; - = not computed: the candidate fails the goodness-of-fit "
                 "test (or see the note), so its evidence cannot change the choice" if any(r["evidence_method"] == NOT_NEEDED
                                                                        for r in comparison["rows"]) else ""))
    for row in comparison["rows"]:
        if row.get("evidence_bound") is not None:
            lines.append(f"note: {row['label']}: its evidence is at most its maximum ln likelihood, "
                         f"{row['evidence_bound']:.6g}, below the {row['evidence_needed']:.6g} it would need to change "
                         "the choice: not computed")
        if row.get("nested_in"):
            lines.append(f"note: {row['label']} sits at its nesting point in {row['nested_in']}, which is adequate: "
                         "its evidence is below that one's (Savage-Dickey) and was not computed")
    lines.append(f"chosen: {chosen} ({comparison['reason']})")
    return "\n".join(lines)


def comparison_html(comparison: Mapping[str, Any]) -> str:
    """A comparison in its JSON form as an HTML table (the report, notebooks), best first."""
    from html import escape

    head = ("model", "k", "reduced chi-square", "p(chi-square)", "p(lack of fit)", "verdict", "BIC", "dBIC",
            "ln Z", "d ln Z", "ln Z by")
    body = []
    for row in comparison["rows"]:
        cells = (row["label"], row["k"], f"{_number(row['redchi']):.3g}", _format_p(_number(row["chi2_p"])),
                 _format_p(_number(row["lack_of_fit_p"])), row["verdict"], f"{_number(row['bic']):.4g}",
                 f"{_number(row['delta_bic']):.3g}", _evidence_text(row, "log_evidence", ".4g"),
                 _evidence_text(row, "delta_log_evidence", ".3g"), _evidence_method_text(row))
        chosen = ' class="chosen"' if row["label"] == comparison["chosen"] else ""
        body.append(f"<tr{chosen}>" + "".join(f"<td>{escape(str(c))}</td>" for c in cells) + "</tr>")
    return ('<table class="comparison"><thead><tr>' + "".join(f"<th>{escape(h)}</th>" for h in head)
            + "</tr></thead><tbody>" + "".join(body) + "</tbody></table>"
            + f"<p>chosen: <b>{escape(comparison['chosen'])}</b> ({escape(comparison['reason'])})</p>")


def _number(value: Any) -> float:
    """A number of a comparison row (``None`` in JSON: NaN)."""
    return math.nan if value is None else float(value)


def _evidence_text(row: Mapping[str, Any], key: str, form: str) -> str:
    """An evidence column of a row, ``-`` where the evidence was not needed."""
    return "-" if row["evidence_method"] == NOT_NEEDED else format(_number(row[key]), form)


def _evidence_method_text(row: Mapping[str, Any]) -> str:
    """``Laplace``, ``SMC+-0.2`` (with the sampled estimate's error), ``-`` (not needed) or ``n/a``."""
    if row["evidence_method"] == "sequential monte carlo":
        return f"SMC+-{row['evidence_error']:.2g}"
    if row["evidence_method"] == NOT_NEEDED:
        return "-"
    if str(row["evidence_method"]).startswith("laplace, quadrature over "):
        return "Laplace+quad"
    return "Laplace" if row["evidence_method"] == "laplace" else "n/a"


def _format_p(p: float) -> str:
    return "n/a" if not math.isfinite(p) else (f"{p:.2g}" if p >= 1e-4 else f"{p:.0e}")


def candidate_label(name: str, fixed: Mapping[str, float]) -> str:
    """The label of a candidate model in a comparison: ``name`` or ``name (k=v, ...)``.

    Examples
    --------
    >>> candidate_label("oren-nayar", {"ir_weight": 1.0})
    'oren-nayar (ir_weight=1)'
    """
    return name + ("" if not fixed else " (" + ", ".join(f"{k}={v:g}" for k, v in fixed.items()) + ")")


def compare_models(
    dataset: Dataset,
    candidates: Sequence[str | tuple[str, Mapping[str, float]]],
    threshold: float = 1.0,
    n_starts: int = 6,
    priors: Mapping[str, Any] | None = None,
    jitter: bool | str = False,
    alignment: str | Sequence[str] | None = None,
    stray_light: bool = False,
) -> ModelComparison:
    """Fit several models by least squares and choose the simplest adequate one (module docstring).

    Parameters
    ----------
    dataset : Dataset
    candidates : sequence
        Model names, or ``(name, fixed)`` pairs.
    threshold : float
        Evidence margin [natural log units] within which the model with fewer free
        parameters is preferred.
    n_starts : int
        Starting points per least-squares fit.
    priors : mapping of Prior, optional
        Priors overriding the defaults, by parameter name (e.g. the calibration's prior on
        ``scale`` from :meth:`gonio.reduction.Reduced.fit_inputs`); each applies to the
        candidates that have that free parameter. They enter the least-squares fits (a
        Gaussian prior makes them posterior modes) and the Laplace evidence, as in
        :func:`gonio.fitting.fit`.
    jitter : bool or {"absolute", "relative", "auto"}
        The extra-noise term of every candidate, as in :func:`gonio.fitting.fit`; "auto"
        adds a relative one to every candidate when no candidate is adequate and some
        follow the data within an understated noise (module docstring).
    alignment : str or sequence of str, optional
        The alignment parameters of every candidate, with their default priors, as in
        :func:`gonio.fitting.fit`.
    stray_light : bool
        The stray-light parameter of every candidate, as in :func:`gonio.fitting.fit`.

    Returns
    -------
    ModelComparison

    Examples
    --------
    >>> import numpy as np, gonio
    >>> tr = np.arange(0.0, 80.0, 5.0)
    >>> values = gonio.brdf("lambert", 30, 0, tr, 0, rho=0.5) * (1 + 0.01 * np.sin(tr))
    >>> comparison = compare_models(Dataset(30, 0, tr, 0, values, 0.003), ["lambert", "minnaert"])
    >>> comparison.chosen
    'lambert'
    """
    if not candidates:
        raise ValueError("compare_models needs at least one candidate model")
    pairs = [(c, {}) if isinstance(c, str) else (c[0], dict(c[1])) for c in candidates]
    noise = None if jitter == "auto" else jitter
    note = ""
    if jitter == "auto" and dataset.metadata.get(ASSUMED_SIGMA):
        noise, note = "relative", "; the data state no uncertainties: compared with a relative noise of fitted size"
    rows, fits, deferred, pending = _fit_candidates(dataset, pairs, n_starts, priors, noise, alignment, stray_light)
    if noise is None and jitter == "auto" and not any(r["adequate"] for r in rows) and any(
            r["verdict"] == "noise understated" for r in rows):
        noise = "relative"
        rows, fits, deferred, pending = _fit_candidates(dataset, pairs, n_starts, priors, noise, alignment,
                                                        stray_light)
        note = ("; compared with a relative extra-noise term, since the data scatter more than stated about "
                "candidates that follow them")
    _complete(rows, pending, deferred, bool(noise), threshold)
    if not any(r["verdict"] in _passing(bool(noise)) for r in rows):  # the best of all is shown: every evidence
        pending = {}
        for row in rows:  # a row already bounded stays so: the evidence it must reach only rises
            if row["evidence_method"] == NOT_NEEDED and "evidence_bound" not in row:
                row.update(_evidence_terms(*deferred[row["label"]], defer=True))
                if row["evidence_method"] == TO_SAMPLE:
                    pending[row["label"]] = deferred[row["label"]]
        _complete(rows, pending, deferred, bool(noise), threshold)
    use_evidence = _annotate_deltas(rows)
    chosen, reason = _choose(rows, threshold, use_evidence, accept_understated=bool(noise))
    if chosen["verdict"] not in _passing(bool(noise)):
        reason += _texture_hint(alignment)
    # best first; a candidate whose evidence was not needed after those with one, by BIC
    rows.sort(key=lambda r: (0, -r["log_evidence"]) if use_evidence and r["evidence_method"] != NOT_NEEDED
              else (1, r["bic"]))
    return ModelComparison(rows=rows, chosen=chosen["label"], reason=reason + note, threshold=threshold, fits=fits,
                           jitter=jitter_mode(noise))


def _texture_hint(alignment: str | Sequence[str] | None) -> str:
    """What a comparison that no candidate passes adds where it models the rig's alignment
    but not the sample's mesoscale slope: on the lab rig the specular sample's true model
    failed in 11 of 20 seeds so and passed in 20 of 20 with the slope fitted
    (docs/calibration.md, section 3)."""
    from .rig_errors import parse_alignment

    names = parse_alignment(alignment)
    if not names or "texture_slope" in names:
        return ""
    return ("; on a textured sample, its mesoscale slope may be what the candidates miss: compare them with "
            "texture_slope fitted too (--alignment all,texture_slope)")


#: ``evidence_method`` of a failing candidate whose evidence was not computed (module docstring).
NOT_NEEDED = "not needed"
#: ``evidence_method`` of a candidate whose Laplace evidence is undefined, while the
#: comparison decides whether it must be sampled (:func:`_sample_nest_or_bound`).
TO_SAMPLE = "to sample"


@dataclass(frozen=True)
class Nesting:
    """A candidate that reduces to another where one parameter takes a value (module
    docstring): ``model`` with ``fixed`` values and ``parameter = value`` is ``nested``
    with ``nested_fixed``."""

    model: str
    parameter: str
    value: float
    fixed: Mapping[str, float]
    nested: str
    nested_fixed: Mapping[str, float]

    def holds(self, row: Mapping[str, Any], other: Mapping[str, Any]) -> bool:
        """Whether ``row``'s candidate reduces to ``other``'s by this nesting."""
        return (row["model"] == self.model and other["model"] == self.nested
                and all(row["fixed"].get(k) == v for k, v in self.fixed.items())
                and all(other["fixed"].get(k) == v for k, v in self.nested_fixed.items()))


#: The nestings among the registered models that the comparison knows: Oren & Nayar's eq 38
#: with kd = 1 and no specular lobe is its diffuse term, eq 33-34 with interreflection.
NESTINGS = (Nesting("oren-nayar+torrance-sparrow", "ks", 0.0, {"kd": 1.0}, "oren-nayar", {"ir_weight": 1.0}),)
#: The nesting parameter's standard error must be below this share of its prior's width.
NESTING_SHARE = 0.1


def _nested_in(row: Mapping[str, Any], judged, rows: Sequence[Mapping[str, Any]],
               accept_understated: bool) -> str | None:
    """The label of an adequate candidate that ``row``'s nests at its optimum (module
    docstring), ``judged`` its (problem, least squares, priors): the nesting parameter free,
    within two standard errors of the nesting value, its standard error below
    :data:`NESTING_SHARE` of its prior's width; None if there is none."""
    problem, least_squares, priors = judged
    for nesting in NESTINGS:
        name = nesting.parameter
        if name not in problem.free:
            continue
        error = least_squares.stderr.get(name, math.nan)
        lo, hi = _support(problem, priors[name], name)
        if not (error > 0 and abs(least_squares.values[name] - nesting.value) <= 2.0 * error
                and error < NESTING_SHARE * (hi - lo)):
            continue
        for other in rows:
            if other is not row and nesting.holds(row, other) and other["verdict"] in _passing(accept_understated):
                return other["label"]
    return None


def _passing(accept_understated: bool) -> tuple[str, ...]:
    """The verdicts of candidates that can be chosen (rule 1 of the module docstring)."""
    return ("adequate", "noise understated") if accept_understated else ("adequate",)


def _fit_candidates(dataset, pairs, n_starts, priors, jitter, alignment, stray_light):
    """The comparison's row and own least-squares fit of every candidate, by label, and the
    (problem, least squares, priors) it is judged by of each whose evidence was left
    uncomputed: not needed, or to be sampled (:func:`_complete`)."""
    rows, fits, deferred, pending = [], {}, {}, {}
    for name, fixed in pairs:
        row, own, judged = _candidate_row(dataset, name, fixed, n_starts, priors, jitter, alignment, stray_light)
        rows.append(row)
        fits[row["label"]] = own
        if row["evidence_method"] == NOT_NEEDED:
            deferred[row["label"]] = judged
        elif row["evidence_method"] == TO_SAMPLE:
            pending[row["label"]] = judged
    return rows, fits, deferred, pending


def _complete(rows: list[dict[str, Any]], pending, deferred, accept_understated: bool, threshold: float) -> None:
    """Sample the :data:`TO_SAMPLE` evidences that can matter, once every verdict of the
    comparison's last pass is known (a first pass that no candidate passes is done again
    with the extra-noise term: its samples would be thrown away). The candidates are taken
    lowest BIC first, so that an evidence sampled can spare the others the sampling."""
    for row in sorted((r for r in rows if r["label"] in pending), key=lambda r: r["bic"]):
        _sample_nest_or_bound(row, pending[row["label"]], rows, accept_understated, threshold)
        if row["evidence_method"] == NOT_NEEDED:
            deferred[row["label"]] = pending[row["label"]]


def _sample_nest_or_bound(row: dict[str, Any], judged, rows: Sequence[Mapping[str, Any]], accept_understated: bool,
                          threshold: float) -> None:
    """Complete a :data:`TO_SAMPLE` row: :data:`NOT_NEEDED` with ``nested_in`` where it sits
    at its nesting point in an adequate candidate (:func:`_nested_in`), :data:`NOT_NEEDED`
    with ``evidence_bound`` where its maximum likelihood is below what it would need to
    matter (:func:`_needed_evidence`), else sampled."""
    nested = _nested_in(row, judged, rows, accept_understated)
    if nested is not None:
        row.update(log_evidence=math.nan, evidence_method=NOT_NEEDED, evidence_error=math.nan, nested_in=nested)
        return
    needed = _needed_evidence(row, rows, accept_understated, threshold)
    bound = _likelihood_bound(*judged) if needed > judged[1].log_likelihood else math.inf
    if bound < needed:
        row.update(log_evidence=math.nan, evidence_method=NOT_NEEDED, evidence_error=math.nan,
                   evidence_bound=bound, evidence_needed=needed)
    else:
        row.update(_sampled_evidence(judged[0], judged[2]))


def _needed_evidence(row: Mapping[str, Any], rows: Sequence[Mapping[str, Any]], accept_understated: bool,
                     threshold: float) -> float:
    """The evidence ``row``'s candidate must reach to change the choice, from the evidences
    computed so far (module docstring): within ``threshold`` of the best passing candidate's
    when some pass, the best of all when none does; -inf while none is known."""
    passing = [r for r in rows if r["verdict"] in _passing(accept_understated)]
    others = [r["log_evidence"] for r in (passing or rows)
              if r is not row and math.isfinite(_number(r.get("log_evidence")))]
    if not others:
        return -math.inf
    return max(others) - (threshold if passing else 0.0)


def _likelihood_bound(problem, least_squares, priors) -> float:
    """An upper bound of a candidate's ln evidence: its maximum ln likelihood over the
    priors' support, since Z = integral of L x prior <= max L for a normalised prior.

    Where Gaussian priors entered the least squares (a posterior mode, not the likelihood's
    maximum) the likelihood is maximised again from there without them, inside their
    supports. Like Laplace's approximation it takes the least squares to have found the
    global maximum."""
    from .least_squares import fit_least_squares

    if not least_squares.gaussian_priors:
        return least_squares.log_likelihood
    flat = {name: _support_only(priors[name]) for name in problem.free}
    unpenalised = fit_least_squares(problem, start=least_squares.values, n_starts=1,
                                    priors={name: prior for name, prior in flat.items() if prior is not None})
    return max(least_squares.log_likelihood, unpenalised.log_likelihood)


def _support_only(prior):
    """A prior that restricts the least squares to its support and pulls nowhere: a
    Gaussian one as the uniform prior on its support (None where that is unbounded: the
    physical range bounds the fit), any other as it is (only Gaussian priors enter the
    least squares' objective)."""
    from .priors import Normal, Uniform

    if not isinstance(prior, Normal):
        return prior
    return Uniform(prior.lower, prior.upper) if math.isfinite(prior.lower) and math.isfinite(prior.upper) else None


def _candidate_row(dataset, name, fixed, n_starts, priors, jitter, alignment, stray_light):
    """Fit one candidate by least squares: its row of the comparison, its own model's fit
    (:attr:`ModelComparison.fits`), and the problem, fit and priors it is judged by (the
    exact model's where a table's fit was polished)."""
    from .least_squares import fit_least_squares
    from .polish import with_table_error
    from .problem import FitProblem

    def problem_of(model: str) -> FitProblem:
        return FitProblem(model, dataset, fixed, jitter=jitter, alignment=alignment, stray_light=stray_light)

    problem = problem_of(name)
    given = {k: v for k, v in problem.priors_with_defaults(priors).items() if k in problem.free}
    own = with_table_error(problem, fit_least_squares(problem, n_starts=n_starts, priors=given), problem_of)
    judged, ls, candidate_priors, verdict, terms = _judged(problem, own, given, problem_of, restartable=True)
    higher = terms.pop("higher_point", None)
    restarted = None if higher is None else _restarted(judged, ls, given, candidate_priors, higher)
    if restarted is not None:
        own = with_table_error(problem, restarted, problem_of)
        judged, ls, candidate_priors, verdict, terms = _judged(problem, own, given, problem_of, restartable=False)
    elif higher is not None:
        terms.update(_sampled_evidence(judged, candidate_priors))
    problem = judged
    row = {
        "label": candidate_label(name, fixed),
        "model": name,
        "fixed": fixed,
        "k": len(problem.free),
        "chi2": ls.chi2,
        "redchi": ls.redchi,
        "chi2_p": verdict.chi2_p,
        "lack_of_fit_p": verdict.lack_of_fit.p if verdict.lack_of_fit is not None else math.nan,
        "verdict": verdict.verdict,
        "adequate": verdict.adequate,
        "adequacy": verdict.headline(),
        "undetermined": _undetermined(problem, ls, candidate_priors),
        **information_criteria(ls.log_likelihood, len(problem.free), problem.n_informative),
        **terms,
        "values": ls.values,
        "warnings": ls.warnings,
    }
    return row, own, (problem, ls, candidate_priors)


def _judged(problem, own, given, problem_of, restartable: bool):
    """What a candidate is judged by: the problem and fit (the exact model's where a
    table's error matters, :mod:`gonio.fitting.polish`), its priors, its verdict and its
    evidence terms (:func:`_evidence_terms`; ``restartable`` only for an unpolished fit)."""
    from .adequacy import assess
    from .mcmc import resolve_priors
    from .polish import polish

    ls = own
    polished = polish(problem, own, given, problem_of)
    if polished is not None:  # the table's error matters: judge the candidate by its exact model
        problem, ls = polished.problem, replace(polished.least_squares,
                                                warnings=[*polished.least_squares.warnings, polished.flag()])
    candidate_priors = resolve_priors(problem, ls.values, given)
    verdict = assess(problem, ls)
    terms = _evidence_terms(problem, ls, candidate_priors, sample=verdict.verdict in _passing(True),
                            restartable=restartable and polished is None, defer=True)
    return problem, ls, candidate_priors, verdict, terms


def _evidence_terms(problem, least_squares, priors, sample: bool = True, restartable: bool = False,
                    defer: bool = False) -> dict[str, Any]:
    """``log_evidence`` and how it was computed, for a row of the comparison.

    Laplace's corrected approximation where it is defined (its terms as
    ``log_evidence_laplace``, ``evidence_truncation``, ``evidence_shape``); where it is not
    (no Gaussian around the mode), sequential Monte Carlo of the same integrand
    (:func:`gonio.fitting.evidence.tempered_evidence`), so that every candidate is judged
    by the same quantity, unless ``sample`` is false (a candidate that fails the
    goodness-of-fit test: :data:`NOT_NEEDED`, module docstring). ``evidence_method`` says
    which, ``evidence_error`` the estimate's standard error (0 for Laplace, a
    deterministic approximation). A failing candidate's profiles (the shape corrections,
    about 30 least-squares fits a parameter near a bound) are not computed either: its
    evidence is then :data:`NOT_NEEDED` too, and computed in full only if no candidate
    passes. With ``restartable``, a Laplace evidence undefined because a profile rose above
    the optimum is returned with that point as ``higher_point`` instead of being sampled:
    the caller restarts the least squares from it. With ``defer``, a candidate that would
    be sampled is returned as :data:`TO_SAMPLE`, for the comparison to decide once every
    verdict is known (:func:`_sample_nest_or_bound`).
    """
    laplace = laplace_evidence(problem, least_squares, priors, profiles=sample)
    terms = {"log_evidence": laplace.log_evidence, "log_evidence_laplace": laplace.raw,
             "evidence_truncation": laplace.truncation, "evidence_shape": dict(laplace.shape),
             "evidence_method": "laplace" if laplace.quadrature_over is None
             else f"laplace, quadrature over {laplace.quadrature_over}", "evidence_error": 0.0}
    if math.isfinite(laplace.log_evidence) and not laplace.profiles_skipped:
        return terms
    if not sample:
        return {**terms, "log_evidence": math.nan, "evidence_method": NOT_NEEDED, "evidence_error": math.nan}
    if restartable and laplace.higher_point is not None:  # the caller restarts the least squares there
        return {**terms, "higher_point": laplace.higher_point}
    if defer:
        return {**terms, "log_evidence": math.nan, "evidence_method": TO_SAMPLE, "evidence_error": math.nan}
    return {**terms, **_sampled_evidence(problem, priors)}


def _restarted(problem, least_squares, given, priors, higher: Mapping[str, float]):
    """The least squares restarted from ``higher``, a point an evidence profile found above
    the optimum (the first fit stopped short of the posterior's mode, evidence module
    docstring), flagged; None if it does not end higher than ``least_squares``."""
    from .least_squares import fit_least_squares

    restarted = fit_least_squares(problem, start=higher, n_starts=1, priors=given)
    if not _at_optimum(problem, priors, restarted) > _at_optimum(problem, priors, least_squares):
        return None
    return replace(restarted, warnings=[*restarted.warnings, "least squares restarted from a higher point of an "
                                        "evidence profile: the first optimum stopped short of the mode"])


def _at_optimum(problem, priors, least_squares) -> float:
    """The log posterior at a least-squares optimum."""
    return log_posterior(problem, priors, np.array([least_squares.values[n] for n in problem.free], float))


def _sampled_evidence(problem, priors) -> dict[str, Any]:
    """``log_evidence``, ``evidence_method`` and ``evidence_error`` by sequential Monte Carlo."""
    sampled = tempered_evidence(problem, priors)
    method = "sequential monte carlo" if math.isfinite(sampled.log_evidence) else "undefined"
    return {"log_evidence": sampled.log_evidence, "evidence_method": method, "evidence_error": sampled.error}


def _undetermined(problem, least_squares, priors) -> list[str]:
    """The factor only its product with ``scale`` determines, when nothing else does."""
    if np.all(np.isfinite(np.asarray(least_squares.covariance, float))):
        return []
    factor = scale_degenerate_factor(problem, least_squares, priors)
    return [factor] if factor else []


def _annotate_deltas(rows: list[dict[str, Any]]) -> bool:
    """Add ``delta_bic`` and ``delta_log_evidence`` to every row; True if every evidence that
    was computed is finite (a :data:`NOT_NEEDED` row has none, and no delta)."""
    best_bic = min(r["bic"] for r in rows)
    computed = [r for r in rows if r["evidence_method"] != NOT_NEEDED]
    use_evidence = bool(computed) and all(math.isfinite(r["log_evidence"]) for r in computed)
    best_z = max(r["log_evidence"] for r in computed) if use_evidence else math.nan
    for row in rows:
        row["delta_bic"] = row["bic"] - best_bic
        row["delta_log_evidence"] = row["log_evidence"] - best_z if use_evidence else math.nan
    return use_evidence


def _choose(rows: list[dict[str, Any]], threshold: float, use_evidence: bool,
            accept_understated: bool = False) -> tuple[dict[str, Any], str]:
    """The chosen row and the reason, by the rule of the module docstring."""
    def support(row: Mapping[str, Any]) -> float:
        """The row's evidence (-inf where it was not needed: it cannot change the choice)."""
        if not use_evidence:
            return -0.5 * row["bic"]
        return -math.inf if row["evidence_method"] == NOT_NEEDED else row["log_evidence"]

    undefined = [r["label"] for r in rows if not math.isfinite(r["log_evidence"]) and r["evidence_method"] != NOT_NEEDED]
    criterion = "evidence" if use_evidence else f"BIC (no evidence could be computed for {', '.join(undefined)})"
    pool = [r for r in rows if r["verdict"] in _passing(accept_understated)]
    if not pool:
        best = max(rows, key=support)
        return best, (f"NO candidate passes the goodness-of-fit test; the best by {criterion} is shown, "
                      "but no candidate explains the data")
    best = max(support(r) for r in pool)
    close = [r for r in pool if best - support(r) <= threshold]
    chosen = min(close, key=lambda r: (r["k"], -support(r)))
    failed = len(rows) - len(pool)
    note = f"; {failed} candidate(s) fail the goodness-of-fit test" if failed else ""
    return chosen, (f"fewest free parameters among the adequate models within {threshold:g} ln-units of the best "
                    f"adequate one by {criterion}{note}")


def compare_loo(results: Mapping[str, Any]):
    """The predictive comparison of MCMC fits by PSIS-LOO (ArviZ ``compare``).

    The expected log pointwise predictive density of each fit estimated by Pareto-smoothed
    importance-sampling leave-one-out cross-validation (Vehtari, Gelman & Gabry 2017),
    ranked, with its standard error, the difference to the best and its standard error, and
    the Pareto k warning. It asks which model predicts a new measurement best, where the
    evidence asks which the data support given the priors; correlated data are left out
    one value at a time with the others' conditional (gonio.fitting.problem).

    Parameters
    ----------
    results : mapping of label to FitResult
        Fits of the same dataset, each with an MCMC chain.

    Returns
    -------
    pandas.DataFrame
        ArviZ's comparison table, best first (columns ``elpd_loo``, ``p_loo``,
        ``elpd_diff``, ``se``, ``dse``, ``warning``, ...).

    References
    ----------
    A. Vehtari, A. Gelman, J. Gabry, "Practical Bayesian model evaluation using leave-one-out
    cross-validation and WAIC", Statistics and Computing 27, 1413 (2017).
    """
    from .diagnostics import arviz

    if len(results) < 2:
        raise ValueError(f"compare_loo needs at least two fits, got {len(results)}")
    missing = [label for label, result in results.items() if result.mcmc is None]
    if missing:
        raise ValueError(f"compare_loo needs MCMC fits; {missing[0]!r} ran without MCMC")
    import warnings

    data = {label: result.inference_data() for label, result in results.items()}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Estimated shape parameter of Pareto", category=UserWarning)
        warnings.filterwarnings("ignore", message="The inplace keyword")  # ArviZ's use of pandas
        return arviz().compare(data, ic="loo")  # the table's 'warning' column says it


def loo_summary(table) -> str:
    """A plain-text form of :func:`compare_loo`'s table."""
    lines = [f"{'model':<34} {'elpd_loo':>10} {'SE':>7} {'p_loo':>7} {'d_elpd':>8} {'dSE':>7}  Pareto k",
             "-" * 86]
    for label, row in table.iterrows():
        warning = "k > 0.7 for some values" if bool(row["warning"]) else "ok"
        lines.append(f"{label:<34} {row['elpd_loo']:>10.2f} {row['se']:>7.2f} {row['p_loo']:>7.2f} "
                     f"{row['elpd_diff']:>8.2f} {row['dse']:>7.2f}  {warning}")
    return "\n".join(lines)
