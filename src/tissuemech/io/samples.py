"""The dataset description: ``samples.csv`` (one row per run) and ``dataset.yaml``, both schema-validated.

``samples.csv`` columns: required ``file`` (path inside the dataset folder, or inside ``source_dir`` when
``dataset.yaml`` names one), ``specimen``, ``sample``, ``test`` (one of
:data:`tissuemech.canonical.TEST_KINDS`), ``order`` (test sequence within the sample); optional
``block`` (block/interval/step index or name when a file holds several), ``shear_rate_1_per_s``,
``strain_pct``, ``stress_pa``, ``frequency_hz``, ``radius_mm``, ``gap_mm``, ``temperature_c``,
``rise_time_s``, ``started_at`` (ISO 8601); reader options ``columns``/``units`` (headerless tidy files).
Any other column is kept as a covariate (run attribute ``covariate_<name>``).
"""
from __future__ import annotations

import json
from datetime import datetime
from importlib import resources
from pathlib import Path

import jsonschema
import pandas as pd
import yaml

from .errors import IngestError

NUMERIC = ("order", "shear_rate_1_per_s", "strain_pct", "stress_pa", "frequency_hz", "radius_mm", "gap_mm",
           "temperature_c", "rise_time_s")
READER_OPTIONS = ("columns", "units")
STANDARD = ("file", "specimen", "sample", "test", "order", "block", "started_at") + NUMERIC + READER_OPTIONS


def _schema(name: str) -> dict:
    return json.loads(resources.files("tissuemech.io").joinpath("schemas", name).read_text())


def row_problems(row: dict) -> list[str]:
    """Schema violations of one sample-sheet row (empty list when valid)."""
    record = {k: v for k, v in row.items() if v is not None and not (isinstance(v, float) and pd.isna(v))}
    errors = sorted(jsonschema.Draft202012Validator(_schema("samples.schema.json")).iter_errors(record),
                    key=lambda e: list(e.path))
    problems = [f"{'/'.join(map(str, e.path)) or 'row'}: {e.message}" for e in errors]
    if "started_at" in record:
        try:
            datetime.fromisoformat(str(record["started_at"]))
        except ValueError:
            problems.append(f"started_at: {record['started_at']!r} is not ISO 8601")
    return problems


def load_samples(dataset_dir) -> pd.DataFrame:
    """The sample sheet as a DataFrame (numeric columns converted; a missing/empty sheet raises IngestError).

    Row validity is checked per row by :func:`row_problems` during ingest, so that one bad row does not
    stop the others.
    """
    path = Path(dataset_dir) / "samples.csv"
    if not path.is_file():
        raise IngestError(path, "sample sheet not found")
    sheet = pd.read_csv(path, dtype=str, keep_default_na=False)
    missing = [c for c in ("file", "specimen", "sample", "test", "order") if c not in sheet]
    if missing:
        raise IngestError(path, f"missing required column(s) {missing}", line=1)
    sheet = sheet.replace({"": None})
    for col in NUMERIC:
        if col in sheet:
            sheet[col] = pd.to_numeric(sheet[col], errors="coerce") if col != "order" else sheet[col]
    return sheet


#: dataset.yaml keys whose absence is a warning in the ingest report (only ``material`` is required)
RECOMMENDED = ("citation", "license")


def dataset_warnings(meta: dict) -> list[str]:
    """Warnings about a valid ``dataset.yaml``: missing ``citation``/``license``."""
    return [f"dataset.yaml has no {key!r}" for key in RECOMMENDED if not meta.get(key)]


def load_dataset_yaml(dataset_dir) -> dict:
    """``dataset.yaml`` validated against its schema (IngestError naming the field otherwise).

    Only ``material`` is required; ``geometry`` is a mapping or a string (see :mod:`tissuemech.io.geometry`).
    """
    path = Path(dataset_dir) / "dataset.yaml"
    if not path.is_file():
        raise IngestError(path, "dataset description not found")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise IngestError(path, f"invalid YAML: {exc}", line=None if mark is None else mark.line + 1) from exc
    errors = list(jsonschema.Draft202012Validator(_schema("dataset.schema.json")).iter_errors(data))
    if errors:
        raise IngestError(path, "; ".join(f"{'/'.join(map(str, e.path)) or 'document'}: {e.message}" for e in errors))
    return data


def source_folder(dataset_dir) -> Path:
    """Folder the sample sheet's ``file`` paths are relative to (``source_dir`` of dataset.yaml, if any)."""
    dataset_dir = Path(dataset_dir)
    meta = yaml.safe_load((dataset_dir / "dataset.yaml").read_text()) if (dataset_dir / "dataset.yaml").is_file() else {}
    return (dataset_dir / meta["source_dir"]) if meta and meta.get("source_dir") else dataset_dir
