"""Three verdicts and one evidence: a wrong model is told from an understated noise by a test
that does not use the size of the stated noise, a comparison still chooses under such noise,
and every candidate is judged by its evidence (docs/fitting.md, "Three verdicts")."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gonio.cli import main
from gonio.fitting import Dataset, compare_models, fit
from gonio.fitting import selection
from gonio.fitting.adequacy import ALPHA, assess
from gonio.fitting.evidence import LaplaceEvidence, laplace_evidence, tempered_evidence
from gonio.fitting.lack_of_fit import lack_of_fit, split_residuals
from gonio.fitting.least_squares import fit_least_squares
from gonio.fitting.mcmc import resolve_priors
from gonio.fitting.problem import FitProblem, predict_quantity
from gonio.fitting.results import EXIT_INADEQUATE, EXIT_NOISE_UNDERSTATED

from .synthetic import in_plane_geometry, synthetic_dataset

GEOMETRY = in_plane_geometry(incidences=(30.0, 45.0, 60.0, 75.0), views=np.arange(-80.0, 81.0, 5.0))
TRUTH = {"rho": 0.9, "sigma": 30.0, "ir_weight": 1.0}


def _understated(model: str = "oren-nayar", stated: float = 0.003, actual: float = 0.006, seed: int = 0) -> Dataset:
    """``model``'s values with relative noise ``actual`` but uncertainties of ``stated``."""
    exact = predict_quantity(model, "brdf", *GEOMETRY, TRUTH if model == "oren-nayar" else
                             {"rho": 0.9, "sigma": 30.0})
    rng = np.random.default_rng(seed)
    return Dataset(*GEOMETRY, exact * (1 + actual * rng.standard_normal(exact.size)), stated * exact,
                   label=f"{model} with understated noise")


def _verdict(data: Dataset, model: str):
    problem = FitProblem(model, data)
    return assess(problem, fit_least_squares(problem))


def test_the_split_is_exact_for_a_linear_model():
    # y = 1 + x^2 seen by a straight line: the lack of fit is the parabola's part outside
    # the line, the rest is zero
    x = np.linspace(-1.0, 1.0, 41)
    residuals = -(x**2 - np.mean(x**2))
    lack, q, pure, dof = split_residuals(residuals, np.c_[np.ones_like(x), x], np.c_[x**2, x**3])
    assert q == 2 and dof == 41 - 2 - 2
    assert lack == pytest.approx(float(residuals @ residuals)) and pure == pytest.approx(0.0, abs=1e-20)


def test_an_understated_noise_is_not_called_a_wrong_model():
    """The true model, its data scattering twice the stated uncertainties: the chi-square
    fails, the lack-of-fit test does not, and the scatter factor is measured."""
    verdict = _verdict(_understated(), "oren-nayar")
    assert verdict.chi2_p < ALPHA
    assert verdict.verdict == "noise understated"
    assert verdict.noise_factor == pytest.approx(2.0, rel=0.15)
    assert verdict.headline().startswith("NOISE UNDERSTATED")


def test_a_wrong_model_is_inadequate_whatever_the_noise():
    """Eq 33-35 fitted to the exact V-cavity model (1 % off at sigma = 30 deg): inadequate with
    the stated noise right and with half of it left out of the budget."""
    for actual in (0.003, 0.006):
        verdict = _verdict(_understated("oren-nayar-exact", actual=actual), "oren-nayar")
        assert verdict.verdict == "inadequate", actual
        assert verdict.lack_of_fit.p < ALPHA
        assert verdict.headline().startswith("MODEL INADEQUATE: the residuals hold structure")


def test_the_lack_of_fit_test_keeps_its_false_alarm_rate():
    """Over 40 seeds of the true model the corrected p-value falls below 0.1 at most about
    a tenth of the time (Bonferroni over the orders makes it conservative), and is not
    stuck at 1 (a test that could not fire)."""
    ps = np.array([lack_of_fit(problem, np.array([fit_least_squares(problem).values[n] for n in problem.free])).p
                   for problem in (FitProblem("oren-nayar", _understated(actual=0.003, seed=seed), {"ir_weight": 1.0})
                                   for seed in range(40))])
    assert np.mean(ps < 0.1) <= 0.2
    assert np.mean(ps < 0.9) >= 0.2


def test_too_few_values_leave_the_two_causes_apart_and_say_so():
    data = _understated()
    small = data.subset(np.arange(data.n) % 12 == 0)  # 12 values: no order leaves room for a test
    verdict = _verdict(small, "oren-nayar")
    assert verdict.lack_of_fit is None
    if verdict.reasons:
        assert verdict.verdict == "inadequate" and "too few values" in verdict.headline()


def test_auto_noise_adds_a_relative_term_only_when_the_noise_is_understated():
    result = fit(_understated(), "oren-nayar", fixed={"ir_weight": 1.0}, jitter="auto", mcmc=False)
    assert result.jitter == "relative" and "rel_jitter" in result.free
    assert result.flags[0].startswith("noise understated") or result.flags[1].startswith("noise understated")
    assert result.least_squares.values["rel_jitter"] == pytest.approx(math.sqrt(0.006**2 - 0.003**2), rel=0.3)
    honest = fit(_understated(actual=0.003), "oren-nayar", fixed={"ir_weight": 1.0}, jitter="auto", mcmc=False)
    assert honest.jitter is None and honest.adequacy.verdict == "adequate"
    wrong = fit(_understated("oren-nayar-exact"), "oren-nayar", fixed={"ir_weight": 1.0}, jitter="auto", mcmc=False)
    assert wrong.jitter is None and wrong.adequacy.verdict == "inadequate"
    assert wrong.exit_code() == EXIT_INADEQUATE


def test_a_comparison_under_understated_noise_still_chooses_the_true_family():
    data = _understated(seed=3)
    plain = compare_models(data, ["lambert", ("oren-nayar", {"ir_weight": 1.0}), "minnaert"], jitter=False)
    assert not any(row["adequate"] for row in plain.rows)
    auto = compare_models(data, ["lambert", ("oren-nayar", {"ir_weight": 1.0}), "minnaert"], jitter="auto")
    assert auto.jitter == "relative" and "extra-noise term" in auto.reason
    assert auto.chosen == "oren-nayar (ir_weight=1)" and auto.chosen_verdict == "noise understated"
    assert auto.row("lambert")["verdict"] == "inadequate"
    saved = auto.to_dict()
    assert saved["chosen_verdict"] == "noise understated" and saved["jitter"] == "relative"
    assert {row["evidence_method"] for row in saved["rows"]} == {"laplace"}


def test_sequential_monte_carlo_agrees_with_laplace_where_both_hold():
    """Where Laplace's approximation holds (a Gaussian posterior well inside its bounds), the
    sampled evidence agrees with it within its stated error plus the estimator's measured
    bias (a few tenths, docs/evidence.md), for a one- and a two-parameter model."""
    data = _understated(actual=0.003)
    for model in ("lambert", "minnaert"):
        problem = FitProblem(model, data)
        ls = fit_least_squares(problem)
        priors = resolve_priors(problem, ls.values, problem.priors_with_defaults(None))
        laplace = laplace_evidence(problem, ls, priors).log_evidence
        sampled = tempered_evidence(problem, priors)
        assert sampled.stages > 3 and 0 < sampled.error < 0.5
        assert sampled.log_evidence == pytest.approx(laplace, abs=3 * sampled.error + 0.5), model


def test_sequential_monte_carlo_follows_a_curved_ridge():
    """Relative radiance without a calibration: rho x scale is a curved ridge along which
    a Gaussian proposal fails; the particles follow it, and the evidence agrees with
    Laplace's product form (gonio.fitting.evidence)."""
    clean = predict_quantity("lambert", "radiance", *GEOMETRY, {"rho": 0.5, "scale": 200.0})
    rng = np.random.default_rng(4)
    data = Dataset(*GEOMETRY, clean * (1 + 0.01 * rng.standard_normal(clean.size)), 0.01 * clean, quantity="radiance")
    problem = FitProblem("lambert", data)
    ls = fit_least_squares(problem)
    priors = resolve_priors(problem, ls.values, problem.priors_with_defaults(None))
    laplace = laplace_evidence(problem, ls, priors).log_evidence
    sampled = tempered_evidence(problem, priors)
    assert sampled.log_evidence == pytest.approx(laplace, abs=3 * sampled.error + 0.5)


def test_a_candidate_without_laplace_evidence_is_judged_by_its_evidence(monkeypatch):
    """Where Laplace's approximation is undefined for a candidate that passes, its evidence
    is sampled and the choice is still by evidence, not by BIC for every row."""
    real = selection.laplace_evidence

    def no_gaussian_for_oren_nayar(problem, least_squares, priors, **kwargs):
        return LaplaceEvidence(math.nan) if problem.base_model.name == "oren-nayar" else real(problem, least_squares,
                                                                                              priors, **kwargs)

    monkeypatch.setattr(selection, "laplace_evidence", no_gaussian_for_oren_nayar)
    data = _understated(actual=0.003)
    comparison = compare_models(data, [("oren-nayar", {"ir_weight": 1.0}), "minnaert"])
    chosen = comparison.row("oren-nayar (ir_weight=1)")
    assert chosen["adequate"]
    assert chosen["evidence_method"] == "sequential monte carlo" and math.isfinite(chosen["log_evidence"])
    assert 0 < chosen["evidence_error"] < 0.5
    assert "BIC" not in comparison.reason and comparison.chosen == "oren-nayar (ir_weight=1)"
    assert "SMC" in comparison.summary()


def test_cli_exit_status_summary_and_json_carry_the_verdict(tmp_path, capsys):
    path = _understated().to_csv(tmp_path / "understated.csv")
    code = main(["fit", str(path), "--model", "oren-nayar", "--fix", "ir_weight=1", "--no-mcmc", "--quiet",
                 "--out", str(tmp_path / "fit")])
    assert code == EXIT_NOISE_UNDERSTATED
    captured = capsys.readouterr()
    assert captured.out.splitlines()[0].startswith("NOISE UNDERSTATED")
    assert "noise understated" in captured.err and "rel_jitter" in captured.out
    saved = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert saved["adequacy"]["verdict"] == "noise understated"
    assert saved["adequacy"]["lack_of_fit"]["p"] >= ALPHA
    assert main(["fit", str(path), "--model", "oren-nayar", "--fix", "ir_weight=1", "--no-mcmc", "--quiet",
                 "--jitter", "none", "--out", str(tmp_path / "plain"), "--report"]) == EXIT_NOISE_UNDERSTATED
    report = (tmp_path / "plain" / "report.html").read_text()
    assert "NOISE UNDERSTATED" in report and "lack-of-fit p-value" in report


def test_every_model_says_what_it_leaves_out():
    from gonio import models
    from gonio.fitting.discrepancy import LEFT_OUT

    assert set(models.available()) <= set(LEFT_OUT), set(models.available()) - set(LEFT_OUT)


def test_the_measured_offsets_are_the_surface_study_s():
    """The statement's numbers are those docs/benchmarks/surfaces.json records (the study
    writes both); a V-cavity fit of the all-bounce V-groove field at sigma = 30 deg is
    quoted with its rho offset."""
    from pathlib import Path

    from gonio.fitting.discrepancy import discrepancy_statement, measured_offsets, offsets_from_study

    study = json.loads((Path(__file__).parents[2] / "docs" / "benchmarks" / "surfaces.json").read_text())
    assert measured_offsets() == offsets_from_study(study)
    row = next(r for r in measured_offsets()["oren-nayar-tabulated"] if r["surface"] == "vgrooves sigma=30")
    statement = discrepancy_statement("oren-nayar-tabulated")
    assert f"rho {row['fitted']['rho']:.3f} (true 0.9, {100 * (row['fitted']['rho'] / 0.9 - 1):+.1f} %)" in statement
    assert statement.startswith("The parameters are effective parameters of oren-nayar-tabulated")
    assert "pits psi=60" not in discrepancy_statement("pitted")  # its own family: no offset to state


def test_summary_json_and_report_state_the_discrepancy(tmp_path):
    from gonio.report.fit_report import write_report

    result = fit(_understated(actual=0.003), "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False)
    assert "discrepancy: The parameters are effective parameters of oren-nayar" in result.summary()
    folder = tmp_path / "fit"
    result.save(folder)
    assert json.loads((folder / "result.json").read_text())["discrepancy"] == result.discrepancy
    write_report(folder)
    assert "Model discrepancy." in (folder / "report.html").read_text()


def test_the_noise_model_spread_vanishes_where_the_model_is_the_data():
    """Noise-free values of the fitted formula: every weighting finds the same parameters (the
    spread is the optimiser's, below 1e-6); a wrong formula's parameters depend on it."""
    from gonio.fitting.noise_models import noise_model_spread

    exact = predict_quantity("oren-nayar", "brdf", *GEOMETRY, TRUTH)
    clean = Dataset(*GEOMETRY, exact, 0.02 * exact)
    spread = noise_model_spread(clean, "oren-nayar", {"ir_weight": 1.0})
    assert set(spread.values) == {"relative", "shot", "absolute"}
    assert spread.half_range["sigma"] < 1e-4 and spread.half_range["rho"] < 1e-6
    other = noise_model_spread(clean, "minnaert")
    assert other.half_range["k"] > 1e-3


def test_a_failing_candidate_without_laplace_evidence_is_not_sampled(monkeypatch):
    """A candidate that fails the goodness-of-fit test cannot be chosen while another
    passes, so where its Laplace evidence is undefined it is not sampled (the lab rig's
    qualitative model took more than twenty minutes of sequential Monte Carlo): its row says
    so, and the choice among the passing ones is still by evidence."""
    real = selection.laplace_evidence

    def no_gaussian_for_lambert(problem, least_squares, priors, **kwargs):
        return LaplaceEvidence(math.nan) if problem.base_model.name == "lambert" else real(problem, least_squares,
                                                                                          priors, **kwargs)

    def never(*args, **kwargs):
        raise AssertionError("a failing candidate's evidence was sampled")

    monkeypatch.setattr(selection, "laplace_evidence", no_gaussian_for_lambert)
    monkeypatch.setattr(selection, "tempered_evidence", never)
    data = _understated(actual=0.003)
    comparison = compare_models(data, ["lambert", ("oren-nayar", {"ir_weight": 1.0})])
    lambert = comparison.row("lambert")
    assert lambert["verdict"] == "inadequate" and lambert["evidence_method"] == "not needed"
    assert math.isnan(lambert["log_evidence"]) and math.isnan(lambert["delta_log_evidence"])
    assert comparison.chosen == "oren-nayar (ir_weight=1)" and "BIC" not in comparison.reason
    assert [row["label"] for row in comparison.rows][-1] == "lambert"  # after the rows with an evidence
    text = comparison.summary()
    assert "not computed" in text and text.splitlines()[2 + 1].split()[-1] == "-"
    assert comparison.to_dict()["rows"][-1]["evidence_method"] == "not needed"


def test_when_no_candidate_passes_every_evidence_is_sampled(monkeypatch):
    """With no candidate adequate the best by evidence is shown, so a failing candidate's
    undefined Laplace evidence is sampled after all."""
    real = selection.laplace_evidence
    sampled = []

    def no_gaussian_for_lambert(problem, least_squares, priors, **kwargs):
        return LaplaceEvidence(math.nan) if problem.base_model.name == "lambert" else real(problem, least_squares,
                                                                                          priors, **kwargs)

    def recorded(problem, priors, *args, **kwargs):
        sampled.append(problem.base_model.name)
        return tempered_evidence(problem, priors, *args, **kwargs)

    monkeypatch.setattr(selection, "laplace_evidence", no_gaussian_for_lambert)
    monkeypatch.setattr(selection, "tempered_evidence", recorded)
    comparison = compare_models(_understated(seed=3), ["lambert", "minnaert"], jitter=False)
    assert not any(row["adequate"] for row in comparison.rows)
    assert sampled == ["lambert"] and comparison.row("lambert")["evidence_method"] == "sequential monte carlo"
    assert "NO candidate passes" in comparison.reason


def test_laplace_evidence_without_profiles_names_what_it_left_out():
    """``profiles=False`` gives the Laplace terms without the shape corrections and names
    the parameters near a bound whose profiles it did not compute; with them, the sigma of
    the Oren-Nayar model fitted to a Lambertian sample (stationary at its bound 0) gets its
    correction."""
    views = np.arange(-80.0, 81.0, 5.0)
    geometry = in_plane_geometry(incidences=(30.0, 60.0), views=views)
    values = predict_quantity("lambert", "brdf", *geometry, {"rho": 0.5})
    data = Dataset(*geometry, values * (1 + 0.003 * np.random.default_rng(1).standard_normal(values.size)),
                   0.003 * values)
    problem = FitProblem("oren-nayar", data, {"ir_weight": 1.0})
    least_squares = fit_least_squares(problem)
    priors = resolve_priors(problem, least_squares.values)
    full = laplace_evidence(problem, least_squares, priors)
    quick = laplace_evidence(problem, least_squares, priors, profiles=False)
    assert "sigma" in full.shape and full.profiles_skipped == ()
    assert quick.profiles_skipped == ("sigma",) and quick.shape == {}
    assert quick.raw == full.raw and quick.truncation == full.truncation


def test_a_failing_candidate_s_profiles_are_computed_only_when_no_candidate_passes(monkeypatch):
    """A failing candidate whose evidence would need profiles (a parameter near a bound) is
    "not needed" while another passes, without one profile fit; when none passes its
    evidence is computed in full, profiles included."""
    from gonio.fitting import evidence

    real = selection.laplace_evidence
    profiled = []

    def lambert_near_a_bound(problem, least_squares, priors, profiles=True):
        terms = real(problem, least_squares, priors, profiles=profiles)
        if problem.base_model.name == "lambert":
            profiled.append(profiles)
            return LaplaceEvidence(terms.raw, terms.truncation, {"rho": -0.5} if profiles else {},
                                   () if profiles else ("rho",))
        return terms

    monkeypatch.setattr(selection, "laplace_evidence", lambert_near_a_bound)
    real_profile = evidence._profile_log_posterior
    forbidden = [True]

    def guarded(*args, **kwargs):
        assert not forbidden[0], "a profile was computed"
        return real_profile(*args, **kwargs)

    monkeypatch.setattr(evidence, "_profile_log_posterior", guarded)
    passing = compare_models(_understated(actual=0.003), ["lambert", ("oren-nayar", {"ir_weight": 1.0})])
    lambert = passing.row("lambert")
    assert lambert["evidence_method"] == "not needed" and math.isnan(lambert["log_evidence"])
    assert profiled == [False] and passing.chosen == "oren-nayar (ir_weight=1)"

    profiled.clear()
    forbidden[0] = False  # with no candidate passing, every evidence is computed in full
    failing = compare_models(_understated(seed=3), ["lambert", "minnaert"], jitter=False)
    assert not any(row["adequate"] for row in failing.rows)
    lambert = failing.row("lambert")
    assert profiled == [False, True] and lambert["evidence_method"] == "laplace"
    assert lambert["log_evidence"] == pytest.approx(lambert["log_evidence_laplace"] + lambert["evidence_truncation"]
                                                    - 0.5)


def test_a_candidate_at_its_nesting_point_in_an_adequate_one_is_not_sampled(monkeypatch):
    """Oren-Nayar + Torrance-Sparrow (kd = 1) on a matte Oren-Nayar sample: its lobe at
    ks = 0, where it is oren-nayar with ir_weight = 1. Where its Laplace evidence is undefined
    (forced here; on the lab rig ks held on 0 leaves sigma_s without effect) it is not
    sampled while the nested candidate is adequate: by the Savage-Dickey ratio its evidence
    is below that one's. The premise holds where both evidences can be computed (this
    sample, the quadrature over sigma_s: 5.6 below), and with the nested candidate absent
    the sum is sampled as before."""
    data = synthetic_dataset_matte()
    candidates = [("oren-nayar", {"ir_weight": 1.0}), ("oren-nayar+torrance-sparrow", {"kd": 1.0, "n": 1.5})]
    computed = compare_models(data, candidates)
    nested, larger = (computed.row(label) for label in ("oren-nayar (ir_weight=1)",
                                                        "oren-nayar+torrance-sparrow (kd=1, n=1.5)"))
    assert larger["log_evidence"] < nested["log_evidence"] - 1.0  # the rule's premise, measured
    sampled = _without_laplace(monkeypatch, "oren-nayar+torrance-sparrow")
    comparison = compare_models(data, candidates)
    row = comparison.row("oren-nayar+torrance-sparrow (kd=1, n=1.5)")
    assert sampled == [] and row["evidence_method"] == "not needed" and row["nested_in"] == "oren-nayar (ir_weight=1)"
    assert comparison.chosen == "oren-nayar (ir_weight=1)" and "BIC" not in comparison.reason
    assert "sits at its nesting point in oren-nayar (ir_weight=1)" in comparison.summary()
    assert comparison.to_dict()["rows"][-1]["nested_in"] == "oren-nayar (ir_weight=1)"
    alone = compare_models(data, [candidates[1], "lambert"])
    assert sampled == ["oren-nayar+torrance-sparrow"]
    assert alone.row(row["label"])["evidence_method"] == "sequential monte carlo"


def _without_laplace(monkeypatch, model: str) -> list[str]:
    """Make ``model``'s Laplace evidence undefined in the comparison; the models whose
    evidence is then sampled (with 300 particles) are recorded in the list returned."""
    real = selection.laplace_evidence
    sampled = []

    def no_gaussian(problem, least_squares, priors, **kwargs):
        return LaplaceEvidence(math.nan) if problem.base_model.name == model else real(
            problem, least_squares, priors, **kwargs)

    def recorded(problem, priors, *args, **kwargs):
        sampled.append(problem.base_model.name)
        return tempered_evidence(problem, priors, *args, particles=300, **kwargs)

    monkeypatch.setattr(selection, "laplace_evidence", no_gaussian)
    monkeypatch.setattr(selection, "tempered_evidence", recorded)
    return sampled


def synthetic_dataset_matte():
    """A matte Oren-Nayar sample (sigma 20 deg, interreflection weight 1), 0.2 % noise."""
    from .synthetic import synthetic_dataset

    return synthetic_dataset("oren-nayar", dict(rho=0.8, sigma=20.0, ir_weight=1.0), 0.002, seed=3)


def test_a_candidate_whose_likelihood_cannot_reach_the_best_evidence_is_not_sampled(monkeypatch):
    """Z = integral of L x prior <= max L: where no candidate passes and the best by evidence
    is shown, a candidate whose Laplace evidence is undefined is not sampled when its maximum
    likelihood is below the best evidence computed (on the lab rig's glossy samples these
    samplings, at reduced chi-squares near 1,000, were most of an 18-minute comparison).
    The bound's premise is measured where the evidence can be computed."""
    data = synthetic_dataset("oren-nayar+torrance-sparrow", dict(rho=0.8, sigma=20.0, ks=0.01, sigma_s=8.0, kd=1.0,
                                                                 n=1.5), 0.002, seed=4)
    candidates = ["lambert", ("oren-nayar", {"ir_weight": 1.0})]
    computed = compare_models(data, candidates)
    assert not any(row["adequate"] for row in computed.rows)
    lambert = computed.row("lambert")
    problem = FitProblem("lambert", data)
    ls = fit_least_squares(problem)
    bound = selection._likelihood_bound(problem, ls, resolve_priors(problem, ls.values, {}))
    assert lambert["log_evidence"] <= bound < computed.row("oren-nayar (ir_weight=1)")["log_evidence"]
    sampled = _without_laplace(monkeypatch, "lambert")
    comparison = compare_models(data, candidates)
    row = comparison.row("lambert")
    assert sampled == [] and row["evidence_method"] == "not needed"
    assert row["evidence_bound"] == pytest.approx(bound, rel=1e-9)
    assert comparison.chosen == computed.chosen and "BIC" not in comparison.reason
    assert "texture_slope" not in comparison.reason  # no rig modelled: no hint of the sample's texture
    assert "its evidence is at most its maximum ln likelihood" in comparison.summary()
    assert comparison.to_dict()["rows"][-1]["evidence_bound"] == pytest.approx(bound, rel=1e-9)


def test_the_likelihood_bound_drops_the_gaussian_priors():
    """Where a Gaussian prior pulled the least squares off the likelihood's maximum, the
    bound is the maximum found again without it: above the posterior mode's likelihood and
    above the evidence."""
    from gonio.fitting import Normal

    data = synthetic_dataset("lambert", {"rho": 0.9}, 0.002, seed=1)
    problem = FitProblem("lambert", data)
    pulled = {"rho": Normal(0.85, 0.001, 0.0, 1.0)}
    ls = fit_least_squares(problem, priors=pulled)
    assert ls.gaussian_priors == ("rho",)
    priors = resolve_priors(problem, ls.values, pulled)
    bound = selection._likelihood_bound(problem, ls, priors)
    free = fit_least_squares(problem).log_likelihood
    assert bound == pytest.approx(free, abs=1e-6) and bound > ls.log_likelihood + 10.0
    assert laplace_evidence(problem, ls, priors).log_evidence < bound


def test_a_comparison_none_passes_on_a_modelled_rig_points_to_the_texture():
    """Where the rig's alignment is modelled and the sample's mesoscale slope is not, a
    comparison that no candidate passes names the parameter that made the lab rig's
    specular sample pass (docs/calibration.md, section 3); not otherwise."""
    hint = selection._texture_hint("all")
    assert "--alignment all,texture_slope" in hint
    assert selection._texture_hint(["tilt_x", "sample_tilt_y"]) == hint
    assert selection._texture_hint("all,texture_slope") == "" and selection._texture_hint(None) == ""
