"""Sweep protocol parsing, validation and dry-run planning (gonio.protocols, gonio plan)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio import protocols as P
from gonio.cli import main

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted((ROOT / "protocols").glob("*.toml"))

MINIMAL = """
[protocol]
name = "t"
[sample]
label = "s"
[[block]]
theta_i = 45
view = [-60, 0, 30]
"""


def test_every_shipped_protocol_loads_and_plans():
    assert len(SHIPPED) >= 8
    for path in SHIPPED:
        plan = P.plan(P.load(path))
        assert plan.points, path
        assert plan.estimated_seconds > 0


def test_fig16_plan_counts_and_refusals():
    """Fig 16: theta_i = 30, 45, 60 deg, views -80..80 step 5 (33 each); the rig refuses
    the retro-reflection views (camera on the lamp) and those exactly at the 5 deg minimum
    separation, where the controller's own check may go either way."""
    plan = P.plan(P.load(ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"))
    assert len(plan.points) + len(plan.refused) == 3 * 33
    assert sorted((r.point.theta_i, r.point.view) for r in plan.refused) == [
        (30, 25), (30, 30), (30, 35), (45, 40), (45, 45), (45, 50), (60, 55), (60, 60), (60, 65)]
    assert all("apart" in r.reason for r in plan.refused)


@pytest.fixture(scope="module")
def emulated_rig():
    """A driver connected to the default emulated rig (nothing measured, only its checks)."""
    from drivers.emulator.rig import EmulatedRig
    from drivers.rig import Rig

    with EmulatedRig(lambda ti, pi, tr, pr: np.full(np.shape(ti), 0.25), seed=3, name="plan-test") as emu:
        emu.start(pty=False)
        with Rig.open(emu.url("stage"), emu.url("camera"), emu.url("lamp"), timeout=0.5) as rig:
            yield rig


#: Views to 95 deg either side, every 0.5 deg near grazing and at the lamp: travel limits,
#: exactly 5 deg from the lamp, and 90 deg views whose radiance window falls off the sample.
EDGE_PROTOCOL = MINIMAL.replace("theta_i = 45", "theta_i = [0, 45, 85]").replace(
    "view = [-60, 0, 30]", "view = [-95, -90, -89.5, -89, -88.5, -88, 40, 45, 50, 80, 85, 87, 89, 90, 95]")


def test_the_plan_refuses_exactly_what_the_rig_refuses(emulated_rig):
    """One rule (drivers.acceptance.GeometryRule): every geometry of the shipped protocols,
    and of one reaching past the travel limits and the sample's grazing image, is planned
    exactly when the emulated rig's own check accepts it, with the same reason."""
    protocols = [P.load(path) for path in SHIPPED] + [P.loads(EDGE_PROTOCOL)]
    for protocol in protocols:
        plan = P.plan(protocol)
        for point in plan.points:
            assert emulated_rig.check_geometry(point.theta_i, point.phi_i, point.view) is None, (protocol.name, point)
        for refusal in plan.refused:
            point = refusal.point
            assert emulated_rig.check_geometry(point.theta_i, point.phi_i, point.view) == refusal.reason, \
                (protocol.name, point)
    from drivers.acceptance import EMULATED_SENSOR

    assert emulated_rig.info == EMULATED_SENSOR  # the plan's camera is the emulated one
    edge = P.plan(protocols[-1])
    reasons = " ".join(r.reason for r in edge.refused)
    assert "travel limits" in reasons and "apart" in reasons and "sample's image" in reasons


def test_fig19_is_off_plane_with_the_papers_azimuths():
    """Fig 19: (theta_i, phi_r - phi_i) = (60, 45) and (75, 60) deg on the positive side."""
    plan = P.plan(P.load(ROOT / "protocols" / "oren-nayar-fig19-off-plane.toml"))
    pairs = {(p.theta_i, round(p.phi_r - p.phi_i, 6)) for p in plan.points}
    assert pairs == {(60.0, 45.0), (75.0, 60.0)}


def test_curet_protocol_has_205_geometries_preserving_relative_azimuth():
    protocol = P.load(ROOT / "protocols" / "curet-205.toml")
    plan = P.plan(protocol)
    assert len(plan.points) + len(plan.refused) == 205
    table = np.loadtxt(ROOT.parent / "shared" / "data" / "curet" / "table.txt") if (ROOT.parent / "shared").exists() else None
    if table is not None:
        tv, pv, ti, pi_ = np.degrees(table[:, 1:]).T
        expected = sorted(zip(np.round(ti, 3), np.round(np.cos(np.radians(pv - pi_)), 3)))
        got = sorted((round(p.theta_i, 3), round(float(np.cos(np.radians(p.phi_r - p.phi_i))), 3)) for p in plan.points)
        assert got == expected


def test_ranges_expand_inclusive_and_theta_lists_make_blocks():
    protocol = P.loads(MINIMAL.replace("theta_i = 45", "theta_i = [30, 60]").replace("[-60, 0, 30]", "{start = -10, stop = 10, step = 5}"))
    assert [b.theta_i for b in protocol.blocks] == [30.0, 60.0]
    assert protocol.blocks[0].views == (-10.0, -5.0, 0.0, 5.0, 10.0)


def test_repeats_multiply_points_and_keys_stay_unique():
    plan = P.plan(P.loads(MINIMAL.replace("view = [-60, 0, 30]", "view = [-60, 0, 30]\nrepeats = 3")))
    assert len(plan.points) == 9
    assert len({p.key for p in plan.points}) == 9


@pytest.mark.parametrize(
    "change, field, expected",
    [
        (("theta_i = 45", "theta_i = 95"), "block[0].theta_i", "[0, 90]"),
        (("theta_i = 45", "theta_i = 'high'"), "block[0].theta_i", "a finite number"),
        (("view = [-60, 0, 30]", "view = {start = 10, stop = 0, step = 5}"), "block[0].view", "stop >= start"),
        (("view = [-60, 0, 30]", "view = {start = 0, stop = 10, step = -5}"), "block[0].view.step", "[1e-06"),
        (("view = [-60, 0, 30]", "veiw = [1]"), "block[0].veiw", "did you mean 'view'"),
        (("label = \"s\"", "label = 3"), "sample.label", "a non-empty string"),
        (("[sample]\nlabel = \"s\"", ""), "sample", "a table"),
        (("[[block]]", "[exposure]\nmode = 'sometimes'\n[[block]]"), "exposure.mode", "'auto', 'fixed', 'hdr'"),
        (("[[block]]", "[exposure]\nmode = 'hdr'\n[[block]]"), "exposure.brackets", "required for mode 'hdr'"),
        (("[[block]]", "[rig]\nmin_separation = -1\n[[block]]"), "rig.min_separation", "[0, 90]"),
        (("[[block]]", "[rig]\ncamera_range = [90, -90]\n[[block]]"), "rig.camera_range", "low <= high"),
        (("[[block]]", "[darks]\nevery = 2.5\n[[block]]"), "darks.every", "an integer"),
        (("name = \"t\"", "name = \"t\"\nformat_version = 7"), "protocol.format_version", "1 (the version"),
    ],
)
def test_bad_fields_are_named_with_file_and_expectation(change, field, expected):
    text = MINIMAL.replace(*change)
    with pytest.raises(P.ProtocolError) as info:
        P.loads(text, source="my.toml")
    message = str(info.value)
    assert message.startswith("my.toml: field '" + field + "'"), message
    assert expected in message


def test_invalid_toml_and_missing_blocks_name_the_file():
    with pytest.raises(P.ProtocolError, match=r"^x\.toml: not valid TOML"):
        P.loads("[protocol\nname=1", source="x.toml")
    with pytest.raises(P.ProtocolError, match=r"x\.toml: field 'block'"):
        P.loads(MINIMAL.split("[[block]]")[0], source="x.toml")


def test_refusals_list_travel_limits_and_separation_never_drop_silently():
    text = MINIMAL.replace("view = [-60, 0, 30]", "view = [-95, -60, 45, 47, 60]")
    plan = P.plan(P.loads(text))
    reasons = {r.point.view: r.reason for r in plan.refused}
    assert "outside the travel limits" in reasons[-95.0]
    assert "apart" in reasons[45.0] and "apart" in reasons[47.0]
    assert [p.view for p in plan.points] == [-60.0, 60.0]


def test_separation_is_the_angle_between_directions():
    # lamp at (45, 0); camera at view 45 on the azimuth-0 side coincides with it
    assert P.camera_lamp_separation(45.0, 0.0, 45.0) == pytest.approx(0.0, abs=1e-12)
    assert P.camera_lamp_separation(45.0, 0.0, -45.0) == pytest.approx(90.0)
    # out of plane: lamp at azimuth 90 and polar 90 vs camera at the normal: 90 deg
    assert P.camera_lamp_separation(90.0, 90.0, 0.0) == pytest.approx(90.0)


def test_move_time_trapezoid_and_triangle():
    # triangle: 2 sqrt(d/a); trapezoid: d/v + v/a
    assert P.move_time(1.0, 10.0, 4.0) == pytest.approx(1.0)
    assert P.move_time(100.0, 10.0, 20.0) == pytest.approx(10.5)


def test_gonio_plan_cli_prints_summary_and_errors_cleanly(tmp_path, capsys):
    assert main(["plan", str(ROOT / "protocols" / "oren-nayar-fig16-plaster.toml")]) == 0
    out = capsys.readouterr().out
    assert "points to measure: 90" in out and "points refused: 9" in out and "h:mm:ss" in out
    bad = tmp_path / "bad.toml"
    bad.write_text(MINIMAL.replace("theta_i = 45", "theta_i = 120"))
    assert main(["plan", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml: field 'block[0].theta_i'" in err and "Traceback" not in err


# ---------------------------------------------------------------------- new fields and limits
WITH_REFERENCE = MINIMAL + """
[reference]
label = "standard"
reflectance = 0.99
geometries = [[30, 0, -10]]
"""


def _with_table(text: str, table: str) -> str:
    """``text`` with ``table`` (TOML) inserted before its first block."""
    return text.replace("[[block]]", table + "\n[[block]]", 1)


def test_defaults_of_the_new_fields_keep_old_protocols_unchanged():
    protocol = P.loads(WITH_REFERENCE)
    assert protocol.checks == P.Checks(every=0, geometry=None, frames=5)
    assert protocol.reference.reflectance_uncertainty == 0.0 and protocol.reference.angular_uncertainty == 0.0
    assert protocol.rig.velocity is None and protocol.rig.acceleration is None
    assert (protocol.rig.estimate_velocity, protocol.rig.estimate_acceleration) == (10.0, 20.0)
    plan = P.plan(protocol)
    assert plan.checks == 0 and plan.check_geometry is None
    assert "lamp-stability checks: 0" in plan.summary()


def test_checks_table_is_parsed_and_counted_as_documented():
    """2 + (n - 1) // every checks, plus one after the reference block."""
    text = MINIMAL.replace("view = [-60, 0, 30]", "view = {start = -80, stop = 80, step = 10}")  # 17 views
    protocol = P.loads(_with_table(text, "[checks]\nevery = 5\ngeometry = [45, 0, -20]\nframes = 7"))
    assert protocol.checks == P.Checks(every=5, geometry=(45.0, 0.0, -20.0), frames=7)
    plan = P.plan(protocol)
    n = len(plan.points)
    # 10 deg steps miss the lamp at 45 deg; 40 and 50 are exactly at the 5 deg minimum: refused
    assert n == 15 and sorted(r.point.view for r in plan.refused) == [40.0, 50.0]
    assert plan.checks == 2 + (n - 1) // 5 == 4
    assert plan.check_geometry == (45.0, 0.0, -20.0)
    assert "lamp-stability checks: 4 (every 5 points, 7 frames each" in plan.summary()
    with_reference = P.plan(P.loads(_with_table(text + WITH_REFERENCE.split(MINIMAL)[1], "[checks]\nevery = 5")))
    assert with_reference.checks == 5


def test_checks_default_geometry_is_the_first_point_the_plan_measures():
    text = MINIMAL.replace("view = [-60, 0, 30]", "view = [-95, 45, 30]")  # -95 outside travel, 45 on the lamp
    plan = P.plan(P.loads(_with_table(text, "[checks]\nevery = 1")))
    assert [p.view for p in plan.points] == [30.0]
    assert plan.check_geometry == (45.0, 0.0, 30.0)
    assert plan.checks == 2  # before and after the only point


def test_checks_every_one_and_no_measured_point():
    text = MINIMAL.replace("view = [-60, 0, 30]", "view = [45]")  # refused: no point measured
    assert P.plan(P.loads(_with_table(text, "[checks]\nevery = 1"))).checks == 0
    assert P.check_count(P.Checks(every=1), 10, reference_measured=True) == 2 + 9 + 1
    assert P.check_count(P.Checks(every=10), 10, reference_measured=False) == 2
    assert P.check_count(P.Checks(every=10), 11, reference_measured=False) == 3


def test_checks_add_frames_and_a_move_each_to_the_time_estimate():
    base = P.loads(MINIMAL)
    checked = P.loads(_with_table(MINIMAL, "[checks]\nevery = 2\nframes = 4\n[exposure]\nmode = 'fixed'\ntime = 0.5"))
    fixed = P.loads(_with_table(MINIMAL, "[exposure]\nmode = 'fixed'\ntime = 0.5"))
    plan, without = P.plan(checked), P.plan(fixed)
    assert plan.checks == 2 + (3 - 1) // 2 == 3
    rig = base.rig
    per_check = P.move_time(90.0, 10.0, 20.0) + rig.settle_time + 4 * (0.5 + rig.readout_time)
    assert plan.estimated_seconds - without.estimated_seconds == pytest.approx(3 * per_check, rel=1e-12)


def test_check_geometry_the_rig_refuses_is_an_error_with_the_reason():
    text = _with_table(MINIMAL, "[rig]\ncamera_range = [-60, 60]\n[checks]\nevery = 3\ngeometry = [30, 0, 70]")
    with pytest.raises(P.ProtocolError, match=r"^my\.toml: field 'checks\.geometry': expected a geometry the rig "
                                              r"can measure \(the plan refuses it: view \(camera swing\)=70 deg is outside the travel"):
        P.loads(text, source="my.toml")


def test_reference_uncertainties_are_read_and_bounded():
    text = WITH_REFERENCE + "reflectance_uncertainty = 0.005\nangular_uncertainty = 0.02\n"
    reference = P.loads(text).reference
    assert (reference.reflectance_uncertainty, reference.angular_uncertainty) == (0.005, 0.02)
    for key in ("reflectance_uncertainty", "angular_uncertainty"):
        for bad in ("-0.1", "0.51", "nan", "'small'"):
            with pytest.raises(P.ProtocolError, match=f"field 'reference.{key}': expected a finite number in"):
                P.loads(WITH_REFERENCE + f"{key} = {bad}\n")


def test_velocity_and_acceleration_are_programmed_values_or_none():
    rig = P.loads(_with_table(MINIMAL, "[rig]\nvelocity = 4\nacceleration = 8")).rig
    assert (rig.velocity, rig.acceleration) == (4.0, 8.0)
    assert (rig.estimate_velocity, rig.estimate_acceleration) == (4.0, 8.0)
    slow = P.plan(P.loads(_with_table(MINIMAL, "[rig]\nvelocity = 4\nacceleration = 8")))
    assert slow.estimated_seconds > P.plan(P.loads(MINIMAL)).estimated_seconds
    for key in ("velocity", "acceleration"):
        for bad in ("0", "-1", "inf", "nan", "true"):
            with pytest.raises(P.ProtocolError, match=f"field 'rig.{key}': expected a finite number"):
                P.loads(_with_table(MINIMAL, f"[rig]\n{key} = {bad}"))


@pytest.mark.parametrize("change, field, limit", [
    (("view = [-60, 0, 30]", "view = [-60, 0, 30]\nrepeats = 10001"), "block[0].repeats", "the limit on repeats"),
    (("[[block]]", "[exposure]\nframes = 101\n[[block]]"), "exposure.frames", "the limit on frames per point"),
    (("[[block]]", "[checks]\nframes = 101\n[[block]]"), "checks.frames", "the limit on frames per check"),
    (("[[block]]", "[exposure]\nmode = 'hdr'\nbrackets = [" + ", ".join(["0.01"] * 17) + "]\n[[block]]"),
     "exposure.brackets", "at most 16 exposure times (the limit on HDR brackets"),
    (("view = [-60, 0, 30]", "view = {start = -90, stop = 90, step = 0.0001}"), "block[0].view", "at most 100000"),
    (("theta_i = 45\nview = [-60, 0, 30]", ("theta_i = {start = 0, stop = 90, step = 0.01}\n"
                                            "view = {start = -90, stop = 90, step = 1}")),
     "block[0]", "9001 theta_i x 181 views x 1 repeats"),
])
def test_limits_are_checked_before_expanding_and_named(change, field, limit):
    with pytest.raises(P.ProtocolError) as info:
        P.loads(MINIMAL.replace(*change), source="my.toml")
    assert str(info.value).startswith(f"my.toml: field '{field}'") and limit in str(info.value), str(info.value)


def test_limits_are_inclusive():
    protocol = P.loads(MINIMAL.replace("view = [-60, 0, 30]", "view = [-60, 0, 30]\nrepeats = 10000"))
    assert protocol.blocks[0].repeats == 10_000
    brackets = ", ".join(["0.01"] * 15 + ["60"])
    assert len(P.loads(_with_table(MINIMAL, f"[exposure]\nmode = 'hdr'\nbrackets = [{brackets}]")).exposure.brackets) == 16
    assert P.loads(_with_table(MINIMAL, "[exposure]\nframes = 100")).exposure.frames == 100


def test_plan_refuses_an_oversized_protocol_built_in_code():
    """The limit holds for protocols constructed directly, not only for parsed files."""
    protocol = P.loads(MINIMAL)
    huge = P.Block("huge", 45.0, 0.0, tuple(float(v) for v in range(-90, 91)), repeats=2000)
    oversized = P.Protocol(protocol.name, protocol.sample, "", {}, protocol.rig, protocol.exposure, protocol.darks,
                           (huge,), source="code")
    with pytest.raises(P.ProtocolError, match=r"^code: field 'block': expected at most 200000 planned points"):
        P.plan(oversized)


def test_views_outside_the_camera_range_stay_refused_points():
    """Views within [-180, 180] but beyond camera_range are refused points, not errors."""
    plan = P.plan(P.loads(MINIMAL.replace("view = [-60, 0, 30]", "view = [-170, 0, 120]")))
    assert [p.view for p in plan.points] == [0.0]
    assert all("outside the travel limits" in r.reason for r in plan.refused)


def test_load_reports_unreadable_paths(tmp_path):
    with pytest.raises(P.ProtocolError, match="it is a directory"):
        P.load(tmp_path)
    (tmp_path / "a.toml").symlink_to(tmp_path / "b.toml")
    (tmp_path / "b.toml").symlink_to(tmp_path / "a.toml")
    with pytest.raises(P.ProtocolError, match=r"a\.toml: cannot read the protocol file"):
        P.load(tmp_path / "a.toml")
    with pytest.raises(FileNotFoundError, match="protocol file not found"):
        P.load(tmp_path / "missing.toml")


def test_refusal_reasons_of_a_block_equal_the_single_point_rule():
    rig = P.RigLimits(camera_range=(-80.0, 80.0), lamp_phi_range=(-90.0, 90.0))
    views = [-95.0, -80.0, 0.0, 42.0, 45.0, 47.0, 50.0, 85.0]
    for theta_i, phi_i in ((45.0, 0.0), (45.0, 120.0), (30.0, 60.0)):
        assert P.refusal_reasons(theta_i, phi_i, views, rig) == [P.refusal_reason(theta_i, phi_i, v, rig) for v in views]
