"""Dataset writer: Anton Paar RheoCompass CSV exports, ``samples.csv``, ``dataset.yaml``, ``truth.json``.

The CSV layout is byte-for-byte the one of a real RheoCompass export (``shared/data/real/
rheocompass_cnf_hydrogel/HC1_stressrelaxation_20C_2.csv``): UTF-16 LE with BOM, tab separated, CRLF line
ends, decimal comma, a ``Test:``/``Result:``/``Interval:`` header, the column-name row, the sub-label row,
the ``[unit]`` row (first cell empty), data rows starting with ``Point No.`` and ending with the ``Status``
cell ``Dy_auto``, and an empty line at the end. Numbers carry 12 significant digits so that ingest returns
the generated channels to ~1e-12 relative precision. The project-header variant (``Project:``,
``Interval and data points:``, ``Interval data:``) is available through ``header="project"``.
"""
from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from ..canonical import atomic_write, to_jsonable

#: canonical variable -> (RheoCompass English column label, unit label, factor from SI to that unit)
RHEOCOMPASS_COLUMNS: dict[str, tuple[str, str, float]] = {
    "total_time": ("Time", "s", 1.0),
    "time": ("Interval Time", "s", 1.0),
    "frequency": ("Frequency", "Hz", 1.0),
    "angular_frequency": ("Angular Frequency", "rad/s", 1.0),
    "shear_strain": ("Shear Strain", "%", 100.0),
    "shear_rate": ("Shear Rate", "1/s", 1.0),
    "shear_stress": ("Shear Stress", "Pa", 1.0),
    "viscosity": ("Viscosity", "Pa·s", 1.0),
    "storage_modulus": ("Storage Modulus", "Pa", 1.0),
    "loss_modulus": ("Loss Modulus", "Pa", 1.0),
    "phase_angle": ("Phase Shift Angle", "°", 180.0 / np.pi),
    "raw_phase": ("Raw Phase", "°", 180.0 / np.pi),
    "relaxation_modulus": ("Relaxation Modulus", "Pa", 1.0),
    "creep_compliance": ("Creep Compliance", "1/Pa", 1.0),
    "torque": ("Torque", "mN·m", 1e3),
    "deflection_angle": ("Deflection Angle", "mrad", 1e3),
    "normal_force": ("Normal Force", "N", 1.0),
    "gap": ("Gap", "mm", 1e3),
    "temperature": ("Temperature", "°C", 1.0),
}

#: column order of an export (those present are written)
COLUMN_ORDER = tuple(RHEOCOMPASS_COLUMNS)

RESULT_NAMES = {
    "amplitude_sweep": "Amplitude sweep",
    "frequency_sweep": "Frequency sweep",
    "constant_shear_rate": "Rotation",
    "stress_relaxation": "Step strain",
    "creep_recovery": "Creep recovery",
    "flow_curve": "Flow curve",
}


def format_number(value: float, digits: int = 12) -> str:
    """RheoCompass number: decimal comma, ``E+04`` exponents, empty cell for NaN."""
    if value is None or not np.isfinite(value):
        return ""
    text = f"{float(value):.{digits}G}"
    return text.replace(".", ",")


def rheocompass_text(columns: Mapping[str, np.ndarray], test_name: str, result_name: str,
                     header: str = "simple", project: str = "tissuemech virtual rheometer") -> str:
    """Text of a RheoCompass export (one result, one interval) from canonical SI columns.

    With ``total_time`` (time since the start of the measurement session) the export has RheoCompass's two
    time columns, ``Time`` (session) and ``Interval Time`` (``time``, since the start of the test); without
    it the single ``Time`` column is the test time, as in a one-interval export.
    """
    names = [c for c in COLUMN_ORDER if c in columns]
    labels_of = dict(RHEOCOMPASS_COLUMNS)
    if "total_time" not in columns:
        labels_of["time"] = ("Time", "s", 1.0)
    unknown = set(columns) - set(RHEOCOMPASS_COLUMNS)
    if unknown:
        raise KeyError(f"no RheoCompass column for {sorted(unknown)}")
    n = len(np.asarray(columns[names[0]]))
    labels = ["Point No."] + [labels_of[c][0] for c in names] + ["Status"]
    units = [""] + [f"[{labels_of[c][1]}]" for c in names] + [""]
    lines: list[str] = []
    if header == "simple":
        lines += [f"Test:\t{test_name}", f"Result:\t{result_name}", "Interval:\t1", "\t".join(labels),
                  "\t" * (len(labels) - 1), "\t".join(units)]
    elif header == "project":
        lines += [f"Project:\t{project}", "", f"Test:\t{test_name}", "", f"Result:\t{result_name}", "",
                  f"Interval and data points:\t1\t{n}", "Interval data:\t" + "\t".join(labels),
                  "\t" * len(labels), "\t" + "\t".join(units)]
    else:
        raise ValueError("header must be 'simple' or 'project'")
    scaled = [np.asarray(columns[c], float) * labels_of[c][2] for c in names]
    lead = "" if header == "simple" else "\t"
    for i in range(n):
        cells = [str(i + 1)] + [format_number(col[i]) for col in scaled] + ["Dy_auto"]
        lines.append(lead + "\t".join(cells))
    return "\r\n".join(lines) + "\r\n\r\n"


def write_rheocompass_csv(path: str | Path, columns: Mapping[str, np.ndarray], test_name: str,
                          result_name: str, header: str = "simple") -> Path:
    """Write a RheoCompass CSV export (UTF-16 LE with BOM), atomically."""
    data = b"\xff\xfe" + rheocompass_text(columns, test_name, result_name, header).encode("utf-16-le")

    def _w(tmp):
        with open(tmp, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o644)            # mkstemp creates 0600; dataset files are meant to be shared
    return atomic_write(path, _w)


SAMPLE_COLUMNS = ("file", "specimen", "sample", "test", "order", "shear_rate_1_per_s", "strain_pct", "stress_pa",
                  "frequency_hz", "radius_mm", "gap_mm", "temperature_c", "started_at")


def write_samples_csv(path: str | Path, rows: Sequence[Mapping[str, object]]) -> Path:
    """Write the sample sheet (columns :data:`SAMPLE_COLUMNS`, then any extra covariate columns)."""
    df = pd.DataFrame(list(rows))
    cols = [c for c in SAMPLE_COLUMNS if c in df.columns] + [c for c in df.columns if c not in SAMPLE_COLUMNS]
    def _w(tmp):
        df[cols].to_csv(tmp, index=False, float_format="%.10g")
        os.chmod(tmp, 0o644)
    return atomic_write(path, _w)


def write_json(path: str | Path, obj) -> Path:
    """``truth.json``: NaN stays NaN (:func:`tissuemech.canonical.to_jsonable` with ``nonfinite_as_null=False``)."""
    text = json.dumps(to_jsonable(obj, nonfinite_as_null=False), indent=1, sort_keys=False)
    return _write_text(path, text + "\n")


def write_yaml(path: str | Path, obj) -> Path:
    text = yaml.safe_dump(to_jsonable(obj, nonfinite_as_null=False), sort_keys=False, allow_unicode=True, width=110)
    return _write_text(path, text)


def _write_text(path: str | Path, text: str) -> Path:
    def _w(tmp):
        Path(tmp).write_text(text, encoding="utf-8")
        os.chmod(tmp, 0o644)
    return atomic_write(path, _w)
