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

from ..canonical import make_run_dataset, sha256_of, write_netcdf, write_text
from .blocks import Block
from .dispatch import read_export
from .errors import IngestError
from .quality import flag_run_files
from .samples import NUMERIC, READER_OPTIONS, STANDARD, load_dataset_yaml, load_samples, row_problems, source_folder

log = logging.getLogger(__name__)
REPORT_COLUMNS = ("run", "file", "block", "test", "specimen", "sample", "status", "reason")


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


def build_run(row: dict, block: Block, dataset: str, source_path: Path) -> "xr.Dataset":  # noqa: F821
    """Canonical run dataset of one row (attributes: see ``docs/architecture.md``)."""
    radius = _number(row.get("radius_mm"))
    gap = _number(row.get("gap_mm"))
    attrs = {
        "dataset": dataset, "run": run_id(row), "test": row["test"], "specimen": str(row["specimen"]),
        "sample": str(row["sample"]), "order": int(float(row["order"])), "source_file": str(row["file"]),
        "source_sha256": sha256_of(source_path), "block": block.name, "block_index": block.index,
        "format": block.meta.get("format", ""),
        "radius_m": radius * 1e-3 if radius is not None else block.meta.get("radius_m"),
        "gap_m": gap * 1e-3 if gap is not None else block.meta.get("gap_m"),
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
    return make_run_dataset(columns, attrs)


def ingest_dataset(dataset_dir, runs_dir, report_path) -> pd.DataFrame:
    """Ingest every row of ``dataset_dir/samples.csv`` into ``runs_dir``; write and return the report."""
    dataset_dir, runs_dir = Path(dataset_dir), Path(runs_dir)
    runs_dir.mkdir(parents=True, exist_ok=True)
    dataset = dataset_dir.name
    meta = load_dataset_yaml(dataset_dir)
    sheet = load_samples(dataset_dir)
    source = source_folder(dataset_dir)
    cache: dict[Path, list[Block]] = {}
    records = []
    for line, row in enumerate(sheet.to_dict("records"), start=2):
        rid = run_id(row) if all(row.get(k) for k in ("specimen", "sample", "test", "order")) else f"row{line}"
        rec = {"run": rid, "file": row.get("file"), "block": row.get("block"), "test": row.get("test"),
               "specimen": row.get("specimen"), "sample": row.get("sample"), "status": "ok", "reason": ""}
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
            if path not in cache:
                cache[path] = read_export(path, **options)
            try:
                block = select_block(cache[path], row.get("block"), path)
            except IngestError as exc:
                # the sample sheet is what is wrong: name its line and column, and the export in the text
                raise IngestError(dataset_dir / "samples.csv", f"{exc.problem} in {path.name}", line=line,
                                  column="block") from exc
            check_required(block, str(row["test"]), path)
            ds = build_run(clean, block, dataset, path)
            write_netcdf(ds, runs_dir / f"{rid}.nc")
        except (IngestError, OSError, ValueError, KeyError) as exc:
            rec.update(status="error", reason=str(exc))
            log.warning("rejected %s: %s", rid, exc)
        records.append(rec)
    # --- hook: point-level quality flags (io/quality.py). A second pass over the runs written above, because the
    # LVE check of a frequency sweep needs the amplitude sweep of the same sample. ------------------------------
    flag_run_files([runs_dir / f"{r['run']}.nc" for r in records if r["status"] == "ok"], meta)
    report = pd.DataFrame(records, columns=list(REPORT_COLUMNS))
    write_text(report.to_csv(index=False), report_path)
    return report
