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
    exactly the three retro-reflection views (camera on the lamp) at 5 deg separation."""
    plan = P.plan(P.load(ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"))
    assert len(plan.points) + len(plan.refused) == 3 * 33
    assert sorted((r.point.theta_i, r.point.view) for r in plan.refused) == [(30, 30), (45, 45), (60, 60)]
    assert all("apart" in r.reason for r in plan.refused)


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
        (("theta_i = 45", "theta_i = 'high'"), "block[0].theta_i", "a number"),
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
    assert "outside travel" in reasons[-95.0]
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
    assert "points to measure: 96" in out and "points refused: 3" in out and "h:mm:ss" in out
    bad = tmp_path / "bad.toml"
    bad.write_text(MINIMAL.replace("theta_i = 45", "theta_i = 120"))
    assert main(["plan", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml: field 'block[0].theta_i'" in err and "Traceback" not in err
