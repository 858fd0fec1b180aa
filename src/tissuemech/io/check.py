"""``tissuemech check raw/<name>``: validate a dataset folder before any pipeline run, and say what was found.

The check runs the real ingest (:func:`tissuemech.io.ingest.ingest_dataset`: sample-sheet schema, ``dataset.yaml``
schema, every export through its reader, the variables each test needs, the quality flags of
:mod:`tissuemech.io.quality`) into a temporary folder outside the dataset, so what it reports is exactly what the
pipeline will do. The dataset folder is only read; nothing is written into it. Per run it prints the test, the
nominal condition, the plate radius and gap with their source (``samples.csv`` / ``dataset.yaml`` / ``export``
when ingest records it in ``radius_source``/``gap_source``; ``no plate radius`` when the data give none), the
canonical columns with their SI units, the quality flags and the checks that were not testable, the ingest
report's warnings (geometry conflicts, missing citation ...) and notes (a block chosen from the test kind, a gap
read from an axial pre-step), and for a rejected run the problem (file, line/column, reason, and the likely
mistake where there is one: ``did you mean `geometry`?``, ``looks like metres``, ``looks like a diameter``).
Files of the folder that no sample-sheet row names are
listed as a note.

Exit status: 0 when every run was read, 1 when the dataset description cannot be read or any run has an error.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import xarray as xr

from ..canonical import read_netcdf
from ..curves import condition_label, condition_of
from .errors import IngestError
from .ingest import ingest_dataset
from .quality import FLAG_VARIABLE, describe_flags
from .samples import load_samples, source_folder

#: files of a dataset folder that are not exports (never reported as unreferenced)
DESCRIPTION_FILES = frozenset({"samples.csv", "dataset.yaml", "truth.json", "README.md", "README.txt", "LICENSE"})


@dataclass
class RunCheck:
    """What the check found for one sample-sheet row."""

    run: str
    file: str
    status: str                   # "ok", "error" or another ingest status (reported as a warning)
    reason: str = ""
    warnings: str = ""            # the ingest report's ``warnings`` column, when it has one
    notes: str = ""               # the ingest report's ``notes`` (a block chosen from the test kind, an axial-step gap)
    lines: list[str] = field(default_factory=list)


@dataclass
class DatasetCheck:
    """Result of :func:`check_dataset`."""

    dataset: Path
    runs: list[RunCheck] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)    # dataset-level errors (description unreadable ...)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when nothing is an error."""
        return not self.errors and all(r.status != "error" for r in self.runs)


def _length_mm(run: xr.Dataset, key: str, label: str, missing: str) -> str:
    value = run.attrs.get(f"{key}_m")
    if value is None or not pd.notna(value):
        return missing
    source = run.attrs.get(f"{key}_source")
    return f"{label} = {float(value) * 1e3:.4g} mm ({source if source else 'source not recorded'})"


def describe_run(run: xr.Dataset) -> list[str]:
    """Human-readable lines for one canonical run: test, condition, geometry + source, columns + units, flags."""
    condition = condition_label(condition_of(run))
    lines = [f"test: {run.attrs.get('test', '?')}   condition: {condition}",
             f"block: {run.attrs.get('block', '')} (format {run.attrs.get('format', '?')})",
             "geometry: " + ", ".join((_length_mm(run, "radius", "R", "no plate radius"),
                                       _length_mm(run, "gap", "gap", "no gap")))]
    columns = [f"{name} [{run[name].attrs.get('units', '?')}]" for name in run.data_vars if name != FLAG_VARIABLE]
    lines.append(f"columns ({run.sizes.get('point', 0)} points): " + ", ".join(columns))
    flags = describe_flags(run)
    if flags:
        lines.append(flags)
    return lines


def _text(value) -> str:
    return "" if value is None or (isinstance(value, float) and pd.isna(value)) else str(value)


def _referenced(sheet: pd.DataFrame) -> set[str]:
    return {Path(str(f)).as_posix() for f in sheet["file"].dropna()}


def check_dataset(dataset_dir: str | Path) -> DatasetCheck:
    """Validate one dataset folder without writing into it (see the module docstring).

    Parameters
    ----------
    dataset_dir : folder holding ``samples.csv`` and ``dataset.yaml``.

    Returns
    -------
    DatasetCheck with one :class:`RunCheck` per sample-sheet row, dataset-level errors and notes.
    """
    dataset_dir = Path(dataset_dir)
    result = DatasetCheck(dataset=dataset_dir)
    if not dataset_dir.is_dir():
        result.errors.append(f"{dataset_dir}: not a folder")
        return result
    with tempfile.TemporaryDirectory(prefix="tissuemech-check-") as tmp:
        out = Path(tmp)
        try:
            report = ingest_dataset(dataset_dir, out / "runs", out / "ingest_report.csv")
        except IngestError as exc:
            result.errors.append(str(exc))
            return result
        for rec in report.to_dict("records"):
            entry = RunCheck(run=str(rec["run"]), file=str(rec["file"]), status=str(rec["status"]),
                             reason=_text(rec.get("reason")), warnings=_text(rec.get("warnings")),
                             notes=_text(rec.get("notes")))
            path = out / "runs" / f"{entry.run}.nc"
            if entry.status != "error" and path.is_file():
                entry.lines = describe_run(read_netcdf(path))
            result.runs.append(entry)
    source = source_folder(dataset_dir)
    referenced = _referenced(load_samples(dataset_dir))
    if source.is_dir():
        unreferenced = sorted(p.relative_to(source).as_posix() for p in source.rglob("*")
                              if p.is_file() and p.name not in DESCRIPTION_FILES and not p.name.startswith("."))
        unreferenced = [p for p in unreferenced if p not in referenced]
        if unreferenced:
            result.notes.append(f"{len(unreferenced)} file(s) not named in samples.csv: "
                                + ", ".join(unreferenced[:10]) + (" ..." if len(unreferenced) > 10 else ""))
    return result


def format_check(result: DatasetCheck) -> str:
    """The printed report of :func:`check_dataset`."""
    lines = [f"dataset {result.dataset}"]
    lines += [f"ERROR {e}" for e in result.errors]
    for r in result.runs:
        tag = {"ok": "ok", "error": "ERROR"}.get(r.status, f"WARNING ({r.status})")
        lines.append(f"run {r.run} [{tag}]  file: {r.file}")
        lines += [f"    {line}" for line in r.lines]
        if r.reason:
            lines.append(f"    problem: {r.reason}")
        if r.warnings:
            lines.append(f"    warnings: {r.warnings}")
        if r.notes:
            lines.append(f"    notes: {r.notes}")
    lines += [f"note: {n}" for n in result.notes]
    n_err = sum(r.status == "error" for r in result.runs)
    n_warn = sum(r.status != "error" and (r.status != "ok" or bool(r.warnings)) for r in result.runs)
    lines.append(f"{len(result.runs) - n_err} of {len(result.runs)} runs readable, {n_err} with errors, "
                 f"{n_warn} with warnings" + (f"; {len(result.errors)} dataset error(s)" if result.errors else "")
                 + (" -> OK" if result.ok else " -> FAILED"))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """``tissuemech check <dataset_dir>``: print the check and return 0 (ok) or 1 (errors)."""
    parser = argparse.ArgumentParser(prog="tissuemech check", description=__doc__.splitlines()[0])
    parser.add_argument("dataset_dir", type=Path, help="dataset folder (samples.csv + dataset.yaml), e.g. raw/<name>")
    args = parser.parse_args(argv)
    result = check_dataset(args.dataset_dir)
    print(format_check(result))
    return 0 if result.ok else 1


if __name__ == "__main__":
    sys.exit(main())
