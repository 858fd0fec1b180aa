"""Shared pieces of the readers: the :class:`Block` record, text decoding and canonical column building."""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..canonical import CANONICAL_VARIABLES
from ..units import UnknownUnitError, to_si
from .errors import IngestError


@dataclass
class Block:
    """One test block of an export (a RheoCompass result interval, a TRIOS step, a Kinexus action ...).

    Attributes
    ----------
    name : block name as written (e.g. ``"Step strain / 1"``, ``"Frequency sweep - 2"``)
    index : 1-based position of the block in the file (what a sample sheet's ``block`` column selects)
    data : canonical columns in SI units (see :data:`tissuemech.canonical.CANONICAL_VARIABLES`)
    meta : geometry (``radius_m``, ``gap_m``), ``temperature_c``, ``instrument``, ``format``, ``labels``
        (canonical -> original label and unit) and ``first_data_line`` (1-based)
    """

    name: str
    index: int
    data: pd.DataFrame
    meta: dict = field(default_factory=dict)


_NUMBER = re.compile(r"^[+-]?(\d+([.,]\d*)?|[.,]\d+)([eE][+-]?\d+)?$")


def parse_number(cell: str, decimal_comma: bool) -> float:
    """A numeric cell (decimal comma or point); empty or ``nan`` -> NaN.

    Raises ``ValueError`` for text, and for ``inf`` or a value beyond the float range (``1e400``): an
    instrument never measures infinity, so it is a damaged cell, never silently ±inf.
    """
    s = cell.strip()
    if s == "":
        return np.nan
    if s.lower() in ("nan", "-nan"):
        return np.nan
    if s.lower().lstrip("+-") in ("inf", "infinity"):
        raise ValueError(f"infinite value: {s!r}")
    if not _NUMBER.match(s):
        raise ValueError(f"not a number: {s!r}")
    if decimal_comma:
        s = s.replace(",", ".")
    elif "," in s:
        raise ValueError(f"not a number: {s!r}")
    value = float(s)
    if not np.isfinite(value):
        raise ValueError(f"value out of range (overflows to ±inf): {s!r}")
    return value


def is_number(cell: str, decimal_comma: bool = True) -> bool:
    """True when a non-empty cell reads as a number (:func:`parse_number`; by default either decimal mark)."""
    try:
        parse_number(cell, decimal_comma)
    except ValueError:
        return False
    return bool(str(cell).strip())


def cell_problem(text: str, decimal_comma: bool) -> str:
    """Report wording of a cell :func:`parse_number` refused (text, infinity or overflow)."""
    try:
        parse_number(str(text), decimal_comma)
    except ValueError as exc:
        if "not a number" not in str(exc):
            return str(exc)
    return f"text in a numeric column: {str(text).strip()!r}"


def detect_decimal_comma(lines: list[str], sep: str) -> bool:
    """True when numeric cells use a decimal comma (``0,019``); separators other than the comma only."""
    if sep == ",":
        return False
    comma = point = 0
    for line in lines[:400]:
        for cell in line.split(sep):
            c = cell.strip()
            if re.fullmatch(r"[+-]?\d+,\d+([eE][+-]?\d+)?", c):
                comma += 1
            elif re.fullmatch(r"[+-]?\d+\.\d+([eE][+-]?\d+)?", c):
                point += 1
    return comma > point


def canonical_frame(path: Path, columns: list[tuple[str, str, np.ndarray, int]]) -> tuple[pd.DataFrame, dict]:
    """Convert ``(canonical name, unit, raw values, column index)`` columns to SI, first occurrence wins.

    Raises :class:`IngestError` naming the column for an unknown unit, or for a unit of another quantity than
    the canonical one (a modulus without a unit is not taken to be in Pa).
    """
    data, labels = {}, {}
    for name, unit, values, col in columns:
        if name in data or name not in CANONICAL_VARIABLES:
            continue
        try:
            with np.errstate(over="ignore"):
                data[name] = to_si(values, unit, expected=CANONICAL_VARIABLES[name][0])
        except UnknownUnitError as exc:
            raise IngestError(path, f"{exc} in column {name!r}", column=col) from exc
        overflow = np.isinf(data[name]) & np.isfinite(values)
        if overflow.any():
            raise IngestError(path, f"value {values[overflow][0]!r} {unit} overflows when converted to "
                                    f"{CANONICAL_VARIABLES[name][0]}", column=col)
        labels[name] = unit
    return pd.DataFrame(data), labels


def check_time(path: Path, frame: pd.DataFrame, first_line: int, line_numbers: np.ndarray | None = None) -> None:
    """Time must be finite, unique and increasing within a block (the line of the first bad point is named)."""
    if "time" not in frame:
        return
    t = frame["time"].to_numpy(float)
    rows = line_numbers if line_numbers is not None else first_line + np.arange(t.size)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise IngestError(path, "missing (NaN) time value", line=int(rows[bad[0]]), column="time")
    d = np.diff(t)
    dup = np.flatnonzero(d == 0)
    if dup.size:
        raise IngestError(path, f"duplicate time {t[dup[0] + 1]:g} s", line=int(rows[dup[0] + 1]), column="time")
    back = np.flatnonzero(d < 0)
    if back.size:
        raise IngestError(path, f"non-monotonic time: {t[back[0] + 1]:g} s after {t[back[0]]:g} s",
                          line=int(rows[back[0] + 1]), column="time")


def parse_column(path: Path, label: str | int, cells, line_numbers, decimal_comma: bool) -> np.ndarray:
    """Numbers of one column (cells as text, or floats from a spreadsheet); empty cells are NaN.

    Raises :class:`IngestError` naming the line and column of the first cell holding text.
    """
    values = np.empty(len(cells))
    for r, cell in enumerate(cells):
        if isinstance(cell, (int, float)) and not isinstance(cell, bool):
            if not np.isfinite(cell) and not np.isnan(cell):
                raise IngestError(path, f"infinite value: {cell!r}", line=int(line_numbers[r]), column=label)
            values[r] = float(cell)
            continue
        text = "" if cell is None else str(cell)
        try:
            values[r] = parse_number(text, decimal_comma)
        except ValueError:
            raise IngestError(path, cell_problem(text, decimal_comma), line=int(line_numbers[r]),
                              column=label) from None
    return values


def pick_columns(path: Path, candidates: dict[str, tuple[str, ...]], table: dict[str, tuple[str, str, int]],
                 cells_of, line_numbers, decimal_comma: bool) -> list[tuple[str, str, np.ndarray, str]]:
    """Choose, per canonical variable, the first candidate label whose column holds data in this block.

    Instruments export steady and oscillatory twins side by side (``Stress`` / ``Oscillation stress``,
    ``Shear strain`` / ``Complex shear strain``) and leave the one that does not apply to the step empty, so
    the label that carries numbers wins; a variable whose candidates are all empty is left out.

    Parameters
    ----------
    candidates : canonical name -> lower-cased labels in order of preference
    table : lower-cased label -> (label as written, unit, column position)
    cells_of : column position -> the column's cells
    """
    chosen = []
    for name, labels in candidates.items():
        for low in labels:
            if low not in table:
                continue
            label, unit, position = table[low]
            values = parse_column(path, label, cells_of(position), line_numbers, decimal_comma)
            if np.isfinite(values).any():
                chosen.append((name, unit, values, label))
                break
    return chosen


def auxiliary_frame(columns: list[tuple[str, str, list]], decimal_comma: bool) -> pd.DataFrame:
    """Numeric columns outside the canonical set, converted to SI where the unit is known.

    ``columns`` holds ``(label, unit, cells)``. Columns holding text, or in a unit without a known SI
    conversion, are left out: they are kept for cross-checks (e.g. a compliance in 1/MPa against
    G'/|G*|^2), never used as canonical data.
    """
    data = {}
    for label, unit, cells in columns:
        try:
            values = np.array([parse_number("" if c is None else str(c), decimal_comma) for c in cells], float)
            with np.errstate(over="ignore"):
                converted = to_si(values, unit)
            if not np.isfinite(converted[np.isfinite(values)]).all():
                continue
            data[label] = converted
        except (ValueError, UnknownUnitError):
            continue
    return pd.DataFrame(data)


def canonical_frame_at(path: Path, columns, units_line: int | None):
    """:func:`canonical_frame`, with an unknown unit reported at the line of the units row."""
    try:
        return canonical_frame(path, columns)
    except IngestError as exc:
        if exc.line is not None or units_line is None:
            raise
        raise IngestError(path, exc.problem, line=units_line, column=exc.column) from exc
