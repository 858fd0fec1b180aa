"""Large seeded mutation fuzz of the readers (``tissuemech.io.fuzz``) over the bundled and real exports.

    PYTHONPATH=src python benchmarks/ingest_fuzz.py --mutants 1500 --seed 20260113

Spreads the mutants evenly over the exports (bundled ``raw/*/`` files, ``tests/io/fixtures`` and, when
present, ``../shared/data/real``; the headerless Budday curves are left out: they need sample-sheet options; a
table without units gets the units its folder's ``dataset.yaml`` declares, ``tissuemech.io.fuzz.reader_options_for``)
and prints the count of each outcome: ``crash`` (exception other than IngestError) and ``wrong`` (silently
wrong values) and ``lost`` (points missing that the mutant file still holds) must be 0; ``file_shorter`` (the
mutation deleted a data row or cut the file's tail, and the reader returned every point left, in a format that
declares no point count) and ``undetectable`` (byte corruption of a checksum-less .xls that still parses) are
reported apart.
"""
from __future__ import annotations

import argparse
import collections
import tempfile
import time
from pathlib import Path

from tissuemech.io.fuzz import fuzz_file, reader_options_for

ROOT = Path(__file__).resolve().parents[1]


def exports() -> list[Path]:
    files = sorted((ROOT / "raw").glob("*/*.csv"))
    files = [f for f in files if f.name != "samples.csv"][::12]  # every 12th synthetic export: same writer
    files += sorted(p for p in (ROOT / "tests" / "io" / "fixtures").iterdir() if p.suffix in (".csv", ".txt", ".xlsx"))
    real = ROOT / ".." / "shared" / "data" / "real"
    if real.is_dir():
        files += sorted(p for p in real.rglob("*") if p.suffix in (".csv", ".txt", ".xls")
                        and "brain_budday2017" not in p.parts and p.name != "README.md")
    return files


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mutants", type=int, default=1500)
    parser.add_argument("--seed", type=int, default=20260113)
    args = parser.parse_args()
    files = exports()
    per_file = max(1, args.mutants // len(files))
    totals, by_kind, examples = collections.Counter(), collections.Counter(), []
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for path in files:
            for kind, detail, outcome, message in fuzz_file(path, Path(tmp), per_file, args.seed,
                                                            **reader_options_for(path)):
                totals[outcome] += 1
                by_kind[(kind, outcome)] += 1
                if outcome in ("crash", "wrong", "lost"):
                    examples.append(f"{path.name}: {kind} ({detail}) -> {outcome}: {message}")
    print(f"{sum(totals.values())} mutants of {len(files)} exports ({per_file} each), seed {args.seed}, "
          f"{time.perf_counter() - start:.0f} s")
    for outcome in ("error", "same", "scaled", "file_shorter", "undetectable", "lost", "crash", "wrong"):
        print(f"  {outcome:13s} {totals[outcome]}")
    for (kind, outcome), n in sorted(by_kind.items()):
        print(f"    {kind:15s} {outcome:13s} {n}")
    for line in examples[:20]:
        print("  !", line)


if __name__ == "__main__":
    main()
