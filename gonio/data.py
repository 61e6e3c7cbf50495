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
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from .files import FolderBusy, FolderLock, lock_folder, unlock_folder, write_atomic

__all__ = [
    "check_measured_rows",
    "COLUMNS",
    "DARK_COLUMNS",
    "RecordingError",
    "RecordingWriter",
    "read_points",
    "read_darks",
    "read_metadata",
    "point_key",
    "row_key",
    "experiment_differences",
    "duplicated_rows",
    "RECORDING_FILES",
    "EMULATED_SAMPLE",
]

#: Key of a reduced recording's metadata (and its datasets') naming the emulated sample it
#: measured: ``{"spec": ..., "parameters": {...}}``, the truth a fit is held against
#: (gonio.fitting.truth); absent for a real rig's recording.
EMULATED_SAMPLE = "emulated_sample"

#: Columns of points.csv: (name, unit, description).
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("index", "-", "index of the point in the protocol's plan (negative: reference standard and lamp checks)"),
    ("block", "-", "name of the protocol block ('reference standard', 'lamp check' for the extra measurements)"),
    ("repeat", "-", "repeat number within the block (0-based; the check number for lamp checks)"),
    ("mounting", "-", "mounting of the sample the point was measured in (0-based; empty for the reference standard)"),
    ("rotation", "deg", "rotation of the sample about its normal in that mounting as the protocol set it "
                        "(empty: the operator's choice)"),
    ("theta_i", "deg", "lamp polar angle (planned)"),
    ("phi_i", "deg", "lamp azimuth from the camera's swing plane (planned)"),
    ("view", "deg", "signed camera angle (planned; + on the azimuth-0 side)"),
    ("theta_r", "deg", "viewing polar angle, sample frame (planned)"),
    ("phi_r", "deg", "viewing azimuth, sample frame (0 or 180)"),
    ("status", "-", "ok, refused (rig refused the move) or error (measurement failed; see message)"),
    ("flags", "-", "';'-separated quality flags of an ok point: saturated (excluded from fits), low_signal"),
    ("roi_mean", "DN", "mean pixel value in the region of interest (mean over the frames)"),
    ("roi_std", "DN", "standard deviation of the pixels in the region of interest (rms over the frames)"),
    ("roi_pixels", "-", "number of pixels in the region of interest"),
    ("saturated", "-", "saturated pixels in the region of interest of the frames used"),
    ("exposure", "s", "exposure time"),
    ("gain", "-", "camera analog gain factor"),
    ("frames", "-", "frames averaged (all at this exposure)"),
    ("frames_saturated", "-", "exposures left out because they saturated (HDR brackets)"),
    ("dark_mean", "DN", "mean of the dark frame used (same exposure and ROI)"),
    ("dark_std", "DN", "standard deviation of that dark ROI"),
    ("signal_rate", "DN/s", "dark-subtracted ROI mean per unit exposure time and gain"),
    ("signal_rate_sigma", "DN/s", "quick 1-sigma estimate of signal_rate from the ROI statistics alone"),
    ("frame_rate_std", "DN/s", "standard deviation of the per-frame signal rates (frames > 1), else empty"),
    ("monitor", "V", "lamp monitor reading over the exposure (mean over the frames); empty without a monitor"),
    ("lamp_voltage", "V", "measured lamp supply voltage"),
    ("lamp_current", "A", "measured lamp supply current"),
    ("stage_camera", "deg", "camera axis read back after the move (the reduction uses it)"),
    ("stage_lamp_theta", "deg", "lamp polar axis read back"),
    ("stage_lamp_phi", "deg", "lamp azimuth axis read back"),
    ("session", "-", "0 for the first run of the recording, k for its k-th resume"),
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
    ("monitor", "V", "lamp monitor reading during the dark exposure (the lamp stays on); empty without one"),
    ("instrument_time", "s", "instrument clock"),
    ("wall_time", "-", "ISO 8601 wall-clock time"),
)

#: Files of a recording folder (a new recording refuses a folder holding any of them).
RECORDING_FILES = ("metadata.json", "points.csv", "darks.csv", "points.partial", "darks.partial")

_NAMES = tuple(c[0] for c in COLUMNS)
_DARK_NAMES = tuple(c[0] for c in DARK_COLUMNS)
_TEXT = {"block", "status", "flags", "wall_time", "message"}
_INT = {"index", "repeat", "mounting", "roi_pixels", "saturated", "frames", "frames_saturated", "session", "after_index"}
#: A text cell starting with one of these is prefixed with "'" so that a spreadsheet
#: shows it as text instead of running it as a formula (OWASP, "CSV Injection"); the
#: quote itself is escaped the same way, so reading strips exactly one.
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r", "'")


class RecordingError(ValueError):
    """A recording folder is missing files, holds rows that do not parse, or cannot be written."""


def point_key(block: str, repeat: int, theta_i: float, phi_i: float, view: float, mounting: int = 0) -> tuple:
    """Identity of a planned point; rows with the same key are the same measurement.

    ``mounting`` is the sample's mounting (a missing one, -1, is the first: recordings of
    older formats and the reference standard's rows).
    """
    return (str(block), int(repeat), round(float(theta_i), 6), round(float(phi_i), 6), round(float(view), 6),
            max(int(mounting), 0))


def row_key(row: Mapping[str, Any]) -> tuple:
    """:func:`point_key` of a row of points.csv (as :func:`read_points` gives it)."""
    return point_key(row["block"], row["repeat"], row["theta_i"], row["phi_i"], row["view"], row.get("mounting", 0))


def _fsync_append(path: Path, text: str) -> None:
    with open(path, "a", encoding="utf-8", newline="") as handle:
        handle.write(text)
        handle.flush()
        os.fsync(handle.fileno())


def _row_text(names: tuple[str, ...], row: Mapping[str, Any]) -> str:
    unknown = set(row) - set(names)
    if unknown:
        raise RecordingError(f"unknown recording columns {sorted(unknown)}; expected some of {list(names)}")
    cells = ["" if row.get(n) is None else _format(row.get(n), n in _TEXT) for n in names]
    buffer = io.StringIO()
    # The csv module quotes a field holding the line terminator ("\n") but not a lone "\r",
    # which a reader of a file opened with newline="" takes for a row's end: such a row is
    # written with every field quoted.
    quoting = csv.QUOTE_ALL if any("\r" in cell for cell in cells) else csv.QUOTE_MINIMAL
    csv.writer(buffer, lineterminator="\n", quoting=quoting).writerow(cells)
    return buffer.getvalue()


def _format(value: Any, text: bool = False) -> str:
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)  # shortest exact round-trip representation
    out = str(value)
    if text and out.startswith(_FORMULA_START):
        out = "'" + out
    return out


def _unescape(value: str) -> str:
    return value[1:] if value.startswith("'") else value


def _write_json_atomic(path: Path, payload: Mapping) -> None:
    write_atomic(path, json.dumps(payload, indent=2, default=str) + "\n")


def experiment_differences(stored: Mapping[str, Any], current: Mapping[str, Any]) -> list[str]:
    """What differs between two experiment descriptions (``metadata["experiment"]``).

    Nested mappings are compared key by key; each difference is one phrase
    ``"<key>: recorded <a>, now <b>"``.

    Examples
    --------
    >>> experiment_differences({"seed": 0, "rig": {"sample": "a"}}, {"seed": 1, "rig": {"sample": "a"}})
    ['seed: recorded 0, now 1']
    """
    out: list[str] = []
    for key in sorted(set(stored) | set(current)):
        a, b = stored.get(key), current.get(key)
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            out += [f"{key}.{d}" for d in experiment_differences(a, b)]
        elif a != b:
            out.append(f"{key}: recorded {a!r}, now {b!r}")
    return out


def duplicated_rows(rows: Iterable[Mapping[str, Any]]) -> dict[tuple, list[int]]:
    """Point keys recorded more than once with a final status (ok or refused), with their CSV lines."""
    seen: dict[tuple, list[int]] = {}
    for line, r in enumerate(rows, start=2):
        if r["status"] in ("ok", "refused"):
            seen.setdefault(row_key(r), []).append(line)
    return {key: lines for key, lines in seen.items() if len(lines) > 1}


def _describe_duplicates(folder: Path, duplicates: Mapping[tuple, list[int]]) -> str:
    shown = "; ".join(f"{key[0]!r} repeat {key[1]} at theta_i={key[2]:g}, phi_i={key[3]:g}, view={key[4]:g} "
                      f"on lines {', '.join(map(str, lines))}" for key, lines in list(duplicates.items())[:3])
    more = f" and {len(duplicates) - 3} more" if len(duplicates) > 3 else ""
    return (f"{folder / 'points.csv'}: {len(duplicates)} point(s) recorded more than once ({shown}{more}); "
            "the recording mixes runs. Keep the rows you trust in a copy of the folder and reduce that")


#: A new recording's files are at most this large before its first point (the headers, the
#: initial metadata); larger ones are never removed by a start that failed.
_HEADER_BYTES_MAX = 1 << 20


def _writer_text(resume: bool) -> str:
    """Who writes the recording now: ``gonio run (process N on HOST, since TIME)``."""
    import datetime
    import socket

    started = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    return f"gonio run{' --resume' if resume else ''} (process {os.getpid()} on {socket.gethostname()}, since {started})"


def _holder(metadata_path: Path) -> str:
    """The writer a recording's metadata names, or "another process"."""
    try:
        return str(json.loads(metadata_path.read_text())["writer"])
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"


@dataclass
class RecordingWriter:
    """Append-only writer of a recording folder (crash-safe, resumable).

    Parameters
    ----------
    folder : path
        Recording folder; created if missing. A new recording refuses a folder that
        already holds any file of a recording (:data:`RECORDING_FILES`): gonio never
        overwrites or appends to files it did not write in this recording.
    metadata : mapping
        Run metadata (protocol text, configuration, versions, and under ``"experiment"``
        what must not change within a recording).  On a new recording it is written as
        metadata.json; on resume the stored metadata is kept and ``metadata`` is
        appended under ``"resumes"``.
    resume : bool
        Continue an existing recording.  It must hold the same experiment (protocol
        content, sample, rig settings, seed, lamp voltage: ``metadata["experiment"]``);
        any difference is refused with a message that names it.

    One writer at a time: the writer holds the folder's lock (:func:`gonio.files.lock_folder`)
    from its creation to :meth:`finish`, and a second writer, new or resuming, in this
    process or another, is refused with a message naming the holder.
    """

    folder: Path
    metadata: Mapping[str, Any]
    resume: bool = False

    def __post_init__(self) -> None:
        self.folder = Path(self.folder)
        self.points_path = self.folder / "points.csv"
        self.darks_path = self.folder / "darks.csv"
        self.metadata_path = self.folder / "metadata.json"
        if self.folder.exists() and not self.folder.is_dir():
            raise RecordingError(f"{self.folder} exists and is not a folder; give a folder for the recording")
        self._lock = self._take_lock()
        try:
            self._metadata = self._open_for_resume() if self.resume else self._create()
            self._metadata["status"] = "running"
            self._metadata["writer"] = _writer_text(self.resume)
            self._write_metadata()
        except BaseException as error:
            if not self.resume:
                self._remove_started_files()
            unlock_folder(self._lock)
            if isinstance(error, OSError):
                raise RecordingError(f"cannot start the recording in {self.folder}: {error.strerror or error} "
                                     "(nothing was recorded; the files the start began are removed)") from None
            raise

    def _remove_started_files(self) -> None:
        """Remove the files a new recording that could not start wrote (a full disk in the
        middle of its headers), so that neither a new run nor a resume finds half a
        recording there; nothing measured is in them."""
        for path in getattr(self, "_started", ()):  # only files this start created
            try:
                if path.is_file() and not path.is_symlink() and path.stat().st_size <= _HEADER_BYTES_MAX:
                    path.unlink()
            except OSError:
                pass

    def _take_lock(self) -> FolderLock | None:
        """The folder's lock (:func:`gonio.files.lock_folder`), as a RecordingError naming the
        holder (from the recording's metadata) when another writer has it."""
        if self.resume and not self.folder.is_dir():
            raise RecordingError(f"{self.folder}: no recording to resume (no such folder)")
        if not self.resume:
            self._refuse_recorded_folder()  # before anything is created in it
        try:
            return lock_folder(self.folder)
        except FolderBusy:
            holder = _holder(self.metadata_path)
            raise RecordingError(f"cannot {'resume' if self.resume else 'record into'} {self.folder}: it is being "
                                 f"written by {holder}; wait for that run to end, or stop it, first (two writers "
                                 "would interleave their points)") from None
        except OSError as error:
            raise RecordingError(f"cannot create the recording folder {self.folder}: {error.strerror or error}") from None

    def _refuse_recorded_folder(self) -> None:
        # lexists: a symbolic link named like a recording file, even one pointing nowhere,
        # is refused too (gonio would write through it, outside the folder)
        present = [name for name in RECORDING_FILES if os.path.lexists(self.folder / name)]
        if present:
            raise RecordingError(
                f"{self.folder} already holds {', '.join(present)}; use resume to continue a recording or "
                "choose another folder (gonio never overwrites measured data)"
            )

    def _create(self) -> dict:
        self._refuse_recorded_folder()  # again, under the lock
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise RecordingError(f"cannot create the recording folder {self.folder}: {error.strerror or error}") from None
        self._started = [path for path in (self.points_path, self.darks_path, self.metadata_path) if not path.exists()]
        _fsync_append(self.points_path, ",".join(_NAMES) + "\n")
        _fsync_append(self.darks_path, ",".join(_DARK_NAMES) + "\n")
        return dict(self.metadata)

    def _open_for_resume(self) -> dict:
        if not (self.points_path.exists() and self.points_path.stat().st_size > 0):
            raise RecordingError(f"{self.folder}: no recording to resume (points.csv missing or empty)")
        stored = read_metadata(self.folder)
        _check_header(self.points_path, _NAMES, for_writing=True)
        differences = experiment_differences(stored.get("experiment", {}), self.metadata.get("experiment", {}))
        if differences:
            raise RecordingError(
                f"cannot resume {self.folder}: this run is a different experiment from the recording ("
                + "; ".join(differences) + "). Start a new recording in another folder"
            )
        self._salvage_partial_line(self.points_path, "points.partial")
        if self.darks_path.exists():
            _check_header(self.darks_path, _DARK_NAMES, for_writing=True)
            self._salvage_partial_line(self.darks_path, "darks.partial")
        else:
            _fsync_append(self.darks_path, ",".join(_DARK_NAMES) + "\n")
        duplicates = duplicated_rows(read_points(self.folder, as_arrays=False))
        if duplicates:
            raise RecordingError(_describe_duplicates(self.folder, duplicates))
        stored.setdefault("resumes", []).append({k: v for k, v in self.metadata.items() if k != "experiment"})
        return stored

    def _write_metadata(self) -> None:
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

    @property
    def stored_metadata(self) -> Mapping[str, Any]:
        """The recording's metadata as it is on disk (read-only view)."""
        return dict(self._metadata)

    def done_keys(self) -> set[tuple]:
        """Keys of points already recorded with a final status (ok or refused)."""
        rows = read_points(self.folder, as_arrays=False)
        return {row_key(r) for r in rows if r["status"] in ("ok", "refused")}

    def append_point(self, row: Mapping[str, Any]) -> None:
        """Append one measured point and flush it to disk before returning."""
        _fsync_append(self.points_path, _row_text(_NAMES, row))

    def append_dark(self, row: Mapping[str, Any]) -> None:
        """Append one dark-frame row and flush it to disk."""
        _fsync_append(self.darks_path, _row_text(_DARK_NAMES, row))

    def update(self, **entries: Any) -> None:
        """Add entries to metadata.json (e.g. a characterisation measured during the run)."""
        self._metadata.update(entries)
        self._write_metadata()

    def finish(self, status: str, **extra: Any) -> None:
        """Record the run's final status ("complete", "incomplete", "interrupted", "failed") in metadata
        and release the folder's lock."""
        try:
            self._metadata["status"] = status
            self._metadata.update(extra)
            self._write_metadata()
        finally:
            unlock_folder(self._lock)


def read_metadata(folder: str | Path) -> dict:
    """The metadata.json of a recording as a dict."""
    path = Path(folder) / "metadata.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RecordingError(f"{folder}: not a recording (metadata.json missing)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise RecordingError(f"{path}: not valid UTF-8 JSON ({error})") from None
    except OSError as error:
        raise RecordingError(f"{path}: cannot read ({error.strerror or error})") from None


def _read_text(path: Path) -> str:
    """The file's text as written (no newline translation: a "\r" inside a field stays).

    Only a regular file is opened: a FIFO or a device named like a recording file would
    block or stream forever."""
    try:
        if path.exists() and not path.is_file():
            raise RecordingError(f"{path}: not a regular file (a pipe, device or folder); a recording's files are "
                                 "plain files")
        with open(path, encoding="utf-8", newline="") as handle:
            return handle.read()
    except FileNotFoundError:
        raise RecordingError(f"{path.parent}: not a recording ({path.name} missing)") from None
    except UnicodeDecodeError as error:
        raise RecordingError(f"{path}: not a UTF-8 text file (byte {error.start}: {error.reason})") from None
    except OSError as error:
        raise RecordingError(f"{path}: cannot read ({error.strerror or error})") from None


def _check_header(path: Path, names: tuple[str, ...], for_writing: bool = False,
                  first_line: str | None = None) -> tuple[str, ...]:
    """The header of a recording CSV; older formats (a subset of the columns) are readable
    but cannot be appended to."""
    if first_line is None:
        first_line = _read_text(path).split("\n", 1)[0]
    header = tuple(next(csv.reader([first_line]), []))
    if header == names:
        return header
    unknown = [h for h in header if h not in names]
    if for_writing or unknown or not header:
        raise RecordingError(
            f"{path}: header {list(header)} is not the expected {list(names)}"
            + (" (a recording of another format cannot be resumed)" if for_writing and not unknown else "")
        )
    return header


def _parse_cell(path: Path, number: int, name: str, value: str | None) -> Any:
    if value is None:
        raise RecordingError(f"{path}, line {number}: the row has fewer fields than the header (column '{name}' missing)")
    if name in _TEXT:
        return _unescape(value)
    if value == "":
        return -1 if name in _INT else np.nan
    try:
        return int(value) if name in _INT else float(value)
    except ValueError:
        raise RecordingError(f"{path}, line {number}, column '{name}': expected a number, got {value!r}") from None


def _read_csv(path: Path, names: tuple[str, ...], as_arrays: bool):
    text = _read_text(path)
    # What follows the last "\n" (the writer's line terminator) is a row still being written:
    # not a measurement yet. The rest is read as the csv module reads a file opened with
    # newline="": a name or message holding "\r", "\n" or another character at which
    # str.splitlines would split ("\v", "\f", "\x1c"-"\x1e", "\x85", U+2028, U+2029) stays
    # inside its field.
    whole = text[: text.rfind("\n") + 1]
    header = _check_header(path, names, first_line=whole[: whole.find("\n") + 1])
    reader = csv.DictReader(io.StringIO(whole, newline=""))
    rows = []
    for number, raw in enumerate(reader, start=2):
        if None in raw:
            raise RecordingError(f"{path}, line {number}: the row has more fields than the header")
        row = {name: _parse_cell(path, number, name, raw[name]) for name in header}
        for name in names:
            if name not in row:  # a column of a newer format: not available
                row[name] = "" if name in _TEXT else (-1 if name in _INT else np.nan)
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


#: What every measured ("ok") row must hold for the reduction: column -> (test, expected).
_MEASURED_RULES = {
    "exposure": (lambda v: np.isfinite(v) & (v > 0), "a finite exposure > 0 s"),
    "gain": (lambda v: np.isfinite(v) & (v > 0), "a finite gain > 0"),
    "roi_pixels": (lambda v: v > 0, "a pixel count > 0"),
    "frames": (lambda v: v > 0, "a frame count > 0"),
    "roi_mean": (np.isfinite, "a finite mean"),
    "roi_std": (lambda v: np.isfinite(v) & (v >= 0), "a finite standard deviation >= 0"),
    "signal_rate": (np.isfinite, "a finite signal rate"),
    "signal_rate_sigma": (lambda v: np.isfinite(v) & (v >= 0), "a finite uncertainty >= 0"),
    "theta_i": (np.isfinite, "a finite angle"),
    "view": (np.isfinite, "a finite angle"),
    "stage_camera": (np.isfinite, "a finite read-back angle"),
}


def check_measured_rows(folder: str | Path, points: Mapping[str, np.ndarray]) -> None:
    """Refuse a recording whose measured rows hold values no measurement gives.

    Every row with status "ok" must satisfy :data:`_MEASURED_RULES` (finite values, positive
    exposure, gain, pixel and frame counts), and the lamp monitor must be read for every
    measured row or for none (an empty column: no monitor). A file edited or damaged by
    hand otherwise reduced to NaN values or a changed result with no word of it.

    Raises
    ------
    RecordingError
        Naming the file, the line, the column, its value and what was expected.
    """
    path = Path(folder) / "points.csv"
    ok = np.flatnonzero(points["status"] == "ok")
    for name, (test, expected) in _MEASURED_RULES.items():
        values = np.asarray(points[name][ok], float)
        bad = ~np.asarray(test(values), bool)
        if bad.any():
            row = int(ok[np.argmax(bad)])
            raise RecordingError(f"{path}, line {row + 2}, column '{name}': {points[name][row]!r} where a measured "
                                 f"point holds {expected}; the file was damaged or edited (restore it from a copy, "
                                 "or mark the row 'error' and resume to measure the point again)")
    monitor = np.asarray(points["monitor"][ok], float)
    read = np.isfinite(monitor) & (monitor > 0)
    if read.any() and not read.all():
        row = int(ok[np.argmax(~read)])
        raise RecordingError(f"{path}, line {row + 2}, column 'monitor': {points['monitor'][row]!r} where the other "
                             "measured points have a lamp monitor reading > 0 V; the file was damaged or edited")


def read_darks(folder: str | Path, as_arrays: bool = True):
    """Rows of darks.csv: a dict of column arrays (default) or a list of row dicts."""
    return _read_csv(Path(folder) / "darks.csv", _DARK_NAMES, as_arrays)


def column_table(columns: Iterable[tuple[str, str, str]] = COLUMNS) -> str:
    """Markdown table of columns (used to keep docs/data-format.md in step with the code)."""
    lines = ["| column | unit | meaning |", "|---|---|---|"]
    lines += [f"| `{n}` | {u} | {d} |" for n, u, d in columns]
    return "\n".join(lines)
