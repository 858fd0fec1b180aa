"""Documented tidy CSV, for curves from other devices (uniaxial, simple shear, indentation).

Two forms:

* **with a header**: one row of ``<canonical name> [<unit>]`` cells, e.g.
  ``stretch [1],nominal_stress [kPa]`` or ``shear_strain [%],shear_stress [Pa],time [s]``; comma separated,
  decimal point; names from :data:`tissuemech.canonical.CANONICAL_VARIABLES`;
* **headerless numeric columns** (e.g. the digitised Budday et al. 2017 curves ``-0.198, -0.535``): the
  sample sheet says what they are with two extra columns, ``columns`` (canonical names joined by ``;``) and
  ``units`` (their units joined by ``;``), passed here as ``columns=`` and ``units=``.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..canonical import CANONICAL_VARIABLES
from .blocks import Block, canonical_frame, cell_problem, check_time, parse_number
from .errors import IngestError
from .textfile import decode_text

_HEADER_CELL = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*\[([^\]]*)\]\s*$")


def looks_like_tidy(text: str) -> bool:
    first = next((line for line in text.splitlines() if line.strip()), "")
    cells = first.split(",")
    if all(_HEADER_CELL.match(c) for c in cells):
        return True
    try:
        [float(c) for c in cells]
        return len(cells) >= 2
    except ValueError:
        return False


def read_tidy(path, text: str | None = None, columns: str | None = None, units: str | None = None) -> list[Block]:
    """The tidy CSV (one block). ``columns``/``units``: ``;``-joined names and units of a headerless file."""
    path = Path(path)
    text = decode_text(path) if text is None else text
    lines = text.splitlines()
    start = 0
    while start < len(lines) and not lines[start].strip():
        start += 1
    if start == len(lines):
        raise IngestError(path, "empty file")
    header = [c.strip() for c in lines[start].split(",")]
    if all(_HEADER_CELL.match(c) for c in header):
        names = [_HEADER_CELL.match(c).group(1) for c in header]
        unit_list = [_HEADER_CELL.match(c).group(2).strip() for c in header]
        first = start + 1
    else:
        if not columns:
            raise IngestError(path, "headerless numeric file: the sample sheet must give its 'columns' and "
                                    "'units' (e.g. columns=shear_strain;shear_stress units=1;kPa)", line=start + 1)
        names = [c.strip() for c in str(columns).split(";")]
        unit_list = [u.strip() for u in str(units or "").split(";")]
        if len(unit_list) != len(names):
            raise IngestError(path, f"sample sheet gives {len(names)} columns but {len(unit_list)} units")
        first = start
    for k, name in enumerate(names):
        if name not in CANONICAL_VARIABLES:
            raise IngestError(path, f"unknown column {name!r}; use canonical names: {sorted(CANONICAL_VARIABLES)}",
                              line=start + 1, column=k + 1)
    rows, line_no = [], []
    for j in range(first, len(lines)):
        if not lines[j].strip():
            continue
        cells = lines[j].split(",")
        if len(cells) != len(names):
            raise IngestError(path, f"expected {len(names)} values, found {len(cells)} (truncated or malformed row)",
                              line=j + 1)
        row = []
        for k, cell in enumerate(cells):
            try:
                row.append(parse_number(cell, decimal_comma=False))
            except ValueError:
                raise IngestError(path, cell_problem(cell, False), line=j + 1,
                                  column=names[k]) from None
        rows.append(row)
        line_no.append(j + 1)
    if not rows:
        raise IngestError(path, "no data rows", line=first + 1)
    data = np.array(rows, float)
    frame, labels = canonical_frame(path, [(n, u, data[:, k], n) for k, (n, u) in enumerate(zip(names, unit_list))])
    check_time(path, frame, line_no[0], np.asarray(line_no))
    return [Block(name="data", index=1, data=frame,
                  meta={"format": "tidy_csv", "labels": labels, "first_data_line": line_no[0]})]
