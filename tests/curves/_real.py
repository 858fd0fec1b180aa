"""Readers of the two real exports these tests use.

They go through the package reader (``tissuemech.io.dispatch.read_export``) when it gives the needed variables;
otherwise (and while it did not exist) a minimal reading done
here from the documented layout (RheoCompass UTF-16 tab CSV with decimal comma; TRIOS .xls step sheets with
name/column/unit rows). Units are converted to the canonical SI units explicitly.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from tissuemech.canonical import make_run_dataset


def _io_read(path: Path):
    """Canonical runs from the package reader, or None when it is not available."""
    try:
        from tissuemech.io.dispatch import read_export  # noqa: PLC0415
    except ImportError:
        return None
    try:
        blocks = read_export(path)
    except Exception:  # reader still in progress elsewhere: fall back to the local reading
        return None
    runs = []
    for block in blocks:
        columns = {name: block.data[name].to_numpy(dtype=float) for name in block.data.columns}
        geometry = {k: block.meta.get(k) for k in ("radius_m", "gap_m") if isinstance(block.meta.get(k), float)}
        try:
            runs.append(make_run_dataset(columns, {"block": block.name, **geometry}))
        except (KeyError, ValueError, TypeError):
            continue
    return runs


def _io_pick(path: Path, wanted) -> xr.Dataset | None:
    """The package reader's run of ``path`` that satisfies ``wanted`` (None: fall back to local reading)."""
    for run in _io_read(path) or []:
        if isinstance(run, xr.Dataset) and wanted(run):
            return run
    return None


def read_rheocompass_relaxation(path: Path, sample: str) -> xr.Dataset:
    """One stress-relaxation run of the CNF hydrogel exports as a canonical run."""
    attrs = {"dataset": "cnf_hydrogel", "run": path.stem, "test": "stress_relaxation", "specimen": "HC1",
             "sample": sample, "order": 1, "source_file": path.name, "source_sha256": ""}
    run = _io_pick(path, lambda r: "time" in r and "shear_stress" in r and "shear_strain" in r)
    if run is not None:
        run.attrs.update({k: v for k, v in attrs.items() if k in ("test", "specimen", "sample", "run")})
        return run
    lines = path.read_bytes().decode("utf-16").splitlines()
    header = lines[3].split("\t")
    units = lines[5].split("\t")
    assert header[1] == "Time" and units[1] == "[s]" and units[2] == "[%]" and units[5] == "[mN·m]"
    rows = [line.split("\t") for line in lines[6:] if line.strip()]
    table = np.array([[float(v.replace(",", ".")) for v in row[1:7]] for row in rows])
    columns = {
        "time": table[:, 0],
        "shear_strain": table[:, 1] / 100.0,
        "shear_stress": table[:, 2],
        "relaxation_modulus": table[:, 3],
        "torque": table[:, 4] * 1e-3,
        "temperature": table[:, 5],
    }
    return make_run_dataset(columns, attrs)


def read_trios_fungi_amplitude_sweep(path: Path) -> xr.Dataset:
    """The HR-20 fungi amplitude sweep step as a canonical run."""
    attrs = {"dataset": "trios_fungi", "run": "fungi_as", "test": "amplitude_sweep", "specimen": "fungi",
             "sample": "1", "order": 2, "source_file": path.name, "source_sha256": "", "frequency_hz": 0.5}
    run = _io_pick(path, lambda r: all(v in r for v in ("shear_strain", "storage_modulus", "loss_modulus"))
                   and r.sizes["point"] == 39)
    if run is not None:
        run.attrs.update({k: v for k, v in attrs.items() if k in ("test", "specimen", "sample", "run")})
        return run
    import xlrd  # noqa: PLC0415

    sheet = xlrd.open_workbook(str(path)).sheet_by_name("Amplitude sweep - 2")
    names = sheet.row_values(1)
    units = sheet.row_values(2)
    table = np.array([sheet.row_values(r) for r in range(3, sheet.nrows)], dtype=float)
    col = {name: table[:, i] for i, name in enumerate(names)}
    assert units[names.index("Oscillation strain")] == "%"
    assert units[names.index("Raw phase")] == "°"
    assert units[names.index("Oscillation torque")] == "µN.m"
    columns = {
        "storage_modulus": col["Storage modulus"],
        "loss_modulus": col["Loss modulus"],
        "loss_factor": col["Tan(delta)"],
        "angular_frequency": col["Angular frequency"],
        "frequency": col["Angular frequency"] / (2 * np.pi),
        "torque": col["Oscillation torque"] * 1e-6,
        "time": col["Step time"],
        "temperature": col["Temperature"],
        "raw_phase": np.deg2rad(col["Raw phase"]),
        "deflection_angle": col["Oscillation displacement"],
        "shear_strain": col["Oscillation strain"] / 100.0,
    }
    return make_run_dataset(columns, attrs)


def read_trios_fungi_frequency_sweep(path: Path) -> xr.Dataset:
    """The HR-20 fungi frequency sweep as a canonical run.

    The export has no strain column: the rim strain is computed from the oscillation displacement θ as
    θ·R/h with the 8 mm plate (R = 4 mm) and the gap at the end of the ``Axial - 1`` pre-step (µm).
    """
    attrs = {"dataset": "trios_fungi", "run": "fungi_fs", "test": "frequency_sweep", "specimen": "fungi",
             "sample": "1", "order": 2, "source_file": path.name, "source_sha256": ""}
    run = _io_pick(path, lambda r: all(v in r for v in ("shear_strain", "storage_modulus", "loss_modulus"))
                   and ("angular_frequency" in r or "frequency" in r) and r.sizes["point"] == 31)
    if run is not None:
        run.attrs.update({k: v for k, v in attrs.items() if k in ("test", "specimen", "sample", "run")})
        return run
    import xlrd  # noqa: PLC0415

    book = xlrd.open_workbook(str(path))
    axial = book.sheet_by_name("Axial - 1")
    assert axial.row_values(1)[4] == "Gap" and axial.row_values(2)[4] == "µm"
    gap_m = axial.row_values(axial.nrows - 1)[4] * 1e-6
    sheet = book.sheet_by_name("Frequency sweep - 2")
    names = sheet.row_values(1)
    table = np.array([sheet.row_values(r) for r in range(3, sheet.nrows)], dtype=float)
    col = {name: table[:, i] for i, name in enumerate(names)}
    radius_m = 4e-3
    columns = {
        "storage_modulus": col["Storage modulus"],
        "loss_modulus": col["Loss modulus"],
        "angular_frequency": col["Angular frequency"],
        "deflection_angle": col["Oscillation displacement"],
        "shear_strain": col["Oscillation displacement"] * radius_m / gap_m,
    }
    return make_run_dataset(columns, {**attrs, "radius_m": radius_m, "gap_m": gap_m})
