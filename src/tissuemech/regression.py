"""Regression check of fitted parameters against a committed reference table (NIST StRD style).

A representative set of model fits (:data:`REFERENCE_FITS`) is redone on the bundled datasets (``raw/<dataset>``)
with the same package functions and settings as the pipeline: ``io.ingest.ingest_dataset`` -> ``pipeline.load_runs``
-> ``curves.average_runs`` -> ``stages.scope_curves`` -> ``ranking.fit_candidate`` with the ``fit:`` seed,
multistart and plate target of ``config/config.yaml`` (the same call ``stages.run_fit_scope`` makes through
``ranking.rank_scope``, minus the cross-validation, which does not change the fitted values). The fitted values are
compared with the committed table ``tests/regression/<dataset>.csv``, one row per parameter:

``dataset, scope, model, parameter, unit, value, stderr, tolerance, reason``

Tolerance of a parameter: ``max(k * stderr, floor)`` with ``k`` = :data:`STDERR_MULTIPLIER` = 0.1 and
``floor`` = :data:`RELATIVE_FLOOR` ``* |value|`` (at least :data:`ABSOLUTE_FLOOR`).

* Why ``k = 0.1``: the standard error is what the data can resolve. A tenth of it is far below what would change a
  scientific conclusion, yet catches any code or data change that shifts an estimate noticeably (thinning to 30
  instead of 40 points per curve moves the agar relaxation and creep fits by 0.14-0.42 standard errors). It is still
  far above the numerical noise of a refit: the least-squares solver stops at relative tolerances 1e-8, and
  refitting every reference fit to 1e-14 moved no parameter by more than 3.2e-4 standard errors (measured when the
  table was made).
* Why the floor: a parameter whose standard error is tiny or missing (singular covariance, parameter held at a
  bound) would otherwise get a tolerance that BLAS/CPU differences alone can exceed; 1e-6 relative is six
  significant digits, the NIST StRD certification level.

The ``reason`` column says which rule set the tolerance and lists the fit's flags that concern the parameter
(at a bound, poorly determined, strongly correlated), so a reviewer knows which rows are fragile. Exchangeable
Prony modes are numbered by increasing time before they are stored or compared (:func:`mode_labels`).

Command line::

    python -m tissuemech.regression --check    # exit 1 with a table of what moved and by how much
    python -m tissuemech.regression --update   # rewrite tests/regression/*.csv and print the diff table
    python -m tissuemech.regression --check --dataset agar_3pct_thesis   # one dataset only
"""
from __future__ import annotations

import argparse
import logging
import math
import re
import sys
import tempfile
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr
import yaml
from . import ranking as R
from .canonical import write_text
from .curves import average_runs
from .io.ingest import ingest_dataset
from .pipeline import load_runs
from .material import baseline_model, fit_material
from .scopes import MATERIAL_LAWS
from .stages import dataset_scopes, scope_curves, spec_curves

#: model fits redone on every check: dataset -> scope (``stages.dataset_scopes``) -> registry keys. Chosen to
#: cover every response kind the fitter handles (flow, shear history of relaxation and CSR ramps, creep,
#: oscillation, the LVE part of amplitude sweeps) and every family (viscous, linear elastic and viscoelastic,
#: fractional, hyperelastic, QLV, beyond-QLV), while staying well under a minute on two cores.
#: the model name that stands for the material scope's baseline (its key is the data's choice)
MATERIAL_BASELINE = "baseline"
#: parameter-name prefix of the material baseline's relaxation times in the table (``relaxation_time_1`` ...)
RELAXATION_TIME = "relaxation_time_"

REFERENCE_FITS: dict[str, dict[str, tuple[str, ...]]] = {
    "agar_3pct_thesis": {
        "amplitude_sweep": ("linear_elastic",),
        "flow_curve": ("power_law", "bingham"),
        "stress_relaxation": ("sls2",),
        "creep_recovery": ("sls2",),
    },
    "porcine_brain_thesis": {
        "amplitude_sweep": ("linear_elastic",),
        "constant_shear_rate": ("linear_elastic", "neo_hookean", "reduced_polynomial3"),
        "stress_relaxation": ("prony3",),
        "creep_recovery": ("burgers",),
        "frequency_sweep": ("springpot",),
        # the material scope chooses its model from the data: the table holds its baseline under the chosen key
        "material": (MATERIAL_BASELINE,),
    },
}

#: tolerance = STDERR_MULTIPLIER x standard error (module docstring says why 0.1)
STDERR_MULTIPLIER = 0.1
#: reproducibility floor relative to |value| (six significant digits)
RELATIVE_FLOOR = 1e-6
#: floor for a parameter whose value is (almost) zero, in the parameter's own unit
ABSOLUTE_FLOOR = 1e-12

KEY_COLUMNS = ("dataset", "scope", "model", "parameter")
COLUMNS = (*KEY_COLUMNS, "unit", "value", "stderr", "tolerance", "reason")
#: columns of the comparison (failure and diff) tables
REPORT_COLUMNS = (*KEY_COLUMNS, "reference", "fresh", "difference", "tolerance", "difference/tolerance", "status")

DEFAULT_RAW_DIR = Path("raw")
DEFAULT_CONFIG = Path("config/config.yaml")
DEFAULT_REFERENCE_DIR = Path("tests/regression")

log = logging.getLogger(__name__)


class ReferenceTableError(ValueError):
    """A malformed reference table; the message names the file, and the line/column when known."""

    def __init__(self, path, problem: str, line: int | None = None, column: str | None = None):
        where = str(path)
        if line is not None:
            where += f", line {line}"
        if column is not None:
            where += f", column {column!r}"
        super().__init__(f"{where}: {problem}")


# ------------------------------------------------------------------------------------------------------
# fresh fits
# ------------------------------------------------------------------------------------------------------
def fit_settings(config_path=DEFAULT_CONFIG) -> dict:
    """The pipeline's fit settings (``seed``, ``multistart``, ``plate_target`` and the whole ``fit:`` block)."""
    config_path = Path(config_path)
    config = yaml.safe_load(config_path.read_text(encoding="utf-8")) or {}
    fit = config.get("fit")
    if not isinstance(fit, Mapping):
        raise ValueError(f"{config_path}: no 'fit:' section")
    missing = [k for k in ("seed", "multistart", "plate_target") if k not in fit]
    if missing:
        raise ValueError(f"{config_path}: 'fit:' lacks {missing}")
    return dict(fit)


def dataset_averages(dataset_dir, work_dir, exclude_flagged: bool = True) -> tuple[xr.Dataset, list[str]]:
    """Ingest ``dataset_dir`` into ``work_dir`` and average its runs, as the ``ingest`` and ``average`` rules do
    (``exclude_flagged``: config ``fit.exclude_flagged``, quality-flagged points left out).

    Returns the averages and the sorted test kinds of the dataset. Rejected runs are logged (the fits then
    move and the comparison says by how much).
    """
    dataset_dir, work_dir = Path(dataset_dir), Path(work_dir)
    if not (dataset_dir / "samples.csv").is_file():
        raise FileNotFoundError(f"{dataset_dir}: no samples.csv (is this a dataset folder?)")
    report = ingest_dataset(dataset_dir, work_dir / "runs", work_dir / "ingest_report.csv")
    for _, row in report[report["status"] != "ok"].iterrows():
        log.warning("%s: run %s rejected: %s", dataset_dir.name, row["run"], row["reason"])
    runs = load_runs(work_dir / "runs")
    tests = sorted({str(r.attrs.get("test", "")) for r in runs} - {""})
    return average_runs(runs, exclude_flagged=exclude_flagged), tests


def _parameter_flags(flags: Sequence[str], name: str) -> list[str]:
    """The fit flags that concern parameter ``name`` (at a bound, poorly determined, correlated)."""
    out = []
    for flag in flags:
        kind, _, detail = flag.partition(": ")
        if kind == "correlated":
            pair = detail.split(" ")[0].split("~")
            if name in {p.removeprefix("log10_") for p in pair}:
                out.append(flag)
        elif kind in ("at_bound", "poorly_determined") and detail.split(" ")[0] == name:
            out.append(flag)
    return out


def tolerance_for(value: float, stderr: float, k: float = STDERR_MULTIPLIER, relative_floor: float = RELATIVE_FLOOR,
                  absolute_floor: float = ABSOLUTE_FLOOR) -> tuple[float, str]:
    """Tolerance of one parameter and the rule that set it (module docstring)."""
    floor = max(relative_floor * abs(value), absolute_floor)
    if not (np.isfinite(stderr) and stderr > 0):
        why = "not estimated (singular covariance)" if not np.isfinite(stderr) else "zero (parameter held fixed)"
        return floor, f"standard error {why}: reproducibility floor {relative_floor:g} x |value|"
    if k * stderr >= floor:
        return k * stderr, f"{k:g} x standard error {stderr:.4g}"
    return floor, f"reproducibility floor {relative_floor:g} x |value| (exceeds {k:g} x standard error {stderr:.3g})"


def mode_labels(params: Mapping[str, float]) -> dict[str, str]:
    """Canonical name -> fitted name that numbers exchangeable relaxation modes by increasing time.

    The modes of a Prony series (``G_i``, ``tau_i``) or a generalized Kelvin-Voigt chain (``G_i``,
    ``tau_ret_i``) can be relabelled without changing the model, and the multistart fit does land on
    permuted labellings whose chi-square differs from the best by ~1e-9 relative, below the solver's
    stopping tolerance. So which labelling wins can change with the platform, and the reference compares modes
    sorted by time instead. Models without free mode times map every name to itself.
    """
    identity = {name: name for name in params}
    time_prefix = next((t for t in ("tau_ret", "tau") if f"{t}_1" in params), None)
    if time_prefix is None:
        return identity
    indices = sorted(int(m.group(1)) for n in params if (m := re.fullmatch(rf"{time_prefix}_(\d+)", n)))
    groups = {}
    for name in params:
        m = re.fullmatch(r"(.+)_(\d+)", name)
        if m and int(m.group(2)) in indices:
            groups.setdefault(m.group(1), set()).add(int(m.group(2)))
    if any(found != set(indices) for found in groups.values()):
        return identity  # not a set of complete, exchangeable modes
    order = sorted(indices, key=lambda i: params[f"{time_prefix}_{i}"])
    labels = dict(identity)
    for new, old in zip(indices, order):
        for prefix in groups:
            labels[f"{prefix}_{new}"] = f"{prefix}_{old}"
    return labels


def reference_rows(dataset: str, result) -> list[dict]:
    """Reference-table rows of one :class:`tissuemech.fitting.FitResult` (modes sorted by :func:`mode_labels`)."""
    rows = []
    labels = mode_labels(result.params)
    for name in result.params:
        fitted = labels[name]
        value = result.params[fitted]
        stderr = float(result.stderr.get(fitted, float("nan")))
        tolerance, reason = tolerance_for(float(value), stderr)
        caveats = _parameter_flags(result.flags, fitted)
        if fitted != name:
            caveats.insert(0, f"fitted as {fitted} (modes numbered by increasing time)")
        if not result.success:
            caveats.insert(0, f"fit not converged: {result.message}")
        if caveats:
            reason += "; " + "; ".join(caveats)
        rows.append({"dataset": dataset, "scope": result.scope, "model": result.model_key, "parameter": name,
                     "unit": result.units.get(name, ""), "value": float(value), "stderr": stderr,
                     "tolerance": float(tolerance), "reason": reason})
    return rows


def material_rows(dataset: str, averages, spec: Mapping, settings: Mapping, scope: str) -> list[dict]:
    """Reference rows of a material scope: :func:`tissuemech.material.fit_material` as the fit stage runs it, and the
    parameters of its baseline model under the key the data chose (a change of the chosen law or relaxation times
    shows as rows missing from the table and rows new to it)."""
    curves = spec_curves(averages, spec)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mf = fit_material(curves, settings["plate_target"], laws=spec.get("laws") or MATERIAL_LAWS,
                          seed=int(settings["seed"]), scope=scope, dataset=dataset)
    key = baseline_model(mf.table)
    if key is None:
        return [{"dataset": dataset, "scope": scope, "model": MATERIAL_BASELINE, "parameter": "<fit failed>",
                 "unit": "", "value": float("nan"), "stderr": float("nan"), "tolerance": float("nan"),
                 "reason": f"no baseline: {mf.recommendation.get('statement', '')}"}]
    rows = reference_rows(dataset, mf.fits[key])
    # the relaxation times are the data's choice (NNLS over the resolved window), held fixed in the fit: a change of
    # them is a regression of the material model too
    for i, tau in enumerate(mf.factories[key].taus_s, start=1):
        tolerance, _ = tolerance_for(float(tau), 0.0)
        rows.append({"dataset": dataset, "scope": scope, "model": key, "parameter": f"{RELAXATION_TIME}{i}",
                     "unit": "s", "value": float(tau), "stderr": 0.0, "tolerance": float(tolerance),
                     "reason": f"relaxation time chosen from the data (NNLS), held fixed in the fit: reproducibility "
                               f"floor {RELATIVE_FLOOR:g} x |value|"})
    return rows


def fresh_table(raw_dir=DEFAULT_RAW_DIR, config_path=DEFAULT_CONFIG,
                selection: Mapping[str, Mapping[str, Sequence[str]]] | None = None) -> pd.DataFrame:
    """Redo the reference fits and return them in the reference-table layout (:data:`COLUMNS`).

    A fit that raises is recorded as a row with parameter ``<fit failed>`` and the error as its reason, so the
    comparison reports it instead of crashing.
    """
    selection = REFERENCE_FITS if selection is None else selection
    settings = fit_settings(config_path)
    rows: list[dict] = []
    for dataset, scopes in selection.items():
        started = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix=f"tissuemech_regression_{dataset}_") as work:
            averages, tests = dataset_averages(Path(raw_dir) / dataset, work,
                                               exclude_flagged=bool(settings.get("exclude_flagged", True)))
        available = dataset_scopes(tests, settings)
        for scope, models in scopes.items():
            if scope not in available:
                raise ValueError(f"{dataset}: scope {scope!r} not produced by the pipeline for tests {tests} "
                                 f"(scopes: {sorted(available)})")
            if available[scope].get("material"):
                rows += material_rows(dataset, averages, available[scope], settings, scope)
                continue
            curves = scope_curves(averages, available[scope]["tests"])
            for key in models:
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore", RuntimeWarning)
                        result = R.fit_candidate(R.Candidate(key, R.RegistryFactory(key)), curves,
                                                 settings["plate_target"], scope, n_random=int(settings["multistart"]),
                                                 seed=int(settings["seed"]))
                except (ValueError, RuntimeError) as exc:
                    rows.append({"dataset": dataset, "scope": scope, "model": key, "parameter": "<fit failed>",
                                 "unit": "", "value": float("nan"), "stderr": float("nan"),
                                 "tolerance": float("nan"), "reason": f"{type(exc).__name__}: {exc}"})
                    continue
                rows += reference_rows(dataset, result)
        log.info("%s: refitted in %.1f s", dataset, time.perf_counter() - started)
    return pd.DataFrame(rows, columns=list(COLUMNS))


# ------------------------------------------------------------------------------------------------------
# the committed table
# ------------------------------------------------------------------------------------------------------
def read_reference_file(path) -> pd.DataFrame:
    """Read and validate one reference CSV.

    Raises
    ------
    ReferenceTableError
        naming file, line and column: missing columns, empty keys or reasons, non-finite values, zero, negative
        or missing tolerances, duplicated parameters.
    """
    path = Path(path)
    try:
        table = pd.read_csv(path, dtype={c: str for c in (*KEY_COLUMNS, "unit", "reason")}, keep_default_na=False,
                            na_values={"value": ["", "nan", "NaN"], "stderr": ["", "nan", "NaN"],
                                       "tolerance": ["", "nan", "NaN"]})
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ReferenceTableError(path, f"not a readable CSV: {exc}") from exc
    missing = [c for c in COLUMNS if c not in table.columns]
    if missing:
        raise ReferenceTableError(path, f"missing columns {missing}; expected {list(COLUMNS)}", line=1)
    for column in ("value", "stderr", "tolerance"):
        numeric = pd.to_numeric(table[column], errors="coerce")
        bad = numeric.isna() & table[column].notna()
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ReferenceTableError(path, f"{table[column].iloc[i]!r} is not a number", line=i + 2, column=column)
        table[column] = numeric.astype(float)
    for i, row in enumerate(table.itertuples(index=False), start=2):
        for column in (*KEY_COLUMNS, "reason"):
            if not str(getattr(row, column)).strip():
                raise ReferenceTableError(path, f"empty {column}", line=i, column=column)
        if not math.isfinite(row.value):
            raise ReferenceTableError(path, "value must be a finite number", line=i, column="value")
        if not (math.isfinite(row.tolerance) and row.tolerance > 0):
            raise ReferenceTableError(path, f"tolerance must be a positive finite number, got {row.tolerance!r}",
                                      line=i, column="tolerance")
    duplicated = table.duplicated(list(KEY_COLUMNS), keep="first")
    if duplicated.any():
        i = int(np.flatnonzero(duplicated)[0])
        key = ", ".join(str(table[c].iloc[i]) for c in KEY_COLUMNS)
        raise ReferenceTableError(path, f"duplicated parameter ({key})", line=i + 2)
    return table[list(COLUMNS)]


def read_reference(reference_dir=DEFAULT_REFERENCE_DIR) -> pd.DataFrame:
    """Every ``<reference_dir>/*.csv`` validated and concatenated (empty table when there is none)."""
    paths = sorted(Path(reference_dir).glob("*.csv"))
    tables = [read_reference_file(p) for p in paths]
    return pd.concat(tables, ignore_index=True) if tables else pd.DataFrame(columns=list(COLUMNS))


def write_reference(table: pd.DataFrame, reference_dir=DEFAULT_REFERENCE_DIR, remove_stale: bool = True) -> list[Path]:
    """Write one CSV per dataset (full float precision); ``remove_stale`` deletes tables of other datasets."""
    reference_dir = Path(reference_dir)
    reference_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for dataset, part in table.groupby("dataset", sort=True):
        path = reference_dir / f"{dataset}.csv"
        write_text(part[list(COLUMNS)].to_csv(index=False), path)
        written.append(path)
    if remove_stale:
        for stale in set(reference_dir.glob("*.csv")) - set(written):
            stale.unlink()
    return written


def select_datasets(datasets: Sequence[str] | None) -> dict[str, dict[str, tuple[str, ...]]]:
    """The part of :data:`REFERENCE_FITS` for ``datasets`` (all when ``None`` or empty)."""
    if not datasets:
        return dict(REFERENCE_FITS)
    unknown = sorted(set(datasets) - set(REFERENCE_FITS))
    if unknown:
        raise ValueError(f"no reference fits for datasets {unknown}; known: {sorted(REFERENCE_FITS)}")
    return {d: REFERENCE_FITS[d] for d in datasets}


# ------------------------------------------------------------------------------------------------------
# comparison
# ------------------------------------------------------------------------------------------------------
def compare(reference: pd.DataFrame, fresh: pd.DataFrame) -> pd.DataFrame:
    """Every parameter of either table with reference, fresh, difference, tolerance and status.

    Status: ``ok`` (|difference| <= tolerance), ``moved``, ``fit failed``, ``missing from fresh fits``
    (a reference row the fits no longer produce) or ``not in reference`` (a new fit or parameter: run
    ``--update``). The tolerance is the committed one; rows not in the reference have none.
    """
    keys = list(KEY_COLUMNS)
    ref = reference[keys + ["value", "tolerance"]].rename(columns={"value": "reference"})
    new = fresh[keys + ["value", "reason"]].rename(columns={"value": "fresh", "reason": "fresh_reason"})
    merged = ref.merge(new, on=keys, how="outer", indicator=True)
    merged["difference"] = merged["fresh"] - merged["reference"]
    with np.errstate(invalid="ignore", divide="ignore"):
        merged["difference/tolerance"] = merged["difference"] / merged["tolerance"]
    status = np.where(merged["difference"].abs() <= merged["tolerance"], "ok", "moved").astype(object)
    status[(merged["_merge"] == "left_only").to_numpy()] = "missing from fresh fits"
    status[(merged["_merge"] == "right_only").to_numpy()] = "not in reference"
    failed = (merged["parameter"] == "<fit failed>").to_numpy()
    status[failed] = ("fit failed: " + merged["fresh_reason"].astype(str)).to_numpy()[failed]
    merged["status"] = status
    merged = merged.drop(columns=["_merge", "fresh_reason"])
    return merged[list(REPORT_COLUMNS)].sort_values(keys, ignore_index=True)


def failures(comparison: pd.DataFrame) -> pd.DataFrame:
    """Rows that fail the check, largest |difference/tolerance| first (non-numeric failures on top)."""
    bad = comparison[comparison["status"] != "ok"].copy()
    order = bad["difference/tolerance"].abs().fillna(np.inf)
    return bad.assign(_order=order).sort_values("_order", ascending=False, kind="stable").drop(columns="_order")


def format_table(table: pd.DataFrame) -> str:
    """Plain-text table for a CI log (numbers in 6 significant digits)."""
    if table.empty:
        return "(no rows)"
    shown = table.copy()
    for column in ("reference", "fresh", "difference", "tolerance"):
        shown[column] = shown[column].map(lambda v: "" if pd.isna(v) else f"{v:.6g}")
    shown["difference/tolerance"] = shown["difference/tolerance"].map(lambda v: "" if pd.isna(v) else f"{v:+.3g}")
    return shown.to_string(index=False)


def check(reference_dir=DEFAULT_REFERENCE_DIR, fresh: pd.DataFrame | None = None, raw_dir=DEFAULT_RAW_DIR,
          config_path=DEFAULT_CONFIG, datasets: Sequence[str] | None = None) -> tuple[bool, pd.DataFrame, str]:
    """Compare fresh fits (computed unless given) with the committed table, for every dataset or ``datasets``.

    Returns ``(passed, comparison, message)``; the message holds the table of every failing parameter.
    """
    selection = select_datasets(datasets)
    reference = read_reference(reference_dir)
    if datasets:
        reference = reference[reference["dataset"].isin(selection)]
    if reference.empty:
        return False, pd.DataFrame(columns=list(REPORT_COLUMNS)), (
            f"no reference table under {reference_dir}: run `python -m tissuemech.regression --update`")
    if fresh is None:
        fresh = fresh_table(raw_dir, config_path, selection)
    fresh = fresh[fresh["dataset"].isin(selection)]
    comparison = compare(reference, fresh)
    bad = failures(comparison)
    if bad.empty:
        worst = comparison["difference/tolerance"].abs().max()
        return True, comparison, (f"fitted-parameter regression: all {len(comparison)} parameters within tolerance "
                                  f"(largest |difference/tolerance| {worst:.3g})")
    message = (f"fitted-parameter regression: {len(bad)} of {len(comparison)} parameters outside tolerance or "
               f"unmatched (reference: {reference_dir})\n{format_table(bad)}\n"
               "If the change is intended, run `make regression-update` (python -m tissuemech.regression --update) "
               "and commit the new tables with the reason.")
    return False, comparison, message


def update(reference_dir=DEFAULT_REFERENCE_DIR, fresh: pd.DataFrame | None = None, raw_dir=DEFAULT_RAW_DIR,
           config_path=DEFAULT_CONFIG, datasets: Sequence[str] | None = None) -> tuple[list[Path], str]:
    """Rewrite the reference tables (of every dataset or ``datasets``) from fresh fits.

    Returns the files written and the diff table against the old tables.
    """
    selection = select_datasets(datasets)
    try:
        old = read_reference(reference_dir)
    except ReferenceTableError as exc:  # a broken table is replaced, and said so
        log.warning("old reference table unreadable, replaced without a diff: %s", exc)
        old = pd.DataFrame(columns=list(COLUMNS))
    if datasets:
        old = old[old["dataset"].isin(selection)]
    if fresh is None:
        fresh = fresh_table(raw_dir, config_path, selection)
    fresh = fresh[fresh["dataset"].isin(selection)]
    failed = fresh[fresh["parameter"] == "<fit failed>"]
    if not failed.empty:
        raise RuntimeError("refusing to write a reference with failed fits:\n"
                           + failed[["dataset", "scope", "model", "reason"]].to_string(index=False))
    written = write_reference(fresh, reference_dir, remove_stale=not datasets)
    comparison = compare(old, fresh)
    changed = comparison[(comparison["difference"] != 0) | comparison["difference"].isna()]
    if changed.empty:
        diff = f"reference unchanged: {len(comparison)} parameters identical"
    else:
        diff = (f"{len(changed)} of {len(comparison)} parameters changed (difference/tolerance uses the old "
                f"tolerance):\n{format_table(changed)}")
    return written, diff


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="tissuemech regression",
                                     description="Check or update the committed reference table of fitted parameters.")
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="refit and compare; exit 1 with a table of what moved")
    mode.add_argument("--update", action="store_true", help="refit, rewrite the tables and print the diff")
    parser.add_argument("--reference-dir", type=Path, default=DEFAULT_REFERENCE_DIR)
    parser.add_argument("--raw-dir", type=Path, default=DEFAULT_RAW_DIR)
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    parser.add_argument("--dataset", action="append", dest="datasets", metavar="NAME",
                        help=f"only this dataset (repeatable; default: all of {sorted(REFERENCE_FITS)})")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    # the pipeline stages log every ingested run; only the regression's own records belong in a CI log.
    # The levels are restored on return: main() is also called in-process (tests), where they must not leak.
    package, levels = logging.getLogger("tissuemech"), (logging.getLogger("tissuemech").level, log.level)
    package.setLevel(logging.WARNING)
    log.setLevel(logging.INFO)
    try:
        return _run(args)
    finally:
        package.setLevel(levels[0])
        log.setLevel(levels[1])


def _run(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    try:
        if args.update:
            written, diff = update(args.reference_dir, raw_dir=args.raw_dir, config_path=args.config,
                                   datasets=args.datasets)
            print(diff)
            print("wrote " + ", ".join(str(p) for p in written))
            status = 0
        else:
            passed, _, message = check(args.reference_dir, raw_dir=args.raw_dir, config_path=args.config,
                                       datasets=args.datasets)
            print(message)
            status = 0 if passed else 1
    except (ReferenceTableError, FileNotFoundError, ValueError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    log.info("done in %.1f s", time.perf_counter() - started)
    return status


if __name__ == "__main__":
    sys.exit(main())
