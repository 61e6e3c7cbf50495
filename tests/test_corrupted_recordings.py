"""A damaged or edited recording is refused with the file, line and column named, never
reduced to NaN values or a changed result (issue: corrupted recordings accepted)."""
from __future__ import annotations

import csv
import io
import os
import shutil

import pytest

from gonio import data
from gonio.reduction import reduce_recording

from .emulated_recording import record

PROTOCOL = """
[protocol]
name = "corruption"
[sample]
label = "plaster"
[[block]]
theta_i = 30
phi_i = 0
view = [-40, -20, 0, 20, 40]
[reference]
label = "standard"
reflectance = 0.99
geometries = [[30, 0, -10]]
"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return record(tmp_path_factory.mktemp("corrupt") / "rec", PROTOCOL, "oren-nayar:rho=0.9,sigma=20", seed=3)


def _with_cell(recording, tmp_path, column: str, value: str, status_ok_row: int = 1):
    """A copy of the recording with one cell of the ``status_ok_row``-th measured row replaced."""
    copy = tmp_path / "copy"
    shutil.copytree(recording, copy)
    text = (copy / "points.csv").read_text()
    rows = list(csv.reader(io.StringIO(text, newline="")))
    header = rows[0]
    ok_rows = [k for k, row in enumerate(rows[1:], start=1) if row[header.index("status")] == "ok"]
    target = ok_rows[status_ok_row]
    rows[target][header.index(column)] = value
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    (copy / "points.csv").write_text(buffer.getvalue())
    return copy, target + 1  # the file's line number


def test_the_recording_reduces_as_measured(recording):
    assert reduce_recording(recording).theta_i.size == 5


@pytest.mark.parametrize("column, value", [
    ("exposure", "0"), ("exposure", "-0.01"), ("gain", "0"), ("roi_pixels", "0"), ("signal_rate", "nan"),
    ("signal_rate", "inf"), ("signal_rate_sigma", "-1"), ("monitor", "nan"), ("monitor", ""), ("stage_camera", "nan"),
])
def test_a_measured_row_with_an_impossible_value_is_refused_by_line_and_column(recording, tmp_path, column, value):
    copy, line = _with_cell(recording, tmp_path, column, value)
    with pytest.raises(data.RecordingError, match=f"line {line}, column '{column}'"):
        reduce_recording(copy)


def test_a_recording_with_no_points_says_so(recording, tmp_path):
    copy = tmp_path / "empty"
    shutil.copytree(recording, copy)
    header = (copy / "points.csv").read_text().split("\n", 1)[0]
    (copy / "points.csv").write_text(header + "\n")
    with pytest.raises(data.RecordingError, match="holds no points yet"):
        reduce_recording(copy)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")
def test_a_fifo_named_like_a_recording_file_is_not_opened(recording, tmp_path):
    copy = tmp_path / "fifo"
    shutil.copytree(recording, copy)
    (copy / "points.csv").unlink()
    os.mkfifo(copy / "points.csv")  # reading it would block forever
    with pytest.raises(data.RecordingError, match="not a regular file"):
        reduce_recording(copy)


def test_another_recording_s_metadata_is_refused(recording, tmp_path):
    """Another recording's metadata.json beside these points was accepted and reduced with
    its protocol: the points must be the ones its protocol plans."""
    other = record(tmp_path / "other", PROTOCOL.replace("view = [-40, -20, 0, 20, 40]", "view = [-30, 30]")
                   .replace('name = "corruption"', 'name = "other"'), "oren-nayar:rho=0.9,sigma=20", seed=4)
    copy = tmp_path / "mixed"
    shutil.copytree(recording, copy)
    shutil.copy(other / "metadata.json", copy / "metadata.json")
    with pytest.raises(data.RecordingError, match="not in the plan of the protocol.*'other'"):
        reduce_recording(copy)
