"""Parameter recovery on the emulated rig: the demo path, and the calibration of its intervals."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from gonio import acquisition, protocols
from gonio.cli import main
from gonio.cli.demo import TRUTH
from gonio.cli.run import emulated_rig
from gonio.fitting import fit

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_gonio_demo_chooses_an_adequate_model_and_states_its_bias(tmp_path, capsys):
    """The README's main job: Figs 16 and 19 measured on the emulated wall plaster, the
    exact V-cavity model (sigma = 30 deg, rho = 0.9), on a real lab's rig (the default
    realism): the fits take the rig's errors as parameters. The paper's approximation (eq
    33-35) is flagged inadequate, the chosen model passes the goodness-of-fit test, and
    every truth is inside its 95 % interval or flagged with its bias."""
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--quiet"]) == 0  # converged and adequate
    printed = capsys.readouterr().out
    assert "report:" in printed and "truth inside" in printed
    comparison = json.loads((out / "fit" / "comparison.json").read_text())
    rows = {row["label"]: row for row in comparison["rows"]}
    assert set(rows) == {"lambert", "oren-nayar-qualitative", "oren-nayar (ir_weight=1)", "oren-nayar-tabulated"}
    assert not rows["oren-nayar (ir_weight=1)"]["adequate"] and not rows["lambert"]["adequate"]
    assert comparison["chosen_adequate"] and rows[comparison["chosen"]]["adequate"]
    assert math.isfinite(rows[comparison["chosen"]]["log_evidence"])
    assert {"tilt_x", "view_offset", "stray_light"} <= set(json.loads((out / "fit" / "result.json").read_text())["free"])
    result = json.loads((out / "fit" / "result.json").read_text())
    assert result["model"] == rows[comparison["chosen"]]["model"]
    assert result["mcmc"]["converged"] is True and result["adequacy"]["adequate"] is True
    assert max(d["r_hat"] for d in result["mcmc"]["diagnostics"].values()) < 1.01
    truth = (out / "fit" / "truth.txt").read_text()
    posterior = result["posterior"]
    for name, value in TRUTH.items():
        inside = posterior["p2_5"][name] <= value <= posterior["p97_5"][name]
        assert inside or f"BIAS: {name}" in truth, (name, posterior["median"][name])
    html = (out / "fit" / "report.html").read_text()
    assert "<img" in html and 'src="fit-' not in html  # figures embedded, not linked
    assert html.index("model adequate") < html.index("What was measured")  # the verdict opens the report
    assert (out / "fit" / "posterior.nc").is_file()
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    assert main(["demo", "--out", str(foreign), "--quiet"]) == 2
    assert (foreign / "notes.txt").read_text() == "keep me"


@pytest.mark.slow
def test_interval_widths_are_calibrated_over_emulator_seeds(tmp_path):
    """Coverage of the uncertainties across independent emulator runs (seeds 1-6).

    The Fig 16 protocol (camera every 10 deg, with the reference standard) is measured at
    six seeds and fitted by least squares with the reduction's stated uncertainties as
    they are (no rescaling by the reduced chi-square, no extra-noise term) and their
    covariance (the PRNU of the nested camera windows). If the intervals are honest,
    z = (fit - truth) / error is standard normal; the rms over the 12 values (6 seeds x
    rho, sigma; the two are strongly correlated, so about 6 independent draws) then lies
    in [0.45, 1.55] with 95 % probability (chi-square with 6 degrees of freedom). The
    window [0.4, 2.0] fails when intervals are several times too narrow (fitting the point
    model instead of the aperture-averaged one gave rms z > 3; ignoring the PRNU
    correlation gave 1.5 over ten seeds) or too wide (a 0.1 % per-point lamp floor gave
    rms z ~ 0.25).
    """
    text = (ROOT / "protocols" / "oren-nayar-fig16-plaster.toml").read_text().replace("step = 5", "step = 10")
    protocol = protocols.loads(text)
    z, redchi = [], []
    for seed in range(1, 7):
        with emulated_rig("oren-nayar:sigma=30,rho=0.9", seed, name=f"coverage-{seed}",
                          realism="ideal") as (rig, emulator, change, meta):
            folder = tmp_path / f"seed-{seed}"
            acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=emulator.control.now,
                                     change_sample=lambda which: change(which, 0.99))
        dataset, _ = acquisition.reduce_recording(folder).fit_inputs()
        least_squares = fit(dataset, "oren-nayar", fixed={"ir_weight": 1.0}, mcmc=False).least_squares
        redchi.append(least_squares.redchi)
        z += [(least_squares.values[n] - t) / least_squares.stderr[n] for n, t in TRUTH.items()]
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.4 < rms < 2.0, (rms, np.round(z, 2))
    # the stated uncertainties are the whole noise: reduced chi-square near 1 (42 dof each,
    # the median of six is within 0.6..1.5 with > 99 % probability)
    assert 0.6 < float(np.median(redchi)) < 1.5, redchi


# ---------------------------------------------------------------------- the output folder
def test_a_new_demo_run_removes_only_what_the_demo_recorded(tmp_path):
    """The marker lists the demo's files; a re-run deletes those (and folders left empty),
    never a file a user put into the output folder."""
    from gonio.cli.demo import MARKER, _prepare_output, demo_paths

    out = _prepare_output(tmp_path / "demo")
    record = json.loads((out / MARKER).read_text())
    files, folders = demo_paths()
    assert (record["files"], record["folders"]) == (files, folders)
    for relative in files:  # what a finished demo leaves
        (out / relative).parent.mkdir(parents=True, exist_ok=True)
        (out / relative).write_text("demo output")
    recording = out / folders[0]
    (recording / "my-notes.txt").write_text("keep me")
    (out / "summary-for-my-thesis.txt").write_text("keep me too")
    assert _prepare_output(out) == out
    remaining = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    assert remaining == sorted([MARKER, "recordings", folders[0], f"{folders[0]}/my-notes.txt",
                                "summary-for-my-thesis.txt"])


def test_an_old_text_marker_stands_for_the_demo_layout(tmp_path):
    from gonio.cli.demo import MARKER, _prepare_output, demo_paths

    out = tmp_path / "demo"
    fit_result = out / "fit-oren-nayar" / "result.json"
    fit_result.parent.mkdir(parents=True)
    fit_result.write_text("{}")
    (out / "fit-oren-nayar" / "mine.txt").write_text("keep")
    (out / MARKER).write_text("output of 'gonio demo'; a new demo run replaces this folder\n")
    _prepare_output(out)
    assert not fit_result.exists() and (out / "fit-oren-nayar" / "mine.txt").read_text() == "keep"
    assert json.loads((out / MARKER).read_text())["files"] == demo_paths()[0]


def test_a_tampered_marker_cannot_reach_outside_the_folder_or_through_links(tmp_path):
    from gonio.cli.demo import MARKER, _prepare_output

    outside = tmp_path / "precious.txt"
    outside.write_text("keep")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "data.csv").write_text("keep")
    out = tmp_path / "demo"
    out.mkdir()
    (out / "linked").symlink_to(elsewhere)
    (out / MARKER).write_text(json.dumps({"files": ["../precious.txt", str(outside), "linked/data.csv"],
                                          "folders": ["..", "linked"]}))
    _prepare_output(out)
    assert outside.read_text() == "keep" and (elsewhere / "data.csv").read_text() == "keep"
    assert (out / "linked").is_symlink()


def test_demo_refuses_a_symlinked_output_folder(tmp_path, capsys):
    target = tmp_path / "real"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    assert main(["demo", "--out", str(tmp_path / "link"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a symbolic link" in err and "Traceback" not in err
    assert not any(target.iterdir())
