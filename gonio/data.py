"""Recordings: the open, self-describing on-disk format of a measurement run.

A recording is a folder:

``metadata.json``
    Written once when the run starts (and rewritten atomically when it resumes or ends):
    the protocol text, sample, rig and emulator configuration with seed, software
    versions, start/end times and run status.
``points.csv``
    One row per measured point, appended and flushed (and fsync'd) as soon as the point is
    measured, so a crash loses at most the point being measured.  Plain CSV with a header
    row; every column is documented in :data:`COLUMNS` and docs/data-format.md.
``darks.csv``
    One row per dark frame, appended the same way.

Anyone can read a recording without gonio (``pandas.read_csv``, a spreadsheet, ``csv``).
:func:`read_points` returns the rows as numpy arrays; :class:`RecordingWriter` is the
appender used by :mod:`gonio.acquisition` and the place that makes resumption safe: on
reopening it moves an incomplete trailing line (a crash in the middle of a write) into
``points.partial`` instead of deleting it, and reports the point keys already measured.
"""
from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

__all__ = [
    "COLUMNS",
    "DARK_COLUMNS",
    "RecordingError",
    "RecordingWriter",
    "read_points",
    "read_darks",
    "read_metadata",
    "point_key",
]

#: Columns of points.csv: (name, unit, description).
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("index", "-", "index of the point in the protocol's plan"),
    ("block", "-", "name of the protocol block"),
    ("repeat", "-", "repeat number within the block (0-based)"),
    ("theta_i", "deg", "lamp polar angle (planned)"),
    ("phi_i", "deg", "lamp azimuth from the camera's swing plane (planned)"),
    ("view", "deg", "signed camera angle (planned; + on the azimuth-0 side)"),
    ("theta_r", "deg", "viewing polar angle, sample frame"),
    ("phi_r", "deg", "viewing azimuth, sample frame (0 or 180)"),
    ("status", "-", "ok, refused (rig refused the move) or error"),
    ("roi_mean", "DN", "mean pixel value in the region of interest"),
    ("roi_std", "DN", "standard deviation of the pixels in the region of interest"),
    ("roi_pixels", "-", "number of pixels in the region of interest"),
    ("saturated", "-", "saturated pixels in the region of interest"),
    ("exposure", "s", "exposure time"),
    ("gain", "-", "camera analog gain factor"),
    ("frames", "-", "frames averaged"),
    ("dark_mean", "DN", "mean of the dark frame used (same exposure and ROI)"),
    ("dark_std", "DN", "standard deviation of that dark ROI"),
    ("signal_rate", "DN/s", "dark-subtracted ROI mean per unit exposure time"),
    ("signal_rate_sigma", "DN/s", "1-sigma uncertainty of signal_rate from the CCD noise model"),
    ("lamp_voltage", "V", "measured lamp supply voltage"),
    ("lamp_current", "A", "measured lamp supply current"),
    ("stage_camera", "deg", "camera axis read back after the move"),
    ("stage_lamp_theta", "deg", "lamp polar axis read back"),
    ("stage_lamp_phi", "deg", "lamp azimuth axis read back"),
    ("instrument_time", "s", "instrument clock at the end of the point"),
    ("wall_time", "-", "ISO 8601 wall-clock time at the end of the point"),
    ("message", "-", "reason for a refused or failed point, else empty"),
)

#: Columns of darks.csv.
DARK_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("after_index", "-", "plan index of the last point measured before this dark frame (-1 at start)"),
    ("exposure", "s", "exposure time"),
    ("gain", "-", "camera analog gain factor"),
    ("roi_mean", "DN", "mean of the dark ROI"),
    ("roi_std", "DN", "standard deviation of the dark ROI"),
    ("roi_pixels", "-", "pixels in the ROI"),
    ("instrument_time", "s", "instrument clock"),
    ("wall_time", "-", "ISO 8601 wall-clock time"),
)

_NAMES = tuple(c[0] for c in COLUMNS)
_DARK_NAMES = tuple(c[0] for c in DARK_COLUMNS)
_TEXT = {"block", "status", "wall_time", "message"}
_INT = {"index", "repeat", "roi_pixels", "saturated", "frames", "after_index"}


class RecordingError(ValueError):
    """A recording folder is missing files or holds rows that do not parse."""


def point_key(block: str, repeat: int, theta_i: float, phi_i: float, view: float) -> tuple:
    """Identity of a planned point; rows with the same key are the same measurement."""
    return (str(block), int(repeat), round(float(theta_i), 6), round(float(phi_i), 6), round(float(view), 6))


def _fsync_append(path: Path, text: str) -> None:
    with open(path, "a", encoding="utf-8", newline="") as handle:
        handle.write(text)
        handle.flush()
        os.fsync(handle.fileno())


def _row_text(names: tuple[str, ...], row: Mapping[str, Any]) -> str:
    unknown = set(row) - set(names)
    if unknown:
        raise RecordingError(f"unknown recording columns {sorted(unknown)}; expected some of {list(names)}")
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["" if row.get(n) is None else _format(row.get(n)) for n in names])
    return buffer.getvalue()


def _format(value: Any) -> str:
    if isinstance(value, float):
        return repr(value)  # shortest exact round-trip representation
    return str(value)


def _write_json_atomic(path: Path, payload: Mapping) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".metadata-", suffix=".json")
    with os.fdopen(fd, "w", encoding="utf-8") as handle:
        json.dump(payload, handle, indent=2, default=str)
        handle.write("\n")
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


@dataclass
class RecordingWriter:
    """Append-only writer of a recording folder (crash-safe, resumable).

    Parameters
    ----------
    folder : path
        Recording folder; created if missing.
    metadata : mapping
        Run metadata (protocol text, configuration, versions).  On a new recording it is
        written as metadata.json; on resume the stored metadata is kept and ``metadata``
        is merged under ``"resumed"`` entries.
    resume : bool
        Continue an existing recording.  Without it, an existing non-empty recording is an
        error (nothing is ever overwritten).
    """

    folder: Path
    metadata: Mapping[str, Any]
    resume: bool = False

    def __post_init__(self) -> None:
        self.folder = Path(self.folder)
        self.points_path = self.folder / "points.csv"
        self.darks_path = self.folder / "darks.csv"
        self.metadata_path = self.folder / "metadata.json"
        exists = self.points_path.exists() and self.points_path.stat().st_size > 0
        if exists and not self.resume:
            raise RecordingError(
                f"{self.folder} already holds a recording; use resume to continue it or choose "
                "another folder (gonio never overwrites measured data)"
            )
        if self.resume and not exists:
            raise RecordingError(f"{self.folder}: no recording to resume (points.csv missing or empty)")
        self.folder.mkdir(parents=True, exist_ok=True)
        if exists:
            self._salvage_partial_line(self.points_path, "points.partial")
            if self.darks_path.exists():
                self._salvage_partial_line(self.darks_path, "darks.partial")
            stored = read_metadata(self.folder)
            stored.setdefault("resumes", []).append(dict(self.metadata))
            self._metadata = stored
        else:
            self._metadata = dict(self.metadata)
            _fsync_append(self.points_path, ",".join(_NAMES) + "\n")
            _fsync_append(self.darks_path, ",".join(_DARK_NAMES) + "\n")
        self._metadata["status"] = "running"
        _write_json_atomic(self.metadata_path, self._metadata)

    def _salvage_partial_line(self, path: Path, partial_name: str) -> None:
        data = path.read_bytes()
        if data and not data.endswith(b"\n"):
            cut = data.rfind(b"\n") + 1
            _fsync_append(self.folder / partial_name, data[cut:].decode("utf-8", "replace") + "\n")
            with open(path, "r+b") as handle:
                handle.truncate(cut)
                handle.flush()
                os.fsync(handle.fileno())

    def done_keys(self) -> set[tuple]:
        """Keys of points already recorded with a final status (ok or refused)."""
        rows = read_points(self.folder, as_arrays=False)
        return {
            point_key(r["block"], r["repeat"], r["theta_i"], r["phi_i"], r["view"])
            for r in rows
            if r["status"] in ("ok", "refused")
        }

    def append_point(self, row: Mapping[str, Any]) -> None:
        """Append one measured point and flush it to disk before returning."""
        _fsync_append(self.points_path, _row_text(_NAMES, row))

    def append_dark(self, row: Mapping[str, Any]) -> None:
        """Append one dark-frame row and flush it to disk."""
        _fsync_append(self.darks_path, _row_text(_DARK_NAMES, row))

    def finish(self, status: str, **extra: Any) -> None:
        """Record the run's final status ("complete", "interrupted", "failed") in metadata."""
        self._metadata["status"] = status
        self._metadata.update(extra)
        _write_json_atomic(self.metadata_path, self._metadata)


def read_metadata(folder: str | Path) -> dict:
    """The metadata.json of a recording as a dict."""
    path = Path(folder) / "metadata.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RecordingError(f"{folder}: not a recording (metadata.json missing)") from None
    except json.JSONDecodeError as error:
        raise RecordingError(f"{path}: not valid JSON ({error})") from None


def _read_csv(path: Path, names: tuple[str, ...], as_arrays: bool):
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RecordingError(f"{path.parent}: not a recording ({path.name} missing)") from None
    lines = text.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines = lines[:-1]  # a row still being written is not a measurement yet
    reader = csv.DictReader(lines)
    if reader.fieldnames is None or tuple(reader.fieldnames) != names:
        raise RecordingError(f"{path}: header {reader.fieldnames} is not the expected {list(names)}")
    rows = []
    for number, raw in enumerate(reader, start=2):
        row = {}
        for name in names:
            value = raw[name]
            if name in _TEXT:
                row[name] = value
            elif value == "":
                row[name] = np.nan if name not in _INT else -1
            else:
                try:
                    row[name] = int(value) if name in _INT else float(value)
                except ValueError:
                    raise RecordingError(f"{path}, line {number}, column '{name}': expected a number, got {value!r}") from None
        rows.append(row)
    if not as_arrays:
        return rows
    return {
        name: np.array([r[name] for r in rows], dtype=object if name in _TEXT else (int if name in _INT else float))
        for name in names
    }


def read_points(folder: str | Path, as_arrays: bool = True):
    """Rows of points.csv: a dict of column arrays (default) or a list of row dicts."""
    return _read_csv(Path(folder) / "points.csv", _NAMES, as_arrays)


def read_darks(folder: str | Path, as_arrays: bool = True):
    """Rows of darks.csv: a dict of column arrays (default) or a list of row dicts."""
    return _read_csv(Path(folder) / "darks.csv", _DARK_NAMES, as_arrays)


def column_table(columns: Iterable[tuple[str, str, str]] = COLUMNS) -> str:
    """Markdown table of columns (used to keep docs/data-format.md in step with the code)."""
    lines = ["| column | unit | meaning |", "|---|---|---|"]
    lines += [f"| `{n}` | {u} | {d} |" for n, u, d in columns]
    return "\n".join(lines)
