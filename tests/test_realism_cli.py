"""``--realism`` of gonio run / emulator / demo: the emulated rig's systematic errors from the
command line, recorded with the recording (docs/emulator.md "Systematic errors",
docs/data-format.md)."""
from __future__ import annotations

import numpy as np
import pytest

from drivers.emulator.systematics import realism
from gonio import data
from gonio.cli import build_parser, main
from gonio.cli.emulator import build_rig

SMALL = """
[protocol]
name = "small"
[sample]
label = "test sample"
[[block]]
theta_i = 40
view = [-60, -20, 0, 20]
"""


def test_gonio_run_records_the_realism_and_reads_back_the_planned_geometry(tmp_path, capsys):
    protocol = tmp_path / "small.toml"
    protocol.write_text(SMALL)
    out = tmp_path / "rec"
    assert main(["run", str(protocol), "--out", str(out), "--seed", "4", "--realism", "lab:stray_light=0",
                 "--quiet", "--no-warm-up"]) == 0
    meta = data.read_metadata(out)
    expected = {"spec": "lab:stray_light=0", **realism("lab:stray_light=0", 4).to_dict()}
    assert meta["rig"]["realism"] == expected
    assert meta["experiment"]["rig"]["realism"] == expected  # part of what a resume must match
    points = data.read_points(out)
    ok = points["status"] == "ok"
    # The encoders read back where the stage was sent; the offsets are invisible to them.
    assert np.all(np.abs(points["stage_camera"][ok] - points["view"][ok]) < 0.01)


def test_the_default_realism_is_a_real_labs_rig():
    args = build_parser().parse_args(["run", "x.toml", "--out", "y"])
    assert args.realism == "lab"
    assert build_parser().parse_args(["demo"]).realism == "lab"
    assert build_parser().parse_args(["demo", "--realism", "ideal"]).realism == "ideal"
    args = build_parser().parse_args(["emulator", "--seed", "2", "--no-pty"])
    assert build_rig(args).systematics == realism("lab", 2)


def test_the_idealised_rig_says_so(tmp_path, capsys):
    protocol = tmp_path / "small.toml"
    protocol.write_text(SMALL)
    assert main(["run", str(protocol), "--out", str(tmp_path / "ideal"), "--realism", "ideal", "--quiet",
                 "--no-warm-up"]) == 0
    assert "IDEALISED" in capsys.readouterr().out
    assert main(["run", str(protocol), "--out", str(tmp_path / "lab"), "--quiet", "--no-warm-up"]) == 0
    assert "IDEALISED" not in capsys.readouterr().out


@pytest.mark.parametrize("spec, words", [("field", "unknown preset 'field'"),
                                         ("lab:tilt=1", "'tilt=1' is not NAME=VALUE"),
                                         ("lab:nonlinearity=0.9", "nonlinearity=0.9: expected a fraction")])
def test_a_bad_realism_is_a_one_line_error(tmp_path, capsys, spec, words):
    protocol = tmp_path / "small.toml"
    protocol.write_text(SMALL)
    assert main(["run", str(protocol), "--out", str(tmp_path / "rec"), "--realism", spec, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--realism" in err and words in err and "Traceback" not in err
    assert not (tmp_path / "rec").exists()


def test_the_demo_blames_a_bias_on_the_model_with_the_rig_errors_it_fitted():
    from types import SimpleNamespace

    from gonio.cli.demo import truth_table

    rows = [{"name": "rho", "unit": "-", "value": 0.91, "median": 0.91, "p2_5": 0.905, "p97_5": 0.915},
            {"name": "sigma", "unit": "deg", "value": 30.0, "median": 30.0, "p2_5": 29.9, "p97_5": 30.1}]
    result = SimpleNamespace(model="oren-nayar-tabulated", parameter_rows=lambda: rows)
    assert "does not reproduce the sample's" in truth_table(result, realism="ideal")
    assert "rig's errors as parameters" not in truth_table(result, realism="ideal")
    # only the sample's texture and the monitor's mismatch: nothing for the fit to model
    quiet = ("lab:view_offset=0,theta_i_offset=0,phi_i_offset=0,tilt_x=0,tilt_y=0,stray_light=0,nonlinearity=0,"
             "beam_falloff=0,wedge=0,mount_tilt=0")
    assert "rig's errors as parameters" not in truth_table(result, realism=quiet)
    text = truth_table(result, realism="lab")
    assert "BIAS: rho" in text and "BIAS: sigma" not in text
    assert "with the rig's errors as parameters (--realism lab) does not reproduce the sample's" in text
