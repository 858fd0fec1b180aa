"""Plain tables: a column-name row, then numbers, with or without a unit row (``instrument_formats.md``, variants).

Two variants seen in other labs' files:

* a RheoCompass table export without its ``Test:``/``Result:``/``Interval:`` header: UTF-16, tab-separated,
  decimal comma, the file starts at the column-name row (``Angular Frequency``, ``Storage Modulus``, ...), an
  empty sub-label row may follow, and there is no ``[unit]`` row;
* a plain table (``Time``, ``Relaxation Modulus``), ASCII, tab-, semicolon- or comma-separated, no units:
  digitised, or copied out of the instrument software.

Labels are RheoCompass's (English, French, German: :data:`tissuemech.io.rheocompass.LABELS`) or canonical
names (:data:`tissuemech.canonical.CANONICAL_VARIABLES`); columns with other labels are left out. A unit comes
from a ``[unit]`` row under the column row, from the label itself (``Time [s]``), or from ``dataset.yaml``
``columns: {<label>: <unit>}`` (``column_units``). **No unit is ever assumed**: a recognised column without one
is an error that names this remedy. A declared unit that contradicts the file's is an error too.

Structure checks (a damaged table is an error, never silently other data): every data row has the column row's
cell count (fewer: cut short; more non-empty ones: the column row was cut), a row that repeats the row before it
cell for cell is a duplicated line, and a text row inside the data is an error (a last row without a line end is
refused by :func:`tissuemech.io.dispatch.read_export`, as for every text export).
"""
from __future__ import annotations

import difflib
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..canonical import CANONICAL_VARIABLES
from ..units import UnknownUnitError, unit_factor
from .blocks import Block, canonical_frame, check_time, detect_decimal_comma, is_number, parse_column
from .errors import IngestError
from .rheocompass import LABELS
from .textfile import decode_text

_LABEL_WITH_UNIT = re.compile(r"^(?P<label>.*?\S)\s*\[(?P<unit>[^\]]*)\]$")


def label_variable(label: str) -> str | None:
    """The canonical variable a column label names (canonical name, or a RheoCompass label), else None."""
    text = str(label).strip()
    m = _LABEL_WITH_UNIT.match(text)
    if m:
        text = m["label"]
    if text in CANONICAL_VARIABLES:
        return text
    return LABELS.get(text.lower())


def _separator(line: str) -> str:
    return "\t" if "\t" in line else ";" if ";" in line else ","



def _blank(cells: list[str]) -> bool:
    return not any(c.strip() for c in cells)


def looks_like_table(text: str) -> bool:
    """A first non-blank row of two or more labels (at least one recognised, none a number), then a number row."""
    lines = [line for line in text.splitlines() if line.strip()][:4]
    if len(lines) < 2:
        return False
    sep = _separator(lines[0])
    names = [c.strip() for c in lines[0].split(sep) if c.strip()]
    if len(names) < 2 or any(is_number(n) for n in names):
        return False
    return any(label_variable(n) for n in names) and any(is_number(c) for line in lines[1:]
                                                          for c in line.split(sep))


def read_table(path, text: str | None = None, column_units: Mapping[str, str] | tuple | None = None) -> list[Block]:
    """The table as one canonical block (see the module docstring).

    Parameters
    ----------
    path : the file
    text : its decoded text (read from ``path`` when None)
    column_units : ``dataset.yaml``'s ``columns``: label as written -> unit, for tables without a unit row

    Raises
    ------
    IngestError : a recognised column without a unit (naming ``dataset.yaml`` ``columns`` as the remedy), a
        declared unit that contradicts the file's, and the structure problems of the module docstring
    """
    path = Path(path)
    text = decode_text(path) if text is None else text
    declared = {str(k).strip(): str(v).strip() for k, v in dict(column_units or {}).items()}
    lines = text.splitlines()
    start = next((k for k, line in enumerate(lines) if line.strip()), None)
    if start is None:
        raise IngestError(path, "empty file")
    sep = _separator(lines[start])
    table = [line.split(sep) for line in lines]
    names = [c.strip() for c in table[start]]
    while names and not names[-1]:
        names.pop()
    j = start + 1
    units_row, unit_line = None, None
    while j < len(table) and not _is_number_row(table[j]):
        cells = [c.strip() for c in table[j]]
        if _blank(cells):                               # the empty sub-label row, blank lines
            j += 1
            continue
        if units_row is None and all(c.startswith("[") and c.endswith("]") for c in cells if c):
            units_row, unit_line = cells, j + 1
            j += 1
            continue
        raise IngestError(path, f"text row between the column row and the data: {cells[:6]}", line=j + 1)
    rows, line_no = [], []
    for k in range(j, len(table)):
        row = table[k]
        if _blank(row):
            continue
        if not _is_number_row(row):
            raise IngestError(path, f"text row inside the data: {[c.strip() for c in row][:6]}", line=k + 1)
        if len(row) < len(names):
            raise IngestError(path, f"truncated row: {len(row)} cells, the column row has {len(names)}", line=k + 1)
        if any(c.strip() for c in row[len(names):]):
            raise IngestError(path, f"row has {len(row)} cells, the column row only {len(names)} (column row cut "
                                    "short?)", line=k + 1)
        if rows and [c.strip() for c in row] == [c.strip() for c in rows[-1]]:
            raise IngestError(path, f"row repeats line {line_no[-1]} cell for cell (a duplicated line?)", line=k + 1)
        rows.append(row)
        line_no.append(k + 1)
    if not rows:
        raise IngestError(path, "column row but no data rows (truncated file?)", line=start + 1)
    comma = detect_decimal_comma(lines[j:], sep)
    columns, seen, sources = [], set(), set()
    for k, raw in enumerate(names):
        name = label_variable(raw)
        if name is None or name in seen:
            continue
        m = _LABEL_WITH_UNIT.match(raw)
        label = m["label"] if m else raw
        unit, source = _unit(path, label, raw, k, names, units_row, unit_line, declared, start + 1, name)
        values = parse_column(path, label, [r[k] for r in rows], line_no, comma)
        seen.add(name)
        sources.add(source)
        columns.append((name, unit, values, label))
    frame, labels = canonical_frame(path, columns)
    check_time(path, frame, line_no[0], np.asarray(line_no))
    meta = {"format": "table", "labels": labels, "first_data_line": line_no[0], "decimal_comma": comma,
            "units_from": ", ".join(sorted(sources))}
    return [Block(name="table", index=1, data=frame, meta=meta)]


def _is_number_row(row: list[str]) -> bool:
    cells = [c.strip() for c in row if c.strip()]
    return bool(cells) and is_number(cells[0])


def _unit(path: Path, label: str, raw: str, k: int, names: list[str], units_row, unit_line, declared: dict,
          header_line: int, name: str) -> tuple[str, str]:
    """The unit of column ``k`` and where it came from; a declared unit must agree with the file's."""
    m = _LABEL_WITH_UNIT.match(raw)
    written = m["unit"].strip() if m else (units_row[k].strip() if units_row and k < len(units_row) else "")
    mine = declared.get(label)
    if written and written.strip("[]").strip():
        if mine is not None and not _same_unit(written, mine, name):
            raise IngestError(path, f"dataset.yaml declares {mine!r} for column {label!r}, the file writes "
                                    f"{written!r}", line=unit_line or header_line, column=label)
        return written, "unit row" if not m else "column label"
    if mine is not None:
        return mine, "dataset.yaml columns"
    example = ", ".join(f'"{x}": <unit>' for x in names if label_variable(x) and not _LABEL_WITH_UNIT.match(x))
    close = difflib.get_close_matches(label, list(declared), n=1, cutoff=0.6)
    near = f"; dataset.yaml declares {close[0]!r}, not {label!r} (a misspelling?)" if close else ""
    raise IngestError(path, f"no unit for column {label!r} in the file (never assumed): declare the table's "
                            f"units in dataset.yaml, e.g. columns: {{{example}}}{near}",
                      line=header_line, column=label)


def _same_unit(a: str, b: str, name: str) -> bool:
    expected = CANONICAL_VARIABLES[name][0]
    try:
        return np.allclose(unit_factor(a, expected), unit_factor(b, expected), rtol=1e-12, atol=0.0)
    except UnknownUnitError:
        return False
