"""Faults injected while a protocol runs: no point is recorded ok at a geometry it was not
measured at, nothing measured is lost, resume refuses another experiment.

The emulator's side channel (docs/emulator.md) trips limit switches, garbles replies,
cuts and stalls lines, burns the lamp out and faults the camera in the middle of a run;
after every scenario each ``ok`` row's encoder readback must match its plan within the
rig's position tolerance, and a resume after the fault is cleared completes the recording
with every planned point exactly once.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from gonio import acquisition, data, protocols
from gonio.cli.run import emulated_rig

#: Two lamp directions (the lamp's polar and azimuth axes both move between them) and a
#: camera sweep; six points with a dark frame every three.
PROTOCOL = """
[protocol]
name = "faults"
[sample]
label = "matte"
[darks]
every = 3
[[block]]
theta_i = 30
view = [-50, -20, 10]
[[block]]
theta_i = 50
phi_i = 40
view = [-40, 0, 20]
"""
TOLERANCE = 0.01  # deg: the rig's default position_tolerance (5 sigma of the 0.002 deg repeatability)


def _off_target(points) -> list[str]:
    """Ok rows whose readback geometry differs from their plan beyond the tolerance."""
    ok = points["status"] == "ok"
    problems = []
    for planned, readback in (("view", "stage_camera"), ("theta_i", "stage_lamp_theta"), ("phi_i", "stage_lamp_phi")):
        bad = ok & ~(np.abs(points[readback] - points[planned]) <= TOLERANCE)
        problems += [f"row {k}: {readback}={points[readback][k]} for {planned}={points[planned][k]}"
                     for k in np.flatnonzero(bad)]
    return problems


def _planned_keys(protocol) -> set:
    plan = protocols.plan(protocol)
    return {data.point_key(*p.key) for p in plan.points} | {data.point_key(*r.point.key) for r in plan.refused}


def _final_keys(folder) -> list:
    rows = data.read_points(folder, as_arrays=False)
    return [data.point_key(r["block"], r["repeat"], r["theta_i"], r["phi_i"], r["view"]) for r in rows
            if r["status"] in ("ok", "refused")]


def _inject(fault):
    """A progress callback that injects ``fault(control)`` once, after the second point."""
    calls = {"n": 0}

    def progress(p):
        calls["n"] += 1
        if calls["n"] == 2:
            fault()
    return progress


SCENARIOS = {
    "limit on the camera axis": lambda c: c.hit_limit(1),
    "limit on the lamp polar axis": lambda c: c.hit_limit(2),
    "limit on the lamp azimuth axis": lambda c: c.hit_limit(3),
    "garbled stage replies": lambda c: c.garble("stage", 6),
    "stalled stage": lambda c: c.stall("stage", 2.5),
    "stage disconnected": lambda c: c.disconnect("stage"),
    "camera disconnected": lambda c: c.disconnect("camera"),
    "camera fault": lambda c: c.camera_fault(True),
    "lamp burn-out": lambda c: c.burn_out_lamp(),
}


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_no_point_is_recorded_ok_off_its_geometry_and_resume_completes(tmp_path, scenario):
    protocol = protocols.loads(PROTOCOL, source="faults.toml")
    folder = tmp_path / "rec"
    with emulated_rig("lambert:rho=0.5", 2, name=f"fault-{scenario}") as (rig, emulator, change, meta):
        control = emulator.control
        rig.stage.line.timeout = rig.camera.line.timeout = 0.3  # a dead line fails in 0.3 s, not 2 s
        try:
            acquisition.run_protocol(protocol, rig, folder, metadata=meta, clock=control.now, warm_up=False,
                                     progress=_inject(lambda: SCENARIOS[scenario](control)))
        except acquisition.AcquisitionError as error:
            # a dead instrument stops the run: the recording keeps what was measured, says
            # "failed", and the message blames the instrument, not the disk
            assert data.read_metadata(folder)["status"] == "failed", scenario
            assert "cannot write the recording" not in str(error), str(error)
        points = data.read_points(folder)
        assert _off_target(points) == [], scenario
        control.clear_faults()
        control.replace_lamp()
        result = acquisition.run_protocol(protocol, rig, folder, resume=True, metadata=meta, clock=control.now,
                                          warm_up=False)
    assert result.status == "complete"
    points = data.read_points(folder)
    assert _off_target(points) == []
    keys = _final_keys(folder)
    assert len(keys) == len(set(keys)) and set(keys) == _planned_keys(protocol)


def test_a_limit_stop_is_retried_and_the_point_measured_where_planned(tmp_path):
    """The issue's case: after a limit hit on the lamp axis, later points were recorded ok
    at theta_i = 30 while the lamp stood at 37.5. Now the move is retried from where the
    axis stopped and every point's readback agrees with its plan."""
    protocol = protocols.loads(PROTOCOL.replace("theta_i = 50", "theta_i = 45"), source="faults.toml")
    with emulated_rig("lambert:rho=0.5", 4, name="limit-lamp") as (rig, emulator, change, meta):
        emulator.control.hit_limit(2)  # the very first lamp move (home 45 -> 30) stops half way at 37.5
        result = acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta,
                                          clock=emulator.control.now, warm_up=False)
    points = data.read_points(tmp_path / "rec")
    assert result.status == "complete" and result.errors == 0
    assert _off_target(points) == []
    sample = points["block"] != acquisition.CHECK_BLOCK
    np.testing.assert_allclose(points["stage_lamp_theta"][sample], points["theta_i"][sample], atol=TOLERANCE)


def test_a_move_that_cannot_be_confirmed_is_an_error_row_with_the_reason(tmp_path):
    protocol = protocols.loads(PROTOCOL, source="faults.toml")
    with emulated_rig("lambert:rho=0.5", 5, name="no-retries") as (rig, emulator, change, meta):
        rig.move_retries = 0
        calls = {"n": 0}

        def trip(p):
            calls["n"] += 1
            if calls["n"] == 1:
                emulator.control.hit_limit(1)
        result = acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta,
                                          clock=emulator.control.now, warm_up=False, progress=trip)
    rows = data.read_points(tmp_path / "rec", as_arrays=False)
    errors = [r for r in rows if r["status"] == "error"]
    assert result.errors == 1 and len(errors) == 1
    assert "PositionError" in errors[0]["message"] and "HARDWARE LIMIT" in errors[0]["message"]
    assert _off_target(data.read_points(tmp_path / "rec")) == []
    # a run with a failed point is not "complete": the recorded status and the result say
    # incomplete (a resume measures the point again), and so does gonio run's exit status
    assert result.status == "incomplete" and data.read_metadata(tmp_path / "rec")["status"] == "incomplete"
    assert result.summary().startswith("incomplete: ")


# ----------------------------------------------------------------------------- resume
SMALL = """
[protocol]
name = "resume"
[sample]
label = "s"
[[block]]
theta_i = 40
view = [-60, -30, 0, 30]
"""


def _interrupted(tmp_path, sample="lambert:rho=0.5", seed=0, lamp_voltage=120.0, text=SMALL):
    """A recording stopped after two points (Ctrl-C), as gonio run leaves it."""
    protocol = protocols.loads(text, source="resume.toml")
    calls = {"n": 0}

    def stop(p):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
    with emulated_rig(sample, seed, name=f"resume-{seed}-{sample}") as (rig, emulator, change, meta):
        with pytest.raises(KeyboardInterrupt):
            acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=emulator.control.now,
                                     warm_up=False, lamp_voltage=lamp_voltage, progress=stop)
    return tmp_path / "rec"


@pytest.mark.parametrize("change, words", [
    ({"text": SMALL.replace("[-60, -30, 0, 30]", "[-60, -30, 0, 35]")}, "protocol_sha256"),
    ({"sample": "oren-nayar:sigma=30,rho=0.9"}, "rig.sample"),
    ({"seed": 3}, "rig.seed"),
    ({"lamp_voltage": 100.0}, "lamp_voltage"),
    ({"realism": "ideal"}, r"rig.realism.spec: recorded 'lab', now 'ideal'"),
    ({"realism": "lab:stray_light=0.001"}, r"rig.realism.stray_light: recorded 0.002, now 0.001"),
])
def test_resume_refuses_a_different_experiment_and_names_the_difference(tmp_path, change, words):
    folder = _interrupted(tmp_path)
    before = (folder / "points.csv").read_bytes(), (folder / "metadata.json").read_bytes()
    options = {"sample": "lambert:rho=0.5", "seed": 0, "lamp_voltage": 120.0, "text": SMALL, "realism": "lab",
               **change}
    protocol = protocols.loads(options["text"], source="resume.toml")
    with emulated_rig(options["sample"], options["seed"], name="resume-other",
                      realism=options["realism"]) as (rig, emulator, _, meta):
        with pytest.raises(data.RecordingError, match=words) as info:
            acquisition.run_protocol(protocol, rig, folder, resume=True, metadata=meta, clock=emulator.control.now,
                                     warm_up=False, lamp_voltage=options["lamp_voltage"])
    assert "different experiment" in str(info.value)
    assert (folder / "points.csv").read_bytes(), (folder / "metadata.json").read_bytes() == before


def test_resume_of_the_same_experiment_completes_and_records_the_session(tmp_path):
    folder = _interrupted(tmp_path)
    protocol = protocols.loads(SMALL, source="resume.toml")
    with emulated_rig("lambert:rho=0.5", 0, name="resume-same") as (rig, emulator, _, meta):
        result = acquisition.run_protocol(protocol, rig, folder, resume=True, metadata=meta,
                                          clock=emulator.control.now, warm_up=False)
    assert result.status == "complete" and result.skipped == 2
    points = data.read_points(folder)
    assert sorted(set(points["session"])) == [0, 1]
    meta = json.loads((folder / "metadata.json").read_text())
    assert "experiment" not in meta["resumes"][0]  # the experiment is stored once


def test_a_duplicated_point_is_detected_by_resume_and_by_the_reduction(tmp_path):
    folder = _interrupted(tmp_path)
    lines = (folder / "points.csv").read_text().splitlines(keepends=True)
    with open(folder / "points.csv", "a") as handle:
        handle.write(lines[1])  # the first point again: two runs mixed into one folder
    with pytest.raises(data.RecordingError, match="recorded more than once.*lines 2, 4"):
        acquisition.reduce_recording(folder)
    protocol = protocols.loads(SMALL, source="resume.toml")
    with emulated_rig("lambert:rho=0.5", 0, name="resume-dup") as (rig, emulator, _, meta):
        with pytest.raises(data.RecordingError, match="recorded more than once"):
            acquisition.run_protocol(protocol, rig, folder, resume=True, metadata=meta, clock=emulator.control.now,
                                     warm_up=False)


# ----------------------------------------------------------------------------- saturation
def test_saturated_points_are_flagged_excluded_counted_and_a_mostly_saturated_fit_refused(tmp_path):
    """The issue's case: a fixed 0.5 s exposure saturates every ROI pixel; every row was ok
    and the fit returned sigma = 1.2e-6. Now the rows are flagged, the reduction excludes
    and counts them, and building a fit dataset is refused with the reason."""
    text = SMALL + "[exposure]\nmode = 'fixed'\ntime = 0.5\n"
    protocol = protocols.loads(text, source="saturating.toml")
    with emulated_rig("oren-nayar:sigma=30,rho=0.9", 0, name="saturate") as (rig, emulator, _, meta):
        result = acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta,
                                          clock=emulator.control.now, warm_up=False)
    points = data.read_points(tmp_path / "rec")
    ok = points["status"] == "ok"
    assert result.flagged == ok.sum() == 4
    assert all("saturated" in f for f in points["flags"][ok])
    with pytest.raises(ValueError, match="no successfully measured, unsaturated sample points"):
        acquisition.reduce_recording(tmp_path / "rec")


def test_a_few_saturated_points_are_excluded_and_counted_in_the_fit_summary(tmp_path):
    """At a fixed 0.12 s a rho = 0.5 Lambertian sample saturates under the steep lamp
    (cos 10 deg: about 4500 DN of signal, above the 3000 DN full well) and not under the
    grazing one (cos 75 deg: about 1200 DN)."""
    from gonio.fitting import fit

    text = """
[protocol]
name = "few"
[sample]
label = "s"
[exposure]
mode = "fixed"
time = 0.12
[[block]]
theta_i = 10
view = [-40, 30]
[[block]]
theta_i = 75
view = [-40, 0, 30]
"""
    protocol = protocols.loads(text, source="few.toml")
    with emulated_rig("lambert:rho=0.5", 0, name="few-saturated") as (rig, emulator, _, meta):
        acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=emulator.control.now,
                                 warm_up=False)
    points = data.read_points(tmp_path / "rec")
    flagged = np.array(["saturated" in f for f in points["flags"]])
    assert flagged.sum() == 2 and np.all(points["theta_i"][flagged] == 10.0)
    reduced = acquisition.reduce_recording(tmp_path / "rec")
    assert reduced.excluded == {"saturated": 2} and len(reduced.radiance) == 3
    result = fit(reduced.relative_radiance(), "lambert", fixed={"rho": 0.5}, mcmc=False)
    assert "2 saturated point(s) excluded" in result.summary()


def test_a_full_disk_stops_the_run_with_one_message_and_leaves_no_temporary_file(tmp_path, monkeypatch):
    """The issue's case: ENOSPC was raised again inside the finishing step (a traceback),
    metadata stayed 'running' and a 0-byte temporary file was left behind."""
    import errno

    import gonio.data
    import gonio.files

    protocol = protocols.loads(SMALL, source="resume.toml")
    state = {"appends": 0, "full": False}
    real_append, real_replace = gonio.data._fsync_append, gonio.files.os.replace

    def append(path, text):
        state["appends"] += 1
        if state["appends"] > 4:  # the two headers, the first dark and the first point fit
            state["full"] = True
        if state["full"]:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real_append(path, text)

    def replace(source, target):
        if state["full"]:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_replace(source, target)
    monkeypatch.setattr(gonio.data, "_fsync_append", append)
    monkeypatch.setattr(gonio.files.os, "replace", replace)
    with emulated_rig("lambert:rho=0.5", 0, name="full-disk") as (rig, emulator, _, meta):
        with pytest.raises(acquisition.AcquisitionError, match="cannot write the recording: No space left") as info:
            acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=emulator.control.now,
                                     warm_up=False)
    assert "metadata.json could not be updated" in str(info.value)
    monkeypatch.undo()
    assert sorted(p.name for p in (tmp_path / "rec").iterdir()) == ["darks.csv", "metadata.json", "points.csv"]
    assert len(data.read_points(tmp_path / "rec")["index"]) == 1  # what was written is intact


def test_a_full_disk_at_the_end_is_not_complete(tmp_path, monkeypatch, capsys):
    """Every point written, then the disk fills before the final status: the run used to say
    'complete' with exit 0 while metadata.json still said 'running'. The result says the
    status was not recorded, and gonio run exits 3 with the command that records it."""
    import errno

    import gonio.data
    from gonio.cli.run import EXIT_INCOMPLETE

    protocol = protocols.loads(SMALL, source="resume.toml")
    real_finish = gonio.data.RecordingWriter.finish

    def full_at_finish(self, status, **extra):
        if status == "complete":
            raise OSError(errno.ENOSPC, "No space left on device")
        real_finish(self, status, **extra)
    monkeypatch.setattr(gonio.data.RecordingWriter, "finish", full_at_finish)
    with emulated_rig("lambert:rho=0.5", 0, name="full-at-end") as (rig, emulator, _, meta):
        result = acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=emulator.control.now,
                                          warm_up=False)
    assert result.status_recorded is False and "still says 'running'" in result.messages[-1]
    assert data.read_metadata(tmp_path / "rec")["status"] == "running"
    protocol_file = tmp_path / "small.toml"
    protocol_file.write_text(SMALL)
    from gonio.cli import main

    assert main(["run", str(protocol_file), "--out", str(tmp_path / "cli"), "--quiet", "--no-warm-up"]) == \
        EXIT_INCOMPLETE
    assert "record the status with: gonio run" in capsys.readouterr().err


def test_an_instrument_timeout_is_not_reported_as_a_full_disk(tmp_path):
    """A reply timeout is an OSError (TimeoutError) too: a run it stops said "cannot write
    the recording". The run blames the instrument, and a file-system error (an errno)
    still says what it is."""
    import errno

    from drivers.errors import ResponseTimeout

    protocol = protocols.loads(PROTOCOL, source="faults.toml")
    faults = {"timeout": ResponseTimeout("TP?", 0.3, port="stage"),
              "full disk": OSError(errno.ENOSPC, "No space left on device")}
    for kind, fault in faults.items():
        with emulated_rig("lambert:rho=0.5", 6, name=f"classify-{kind}") as (rig, emulator, change, meta):
            def fail(progress, fault=fault):
                raise fault
            with pytest.raises(acquisition.AcquisitionError) as raised:
                acquisition.run_protocol(protocol, rig, tmp_path / kind, metadata=meta, clock=emulator.control.now,
                                         warm_up=False, progress=fail)
        message = str(raised.value)
        if kind == "timeout":
            assert "instrument fault: ResponseTimeout" in message and "cannot write" not in message
        else:
            assert "cannot write the recording: No space left on device" in message
        assert data.read_metadata(tmp_path / kind)["status"] == "failed"


def test_a_lost_line_still_records_the_status(tmp_path):
    """The issue's case: with the instrument line lost, finishing the run read the
    instrument clock over that same line, raised again, and left the recording 'running'
    with a bare 'rig: TransportError'. The clock's failure no longer stops the status."""
    from drivers.errors import TransportError

    protocol = protocols.loads(PROTOCOL, source="faults.toml")
    with emulated_rig("lambert:rho=0.5", 7, name="lost-line") as (rig, emulator, change, meta):
        calls = {"n": 0}

        def clock():
            calls["n"] += 1
            if calls["n"] > 3:
                raise TransportError("camera: read failed: socket disconnected")
            return emulator.control.now()

        def cut(progress):
            raise TransportError("camera: read failed: socket disconnected")
        with pytest.raises(acquisition.AcquisitionError, match="instrument fault: TransportError"):
            acquisition.run_protocol(protocol, rig, tmp_path / "rec", metadata=meta, clock=clock, warm_up=False,
                                     progress=cut)
    meta_out = data.read_metadata(tmp_path / "rec")
    assert meta_out["status"] == "failed" and meta_out["last_run"]["instrument_seconds"] is None
