"""Rendered surfaces as emulated samples: the sample spec, protocol files, gonio run and
gonio demo, and the recordings' resume check."""
from __future__ import annotations

import json

import numpy as np
import pytest

from gonio import acquisition, data, protocols
from gonio.cli import CLIError, main
from gonio.cli import demo
from gonio.cli.run import DEFAULT_SAMPLE, emulated_rig
from gonio.cli.samples import check_sample_spec, parse_sample_spec
from gonio.surfaces.table import EXACT_GRIDS, GRIDS, SurfaceGrid, TabulatedSurface

SMALL = SurfaceGrid(6, 5, 6)
#: A surface sample whose table renders in a fraction of a second (small grid, 100 paths).
GROOVES = "surface:kind=vgrooves,sigma=30,rho=0.9,paths=100"
PROTOCOL = """
[protocol]
name = "surface sample"
[sample]
label = "grooves"
{emulated}
[[block]]
theta_i = 40
view = [-60, -30, 0, 30]
"""


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private table cache, and small grids so that every table renders at once."""
    monkeypatch.setenv("GONIO_TABLE_DIR", str(tmp_path / "tables"))
    for grids in (GRIDS, EXACT_GRIDS):
        for kind in list(grids):
            monkeypatch.setitem(grids, kind, SMALL)
    return tmp_path / "tables"


def _protocol(emulated: str = "") -> protocols.Protocol:
    return protocols.loads(PROTOCOL.format(emulated=emulated), source="surface.toml")


def test_a_surface_spec_is_an_emulated_sample_with_a_lazy_table(cache):
    sample = parse_sample_spec(GROOVES)
    assert sample.model == "surface" and isinstance(sample.brdf, TabulatedSurface)
    assert sample.parameters["kind"] == "vgrooves" and sample.parameters["sigma"] == 30.0
    assert sample.parameters["paths"] == 100 and sample.parameters["bounces"] == "all"
    assert sample.parameters["canonical"] == "surface:kind=vgrooves,sigma=30,rho=0.9,paths=100,seed=0,bounces=all"
    assert not (cache / sample.parameters["table"]).exists()  # parsing renders nothing
    sample.prepare()
    assert (cache / sample.parameters["table"]).is_file()
    value = float(sample.brdf(45.0, 0.0, 30.0, 180.0))
    assert 0.2 < value < 0.3  # oren-nayar-exact gives 0.23 here; a 100-path table is within ~10 %


@pytest.mark.parametrize("spec,message", [
    ("surface:kind=nope", "unknown kind 'nope'"),
    ("surface:kind=vgrooves,sigma=30", "kind vgrooves needs rho"),
    ("surface:kind=vgrooves,sigma=-1,rho=0.5", "sigma [deg] = -1 is outside its valid range [0, 90]"),
    ("surface:kind=vgroove,theta_a=30,phi_a=10,rho=0.5", "an anisotropic surface (a V-groove with phi_a) cannot be"),
])
def test_bad_surface_specs_are_clear_errors(spec, message, capsys):
    with pytest.raises(CLIError) as error:
        parse_sample_spec(spec)
    assert message in str(error.value)
    assert main(["emulator", "--sample", spec]) == 2
    assert message in capsys.readouterr().err


def test_recording_of_a_surface_sample_and_resume_with_another_is_refused(cache, tmp_path):
    protocol = _protocol()
    calls = {"n": 0}

    def stop(progress):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt

    folder = tmp_path / "rec"
    with emulated_rig(GROOVES, 0, name="surface-a") as (rig, emulator, _, meta):
        with pytest.raises(KeyboardInterrupt):
            acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=emulator.control.now,
                                     warm_up=False, progress=stop)
    stored = data.read_metadata(folder)
    assert stored["rig"]["sample"] == GROOVES and stored["rig"]["model"] == "surface"
    assert stored["rig"]["parameters"]["sigma"] == 30.0
    before = (folder / "points.csv").read_bytes()
    other = GROOVES.replace("sigma=30", "sigma=20")
    with emulated_rig(other, 0, name="surface-b") as (rig, emulator, _, meta):
        with pytest.raises(data.RecordingError, match="different experiment.*rig.sample"):
            acquisition.run_protocol(protocol, rig, folder, resume=True, metadata=meta,
                                     clock=emulator.control.now, warm_up=False)
    assert (folder / "points.csv").read_bytes() == before
    with emulated_rig(GROOVES, 0, name="surface-c") as (rig, emulator, _, meta):  # the same: completes
        result = acquisition.run_protocol(protocol, rig, folder, resume=True, metadata=meta,
                                          clock=emulator.control.now, warm_up=False)
    assert result.status == "complete" and result.skipped == 2


def test_protocol_field_sample_emulated_is_validated_naming_file_and_field():
    assert _protocol().emulated is None
    assert _protocol(f'emulated = "{GROOVES}"').emulated == GROOVES
    assert _protocol('emulated = "curet:10"').emulated == "curet:10"  # its data are read when emulated
    for bad, words in (('emulated = "surface:kind=vgrooves,sigma=100,rho=0.5"', "sigma [deg] = 100 is outside"),
                       ('emulated = "no-such-model"', "no-such-model"),
                       ('emulated = ""', "a non-empty string"),
                       ("emulated = 3", "a non-empty string"),
                       ('emulated = "curet:"', "expected curet:NUMBER or curet:NAME")):
        with pytest.raises(protocols.ProtocolError) as error:
            _protocol(bad)
        assert "surface.toml: field 'sample.emulated'" in str(error.value) and words in str(error.value)


def test_gonio_run_mounts_the_protocols_sample_unless_the_command_line_says_otherwise(cache, tmp_path, capsys):
    path = tmp_path / "p.toml"
    path.write_text(PROTOCOL.format(emulated=f'emulated = "{GROOVES}"'))
    assert main(["run", str(path), "--out", str(tmp_path / "a"), "--no-warm-up", "--quiet"]) == 0
    assert data.read_metadata(tmp_path / "a")["rig"]["sample"] == GROOVES
    assert main(["run", str(path), "--out", str(tmp_path / "b"), "--no-warm-up", "--quiet",
                 "--sample", "lambert:rho=0.5"]) == 0
    assert data.read_metadata(tmp_path / "b")["rig"]["sample"] == "lambert:rho=0.5"
    path.write_text(PROTOCOL.format(emulated=""))
    assert main(["run", str(path), "--out", str(tmp_path / "c"), "--no-warm-up", "--quiet"]) == 0
    assert data.read_metadata(tmp_path / "c")["rig"]["sample"] == DEFAULT_SAMPLE
    grooves = data.read_points(tmp_path / "a")["roi_mean"]
    lambert = data.read_points(tmp_path / "b")["roi_mean"]
    assert not np.allclose(grooves, lambert, rtol=0.05)


def test_demo_takes_a_sample_and_keeps_its_default(tmp_path, monkeypatch, capsys):
    args = __import__("gonio.cli", fromlist=["build_parser"]).build_parser().parse_args(["demo"])
    assert args.sample == demo.DEFAULT_SAMPLE == "oren-nayar-exact:rho=0.9,sigma=30"
    assert demo.sample_truth(demo.DEFAULT_SAMPLE) == demo.TRUTH
    assert demo.sample_truth(GROOVES) == {"rho": 0.9, "sigma": 30.0}
    assert demo.sample_truth("surface:kind=pits,psi=60,coverage=0.5,rho=0.8") == {"rho": 0.8}
    # a bad sample fails before the output folder is touched
    assert main(["demo", "--out", str(tmp_path / "demo"), "--sample", "surface:kind=nope"]) == 2
    assert "unknown kind 'nope'" in capsys.readouterr().err and not (tmp_path / "demo").exists()
    # the sample reaches the emulated rig and the recording
    seen = []

    class Stop(Exception):
        pass

    def record(protocol, rig, folder, metadata=None, **options):
        seen.append(metadata["rig"]["sample"])
        raise Stop

    monkeypatch.setattr(acquisition, "run_protocol", record)
    with pytest.raises(Stop):
        demo.measure_demo(tmp_path / "out", sample="lambert:rho=0.5")
    assert seen == ["lambert:rho=0.5"]


def test_truth_table_of_a_surface_sample_names_it():
    class Result:
        model = "oren-nayar-tabulated"

        @staticmethod
        def parameter_rows():
            return [{"name": "rho", "unit": "-", "value": 0.95, "median": 0.95, "p2_5": 0.94, "p97_5": 0.96},
                    {"name": "sigma", "unit": "deg", "value": 29.0, "median": 29.0, "p2_5": 28.0, "p97_5": 31.0}]

    table = demo.truth_table(Result(), demo.sample_truth(GROOVES), GROOVES)
    assert "BIAS: rho is +0.05 from the truth" in table and f"the sample's {GROOVES}" in table
    assert "sigma" in table and "yes" in table
    assert "states no value" in demo.truth_table(Result(), {}, "curet:10")


def test_check_sample_spec_builds_nothing(cache):
    check_sample_spec(GROOVES)
    assert not cache.exists()
    with pytest.raises(ValueError, match="unknown kind"):
        check_sample_spec("surface:kind=x")


def test_recorded_parameters_are_plain_json(cache):
    sample = parse_sample_spec("surface:kind=vgroove,theta_a=30,rho=0.5,paths=100")
    assert json.loads(json.dumps(sample.parameters))["phi_a"] is None
