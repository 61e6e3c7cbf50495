"""Every field a protocol file may contain changes what is measured (or is refused).

docs/protocols.md lists the fields. For each one a variant of a small protocol is run on
the emulated rig next to the baseline, and the quantity the field controls must differ:
the recorded rows, exposures, dark frames, checks, reference, metadata, instrument time
or (for the fields that only feed the plan's estimate) the estimate. A final test checks
that the table below covers every field the parser knows, so that a new field cannot be
added without saying what it changes.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from gonio import acquisition, data, protocols
from gonio.cli.run import emulated_rig

BASE = """
[protocol]
{head}
[sample]
{sample}
{tables}
[[block]]
{block}
"""
HEAD = 'name = "fields"\ndescription = "every field"'
SAMPLE = 'label = "matte"'
BLOCK = "theta_i = 40\nview = [-30, 10]"
REFERENCE = '[reference]\nlabel = "standard"\nreflectance = 0.99\ngeometries = [[40, 0, -10]]\n'


@dataclass
class Run:
    """What one protocol measured on the emulator."""

    folder: Path
    protocol: protocols.Protocol
    plan: protocols.Plan
    points: dict
    darks: dict
    meta: dict
    instrument_seconds: float

    def rows(self, block: str) -> dict:
        keep = (self.points["status"] == "ok") & (self.points["block"] == block)
        return {k: v[keep] for k, v in self.points.items()}

    def sample_rows(self) -> dict:
        keep = (self.points["status"] == "ok") & ~np.isin(
            self.points["block"], [acquisition.CHECK_BLOCK, acquisition.REFERENCE_BLOCK])
        return {k: v[keep] for k, v in self.points.items()}

    def reduced(self):
        return acquisition.reduce_recording(self.folder)


def protocol_text(head: str = HEAD, sample: str = SAMPLE, tables: str = "", block: str = BLOCK) -> str:
    return BASE.format(head=head, sample=sample, tables=tables, block=block)


def measure(folder: Path, head: str = HEAD, sample: str = SAMPLE, tables: str = "", block: str = BLOCK,
            emulated: str = "oren-nayar:sigma=20,rho=0.8", standard: float = 0.99, **options) -> Run:
    """Run the protocol; the emulated reference standard is a Lambertian of ``standard``
    (whatever the protocol says its reflectance is)."""
    protocol = protocols.loads(protocol_text(head, sample, tables, block), source="fields.toml")
    reflectance = standard
    emulated = protocol.emulated or emulated  # as gonio run chooses (gonio.cli.run.emulated_sample)
    with emulated_rig(emulated, 0, name=f"fields-{folder.parent.name}-{folder.name}", realism="ideal",
                      remount_time=protocol.rig.remount_time) as (rig, emulator, change, meta):
        result = acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=emulator.control.now,
                                          warm_up=False, change_sample=lambda w, **how: change(w, reflectance, **how),
                                          **options)
    return Run(folder, protocol, protocols.plan(protocol), data.read_points(folder), data.read_darks(folder),
               data.read_metadata(folder), result.instrument_seconds)


def _exposures(run: Run) -> list:
    return list(run.sample_rows()["exposure"])


def _status(run: Run) -> list:
    return list(run.points["status"])


#: field -> (changes to the baseline protocol, the quantity the field controls)
CASES: dict[str, tuple[dict, Callable[[Run], Any]]] = {
    "protocol.name": ({"head": 'name = "fields 2"'}, lambda r: r.meta["protocol"]["name"]),
    "protocol.description": ({"head": 'name = "fields"\ndescription = "another"'},
                             lambda r: r.meta["protocol"]["text"]),
    "sample.label": ({"sample": 'label = "other matte"'}, lambda r: r.meta["sample"]["label"]),
    "sample.metadata": ({"sample": 'label = "matte"\n[sample.metadata]\nsupplier = "Labsphere"'},
                        lambda r: r.meta["sample"]["metadata"]),
    "sample.emulated": ({"sample": 'label = "matte"\nemulated = "lambert:rho=0.3"'},
                        lambda r: [round(x, -2) for x in r.sample_rows()["roi_mean"]]),
    "sample.mountings": ({"sample": 'label = "matte"\nmountings = 2'}, lambda r: list(r.sample_rows()["mounting"])),
    "sample.rotations": ({"sample": 'label = "matte"\nrotations = [0, 90]'},
                         lambda r: list(np.nan_to_num(r.sample_rows()["rotation"], nan=-1.0))),
    "sample.spin": ({"sample": 'label = "matte"\nspin = true'}, lambda r: r.meta["mountings"]["0"]["spin"]),
    "rig.camera_range": ({"tables": "[rig]\ncamera_range = [-20, 20]"}, _status),
    "rig.lamp_theta_range": ({"tables": "[rig]\nlamp_theta_range = [0, 30]"}, _status),
    "rig.lamp_phi_range": ({"tables": "[rig]\nlamp_phi_range = [-10, 10]", "block": BLOCK + "\nphi_i = 30"}, _status),
    "rig.min_separation": ({"tables": "[rig]\nmin_separation = 40", "block": BLOCK.replace("[-30, 10]", "[-30, 10, 75]")},
                           _status),
    "rig.velocity": ({"tables": "[rig]\nvelocity = 2"}, lambda r: round(r.instrument_seconds)),
    "rig.acceleration": ({"tables": "[rig]\nacceleration = 1"}, lambda r: round(r.instrument_seconds)),
    "rig.settle_time": ({"tables": "[rig]\nsettle_time = 5"}, lambda r: round(r.instrument_seconds)),
    # an estimate of the plan only: the camera's readout is the camera's (docs/protocols.md)
    "rig.readout_time": ({"tables": "[rig]\nreadout_time = 1"}, lambda r: round(r.plan.estimated_seconds)),
    # the operator's time to swap the sample for the reference standard and back
    "rig.remount_time": ({"tables": REFERENCE}, lambda r: round(r.instrument_seconds)),
    "exposure.mode": ({"tables": '[exposure]\nmode = "fixed"\ntime = 0.01'}, _exposures),
    "exposure.time": ({"tables": '[exposure]\nmode = "fixed"\ntime = 0.015'}, _exposures),
    "exposure.brackets": ({"tables": '[exposure]\nmode = "hdr"\nbrackets = [0.004, 0.008]'}, _exposures),
    "exposure.target_fraction": ({"tables": "[exposure]\ntarget_fraction = 0.2"},
                                 lambda r: [round(x, -2) for x in r.sample_rows()["roi_mean"]]),
    "exposure.max_time": ({"tables": "[exposure]\nmax_time = 0.01"}, _exposures),
    "exposure.frames": ({"tables": "[exposure]\nframes = 3"}, lambda r: list(r.sample_rows()["frames"])),
    "darks.at_start": ({"tables": "[darks]\nat_start = false"}, lambda r: len(r.darks["exposure"])),
    "darks.every": ({"tables": "[darks]\nevery = 1"}, lambda r: len(r.darks["exposure"])),
    "reference.label": ({"tables": REFERENCE}, lambda r: r.meta["protocol"]["text"]),
    "reference.reflectance": ({"tables": REFERENCE}, lambda r: round(r.reduced().reference_irradiance, -3)),
    "reference.geometries": ({"tables": REFERENCE}, lambda r: len(r.rows(acquisition.REFERENCE_BLOCK)["index"])),
    "reference.reflectance_uncertainty": ({"tables": REFERENCE}, lambda r: r.reduced().calibration["certificate"]),
    "reference.angular_uncertainty": ({"tables": REFERENCE}, lambda r: r.reduced().calibration["angular behaviour"]),
    "checks.every": ({"tables": "[checks]\nevery = 1"}, lambda r: len(r.rows(acquisition.CHECK_BLOCK)["index"])),
    "checks.geometry": ({"tables": "[checks]\nevery = 1\ngeometry = [30, 0, 0]"},
                        lambda r: sorted(set(r.rows(acquisition.CHECK_BLOCK)["theta_i"]))),
    "checks.frames": ({"tables": "[checks]\nevery = 1\nframes = 3"},
                      lambda r: list(r.rows(acquisition.CHECK_BLOCK)["frames"])),
    "block.name": ({"block": 'name = "my block"\n' + BLOCK}, lambda r: sorted(set(r.points["block"]))),
    "block.theta_i": ({"block": BLOCK.replace("40", "25")}, lambda r: sorted(set(r.points["theta_i"]))),
    "block.phi_i": ({"block": BLOCK + "\nphi_i = 60"}, lambda r: sorted(set(r.points["stage_lamp_phi"].round(1)))),
    "block.view": ({"block": BLOCK.replace("[-30, 10]", "[-50, 0]")}, lambda r: sorted(set(r.points["view"]))),
    "block.repeats": ({"block": BLOCK + "\nrepeats = 2"}, lambda r: len(r.points["index"])),
    "block.geometries": ({"block": "geometries = [[40, 0, 30, 180], [40, 0, 10, 90]]"},
                         lambda r: sorted(zip(r.points["phi_i"], r.points["view"]))),
}
#: The reference fields are compared with a baseline that has the [reference] table; the
#: variant changes the one field.
REFERENCE_VARIANTS = {
    "reference.label": REFERENCE.replace('"standard"', '"diffuse standard"'),
    "reference.reflectance": REFERENCE.replace("0.99", "0.5"),
    "reference.geometries": REFERENCE.replace("[[40, 0, -10]]", "[[40, 0, -10], [30, 0, 0]]"),
    "reference.reflectance_uncertainty": REFERENCE + "reflectance_uncertainty = 0.01\n",
    "reference.angular_uncertainty": REFERENCE + "angular_uncertainty = 0.01\n",
    "rig.remount_time": REFERENCE + "[rig]\nremount_time = 5\n",
}


@pytest.fixture(scope="module")
def baseline(tmp_path_factory) -> Run:
    return measure(tmp_path_factory.mktemp("baseline") / "rec")


@pytest.mark.parametrize("field", sorted(CASES))
def test_each_protocol_field_changes_what_is_measured(tmp_path, baseline, field):
    changes, quantity = CASES[field]
    if field in REFERENCE_VARIANTS:
        base = measure(tmp_path / "base", **changes)
        changes = {"tables": REFERENCE_VARIANTS[field]}
    else:
        base = baseline
    variant = measure(tmp_path / "variant", **changes)
    assert quantity(variant) != quantity(base), field


def test_exposure_max_time_caps_the_automatic_exposure(tmp_path):
    """The issue's case: at low lamp voltage the automatic exposure reached 10 s against a
    max_time of 5 s; now it stops at max_time and the point is kept (a weak signal is data)."""
    run = measure(tmp_path / "rec", tables="[exposure]\nmax_time = 0.02", emulated="lambert:rho=0.05", lamp_voltage=60.0)
    rows = run.sample_rows()
    assert len(rows["exposure"]) == 2 and np.all(rows["exposure"] <= 0.02)


def test_apertures_that_contradict_the_rig_are_refused(tmp_path):
    protocol = protocols.loads(protocol_text(tables="[rig]\nlamp_solid_angle = 0.01"), source="f.toml")
    with emulated_rig("lambert:rho=0.5", 0, name="fields-aperture") as (rig, emulator, _, meta):
        with pytest.raises(acquisition.AcquisitionError, match="rig.lamp_solid_angle.*0.003"):
            acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=emulator.control.now)
    assert not (tmp_path / "rec").exists()


def test_apertures_of_the_protocol_are_used_when_the_rig_reports_none(tmp_path):
    run = measure(tmp_path / "rec")
    meta = data.read_metadata(tmp_path / "rec")
    meta["rig"].pop("aperture_sr")  # as a real rig records it
    text = meta["protocol"]["text"].replace("[sample]", "[rig]\nlamp_solid_angle = 0.002\n[sample]")
    meta["protocol"]["text"] = text
    (tmp_path / "rec" / "metadata.json").write_text(__import__("json").dumps(meta))
    assert acquisition.reduce_recording(tmp_path / "rec").metadata["aperture_sr"] == [0.002, 0.0009]
    assert run.meta["rig"]["aperture_sr"] == [0.003, 0.0009]


def test_the_table_covers_every_field_the_parser_knows():
    known = {f"protocol.{k}" for k in ("name", "description")} | {f"sample.{k}" for k in (
        "label", "metadata", "emulated", "mountings", "rotations", "spin")}
    for section, cls in (("rig", protocols.RigLimits), ("exposure", protocols.Exposure), ("darks", protocols.Darks),
                         ("checks", protocols.Checks), ("block", protocols.Block)):
        known |= {f"{section}.{f.name}" for f in dataclasses.fields(cls)}
    known |= {f"reference.{f.name}" for f in dataclasses.fields(protocols.Reference)}
    known = (known - {"block.views"}) | {"block.view", "block.geometries"}  # the TOML keys
    known -= {"rig.lamp_solid_angle", "rig.camera_solid_angle"}  # the two aperture tests above
    assert known - set(CASES) == set()
