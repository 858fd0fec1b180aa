"""Sample-sheet rows -> canonical run files (``results/<dataset>/runs/<run>.nc``) and an ingest report.

Each row is read, converted and written independently: a bad file or row is listed in the report with the
reason (file, line/column, problem) and the other runs are still processed. Inputs are only read (raw/
stays untouched); outputs are written atomically.
"""
from __future__ import annotations

import logging
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from ..canonical import make_run_dataset, sha256_of, write_netcdf, write_text
from .blocks import Block
from .dispatch import read_export
from .errors import IngestError
from .geometry import AXIAL_STEP_SOURCE, CONFLICT_REL, axial_step_gap, dataset_geometry, resolve_geometry
from .plausibility import diameter_problem, ranges_with, temperature_problem
from .quality import flag_run_files
from .samples import (READER_OPTIONS, STANDARD, dataset_warnings, load_dataset_yaml, load_samples, parse_row,
                      source_folder)

log = logging.getLogger(__name__)
REPORT_COLUMNS = ("run", "file", "block", "test", "specimen", "sample", "status", "reason", "line", "column",
                  "warnings", "notes")
#: test kinds measured between plates (a missing radius or gap is a report warning for these only)
PLATE_TESTS = ("amplitude_sweep", "frequency_sweep", "constant_shear_rate", "stress_relaxation", "creep_recovery",
               "flow_curve")


def run_id(row: dict) -> str:
    """Stable run name: ``<specimen>_<sample>_<test>_<order>[_b<block>]`` with unsafe characters replaced."""
    parts = [row["specimen"], row["sample"], row["test"], str(row["order"])]
    if row.get("block") not in (None, ""):
        parts.append(f"b{row['block']}")
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", "_".join(map(str, parts)))


#: canonical variables a run of each test kind must hold (each entry: alternatives, at least one present)
REQUIRED_VARIABLES: dict[str, tuple[tuple[str, ...], ...]] = {
    "amplitude_sweep": (("shear_strain",), ("storage_modulus",), ("loss_modulus",)),
    "frequency_sweep": (("frequency", "angular_frequency"), ("storage_modulus",), ("loss_modulus",)),
    "constant_shear_rate": (("time",), ("shear_stress",)),
    "stress_relaxation": (("time",), ("shear_stress", "relaxation_modulus")),
    "creep_recovery": (("time",), ("shear_strain", "creep_compliance")),
    "flow_curve": (("shear_rate",), ("shear_stress", "viscosity")),
    "simple_shear": (("shear_strain",), ("shear_stress", "nominal_stress")),
    "uniaxial": (("stretch",), ("nominal_stress",)),
    "indentation": (("displacement",), ("force",)),
}


def missing_variables(block: Block, test: str) -> list[tuple[str, ...]]:
    """The groups of :data:`REQUIRED_VARIABLES` of ``test`` of which ``block`` holds no data."""
    return [alternatives for alternatives in REQUIRED_VARIABLES.get(test, ())
            if not any(v in block.data and block.data[v].notna().any() for v in alternatives)]


def check_required(block: Block, test: str, path) -> None:
    """The block holds the variables its test kind needs, at two points at least (a curve).

    Raises IngestError naming the export: a missing column, or fewer than two points that hold every required
    variable (an export with one data row).
    """
    missing = missing_variables(block, test)
    if missing:
        wanted = " or ".join(repr(v) for v in missing[0])
        raise IngestError(path, f"missing column: block {block.name!r} has no {wanted} data, needed for a "
                                f"{test} run; it has {list(block.data.columns)}",
                          line=block.meta.get("first_data_line"), column=missing[0][0])
    complete = np.ones(len(block.data), bool)
    for alternatives in REQUIRED_VARIABLES.get(test, ()):
        complete &= np.any([block.data[v].notna().to_numpy() for v in alternatives if v in block.data], axis=0)
    if complete.sum() < 2:
        raise IngestError(path, f"block {block.name!r} holds {int(complete.sum())} data point(s) with the {test} "
                                "variables: a curve needs at least 2 (an export with one data row?)",
                          line=block.meta.get("first_data_line"))


def select_block(blocks: list[Block], block, path, test: str | None = None) -> tuple[Block, str]:
    """The block a sample-sheet row asks for (index from 1, or a name), and a note when it was chosen here.

    Without a ``block``: the only block of the file; else, given the row's ``test``, the one block that holds
    that test kind's variables (:data:`REQUIRED_VARIABLES`), with the note ``block chosen: ...``. Several or no
    such blocks is an error listing them.
    """
    listing = ", ".join(f"{b.index}: {b.name}" for b in blocks)
    if block in (None, ""):
        if len(blocks) == 1:
            return blocks[0], ""
        matching = [b for b in blocks if test and not missing_variables(b, test)]
        if len(matching) == 1:
            b = matching[0]
            return b, (f"block chosen: {b.index}: {b.name!r}, the only one of the file's {len(blocks)} blocks "
                       f"with {test} data")
        what = (f"{len(matching)} of them hold {test} data ({', '.join(f'{b.index}: {b.name}' for b in matching)})"
                if matching else f"none holds {test} data" if test else "")
        raise IngestError(path, f"file holds {len(blocks)} blocks ({listing}); {what}: the sample sheet must "
                                "select one with 'block'")
    text = str(block).strip()
    if text.isdigit() and len(text) <= 9:
        k = int(text)
        for b in blocks:
            if b.index == k:
                return b, ""
    for b in blocks:
        if b.name == text:
            return b, ""
    raise IngestError(path, f"block {text[:80]!r} not found (mismatched 'block'); available: {listing}")


def _number(v):
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(f) else f


def _export_geometry(block: Block, blocks: list[Block] | None = None) -> tuple[dict, str]:
    """Radius and gap the export states: header/measuring system, else a constant ``gap`` column (within 1 %),
    else the gap an ``Axial`` pre-step left (:func:`tissuemech.io.geometry.axial_step_gap`, with its note)."""
    out = {k: block.meta[k] for k in ("radius_m", "gap_m") if block.meta.get(k) is not None}
    if "gap_m" not in out and "gap" in block.data:
        gap = block.data["gap"].to_numpy(float)
        gap = gap[np.isfinite(gap)]
        if gap.size and np.all(gap > 0) and np.ptp(gap) <= CONFLICT_REL * np.median(gap):
            out["gap_m"] = float(np.median(gap))
    if "gap_m" not in out and blocks:
        axial = axial_step_gap(blocks, block)
        if axial:
            out["gap_m"] = axial[0]
            return out, axial[1]
    return out, ""


def build_run(row: dict, block: Block, dataset: str, source_path: Path,
              dataset_meta: dict | None = None, blocks: list[Block] | None = None,
              where: tuple[Path, int] | None = None) -> tuple[xr.Dataset, list[str]]:
    """Canonical run dataset of one row, and its warnings for the ingest report.

    Geometry follows ``samples.csv`` (``radius_mm``/``gap_mm``) > ``dataset.yaml`` (``geometry``) > the export
    (:func:`tissuemech.io.geometry.resolve_geometry`; with ``blocks``, the gap of a preceding ``Axial`` step,
    ``gap_source`` ``export (axial step)``): attributes ``radius_m``, ``radius_source``, ``gap_m``,
    ``gap_source`` are written only when some source states them (never NaN, never a default), and
    ``measuring_system`` when the export or ``dataset.yaml`` names one. Warnings: ``no plate radius``, ``no gap``
    (for plate tests), geometry conflicts, a stated temperature another than the logged one. A gap read from an
    axial step carries its note in the attribute ``gap_note``. Other attributes: ``docs/architecture.md``.

    Raises
    ------
    IngestError : naming ``where`` (the sample sheet and the row's line) or ``dataset.yaml``: a stated radius
        twice the export's (``looks like a diameter``), a temperature in kelvin against the export's logged one
    """
    dataset_meta = dataset_meta or {}
    yaml_geometry = dataset_geometry(dataset_meta.get("geometry"))
    radius, gap = _number(row.get("radius_mm")), _number(row.get("gap_mm"))
    sheet_geometry = {k: v * 1e-3 for k, v in (("radius_m", radius), ("gap_m", gap)) if v is not None}
    export_geometry, geometry_note = _export_geometry(block, blocks)
    sheet_path, line = where or (Path("samples.csv"), None)
    for stated, source, path, at in ((sheet_geometry, "samples.csv", sheet_path, (line, "radius_mm")),
                                     (yaml_geometry, "dataset.yaml", sheet_path.parent / "dataset.yaml",
                                      (None, "geometry"))):
        problem = diameter_problem(stated.get("radius_m"), export_geometry.get("radius_m"), source, CONFLICT_REL)
        if problem:
            raise IngestError(path, problem, line=at[0], column=at[1])
    geometry, notes = resolve_geometry(sheet_geometry, yaml_geometry, export_geometry)
    if geometry_note and geometry.get("gap_source") == "export":
        geometry["gap_source"] = AXIAL_STEP_SOURCE
    if str(row["test"]) not in PLATE_TESTS:
        notes = [n for n in notes if n not in ("no plate radius", "no gap")]
    temperature = _number(row.get("temperature_c"))
    if "temperature" in block.data and block.data["temperature"].notna().any():
        logged = float(block.data["temperature"].median())
        error, warning = temperature_problem(temperature, logged, "samples.csv")
        if error:
            raise IngestError(sheet_path, error, line=line, column="temperature_c")
        notes += [warning] if warning else []
    attrs = {
        "dataset": dataset, "run": run_id(row), "test": row["test"], "specimen": str(row["specimen"]),
        "sample": str(row["sample"]), "order": int(float(row["order"])), "source_file": str(row["file"]),
        "source_sha256": sha256_of(source_path), "block": block.name, "block_index": block.index,
        "format": block.meta.get("format", ""),
        **geometry,
        "measuring_system": block.meta.get("measuring_system") or yaml_geometry.get("measuring_system"),
        "temperature_c": temperature,
        "started_at": row.get("started_at"),
    }
    if geometry_note and geometry.get("gap_source") == AXIAL_STEP_SOURCE:
        attrs["gap_note"] = geometry_note
    for key in ("shear_rate_1_per_s", "strain_pct", "stress_pa", "frequency_hz", "rise_time_s"):
        attrs[key] = _number(row.get(key))
    for key, value in row.items():
        if key not in STANDARD and value not in (None, ""):
            num = _number(value)
            attrs[f"covariate_{key}"] = num if num is not None else str(value)
    columns = {name: block.data[name].to_numpy(float) for name in block.data.columns}
    return make_run_dataset(columns, attrs), notes


def _error_fields(exc: BaseException) -> dict:
    """Report fields of an exception: IngestError's file/line/column, any other exception by type and text."""
    if isinstance(exc, IngestError):
        return {"reason": str(exc), "line": exc.line, "column": exc.column}
    return {"reason": f"{type(exc).__name__}: {exc}", "line": None, "column": None}


def _read_cached(cache: dict, path: Path, options: dict) -> list[Block]:
    """Blocks of an export, read once; a file that failed is not read again (its error is re-raised)."""
    key = (path, tuple(sorted(options.items())))
    if key not in cache:
        try:
            cache[key] = read_export(path, **options)
        except Exception as exc:  # noqa: BLE001 - any failure of one file is that file's report row
            cache[key] = exc
    if isinstance(cache[key], BaseException):
        exc = cache[key]
        if isinstance(exc, IngestError):
            raise exc
        raise IngestError(path, f"unreadable export ({type(exc).__name__}: {exc})") from exc
    return cache[key]


def reader_options(row: dict, meta: dict) -> dict:
    """Options of :func:`tissuemech.io.dispatch.read_export` for one row: the row's ``columns``/``units``
    (headerless tidy files) and ``dataset.yaml``'s ``columns`` (units of plain tables) as ``column_units``."""
    options = {k: row[k] for k in READER_OPTIONS if row.get(k)}
    if meta.get("columns"):
        options["column_units"] = tuple(sorted((str(k), str(v)) for k, v in meta["columns"].items()))
    return options


def ingest_dataset(dataset_dir, runs_dir, report_path) -> pd.DataFrame:
    """Ingest every row of ``dataset_dir/samples.csv`` into ``runs_dir``; write and return the report.

    Every exception while handling one row (a damaged export, a bad sheet row, a failed write) becomes that
    row's ``error`` line in the report and the other rows go on. A ``dataset.yaml`` or ``samples.csv`` that
    cannot be read at all is written to the report as a single error row and then raised. A row that selects
    the same file, block and test as an earlier row is an error naming both lines.

    Report columns: :data:`REPORT_COLUMNS` (``line``/``column`` where known; ``warnings``: ``no plate radius``,
    ``no gap``, geometry and temperature conflicts, missing ``citation``/``license``; ``notes``: a block chosen
    from the test kind, a gap read from an axial step; each joined by ``; ``).
    """
    dataset_dir, runs_dir = Path(dataset_dir), Path(runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
    dataset = dataset_dir.name
    sheet_path = dataset_dir / "samples.csv"
    try:
        meta = load_dataset_yaml(dataset_dir)
        yaml_warnings = dataset_warnings(meta)
        dataset_geometry(meta.get("geometry"))
        ranges = ranges_with(meta.get("plausible_ranges"))
        sheet = load_samples(dataset_dir)
        source = source_folder(dataset_dir)
    except Exception as exc:
        file = exc.path.name if isinstance(exc, IngestError) else ""
        report = pd.DataFrame([{"file": file, "status": "error", **_error_fields(exc)}], columns=list(REPORT_COLUMNS))
        write_text(report.to_csv(index=False), report_path)
        if isinstance(exc, IngestError):
            raise
        raise IngestError(dataset_dir / "dataset.yaml", str(exc)) from exc
    cache: dict = {}
    seen: dict = {}                  # (export, block index, test) -> line of the first row that selected it
    records = []
    for line, row in zip(sheet.index, sheet.to_dict("records")):
        rid = run_id(row) if all(row.get(k) for k in ("specimen", "sample", "test", "order")) else f"row{line}"
        rec = {"run": rid, "file": row.get("file"), "block": row.get("block"), "test": row.get("test"),
               "specimen": row.get("specimen"), "sample": row.get("sample"), "status": "ok", "reason": "",
               "line": None, "column": None, "warnings": "", "notes": ""}
        try:
            clean = parse_row(row, line, sheet_path, sheet.attrs["decimal_comma"], ranges)
            rec["run"] = rid = run_id(clean)
            path = source / str(clean["file"])
            if not path.is_file():
                raise IngestError(sheet_path, f"file {clean['file']!r} not found", line=line, column="file")
            blocks = _read_cached(cache, path, reader_options(clean, meta))
            try:
                block, chosen = select_block(blocks, clean.get("block"), path, str(clean["test"]))
            except IngestError as exc:
                # the sample sheet is what is wrong: name its line and column, and the export in the text
                raise IngestError(sheet_path, f"{exc.problem} in {path.name}", line=line, column="block") from exc
            key = (path.resolve(), block.index, str(clean["test"]))
            if key in seen:
                raise IngestError(sheet_path, f"duplicate row: same file {clean['file']!r}, block {block.name!r} "
                                              f"and test {clean['test']!r} as line {seen[key]} (two identical "
                                              "runs); remove one of the two rows", line=line, column="file")
            seen[key] = line
            check_required(block, str(clean["test"]), path)
            ds, warnings = build_run(clean, block, dataset, path, meta, blocks, (sheet_path, line))
            write_netcdf(ds, runs_dir / f"{rid}.nc")
            rec["warnings"] = "; ".join(warnings + yaml_warnings)
            rec["notes"] = "; ".join(filter(None, [chosen, ds.attrs.get("gap_note", "")]))
            if chosen:
                rec["block"] = block.name
        except Exception as exc:  # noqa: BLE001 - one bad row or file never takes the dataset down
            rec.update(status="error", **_error_fields(exc))
            log.warning("rejected %s: %s", rid, rec["reason"])
        records.append(rec)
    # --- hook: point-level quality flags (io/quality.py). A second pass over the runs written above, because the
    # LVE check of a frequency sweep needs the amplitude sweep of the same sample. ------------------------------
    ok = [r for r in records if r["status"] == "ok"]
    try:
        flag_run_files([runs_dir / f"{r['run']}.nc" for r in ok], meta)
    except Exception as exc:  # noqa: BLE001 - the runs stay; the report says they carry no flags
        log.warning("quality flags not computed: %s", exc)
        for r in ok:
            r["warnings"] = "; ".join(filter(None, [r["warnings"], f"quality flags not computed ({exc})"]))
    report = pd.DataFrame(records, columns=list(REPORT_COLUMNS))
    write_text(report.to_csv(index=False), report_path)
    return report
