"""``tissuemech ingest <dataset_dir> --out results/<name>``: canonical runs + ingest report of one dataset."""
from __future__ import annotations

import argparse
from pathlib import Path

from .ingest import ingest_dataset


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="tissuemech ingest", description=__doc__)
    parser.add_argument("dataset_dir", type=Path)
    parser.add_argument("--out", type=Path, required=True, help="output folder (runs/ and ingest_report.csv)")
    args = parser.parse_args(argv)
    report = ingest_dataset(args.dataset_dir, args.out / "runs", args.out / "ingest_report.csv")
    bad = report[report["status"] != "ok"]
    print(f"ingested {len(report) - len(bad)} runs, rejected {len(bad)}")
    for _, row in bad.iterrows():
        print(f"  {row['run']}: {row['reason']}")
    return 1 if len(bad) == len(report) else 0
