"""Anton Paar RheoCompass text/CSV exports (``instrument_formats.md`` section 2.5).

Layouts read, as the software writes them:

* UTF-16 LE with BOM (or UTF-8), tab- or semicolon-separated, CRLF, decimal comma or point;
* *simple* header: ``Test:``, ``Result:``, ``Interval:`` lines, then the column-name row (first cell
  ``Point No.``), a sub-label row and a ``[unit]`` row;
* *project* header: ``Project:``/``Projet:``, ``Test:``, ``Result:``/``Résultat:``/``Ergebnis:``, then per interval
  ``Interval and data points:`` + ``Interval data:`` (column names after the label cell), sub-label and units;
* several results and intervals per file: each interval is one :class:`~tissuemech.io.blocks.Block`
  (``name = "<result> / <interval>"``, ``index`` counting from 1 through the file);
* waveform data: columns whose sub-label is ``Waveform``/``Sinusoïdes``/``Wellenform`` are raw periods and are
  dropped, as are the rows that only fill them (no ``Point No.``); repeated column names keep their first
  non-waveform occurrence;
* English, French and German labels (:data:`LABELS`).

``Time`` is the interval time when no separate interval-time column exists; with both (``Temps`` and
``Intervalle Temps``) the interval time is ``time`` and the other ``total_time``.

A file cut short is reported: an interval with another point count than its ``Interval and data points:``
count, a point row with fewer cells than the column row (real exports write every cell, empty ones included)
or more non-empty ones, point numbers that do not count up by one (a deleted or duplicated row), and a data
header whose ``Interval`` row is missing (it would merge or rename intervals and shift every later block
index). A ``Measuring System:`` header row (``PP25``, ``CP50-1``) gives ``meta["measuring_system"]`` and the
plate radius (:mod:`tissuemech.io.geometry`); the real exports seen so far do not write one.
Excel exports (.xlsx, section 2.6) go through the same parsing, sheet by sheet (:func:`read_rheocompass_xlsx`).
"""
from __future__ import annotations

import io
import re
import zipfile
from pathlib import Path

import numpy as np
import openpyxl

from .blocks import (Block, canonical_frame_at, cell_problem, check_time, detect_decimal_comma, is_number,
                     parse_number)
from .errors import IngestError
from .geometry import measuring_system
from .textfile import decode_text

#: lower-cased RheoCompass label -> canonical variable (English, French, German)
LABELS: dict[str, str] = {
    "interval time": "time", "intervalle temps": "time", "intervallzeit": "time",
    "time": "time", "temps": "time", "zeit": "time", "average time": "time",
    "shear strain": "shear_strain", "déformation de cisaillement": "shear_strain", "scherdeformation": "shear_strain",
    "deformation": "shear_strain", "strain": "shear_strain",
    "shear stress": "shear_stress", "contrainte de cisaillement": "shear_stress", "schubspannung": "shear_stress",
    "shear rate": "shear_rate", "gradient de cisaillement": "shear_rate", "vitesse de cisaillement": "shear_rate",
    "scherrate": "shear_rate",
    "viscosity": "viscosity", "viscosité": "viscosity", "viskosität": "viscosity",
    "complex viscosity": "complex_viscosity", "viscosité complexe": "complex_viscosity",
    "komplexe viskosität": "complex_viscosity",
    "storage modulus": "storage_modulus", "module de stockage": "storage_modulus",
    "module de conservation": "storage_modulus", "speichermodul": "storage_modulus",
    "loss modulus": "loss_modulus", "module de perte": "loss_modulus", "verlustmodul": "loss_modulus",
    "complex shear modulus": "complex_modulus", "complex modulus": "complex_modulus",
    "loss factor": "loss_factor", "facteur de perte": "loss_factor", "verlustfaktor": "loss_factor",
    "phase shift angle": "phase_angle", "phase angle": "phase_angle", "angle de phase": "phase_angle",
    "phasenverschiebungswinkel": "phase_angle", "raw phase": "raw_phase",
    "torque": "torque", "couple": "torque", "drehmoment": "torque",
    "deflection angle": "deflection_angle", "angle de déflexion": "deflection_angle", "auslenkwinkel": "deflection_angle",
    "normal force": "normal_force", "force normale": "normal_force", "normalkraft": "normal_force",
    "gap": "gap", "entrefer": "gap", "spalt": "gap", "messspalt": "gap",
    "temperature": "temperature", "température": "temperature", "temperatur": "temperature",
    "frequency": "frequency", "fréquence": "frequency", "frequenz": "frequency",
    "angular frequency": "angular_frequency", "fréquence angulaire": "angular_frequency",
    "kreisfrequenz": "angular_frequency",
    "relaxation modulus": "relaxation_modulus", "module de relaxation": "relaxation_modulus",
    "relaxationsmodul": "relaxation_modulus",
    "creep compliance": "creep_compliance", "complaisance de fluage": "creep_compliance",
    "kriechnachgiebigkeit": "creep_compliance",
}
_INTERVAL_TIME = {"interval time", "intervalle temps", "intervallzeit"}
_WAVEFORM = ("waveform", "sinusoïdes", "sinusoides", "wellenform")
_RESULT = ("result:", "résultat:", "resultat:", "ergebnis:")
#: the table layout's interval row (its column-name row follows directly)
_INTERVAL_ONLY = ("interval:", "intervalle:", "intervall:")
_INTERVAL = _INTERVAL_ONLY + ("interval and data points:", "intervalle et points de données:",
                              "intervall und datenpunkte:")
_INTERVAL_DATA = ("interval data:", "interval données:", "intervalle données:", "intervalldaten:")
#: point numbers the software marks as invalid ("12 (invalid)", "12  (invalide)", "12 (ungültig)")
_INVALID = re.compile(r"\((invalid|invalide|ungültig|ungueltig)\)", re.IGNORECASE)
_POINT_NO = ("point no.", "point no", "punkt nr.", "messpunkt", "n° de point")
#: header rows naming the measuring system (``Measuring System:	PP25``)
_MEASURING_SYSTEM = ("measuring system:", "measuring-system:", "système de mesure:", "systeme de mesure:",
                     "messsystem:", "geometry:", "géométrie:", "geometrie:")
_LEADING_INT = re.compile(r"^\s*(\d+)")


def looks_like_rheocompass(text: str) -> bool:
    head = [line.strip().lower() for line in text.splitlines()[:12]]
    return any(h.startswith(("test:", "project:", "projet:", "projekt:")) for h in head) and any(
        h.startswith(_RESULT) for h in head)


def _sep(lines: list[str]) -> str:
    for line in lines[:10]:
        low = line.lower()
        if low.startswith(("test:", "project:", "projet:", "projekt:")):
            return ";" if low.split(":", 1)[1][:1] == ";" else "\t"
    return "\t"


def read_rheocompass(path, text: str | None = None) -> list[Block]:
    """Every interval of a RheoCompass export as canonical blocks (see module docstring)."""
    path = Path(path)
    text = decode_text(path) if text is None else text
    lines = text.splitlines()
    sep = _sep(lines)
    comma = detect_decimal_comma(lines, sep)
    blocks = _read_rows(path, [line.split(sep) for line in lines], comma)
    if not blocks:
        raise IngestError(path, "no data block found (expected a 'Point No.' or 'Interval data:' column header row, "
                                "or a column row right after an 'Interval:' row)")
    return blocks


_HEADER_KEYS = _RESULT + _INTERVAL + _INTERVAL_DATA + ("test:", "project:", "projet:", "projekt:")


def _is_header(row: list[str]) -> bool:
    first = row[0].strip().lower() if row else ""
    return first.endswith(":") and first.startswith(_HEADER_KEYS)



def _is_column_row(row: list[str]) -> bool:
    """A table export's column-name row: two or more labels, no number, not a header key row."""
    cells = [c.strip() for c in row if c.strip()]
    return len(cells) >= 2 and not _is_header(row) and not any(is_number(c) for c in cells)


def _read_rows(path: Path, table: list[list[str]], comma: bool, result: str = "result", first_index: int = 1,
               meta_extra: dict | None = None) -> list[Block]:
    """Blocks of a grid of cells (text lines split at the separator, or a spreadsheet's rows).

    ``table[i]`` is line/row ``i + 1`` of the file (what errors name). ``result`` names blocks before any
    ``Result:`` row (an Excel sheet without one uses its sheet name). Two block layouts: a data header
    (``Point No.`` or ``Interval data:``) with point numbers, and the *table* layout (a column-name row right
    after the ``Interval:`` row, no point numbers; its data rows end at the next header row). Structure checks
    (a damaged file is an error, never a block lost or renamed): a ``Test:`` row needs its ``Result:`` row before
    the data and a block after it, an ``Interval:`` row its interval, a data row must be inside a block, a block
    name appears once within a test, and a table-layout row is not an exact copy of the row before it (point
    rows of real instruments never repeat every cell).
    """
    meta_common = {"format": "anton_paar_rheocompass", "decimal_comma": comma, **(meta_extra or {})}
    blocks: list[Block] = []
    index = first_index - 1
    interval = "1"
    declared = None
    fresh = True  # a Result:/Interval: row since the last block (a block header without one lost its interval row)
    after_interval = False        # the previous non-blank row was an 'Interval:' row (table layout follows)
    test_line = None              # line of the last 'Test:' row, until a block follows it
    result_of_test = True         # a 'Result:' row since the last 'Test:' row
    names_in_test: set[str] = set()
    i = 0
    while i < len(table):
        cells = table[i]
        head = cells[0].strip().lower() if cells else ""
        blank = not any(c.strip() for c in cells)
        if head.startswith(("test:",)):
            meta_common["test_name"] = cells[1].strip() if len(cells) > 1 else ""
            test_line, result_of_test, names_in_test = i + 1, False, set()
        if head.startswith(_MEASURING_SYSTEM) and len(cells) > 1:
            meta_common.update(measuring_system(cells[1]))
        table_header = after_interval and _is_column_row(cells)
        if not blank:
            after_interval = False
        if head.startswith(_RESULT):
            if not (len(cells) > 1 and cells[1].strip()):
                raise IngestError(path, "'Result:' row without a result name (row cut short?)", line=i + 1)
            result = cells[1].strip()
            fresh = result_of_test = True
        elif head.startswith(_INTERVAL):
            fresh = True
            if not (len(cells) > 1 and cells[1].strip()):
                raise IngestError(path, "'Interval' row without an interval number (row cut short?)", line=i + 1)
            interval = cells[1].strip()
            if interval.isdigit():
                _count(path, interval, i + 1, 2, "interval number")
            after_interval = head.startswith(_INTERVAL_ONLY)
            # "Interval and data points:  1  60": the point count lets a cut-short file be told from a short test
            declared = None
            if len(cells) > 2 and cells[2].strip():
                declared = _count(path, cells[2], i + 1, 3, "declared point count")
        elif head.startswith(_INTERVAL_DATA) or head in _POINT_NO or table_header:
            offset = 1 if head.startswith(_INTERVAL_DATA) else 0 if head in _POINT_NO else -1
            if not fresh:
                # a deleted "Interval:" row would merge or rename intervals and shift every later block index
                raise IngestError(path, f"data header without its 'Interval' row (after block '{result} / "
                                        f"{interval}'): interval numbering cannot be trusted", line=i + 1)
            if not result_of_test:
                raise IngestError(path, f"'Test:' row (line {test_line}) without its 'Result:' row before the data "
                                        "(a deleted row?)", line=i + 1)
            fresh = False
            names = [c.strip() for c in cells]
            if i + 2 >= len(table):
                raise IngestError(path, "truncated file: column header without sub-label and unit rows", line=i + 1)
            sub = table[i + 1]
            units = table[i + 2]
            if offset < 0:
                _check_table_rows(path, names, sub, units, i)
            rows, line_no, invalid, j = _data_rows(path, table, i + 3, names, offset, result, interval)
            index += 1
            if declared is not None and len(rows) + invalid != declared:
                what = "truncated file" if len(rows) + invalid < declared else "more points than declared"
                raise IngestError(path, f"{what}: interval '{result} / {interval}' declares {declared} "
                                        f"points, found {len(rows) + invalid}", line=j)
            declared = None
            name = f"{result} / {interval}"
            if name in names_in_test:
                raise IngestError(path, f"second block named {name!r} within one test (a deleted 'Result:' or "
                                        "'Interval:' row?)", line=i + 1)
            names_in_test.add(name)
            test_line = None
            if rows or not invalid:
                block = _block(path, names, sub, units, rows, line_no, offset, comma, result, interval,
                               index, i + 1, meta_common)
                block.meta["invalid_points"] = invalid
                if offset < 0:
                    block.meta["layout"] = "table"
                blocks.append(block)
            # an interval whose points are all flagged invalid by the instrument is not a block of data
            i = j
            continue
        elif not blank and is_number(cells[0]):
            raise IngestError(path, "data row outside any block (a deleted 'Interval:' or column row?)", line=i + 1)
        i += 1
    if test_line is not None:
        raise IngestError(path, "truncated file: 'Test:' row without a data block after it", line=test_line)
    return blocks


def _count(path: Path, cell: str, line: int, column, what: str) -> int:
    """A count written in a cell (point number, declared points): digits only, at most 9 of them."""
    text = str(cell).strip()
    if not (text.isdigit() and len(text) <= 9):
        raise IngestError(path, f"{what} is not a count: {text[:40]!r}" + ("..." if len(text) > 40 else ""),
                          line=line, column=column)
    return int(text)


def _check_table_rows(path: Path, names: list[str], sub: list[str], units: list[str], i: int) -> None:
    """The table layout's sub-label row (empty or labels) and ``[unit]`` row (bracketed or empty cells)."""
    if any(is_number(c) for c in sub):
        raise IngestError(path, "expected the (empty) sub-label row under the column row, found data",
                          line=i + 2)
    bad = [c.strip() for c in units if c.strip() and not (c.strip().startswith("[") and c.strip().endswith("]"))]
    if bad or not any(c.strip() for c in units):
        raise IngestError(path, f"expected the '[unit]' row under the column and sub-label rows, found "
                                f"{[c.strip() for c in units][:6]}", line=i + 3)
    if len([c for c in units if c.strip()]) > len([n for n in names if n]):
        raise IngestError(path, f"'[unit]' row has more units than the column row has names ({names})", line=i + 3)


def _data_rows(path: Path, table, j: int, names: list[str], offset: int, result: str, interval: str):
    """Point rows of one block from row ``j`` to the next header row: ``(rows, lines, invalid, end)``."""
    rows, line_no, invalid, last_pn = [], [], 0, 0
    while j < len(table):
        row = table[j]
        if _is_header(row):
            break
        if not any(c.strip() for c in row):
            j += 1
            continue
        if offset < 0:
            pn = "table row"
        else:
            pn = row[offset].strip() if len(row) > offset else ""
            number = _LEADING_INT.match(pn)
            if number:
                # point numbers count up within an interval: a restart means a lost interval header
                k = _count(path, number.group(1), j + 1, names[offset] or offset + 1, "point number")
                if last_pn and k != last_pn + 1:
                    raise IngestError(path, f"point number {k} after {last_pn} in '{result} / {interval}': a "
                                            "deleted, duplicated or moved row, or a missing interval header",
                                      line=j + 1, column=names[offset] or offset + 1)
                last_pn = k
        if _INVALID.search(pn):
            invalid += 1
        elif pn:
            # every real export writes all cells of a point row (empty ones included): fewer means cut off
            if len(row) < len(names):
                raise IngestError(path, f"truncated row: {len(row)} cells, the column row has {len(names)}",
                                  line=j + 1)
            if any(c.strip() for c in row[len(names):]):
                raise IngestError(path, f"row has {len(row)} cells, the column row only {len(names)} "
                                        "(column row cut short?)", line=j + 1)
            if offset < 0 and rows and [c.strip() for c in row] == [c.strip() for c in rows[-1]]:
                raise IngestError(path, f"row repeats line {line_no[-1]} cell for cell (a duplicated line?)",
                                  line=j + 1)
            rows.append(row)
            line_no.append(j + 1)
        j += 1
    return rows, line_no, invalid, j


def _block(path, names, sub, units, rows, line_no, offset, comma, result, interval, index, header_line, meta_common):
    n_cols = len(names)
    if not rows:
        raise IngestError(path, f"block '{result} / {interval}' has a header but no data rows (truncated file?)",
                          line=header_line)
    has_interval_time = any(n.lower() in _INTERVAL_TIME for n in names)
    columns, seen = [], set()
    for k in range(offset + 1, n_cols):
        label = names[k]
        low = label.lower()
        is_wave = k < len(sub) and sub[k].strip().lower().startswith(_WAVEFORM)
        if is_wave or low in ("status", "etat", "état", "") or low not in LABELS:
            continue
        name = LABELS[low]
        if name == "time" and has_interval_time and low not in _INTERVAL_TIME:
            name = "total_time"
        if name in seen:
            continue
        unit = units[k].strip() if k < len(units) else ""
        values = np.empty(len(rows))
        for r, row in enumerate(rows):
            cell = row[k] if k < len(row) else ""
            try:
                values[r] = parse_number(cell, comma)
            except ValueError:
                raise IngestError(path, cell_problem(cell, comma), line=line_no[r],
                                  column=label) from None
        seen.add(name)
        columns.append((name, unit, values, label))
    if not columns:
        raise IngestError(path, f"block '{result} / {interval}' has no recognised column; labels: {names[offset + 1:]}",
                          line=header_line)
    frame, labels = canonical_frame_at(path, columns, header_line + 2)
    check_time(path, frame, line_no[0], np.asarray(line_no))
    meta = dict(meta_common, labels=labels, first_data_line=line_no[0], result=result, interval=interval)
    return Block(name=f"{result} / {interval}", index=index, data=frame, meta=meta)


def _cell_text(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return str(value)


def looks_like_rheocompass_sheet(rows: list[list[str]]) -> bool:
    """A sheet whose first rows hold a ``Point No.`` column row or an ``Interval data:`` row."""
    for cells in rows[:20]:
        head = cells[0].strip().lower() if cells else ""
        if head in _POINT_NO or head.startswith(_INTERVAL_DATA):
            return True
    return False


def read_rheocompass_xlsx(path) -> list[Block]:
    """Every interval of every sheet of a RheoCompass Excel (.xlsx) export (``instrument_formats.md`` 2.6).

    Two sheet layouts are read: the text export's (``Test:``/``Result:``/``Interval:`` rows, then the column,
    sub-label and ``[unit]`` rows) and the one with a title in row 1 and the column row in row 2. Numeric cells
    are numbers; cells written as text with a decimal comma are read too. Errors name the sheet, the row
    (as ``line``) and the column label. Sheets without a ``Point No.`` column row are skipped; blocks are
    numbered through the workbook. Every zip member must pass its CRC-32 check (a damaged member name would
    otherwise drop its sheet without a word).
    """
    path = Path(path)
    raw = path.read_bytes()
    try:
        # every member's CRC-32: openpyxl skips a worksheet whose stored name was damaged, losing it silently
        bad = zipfile.ZipFile(io.BytesIO(raw)).testzip()
    except Exception as exc:  # noqa: BLE001 - zipfile raises BadZipFile, zlib errors, EOFError ... on damage
        raise IngestError(path, f"not a readable .xlsx workbook (truncated or damaged file?): {exc}") from exc
    if bad is not None:
        raise IngestError(path, f"damaged .xlsx workbook: member {bad!r} fails its CRC-32 check")
    try:
        # a file object, because openpyxl refuses paths whose extension is not .xlsx (format comes from content)
        book = openpyxl.load_workbook(io.BytesIO(raw), data_only=True)
    except Exception as exc:  # openpyxl raises zipfile/KeyError/InvalidFileException for damaged files
        raise IngestError(path, f"not a readable .xlsx workbook (truncated or damaged file?): {exc}") from exc
    blocks: list[Block] = []
    try:
        for sheet in book.worksheets:
            table = [[_cell_text(v) for v in row]
                     for row in sheet.iter_rows(min_row=1, min_col=1, values_only=True)]
            if not looks_like_rheocompass_sheet(table):
                continue
            text_cells = [c for row in table for c in row if c and not _looks_float_repr(c)]
            comma = detect_decimal_comma(["\t".join(text_cells)], "\t")
            title = table[0][0].strip() if table and table[0] else ""
            extra = {"sheet": sheet.title}
            if title and not title.endswith(":") and ":" not in title[:12]:
                extra["test_name"] = title
            try:
                found = _read_rows(path, table, comma, result=sheet.title, first_index=len(blocks) + 1,
                                   meta_extra=extra)
            except IngestError as exc:
                raise IngestError(path, f"sheet {sheet.title!r}: {exc.problem}", line=exc.line,
                                  column=exc.column) from exc
            for block in found:
                block.meta["format"] = "anton_paar_rheocompass_xlsx"
            blocks.extend(found)
    finally:
        book.close()
    if not blocks:
        raise IngestError(path, "no RheoCompass data sheet in the workbook (expected a 'Point No.' column row "
                                "under a Test:/Result: header or a title row)")
    return blocks


def _looks_float_repr(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True
