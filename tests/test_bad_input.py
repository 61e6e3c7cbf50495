"""Bad input gives one clear line, never a traceback, a hang or a changed file (DESIGN.md, "Bad input").

Every case runs ``gonio.cli.main`` in-process under a deadline and asserts the exit code,
exactly one line on stderr that names the file, field or argument and what was expected,
no traceback, and that no file in the test's folder changed (names, sizes and
modification times compared before and after).
"""
from __future__ import annotations

import errno
import os
import signal
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from gonio import protocols
from gonio.cli import main
from tests.test_protocols import MINIMAL

ROOT = Path(__file__).resolve().parents[1]
FIG16 = ROOT / "protocols" / "oren-nayar-fig16-plaster.toml"
#: Longest a refusal may take [s]: a refusal is a few checks, it must never expand a plan
#: (the 90k x 90k case would take hours) or wait on a device.
DEADLINE_SECONDS = 5.0

CSV = "theta_i,phi_i,theta_r,phi_r,value,sigma\n30,0,10,0,0.30,0.01\n30,0,20,0,0.29,0.01\n30,0,40,180,0.28,0.01\n"


class DeadlineExceeded(BaseException):
    """Raised by the alarm; a BaseException so that the CLI's catch-all cannot swallow it."""


@contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Abort the block with DeadlineExceeded after ``seconds`` of wall time."""
    def expire(signum, frame):
        raise DeadlineExceeded(f"no answer within {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def snapshot(folder: Path) -> dict[str, tuple]:
    """Every entry below ``folder``: relative name -> (kind, size, mtime_ns), links not followed."""
    entries = {}
    for directory, subdirectories, files in os.walk(folder, followlinks=False):
        for name in subdirectories + files:
            path = Path(directory) / name
            status = path.lstat()
            kind = "link" if path.is_symlink() else "dir" if path.is_dir() else "file"
            size = 0 if kind == "dir" else status.st_size
            entries[str(path.relative_to(folder))] = (kind, size, status.st_mtime_ns)
    return entries


def run_refused(argv: list[str], folder: Path, capsys, code: int = 2) -> str:
    """Run the CLI, assert a one-line refusal with ``code`` that changed nothing; return the line."""
    capsys.readouterr()
    before = snapshot(folder)
    start = time.perf_counter()
    with deadline(DEADLINE_SECONDS):
        returned = main(argv)
    elapsed = time.perf_counter() - start
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert returned == code, (returned, captured.err)
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("gonio: error: "), lines[0]
    assert "Traceback" not in captured.err + captured.out
    assert elapsed < DEADLINE_SECONDS
    assert snapshot(folder) == before
    return lines[0]


# --------------------------------------------------------------------------- protocols
def _set(old: str, new: str) -> tuple[str, str]:
    return old, new


BEFORE_BLOCK = "[[block]]"
VIEW = "view = [-60, 0, 30]"
THETA_VIEW = "theta_i = 45\nview = [-60, 0, 30]"


def _table(text: str) -> tuple[str, str]:
    """Insert ``text`` (TOML tables) before the first block."""
    return BEFORE_BLOCK, text + "\n" + BEFORE_BLOCK


REFERENCE = "[reference]\nlabel = 'standard'\nreflectance = 0.99\n"

MALFORMED_PROTOCOLS = [
    # (id, change to MINIMAL, field named, expectation in the message)
    ("view-range-to-inf", _set(VIEW, "view = {start = 0, stop = inf, step = 5}"), "block[0].view.stop", "finite"),
    ("view-nan-in-list", _set(VIEW, "view = [-60, nan, 30]"), "block[0].view[1]", "finite number in [-180, 180]"),
    ("view-beyond-180", _set(VIEW, "view = [-60, 200]"), "block[0].view[1]", "[-180, 180]"),
    ("theta-nan", _set("theta_i = 45", "theta_i = nan"), "block[0].theta_i", "finite number in [0, 90]"),
    ("theta-inf-in-list", _set("theta_i = 45", "theta_i = [30, inf]"), "block[0].theta_i[1]", "finite"),
    ("theta-range-nan", _set("theta_i = 45", "theta_i = {start = 0, stop = nan, step = 5}"),
     "block[0].theta_i.stop", "finite"),
    ("theta-huge-integer", _set("theta_i = 45", "theta_i = 99999999999999999999999999"), "block[0].theta_i",
     "[0, 90]"),
    ("phi-inf", _set(VIEW, VIEW + "\nphi_i = -inf"), "block[0].phi_i", "[-360, 360]"),
    ("settle-time-inf", _table("[rig]\nsettle_time = inf"), "rig.settle_time", "finite"),
    ("camera-range-nan", _table("[rig]\ncamera_range = [nan, nan]"), "rig.camera_range", "finite numbers"),
    ("velocity-zero", _table("[rig]\nvelocity = 0"), "rig.velocity", "(0, inf)"),
    ("acceleration-nan", _table("[rig]\nacceleration = nan"), "rig.acceleration", "finite"),
    ("exposure-time-inf", _table("[exposure]\ntime = inf"), "exposure.time", "finite"),
    ("max-time-nan", _table("[exposure]\nmax_time = nan"), "exposure.max_time", "finite"),
    ("frames-billion", _table("[exposure]\nframes = 1000000000"), "exposure.frames", "the limit on frames"),
    ("hdr-nan-bracket", _table("[exposure]\nmode = 'hdr'\nbrackets = [0.01, nan]"), "exposure.brackets[1]",
     "(0, 60] [s]"),
    ("hdr-1e9-bracket", _table("[exposure]\nmode = 'hdr'\nbrackets = [1e9]"), "exposure.brackets[0]", "(0, 60]"),
    ("hdr-17-brackets", _table("[exposure]\nmode = 'hdr'\nbrackets = {start = 0.01, stop = 0.17, step = 0.01}"),
     "exposure.brackets", "the limit on HDR brackets"),
    ("repeats-billion", _set(VIEW, VIEW + "\nrepeats = 1000000000"), "block[0].repeats", "the limit on repeats"),
    ("90k-by-90k", _set(THETA_VIEW, "theta_i = {start = 0, stop = 90, step = 0.001}\n"
                                    "view = {start = -90, stop = 90, step = 0.002}"),
     "block[0]", "at most 200000 planned points"),
    ("many-blocks", _set(VIEW, "view = {start = -90, stop = 90, step = 0.002}\nrepeats = 3"),
     "block[0]", "at most 200000 planned points"),
    ("nested-reference-geometry", _table(REFERENCE + "geometries = [[40, 0, [1]]]"),
     "reference.geometries[0][2] (view)", "finite number"),
    ("reference-theta-120", _table(REFERENCE + "geometries = [[120, 0, 10]]"),
     "reference.geometries[0][0] (theta_i)", "[0, 90]"),
    ("reference-theta-nan", _table(REFERENCE + "geometries = [[nan, 0, 10]]"),
     "reference.geometries[0][0] (theta_i)", "finite"),
    ("reference-view-below-horizon", _table(REFERENCE + "geometries = [[30, 0, -95]]"),
     "reference.geometries[0][2] (view)", "[-90, 90]"),
    ("reference-pair", _table(REFERENCE + "geometries = [[30, 0]]"), "reference.geometries[0]",
     "[theta_i, phi_i, view] triple"),
    ("reference-uncertainty-big", _table(REFERENCE + "reflectance_uncertainty = 0.7"),
     "reference.reflectance_uncertainty", "[0, 0.5]"),
    ("angular-uncertainty-nan", _table(REFERENCE + "angular_uncertainty = nan"), "reference.angular_uncertainty",
     "finite"),
    ("checks-refused-geometry", _table("[checks]\nevery = 10\ngeometry = [45, 0, 45]"), "checks.geometry",
     "a geometry the rig can measure"),
    ("checks-one-frame", _table("[checks]\nevery = 10\nframes = 1"), "checks.frames", "[2, 100]"),
    ("checks-negative-every", _table("[checks]\nevery = -1"), "checks.every", "an integer >= 0"),
    ("checks-unknown-field", _table("[checks]\nevry = 3"), "checks.evry", "did you mean 'every'"),
    ("metadata-nan", _table("[sample.metadata]\nvalue = nan"), "sample.metadata.value", "finite"),
    ("sample-geometry-nan", _set(THETA_VIEW, "geometries = [[30, 0, 20, nan]]"),
     "block[0].geometries[0][3] (phi_r)", "finite"),
    ("sample-geometry-nested", _set(THETA_VIEW, "geometries = [[30, 0, [20], 0]]"),
     "block[0].geometries[0][2] (theta_r)", "finite"),
]


@pytest.mark.parametrize("change, field, expected", [case[1:] for case in MALFORMED_PROTOCOLS],
                         ids=[case[0] for case in MALFORMED_PROTOCOLS])
def test_malformed_protocol_is_one_line_naming_file_field_and_expectation(change, field, expected, tmp_path, capsys):
    text = MINIMAL.replace(*change)
    assert text != MINIMAL
    path = tmp_path / "bad.toml"
    path.write_text(text)
    line = run_refused(["plan", str(path)], tmp_path, capsys)
    assert f"{path}: field '{field}'" in line, line
    assert expected in line, line


def test_formula_like_names_are_accepted_for_the_recording_to_escape():
    text = MINIMAL.replace(VIEW, VIEW + "\nname = '=HYPERLINK(\"x\")'") + "\n" + REFERENCE.replace(
        "'standard'", "'+cmd'")
    protocol = protocols.loads(text)
    assert protocol.blocks[0].name == '=HYPERLINK("x")' and protocol.reference.label == "+cmd"


def _directory(tmp_path: Path) -> Path:
    (tmp_path / "folder.toml").mkdir()
    return tmp_path / "folder.toml"


def _symlink_loop(tmp_path: Path) -> Path:
    os.symlink(tmp_path / "loop-b.toml", tmp_path / "loop-a.toml")
    os.symlink(tmp_path / "loop-a.toml", tmp_path / "loop-b.toml")
    return tmp_path / "loop-a.toml"


def _binary(tmp_path: Path) -> Path:
    path = tmp_path / "binary.toml"
    path.write_bytes(b"\xff\xfe\x00[protocol]")
    return path


def _deeply_nested(tmp_path: Path) -> Path:
    path = tmp_path / "nested.toml"
    path.write_text("x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    return path


@pytest.mark.parametrize("make, expected", [
    (_directory, "cannot read the protocol file: it is a directory"),
    (_symlink_loop, "cannot read the protocol file"),
    (_binary, "not a UTF-8 text file"),
    (_deeply_nested, "not valid TOML"),
    (lambda tmp_path: Path("/dev/zero"), "not a regular file"),
    (lambda tmp_path: tmp_path / "missing.toml", "protocol file not found"),
])
def test_unreadable_protocol_paths_are_one_line(make, expected, tmp_path, capsys):
    path = make(tmp_path)
    line = run_refused(["plan", str(path)], tmp_path, capsys)
    assert str(path) in line and expected in line, line


# --------------------------------------------------------------------------- CLI arguments
@pytest.fixture
def workspace(tmp_path: Path, monkeypatch) -> Path:
    """A folder with a data file, a protocol, a plain file, a foreign folder, a link to it and
    a (stub) result folder; the working directory of the test."""
    (tmp_path / "data.csv").write_text(CSV)
    (tmp_path / "latin1.csv").write_bytes(CSV.replace("sigma", "sigma\u00b5").encode("latin-1"))
    (tmp_path / "plan.toml").write_text(MINIMAL)
    (tmp_path / "notes.txt").write_text("a user's file\n")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "keep.txt").write_text("keep me\n")
    os.symlink(tmp_path / "mine", tmp_path / "link")
    (tmp_path / "result").mkdir()
    (tmp_path / "result" / "result.json").write_text('{"format": "gonio-fit-result"}')
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("GONIO_TABLE_DIR", str(tmp_path / "tables"))
    return tmp_path


BAD_ARGUMENTS = [
    # (id, argv, expected parts of the line)
    ("run-out-empty", ["run", "plan.toml", "--out", ""], ["--out ''", "an empty name"]),
    ("run-out-file", ["run", "plan.toml", "--out", "notes.txt"], ["--out notes.txt", "an existing file"]),
    ("run-out-device", ["run", "plan.toml", "--out", "/dev/null"], ["--out /dev/null", "device"]),
    ("run-missing-protocol", ["run", "nothing.toml", "--out", "rec"], ["nothing.toml", "not found"]),
    ("run-protocol-is-folder", ["run", "mine", "--out", "rec"], ["mine", "it is a directory"]),
    ("run-missing-port", ["run", "plan.toml", "--out", "rec", "--stage", "/dev/ttyUSB9", "--camera",
                          "/dev/ttyUSB8", "--lamp", "/dev/ttyUSB7"], ["--stage /dev/ttyUSB9", "no such serial port"]),
    ("run-port-not-serial", ["run", "plan.toml", "--out", "rec", "--stage", "/dev/null", "--camera", "/dev/null",
                             "--lamp", "/dev/null"], ["rig: TransportError", "/dev/null"]),
    ("run-lamp-voltage-beyond-supply", ["run", "plan.toml", "--out", "rec", "--lamp-voltage", "200"],
     ["--lamp-voltage 200", "at most 132 V"]),
    ("run-lamp-voltage-negative", ["run", "plan.toml", "--out", "rec", "--lamp-voltage", "-5"],
     ["--lamp-voltage -5", "> 0 V"]),
    ("fit-csv-not-utf8", ["fit", "latin1.csv", "--model", "lambert", "--no-mcmc"],
     ["latin1.csv", "not a UTF-8 text file"]),
    ("run-partial-ports", ["run", "plan.toml", "--out", "rec", "--stage", "/dev/ttyUSB9"],
     ["--stage, --camera and --lamp"]),
    ("run-unknown-sample", ["run", "plan.toml", "--out", "rec", "--sample", "no-such-model"],
     ["unknown model", "no-such-model"]),
    ("plan-folder", ["plan", "mine"], ["mine", "it is a directory"]),
    ("plan-missing", ["plan", "nothing.toml"], ["nothing.toml", "not found"]),
    ("fit-missing-data", ["fit", "nothing.csv", "--model", "lambert"], ["nothing.csv", "no such file or recording folder"]),
    ("fit-folder-not-recording", ["fit", "mine", "--model", "lambert"], ["mine", "not a recording"]),
    ("fit-unknown-model", ["fit", "data.csv", "--model", "no-such-model"], ["unknown model", "no-such-model"]),
    ("fit-prior-outside-range", ["fit", "data.csv", "--model", "oren-nayar", "--no-mcmc", "--prior",
                                 "sigma=uniform:100:120"], ["--prior sigma=uniform:100:120", "physical range is [0, 90]"]),
    ("fit-texture-prior-negative", ["fit", "data.csv", "--model", "oren-nayar", "--no-mcmc", "--alignment",
                                    "texture_slope", "--prior", "texture_slope=uniform:4:5"],
     ["--prior texture_slope=uniform:4:5", "physical range is [0, 3]"]),
    ("fit-alignment-unknown", ["fit", "data.csv", "--model", "oren-nayar", "--no-mcmc", "--alignment", "texture"],
     ["--alignment", "'texture'", "texture_slope"]),
    ("fit-out-file", ["fit", "data.csv", "--model", "lambert", "--no-mcmc", "--out", "notes.txt"],
     ["--out notes.txt", "an existing file"]),
    ("fit-out-device", ["fit", "data.csv", "--model", "lambert", "--no-mcmc", "--out", "/dev/null"],
     ["--out /dev/null", "device"]),
    ("fit-out-empty", ["fit", "data.csv", "--model", "lambert", "--no-mcmc", "--out", ""], ["--out ''"]),
    ("fit-out-foreign-folder", ["fit", "data.csv", "--model", "lambert", "--no-mcmc", "--out", "mine"],
     ["--out mine", "already holds files", "--overwrite"]),
    ("fit-overwrite-foreign-folder", ["fit", "data.csv", "--model", "lambert", "--no-mcmc", "--out", "mine",
                                      "--overwrite"], ["--out mine", "no gonio fit result"]),
    ("report-not-a-result", ["report", "mine"], ["mine", "no result.json"]),
    ("report-out-file", ["report", "result", "--out", "notes.txt"], ["--out notes.txt", "an existing file"]),
    ("report-out-empty", ["report", "result", "--out", ""], ["--out ''"]),
    ("demo-out-symlink", ["demo", "--out", "link"], ["--out link", "symbolic link"]),
    ("demo-out-file", ["demo", "--out", "notes.txt"], ["--out notes.txt", "an existing file"]),
    ("demo-out-device", ["demo", "--out", "/dev/null"], ["--out /dev/null", "device"]),
    ("demo-out-foreign-folder", ["demo", "--out", "mine"], ["--out mine", "not a gonio demo folder"]),
    ("demo-out-empty", ["demo", "--out", ""], ["--out ''"]),
    ("tables-output-folder", ["tables", "build", "oren-nayar", "--out", "mine"], ["--out mine", "is a folder"]),
    ("tables-output-foreign-file", ["tables", "build", "oren-nayar", "--output", "notes.txt"],
     ["--out notes.txt", "not a table written by"]),
    ("tables-unknown", ["tables", "build", "no-such-table"], ["unknown table", "no-such-table"]),
]


@pytest.mark.parametrize("argv, expected", [case[1:] for case in BAD_ARGUMENTS],
                         ids=[case[0] for case in BAD_ARGUMENTS])
def test_bad_arguments_are_one_line_and_change_nothing(argv, expected, workspace, capsys):
    line = run_refused(argv, workspace, capsys)
    for part in expected:
        assert part in line, line


# --------------------------------------------------------------------------- the catch-all
def _raise(error: BaseException):
    def run(args):
        raise error

    return run


@pytest.mark.parametrize("error, code, expected", [
    (RuntimeError("boom"), 1, "gonio: error: RuntimeError: boom (run with --debug for the traceback)"),
    (ZeroDivisionError("division by zero"), 1, "ZeroDivisionError: division by zero (run with --debug"),
    (PermissionError(errno.EACCES, "Permission denied", "/data/p.toml"), 2, "gonio: error: /data/p.toml: Permission denied"),
    (OSError(errno.ENOSPC, "No space left on device", "/data/out/result.json"), 2,
     "gonio: error: /data/out/result.json: No space left on device"),
    (IsADirectoryError(errno.EISDIR, "Is a directory", "/data/x"), 2, "/data/x: Is a directory"),
    (FileExistsError(errno.EEXIST, "File exists", "/data/x"), 2, "/data/x: File exists"),
    (RuntimeError("first line\nsecond line"), 1, "RuntimeError: first line second line"),
])
def test_unhandled_errors_become_one_line_with_an_exit_code(error, code, expected, monkeypatch, tmp_path, capsys):
    monkeypatch.setattr("gonio.cli.plan._run", _raise(error))
    line = run_refused(["plan", "x.toml"], tmp_path, capsys, code=code)
    assert expected in line, line


def test_driver_errors_are_bad_input_without_a_traceback(monkeypatch, tmp_path, capsys):
    from drivers.errors import TransportError

    monkeypatch.setattr("gonio.cli.plan._run", _raise(TransportError("cannot open stage (/dev/ttyUSB9)")))
    line = run_refused(["plan", "x.toml"], tmp_path, capsys, code=2)
    assert line == "gonio: error: rig: TransportError: cannot open stage (/dev/ttyUSB9)"


def test_debug_shows_the_traceback_and_ctrl_c_is_130(monkeypatch, capsys):
    monkeypatch.setattr("gonio.cli.plan._run", _raise(RuntimeError("boom")))
    with pytest.raises(RuntimeError, match="boom"):
        main(["--debug", "plan", "x.toml"])
    monkeypatch.setattr("gonio.cli.plan._run", _raise(KeyboardInterrupt()))
    assert main(["plan", "x.toml"]) == 130
    assert capsys.readouterr().err == "gonio: interrupted\n"


def test_importing_gonio_does_not_import_the_drivers():
    import subprocess
    import sys

    code = "import sys, gonio, gonio.cli; print(any(m.startswith('drivers') for m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == "False", done.stderr


# --------------------------------------------------------------------------- fast paths stay fast
def test_the_largest_allowed_plan_is_expanded_in_seconds():
    """200,000 points is the limit because a plan that size is still quick to expand and
    estimate (about 1 s on one core): the limit is never the thing that hangs."""
    text = MINIMAL.replace(THETA_VIEW, "theta_i = {start = 0, stop = 89.5, step = 0.5}\n"
                                       "view = {start = -90, stop = 90, step = 1}\nrepeats = 5")
    protocol = protocols.loads(text)
    assert protocols.planned_point_count(protocol) == 180 * 181 * 5
    with deadline(20.0):  # generous for a loaded 2-core machine
        plan = protocols.plan(protocol)
    assert len(plan.points) + len(plan.refused) == 180 * 181 * 5
    assert np.isfinite(plan.estimated_seconds)
