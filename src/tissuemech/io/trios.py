"""TA Instruments TRIOS exports: text (tab), CSV (comma) and Excel .xls (``instrument_formats.md`` 2.1-2.3).

Text/CSV: a key/value header, ``[Section]`` blocks of key/value lines (``[Geometry Parameters]`` holds
``Diameter 40.0 mm`` and ``Gap 1000 µm``: value and unit in one cell), then per step ``[step]``, the step name
(``Peak hold - 1``), the column row, the units row (empty cell = dimensionless) and data rows. Units are
converted per column (step time may be in minutes). Excel: a ``Details`` sheet and one sheet per step
(row 0 step name, row 1 columns, row 2 units, data from row 3); empty sheets are skipped.

Geometry (``Block.meta``): ``measuring_system`` from ``Geometry name`` (``8.0mm parallel plate`` -> 4 mm
radius, see :mod:`tissuemech.io.geometry`), ``radius_m``/``gap_m`` from ``Diameter``/``Gap`` with their
units dimension-checked (concentric cylinders: none). Checks: every text data row has as many fields as
the column row (a row cut short, or a decimal comma in a comma-separated file, would shift later columns),
the header's ``proceduresegments`` step count against the ``[step]`` blocks found, ±inf/overflow cells, a step
whose column row holds no recognised label or whose units row holds numbers (a deleted column or units row); any
failure of xlrd on a damaged ``.xls`` becomes an :class:`IngestError` naming the file.
"""
from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np

import xlrd

from ..units import UnknownUnitError
from .blocks import Block, canonical_frame, cell_problem, check_time, is_number, parse_number
from .errors import IngestError
from .geometry import measuring_system, value_with_unit
from .textfile import decode_text

#: lower-cased TRIOS column -> canonical variable
LABELS: dict[str, str] = {
    "step time": "time", "time": "total_time", "run time": "total_time",
    "stress": "shear_stress", "oscillation stress": "shear_stress",
    "strain": "shear_strain", "oscillation strain": "shear_strain",
    "shear rate": "shear_rate", "viscosity": "viscosity", "complex viscosity": "complex_viscosity",
    "storage modulus": "storage_modulus", "loss modulus": "loss_modulus", "complex modulus": "complex_modulus",
    "tan(delta)": "loss_factor", "phase angle": "phase_angle", "raw phase": "raw_phase",
    "frequency": "frequency", "angular frequency": "angular_frequency",
    "torque": "torque", "oscillation torque": "torque",
    "displacement": "deflection_angle", "oscillation displacement": "deflection_angle",
    "normal force": "normal_force", "axial force": "normal_force",
    "gap": "gap", "temperature": "temperature", "modulus": "relaxation_modulus",
}


def looks_like_trios(text: str) -> bool:
    low = text[:20000].lower()
    return "[step]" in low and ("procedure name" in low or "instrument name" in low or "filename" in low)


def _geometry(path: Path, text_lines: list[str], sep: str) -> dict:
    """Measuring system and plate geometry of the header (``Geometry name``, ``Geometry Type``, ``Diameter``,
    ``Gap``), dimension-checked: a diameter or gap whose unit is not a length is an error naming the line.
    Concentric cylinders have no plate radius or plate gap."""
    meta, values = {}, {}
    for n, line in enumerate(text_lines, start=1):
        cells = [c.strip() for c in line.split(sep)]
        if len(cells) < 2 or not cells[1]:
            continue
        key = cells[0].lower()
        if key == "geometry name":
            meta.update(measuring_system(cells[1]))
        elif key == "geometry type":
            meta["geometry_type"] = cells[1]
        elif key in ("diameter", "gap"):
            try:
                values[key] = value_with_unit(cells[1])
            except (ValueError, UnknownUnitError) as exc:
                raise IngestError(path, f"geometry {cells[0]!r}: {exc}", line=n, column=2) from exc
    if "cylinder" in str(meta.get("geometry_type", "")).lower():
        meta.pop("radius_m", None)
        return meta
    if values.get("diameter", 0) > 0:
        meta["radius_m"] = values["diameter"] / 2.0
    if values.get("gap", 0) > 0:
        meta["gap_m"] = values["gap"]
    return meta


def read_trios_text(path, text: str | None = None) -> list[Block]:
    """Every ``[step]`` of a TRIOS text or CSV export as canonical blocks."""
    path = Path(path)
    text = decode_text(path) if text is None else text
    lines = text.splitlines()
    sep = "\t" if sum(line.count("\t") for line in lines[:50]) >= sum(line.count(",") for line in lines[:50]) else ","
    starts = [i for i, line in enumerate(lines) if line.strip().lower() == "[step]"]
    if not starts:
        raise IngestError(path, "no [step] block in a TRIOS export")
    meta_common = {"format": "ta_trios_text" if sep == "\t" else "ta_trios_csv",
                   **_geometry(path, lines[: starts[0]], sep)}
    # the header lists the procedure's steps ("proceduresegments  Peak hold#Flow sweep#..."): fewer [step]
    # blocks than that is a file cut at a step boundary
    for n, line in enumerate(lines[: starts[0]], start=1):
        cells = line.split(sep)
        if cells[0].strip().lower() == "proceduresegments" and len(cells) > 1 and cells[1].strip():
            declared = len(cells[1].split("#"))
            if len(starts) < declared:
                raise IngestError(path, f"truncated file: the procedure declares {declared} steps "
                                        f"(proceduresegments), found {len(starts)}", line=n)
    blocks = []
    for b, s in enumerate(starts):
        end = starts[b + 1] if b + 1 < len(starts) else len(lines)
        if s + 3 >= end:
            raise IngestError(path, "truncated [step] block (needs name, columns and units rows)", line=s + 1)
        name = lines[s + 1].strip()
        cols = [c.strip() for c in lines[s + 2].split(sep)]
        units = [c.strip() for c in lines[s + 3].split(sep)]
        rows, line_no = [], []
        for j in range(s + 4, end):
            if not lines[j].strip():
                continue
            cells = lines[j].split(sep)
            # a row cut short, or a decimal comma in a comma-separated file, would shift every later column
            if len(cells) != len(cols):
                raise IngestError(path, f"malformed row: {len(cells)} fields, the column row of step {name!r} has "
                                        f"{len(cols)} (row cut short, or a decimal comma in a comma-separated "
                                        "file)", line=j + 1)
            rows.append(cells)
            line_no.append(j + 1)
        blocks.append(_step_block(path, name, b + 1, cols, units, rows, line_no, meta_common))
    return blocks


def _step_block(path, name, index, cols, units, rows, line_no, meta_common) -> Block:
    if not rows:
        raise IngestError(path, f"step {name!r} has no data rows", line=line_no[0] if line_no else None)
    columns, seen = [], set()
    for k, label in enumerate(cols):
        canon = LABELS.get(label.lower())
        if canon is None or canon in seen:
            continue
        values = np.empty(len(rows))
        for r, row in enumerate(rows):
            raw = row[k] if k < len(row) else ""
            cell = str(raw)
            try:
                values[r] = float(raw) if isinstance(raw, float) else parse_number(cell, decimal_comma=False)
            except ValueError:
                raise IngestError(path, cell_problem(cell, False), line=line_no[r],
                                  column=label) from None
        unit = units[k] if k < len(units) else ""
        seen.add(canon)
        columns.append((canon, unit, values, label))
    if not columns:
        # a step whose column row was lost reads its units row as labels: nothing is recognised
        raise IngestError(path, f"step {name!r}: no recognised column (column row missing or damaged?); "
                                f"labels: {[c for c in cols if c][:8]}", line=line_no[0] - 2)
    numeric_units = [u for u in units if str(u).strip() and is_number(str(u), decimal_comma=False)]
    if numeric_units:
        raise IngestError(path, f"step {name!r}: the units row holds numbers {numeric_units[:3]} (units row "
                                "missing?)", line=line_no[0] - 1)
    frame, labels = canonical_frame(path, columns)
    check_time(path, frame, line_no[0], np.asarray(line_no))
    return Block(name=name, index=index, data=frame,
                 meta=dict(meta_common, labels=labels, first_data_line=line_no[0]))



#: a TRIOS step sheet's name: the step and its 1-based position in the procedure ("Frequency sweep - 2")
_STEP_SHEET = re.compile(r".+ - \d+$")


def read_trios_xls(path) -> list[Block]:
    """Every step sheet of a TRIOS Excel (.xls, BIFF8) export.

    The ``Details`` sheet gives the measuring system (``Geometry name``, e.g. ``8.0mm parallel plate``: an
    8 mm plate). A damaged workbook (truncated, corrupt bytes) raises :class:`IngestError` naming the file,
    whatever xlrd raised (``XLRDError``, ``struct.error``, ``IndexError``, ``AssertionError``,
    ``RecursionError`` ...).
    """
    path = Path(path)
    try:
        return _read_xls(path)
    except IngestError:
        raise
    except Exception as exc:  # xlrd surfaces damage as any of a dozen exception types
        raise IngestError(path, f"not a readable TRIOS .xls workbook (truncated or damaged file?): "
                                f"{type(exc).__name__}: {exc}") from exc


def _read_xls(path: Path) -> list[Block]:
    book = xlrd.open_workbook(str(path), logfile=io.StringIO())  # xlrd's damage warnings go to the error
    geometry: dict = {}
    blocks = []
    for sheet in book.sheets():
        if sheet.name.lower() == "details":
            for r in range(sheet.nrows):
                vals = sheet.row_values(r)
                if len(vals) > 1 and str(vals[0]).strip().lower() == "geometry name":
                    geometry.update(measuring_system(str(vals[1])))
            continue
        if sheet.nrows < 4:
            if _STEP_SHEET.match(sheet.name):
                # TRIOS names each step's sheet "<step> - <k>"; one without a header and data lost them
                raise IngestError(path, f"step sheet {sheet.name!r} has {sheet.nrows} row(s): no header and data "
                                        f"(damaged workbook?)")
            continue  # Excel's empty default sheets ("Sheet1")
        name = str(sheet.cell_value(0, 0)).strip() or sheet.name
        cols = [str(v).strip() for v in sheet.row_values(1)]
        units = [str(v).strip() for v in sheet.row_values(2)]
        rows = []
        for r in range(3, sheet.nrows):
            vals = sheet.row_values(r)
            rows.append([v if isinstance(v, float) else str(v) for v in vals])
        blocks.append(_step_block(path, name, len(blocks) + 1, cols, units, rows, list(range(4, sheet.nrows + 1)),
                                  {"format": "ta_trios_xls", "sheet": sheet.name}))
    if not blocks:
        raise IngestError(path, "no step sheet with data in the workbook")
    for block in blocks:
        block.meta.update(geometry)
    return blocks
