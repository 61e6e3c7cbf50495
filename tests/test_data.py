"""The recording format (gonio.data): append-only, flushed, resumable, readable without gonio."""
from __future__ import annotations

import csv
import json

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
    with pytest.raises(data.RecordingError, match="never overwrites"):
        data.RecordingWriter(tmp_path, {})
    assert len(data.read_points(tmp_path)["index"]) == 1


def test_resume_salvages_a_torn_last_line_and_reports_done_keys(tmp_path):
    w = data.RecordingWriter(tmp_path, {"run": 1})
    w.append_point(_row(0, -5.0))
    w.append_point(_row(1, 0.0, status="refused", message="too close"))
    w.append_point(_row(2, 5.0, status="error", message="timeout"))
    with open(tmp_path / "points.csv", "a") as handle:  # a crash in the middle of a write
        handle.write("3,b,0,30.0,0.0,10.0,10")
    assert len(data.read_points(tmp_path)["index"]) == 3  # the torn row is not a point
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
