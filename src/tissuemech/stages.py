"""Pipeline stages above the science modules: what to fit on a dataset, and how fits become rankings and cards.

A *scope* is a set of test kinds fitted jointly with a list of candidate models:

* one scope per test kind present in the dataset that has models in ``config.fit.models`` (e.g. ``flow_curve``,
  ``stress_relaxation``, ``constant_shear_rate``);
* ``material`` when the dataset has any viscoelastic shear test: one QLV model fitted jointly to every ramp,
  relaxation, creep-recovery, frequency sweep and amplitude sweep through the plate, its relaxation times chosen
  from the window the tests resolve and its instantaneous law by AICc (:mod:`tissuemech.material`); refitted
  without each test kind to predict it (``cross_test.csv``);
* ``all_modes`` when the dataset has simple shear *and* uniaxial curves (e.g. Budday et al.): hyperelastic laws
  fitted to every mode jointly, cross-validated by leaving one mode out;
* ``mastercurve`` instead of ``frequency_sweep`` when the sweeps carry >= 2 temperatures: the sweeps shifted by
  the dataset's ``tts.nc`` (rule ``tts``) form one curve at the reference temperature
  (:func:`tissuemech.tts.mastercurve_curve`), fitted like any other curve; its cards carry the shift function
  (``time_temperature_shift``, Abaqus ``*TRS`` after ``*VISCOELASTIC``). One parameter set fitted to sweeps at
  20 temperatures as if they were one (the scope's former behaviour) describes no temperature.

Outputs of one scope (``run_fit_scope``): ``<fits_dir>/<model>.nc`` per fitted model, a ranking table, the
cross-validation records, the recommendation, and material cards of every converged model.

``spectra.run_spectrum`` writes ``spectrum.nc`` (the average job): the relaxation spectrum of every averaged
frequency sweep and stress relaxation, with the Kramers-Kronig discrepancy of each sweep.
"""
from __future__ import annotations

import json
import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr
from matplotlib.lines import Line2D

from . import cards as cards_mod
from .adequacy import ADEQUACY_FACTOR
from . import fitting as F
from . import ranking as R
from .canonical import read_netcdf, write_json, write_netcdf, write_text
from .curves import as_str, select_average
from .fem.experiments import flat_punch_indentation, rheometer_torsion
from .fem.materials import available_laws
from .fem.replay import FIX_SIMULATION_METRIC, ReplayCard, ReplaySettings, fix_simulation, replay
from .fem.tled import DynamicRelaxationError, ElementInversionError
from .material import MaterialFit, baseline_model, cross_test, fit_material, held_out_score
from .models.registry import get_model
from .plots import new_figure, plot_cross_test, plot_force_depth, plot_torque, save_figure
from .records import SIMULATION_CARDS_INDEX, MaterialCard
from .scopes import (ALL_MODES_SCOPE, MASTERCURVE_SCOPE, MATERIAL_LAWS, MATERIAL_SCOPE,  # noqa: F401 (re-exported)
                     MATERIAL_TESTS, dataset_scopes)
from .stats import nrmse
from .tts import mastercurve_curve, tts_card

logger = logging.getLogger(__name__)

#: points per curve kept for fitting (dense rheometer curves have autocorrelated residuals, science.md 4.2)
POINTS_PER_CURVE = 40


def _geometry_by_test(avg: xr.Dataset, name: str) -> dict[str, float]:
    out: dict[str, float] = {}
    if name not in avg:
        return out
    tests = [str(t) for t in avg["test"].values]
    values = np.asarray(avg[name].values, float)
    for test in set(tests):
        v = values[[t == test for t in tests]]
        v = v[np.isfinite(v)]
        if v.size:
            out[test] = float(np.median(v))
    return out


def scope_curves(averages: xr.Dataset, tests: Sequence[str], relaxation: str = "measured",
                 tts: xr.Dataset | None = None, amplitude: str = "lve",
                 n_points: int | None = None) -> list[F.Curve]:
    """Averaged curves of ``tests`` with their plate geometry, thinned to ``n_points`` points (default
    :data:`POINTS_PER_CURVE`).

    With ``tts`` (the dataset's ``tts.nc``; the ``mastercurve`` scope) the frequency sweeps, one per temperature
    and each thinned alone, are replaced by their mastercurve at the reference temperature, one curve
    (:func:`tissuemech.tts.mastercurve_curve`); sweeps without a finite shift are left out (logged).
    ``amplitude``: an amplitude sweep's linear part as an elastic curve (``"lve"``, the per-test scope) or every
    amplitude as measured (``"full"``, the material scope): :func:`tissuemech.fitting.curves_from_averages`.
    """
    curves = F.curves_from_averages(averages, radius_m=_geometry_by_test(averages, "radius_m"),
                                    gap_m=_geometry_by_test(averages, "gap_m"), relaxation=relaxation, tests=tests,
                                    amplitude=amplitude)
    curves = [F.thin(c, POINTS_PER_CURVE if n_points is None else n_points) for c in curves]
    if tts is None:
        return curves
    labels = as_str(averages["condition"].values)
    kinds = as_str(averages["test"].values)
    temps = np.asarray(averages["temperature_c"].values, float) if "temperature_c" in averages else \
        np.full(len(labels), np.nan)
    temp_of = {(str(k), str(c)): float(t) for k, c, t in zip(kinds, labels, temps)}
    sweeps = [c for c in curves if c.test == "frequency_sweep"]
    master, record = mastercurve_curve(sweeps, [temp_of.get((c.test, c.condition), np.nan) for c in sweeps], tts)
    if record["left_out"]:
        logger.warning("mastercurve: sweeps left out: %s", record["left_out"])
    return [c for c in curves if c.test != "frequency_sweep"] + [master]


def spec_curves(averages: xr.Dataset, spec: Mapping | Sequence[str], relaxation: str = "measured",
                tts: xr.Dataset | None = None) -> list[F.Curve]:
    """:func:`scope_curves` of a scope's spec (:func:`dataset_scopes`; a plain list of test kinds is a per-test
    spec): the material scope takes its amplitude sweeps whole and its ``points_per_curve``."""
    if not isinstance(spec, Mapping):
        spec = {"tests": list(spec)}
    if spec.get("material"):
        return scope_curves(averages, spec["tests"], relaxation, tts, amplitude="full",
                            n_points=spec.get("points_per_curve"))
    return scope_curves(averages, spec["tests"], relaxation, tts)


def scope_folds(scope: str, curves: Sequence[F.Curve]) -> list[R.Fold]:
    """Cross-validation designs of a scope (science.md section 4.3)."""
    folds: list[R.Fold] = []
    if scope == "constant_shear_rate":
        folds += R.leave_one_condition_out(curves, "constant_shear_rate")
    if scope == "stress_relaxation":
        folds += R.leave_one_condition_out(curves, "stress_relaxation")
    if scope == ALL_MODES_SCOPE:
        folds += R.train_on_tests(curves, ("simple_shear",), ("uniaxial",))
        folds += R.train_on_tests(curves, ("uniaxial",), ("simple_shear",))
    return folds


def run_fit_scope(averages_path, scope: str, spec: Mapping, target: str, seed: int, multistart: int,
                  fits_dir, cards_dir, ranking_path, poisson_ratio: float, dataset: str = "",
                  tts_path=None) -> pd.DataFrame:
    """Fit, cross-validate and rank every candidate of one scope; write fits, cards and the ranking table.

    Parameters
    ----------
    averages_path : ``results/<dataset>/averages.nc``
    scope, spec : scope name and ``{"tests": [...], "models": [...]}`` from :func:`dataset_scopes`
    target : parallel-plate target (``apparent_stress``, ``corrected_stress`` or ``torque``), recorded per fit
    seed, multistart : seeded random starts per model
    fits_dir, cards_dir : output folders (``<model>.nc``; ``<model>.json/.inp/.feb``)
    ranking_path : CSV of the ranking table (also holds the recommendation statement)
    tts_path : the dataset's ``tts.nc``; required by a ``mastercurve`` spec (``spec["mastercurve"]``), whose
        sweeps are fitted as one curve at the reference temperature and whose cards carry the shift function
        (``time_temperature_shift``: :func:`tissuemech.tts.tts_card`; Abaqus ``*TRS``)

    Returns
    -------
    The ranking table.
    """
    avg = read_netcdf(averages_path)
    tts_ds = None
    if spec.get("mastercurve"):
        if tts_path is None:
            raise ValueError(f"scope {scope!r} fits the TTS mastercurve and needs the dataset's tts.nc (tts_path)")
        tts_ds = read_netcdf(tts_path)
    curves = spec_curves(avg, spec, tts=tts_ds)
    shift_card = None
    if tts_ds is not None:
        shift_card = tts_card(tts_ds, dataset)
    fits_dir, cards_dir = Path(fits_dir), Path(cards_dir)
    fits_dir.mkdir(parents=True, exist_ok=True)
    cards_dir.mkdir(parents=True, exist_ok=True)
    if spec.get("material"):
        return run_material_scope(avg, curves, scope, spec, target, seed, fits_dir, cards_dir, ranking_path,
                                  poisson_ratio, dataset, shift_card)
    # a mastercurve spans far more decades of reduced frequency than the rheometer window the registry's bounds
    # suit: its candidates' time and modulus bounds are widened to the data (fitting.oscillation_window_bounds)
    candidates = [R.Candidate(key, R.RegistryFactory(key),
                              bounds=F.oscillation_window_bounds(get_model(key), curves) if tts_ds is not None else {})
                  for key in spec["models"]]
    failures: dict[str, str] = {}
    if curves:
        table, fits, cv, rec = R.rank_scope(candidates, curves, target, scope, folds=scope_folds(scope, curves),
                                            dataset=dataset, n_random=multistart, seed=seed, failures=failures)
    else:
        table, fits, cv, rec = pd.DataFrame(), {}, pd.DataFrame(), {"statement": "no curves in this scope"}
    cross = pd.DataFrame(columns=CROSS_TEST_COLUMNS)
    if rec.get("recommended"):
        # the scope's choice, fitted to its own test kind, predicting every other shear test of the dataset
        key = rec["recommended"]
        others = [t for t in MATERIAL_TESTS if t in set(as_str(avg["test"].values)) and t not in spec["tests"]]
        cross = predict_other_tests(get_model(key), fits[key], scope_curves(avg, others, amplitude="full"), target,
                                    scope)
    write_scope_outputs(fits, table, rec, cv, cross, failures, scope, fits_dir, cards_dir, ranking_path,
                        poisson_ratio, dataset, shift_card, {k: get_model(k) for k in fits})
    return table


#: columns of ``ranking/<scope>.cross_test.csv`` and of the dataset's ``cross_test.csv``
CROSS_TEST_COLUMNS = ("scope", "model", "held_out_test", "nrmse", "n_points", "misfit_noise_units", "skill",
                      "fitted_to", "status")


def predict_other_tests(model, result: F.FitResult, curves: Sequence[F.Curve], target: str, scope: str) -> pd.DataFrame:
    """How a per-test scope's fit predicts the dataset's other test kinds (``curves``), one row per kind:
    :data:`CROSS_TEST_COLUMNS` (held-out NRMSE of :func:`tissuemech.fitting.evaluate`, misfit in noise units and
    skill of :func:`tissuemech.adequacy.misfit_in_noise_units`; ``status`` says why a kind was not scored, e.g. a
    model that cannot describe it)."""
    rows = []
    fitted_to = " ".join(sorted({str(s.get("test")) for s in result.selection}))
    for kind in sorted({c.test for c in curves}):
        held = [c for c in curves if c.test == kind]
        row = {"scope": scope, "model": result.model_key, "held_out_test": kind, "nrmse": np.nan,
               "n_points": int(sum(c.n_points for c in held)), "misfit_noise_units": np.nan, "skill": np.nan,
               "fitted_to": fitted_to, "status": "ok"}
        if not all(F.describes(model, c.response) for c in held):
            row["status"] = f"not scored: {result.model_key} cannot describe {kind}"
            rows.append(row)
            continue
        try:
            row.update(held_out_score(model, result.params, held, target))
        except (ValueError, RuntimeError, FloatingPointError) as exc:
            row["status"] = f"failed: {exc}"
        rows.append(row)
    return pd.DataFrame(rows, columns=list(CROSS_TEST_COLUMNS))


def write_scope_outputs(fits: Mapping, table: pd.DataFrame, rec: Mapping, cv: pd.DataFrame, cross: pd.DataFrame,
                        failures: dict, scope: str, fits_dir: Path, cards_dir: Path, ranking_path, poisson_ratio: float,
                        dataset: str, shift_card, models: Mapping) -> None:
    """Fit records, cards, the ranking table, its CV and cross-test tables and the recommendation of one scope.

    A card is written for every fit that may stand for the material: recommendable (converged, with a covariance,
    no parameter at a bound) and better than the curves' means (``skill`` > 0); never for one that predicts worse
    than a flat line. Each card states its fit quality (``fit_quality``: misfit in noise units, adequacy,
    determinacy, skill, the scope's verdict) and, for the recommended one, how it predicts the other test kinds
    (``cross_test``).
    """
    quality = table.set_index("model") if not table.empty and "model" in table else pd.DataFrame()
    for key, result in fits.items():
        F.write_fit_netcdf(result, fits_dir / f"{key}.nc")
        row = quality.loc[key] if key in quality.index else None
        if row is None or not bool(row.get("recommendable", False)) or not float(row.get("skill", np.nan)) > 0:
            continue
        try:
            card = cards_mod.make_card(result, models[key], poisson_ratio=poisson_ratio, dataset=dataset,
                                       fit_file=str(fits_dir / f"{key}.nc"))
        except (ValueError, KeyError, RuntimeError) as exc:
            failures[f"card:{key}"] = str(exc)
            continue
        if shift_card is not None:
            card["time_temperature_shift"] = shift_card
        card["fit_quality"] = {
            "misfit_noise_units": float(row["misfit_noise_units"]), "adequate": bool(row["adequate"]),
            "determined": bool(row["determined"]), "undetermined": str(row.get("undetermined") or ""),
            "skill": float(row["skill"]), "recommended": key == rec.get("recommended"),
            "scope_verdict": str(rec.get("verdict", "")), "adequacy_factor": ADEQUACY_FACTOR}
        if key == rec.get("recommended") and not cross.empty:
            card["cross_test"] = cross.to_dict("records")
        cards_mod.write_card_files(card, cards_dir, stem=key)
    if not table.empty:
        table["failures"] = json.dumps(failures) if failures else ""
    else:
        table = pd.DataFrame([{"dataset": dataset, "scope": scope, "model": None, "recommended": False,
                               "verdict": rec.get("verdict", "no_model_supported"),
                               "verdict_reason": rec.get("reason", rec.get("statement", "")),
                               "recommendation": rec.get("statement", ""), "failures": json.dumps(failures)}])
    ranking_path = Path(ranking_path)
    write_text(table.to_csv(index=False), ranking_path)
    write_text(cv.to_csv(index=False) if not cv.empty else "fold,design,model,status\n",
               ranking_path.with_suffix(".cv.csv"))
    write_text(cross.to_csv(index=False), ranking_path.with_suffix(".cross_test.csv"))
    write_json(dict(rec), ranking_path.with_suffix(".recommendation.json"), newline=False)


def run_material_scope(avg: xr.Dataset, curves: Sequence[F.Curve], scope: str, spec: Mapping, target: str, seed: int,
                       fits_dir: Path, cards_dir: Path, ranking_path, poisson_ratio: float, dataset: str,
                       shift_card) -> pd.DataFrame:
    """The ``material`` scope of :func:`run_fit_scope`: :func:`tissuemech.material.fit_material` on every shear
    test, the cross-test refits of its baseline (:func:`tissuemech.material.cross_test`), and the scope's files."""
    if curves:
        mf = fit_material(curves, target, laws=spec.get("laws") or MATERIAL_LAWS, seed=seed, scope=scope,
                          dataset=dataset)
    else:
        mf = MaterialFit(pd.DataFrame(), {}, {}, {"recommended": None, "verdict": "no_model_supported",
                                                   "reason": "no curves in this scope",
                                                   "statement": "no_model_supported: no curves in this scope"}, {}, {})
    baseline = baseline_model(mf.table)
    cross = pd.DataFrame(columns=CROSS_TEST_COLUMNS)
    if baseline is not None:
        cross = cross_test(mf.factories[baseline], mf.fits[baseline], curves, target, seed=seed)
        cross.insert(0, "scope", scope)
        cross = cross.rename(columns={"train_tests": "fitted_to"})[list(CROSS_TEST_COLUMNS)]
    rec = {**mf.recommendation, "baseline": baseline,
           "relaxation_times_s": [float(t) for t in mf.spectrum.get("taus_s", [])],
           "window": {k: v for k, v in mf.spectrum.get("window", {}).items()},
           "equilibrium_share": mf.spectrum.get("equilibrium_share"), "spectrum_method": mf.spectrum.get("method")}
    write_scope_outputs(mf.fits, mf.table, rec, pd.DataFrame(), cross, dict(mf.failures), scope, fits_dir,
                        cards_dir, ranking_path, poisson_ratio, dataset, shift_card,
                        {k: f() for k, f in mf.factories.items()})
    return mf.table


def collect_scopes(ranking_paths: Sequence, ranking_out, figure_out=None) -> pd.DataFrame:
    """Merge the per-scope rankings into ``ranking.csv`` (and draw the ranking figure). The tidy ``fits.csv`` is
    :func:`write_fits_table`'s (the same rank job, after the dataset's posteriors, so that it carries their
    credible intervals)."""
    tables = [pd.read_csv(p) for p in ranking_paths if Path(p).stat().st_size > 0]
    ranking = pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()
    if not ranking.empty:
        ranking["recommended"] = R.recommended_mask(ranking)
    write_text(ranking.to_csv(index=False), ranking_out)
    if figure_out is not None and not ranking.empty and "model" in ranking:
        shown = ranking.dropna(subset=["model"]).copy()
        shown["model"] = shown["scope"].astype(str) + ": " + shown["model"].astype(str)
        R.plot_ranking(shown, figure_out)
    return ranking


def collect_cross_tests(ranking_paths: Sequence, dataset: str, out, figure_out=None) -> pd.DataFrame:
    """The dataset's ``cross_test.csv``: every scope's ``ranking/<scope>.cross_test.csv`` (the material model refitted
    without each test kind, each per-test scope's recommended fit predicting the other kinds;
    :data:`CROSS_TEST_COLUMNS` and ``dataset``), and its figure (:func:`tissuemech.plots.plot_cross_test`)."""
    parts = []
    for p in ranking_paths:
        path = Path(p).with_suffix(".cross_test.csv")
        if path.is_file() and path.stat().st_size > 0:
            t = pd.read_csv(path)
            if not t.empty:
                parts.append(t)
    table = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=list(CROSS_TEST_COLUMNS))
    table.insert(0, "dataset", dataset)
    write_text(table.to_csv(index=False), out)
    if figure_out is not None:
        plot_cross_test(table, figure_out, ADEQUACY_FACTOR)
    return table


def write_fits_table(fits_dirs: Sequence, dataset: str, out, posterior_tables: Sequence = ()) -> pd.DataFrame:
    """The tidy ``fits.csv``: one row per fit record ``<fits_dir>/<model>.nc``
    (:func:`tissuemech.fitting.fits_csv_row`), with the credible intervals of the records that have a posterior.

    Parameters
    ----------
    fits_dirs : the scopes' fit-record folders.
    dataset : dataset name (column ``dataset``).
    out : the CSV to write.
    posterior_tables : credible-interval tables ``posterior/<scope>/<model>.csv`` (``tissuemech.uq.run_posterior``;
        columns ``scope``, ``model``, ``parameter``, ``ci05`` ...); an empty table (a model without a record) adds
        nothing. A record is matched by its scope and model.

    Returns
    -------
    The table written.
    """
    intervals = [pd.read_csv(p) for p in posterior_tables if Path(p).stat().st_size > 0]
    intervals = [t for t in intervals if not t.empty]
    by_fit = {}
    if intervals:
        for (scope, model), rows in pd.concat(intervals, ignore_index=True).groupby(["scope", "model"]):
            by_fit[(str(scope), str(model))] = rows
    rows = []
    for folder in fits_dirs:
        for path in sorted(Path(folder).glob("*.nc")):
            record = F.FitRecord.from_netcdf(path)
            rows.append(F.fits_csv_row(record, dataset, file=str(path),
                                       posterior=by_fit.get((str(record.scope), str(record.model_key)))))
    table = pd.DataFrame(rows)
    write_text(table.to_csv(index=False), out)
    return table


# ------------------------------------------------------------------------------------------------------
# FEM experiments driven by the material cards
# ------------------------------------------------------------------------------------------------------
#: scopes whose cards describe the shear response of a parallel-plate sample, best first
TORSION_SCOPES = (MATERIAL_SCOPE, "constant_shear_rate", "stress_relaxation", "amplitude_sweep", ALL_MODES_SCOPE,
                  "simple_shear")


def select_cards(ranking_csv, cards_root, scopes: Sequence[str] = TORSION_SCOPES) -> list[Path]:
    """Card JSON files of the recommended model (``ranking.csv`` column ``recommended``) of each of the given
    scopes, in the order of ``scopes``, where the FEM can run it.

    A card is runnable when it names an elastic law the TLED materials know (``fem.materials.available_laws``).
    A scope without a recommendation, without the card or with a law the FEM lacks contributes no card (logged):
    the FEM never falls back to another model than the ranking's choice.
    """
    chosen_models = R.recommended_models(ranking_csv)
    chosen: list[Path] = []
    for scope in scopes:
        model = chosen_models.get(scope)
        if model is None:
            continue
        path = Path(cards_root) / scope / f"{model}.json"
        problem = fem_card_problem(path)
        if problem:
            logger.warning("select_cards: %s/%s (the recommended model): %s", scope, model, problem)
            continue
        chosen.append(path)
    return chosen


def fem_card_problem(path: Path) -> str:
    """Why the FEM cannot run the card file ``path`` (no file, or a law the TLED materials lack,
    ``fem.materials.available_laws``); empty when it can."""
    if not Path(path).is_file():
        return f"no card {path}"
    law = MaterialCard.from_json(path).fem_law
    return "" if law in available_laws() else f"the FEM has no law {law!r}"


def card_for_fem(path: Path) -> dict:
    """The card file as the FEM takes it (:meth:`tissuemech.records.MaterialCard.for_fem`)."""
    return MaterialCard.from_json(path).for_fem()


def run_fem_torsion(card_paths: Sequence, averages_path, out_nc, out_csv, figure_path, element_size_m: float = 2.5e-3,
                    n_points: int = 12, rates: Sequence[float] | None = None, vtu_dir=None,
                    n_threads: int = 1) -> pd.DataFrame:
    """Twist the rheometer sample as in the dataset's constant-shear-rate tests, for every card
    (``n_threads`` numba threads per solve: the job's Snakemake threads).

    The simulated torque of each card is compared with the measured mean torque of the same rate
    (``shear_stress * pi R^3 / 2`` of the averaged apparent rim stress); the error table reports the
    normalised RMS error and the error at the largest strain, per card and rate.
    """
    avg = read_netcdf(averages_path)
    tests = [str(t) for t in avg["test"].values]
    idx = [i for i, t in enumerate(tests) if t == "constant_shear_rate"]
    all_rates = sorted({float(avg["shear_rate_1_per_s"].values[i]) for i in idx})
    if rates is None:
        rates = [all_rates[0], all_rates[-1]] if len(all_rates) > 1 else all_rates
    # geometry as the runs state it (samples.csv > dataset.yaml > export): never a default plate
    radius = _geometry_by_test(avg, "radius_m").get("constant_shear_rate")
    gap = _geometry_by_test(avg, "gap_m").get("constant_shear_rate")
    series, reference, rows, measured = {}, {}, [], {}
    missing = [what for what, v in (("no plate radius", radius), ("no gap", gap)) if v is None]
    if missing:
        reason = (f"skipped: {' and '.join(missing)} for the constant_shear_rate runs (stated by neither samples.csv, "
                  "dataset.yaml nor the export); the torsion comparison needs the plate geometry")
        logger.warning("torsion: %s", reason)
        rows = [{"card": f"{Path(p).parent.name}/{Path(p).stem}", "rate_1_s": rate, "nrmse": float("nan"),
                 "rel_error_at_max_strain": float("nan"), "max_strain": float("nan"),
                 "normal_force_at_max_strain_n": float("nan"), "status": reason}
                for p in card_paths for rate in rates]
        rates = []

    for rate in rates:
        i = next(i for i in idx if math.isclose(float(avg["shear_rate_1_per_s"].values[i]), rate))
        one = select_average(avg, "constant_shear_rate", str(avg["condition"].values[i]))
        strain = np.asarray(one[next(iter(one.coords))].values, float)
        stress = np.asarray(one["shear_stress_mean"].values, float)
        ok = np.isfinite(strain) & np.isfinite(stress) & (strain > 0)
        strain, stress = strain[ok], stress[ok]
        torque_measured = stress * math.pi * radius**3 / 2.0
        gamma_sim = np.linspace(strain.max() / n_points, strain.max(), n_points)
        reference[f"measured {rate:g} 1/s"] = (gamma_sim, np.interp(gamma_sim, strain, torque_measured))
        for path in card_paths:
            card = card_for_fem(Path(path))
            label = f"{Path(path).parent.name}/{Path(path).stem} {rate:g} 1/s"
            vtu = None if vtu_dir is None else Path(vtu_dir) / f"{Path(path).parent.name}__{Path(path).stem}__{rate:g}.vtu"
            if vtu is not None:
                vtu.parent.mkdir(parents=True, exist_ok=True)
            meas = np.interp(gamma_sim, strain, torque_measured)
            card_name = f"{Path(path).parent.name}/{Path(path).stem}"
            try:
                ds = rheometer_torsion(card, gamma_sim / rate, gamma_sim, radius_m=radius, gap_m=gap,
                                       element_size_m=element_size_m, n_threads=n_threads, vtu_path=vtu)
            except (ElementInversionError, DynamicRelaxationError) as err:
                logger.warning("torsion %s: %s", label, err)
                rows.append({"card": card_name, "rate_1_s": rate, "nrmse": float("nan"),
                             "rel_error_at_max_strain": float("nan"), "max_strain": float(gamma_sim[-1]),
                             "normal_force_at_max_strain_n": float("nan"), "status": f"failed: {err}"})
                continue
            sim = np.asarray(ds["torque"].values, float)
            series[label] = (gamma_sim, sim)
            measured[label] = meas
            rows.append({"card": card_name, "rate_1_s": rate,
                         "nrmse": nrmse(meas, sim),
                         "rel_error_at_max_strain": float((sim[-1] - meas[-1]) / meas[-1]),
                         "max_strain": float(gamma_sim[-1]),
                         "normal_force_at_max_strain_n": float(ds["normal_force"].values[-1]), "status": "ok"})
    table = pd.DataFrame(rows)
    write_text(table.to_csv(index=False), out_csv)
    combined = xr.Dataset(
        {"rim_strain": (("case", "point"), np.array([series[k][0] for k in series])),
         "torque_fem": (("case", "point"), np.array([series[k][1] for k in series]), {"units": "N m"}),
         "torque_measured": (("case", "point"), np.array([measured[k] for k in series]), {"units": "N m"})},
        coords={"case": list(series)}) if series else xr.Dataset()

    write_netcdf(combined, out_nc)
    plot_torque(series, figure_path, xlabel="rim strain [-]", reference=reference,
                title="TLED rheometer torsion vs measured torque")
    return table


#: scopes whose cards the FEM replay of the measured tests runs, best first (:func:`replay_cards`): the first with a
#: card the FEM can run supplies the baseline card and the extension cards
REPLAY_SCOPES = (MATERIAL_SCOPE, "stress_relaxation", "creep_recovery", "frequency_sweep", MASTERCURVE_SCOPE,
                 "amplitude_sweep", "constant_shear_rate")


def replay_cards(ranking_csv, cards_root, diagnosis_json=None, extension_cards_dir=None,
                 scopes: Sequence[str] = REPLAY_SCOPES) -> list[ReplayCard]:
    """The cards the FEM replay runs: the baseline card first, then the cards of each extension the diagnosis names.

    Baseline: in the first of ``scopes`` that has one the FEM can run, the card of the diagnosis's baseline model
    (``diagnosis.json`` ``model``), else the scope's baseline (the material scope's ``baseline`` column) or
    recommended card (``ranking.csv``). Extensions: the simulation cards of the diagnosis
    (``extension_cards_dir``, :mod:`tissuemech.diagnosis.simulation_cards`): per named cause its extension fitted
    to every run (role: the cause, replayed on every test) and, per fold, the baseline and the extension fitted
    without the fold's held-out curves (roles ``<cause>:baseline`` and the cause, replayed on those curves only).
    A card the FEM cannot run is kept with the reason (its rows say ``not replayed``). Without any runnable baseline
    card the list is empty (logged).
    """
    recommended = R.recommended_models(ranking_csv)
    baselines = R.recommended_models(ranking_csv, column="baseline")
    diagnosis = json.loads(Path(diagnosis_json).read_text()) if diagnosis_json else {}
    for scope in scopes:
        for model in dict.fromkeys(m for m in (diagnosis.get("model"), baselines.get(scope), recommended.get(scope))
                                   if m):
            path = Path(cards_root) / scope / f"{model}.json"
            problem = fem_card_problem(path)
            if problem:
                logger.info("replay_cards: %s/%s: %s", scope, model, problem)
                continue
            return [ReplayCard(f"{scope}/{model}", "baseline", MaterialCard.from_json(path))] + \
                extension_replay_cards(extension_cards_dir)
    logger.warning("replay_cards: no card the FEM can run in the scopes %s", list(scopes))
    return []


def extension_replay_cards(extension_cards_dir) -> list[ReplayCard]:
    """The replay cards of the diagnosis's simulation cards (``index.json`` of
    :func:`tissuemech.diagnosis.simulation_cards.write_simulation_cards`); none without the folder or its index."""
    index_path = Path(extension_cards_dir) / SIMULATION_CARDS_INDEX if extension_cards_dir else None
    if index_path is None or not index_path.is_file():
        return []
    index = json.loads(index_path.read_text())
    folder = index_path.parent
    out = []
    for cause, entry in (index.get("causes") or {}).items():
        if entry.get("card"):
            path = folder / entry["card"]
            out.append(ReplayCard(f"extension/{path.stem}", cause, MaterialCard.from_json(path), fem_card_problem(path)))
        for fold in entry.get("folds", []):
            only = frozenset(fold.get("held_out", []))
            for file, role in ((fold["baseline"], f"{cause}:baseline"), (fold["extension"], cause)):
                path = folder / file
                out.append(ReplayCard(f"extension/{path.name.removesuffix('.json')}", role,
                                      MaterialCard.from_json(path), fem_card_problem(path), only=only))
    return out


def simulation_fixes(table: pd.DataFrame, extension_cards_dir) -> dict:
    """``fix.simulation`` of every named cause with simulation cards: per fold the replay's held-out NRMSE of the
    fold's baseline card and of its extension card (:func:`tissuemech.fem.replay.fix_simulation`), averaged over the
    folds (``before``, ``after``, ``gain``, ``held_out_tests``, ``folds``)."""
    index_path = Path(extension_cards_dir) / SIMULATION_CARDS_INDEX if extension_cards_dir else None
    if index_path is None or not index_path.is_file():
        return {}
    out = {}
    for cause, entry in (json.loads(index_path.read_text()).get("causes") or {}).items():
        folds = []
        for fold in entry.get("folds", []):
            rec = fix_simulation(table, cause, f"extension/{fold['extension'].removesuffix('.json')}",
                                 baseline_card=f"extension/{fold['baseline'].removesuffix('.json')}")
            folds.append({"label": fold["label"], **rec})
        scored = [f for f in folds if np.isfinite(f["before"]) and np.isfinite(f["after"])]
        before = float(np.mean([f["before"] for f in scored])) if scored else float("nan")
        after = float(np.mean([f["after"] for f in scored])) if scored else float("nan")
        out[cause] = {"metric": FIX_SIMULATION_METRIC, "before": before, "after": after,
                      "gain": (before - after) / before if before > 0 else float("nan"),
                      "held_out_tests": sorted({t for f in scored for t in f["held_out_tests"]}),
                      "extension_card": entry.get("card"), "folds": folds}
        if not scored:
            out[cause]["note"] = "no fold's held-out curve was replayed by both of its cards"
    return out


#: what the replay figure draws per test kind: (x label, y label, log x, log y)
REPLAY_AXES = {
    "constant_shear_rate": ("rim strain [-]", "apparent rim stress [Pa]", False, False),
    "stress_relaxation": ("time [s]", "apparent rim stress [Pa]", True, False),
    "creep_recovery": ("time [s]", "rim strain [-]", True, False),
    "frequency_sweep": ("frequency [Hz]", "G' (o, thick lines) and G'' (^, thin lines) [Pa]", True, True),
    "amplitude_sweep": ("strain amplitude [-]", "G' (o, thick lines) and G'' (^, thin lines) [Pa]", True, True),
}


def figure_replay(points: pd.DataFrame, table: pd.DataFrame):
    """Measured averages (markers) and the simulation of each card (lines: baseline solid, extensions dashed), one
    panel per replayed test kind, one colour per condition; each card's NRMSE per condition in the legend."""
    kinds = [k for k in REPLAY_AXES if k in set(points["test"])]
    fig, axes = new_figure(ncols=max(1, min(3, len(kinds))), nrows=max(1, -(-len(kinds) // 3)), width=4.6, height=3.6)
    roles = list(dict.fromkeys(table.loc[table["status"] == "ok", "role"]))
    styles = {r: ("-" if r == "baseline" else ("--", "-.")[i % 2]) for i, r in enumerate(roles)}
    for ax, kind in zip(axes, kinds):
        xlabel, ylabel, logx, logy = REPLAY_AXES[kind]
        sel = points[points["test"] == kind]
        handles = []
        for ci, cond in enumerate(dict.fromkeys(sel["condition"])):
            colour = f"C{ci % 10}"
            one = sel[sel["condition"] == cond]
            for obs, marker, width in (("storage_modulus", "o", 1.4), ("loss_modulus", "^", 0.7),
                                       ("shear_stress", "o", 1.2), ("shear_strain", "o", 1.2)):
                o = one[one["observable"] == obs]
                if o.empty:
                    continue
                first = o[o["card"] == o["card"].iloc[0]]
                ax.plot(first["x"], first["measured"], marker, color=colour, ms=4, mfc="none", ls="none")
                for _, c in o.groupby("card", sort=False):
                    ax.plot(c["x"], c["simulated"], color=colour, lw=width, ls=styles.get(c["role"].iloc[0], "-"))
            scores = table[(table["test"] == kind) & (table["condition"] == cond) & (table["status"] == "ok")]
            text = ", ".join(f"{r.role} {r.nrmse:.2f}" for r in scores.itertuples())
            handles.append(Line2D([], [], color=colour, marker="o", mfc="none", label=f"{cond} (NRMSE {text})"))
        handles += [Line2D([], [], color="k", ls=styles[r], label=f"simulated: {r}") for r in roles]
        handles.append(Line2D([], [], color="k", marker="o", mfc="none", ls="none", label="measured mean"))
        ax.set(xlabel=xlabel, ylabel=ylabel, title=kind.replace("_", " "))
        if logx:
            ax.set_xscale("log")
        if logy:
            ax.set_yscale("log")
        ax.legend(handles=handles, fontsize=6)
    for ax in axes[len(kinds):]:
        ax.set_axis_off()
    if not kinds:
        axes[0].text(0.5, 0.5, "no test was replayed (see replay.csv)", ha="center", va="center")
        axes[0].set_axis_off()
    return fig


def read_replay_table(path) -> pd.DataFrame:
    """A ``replay.csv`` as :func:`tissuemech.fem.replay.replay` returned it: text columns as text (an empty card
    name stays ``""``), ``held_out`` as a nullable boolean."""
    table = pd.read_csv(path)
    for name in ("test", "condition", "card", "role", "status"):
        table[name] = table[name].fillna("").astype(str)
    table["held_out"] = table["held_out"].astype("boolean")
    return table


def run_fem_replay(cards: Sequence[ReplayCard], averages_path, out_csv, points_csv, figure_path=None,
                   element_size_m: float = float("nan"), n_threads: int = 1, extension_cards_dir=None,
                   fix_json=None, replayed=None) -> pd.DataFrame:
    """The FEM replay of a dataset's measured tests (:func:`tissuemech.fem.replay.replay`) with ``cards``
    (:func:`replay_cards`): ``replay.csv`` (one row per test x condition x card), the measured and simulated points
    (``points_csv``) and, with ``figure_path``, their figure. Without any card the table still lists every test,
    ``not replayed``. With ``fix_json``: the ``fix.simulation`` of every named cause whose simulation cards were
    replayed (:func:`simulation_fixes`), for the final ``diagnosis.json``.

    ``replayed``: ``(table_csv, points_csv)`` of a replay already run (rule ``fem_replay_baseline``: the baseline
    card, which needs no diagnosis, runs beside the diagnosis); its rows are kept, and a card it already ran (same
    name) is not run again.
    """
    settings = ReplaySettings(element_size_m=float(element_size_m), n_threads=n_threads)

    def progress(row):
        logger.info("replay %s %s %s: %s, NRMSE %.4g, %d elements, %.2f s", row["card"], row["test"],
                    row["condition"], row["status"], row["nrmse"], row["n_elements"], row["wall_s"])

    done_table = done_points = None
    if replayed is not None:
        done_table = read_replay_table(replayed[0])
        done_points = pd.read_csv(replayed[1])
        done = set(done_table["card"].dropna().astype(str))
        cards = [c for c in cards if c.name not in done]
    # without a card the FEM can run, every test still gets its row, saying so
    elif not cards:
        cards = [ReplayCard("", "baseline", None, "no card the FEM can run in the replay scopes "
                                                  f"{', '.join(REPLAY_SCOPES)}")]
    table, points = replay(read_netcdf(averages_path), cards, settings, on_row=progress)
    if done_table is not None:
        table = pd.concat([done_table, table], ignore_index=True) if len(table) else done_table
        table["held_out"] = table["held_out"].astype("boolean")
        points = pd.concat([done_points, points], ignore_index=True) if len(points) else done_points
    write_text(table.to_csv(index=False), out_csv)
    write_text(points.to_csv(index=False), points_csv)
    if figure_path is not None:
        # the baseline and the full-data extension cards over every test (fold cards are scores, not curves)
        full = ~table["role"].str.endswith(":baseline") & ~table["card"].str.contains(r"\.extension$", regex=True)
        save_figure(figure_replay(points[points["card"].isin(set(table.loc[full, "card"]))], table[full]),
                    figure_path)
    if fix_json is not None:
        write_json(simulation_fixes(table, extension_cards_dir), fix_json)
    return table


def run_fem_indentation(card_paths: Sequence, out_nc, figure_path, punch_diameters_m=(8e-3, 15e-3),
                        max_depth_m: float = 1.5e-3, speed_m_s: float = 1e-4, element_size_m: float = 1e-3,
                        vtu_dir=None, n_threads: int = 1) -> xr.Dataset:
    """Flat-punch indentation (8 and 15 mm punches, constant slow speed) of a tissue sample per card
    (``n_threads`` numba threads per solve)."""
    series, parts, status = {}, [], {}
    for path in card_paths:
        card = card_for_fem(Path(path))
        for d in punch_diameters_m:
            label = f"{Path(path).parent.name}/{Path(path).stem} {d * 1e3:g} mm"
            vtu = None if vtu_dir is None else Path(vtu_dir) / f"{Path(path).parent.name}__{Path(path).stem}__{d * 1e3:g}mm.vtu"
            if vtu is not None:
                vtu.parent.mkdir(parents=True, exist_ok=True)
            n_increments = 10
            try:
                ds = flat_punch_indentation(card, d, max_depth_m, speed_m_s, element_size_m=min(element_size_m, d / 4),
                                            n_increments=n_increments, n_threads=n_threads, vtu_path=vtu)
            except (ElementInversionError, DynamicRelaxationError) as err:
                # a card fitted in one mode can be unstable in another (e.g. a shear-only polynomial in
                # compression): the failure is a result to report for that card, not a reason to lose the others
                depth = np.linspace(0.0, max_depth_m, n_increments + 1)[1:]
                failed_at = speed_m_s * getattr(err, "time_s", float("nan"))
                series[label] = (depth, np.full(depth.size, np.nan))
                status[label] = f"failed at depth {failed_at * 1e3:.3g} mm: {err}"
                logger.warning("indentation %s: %s", label, status[label])
                continue
            series[label] = (np.asarray(ds["displacement"].values), np.asarray(ds["force"].values))
            status[label] = "ok"
            parts.append((label, ds))
    out = xr.Dataset(
        {"depth": (("case", "point"), np.array([s[0] for s in series.values()]), {"units": "m"}),
         "force": (("case", "point"), np.array([s[1] for s in series.values()]), {"units": "N"}),
         "status": ("case", np.array([status[k] for k in series], dtype=str))},
        coords={"case": list(series)}) if series else xr.Dataset()

    write_netcdf(out, out_nc)
    plot_force_depth(series, figure_path, title="TLED flat-punch indentation per material card")
    return out


# ------------------------------------------------------------------------------------------------
# relaxation spectra of the averaged curves (issue 15 item 3): results/<ds>/spectrum.nc
# ------------------------------------------------------------------------------------------------


