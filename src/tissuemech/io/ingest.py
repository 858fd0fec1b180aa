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
from .geometry import CONFLICT_REL, dataset_geometry, resolve_geometry
from .quality import flag_run_files
from .samples import (NUMERIC, READER_OPTIONS, STANDARD, dataset_warnings, load_dataset_yaml, load_samples,
                      row_problems, source_folder)

log = logging.getLogger(__name__)
REPORT_COLUMNS = ("run", "file", "block", "test", "specimen", "sample", "status", "reason", "line", "column",
                  "warnings")
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


def check_required(block: Block, test: str, path) -> None:
    """The block holds the variables its test kind needs (missing column -> IngestError naming it)."""
    for alternatives in REQUIRED_VARIABLES.get(test, ()):
        present = [v for v in alternatives if v in block.data and block.data[v].notna().any()]
        if not present:
            wanted = " or ".join(repr(v) for v in alternatives)
            raise IngestError(path, f"missing column: block {block.name!r} has no {wanted} data, needed for a "
                                    f"{test} run; it has {list(block.data.columns)}",
                              line=block.meta.get("first_data_line"), column=alternatives[0])


def select_block(blocks: list[Block], block, path) -> Block:
    """The block a sample-sheet row asks for (index from 1, or a name); the only block when none is given."""
    if block in (None, ""):
        if len(blocks) > 1:
            names = ", ".join(f"{b.index}: {b.name}" for b in blocks)
            raise IngestError(path, f"file holds {len(blocks)} blocks; the sample sheet must select one with "
                                    f"'block' ({names})")
        return blocks[0]
    text = str(block).strip()
    if text.isdigit():
        k = int(text)
        for b in blocks:
            if b.index == k:
                return b
    for b in blocks:
        if b.name == text:
            return b
    raise IngestError(path, f"block {text!r} not found (mismatched 'block'); available: "
                            + ", ".join(f"{b.index}: {b.name}" for b in blocks))


def _number(v):
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(f) else f


def _export_geometry(block: Block) -> dict:
    """Radius and gap the export states: header/measuring system, else a constant ``gap`` column (within 1 %)."""
    out = {k: block.meta[k] for k in ("radius_m", "gap_m") if block.meta.get(k) is not None}
    if "gap_m" not in out and "gap" in block.data:
        gap = block.data["gap"].to_numpy(float)
        gap = gap[np.isfinite(gap)]
        if gap.size and np.all(gap > 0) and np.ptp(gap) <= CONFLICT_REL * np.median(gap):
            out["gap_m"] = float(np.median(gap))
    return out


def build_run(row: dict, block: Block, dataset: str, source_path: Path,
              dataset_meta: dict | None = None) -> tuple[xr.Dataset, list[str]]:
    """Canonical run dataset of one row, and its notes for the ingest report.

    Geometry follows ``samples.csv`` (``radius_mm``/``gap_mm``) > ``dataset.yaml`` (``geometry``) > the export
    (:func:`tissuemech.io.geometry.resolve_geometry`): attributes ``radius_m``, ``radius_source``, ``gap_m``,
    ``gap_source`` are written only when some source states them (never NaN, never a default), and
    ``measuring_system`` when the export or ``dataset.yaml`` names one. Notes: ``no plate radius``, ``no gap``
    (for plate tests), geometry conflicts, ``dataset.yaml`` warnings. Other attributes: ``docs/architecture.md``.
    """
    dataset_meta = dataset_meta or {}
    yaml_geometry = dataset_geometry(dataset_meta.get("geometry"))
    radius, gap = _number(row.get("radius_mm")), _number(row.get("gap_mm"))
    sheet_geometry = {k: v * 1e-3 for k, v in (("radius_m", radius), ("gap_m", gap)) if v is not None}
    geometry, notes = resolve_geometry(sheet_geometry, yaml_geometry, _export_geometry(block))
    if str(row["test"]) not in PLATE_TESTS:
        notes = [n for n in notes if n not in ("no plate radius", "no gap")]
    attrs = {
        "dataset": dataset, "run": run_id(row), "test": row["test"], "specimen": str(row["specimen"]),
        "sample": str(row["sample"]), "order": int(float(row["order"])), "source_file": str(row["file"]),
        "source_sha256": sha256_of(source_path), "block": block.name, "block_index": block.index,
        "format": block.meta.get("format", ""),
        **geometry,
        "measuring_system": block.meta.get("measuring_system") or yaml_geometry.get("measuring_system"),
        "temperature_c": _number(row.get("temperature_c")),
        "started_at": row.get("started_at"),
    }
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


def ingest_dataset(dataset_dir, runs_dir, report_path) -> pd.DataFrame:
    """Ingest every row of ``dataset_dir/samples.csv`` into ``runs_dir``; write and return the report.

    Every exception while handling one row (a damaged export, a bad sheet row, a failed write) becomes that
    row's ``error`` line in the report and the other rows go on. A ``dataset.yaml`` or ``samples.csv`` that
    cannot be read at all is written to the report as a single error row and then raised.

    Report columns: :data:`REPORT_COLUMNS` (``line``/``column`` where known; ``warnings``: ``no plate radius``,
    ``no gap``, geometry conflicts, missing ``citation``/``license`` joined by ``; ``).
    """
    dataset_dir, runs_dir = Path(dataset_dir), Path(runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
    dataset = dataset_dir.name
    try:
        meta = load_dataset_yaml(dataset_dir)
        yaml_warnings = dataset_warnings(meta)
        dataset_geometry(meta.get("geometry"))
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
    records = []
    for line, row in enumerate(sheet.to_dict("records"), start=2):
        rid = run_id(row) if all(row.get(k) for k in ("specimen", "sample", "test", "order")) else f"row{line}"
        rec = {"run": rid, "file": row.get("file"), "block": row.get("block"), "test": row.get("test"),
               "specimen": row.get("specimen"), "sample": row.get("sample"), "status": "ok", "reason": "",
               "line": None, "column": None, "warnings": ""}
        try:
            clean = {k: (int(float(v)) if k == "order" and v is not None and str(v).strip() else v)
                     for k, v in row.items()}
            for key in NUMERIC:
                if key in clean and key != "order":
                    clean[key] = _number(clean[key])
            problems = row_problems(clean)
            if problems:
                field = problems[0].split(":", 1)[0]
                raise IngestError(dataset_dir / "samples.csv", "; ".join(problems), line=line,
                                  column=field if field in row else None)
            path = source / str(row["file"])
            if not path.is_file():
                raise IngestError(dataset_dir / "samples.csv", f"file {row['file']!r} not found", line=line,
                                  column="file")
            options = {k: row[k] for k in READER_OPTIONS if row.get(k)}
            blocks = _read_cached(cache, path, options)
            try:
                block = select_block(blocks, row.get("block"), path)
            except IngestError as exc:
                # the sample sheet is what is wrong: name its line and column, and the export in the text
                raise IngestError(dataset_dir / "samples.csv", f"{exc.problem} in {path.name}", line=line,
                                  column="block") from exc
            check_required(block, str(row["test"]), path)
            ds, notes = build_run(clean, block, dataset, path, meta)
            write_netcdf(ds, runs_dir / f"{rid}.nc")
            rec["warnings"] = "; ".join(notes + yaml_warnings)
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
