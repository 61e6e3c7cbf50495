"""The recording format (gonio.data): append-only, flushed, resumable, readable without gonio."""
from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

from gonio import data


def _row(index, view, status="ok", **extra):
    row = {"index": index, "block": "b", "repeat": 0, "theta_i": 30.0, "phi_i": 0.0, "view": view,
           "theta_r": abs(view), "phi_r": 0.0 if view >= 0 else 180.0, "status": status,
           "roi_mean": 1000.5, "signal_rate": 12345.678901234567, "message": ""}
    row.update(extra)
    return row


def test_new_recording_writes_header_metadata_and_rows(tmp_path):
    w = data.RecordingWriter(tmp_path / "run", {"protocol": "p", "seed": 3})
    w.append_point(_row(0, -10.0))
    w.append_point(_row(1, 10.0, message="a, comma"))
    w.finish("complete")
    meta = data.read_metadata(tmp_path / "run")
    assert meta["status"] == "complete" and meta["seed"] == 3
    points = data.read_points(tmp_path / "run")
    np.testing.assert_array_equal(points["view"], [-10.0, 10.0])
    assert points["signal_rate"][0] == 12345.678901234567  # floats round-trip exactly
    assert np.isnan(points["roi_std"]).all()  # not given -> empty -> NaN
    # readable with nothing but the csv module
    with open(tmp_path / "run" / "points.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert rows[1]["message"] == "a, comma"


def test_existing_recording_is_never_overwritten(tmp_path):
    w = data.RecordingWriter(tmp_path, {})
    w.append_point(_row(0, 5.0))
    w.finish("complete")
    with pytest.raises(data.RecordingError, match="never overwrites"):
        data.RecordingWriter(tmp_path, {})
    assert len(data.read_points(tmp_path)["index"]) == 1


def test_one_writer_at_a_time(tmp_path):
    """While a run writes a folder, a second run or resume of it is refused, naming the
    holder; the lock goes with the writer (finished, or its process gone)."""
    import os

    w = data.RecordingWriter(tmp_path, {})
    w.append_point(_row(0, 5.0))
    with pytest.raises(data.RecordingError, match=f"written by gonio run \\(process {os.getpid()} "):
        data.RecordingWriter(tmp_path, {}, resume=True)
    w.finish("interrupted")
    resumed = data.RecordingWriter(tmp_path, {}, resume=True)
    with pytest.raises(data.RecordingError, match="written by gonio run --resume"):
        data.RecordingWriter(tmp_path, {}, resume=True)
    del resumed  # its process gone: the operating system releases the lock
    data.RecordingWriter(tmp_path, {}, resume=True).finish("complete")
    assert len(data.read_points(tmp_path)["index"]) == 1


def test_resume_salvages_a_torn_last_line_and_reports_done_keys(tmp_path):
    w = data.RecordingWriter(tmp_path, {"run": 1})
    w.append_point(_row(0, -5.0))
    w.append_point(_row(1, 0.0, status="refused", message="too close"))
    w.append_point(_row(2, 5.0, status="error", message="timeout"))
    with open(tmp_path / "points.csv", "a") as handle:  # a crash in the middle of a write
        handle.write("3,b,0,30.0,0.0,10.0,10")
    assert len(data.read_points(tmp_path)["index"]) == 3  # the torn row is not a point
    del w  # the crashed process is gone, and its lock on the folder with it
    resumed = data.RecordingWriter(tmp_path, {"run": 2}, resume=True)
    assert (tmp_path / "points.partial").read_text().startswith("3,b,0,30.0")
    keys = resumed.done_keys()
    assert data.point_key("b", 0, 30.0, 0.0, -5.0) in keys
    assert data.point_key("b", 0, 30.0, 0.0, 0.0) in keys       # refused is final
    assert data.point_key("b", 0, 30.0, 0.0, 5.0) not in keys   # error is retried
    meta = json.loads((tmp_path / "metadata.json").read_text())
    assert meta["run"] == 1 and meta["resumes"] == [{"run": 2}] and meta["status"] == "running"


def test_resume_without_recording_and_bad_rows_are_clear_errors(tmp_path):
    with pytest.raises(data.RecordingError, match="no recording to resume"):
        data.RecordingWriter(tmp_path / "none", {}, resume=True)
    w = data.RecordingWriter(tmp_path / "r", {})
    with pytest.raises(data.RecordingError, match="unknown recording columns"):
        w.append_point({"index": 0, "colour": "red"})
    with open(tmp_path / "r" / "points.csv", "a") as handle:
        handle.write(",".join(["x"] * len(data.COLUMNS)) + "\n")
    with pytest.raises(data.RecordingError, match="line 2, column 'index'"):
        data.read_points(tmp_path / "r")


def test_darks_round_trip(tmp_path):
    w = data.RecordingWriter(tmp_path, {})
    w.append_dark({"after_index": -1, "exposure": 0.02, "gain": 1.0, "roi_mean": 100.25, "roi_std": 3.5, "roi_pixels": 400})
    darks = data.read_darks(tmp_path)
    assert darks["after_index"][0] == -1 and darks["roi_mean"][0] == 100.25


def test_data_format_doc_lists_the_columns_the_code_writes():
    """docs/data-format.md shows the column tables generated from data.COLUMNS / DARK_COLUMNS."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parent.parent / "docs" / "data-format.md").read_text()
    assert data.column_table(data.COLUMNS) in doc
    assert data.column_table(data.DARK_COLUMNS) in doc


# ----------------------------------------------------------------------------- safety
def test_a_new_recording_refuses_a_folder_with_any_recording_file_and_changes_nothing(tmp_path):
    """The issue's case: --out into a folder without points.csv replaced the user's
    metadata.json and appended to their darks.csv."""
    for name in data.RECORDING_FILES:
        folder = tmp_path / name.replace(".", "_")
        folder.mkdir()
        (folder / name).write_text("the user's own file\n")
        with pytest.raises(data.RecordingError, match=f"already holds {name}"):
            data.RecordingWriter(folder, {"protocol": "p"})
        assert sorted(p.name for p in folder.iterdir()) == [name]
        assert (folder / name).read_text() == "the user's own file\n"
    with pytest.raises(data.RecordingError, match="not a folder"):
        (tmp_path / "file").write_text("x")
        data.RecordingWriter(tmp_path / "file", {})


def test_metadata_gets_the_permissions_of_the_csv_files_beside_it(tmp_path):
    import os
    import stat

    old = os.umask(0o022)
    try:
        data.RecordingWriter(tmp_path / "run", {})
    finally:
        os.umask(old)
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in (tmp_path / "run").iterdir()}
    assert modes == {"metadata.json": 0o644, "points.csv": 0o644, "darks.csv": 0o644}


def test_a_failed_metadata_write_leaves_no_temporary_file(tmp_path, monkeypatch):
    import errno
    import os

    writer = data.RecordingWriter(tmp_path / "run", {})

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError):
        writer.finish("complete")
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["darks.csv", "metadata.json", "points.csv"]
    assert data.read_metadata(tmp_path / "run")["status"] == "running"  # the last good state


def test_a_deleted_darks_file_is_recreated_with_its_header_on_resume(tmp_path):
    w = data.RecordingWriter(tmp_path, {})
    w.append_point(_row(0, 5.0))
    (tmp_path / "darks.csv").unlink()
    del w  # its process gone, and its lock with it
    resumed = data.RecordingWriter(tmp_path, {}, resume=True)
    resumed.append_dark({"after_index": 0, "exposure": 0.02, "gain": 1.0, "roi_mean": 100.0, "roi_std": 1.0,
                         "roi_pixels": 9})
    assert data.read_darks(tmp_path)["roi_mean"].tolist() == [100.0]


def test_unreadable_rows_and_files_name_the_file_and_the_line(tmp_path):
    w = data.RecordingWriter(tmp_path / "r", {})
    w.append_point(_row(0, 5.0))
    with open(tmp_path / "r" / "points.csv", "a") as handle:
        handle.write("5,block\n")  # a short row
    with pytest.raises(data.RecordingError, match=r"points.csv, line 3: the row has fewer fields"):
        data.read_points(tmp_path / "r")
    (tmp_path / "r" / "points.csv").write_bytes((tmp_path / "r" / "points.csv").read_bytes()[:-8] + b"\xff\xfe\n")
    with pytest.raises(data.RecordingError, match=r"points.csv: not a UTF-8 text file"):
        data.read_points(tmp_path / "r")


def test_text_cells_that_look_like_formulas_are_escaped_and_read_back(tmp_path):
    """OWASP CSV injection: a cell starting with = + - @ is prefixed with ' in the file
    (a spreadsheet shows text, runs nothing) and gonio reads the original back."""
    w = data.RecordingWriter(tmp_path, {})
    names = ["=HYPERLINK(\"x\")", "+1", "-2 deg", "@sum", "'quoted", "plain"]
    for k, name in enumerate(names):
        w.append_point(_row(k, float(k), block=name))
    with open(tmp_path / "points.csv", newline="") as handle:
        raw = [r["block"] for r in csv.DictReader(handle)]
    assert raw == ["'=HYPERLINK(\"x\")", "'+1", "'-2 deg", "'@sum", "''quoted", "plain"]
    assert data.read_points(tmp_path)["block"].tolist() == names


def test_a_recording_of_the_earlier_format_is_read_but_not_resumed(tmp_path):
    old = [name for name, _, _ in data.COLUMNS if name not in ("flags", "frames_saturated", "frame_rate_std",
                                                                  "monitor", "session")]
    (tmp_path / "metadata.json").write_text("{}")
    (tmp_path / "darks.csv").write_text(",".join(n for n, _, _ in data.DARK_COLUMNS if n != "monitor") + "\n")
    row = {"index": "0", "block": "b", "repeat": "0", "theta_i": "30", "phi_i": "0", "view": "10", "status": "ok"}
    (tmp_path / "points.csv").write_text(",".join(old) + "\n" + ",".join(row.get(n, "") for n in old) + "\n")
    points = data.read_points(tmp_path)
    assert points["view"].tolist() == [10.0] and points["flags"].tolist() == [""] and np.isnan(points["monitor"][0])
    with pytest.raises(data.RecordingError, match="another format cannot be resumed"):
        data.RecordingWriter(tmp_path, {}, resume=True)


@pytest.mark.parametrize("separator", ["\r", "\n", "\r\n", "\v", "\f", "\x1c", "\x1d", "\x1e", "\x85", "\u2028",
                                       "\u2029"])
def test_text_with_a_line_separator_round_trips(tmp_path, separator):
    """A block name or message may hold any of the characters str.splitlines splits at:
    the row stays one row (csv quotes what it must), read back as written, readable by the
    csv module alone."""
    name = f"sweep{separator}A"
    w = data.RecordingWriter(tmp_path, {})
    w.append_point(_row(0, -10.0, block=name, message=f"note{separator}2"))
    w.append_point(_row(1, 10.0))
    w.finish("complete")
    points = data.read_points(tmp_path, as_arrays=False)
    assert [p["block"] for p in points] == [name, "b"]
    assert points[0]["message"] == f"note{separator}2"
    with open(tmp_path / "points.csv", newline="") as handle:
        assert [row["block"] for row in csv.DictReader(handle)] == [name, "b"]


@pytest.mark.parametrize("name", ["in\u2028plane", "plane\rsweep", "a\x1eb", "bell\x07"])
def test_a_protocol_name_across_a_line_separator_is_refused_at_load(name):
    """Names end up in the recording and the reports, one line each: a block name, sample
    or reference label holding a control character or a line separator is refused when the
    protocol is loaded, naming the field and the character (the recording's own format
    keeps such text in one cell, above, for recordings made before)."""
    from gonio import protocols

    for field, table in (("block[0].name", "[[block]]\nname = {}\ntheta_i = 30\nphi_i = 0\nview = [0]\n"),
                         ("sample.label", None)):
        if table is None:
            text = f'[protocol]\nname = "p"\n[sample]\nlabel = {json.dumps(name)}\n[[block]]\ntheta_i = 30\nphi_i = 0\nview = [0]\n'
        else:
            text = '[protocol]\nname = "p"\n[sample]\nlabel = "s"\n' + table.format(json.dumps(name))
        with pytest.raises(protocols.ProtocolError, match=f"field '{re.escape(field)}': expected text on one line"):
            protocols.loads(text, source="names.toml")


def test_a_writer_in_another_process_holds_the_folder_until_it_dies(tmp_path):
    """Two processes on one recording (two 'gonio run --resume' of one folder recorded
    points twice): the second is refused while the first lives, and a kill -9 of the first
    frees the folder for a resume."""
    import signal
    import subprocess
    import sys

    data.RecordingWriter(tmp_path, {}).finish("interrupted")
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time; from gonio import data; w = data.RecordingWriter(sys.argv[1], {}, resume=True); "
        "print('holding', flush=True); time.sleep(60)"), str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "holding"
        with pytest.raises(data.RecordingError, match=f"gonio run --resume \\(process {holder.pid} "):
            data.RecordingWriter(tmp_path, {}, resume=True)
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait(timeout=30)
    data.RecordingWriter(tmp_path, {}, resume=True).finish("complete")


def test_a_recording_that_cannot_start_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    """A full disk while a new recording writes its headers used to leave a folder that a
    new run refused (it 'already holds' a recording) and a resume refused too (no
    recording): the files the start wrote are removed, and the error says so. An existing
    recording is never touched by a refused start."""
    import errno

    real = data._write_json_atomic

    def full_disk(path, payload):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(data, "_write_json_atomic", full_disk)
    with pytest.raises(data.RecordingError, match="No space left on device.*nothing was recorded"):
        data.RecordingWriter(tmp_path / "new", {})
    assert list((tmp_path / "new").iterdir()) == []
    monkeypatch.setattr(data, "_write_json_atomic", real)
    w = data.RecordingWriter(tmp_path / "new", {})  # the folder is usable at once
    w.append_point(_row(0, 5.0))
    w.finish("complete")
    with pytest.raises(data.RecordingError, match="already holds"):
        data.RecordingWriter(tmp_path / "new", {})
    assert len(data.read_points(tmp_path / "new")["index"]) == 1  # the refused start removed nothing


def test_a_dangling_link_named_like_a_recording_file_is_not_written_through(tmp_path):
    """A symbolic link 'points.csv' pointing outside the folder, to nothing yet, passed the
    'already holds a recording' check and gonio wrote through it, outside the folder."""
    outside = tmp_path / "elsewhere.csv"
    folder = tmp_path / "rec"
    folder.mkdir()
    (folder / "points.csv").symlink_to(outside)
    with pytest.raises(data.RecordingError, match="already holds points.csv"):
        data.RecordingWriter(folder, {})
    assert not outside.exists()
