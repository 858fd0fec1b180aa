# Shared helpers: dataset discovery, package source hashes (rerun triggers), target lists.
import hashlib
from pathlib import Path

import pandas as pd

PACKAGE_DIR = Path(workflow.basedir) / "src" / "tissuemech"


def package_hash(*parts):
    """SHA-256 over the package sources a rule depends on (Snakemake does not track imported code)."""
    h = hashlib.sha256()
    paths = []
    for part in parts or ("",):
        target = PACKAGE_DIR / part
        paths += sorted(target.rglob("*.py")) if target.is_dir() else [target]
    for path in sorted(set(paths)):
        h.update(str(path.relative_to(PACKAGE_DIR)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def discover_datasets():
    """Dataset name -> folder: every raw/<name>/ with a samples.csv, plus configured external folders."""
    found = {}
    raw = Path(config["raw_dir"])
    for sheet in sorted(raw.glob("*/samples.csv")):
        found[sheet.parent.name] = str(sheet.parent)
    for name, folder in config.get("external_datasets", {}).items():
        if (Path(folder) / "samples.csv").is_file():
            found[name] = folder
        else:
            logger.warning(f"external dataset {name!r}: {folder}/samples.csv not found, skipped")
    wanted = config.get("datasets") or list(found)
    missing = sorted(set(wanted) - set(found))
    if missing:
        raise ValueError(f"configured datasets not found under {raw}/: {missing}")
    return {name: found[name] for name in wanted}


DATASETS = discover_datasets()


wildcard_constraints:
    dataset="|".join(DATASETS) or "NO_DATASET",


def dataset_dir(wildcards):
    return DATASETS[wildcards.dataset]


def dataset_files(wildcards):
    """Every input file of a dataset (sample sheet, description, instrument files) so edits rerun ingest."""
    folder = Path(DATASETS[wildcards.dataset])
    return sorted(str(p) for p in folder.rglob("*") if p.is_file())


def dataset_tests(name):
    sheet = pd.read_csv(Path(DATASETS[name]) / "samples.csv", dtype=str)
    return sorted(set(sheet["test"].dropna())) if "test" in sheet else []
