"""The bundled brain's material model (scope ``material``: one QLV model fitted to every shear test), fitted by the
pipeline's stage with the pipeline's configuration: its baseline's posterior (sampled with the configured
``posterior`` settings, as rule ``posterior`` does) has split R-hat < 1.01 and ESS > 400 for every parameter, and
credible intervals that agree with the lmfit standard errors wherever the posterior is near-Gaussian; and its
cross-test matrix (the model refitted without each test kind) names the test kind one QLV model cannot predict
from the others: the amplitude sweep, whose softening the data hold (``dataset.yaml``: amplitude_softening).

Near-Gaussian is judged from the samples themselves, independently of lmfit: in the sampled coordinate (log10 for
moduli and times) the skewness is below 0.5 in magnitude and the Laplace interval ``value +- 3 se`` lies inside the
uniform prior (a posterior cut by a bound, such as a Prony weight at 0, is not Gaussian and is not compared). There,
the 90 % credible width must be ``2 x 1.645`` lmfit standard errors within 20 %. Slow (full ingest, joint fits with
cross-tests, one posterior): about 2-3 min on one core.
"""
from __future__ import annotations

import importlib
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.stats import skew

from tissuemech import fitting as F
from tissuemech import uq
from tissuemech.curves import average_runs, write_averages
from tissuemech.io.ingest import ingest_dataset
from tissuemech.pipeline import load_runs
from tissuemech.ranking import scope_model
from tissuemech.scopes import MATERIAL_SCOPE, dataset_scopes
from tissuemech.stages import run_fit_scope

importlib.import_module("emcee")  # test extra: a missing emcee is an error, not a skip

ROOT = Path(__file__).resolve().parents[2]
BRAIN = ROOT / "raw" / "porcine_brain_thesis"
CONFIG = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("bundled_brain")]

#: the material scope's sampled model (rule posterior's wildcard)
MODELS = ("baseline",)


@pytest.fixture(scope="module")
def brain_posteriors(tmp_path_factory):
    """The pipeline's path on the full bundled brain: ingest, average, fit the material scope, sample its baseline."""
    out = tmp_path_factory.mktemp("brain_uq")
    report = ingest_dataset(BRAIN, out / "runs", out / "ingest_report.csv")
    assert (report["status"] == "ok").all()
    averages = average_runs(load_runs(out / "runs"), exclude_flagged=CONFIG["fit"]["exclude_flagged"])
    write_averages(averages, out / "averages.nc")
    spec = dataset_scopes(sorted(set(report["test"])), CONFIG["fit"])[MATERIAL_SCOPE]
    assert set(spec["tests"]) == {"constant_shear_rate", "stress_relaxation", "creep_recovery", "frequency_sweep",
                                  "amplitude_sweep"}
    fit = CONFIG["fit"]
    run_fit_scope(out / "averages.nc", MATERIAL_SCOPE, spec, target=fit["plate_target"], seed=fit["seed"],
                  multistart=fit["multistart"], fits_dir=out / "fits", cards_dir=out / "cards",
                  ranking_path=out / "ranking.csv", poisson_ratio=CONFIG["fem"]["poisson_ratio"])
    post = CONFIG["posterior"]
    tables = {}
    for model in MODELS:
        key = scope_model(out / "ranking.csv", model)
        tables[model] = uq.run_posterior(out / "averages.nc", out / "fits", MATERIAL_SCOPE, key, spec,
                                         out / f"{model}.nc", out / f"{model}.csv", walkers=post["walkers"],
                                         steps=post["steps"], burn=post["burn"], seed=post["seed"])
    return out, tables


def test_brain_material_model_and_cross_test_matrix(brain_posteriors):
    """Every shear test kind is held out once; the one the others cannot predict is the amplitude sweep (its
    Kraus softening is no QLV behaviour); every other kind is predicted with skill over its curves' means."""
    out, _ = brain_posteriors
    ranking = pd.read_csv(out / "ranking.csv")
    assert ranking["verdict"].iloc[0] == "supported" and ranking["recommended"].sum() == 1
    chosen = ranking[ranking["recommended"]].iloc[0]
    assert chosen["determined"] and chosen["misfit_noise_units"] <= 2.0
    cross = pd.read_csv(out / "ranking.cross_test.csv").set_index("held_out_test")
    assert set(cross.index) == {"constant_shear_rate", "stress_relaxation", "creep_recovery", "frequency_sweep",
                                "amplitude_sweep"}
    assert (cross["status"] == "ok").all() and (cross["model"] == chosen["model"]).all()
    assert cross.loc["amplitude_sweep", "skill"] < 0
    others = cross.drop(index="amplitude_sweep")
    assert (others["skill"] > 0.5).all(), others[["nrmse", "misfit_noise_units", "skill"]]
    card = pd.read_json(out / "cards" / f"{chosen['model']}.json", typ="series")
    assert card["fit_quality"]["recommended"] and len(card["cross_test"]) == 5


# The material baseline used to be qlv_rp3_prony5 with a 1 ms mode a decade below the resolved window, whose weight
# traded against C10 (rho = 0.999): split R-hat 1.02-1.08 at these settings, the tests below strict xfails. With the
# creep recoveries weighed in the fit (thinned by phase, tissuemech.fitting.thin) the data choose qlv_rp3_prony4
# without that mode, and the configured 8 walkers x 1400 steps mix.
@pytest.mark.parametrize("model", MODELS)
def test_brain_posteriors_converge(brain_posteriors, model):
    out, tables = brain_posteriors
    table = tables[model]
    record = F.FitRecord.from_netcdf(out / "fits" / f"{scope_model(out / 'ranking.csv', model)}.nc")
    assert set(table["parameter"]) == set(record.varying)
    assert (table["rhat"] < 1.01).all(), table[["parameter", "rhat"]]
    assert (table["ess"] > 400).all(), table[["parameter", "ess"]]


@pytest.mark.parametrize("model", MODELS)
def test_brain_credible_intervals_match_lmfit_where_near_gaussian(brain_posteriors, model):
    out, tables = brain_posteriors
    table = tables[model].set_index("parameter")
    post = uq.read_inference_group(out / f"{model}.nc", "posterior")
    compared = []
    for name, row in table.iterrows():
        x = np.asarray(post[name].values, float).ravel()
        log = row["sampled_as"] == "log10"
        x = np.log10(x) if log else x
        centre = np.log10(row["value"]) if log else row["value"]
        se = row["stderr"] / (np.log(10.0) * row["value"]) if log else row["stderr"]
        lo, hi = (float(v) for v in str(row["prior"]).removeprefix("uniform on [").rstrip("]").split(","))
        if abs(skew(x)) < 0.5 and lo < centre - 3 * se and centre + 3 * se < hi:
            compared.append(name)
            assert row["ci90_over_lmfit"] == pytest.approx(1.0, abs=0.2), (name, row.to_dict())
    # not vacuous: most parameters are near-Gaussian
    assert len(compared) >= len(table) - 2, (compared, list(table.index))


def test_brain_fits_csv_carries_the_intervals(brain_posteriors):
    """fits.csv built from the records and the posterior tables has each quantile next to its standard error."""
    from tissuemech.stages import write_fits_table

    out, tables = brain_posteriors
    fits = write_fits_table([out / "fits"], "porcine_brain_thesis", out / "fits.csv",
                            posterior_tables=[out / f"{m}.csv" for m in MODELS]).set_index("model")
    for model in MODELS:
        key = scope_model(out / "ranking.csv", model)
        for _, row in tables[model].iterrows():
            assert fits.loc[key, f"ci05_{row['parameter']}"] == pytest.approx(row["ci05"])
            assert fits.loc[key, f"ci95_{row['parameter']}"] == pytest.approx(row["ci95"])
        assert fits.loc[key, "posterior_rhat_max"] < 1.01
    # every candidate's record is a row; only the sampled one has intervals
    assert fits["posterior_rhat_max"].notna().sum() == len(MODELS)
    shutil.rmtree(out / "runs", ignore_errors=True)
