"""The pipeline's path for one dataset in one process: ingest -> averages -> fits -> ranking -> diagnosis.

:func:`analyse_dataset` runs, in order and with the same arguments, the package functions that the Snakemake
rules' scripts run for one dataset (``workflow/rules/{ingest,curves,fit,diagnose}.smk`` and
``workflow/scripts/{ingest,average,tts,fit_scope,rank,diagnose}.py``), and writes the same files in the same
layout under ``results_folder`` (the workflow's ``results/<dataset>``). The workflow's decisions are the
package's (:mod:`tissuemech.pipeline`: which stages a sample sheet gets, which scope the diagnosis reads; the scopes
are :func:`tissuemech.scopes.dataset_scopes` of the test kinds). It is what the diagnosis calibration
(``benchmarks/pipeline_calibration.py``) and its CI subset run, so that their figures describe what a user
running ``make run`` gets; ``tests/workflow/test_analysis_path.py`` checks it against a Snakemake run.

Not run here: the posterior and population stages (config ``posterior``), so ``fits.csv`` carries no credible
intervals, the FEM experiments and the HTML summary (none of them is an input of the diagnosis). The scripts stay
separate adapters because one job per stage imports only what that stage needs (issue 17).
"""
from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from pathlib import Path

import pandas as pd

from .canonical import read_netcdf
from .curves import average_runs, write_averages
from .diagnosis.report import run_diagnosis
from .diagnosis.simulation_cards import attach_simulation
from .diagnosis.temperature import leave_one_temperature_out
from .io.ingest import ingest_dataset
from .lve import lve_summary, write_lve
from .pipeline import diagnosis_scope, is_diagnosed, load_runs, sheet_tests, sweep_temperatures
from .plots import plot_all_averages, plot_all_lve
from .scopes import dataset_scopes
from .spectra import run_spectrum
from .stages import collect_cross_tests, collect_scopes, write_fits_table
from .summary import fit_scope_job, plot_cards
from .tts import run_tts

log = logging.getLogger(__name__)


def analyse_dataset(raw_folder, results_folder, config: Mapping, *, figures: bool = True) -> dict:
    """Run the pipeline on one dataset folder and return what it wrote.

    Parameters
    ----------
    raw_folder : the dataset folder as a user drops it in ``raw/`` (``samples.csv``, ``dataset.yaml``, the
        instrument exports or a ``source_dir``); only read. Its name is the dataset name.
    results_folder : the dataset's results folder (the workflow's ``results/<dataset>``); created.
    config : the pipeline configuration (``config/config.yaml`` as a dict: ``fit``, ``fem.poisson_ratio``,
        ``diagnosis.alpha``, ``tts``).
    figures : also draw the figures and ``cards.csv`` the rules draw before the diagnosis (raw vs averages, LVE,
        TTS mastercurve, fits, ranking, cards). ``False`` leaves them out; every table, netCDF and
        ``diagnosis.json`` is the same, and the diagnosis draws its own figures either way
        (:func:`tissuemech.diagnosis.report.run_diagnosis`).

    Returns
    -------
    ``{"dataset", "tests", "scopes", "tts", "diagnosis_scope", "ingest_report", "ranking", "diagnosis",
    "seconds"}``: the scopes fitted, the ingest report and ranking tables, the diagnosis result (``None`` where the
    workflow does not diagnose the dataset) and the wall-clock seconds of each stage (``ingest``, ``average``,
    ``tts``, ``fit``, ``rank``, ``diagnose``).
    """
    folder, out = Path(raw_folder), Path(results_folder)
    name = folder.name
    sheet = pd.read_csv(folder / "samples.csv", dtype=str)   # as the DAG reads it (common.smk sample_sheet)
    tests = sheet_tests(sheet)
    tts = len(sweep_temperatures(sheet)) >= 2
    scopes = dataset_scopes(tests, config["fit"], tts=tts)
    exclude_flagged = config["fit"].get("exclude_flagged", True)
    tts_config = config.get("tts", {})
    fig = out / "figures"
    done = {"dataset": name, "tests": tests, "scopes": list(scopes), "tts": tts,
            "diagnosis_scope": None, "ranking": None, "diagnosis": None, "seconds": {}}
    clock = [time.perf_counter()]

    def lap(stage: str) -> None:
        now = time.perf_counter()
        done["seconds"][stage] = now - clock[0]
        clock[0] = now

    # rule ingest (workflow/scripts/ingest.py)
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    done["ingest_report"] = ingest_dataset(folder, runs_dir, out / "ingest_report.csv")
    lap("ingest")

    # rule average (workflow/scripts/average.py)
    runs = load_runs(runs_dir)
    averages = average_runs(runs, exclude_flagged=exclude_flagged)
    write_averages(averages, out / "averages.nc")
    if figures:
        plot_all_averages(averages, runs, fig / "averages")
    averages = read_netcdf(out / "averages.nc")  # the LVE limits read the file every later stage reads
    summary = lve_summary(runs, averages)
    write_lve(summary, out / "lve.nc", out / "lve.csv")
    if figures:
        (fig / "lve").mkdir(parents=True, exist_ok=True)
        plot_all_lve(summary, runs, averages, fig / "lve")
    run_spectrum(out / "averages.nc", out / "spectrum.nc")
    lap("average")

    # rule tts (workflow/scripts/tts.py), for sweeps at >= 2 temperatures
    tts_path = None
    if tts:
        tts_path = out / "tts.nc"
        run_tts(runs_dir, tts_path, out / "tts_card.json", out / "tts_card.inp",
                fig / "tts_mastercurve.png" if figures else None, dataset=name, t_ref_c=tts_config.get("t_ref_c"),
                vertical=tts_config.get("vertical", False), exclude_flagged=exclude_flagged,
                held_out=leave_one_temperature_out)
        lap("tts")
    if not scopes:
        return done

    # rule fit_scope (workflow/scripts/fit_scope.py), one scope after the other
    for scope, spec in scopes.items():
        scope_tts = tts_path if spec.get("mastercurve") else None
        fit_scope_job(out / "averages.nc", scope, spec, target=config["fit"]["plate_target"],
                      seed=config["fit"]["seed"], multistart=config["fit"]["multistart"],
                      fits_dir=out / "fits" / scope, cards_dir=out / "cards" / scope,
                      ranking_path=out / "ranking" / f"{scope}.csv", dataset=name,
                      poisson_ratio=config["fem"]["poisson_ratio"], tts_path=scope_tts,
                      figures_dir=fig / "fits" / scope if figures else None)
    lap("fit")

    # rule rank (workflow/scripts/rank.py); no posterior tables (not run here)
    done["ranking"] = collect_scopes([out / "ranking" / f"{s}.csv" for s in scopes], out / "ranking.csv",
                                     figure_out=fig / "ranking.png" if figures else None)
    collect_cross_tests([out / "ranking" / f"{s}.csv" for s in scopes], name, out / "cross_test.csv",
                        figure_out=fig / "cross_test.png" if figures else None)
    write_fits_table([out / "fits" / s for s in scopes], name, out / "fits.csv", posterior_tables=[])
    if figures:
        plot_cards(out / "cards", out / "ranking.csv", fig / "cards", out / "cards.csv")
    lap("rank")

    # rule diagnose (workflow/scripts/diagnose.py)
    if is_diagnosed(tests, scopes):
        scope = diagnosis_scope(scopes)
        done["diagnosis_scope"] = scope
        done["diagnosis"] = run_diagnosis(runs_dir, out / "fits" / scope, out / "diagnosis" / "findings.json",
                                          out / "residuals.nc", fig / "diagnosis", dataset=name,
                                          alpha=config["diagnosis"]["alpha"], ranking=out / "ranking.csv",
                                          extension_cards_dir=out / "diagnosis" / "simulation_cards",
                                          poisson_ratio=config["fem"]["poisson_ratio"])
        # the FEM replay is not run here: diagnosis.json says so (rule diagnosis without fix_simulation.json)
        attach_simulation(out / "diagnosis" / "findings.json", None, out / "diagnosis.json")
        named = [f["effect"] for f in done["diagnosis"].get("findings", []) if f.get("detected")]
        log.info("diagnosis of %s (baseline %s): %s", name, done["diagnosis"].get("model"),
                 ", ".join(named) or "no named cause")
        lap("diagnose")
    return done
