"""``tissuemech`` command line: thin dispatcher to the package's sub-commands.

Sub-commands
------------
synth        generate a virtual-rheometer dataset folder (``tissuemech synth --config c.yaml --seed 1 --out raw/x``)
ingest       ingest one dataset folder into canonical run files
check        validate a dataset folder before any run (``tissuemech check raw/<name>``; exit 1 on errors)
regression   check (or ``--update``) the committed reference table of fitted parameters
"""
from __future__ import annotations

import argparse
import importlib
import sys

SUBCOMMANDS = {
    "synth": ("tissuemech.synth.cli", "generate a synthetic dataset with the virtual rheometer"),
    "ingest": ("tissuemech.io.cli", "ingest a dataset folder into canonical netCDF runs"),
    "check": ("tissuemech.io.check", "validate a dataset folder (reads only) and print what was found per run"),
    "regression": ("tissuemech.regression", "check or update the fitted-parameter reference table"),
}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="tissuemech", description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=sorted(SUBCOMMANDS), help="; ".join(
        f"{k}: {v[1]}" for k, v in sorted(SUBCOMMANDS.items())))
    if not argv or argv[0] in ("-h", "--help"):
        parser.print_help()
        return 0
    args, rest = parser.parse_known_args(argv[:1])
    module = importlib.import_module(SUBCOMMANDS[args.command][0])
    return int(module.main(argv[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main())
