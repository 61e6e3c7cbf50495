"""Reduction at normal incidence: a lamp read back a hair past the normal (encoder noise
around theta_i = 0) is the direction at |theta_i| and phi_i + 180 deg, a valid geometry."""
from __future__ import annotations

import numpy as np

from gonio import acquisition, data, protocols
from gonio.cli.run import emulated_rig

NORMAL = """
[protocol]
name = "normal-incidence"
[sample]
label = "lambertian"
[reference]
label = "standard"
reflectance = 0.99
geometries = [[30, 0, -10]]
[[block]]
theta_i = 0
phi_i = 180
view = [-70, -50, -30, -15, 15, 30, 50, 70]
"""


def test_lamp_read_back_below_zero_reduces_to_a_valid_direction(tmp_path):
    protocol = protocols.loads(NORMAL, source="normal.toml")
    with emulated_rig("lambert:rho=0.5", 0, name="normal-incidence", realism="ideal") as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=emulator.control.now,
                                 warm_up=False, change_sample=lambda which: change(which, 0.99))
    points = data.read_points(tmp_path / "rec")
    sample_rows = (points["status"] == "ok") & (points["block"] != acquisition.REFERENCE_BLOCK)
    assert np.all(points["stage_lamp_theta"][sample_rows] < 0.0)  # seed 0: the case this test is about
    reduced = acquisition.reduce_recording(tmp_path / "rec")
    assert np.all((reduced.theta_i >= 0.0) & (reduced.theta_i < 0.05))
    brdf = reduced.brdf()  # a Dataset: refuses polar angles outside [0, 90] deg
    # Lambertian 0.5 through a 0.99 standard: rho/pi within 0.5 % (one reference point's noise)
    np.testing.assert_allclose(brdf.value * np.pi, 0.5, rtol=5e-3)


REFERENCE_AT_NORMAL = NORMAL.replace("geometries = [[30, 0, -10]]", "geometries = [[0, 0, -10], [0, 0, 10]]")


def test_a_reference_standard_read_at_normal_incidence_reduces(tmp_path):
    """The standard read at theta_i = 0 (a design measures it at its own incidences) with
    the lamp read back below 0: the reduction divides by its irradiance, not a crash."""
    protocol = protocols.loads(REFERENCE_AT_NORMAL, source="normal.toml")
    with emulated_rig("lambert:rho=0.5", 0, name="normal-reference", realism="ideal") as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=emulator.control.now,
                                 warm_up=False, change_sample=lambda which: change(which, 0.99))
    points = data.read_points(tmp_path / "rec")
    reference_rows = points["block"] == acquisition.REFERENCE_BLOCK
    assert np.any(points["stage_lamp_theta"][reference_rows] < 0.0)  # the case this test is about
    brdf = acquisition.reduce_recording(tmp_path / "rec").brdf()
    np.testing.assert_allclose(brdf.value * np.pi, 0.5, rtol=5e-3)
