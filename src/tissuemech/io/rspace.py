"""Malvern Kinexus rSpace CSV export (``instrument_formats.md`` section 2.8).

One header line, then one row per sample; semicolon-separated with a decimal comma in the locales seen
(comma- or tab-separated with a decimal point is read too); UTF-8. The unit sits in the last parentheses of
the column name (``Shear rate(s-¹)``, ``Shear modulus (elastic component)(Pa)``, ``Torque(N m)``) and the step
is named on every row in ``Action Name``::

    Action Name;Time (sequence)(s);Time (action)(s);Shear stress(Pa);Shear rate(s-¹);...;Gap(mm)
    Pre Shear Initial;112,3;1,000;30,54;47,57;4,75275E+003;0,2044;;;;;;;1,284E-003;4,516;20,93;9,1500

Each run of consecutive rows with the same action name is one :class:`~tissuemech.io.blocks.Block`
(``name`` = the action name, ``index`` counting from 1). ``Time (action)`` is ``time``, ``Time (sequence)``
is ``total_time``. Steady and oscillation twins share a canonical name (``Shear strain`` / ``Complex shear
strain``): the one holding numbers in the action is used. In oscillation actions the rows that fill only the
raw channels (torque, angular displacement, normal force; no frequency or modulus) are the sampled waveform:
they are dropped (counted in ``meta["waveform_rows"]``), as RheoCompass waveform rows are. An action whose
rows all fill only the raw channels (a file cut inside an oscillation action, before its first point) is an
error, never read as points. Columns empty throughout an action are left out of its block.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .blocks import Block, canonical_frame_at, check_time, detect_decimal_comma, pick_columns
from .errors import IngestError
from .textfile import decode_text

#: canonical variable -> lower-cased rSpace column names (unit stripped), preferred first
CANDIDATES: dict[str, tuple[str, ...]] = {
    "time": ("time (action)", "action time"),
    "total_time": ("time (sequence)", "sequence time", "time"),
    "shear_stress": ("shear stress", "complex shear stress"),
    "shear_strain": ("shear strain", "complex shear strain"),
    "shear_rate": ("shear rate",),
    "viscosity": ("shear viscosity", "viscosity"),
    "complex_viscosity": ("complex shear viscosity", "complex viscosity"),
    "storage_modulus": ("shear modulus (elastic component)", "elastic modulus"),
    "loss_modulus": ("shear modulus (viscous component)", "viscous modulus"),
    "complex_modulus": ("shear modulus (complex component)", "complex modulus"),
    "phase_angle": ("phase angle",),
    "frequency": ("frequency",),
    "angular_frequency": ("angular frequency",),
    "torque": ("torque",),
    "deflection_angle": ("angular displacement",),
    "normal_force": ("normal force",),
    "gap": ("gap",),
    "temperature": ("temperature",),
}
#: columns a raw waveform sample fills (everything else is empty in such a row)
_RAW_ONLY = ("time (sequence)", "time (action)", "sequence time", "action time", "time", "torque",
             "angular displacement", "normal force", "temperature", "gap")
#: columns that only oscillation *points* fill (the raw waveform samples leave them empty)
_POINT_ONLY = ("frequency", "complex shear strain", "complex shear stress", "shear modulus (elastic component)",
               "shear modulus (complex component)", "phase angle")
_HEADER_CELL = re.compile(r"^(?P<label>.*?)\s*\((?P<unit>[^()]*)\)$")
_ACTION = ("action name", "action")


def looks_like_rspace(text: str) -> bool:
    first = text.lstrip("\ufeff").split("\n", 1)[0]
    sep = _sep(first)
    cells = [c.strip() for c in first.split(sep)]
    return bool(cells) and cells[0].lower() in _ACTION and sum(bool(_HEADER_CELL.match(c)) for c in cells) >= 2


def _sep(header: str) -> str:
    return max((";", "\t", ","), key=header.count)


def read_rspace(path, text: str | None = None) -> list[Block]:
    """Every action of a Kinexus rSpace CSV export as canonical blocks (see module docstring)."""
    path = Path(path)
    text = decode_text(path) if text is None else text
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise IngestError(path, "empty file", line=1)
    sep = _sep(lines[0])
    header = [c.strip() for c in lines[0].split(sep)]
    if header[0].lower() not in _ACTION:
        raise IngestError(path, "first column must be 'Action Name' (rSpace export)", line=1, column=1)
    table = {}
    for k, cell in enumerate(header[1:], start=1):
        m = _HEADER_CELL.match(cell)
        label, unit = (m.group("label").strip(), m.group("unit").strip()) if m else (cell, "")
        if label.lower() not in table:
            table[label.lower()] = (cell, unit, k)
    comma = detect_decimal_comma(lines[1:], sep)
    groups: list[tuple[str, list[list[str]], list[int]]] = []
    for j in range(1, len(lines)):
        if not lines[j].strip():
            continue
        cells = lines[j].split(sep)
        if len(cells) != len(header):
            raise IngestError(path, f"truncated or malformed row: {len(cells)} fields, the header has {len(header)}",
                              line=j + 1)
        action = cells[0].strip()
        if not action:
            raise IngestError(path, "empty 'Action Name'", line=j + 1, column=header[0])
        if not groups or groups[-1][0] != action:
            groups.append((action, [], []))
        groups[-1][1].append(cells)
        groups[-1][2].append(j + 1)
    if not groups:
        raise IngestError(path, "header line but no data rows (truncated file?)", line=1)
    meta_common = {"format": "malvern_rspace", "decimal_comma": comma}
    return [_block(path, name, k, rows, line_no, table, comma, meta_common)
            for k, (name, rows, line_no) in enumerate(groups, start=1)]


def _block(path, name, index, rows, line_no, table, comma, meta_common) -> Block:
    point_cols = [table[c][2] for c in _POINT_ONLY if c in table]
    is_point = [any(row[k].strip() for k in point_cols) for row in rows]
    derived_cols = [k for low, (_, _, k) in table.items() if low not in _RAW_ONLY]
    if point_cols and not any(is_point) and not any(row[k].strip() for row in rows for k in derived_cols):
        # only raw channels filled in every row: the sampled waveform of an oscillation action whose points
        # are missing (file cut inside the action); they are never returned as points
        raise IngestError(path, f"action {name!r} holds only raw waveform samples (torque, displacement), no "
                                "oscillation points: file cut inside an oscillation action?", line=line_no[0])
    waveform_rows = 0
    if any(is_point) and not all(is_point):
        waveform_rows = len(rows) - sum(is_point)
        rows = [r for r, p in zip(rows, is_point) if p]
        line_no = [n for n, p in zip(line_no, is_point) if p]
    columns = pick_columns(path, CANDIDATES, table, lambda k: [row[k] for row in rows], line_no, comma)
    if not columns:
        raise IngestError(path, f"action {name!r} has no recognised column with data", line=line_no[0])
    frame, labels = canonical_frame_at(path, columns, 1)
    check_time(path, frame, line_no[0], np.asarray(line_no))
    meta = dict(meta_common, labels=labels, first_data_line=line_no[0], waveform_rows=waveform_rows)
    return Block(name=name, index=index, data=frame, meta=meta)
