"""Mountings of the sample and the noise sources of a real lab's rig, from protocol to budget.

A protocol asks for several mountings (``[sample] mountings``, ``rotations``, ``spin``);
the plan and its time estimate include them; every row records its mounting; each
mounting's texture image and monitor series are recorded; and each of the lab rig's new
noise sources, switched on alone, is found in its own budget component at the size the
emulator gives it (docs/emulator.md "The sample as labs meet it", docs/acquisition.md
"Mountings").
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from gonio import acquisition, data, protocols, reduction
from gonio.cli.run import emulated_rig

BASE = """
[protocol]
name = "mountings"
[sample]
label = "plaster"
{sample}
[[block]]
theta_i = {theta_i}
phi_i = 0
view = {views}
repeats = {repeats}
"""


def _text(sample: str = "", theta_i: float = 45, views: str = "[-40, -20, 0, 20]", repeats: int = 1) -> str:
    return BASE.format(sample=sample, theta_i=theta_i, views=views, repeats=repeats)


def _run(folder, text, realism, seed=0, sample="oren-nayar:sigma=30,rho=0.9"):
    protocol = protocols.loads(text, source=f"{folder.name}.toml")
    with emulated_rig(sample, seed, name=f"mountings-{folder.name}", realism=realism,
                      remount_time=protocol.rig.remount_time) as (rig, emulator, change, meta):
        acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=emulator.control.now, warm_up=False,
                                 change_sample=lambda which, **how: change(which, 0.99, **how))
    return folder


# ----------------------------------------------------------------------------- the protocol
def test_mountings_rotations_and_spin_are_read_and_planned():
    p = protocols.loads(_text("mountings = 3\nspin = true"))
    assert p.mountings == protocols.Mountings(3, (None, None, None), True)
    plan = protocols.plan(p)
    assert len(plan.points) == 12 and [pt.mounting for pt in plan.points] == [0] * 4 + [1] * 4 + [2] * 4
    assert len({pt.key for pt in plan.points}) == 12 and [pt.index for pt in plan.points] == list(range(12))
    assert "mountings of the sample: 3" in plan.summary() and "spinning" in plan.summary()
    rotated = protocols.loads(_text("rotations = [0, 90, 180, 270]"))
    assert rotated.mountings.count == 4 and rotated.mountings.rotations == (0.0, 90.0, 180.0, 270.0)
    single = protocols.plan(protocols.loads(_text()))
    # two more mountings: two remounts (60 s each) and two more texture images and sweeps
    assert plan.estimated_seconds - single.estimated_seconds > 2 * 60 + 2 * protocols.TEXTURE_IMAGE_SECONDS
    assert not protocols.loads(_text()).mountings.declared


@pytest.mark.parametrize("sample, field, expected", [
    ("mountings = 0", "sample.mountings", "an integer in [1, 100]"),
    ("mountings = 101", "sample.mountings", "the limit on mountings"),
    ("mountings = 2.5", "sample.mountings", "an integer"),
    ("rotations = []", "sample.rotations", "a non-empty list of rotations"),
    ("rotations = [0, 400]", "sample.rotations[1]", "in [-360, 360]"),
    ("mountings = 3\nrotations = [0, 90]", "sample.mountings", "the number of sample.rotations (2)"),
    ("spin = 1", "sample.spin", "true or false"),
    ("mounting = 2", "sample.mounting", "did you mean 'mountings'"),
])
def test_bad_mounting_fields_are_named(sample, field, expected):
    with pytest.raises(protocols.ProtocolError) as info:
        protocols.loads(_text(sample), source="m.toml")
    assert f"'{field}'" in str(info.value) and expected in str(info.value) and "m.toml" in str(info.value)


def test_a_protocol_with_mountings_needs_a_way_to_mount_the_sample(tmp_path):
    protocol = protocols.loads(_text("mountings = 2"))
    with emulated_rig("lambert:rho=0.5", 0, name="no-mount", realism="ideal") as (rig, emulator, _, meta):
        with pytest.raises(acquisition.AcquisitionError, match="no way to mount it"):
            acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=emulator.control.now)


# ----------------------------------------------------------------------------- the recording
@pytest.fixture(scope="module")
def remounted(tmp_path_factory):
    """The lab rig, two rotations and spinning off, two readings per geometry."""
    return _run(tmp_path_factory.mktemp("remounted") / "rec", _text("rotations = [0, 90]", repeats=2), "lab", seed=3)


def test_every_row_records_its_mounting_and_every_mounting_its_image_and_series(remounted):
    points = data.read_points(remounted)
    sample = points["block"] == "theta_i=45"
    assert sorted(set(points["mounting"][sample])) == [0, 1]
    assert sorted(set(points["rotation"][sample])) == [0.0, 90.0]
    meta = data.read_metadata(remounted)
    assert sorted(meta["mountings"]) == ["0", "1"]
    for record in meta["mountings"].values():
        assert record["rotation"] in (0.0, 90.0) and record["spin"] is False
        assert 1e-3 < record["texture_relative"] < 6e-3  # the lab texture's window mean, 0.2-0.35 %
        assert 3 < record["correlation_lengths_px"][1] < 8  # 1 mm over 0.18 mm pixels: 5.5
        assert len(record["monitor_series"]["monitor"]) == acquisition.RATIO_SERIES


def test_resume_continues_in_the_mounting_it_stopped_in(tmp_path):
    """Interrupted in the second mounting, a resume records the rest once, in that mounting,
    and does not image the first mounting again."""
    text = _text("mountings = 2")
    protocol = protocols.loads(text, source="resume.toml")
    calls = {"n": 0}

    def stop(_):
        calls["n"] += 1
        if calls["n"] == 6:
            raise KeyboardInterrupt

    folder = tmp_path / "rec"
    for attempt in range(2):
        with emulated_rig("lambert:rho=0.5", 1, name=f"resume-mount-{attempt}") as (rig, emulator, change, meta):
            run = lambda **kw: acquisition.run_protocol(  # noqa: E731
                protocol, rig, folder, metadata=meta, clock=emulator.control.now, warm_up=False,
                change_sample=lambda which, **how: change(which, 0.99, **how), **kw)
            if attempt == 0:
                with pytest.raises(KeyboardInterrupt):
                    run(progress=stop)
            else:
                run(resume=True)
    points = data.read_points(folder)
    keys = [(m, v) for m, v, s in zip(points["mounting"], points["view"], points["status"]) if s == "ok"]
    assert sorted(keys) == sorted((m, v) for m in (0, 1) for v in (-40.0, -20.0, 0.0, 20.0))
    assert sorted(data.read_metadata(folder)["mountings"]) == ["0", "1"]


# ----------------------------------------------------------------------------- one source at a time
def test_monitor_mismatch_alone_is_the_monitor_ratio_term_and_the_repeats_scatter(tmp_path):
    """Only the monitor's mismatch (1e-3, twice the lab's): the monitor series measures it
    (47 degrees of freedom: to 10 %), and 30 repeats scatter by the budget."""
    folder = _run(tmp_path / "rec", _text(views="[-20]", repeats=30), "ideal:monitor_mismatch=0.001")
    reduced = reduction.reduce_recording(folder)
    measured = reduced.consistency["monitor_ratio_relative"]
    assert measured == pytest.approx(1e-3, rel=0.3)  # 3 sigma of a 47-dof estimate
    per_reading = reduced.budget["monitor_ratio"] * math.sqrt(reduced.repeats[0]) / abs(reduced.radiance[0])
    assert per_reading == pytest.approx(measured, rel=1e-3)  # |weighted mean| against mean |value|
    ratios = [s["observed_std"] / s["stated_std"] for s in reduced.repeat_statistics]
    assert all(0.45 < r < 1.75 for r in ratios), ratios
    assert "texture" in reduced.budget and reduced.consistency["texture_relative"] == 0.0  # no texture: none found


def test_texture_alone_is_the_texture_term_common_to_every_value(tmp_path):
    """Only the sample's albedo texture (3 %): the image states 0.15-0.5 % for the window's
    mean, the same fraction of every value, and the covariance holds it as one error."""
    folder = _run(tmp_path / "rec", _text(), "ideal:texture_albedo=0.03")
    reduced = reduction.reduce_recording(folder)
    relative = reduced.budget["texture"] / np.abs(reduced.radiance)
    assert np.allclose(relative, relative[0]) and 1.5e-3 < relative[0] < 5e-3
    covariance = reduced.covariance()
    correlation = covariance / np.sqrt(np.outer(np.diag(covariance), np.diag(covariance)))
    assert np.all(correlation > 0.9)  # the texture dominates every value's budget
    assert reduced.budget["monitor_ratio"].max() == 0.0 or reduced.consistency["monitor_ratio_relative"] < 2e-4


def test_slope_texture_alone_is_the_texture_term_growing_with_the_slope(tmp_path):
    """Only the sample's mesoscale slope: each pixel sees its facets' radiance, which the
    image's spatial statistics state as the texture term, to first order proportional to
    the slope (0.3 deg, the lab's, against 1 deg); nothing else is found."""
    found = {}
    for slope in (0.3, 1.0):
        reduced = reduction.reduce_recording(_run(tmp_path / f"rec{slope}", _text(), f"ideal:texture_slope={slope}"))
        relative = reduced.budget["texture"] / np.abs(reduced.radiance)
        assert np.allclose(relative, relative[0]) and relative[0] > 0
        assert reduced.consistency["monitor_ratio_relative"] < 2e-4
        found[slope] = relative[0]
    assert 2.5 < found[1.0] / found[0.3] < 4.5  # 1 / 0.3 = 3.3


def test_mount_tilt_alone_is_the_mounting_term_with_its_correlation(tmp_path):
    """Only the seating's tilt (0.2 deg, four times the lab's), six mountings: the values
    change between mountings as a tilt changes them (up on one side of the normal, down on
    the other); the mounting term states it, its factors correlate the values as the
    tilt does, and a single mounting's recording says it is not measured."""
    text = _text("mountings = 6", theta_i=60, views="[-60, -40, -20, 20, 40]")
    folder = _run(tmp_path / "rec", text, "ideal:mount_tilt=0.2", seed=2)
    reduced = reduction.reduce_recording(folder)
    relative = reduced.budget["mounting"] / np.abs(reduced.radiance)
    # d ln L / d tilt ~ tan(60) = 1.7 per rad: 0.2 deg is 6e-3 per mounting, /sqrt(6)
    assert np.all(relative > 5e-4) and np.all(relative < 6e-3)
    factors = reduced.mounting_factors
    assert factors is not None and factors.shape[0] == len(reduced.radiance)
    assert np.allclose(np.sqrt(np.sum(factors**2, axis=1)), reduced.budget["mounting"])
    covariance = reduced.covariance()
    assert np.linalg.eigvalsh(covariance).min() > 0
    single = reduction.reduce_recording(_run(tmp_path / "one", _text(), "ideal:mount_tilt=0.2"))
    assert "mounting" not in single.budget
    assert any("mounted once" in w and "mountings = 4" in w for w in single.warnings)


def test_joined_recordings_keep_each_ones_mounting_factors(tmp_path):
    text = _text("mountings = 3", views="[-30, 0, 30]")
    first = reduction.reduce_recording(_run(tmp_path / "a", text, "ideal:mount_tilt=0.1", seed=4))
    second = reduction.reduce_recording(_run(tmp_path / "b", text, "ideal:mount_tilt=0.1", seed=5))
    joined = reduction.combine_reduced([first, second])
    n = len(first.radiance)
    f = joined.mounting_factors
    assert f.shape == (n + len(second.radiance), first.mounting_factors.shape[1] + second.mounting_factors.shape[1])
    assert np.all(f[:n, first.mounting_factors.shape[1]:] == 0) and np.all(f[n:, :first.mounting_factors.shape[1]] == 0)
    assert np.allclose(joined.covariance()[:n, :n], first.covariance())


def test_wedge_alone_turns_with_the_sample_and_spinning_averages_it(tmp_path):
    """Only the sample's wedge (0.5 deg): rotated by quarter turns it tilts the sample
    another way in each mounting, which the mounting term states; spun during the
    exposures, the four mountings agree to their noise and the term is (nearly) gone."""
    text = _text("rotations = [0, 90, 180, 270]", theta_i=60, views="[-40, -20, 20]")
    rotated = reduction.reduce_recording(_run(tmp_path / "rotated", text, "ideal:wedge=0.5", seed=6))
    wedge = rotated.budget["mounting"] / np.abs(rotated.radiance)
    # d ln L / d tilt ~ tan(60) = 1.7 per rad: 0.5 deg is 1.5 % in one mounting, /sqrt(4)
    assert np.all(wedge > 2e-3)
    spun = reduction.reduce_recording(_run(tmp_path / "spun", _text("mountings = 4\nspin = true", theta_i=60,
                                                                       views="[-40, -20, 20]"), "ideal:wedge=0.5",
                                           seed=6))
    assert np.all(spun.budget["mounting"] / np.abs(spun.radiance) < 0.05 * wedge)
