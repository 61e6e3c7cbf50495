"""Reading a table of measurements as labs keep them: the CSV form of a :class:`Dataset`.

A file is optional ``# key: value`` header lines (values in JSON; older files' plain text
is kept as text), one line of column names, then one row per measurement. What this
reader accepts beyond gonio's own files (docs/data-format.md, "Your own data"):

- **Column names of your own**, mapped to gonio's with ``columns={"theta_i": "ti", ...}``
  (``gonio fit --columns theta_i=ti,...``).
- **Any usual delimiter**: comma, semicolon, tab, or runs of spaces, told from the line of
  column names.
- **No sigma column**: every value gets :data:`ASSUMED_RELATIVE_SIGMA` of itself as its
  stated uncertainty and the metadata key :data:`ASSUMED_SIGMA` says so; a fit then takes
  the noise as relative to each value and fits its size (``rel_jitter``).
- **Missing values** (an empty cell, ``nan``, ``NA``): the row is left out and counted,
  with its line numbers, in the metadata key :data:`DROPPED_ROWS`.
- **Angles in radians**: refused when every polar angle lies within ``[0, pi/2]`` and
  the file does not say its unit (``angle_unit="rad"`` converts them; ``"deg"`` is the
  default).

Text that is not a number (``oops``) stays an error naming the file, line and column: a
typing error is not a missing value.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

__all__ = ["Table", "read_table", "data_notes", "ASSUMED_RELATIVE_SIGMA", "ASSUMED_SIGMA", "DROPPED_ROWS", "DATA_NOTES", "MISSING_TEXT",
           "ANGLE_UNITS"]

#: Stated uncertainty of a value in a file without a sigma column, relative to the value
#: [-]: a floor well below any real gonioreflectometer's (NIST STARR: 0.15-0.6 % at k=2),
#: so that the fitted extra noise (rel_jitter), not this number, sets the weights.
ASSUMED_RELATIVE_SIGMA = 1e-3
#: Metadata key saying the uncertainties were not in the file (its value says what was assumed).
ASSUMED_SIGMA = "sigma_assumed"
#: Metadata key listing the rows left out for a missing value: ``{"count": n, "lines": [...]}``.
DROPPED_ROWS = "dropped_rows"
#: Metadata key of further notes on the data a loader adds (list of str; an incomplete recording's).
DATA_NOTES = "notes"
#: Cell texts read as a missing value (case-insensitive).
MISSING_TEXT = ("", "nan", "na", "n/a", "null", "none", "-")
#: Units the angle columns may be in.
ANGLE_UNITS = ("deg", "rad")

_ANGLES = ("theta_i", "phi_i", "theta_r", "phi_r")
_POLAR = ("theta_i", "theta_r")


@dataclass(frozen=True)
class Table:
    """The numbers of a measurement table and what was read about them.

    Attributes
    ----------
    header : dict
        The ``# key: value`` lines (JSON values decoded).
    columns : dict of str to numpy.ndarray
        gonio's column names to values; angles in degrees.
    metadata : dict
        What the reading assumed or left out (:data:`ASSUMED_SIGMA`, :data:`DROPPED_ROWS`).
    """

    header: dict[str, Any]
    columns: dict[str, np.ndarray]
    metadata: dict[str, Any]


def read_table(path: str | Path, required: tuple[str, ...], optional: tuple[str, ...] = ("sigma",),
               columns: Mapping[str, str] | None = None, angle_unit: str | None = None) -> Table:
    """Read a measurement table (see the module notes).

    Parameters
    ----------
    path : path
        The file (UTF-8 text).
    required, optional : tuple of str
        gonio's column names the table must have, and may have.
    columns : mapping, optional
        gonio's column name to the file's, for those whose names differ.
    angle_unit : {"deg", "rad"}, optional
        Unit of the angle columns; default the header's ``angle_unit``, else degrees.

    Raises
    ------
    ValueError
        Naming the file and what is wrong: not UTF-8, no column line, a column missing
        (listing the file's), a cell that is not a number (line and column), angles that
        look like radians, every row missing a value.
    """
    path = Path(path)
    lines = _text(path).splitlines()
    header, start = _header(lines)
    if start == len(lines):
        raise ValueError(f"{path}: no line of column names; expected the columns {','.join(required + optional)}")
    delimiter = _delimiter(lines[start])
    names = [c.strip() for c in _split(lines[start], delimiter)]
    where = _column_positions(path, names, required, optional, dict(columns or {}))
    values, dropped = _rows(path, lines, start, delimiter, where)
    metadata: dict[str, Any] = {}
    if dropped:
        metadata[DROPPED_ROWS] = {"count": len(dropped), "lines": dropped[:50]}
    if not values[required[0]]:
        raise ValueError(f"{path}: no row with every value present ({len(dropped)} row(s) have a missing value)")
    table = {name: np.array(v, dtype=float) for name, v in values.items()}
    unit = angle_unit or header.get("angle_unit", "deg")
    _convert_angles(path, table, unit, explicit=angle_unit is not None or "angle_unit" in header)
    return Table(header, table, metadata)


def _text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not a UTF-8 text file (byte {error.start}: {error.reason}); save the CSV as "
                         "UTF-8 (or plain ASCII)") from None


def _header(lines: list[str]) -> tuple[dict[str, Any], int]:
    """The ``# key: value`` lines before the column names, and the index of that line."""
    header: dict[str, Any] = {}
    start = 0
    while start < len(lines) and (lines[start].startswith("#") or not lines[start].strip()):
        comment = lines[start].lstrip("#").strip()
        if ":" in comment:
            key, _, value = comment.partition(":")
            header[key.strip()] = _header_value(value.strip())
        start += 1
    return header, start


def _header_value(text: str) -> Any:
    """A header value: JSON when it parses, else the text (files of older gonio versions)."""
    try:
        return json.loads(text)
    except ValueError:
        return text


def _delimiter(line: str) -> str | None:
    """The delimiter of a line of column names: tab, semicolon, comma, or None (spaces)."""
    for candidate in ("\t", ";", ","):
        if candidate in line:
            return candidate
    return None


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return next(csv.reader([line], delimiter=delimiter))


def _column_positions(path: Path, names: list[str], required: tuple[str, ...], optional: tuple[str, ...],
                      columns: dict[str, str]) -> dict[str, int]:
    unknown = sorted(set(columns) - set(required + optional))
    if unknown:
        raise ValueError(f"{path}: column mapping names {unknown}, which are not gonio's columns; expected some of "
                         f"{', '.join(required + optional)} (as gonio_name=file_column)")
    wanted = {name: columns.get(name, name) for name in required + optional}
    missing = [name for name in required if wanted[name] not in names]
    if missing:
        shown = [f"{name} (as {wanted[name]!r})" if wanted[name] != name else name for name in missing]
        raise ValueError(f"{path}: header lacks the column(s) {missing}: looked for {', '.join(shown)} among the "
                         f"file's columns {names}; map yours with --columns (e.g. theta_i=incidence) or "
                         f"columns={{'theta_i': 'incidence'}}")
    return {name: names.index(file_name) for name, file_name in wanted.items() if file_name in names}


def _rows(path: Path, lines: list[str], start: int, delimiter: str | None,
          where: dict[str, int]) -> tuple[dict[str, list[float]], list[int]]:
    """Every row's numbers by column; rows with a missing value left out (their line numbers)."""
    values: dict[str, list[float]] = {name: [] for name in where}
    dropped: list[int] = []
    for line_number, line in enumerate(lines[start + 1:], start=start + 2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        row = _split(line, delimiter)
        numbers = {name: _cell(path, line_number, name, row, index) for name, index in where.items()}
        if any(math.isnan(x) for x in numbers.values()):
            dropped.append(line_number)
            continue
        for name, x in numbers.items():
            values[name].append(x)
    return values, dropped


def _cell(path: Path, line_number: int, name: str, row: list[str], index: int) -> float:
    text = row[index].strip() if index < len(row) else ""
    if text.lower() in MISSING_TEXT:
        return math.nan
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{path}, line {line_number}: column {name!r} = {text!r} is not a number") from None


def _convert_angles(path: Path, table: dict[str, np.ndarray], unit: str, explicit: bool) -> None:
    """Angles in degrees, in place; refuse radians that were not declared."""
    if unit not in ANGLE_UNITS:
        raise ValueError(f"{path}: angle_unit {unit!r}; expected one of {list(ANGLE_UNITS)}")
    if unit == "rad":
        for name in _ANGLES:
            if name in table:
                table[name] = np.degrees(table[name])
        return
    polar = np.concatenate([np.abs(table[name]) for name in _POLAR if name in table])
    if not explicit and polar.size > 2 and np.max(polar) <= math.pi / 2 + 1e-9 and np.ptp(polar) > 0.05:
        raise ValueError(f"{path}: every polar angle lies within [0, pi/2] (largest {np.max(polar):.4g}): the "
                         "angles look like radians, and gonio reads degrees. Give --angle-unit rad (Python: "
                         "angle_unit='rad') or a '# angle_unit: \"rad\"' header line to convert them, or "
                         "--angle-unit deg if they really are degrees")


def data_notes(metadata: Mapping[str, Any]) -> list[str]:
    """What reading the data assumed or left out, in words (a fit's flags and summary).

    >>> data_notes({DROPPED_ROWS: {"count": 2, "lines": [4, 9]}})
    ['2 row(s) of the file had a missing value and were left out (lines 4, 9)']
    """
    notes = []
    dropped = metadata.get(DROPPED_ROWS)
    if isinstance(dropped, Mapping):
        lines = ", ".join(str(n) for n in dropped.get("lines", []))
        more = ", ..." if dropped.get("count", 0) > len(dropped.get("lines", [])) else ""
        notes.append(f"{dropped.get('count')} row(s) of the file had a missing value and were left out "
                     f"(lines {lines}{more})")
    if metadata.get(ASSUMED_SIGMA):
        notes.append(str(metadata[ASSUMED_SIGMA]))
    extra = metadata.get(DATA_NOTES, [])
    return notes + ([extra] if isinstance(extra, str) else [str(n) for n in extra])
