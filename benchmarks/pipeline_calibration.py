"""Calibration of the diagnosis users run: dataset folders through the pipeline's path (issue 32 item 4; not a test).

Every dataset is a folder written by :func:`independent_rheometer.write_dataset_folder` (instrument exports in
their real formats and units, ``samples.csv``, ``dataset.yaml``; the truth beside the folder, never read by the
pipeline) and analysed by :func:`tissuemech.analysis.analyse_dataset` with the pipeline configuration
(``config/config.yaml`` unless ``--config``): ingest -> averages -> every fit scope -> ranking -> diagnosis, the
functions ``make run`` runs. ``tests/diagnosis/test_calibration.py`` runs the CI subset through :func:`one`.

Counted
-------
* **null** (``--null N``): a family-wise false alarm is any ``detected`` cause, any ``unexplained`` entry, an
  export the ingest rejected, or a crash. A detected ``baseline_inadequate`` is a statement about the baseline
  (counted in its own line), and a named cause that is a fact of the generated measurement verified on its raw
  channels (``inertia_dominated_points``: a raw phase above 90 deg) is a correct finding
  (``diagnosis_calibration.measurement_facts``). Rates with Clopper-Pearson 95 % intervals; broken down by the
  design choices (test family, specimens, blocks or interleaved, days, export format).
* **power** (``--power-reps R`` datasets per cause and magnitude, ``--magnitudes``): the injected effect is
  *named* when the cause in :data:`NAMED_AS` is detected; the normal-force preload, which has no cause of its own,
  when the diagnosis attributes structure to the normal-force channel (:data:`ATTRIBUTED_TO`: an ``unexplained``
  entry or a significant ``covariates`` row). The design of a power dataset is drawn among those that can show the
  effect (``independent_rheometer.SHOWN_BY``, ``MIN_SAMPLES``); the same seed at every magnitude (paired).

Seeds (the rule): null dataset ``i`` has seed ``base + i``; replicate ``r`` of cause ``k`` (its index in
``independent_rheometer.FOLDER_EFFECTS``) has seed ``base + 100000 + 1000 k + r`` at every magnitude. The base is
given on the command line (``--seed-base``, no default) and must be fresh: the script refuses a base whose seeds
meet :data:`DEVELOPMENT_SEEDS` (seeds looked at while the code or this yardstick were written, and the CI subset).

``--rows-json`` keeps one row per dataset and makes a run resumable: rows already in it (or in its
``.partial.jsonl``, appended as each dataset finishes) are not run again. ``--from-json`` renders the tables of
earlier rows.

Usage::

    NUMBA_CACHE_DIR=.numba_cache PYTHONPATH=src .venv/bin/python benchmarks/pipeline_calibration.py \\
        --seed-base 40000000 --null 200 --power-reps 5 --jobs 2 --rows-json /tmp/pipeline_calibration.json \\
        --out docs/calibration.md --title "Pipeline path calibration"
"""
from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import json
import os
import shlex
import shutil
import sys
import tempfile
import time
import traceback
import warnings
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import yaml
from scipy.stats import binomtest, nct
from scipy.stats import t as student_t

sys.path.insert(0, str(Path(__file__).resolve().parent))

import independent_rheometer as ir  # noqa: E402
from diagnosis_calibration import NOT_A_CAUSE, machine, measurement_facts, own_verdict, write_section  # noqa: E402

from tissuemech.analysis import analyse_dataset  # noqa: E402
from tissuemech.canonical import write_text  # noqa: E402
from tissuemech.pipeline import load_runs  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: the diagnosis cause that names each injected effect (``None``: no cause of its own, see :data:`ATTRIBUTED_TO`)
NAMED_AS = {**{e: e for e in ir.EFFECTS}, "creep_ringing": "inertial_ringing",
            "temperature_spread": "temperature_dependence", "normal_force_preload": None}
#: covariates the diagnosis must attribute an effect without a cause of its own to
ATTRIBUTED_TO = {"normal_force_preload": ("channel_normal_force",)}
#: seed ranges [first, last] looked at while the code and this yardstick were written, and the CI subset's seeds:
#: never the seeds of a calibration run
DEVELOPMENT_SEEDS = (
    (0, 9999),                     # tests of the generators and of the one path (tests/)
    (20261123, 20472200),          # the runs-only studies of docs/calibration.md (null, power, examined alarms)
    (32000000, 32199999),          # development runs of this benchmark (docs/calibration.md, "Pipeline path")
    (32500000, 32799999),          # the CI subset (tests/diagnosis/test_calibration.py)
    (41000000, 41199999),          # a full study begun and stopped after its first dataset (docs/calibration.md)
)
POWER_OFFSET = 100000


def seeds(base: int, n_null: int, power_reps: int, effects) -> list[tuple[str | None, int]]:
    """(effect or None, seed) of every dataset of a run, by the rule of the module docstring."""
    out = [(None, base + i) for i in range(n_null)]
    for k, eff in enumerate(ir.FOLDER_EFFECTS):
        if eff in effects:
            out += [(eff, base + POWER_OFFSET + 1000 * k + r) for r in range(power_reps)]
    return out


def development_overlap(used: list[int]) -> list[tuple[int, int]]:
    """The development ranges that some of ``used`` fall in."""
    return [(a, b) for a, b in DEVELOPMENT_SEEDS if any(a <= s <= b for s in used)]


def named(result: dict, effect: str) -> bool:
    """Whether a diagnosis result names the injected ``effect`` (module docstring)."""
    cause = NAMED_AS[effect]
    if cause is not None:
        return any(f["effect"] == cause and f.get("detected") for f in result["findings"])
    covs = ATTRIBUTED_TO[effect]
    return (any(u.get("covariate") in covs for u in result.get("unexplained", []))
            or any(c.get("covariate") in covs and c.get("significant") for c in result.get("covariates", [])))


def design_summary(truth: dict) -> dict:
    d = truth["design"]
    return {"family": d["family"], "kinds": d["kinds"], "n_specimens": d["n_specimens"],
            "n_samples": int(sum(d["samples_per_specimen"])), "layout": d["layout"], "days": d["days"],
            "order": d["order"], "format": d["format"], "torque_unit": d["torque_unit"],
            "geometry_source": d["geometry_source"], "logs_normal_force": d["logs_normal_force"]}


def one(job: tuple, work_dir, config: dict, keep: bool = False, figures: bool = False) -> dict:
    """(effect or None, magnitude, seed) -> the row of one generated and analysed dataset folder.

    The folder is written under ``work_dir/raw/<name>`` (truth beside it), analysed into
    ``work_dir/results/<name>`` by :func:`tissuemech.analysis.analyse_dataset`, and removed unless ``keep``."""
    effect, magnitude, seed = job
    name = f"calib_{seed}" + (f"_{effect}_{magnitude:g}x" if effect else "")
    raw, res = Path(work_dir) / "raw" / name, Path(work_dir) / "results" / name
    row = {"effect": effect, "magnitude": magnitude, "seed": seed, "dataset": name, "error": None,
           "detected": [], "unexplained": [], "baseline": [], "named_facts": []}
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            truth = ir.write_dataset_folder(seed, raw, {effect: magnitude} if effect else None)
            row.update(law=truth["law"], kernel=truth["kernel"], design=design_summary(truth),
                       specimen_log_sd=truth["specimens"]["log_sd"], generate_s=time.perf_counter() - t0)
            done = analyse_dataset(raw, res, config, figures=figures)
        rejected = done["ingest_report"][done["ingest_report"]["status"] != "ok"]
        row.update(n_runs=int((done["ingest_report"]["status"] == "ok").sum()), rejected=len(rejected),
                   scopes=done["scopes"], diagnosis_scope=done["diagnosis_scope"], stage_s=done["seconds"])
        if len(rejected):
            row["error"] = f"ingest rejected {len(rejected)} export(s): {rejected['reason'].iloc[0]}"
        result = done["diagnosis"]
        if result is None:
            row["error"] = row["error"] or "not diagnosed"
        else:
            det = [f["effect"] for f in result["findings"] if f.get("detected") and f["effect"] not in NOT_A_CAUSE]
            facts = measurement_facts(load_runs(res / "runs"))
            row["named_facts"] = [e for e in det if e in facts and e != NAMED_AS.get(effect)]
            row.update(detected=[e for e in det if e not in row["named_facts"]],
                       unexplained=[f"{u.get('covariate')}@{u.get('test')}" for u in result.get("unexplained", [])],
                       baseline=[f["effect"] for f in result["findings"]
                                 if f.get("detected") and f["effect"] in NOT_A_CAUSE],
                       model=result.get("model"))
            if effect:
                row["named"] = named(result, effect)
                cause = NAMED_AS[effect]
                row["verdict"] = ("detected" if row["named"] else
                                  own_verdict(result, cause) if cause else "not attributed")
    except Exception as exc:  # noqa: BLE001 -- a crash is a result of the study, recorded with its message
        row.update(error=f"{type(exc).__name__}: {exc}", trace=traceback.format_exc(limit=4))
    row["seconds"] = time.perf_counter() - t0
    if not keep:
        shutil.rmtree(raw, ignore_errors=True)
        shutil.rmtree(res, ignore_errors=True)
        Path(f"{raw}.truth.json").unlink(missing_ok=True)
    return row


def is_alarm(row: dict) -> bool:
    return bool(row["detected"] or row["unexplained"] or row["error"])


def outlier_power(n_specimens: int, delta_over_sigma: float, alpha: float, n_causes: int) -> float:
    """Power of the studentized deletion t of the most extreme of ``n_specimens`` specimen levels (df = n - 2),
    Bonferroni over the specimens and Holm's first step over ``n_causes`` tested causes, for an outlier
    ``delta_over_sigma`` between-specimen SDs away (noncentral t; as in docs/power_study.md)."""
    if n_specimens < 3:
        return 0.0
    df = n_specimens - 2
    crit = student_t.ppf(1.0 - alpha / (2.0 * n_specimens * n_causes), df)
    return float(nct.sf(crit, df, delta_over_sigma))


def _ci(k: int, n: int) -> str:
    if not n:
        return "-"
    ci = binomtest(k, n).proportion_ci(0.95, method="exact")
    return f"{100 * ci.low:.1f}-{100 * ci.high:.1f} %"


def _breakdown(rows: list[dict], key, label: str) -> list[str]:
    lines = [f"| {label} | datasets | false alarms | named / unexplained (commonest) |", "|---|---|---|---|"]
    groups: dict = {}
    for r in rows:
        groups.setdefault(key(r), []).append(r)
    for g in sorted(groups, key=str):
        sub = groups[g]
        what = Counter([e for r in sub for e in r["detected"]] + [u for r in sub for u in r["unexplained"]]
                       + [r["error"].split(":")[0] for r in sub if r["error"]])
        lines.append(f"| {g} | {len(sub)} | {sum(map(is_alarm, sub))} | "
                     + (", ".join(f"{e} ({c})" for e, c in what.most_common(4)) or "-") + " |")
    return lines


def _specimens(r):
    n = r.get("design", {}).get("n_specimens", 0)
    return "1" if n == 1 else "2-3" if n <= 3 else "4-8"


def null_table(rows: list[dict]) -> list[str]:
    n = len(rows)
    k = sum(map(is_alarm, rows))
    lines = ["### Null datasets (no effect injected)", "",
             f"Family-wise false alarms (a detected cause, an unexplained entry, a rejected export or a crash): "
             f"**{k}/{n} = {100 * k / max(n, 1):.1f} %** (Clopper-Pearson 95 %: {_ci(k, n)}). Target: <= 1 % on "
             f">= 200 datasets.", ""]
    lines += _breakdown(rows, lambda r: r.get("design", {}).get("family", "?"), "test family") + [""]
    lines += _breakdown(rows, _specimens, "specimens") + [""]
    lines += _breakdown(rows, lambda r: r.get("design", {}).get("layout", "?"), "sequence") + [""]
    lines += _breakdown(rows, lambda r: r.get("design", {}).get("days", "?"), "days") + [""]
    lines += _breakdown(rows, lambda r: r.get("design", {}).get("format", "?"), "export format") + [""]
    lines += _breakdown(rows, lambda r: r.get("law", "?"), "truth law") + [""]
    flagged = sum(bool(r["baseline"]) for r in rows)
    facts = Counter(e for r in rows for e in r.get("named_facts", []))
    lines += [f"Baseline reported inadequate (not counted as a false alarm): {flagged}/{n}.", "",
              "Measurement facts named and verified on the raw channels (correct findings, not alarms): "
              + (", ".join(f"{e} ({c})" for e, c in facts.most_common()) or "none") + ".", "",
              "Seeds with a false alarm: " + (", ".join(str(r["seed"]) for r in rows if is_alarm(r)) or "none")]
    errs = Counter(r["error"][:100] for r in rows if r["error"])
    if errs:
        lines += ["", "Crashes and rejections: " + "; ".join(f"{e} ({c})" for e, c in errs.most_common(5))]
    return lines


def _design_rule(effect: str) -> str:
    kinds = ir.SHOWN_BY[effect]
    text = "any test" if set(kinds) == set(ir.FOLDER_TESTS) else " or ".join(k.replace("_", " ") for k in kinds)
    extra = []
    if effect in ir.MIN_SAMPLES:
        extra.append(f">= {ir.MIN_SAMPLES[effect]} samples")
    if effect == "outlier_specimen":
        extra.append("4-6 specimens")
    return text + (f"; {', '.join(extra)}" if extra else "")


def power_table(rows: list[dict], magnitudes) -> list[str]:
    lines = ["### Power per cause (named under its own name)", "",
             "| injected | named as | designs that show it | " + " | ".join(f"{m:g}x" for m in magnitudes)
             + " | 1x by test family | other causes named | why missed |",
             "|---|---|---|" + "---|" * len(magnitudes) + "---|---|---|"]
    for eff in [e for e in ir.FOLDER_EFFECTS if any(r["effect"] == e for r in rows)]:
        sub_all = [r for r in rows if r["effect"] == eff]
        cells = []
        for m in magnitudes:
            sub = [r for r in sub_all if r["magnitude"] == m]
            cells.append(f"{sum(bool(r.get('named')) for r in sub)}/{len(sub)}" if sub else "-")
        fam: dict = {}
        for r in sub_all:
            if r["magnitude"] == 1.0:
                fam.setdefault(r.get("design", {}).get("family", "?"), []).append(bool(r.get("named")))
        own = NAMED_AS[eff]
        other = Counter(e for r in sub_all for e in r["detected"] if e != own)
        other.update("(crash)" for r in sub_all if r["error"])
        why = Counter(r.get("verdict") for r in sub_all if r.get("verdict") not in (None, "detected"))
        lines.append(f"| {eff} | {own or 'covariate ' + '/'.join(ATTRIBUTED_TO[eff])} | {_design_rule(eff)} | "
                     + " | ".join(cells) + " | "
                     + (", ".join(f"{f} {sum(v)}/{len(v)}" for f, v in sorted(fam.items())) or "-") + " | "
                     + (", ".join(f"{e} ({c})" for e, c in other.most_common(4)) or "-") + " | "
                     + (", ".join(f"{v} ({c})" for v, c in why.most_common()) or "-") + " |")
    out_rows = [r for r in rows if r["effect"] == "outlier_specimen" and r["magnitude"] == 1.0 and "design" in r]
    if out_rows:
        delta = np.log1p(ir.EFFECT_SIZES["outlier_specimen"]["factor_minus_1"])
        p = [outlier_power(r["design"]["n_specimens"], delta / r["specimen_log_sd"], 0.01, 14) for r in out_rows]
        lines += ["", f"Outlier specimen at 1x (x{1 + ir.EFFECT_SIZES['outlier_specimen']['factor_minus_1']:g}): "
                      f"the best power a deletion test can have on these designs (4-6 specimens, specimen log-SD "
                      f"0.05-0.3; `outlier_power`) is {np.mean(p):.2f} on average (median {np.median(p):.2f}, "
                      f"min {np.min(p):.2f}), so >= 80 % is out of reach wherever the specimen SD is large."]
    return lines


def load_rows(path: Path | None) -> list[dict]:
    """Rows of an earlier (possibly interrupted) run: ``path`` and its ``.partial.jsonl``, one row per dataset."""
    if path is None:
        return []
    rows = {}
    if path.is_file():
        for r in json.loads(path.read_text(encoding="utf-8")):
            rows[(r["effect"], r["magnitude"], r["seed"])] = r
    partial = path.with_name(path.name + ".partial.jsonl")
    if partial.is_file():
        for line in partial.read_text(encoding="utf-8").splitlines():
            if line.strip():
                r = json.loads(line)
                rows[(r["effect"], r["magnitude"], r["seed"])] = r
    return list(rows.values())


def _run_one(args):
    job, work_dir, config, keep, figures = args
    return one(job, work_dir, config, keep, figures)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed-base", type=int, default=None, help="first seed (rule in the module docstring)")
    ap.add_argument("--null", type=int, default=200, help="number of null datasets")
    ap.add_argument("--power-reps", type=int, default=5, help="datasets per cause and magnitude")
    ap.add_argument("--magnitudes", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    ap.add_argument("--effects", nargs="+", default=list(ir.FOLDER_EFFECTS), choices=ir.FOLDER_EFFECTS)
    ap.add_argument("--config", type=Path, default=ROOT / "config" / "config.yaml", help="pipeline configuration")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--work-dir", type=Path, default=None, help="where the folders are written (default: a temp dir)")
    ap.add_argument("--keep", action="store_true", help="keep every dataset folder and its results")
    ap.add_argument("--figures", action="store_true", help="also draw the figures (as make run does; slower)")
    ap.add_argument("--rows-json", type=Path, default=None, help="rows of every dataset (JSON); resumes a run")
    ap.add_argument("--from-json", type=Path, nargs="+", default=None, help="render earlier --rows-json files")
    ap.add_argument("--allow-development-seeds", action="store_true",
                    help="allow seeds of DEVELOPMENT_SEEDS (development runs only, never for the calibration table)")
    ap.add_argument("--out", type=Path, default=None, help="markdown file to write (e.g. docs/calibration.md)")
    ap.add_argument("--title", default="Pipeline path calibration")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    if a.from_json:
        rows = [r for f in a.from_json for r in load_rows(f)]
        magnitudes = sorted({r["magnitude"] for r in rows if r["effect"]}) or a.magnitudes
    else:
        if a.seed_base is None:
            ap.error("--seed-base is required: choose a fresh base (module docstring)")
        plan = seeds(a.seed_base, a.null, a.power_reps, a.effects)
        hit = development_overlap([s for _, s in plan])
        if hit and not a.allow_development_seeds:
            ap.error(f"seeds {a.seed_base}.. meet the development seeds {hit}: choose another --seed-base")
        jobs = [(None, 0.0, s) if e is None else (e, m, s) for e, s in plan for m in ([0.0] if e is None else
                                                                                    a.magnitudes)]
        rows = load_rows(a.rows_json)
        done = {(r["effect"], r["magnitude"], r["seed"]) for r in rows}
        todo = [j for j in jobs if j not in done]
        print(f"{len(jobs)} datasets, {len(jobs) - len(todo)} already in {a.rows_json}", file=sys.stderr)
        config = yaml.safe_load(a.config.read_text(encoding="utf-8"))
        work = a.work_dir or Path(tempfile.mkdtemp(prefix="pipeline_calibration_"))
        partial = a.rows_json.with_name(a.rows_json.name + ".partial.jsonl") if a.rows_json else None
        args = [(j, work, config, a.keep, a.figures) for j in todo]
        with ProcessPoolExecutor(a.jobs) if a.jobs > 1 else contextlib.nullcontext() as ex:
            for row in (ex.map(_run_one, args) if ex else map(_run_one, args)):
                rows.append(row)
                print(f"{row['dataset']}: {row['seconds']:.1f} s, detected {row['detected']}, "
                      f"unexplained {len(row['unexplained'])}, error {row['error']}", file=sys.stderr, flush=True)
                if partial:
                    with partial.open("a", encoding="utf-8") as fh:
                        fh.write(json.dumps(row, default=str) + "\n")
        if a.rows_json:
            write_text(json.dumps(rows, indent=1, default=str), a.rows_json)
        if not a.keep and a.work_dir is None:
            shutil.rmtree(work, ignore_errors=True)
        magnitudes = a.magnitudes
    wall = time.perf_counter() - t0
    secs = np.array([r["seconds"] for r in rows]) if rows else np.zeros(1)
    cmd = "PYTHONPATH=src python " + shlex.join(["benchmarks/pipeline_calibration.py",
                                                 *(argv if argv is not None else sys.argv[1:])])
    lines = [f"## {a.title}", "",
             (f"- date: {dt.date.today().isoformat()}; machine: {machine()}; `--jobs {a.jobs}`; "
              f"NUMBA_CACHE_DIR={os.environ.get('NUMBA_CACHE_DIR', '(unset)')}" if not a.from_json else
              f"- tables rendered {dt.date.today().isoformat()} from {', '.join(map(str, a.from_json))}"),
             f"- command: `{cmd}`",
             "- path: `tissuemech.analysis.analyse_dataset` (ingest -> averages -> every fit scope -> ranking -> "
             "diagnosis) on folders of `independent_rheometer.write_dataset_folder`, configuration "
             f"`{a.config.relative_to(ROOT) if a.config.is_relative_to(ROOT) else a.config}`",
             f"- {len(rows)} datasets" + ("" if a.from_json else f" in {wall:.0f} s")
             + f" (per dataset: median {np.median(secs):.1f} s, max {secs.max():.1f} s)", ""]
    null_rows = [r for r in rows if r["effect"] is None]
    if null_rows:
        lines += null_table(null_rows) + [""]
    power_rows = [r for r in rows if r["effect"] is not None]
    if power_rows:
        lines += power_table(power_rows, magnitudes) + [""]
    text = "\n".join(lines)
    print(text)
    if a.out:
        write_section(a.out, a.title, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
