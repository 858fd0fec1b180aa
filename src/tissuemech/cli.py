"""The tissuemech command: runs the pipeline, builds the results pages, and dispatches the package's tools.

run and report drive the Snakemake workflow of the project folder (the folder holding the Snakefile, config/ and
raw/: the current folder or one above it, else the clone the package was installed from). The other commands
live in their modules (check and ingest in io/, synth in synth/, regression in regression.py).
"""
from __future__ import annotations

import argparse
import importlib
import os
import re
import subprocess
import sys
import textwrap
from collections.abc import Sequence
from contextlib import contextmanager
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import yaml

from .numba_cache import source_keyed_cache_dir

#: command -> (module whose main(argv) runs it, or None for this module's own, one-line description)
SUBCOMMANDS: dict[str, tuple[str | None, str]] = {
    "run": (None, "run the pipeline (Snakemake) on every dataset under raw/, or on the named ones"),
    "report": (None, "rebuild the results pages (results/summary.html and one page per dataset) and "
                     "results/report.html"),
    "check": ("tissuemech.io.check", "validate a dataset folder before a run (reads only; exit 1 on errors)"),
    "ingest": ("tissuemech.io.cli", "ingest one dataset folder into canonical runs"),
    "synth": ("tissuemech.synth.cli", "generate a virtual-rheometer dataset"),
    "regression": ("tissuemech.regression", "check or update the committed reference table of fitted parameters"),
}

_USAGE_EXAMPLES = """examples:
  tissuemech run                        every dataset under raw/ (and the configured external ones)
  tissuemech run my_gel -n              what would run for raw/my_gel, without running it
  tissuemech check raw/my_gel           what the sample sheet and the exports give, per run
  tissuemech report                     the results pages again, from what is in results/

Run "tissuemech COMMAND --help" for the options of a command."""


def package_version() -> str:
    """The installed version of tissuemech ("unknown" when the package is not installed, only on the path)."""
    try:
        return version("tissuemech")
    except PackageNotFoundError:
        return "unknown (not installed)"


def plain_text(text: str) -> str:
    """Help text without reStructuredText/Markdown markup (the docstrings' ``code`` and :role:`target`).

    >>> plain_text("``tissuemech check raw/<name>``: validate a **dataset** (:func:`main`)")
    'tissuemech check raw/<name>: validate a dataset (main)'
    """
    text = re.sub(r":[\w.]+:`([^`]*)`", r"\1", text)
    text = re.sub(r"``([^`]*)``", r"\1", text)
    text = re.sub(r"\*\*([^*]*)\*\*", r"\1", text)
    return re.sub(r"`([^`]*)`", r"\1", text)


@contextmanager
def _plain_help():
    """Every argparse help printed inside the block is :func:`plain_text` (the sub-commands' descriptions are
    their module docstrings, written in reStructuredText)."""
    original = argparse.ArgumentParser.format_help

    def format_help(self):
        return plain_text(original(self))

    argparse.ArgumentParser.format_help = format_help
    try:
        yield
    finally:
        argparse.ArgumentParser.format_help = original


def project_folder(start: Path | None = None) -> Path:
    """The project folder: the first of ``start`` (default: the current folder) and its parents that holds a
    Snakefile and config/config.yaml, else the source clone of the installed package."""
    here = (start or Path.cwd()).resolve()
    for folder in (here, *here.parents, Path(__file__).resolve().parents[2]):
        if (folder / "Snakefile").is_file() and (folder / "config" / "config.yaml").is_file():
            return folder
    raise SystemExit(f"tissuemech: no Snakefile with config/config.yaml in {here} or above it, nor in the clone "
                     "the package was installed from; run from the project folder (a clone of the repository) or "
                     "give it with --directory")


def snakemake_command(folder: Path, *args: str) -> list[str]:
    """``python -m snakemake`` on the project's Snakefile, working in ``folder`` (its workflow profile applies)."""
    return [sys.executable, "-m", "snakemake", "--snakefile", str(folder / "Snakefile"), "--directory", str(folder),
            *args]


def _environment(folder: Path) -> dict[str, str]:
    """What ``make run`` exports: numba's cache named after the compiled sources, the Agg backend, no HDF5 locks."""
    env = dict(os.environ)
    env.setdefault("NUMBA_CACHE_DIR", str(source_keyed_cache_dir(folder / ".numba_cache")))
    env.setdefault("MPLBACKEND", "Agg")
    env.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
    return env


def _call(cmd: Sequence[str], folder: Path) -> int:
    print("+ " + " ".join(cmd), flush=True)
    return subprocess.run(list(cmd), cwd=folder, env=_environment(folder)).returncode


def _datasets_config(names: Sequence[str]) -> list[str]:
    return ["--config", "datasets=[" + ",".join(repr(n) for n in names) + "]"] if names else []


def _workflow_parser(name: str, description: str, example: str) -> argparse.ArgumentParser:
    text = textwrap.fill(" ".join(description.split()), width=79) + f"\n\nexample:\n  {example}"
    parser = argparse.ArgumentParser(prog=f"tissuemech {name}", description=text,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-n", "--dry-run", action="store_true", help="print what would run, run nothing")
    parser.add_argument("--directory", type=Path, default=None,
                        help="project folder (default: the current folder or the first one above it with a "
                             "Snakefile)")
    return parser


def run(argv: Sequence[str]) -> int:
    """``tissuemech run [DATASET ...]``: the workflow, then Snakemake's report (as ``make run``)."""
    parser = _workflow_parser("run", """Run the pipeline through Snakemake: ingest, averages, fits, ranking, cards,
diagnosis, FEM and the results pages, for every dataset under raw/ (and the external ones the configuration
names) or only for the datasets named. Results go to results/, logs to logs/<dataset>/. Jobs whose outputs are
up to date do not run again. A failed job stops only what depends on it; the command then exits non-zero and
names the failed jobs and their logs. Options after "--" go to Snakemake unchanged.""",
                              "tissuemech run my_gel -- --until rank")
    parser.add_argument("datasets", nargs="*", metavar="DATASET", help="dataset folder names under raw/")
    parser.add_argument("--cores", default="all", help="CPU cores for the jobs (default: all)")
    argv = list(argv)
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    args = parser.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    folder = args.directory.resolve() if args.directory else project_folder()
    cmd = snakemake_command(folder, "--cores", str(args.cores), *_datasets_config(args.datasets),
                            *(["--dry-run"] if args.dry_run else []), *extra)
    code = _call(cmd, folder)
    if code or args.dry_run:
        return code
    return _call(snakemake_command(folder, *_datasets_config(args.datasets), "--report", "results/report.html"),
                 folder)


def report(argv: Sequence[str]) -> int:
    """``tissuemech report``: the summary pages from what is in results/, then Snakemake's report."""
    parser = _workflow_parser("report", """Rebuild the results pages from what is in results/: results/summary.html
(per dataset the recommended model of each scope, how good it is and what the diagnosis finds) and a page per
dataset, results/<dataset>/summary.html (every table with its CSV file, every figure). Then Snakemake's own
report, results/report.html (provenance, run times, the rule graph). Nothing is computed again: run
"tissuemech run" first.""", "tissuemech report --no-snakemake-report")
    parser.add_argument("--no-snakemake-report", action="store_true", help="only the summary pages")
    args = parser.parse_args(list(argv))
    folder = args.directory.resolve() if args.directory else project_folder()
    results = folder / "results"
    summary = importlib.import_module("tissuemech.summary")
    datasets = summary.results_datasets(results)
    if not datasets:
        print(f"tissuemech report: no results in {results} (no <dataset>/ingest_report.csv); run "
              "\"tissuemech run\" first", file=sys.stderr)
        return 1
    print(f"summary pages of {len(datasets)} dataset(s): {', '.join(datasets)} -> {results / 'summary.html'}")
    cmd = snakemake_command(folder, "--report", "results/report.html")
    if args.dry_run:
        if not args.no_snakemake_report:
            print("would run: " + " ".join(cmd))
        return 0
    config = yaml.safe_load((folder / "config" / "config.yaml").read_text(encoding="utf-8"))
    page = summary.build_summary(results, datasets, results / "summary.html",
                                 captions_dir=folder / "workflow" / "report", config=config)
    print(f"wrote {page} ({page.stat().st_size / 1e3:.0f} kB) and {len(datasets)} dataset pages")
    return 0 if args.no_snakemake_report else _call(cmd, folder)


_OWN = {"run": run, "report": report}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    width = max(len(name) for name in SUBCOMMANDS)
    commands = "\n".join(f"  {name:<{width}}  {text}" for name, (_, text) in SUBCOMMANDS.items())
    parser = argparse.ArgumentParser(
        prog="tissuemech", formatter_class=argparse.RawDescriptionHelpFormatter,
        usage="tissuemech [-h] [--version] COMMAND [ARGS ...]",
        description="Parallel-plate rheometry of soft tissue -> validated constitutive models -> real-time FEM.",
        epilog=f"commands:\n{commands}\n\n{_USAGE_EXAMPLES}")
    parser.add_argument("--version", action="version", version=f"tissuemech {package_version()}")
    parser.add_argument("command", choices=list(SUBCOMMANDS), metavar="COMMAND", help=argparse.SUPPRESS)
    if not argv or argv[0] in ("-h", "--help"):
        parser.print_help()
        return 0
    args = parser.parse_args(argv[:1])
    with _plain_help():
        if args.command in _OWN:
            return int(_OWN[args.command](argv[1:]) or 0)
        module = importlib.import_module(SUBCOMMANDS[args.command][0])
        return int(module.main(argv[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main())
