"""Adaptive runs (gonio.adaptive, gonio run --adaptive; docs/design.md "Adaptive runs") and
the growing recording they rest on (gonio.protocols.extended, run_protocol's extend)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gonio import acquisition, adaptive
from gonio import design as D
from gonio import protocols as P
from gonio.cli import main

PRIORS = {"sigma": (10.0, 45.0), "rho": (0.5, 1.0)}
SAMPLE = "oren-nayar-exact:rho=0.9,sigma=30"
MODEL = "oren-nayar-tabulated"
#: A small starting protocol: the plaster's design at 300 s, reading the standard at the
#: lamp angles a longer design uses too (what an adaptive run may add points at).
REFERENCE_AT = (0.0, 55.0, 75.0, 85.0)


@pytest.fixture(scope="module")
def start_text() -> str:
    return D.design_protocol_text(D.design(MODEL, PRIORS, 300.0, reference_at=REFERENCE_AT))


def _measure(text: str, folder: Path, extend=None, progress=None, resume=False):
    from gonio.cli.run import emulated_rig

    protocol = P.loads(text, source="start.toml")
    with emulated_rig(SAMPLE, 0) as (rig, _, change_sample, metadata):
        return acquisition.run_protocol(protocol, rig, folder, metadata=metadata, extend=extend, progress=progress,
                                        resume=resume, change_sample=lambda which, **how: change_sample(which, 0.99, **how))


# -- a protocol that grows ----------------------------------------------------------------------
def test_an_extended_protocol_keeps_every_point_and_adds_the_new_blocks(start_text):
    base = P.loads(start_text)
    grown = P.extended(base, '# why\n[[block]]\nname = "more"\ntheta_i = 55\nview = [30, 35]\n')
    old, new = P.plan(base).points, P.plan(grown).points
    assert [p.key for p in new[:len(old)]] == [p.key for p in old]  # what is recorded keeps its identity
    assert [(p.theta_i, p.view) for p in new[len(old):]] == [(55.0, 30.0), (55.0, 35.0)]
    assert grown.reference == base.reference and grown.text.startswith(base.text.rstrip("\n"))


@pytest.mark.parametrize("text, words", [
    ("[exposure]\nframes = 3\n", "not valid TOML"),  # a second [exposure]: TOML itself refuses it
    ("[checks]\nevery = 5\n", "changes more than the blocks"),
])
def test_an_extension_that_changes_more_than_the_blocks_is_refused(start_text, text, words):
    with pytest.raises(ValueError, match=words):
        P.extended(P.loads(start_text), text)


def test_a_protocol_with_several_mountings_is_not_extended():
    text = '[protocol]\nname = "m"\n[sample]\nlabel = "s"\nmountings = 2\n[[block]]\ntheta_i = 30\nview = [0]\n'
    with pytest.raises(ValueError, match="mounts the sample 2 times"):
        P.extended(P.loads(text), '[[block]]\ntheta_i = 30\nview = [10]\n')


def test_a_run_measures_what_its_callback_appends_and_records_why(start_text, tmp_path):
    """The callback is asked once the protocol's points are measured; its blocks are
    measured in the same session (no second warm-up, reference or characterisation), and
    every decision is in metadata.json with the protocol the recording now holds."""
    decisions = iter([acquisition.Extension('[[block]]\nname = "extra"\ntheta_i = 55\nview = [30, 35]\n',
                                            {"why": "test"}),
                      acquisition.Extension(None, {"stopped": "enough"})])
    seen = []

    def extend(result: acquisition.RunResult) -> acquisition.Extension:
        seen.append(result.measured)
        return next(decisions)

    result = _measure(start_text, tmp_path / "rec", extend)
    assert result.status == "complete" and len(seen) == 2 and seen[1] == seen[0] + 2
    metadata = json.loads((tmp_path / "rec" / "metadata.json").read_text())
    assert [e["note"] for e in metadata["extensions"]] == [{"why": "test"}, {"stopped": "enough"}]
    grown = P.loads(metadata["protocol"]["text"])
    assert grown.blocks[-1].name == "extra"
    assert metadata["experiment"]["protocol_sha256"] == acquisition.protocol_sha256(grown)
    rows = [json.loads(json.dumps(r)) for r in __import__("gonio").data.read_points(tmp_path / "rec", as_arrays=False)]
    assert sum(r["block"] == "extra" and r["status"] == "ok" for r in rows) == 2
    assert sum(r["block"] == "reference standard" for r in rows) == len(REFERENCE_AT)  # read once


def test_an_interrupted_extension_resumes_with_the_grown_protocol(start_text, tmp_path):
    """Ctrl-C inside an appended block: the recording's protocol is the extended one, and a
    resume with it measures only what is missing."""
    block = '[[block]]\nname = "extra"\ntheta_i = 55\nview = [30, 35, 40]\n'

    def interrupt(progress: acquisition.Progress) -> None:
        if progress.point is not None and progress.point.block == "extra":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _measure(start_text, tmp_path / "rec", lambda result: acquisition.Extension(block), progress=interrupt)
    metadata = json.loads((tmp_path / "rec" / "metadata.json").read_text())
    assert metadata["status"] == "interrupted"
    grown = metadata["protocol"]["text"]
    result = _measure(grown, tmp_path / "rec", lambda result: acquisition.Extension(None, {"stopped": "done"}),
                      resume=True)
    assert result.status == "complete" and result.measured == 2  # the two views the interruption left


# -- choosing the next batch -------------------------------------------------------------------
def _posterior(sigma: float = 30.0, sd: float = 0.5) -> adaptive.Posterior:
    return adaptive.Posterior({"sigma": sigma, "rho": 0.9}, {"sigma": sd, "rho": 0.002},
                              np.diag([sd**2, 0.002**2]), 1.0, 12, {"sigma": sigma, "rho": 0.9}, 0.0025)


def test_a_batch_stays_on_the_standards_lamp_angles_fits_its_time_and_the_rig_accepts_it(start_text):
    protocol = P.loads(start_text)
    settings = adaptive.AdaptiveSettings(MODEL, {"sigma": 0.1}, 900.0, PRIORS)
    points, seconds = adaptive.next_batch(protocol, _posterior(), settings, 60.0)
    assert len(points) > 5 and 0 < seconds <= 60.0
    assert set(points[:, 0].tolist()) <= set(REFERENCE_AT)
    grown = P.extended(protocol, adaptive.batch_text(points, 1, "why"))
    assert P.plan(grown).refused == ()  # the rig's own rule chose the candidates
    assert P.plan(grown).estimated_seconds - P.plan(protocol).estimated_seconds == pytest.approx(seconds)
    common = adaptive.AdaptiveSettings(MODEL, {"sigma": 0.1}, 900.0, PRIORS, calibration="common")
    free, _ = adaptive.next_batch(protocol, _posterior(), common, 60.0)
    assert len(free) > 0  # without a calibration per incidence any lamp angle may be chosen


def test_a_batch_goes_where_the_target_parameter_is_learnt():
    """The criterion is the information about the targets' parameters: at equal time a
    batch chosen for sigma tells more about sigma than one chosen for rho (expected widths,
    Laplace, from the same starting protocol)."""
    protocol = P.loads(D.design_protocol_text(D.design(MODEL, PRIORS, 300.0, reference_at=REFERENCE_AT)))
    measured = [(p.theta_i, p.phi_i, p.view) for p in P.plan(protocol).points]
    widths = {}
    for target in ("sigma", "rho"):
        settings = adaptive.AdaptiveSettings(MODEL, {target: 0.001}, 900.0, PRIORS)
        points, _ = adaptive.next_batch(protocol, _posterior(), settings, 60.0)
        widths[target] = D.expected_widths(MODEL, measured + [tuple(p) for p in points], PRIORS,
                                           at={"sigma": 30.0, "rho": 0.9})
    assert widths["sigma"]["sigma"] < widths["rho"]["sigma"]
    assert widths["rho"]["rho"] <= widths["sigma"]["rho"]


def test_a_fit_that_fails_ends_the_run_saying_why(monkeypatch, start_text, tmp_path):
    """Nothing is lost when the fit fails: the run ends with the reason, the recording whole."""
    def failing(*args, **kwargs):
        raise ValueError("3 values for 16 parameters")

    monkeypatch.setattr(adaptive, "fit_posterior", failing)
    settings = adaptive.AdaptiveSettings(MODEL, {"sigma": 0.1}, 900.0, PRIORS)
    decision = adaptive.AdaptiveRun(tmp_path, P.loads(start_text), settings)(acquisition.RunResult(tmp_path))
    assert decision.text is None
    assert "the fit of the recording so far failed (ValueError: 3 values for 16 parameters)" in decision.note["stopped"]


@pytest.mark.parametrize("changes, words", [
    ({"until": {}}, "at least one target"),
    ({"until": {"kappa": 0.1}}, "not a parameter"),
    ({"until": {"sigma": 0.0}}, "width > 0"),
    ({"until": {"sigma": 0.1}, "priors": {"rho": (0.5, 1.0)}}, "prior range too"),
    ({"budget": -5.0}, "instrument time > 0"),
    ({"batch_seconds": float("nan")}, "batch nan"),
    ({"calibration": "daily"}, "per-incidence"),
    ({"priors": {"sigma": (10.0, 95.0), "rho": (0.5, 1.0)}}, "within the bounds"),
])
def test_bad_adaptive_settings_are_refused_naming_why(changes, words):
    arguments = {"model": MODEL, "until": {"sigma": 0.1}, "budget": 600.0, "priors": PRIORS, **changes}
    with pytest.raises(ValueError, match=words):
        adaptive.AdaptiveSettings(**arguments)


# -- gonio run --adaptive ----------------------------------------------------------------------
def test_gonio_run_adaptive_stops_at_the_target_and_records_why(start_text, tmp_path, capsys):
    """From the 300-s start the plaster's sigma is known to +-1.3 deg; one or two batches of
    60 s take its 95 % width below 0.5 deg (measured: one batch, 0.11 deg)."""
    start = tmp_path / "start.toml"
    start.write_text(start_text)
    out = tmp_path / "rec"
    code = main(["run", str(start), "--out", str(out), "--sample", SAMPLE, "--quiet", "--adaptive",
                 "--model", MODEL, "--prior", "sigma=10:45,rho=0.5:1", "--until", "sigma=0.5", "--budget", "10min"])
    assert code == 0
    metadata = json.loads((out / "metadata.json").read_text())
    last = metadata["extensions"][-1]["note"]
    assert last["stopped"].startswith("target reached: sigma")
    assert last["posterior"]["widths"]["sigma"] <= 0.5
    batches = adaptive.appended_batches(metadata)
    assert batches >= 1 and metadata["adaptive"]["until"] == {"sigma": 0.5}
    grown = P.loads(metadata["protocol"]["text"])
    assert P.plan(grown).estimated_seconds <= 600.0
    assert any(b.name.startswith("adaptive 1: ") for b in grown.blocks)
    assert "# adaptive batch 1:" in metadata["protocol"]["text"]  # from which posterior, and why
    # a plain resume of an adaptive recording is refused; an adaptive one re-decides and stops
    assert main(["run", str(start), "--out", str(out), "--resume", "--quiet", "--sample", SAMPLE]) == 2
    assert "was run adaptively" in capsys.readouterr().err
    assert main(["run", str(start), "--out", str(out), "--resume", "--quiet", "--sample", SAMPLE, "--adaptive",
                 "--model", MODEL, "--prior", "sigma=10:45,rho=0.5:1", "--until", "sigma=0.5",
                 "--budget", "10min"]) == 0
    again = json.loads((out / "metadata.json").read_text())
    assert adaptive.appended_batches(again) == batches and again["extensions"][-1]["note"]["stopped"]


@pytest.mark.parametrize("arguments, words", [
    (["--until", "sigma=0.5"], "options of an adaptive run; add --adaptive"),
    (["--adaptive", "--model", MODEL], "--adaptive needs --until, --budget"),
    (["--adaptive", "--model", MODEL, "--until", "sigma=0.5", "--budget", "soon"], "expected a duration"),
    (["--adaptive", "--model", MODEL, "--until", "kappa=0.5", "--budget", "5min"], "not a parameter"),
    (["--adaptive", "--model", MODEL, "--until", "sigma=0.5", "--budget", "5min", "--prior", "psi=1:2"],
     "not parameters of"),
    (["--adaptive", "--model", "no-such-model", "--until", "sigma=0.5", "--budget", "5min"], "--model no-such-model"),
])
def test_bad_adaptive_command_lines_are_refused(arguments, words, tmp_path, capsys):
    protocol = Path(__file__).resolve().parents[1] / "protocols" / "oren-nayar-fig16-plaster.toml"
    assert main(["run", str(protocol), "--out", str(tmp_path / "rec"), "--quiet"] + arguments) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / "rec").exists()  # nothing started


def test_an_adaptive_run_without_a_standard_needs_a_common_calibration(tmp_path, capsys):
    text = '[protocol]\nname = "x"\n[sample]\nlabel = "s"\n[[block]]\ntheta_i = 30\nview = [0, 20]\n'
    protocol = tmp_path / "plain.toml"
    protocol.write_text(text)
    assert main(["run", str(protocol), "--out", str(tmp_path / "rec"), "--quiet", "--adaptive", "--model", MODEL,
                 "--until", "sigma=0.5", "--budget", "5min"]) == 2
    assert "give --calibration common" in capsys.readouterr().err


def test_a_design_reads_the_standard_where_an_adaptive_run_may_go():
    result = D.design(MODEL, PRIORS, 300.0, reference_at=(70.0, 80.0))
    protocol = P.loads(D.design_protocol_text(result))
    angles = {g[0] for g in protocol.reference.geometries}
    assert {70.0, 80.0} <= angles and {p[0] for p in result.points} <= angles
    with pytest.raises(ValueError, match="reference_at 95 deg"):
        D.design(MODEL, PRIORS, 300.0, reference_at=(95.0,))


def test_gonio_design_refuses_reference_angles_it_cannot_read(tmp_path, capsys):
    for value, words in (("0,fifty", "expected angles in degrees separated by commas"),
                         ("95", "reference_at 95 deg: the rig cannot read the reference standard")):
        assert main(["design", "--model", "lambert", "--prior", "rho=0.2:0.9", "--budget", "5min", "--out",
                     str(tmp_path / "x.toml"), "--reference-at", value]) == 2
        assert words in capsys.readouterr().err
        assert not (tmp_path / "x.toml").exists()
