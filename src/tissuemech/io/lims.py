"""TA Instruments "LIMS export format" (ARES-G2 / TRIOS, ``instrument_formats.md`` section 2.4).

An INI-like text file (UTF-8, tab-separated, decimal point)::

    [Version]
    TA Instruments LIMS export format version	0
    [Header] [Sample] [Geometry: Standard] ... [Parameters: ...]     (key<TAB>value lines)
    [Step]
    Step name	Frequency sweep (150.0 °C)
    Number of points	17
    Variables	Run time	Temperature	Angular frequency	...	Oscillation torque	...
    Units	s	°C	rad/s	...	g.cm	...	1/MPa	...	kPa
    Data point	552.17	149.978	0.6283	...

Every ``[Step]`` is one :class:`~tissuemech.io.blocks.Block` (``name`` = the step name). Units are converted per
column (torque in g·cm, compliances in 1/MPa, some moduli in kPa); a canonical column in a unit without a known
conversion is an error, never assumed SI. The declared ``Number of points`` is checked, so a file cut short
is reported as truncated. Numeric columns outside the canonical set (compliances, ``G*.sin(delta)`` ...) are
kept, in SI, in ``meta["auxiliary"]``. A geometry diameter/gap of zero (anonymised exports) is treated as
unknown.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..units import UnknownUnitError
from .blocks import Block, auxiliary_frame, canonical_frame_at, check_time, pick_columns
from .errors import IngestError
from .geometry import measuring_system, value_with_unit
from .textfile import decode_text

#: canonical variable -> lower-cased LIMS/TRIOS variable names, preferred first (oscillation amplitude before
#: the steady value of the same quantity; the first one holding numbers in a step is used)
CANDIDATES: dict[str, tuple[str, ...]] = {
    "time": ("step time", "time"),
    "total_time": ("run time",),
    "shear_strain": ("oscillation strain", "strain"),
    "shear_stress": ("oscillation stress", "stress"),
    "shear_rate": ("shear rate",),
    "viscosity": ("viscosity",),
    "complex_viscosity": ("complex viscosity",),
    "storage_modulus": ("storage modulus",),
    "loss_modulus": ("loss modulus",),
    "complex_modulus": ("complex modulus",),
    "loss_factor": ("tan(delta)",),
    "phase_angle": ("phase angle",),
    "raw_phase": ("raw phase (torque)", "raw phase"),
    "frequency": ("frequency",),
    "angular_frequency": ("angular frequency",),
    "torque": ("oscillation torque", "torque"),
    "deflection_angle": ("oscillation displacement", "displacement"),
    "normal_force": ("axial force", "normal force"),
    "gap": ("gap",),
    "temperature": ("temperature",),
    "relaxation_modulus": ("modulus", "relaxation modulus"),
    "creep_compliance": ("compliance", "creep compliance"),
}
_MAGIC = "ta instruments lims export format"


def looks_like_lims(text: str) -> bool:
    return _MAGIC in text[:2000].lower()


def _geometry(path: Path, lines: list[str]) -> dict:
    """Measuring system (``Geometry name``/``Geometry type`` of ``[Geometry]``), plate radius and gap of
    ``[Geometry: Standard]`` (value and unit in one cell: ``25.0 mm``), dimension-checked (a gap in ``s`` is an
    error naming the line); zero values (anonymised exports) are unknown."""
    meta, section = {}, ""
    for n, line in enumerate(lines, start=1):
        s = line.strip()
        if s.startswith("[") and s.endswith("]"):
            section = s.lower()
            continue
        if not section.startswith("[geometry"):
            continue
        cells = [c.strip() for c in line.split("\t")]
        if len(cells) < 2 or not cells[1]:
            continue
        key = cells[0].lower()
        if key in ("geometry name", "name") and section == "[geometry]":
            meta.update(measuring_system(cells[1]))
            continue
        if key not in ("diameter", "gap"):
            continue
        try:
            value = value_with_unit(cells[1])
        except (ValueError, UnknownUnitError) as exc:
            raise IngestError(path, f"geometry {cells[0]!r}: {exc}", line=n, column=2) from exc
        if value > 0:  # anonymised exports write 0.0 mm
            if key == "diameter":
                meta["radius_m"] = value / 2.0
            else:
                meta["gap_m"] = value
    return meta


#: rows that belong inside a [Step] section
_STEP_KEYS = ("step name", "number of points", "variables", "units", "data point")


def read_lims(path, text: str | None = None) -> list[Block]:
    """Every ``[Step]`` of a TA LIMS export as canonical blocks (see module docstring)."""
    path = Path(path)
    text = decode_text(path) if text is None else text
    lines = text.splitlines()
    starts = [i for i, line in enumerate(lines) if line.strip().lower() == "[step]"]
    if not starts:
        raise IngestError(path, "no [Step] block in a TA LIMS export")
    for j, line in enumerate(lines[: starts[0]]):
        if line.split("\t")[0].strip().lower() in _STEP_KEYS:
            raise IngestError(path, f"{line.split(chr(9))[0].strip()!r} row before the first [Step] header "
                                    f"([Step] line missing?)", line=j + 1)
    meta_common = {"format": "ta_lims", **_geometry(path, lines[: starts[0]])}
    blocks = []
    for b, s in enumerate(starts):
        end = starts[b + 1] if b + 1 < len(starts) else len(lines)
        blocks.append(_step(path, lines, s, end, b + 1, meta_common))
    return blocks


def _step(path: Path, lines: list[str], start: int, end: int, index: int, meta_common: dict) -> Block:
    keys: dict[str, tuple[int, list[str]]] = {}
    rows, line_no = [], []
    for j in range(start + 1, end):
        cells = lines[j].split("\t")
        key = cells[0].strip().lower()
        if key == "data point":
            rows.append(cells)
            line_no.append(j + 1)
        elif key and key not in keys:
            keys[key] = (j + 1, cells)
    if "step name" in keys and not (len(keys["step name"][1]) > 1 and keys["step name"][1][1].strip()):
        raise IngestError(path, "'Step name' row without a name (row cut short?)", line=keys["step name"][0])
    if "step name" not in keys:
        # every LIMS step is named (the name carries the test and its temperature, instrument_formats.md 2.4)
        raise IngestError(path, "[Step] without a 'Step name' row (line deleted?)", line=start + 1)
    name = keys["step name"][1][1].strip()
    for needed in ("variables", "units"):
        if needed not in keys:
            raise IngestError(path, f"step {name!r} has no '{needed.capitalize()}' row (truncated file?)",
                              line=start + 1)
    variables_line, variables = keys["variables"]
    units_line, units = keys["units"]
    if len(units) != len(variables):
        raise IngestError(path, f"'Units' row has {len(units) - 1} units for {len(variables) - 1} variables",
                          line=units_line)
    declared = None
    if "number of points" in keys:
        try:
            declared = int(keys["number of points"][1][1])
        except (IndexError, ValueError):
            raise IngestError(path, "'Number of points' is not an integer", line=keys["number of points"][0]) from None
    last_line = line_no[-1] if line_no else units_line
    if declared is not None and len(rows) != declared:
        what = "truncated file" if len(rows) < declared else "more points than declared"
        raise IngestError(path, f"{what}: step {name!r} declares {declared} points, found {len(rows)}",
                          line=last_line)
    if not rows:
        raise IngestError(path, f"step {name!r} has no data points", line=units_line)
    for row, ln in zip(rows, line_no):
        if len(row) != len(variables):
            raise IngestError(path, f"truncated or malformed data row: {len(row) - 1} values for "
                                    f"{len(variables) - 1} variables", line=ln)
    table = {}
    for k in range(1, len(variables)):
        low = variables[k].strip().lower()
        if low and low not in table:  # repeated names keep their first occurrence
            table[low] = (variables[k].strip(), units[k].strip(), k)
    columns = pick_columns(path, CANDIDATES, table, lambda k: [row[k] for row in rows], line_no,
                           decimal_comma=False)
    if not columns:
        raise IngestError(path, f"step {name!r} has no recognised variable; variables: {variables[1:]}",
                          line=variables_line)
    frame, labels = canonical_frame_at(path, columns, units_line)
    check_time(path, frame, line_no[0], np.asarray(line_no))
    used = {label.lower() for _, _, _, label in columns}
    aux = auxiliary_frame([(label, unit, [row[k] for row in rows]) for low, (label, unit, k) in table.items()
                           if low not in used], decimal_comma=False)
    meta = dict(meta_common, labels=labels, first_data_line=line_no[0], auxiliary=aux,
                declared_points=declared)
    return Block(name=name, index=index, data=frame, meta=meta)
