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
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .blocks import Block, canonical_frame, check_time, decode_text, detect_decimal_comma, parse_number
from .errors import IngestError

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
_INTERVAL = ("interval:", "intervalle:", "intervall:", "interval and data points:", "intervalle et points de données:",
             "intervall und datenpunkte:")
_INTERVAL_DATA = ("interval data:", "interval données:", "intervalle données:", "intervalldaten:")
#: point numbers the software marks as invalid ("12 (invalid)", "12  (invalide)", "12 (ungültig)")
_INVALID = re.compile(r"\((invalid|invalide|ungültig|ungueltig)\)", re.IGNORECASE)
_POINT_NO = ("point no.", "point no", "punkt nr.", "messpunkt", "n° de point")


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
    meta_common = {"format": "anton_paar_rheocompass", "decimal_comma": comma}
    blocks: list[Block] = []
    index = 0
    result = "result"
    interval = "1"
    i = 0
    while i < len(lines):
        cells = lines[i].split(sep)
        head = cells[0].strip().lower()
        if head.startswith(("test:",)):
            meta_common["test_name"] = cells[1].strip() if len(cells) > 1 else ""
        if head.startswith(_RESULT):
            result = cells[1].strip() if len(cells) > 1 else "result"
        elif head.startswith(_INTERVAL):
            interval = cells[1].strip() if len(cells) > 1 else str(len(blocks) + 1)
        elif head.startswith(_INTERVAL_DATA) or head in _POINT_NO:
            offset = 1 if head.startswith(_INTERVAL_DATA) else 0
            names = [c.strip() for c in cells]
            if i + 2 >= len(lines):
                raise IngestError(path, "truncated file: column header without sub-label and unit rows", line=i + 1)
            sub = lines[i + 1].split(sep)
            units = lines[i + 2].split(sep)
            j = i + 3
            rows, line_no, invalid = [], [], 0
            while j < len(lines):
                raw = lines[j]
                row = raw.split(sep)
                first = row[0].strip().lower()
                if first.endswith(":") and any(first.startswith(k) for k in _RESULT + _INTERVAL + _INTERVAL_DATA
                                               + ("test:", "project:", "projet:")):
                    break
                if not raw.strip():
                    j += 1
                    # an empty line ends the block when the next non-empty line starts a new section
                    continue
                pn = row[offset].strip() if len(row) > offset else ""
                if _INVALID.search(pn):
                    invalid += 1
                elif pn:
                    rows.append(row)
                    line_no.append(j + 1)
                j += 1
            index += 1
            if rows or not invalid:
                block = _block(path, names, sub, units, rows, line_no, offset, comma, result, interval,
                               index, i + 1, meta_common)
                block.meta["invalid_points"] = invalid
                blocks.append(block)
            # an interval whose points are all flagged invalid by the instrument is not a block of data
            i = j
            continue
        i += 1
    if not blocks:
        raise IngestError(path, "no data block found (expected a 'Point No.' or 'Interval data:' column header row)")
    return blocks


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
                raise IngestError(path, f"text in a numeric column: {cell.strip()!r}", line=line_no[r],
                                  column=label) from None
        seen.add(name)
        columns.append((name, unit, values, label))
    if not columns:
        raise IngestError(path, f"block '{result} / {interval}' has no recognised column; labels: {names[offset + 1:]}",
                          line=header_line)
    frame, labels = canonical_frame(path, columns)
    check_time(path, frame, line_no[0], np.asarray(line_no))
    meta = dict(meta_common, labels=labels, first_data_line=line_no[0], result=result, interval=interval)
    return Block(name=f"{result} / {interval}", index=index, data=frame, meta=meta)
