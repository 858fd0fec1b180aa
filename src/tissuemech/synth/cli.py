"""``tissuemech synth --config <yaml> --seed N --out raw/<name>``: generate a virtual-rheometer dataset."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .generator import generate_dataset, load_config


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="tissuemech synth", description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True, help="generator config (YAML), e.g. config/synth/agar_3pct_thesis.yaml")
    parser.add_argument("--seed", type=int, default=1, help="random seed (the dataset is reproducible from it)")
    parser.add_argument("--out", required=True, help="output dataset folder, e.g. raw/agar_3pct_thesis")
    parser.add_argument("--header", choices=("simple", "project"), default="simple",
                        help="RheoCompass header variant of the CSV exports")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    t0 = time.perf_counter()
    result = generate_dataset(load_config(args.config), args.seed, args.out, header=args.header)
    size = sum(f.stat().st_size for f in Path(args.out).iterdir() if f.is_file())
    print(f"wrote {len(result['runs'])} runs to {args.out} ({size / 1024:.0f} KiB) in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
