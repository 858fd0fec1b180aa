"""Posteriors of fit records (tissuemech.uq): on a near-Gaussian synthetic fit with known truth the 5-95 % credible
interval agrees with the lmfit standard error within 15 %, the InferenceData file reads back, the predictive band
enters the fit figure and the intervals enter fits.csv, and a model without a fit record says so."""
from __future__ import annotations

import importlib

import numpy as np
import pandas as pd
import pytest

from tissuemech import fitting as F
from tissuemech import uq
from tissuemech.models.registry import get_model
from tissuemech.stats import mixed_effects

importlib.import_module("emcee")  # test extra: a missing emcee is an error, not a skip

TRUTH = {"C10": 150.0, "C20": 100.0}


@pytest.fixture(scope="module")
def synthetic_fit():
    """Reduced-polynomial-2 simple shear with 2 % Gaussian noise (known truth), fitted by lmfit: a near-Gaussian
    posterior."""
    model = get_model("reduced_polynomial2")
    g = np.linspace(0.01, 0.8, 60)
    clean = model.elastic_shear_stress(TRUTH, g)
    rng = np.random.default_rng(11)
    y = clean * (1.0 + 0.02 * rng.standard_normal(g.size))
    curve = F.Curve(test="simple_shear", condition="shear", response="elastic_shear", inputs={"shear_strain": g},
                    observed={"shear_stress": y})
    problem = F.FitProblem(model, [curve], target="none", model_key="reduced_polynomial2", scope="simple_shear")
    result = F.fit(problem, starts=[TRUTH], n_random=0)
    return problem, F.FitRecord.from_result(result)


def test_credible_intervals_match_lmfit_standard_errors(synthetic_fit):
    problem, record = synthetic_fit
    post, info = uq.sample_record_posterior(problem, record, walkers=8, steps=1500, burn=200, seed=3)
    table = uq.posterior_table(record, post, scope="simple_shear").set_index("parameter")
    assert info["laplace_start"] and set(table.index) == set(record.varying)
    for name in record.varying:
        row = table.loc[name]
        # near-Gaussian posterior: 90 % credible width = 2 x 1.645 lmfit standard errors within 15 %
        assert row["ci90_over_lmfit"] == pytest.approx(1.0, abs=0.15), row
        assert abs(row["post_mean"] - TRUTH[name]) < 3 * row["stderr"]  # the truth is where the posterior is
        assert row["ci05"] < row["value"] < row["ci95"]
        assert row["rhat"] < 1.01 and row["ess"] > 400
    assert post.warnings == []


def test_inference_data_round_trip(synthetic_fit, tmp_path):
    problem, record = synthetic_fit
    post, info = uq.sample_record_posterior(problem, record, walkers=4, steps=100, burn=40, seed=1)
    path = uq.write_inference_data(uq.inference_data(record, post, info, dataset="d", scope="s"), tmp_path / "p.nc")
    g = uq.read_inference_group(path, "posterior")
    assert g.sizes == {"chain": 4, "draw": 100} and set(g.data_vars) == set(record.varying)
    np.testing.assert_allclose(g["C10"].values, 10.0 ** post.chain[:, :, post.names.index("log10_C10")])
    assert g.attrs["model"] == "reduced_polynomial2" and "uniform on" in g["C10"].attrs["prior"]
    assert set(eval(g.attrs["rhat"])) == set(record.varying)  # JSON of plain floats
    assert uq.read_inference_group(path, "sample_stats")["lp"].shape == (4, 100)
    pred = uq.predictive_draws(problem, record, post, n_draws=10)
    assert len(pred) == 1 and pred[0]["shear_stress"].shape == (10, 60)
    # the draws scatter around the fitted curve
    np.testing.assert_allclose(np.median(pred[0]["shear_stress"], axis=0), record.predicted, rtol=0.05)


def test_posterior_band_in_fit_figure_and_credible_intervals_in_fits_csv(synthetic_fit, tmp_path):
    """run_posterior writes the predictive draws aligned with the record's points: the band drawn in the fit
    figure brackets the fitted curve at every point, and fits.csv carries the posterior table's quantiles next to
    each parameter's standard error (read back from the two files, not recomputed)."""
    from tissuemech.stages import write_fits_table
    from tissuemech.summary import figure_scope_fit, fit_panels

    problem, record = synthetic_fit
    post, info = uq.sample_record_posterior(problem, record, walkers=4, steps=300, burn=60, seed=2)
    fits_dir = tmp_path / "fits" / "simple_shear"
    fits_dir.mkdir(parents=True)
    record.to_netcdf(fits_dir / "reduced_polynomial2.nc")
    groups = uq.inference_data(record, post, info, scope="simple_shear")
    pred = uq.predictive_draws(problem, record, post, n_draws=32)
    flat = np.concatenate([np.concatenate(list(d.values()), axis=1) for d in pred], axis=1)
    import xarray as xr
    groups["posterior_predictive"] = xr.Dataset({"response": (("chain", "draw", "point"), flat[None])})
    nc = uq.write_inference_data(groups, tmp_path / "post.nc")
    band = uq.predictive_band(nc)
    assert band["q05"].shape == record.predicted.shape
    assert np.all(band["q05"] <= record.predicted * 1.0001) and np.all(record.predicted <= band["q95"] * 1.0001)
    panels = fit_panels(record, problem.curves, band)
    (series,) = panels[("simple_shear", "shear_stress")]
    np.testing.assert_allclose(series["band"][0], band["q05"])
    fig = figure_scope_fit(record, problem.curves, band=band)
    assert "posterior-predictive band" in fig._suptitle.get_text()
    table = uq.posterior_table(record, post, scope="simple_shear")
    table["acceptance"], table["warnings"] = post.acceptance, ""
    table.to_csv(tmp_path / "post.csv", index=False)
    fits = write_fits_table([fits_dir], "d", tmp_path / "fits.csv", posterior_tables=[tmp_path / "post.csv"])
    back = pd.read_csv(tmp_path / "fits.csv")
    cols = list(back.columns)
    for name in record.varying:
        row = table.set_index("parameter").loc[name]
        assert back.loc[0, f"ci05_{name}"] == pytest.approx(row["ci05"], rel=1e-12)
        assert back.loc[0, f"ci95_{name}"] == pytest.approx(row["ci95"], rel=1e-12)
        assert cols.index(f"ci05_{name}") == cols.index(f"se_{name}") + 1  # next to the standard error
    assert back.loc[0, "posterior_rhat_max"] == pytest.approx(table["rhat"].max())
    # without posterior tables the same records give the same table minus the posterior columns
    plain = write_fits_table([fits_dir], "d", tmp_path / "plain.csv")
    assert [c for c in fits.columns if not c.startswith(("ci", "posterior_"))] == list(plain.columns)


def test_model_without_record_writes_status(tmp_path):
    table = uq.run_posterior(tmp_path / "none.nc", tmp_path, "simple_shear", "neo_hookean", ["simple_shear"],
                             tmp_path / "p.nc", tmp_path / "p.csv")
    assert table.empty and pd.read_csv(tmp_path / "p.csv").empty
    import xarray as xr
    with xr.open_dataset(tmp_path / "p.nc", engine="h5netcdf") as ds:
        assert "no fit record of neo_hookean" in ds.attrs["status"]
    assert uq.predictive_band(tmp_path / "p.nc") is None
    with pytest.raises(FileNotFoundError, match="posterior.models"):
        uq.recommended_posterior([tmp_path / "p.nc"], "ogden1")


# ------------------------------------------------------------------------------------------------------
# specimen variability
# ------------------------------------------------------------------------------------------------------
def _hierarchical(rng, n_spec=8, n_samp=6, n_rep=1, mu=np.log(300.0), sd_spec=0.25, sd_samp=0.12, sd_rep=0.05):
    rows = []
    for i in range(n_spec):
        b = rng.normal(0.0, sd_spec)
        for j in range(n_samp):
            c = rng.normal(0.0, sd_samp)
            for _ in range(n_rep):
                rows.append({"specimen": f"sp{i}", "sample": f"s{j}",
                             "log_g0": mu + b + c + (rng.normal(0.0, sd_rep) if n_rep > 1 else 0.0)})
    return pd.DataFrame(rows)


def test_mixed_effects_recovers_known_variance_components():
    """Simulated specimens x samples with known mean and SDs: the estimates are within 3 SE of the truth, and over
    40 replicate datasets the +-1.645 SE intervals of the mean and of the sample SD cover the truth about 90 % of
    the time (the SEs are calibrated, not just the estimates)."""
    rng = np.random.default_rng(2026)
    mu, sd_spec, sd_samp = np.log(300.0), 0.25, 0.12
    est = mixed_effects(_hierarchical(rng), "log_g0")
    assert est["n_specimens"] == 8 and est["n_pieces"] == 48 and np.isnan(est["sd_residual"])
    assert abs(est["mean"] - mu) < 3 * est["mean_se"]
    assert abs(est["sd_specimen"] - sd_spec) < 3 * est["sd_specimen_se"]
    assert abs(est["sd_sample"] - sd_samp) < 3 * est["sd_sample_se"]
    cover_mean, cover_samp = [], []
    for _ in range(40):
        e = mixed_effects(_hierarchical(rng), "log_g0")
        cover_mean.append(abs(e["mean"] - mu) < 1.645 * e["mean_se"])
        cover_samp.append(abs(e["sd_sample"] - sd_samp) < 1.645 * e["sd_sample_se"])
    assert 0.75 <= np.mean(cover_mean) <= 1.0 and 0.75 <= np.mean(cover_samp) <= 1.0


def test_mixed_effects_with_no_specimen_variance_gives_zero_blups():
    """Every specimen holds the same six values (shuffled): the specimen means are equal, REML puts the specimen
    variance on its boundary, and the predicted intercepts are all 0 (statsmodels raises when asked for them)."""
    rng = np.random.default_rng(7)
    values = np.log(300.0) + rng.normal(0.0, 0.12, 6)
    table = pd.DataFrame([{"specimen": f"sp{i}", "sample": f"s{j}", "log_g0": v}
                          for i in range(5) for j, v in enumerate(rng.permutation(values))])
    est = mixed_effects(table, "log_g0")
    assert est["sd_specimen"] == pytest.approx(0.0, abs=1e-6)
    assert est["mean"] == pytest.approx(values.mean(), abs=1e-9)
    assert est["sd_sample"] == pytest.approx(np.tile(values, 5).std(ddof=1), rel=1e-6)   # the 30 rows' SD
    assert "refitted without it" in est["method"]
    assert est["blup_z"] == {f"sp{i}": 0.0 for i in range(5)}


def test_mixed_effects_with_no_specimen_variance_and_repeated_runs():
    """As above with two runs per piece (REML lands at or next to the boundary): the sample component and the
    within-piece residual are still those of the data."""
    rng = np.random.default_rng(8)
    pieces = np.log(300.0) + rng.normal(0.0, 0.12, 6)
    runs = rng.normal(0.0, 0.03, (6, 2))
    table = pd.DataFrame([{"specimen": f"sp{i}", "sample": f"s{j}", "log_g0": pieces[k] + runs[k, r]}
                          for i in range(5) for j, k in enumerate(rng.permutation(6)) for r in range(2)])
    est = mixed_effects(table, "log_g0")
    assert est["n_pieces"] == 30 and est["sd_specimen"] < 1e-3
    assert est["mean"] == pytest.approx(table["log_g0"].mean(), abs=1e-6)   # balanced: GLS mean = mean
    within = np.sqrt(np.mean((runs[:, 0] - runs[:, 1]) ** 2 / 2.0))        # pooled within-piece SD (balanced)
    assert est["sd_residual"] == pytest.approx(within, rel=1e-3)
    assert abs(est["sd_sample"] - pieces.std(ddof=1)) < 3 * est["sd_sample_se"]


def test_mixed_effects_with_repeated_runs_separates_sample_from_within_piece():
    rng = np.random.default_rng(5)
    est = mixed_effects(_hierarchical(rng, n_spec=6, n_samp=5, n_rep=3), "log_g0")
    assert est["n_pieces"] == 30 and est["n_runs"] == 90
    assert abs(est["sd_specimen"] - 0.25) < 3 * est["sd_specimen_se"]
    assert abs(est["sd_sample"] - 0.12) < 3 * est["sd_sample_se"]
    assert abs(est["sd_residual"] - 0.05) < 3 * est["sd_residual_se"]
    assert "nested" in est["method"]


# ------------------------------------------------------------------------------------------------------
# propagation to the FEM: the cards of posterior draws
# ------------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def qlv_fit(qlv_rp3_fit):
    """The card and record of the QLV fit of ``tests/conftest.py``."""
    from tissuemech import cards as C

    model, result = qlv_rp3_fit
    return C.make_card(result, model, poisson_ratio=0.49), F.FitRecord.from_result(result)


def test_elastic_card_of_a_qlv_fit_reproduces_its_card(qlv_fit):
    """At the optimum, the draw card of a QLV fit is the fit's own card (law, parameters, bulk modulus, Prony
    series from the step response = the QLV weights), so the posterior draws are solved with the same material."""
    card, record = qlv_fit
    draw = uq.elastic_card(card, record, record.params)
    assert draw["elastic_law"] == card["elastic_law"] == "reduced_polynomial3"
    for k, v in card["elastic_parameters"].items():
        assert draw["elastic_parameters"][k] == pytest.approx(v, rel=1e-12)
    assert draw["bulk_modulus"] == pytest.approx(card["bulk_modulus"], rel=1e-9)
    np.testing.assert_allclose(draw["prony"]["g"], card["prony"]["g"], atol=1e-9)
    assert draw["prony"]["g_inf"] == pytest.approx(card["prony"]["g_inf"], abs=1e-9)
    bands = uq.band(np.array([[1.0, 2.0], [3.0, 4.0], [np.nan, 6.0]]))
    assert bands["q50"][0] == pytest.approx(2.0) and bands["q50"][1] == pytest.approx(4.0)


def test_propagate_splits_sources_and_corrects_cheap_draw_solves(qlv_fit):
    """With a stand-in solver linear in C10: the specimen band is the population factor times the optimum, and
    draws solved by a 10 % stiffer 'coarse' solver are corrected back to the fine solver exactly."""
    import xarray as xr

    card, record = qlv_fit
    x = np.linspace(0.1, 1.0, 5)
    c10 = np.random.default_rng(0).normal(record.params["C10"], 2.0, size=(2, 50))
    post = xr.Dataset({"C10": (("chain", "draw"), c10)})
    pop = {"value": "log_g0", "mean": np.log(uq.reference_shear_modulus(record.model_key, record.params)),
           "sd_specimen": 0.1, "sd_sample": 0.05}

    def fine(c):
        return x, c["elastic_parameters"]["C10"] * x

    def coarse(c):
        return x, 1.1 * c["elastic_parameters"]["C10"] * x

    res = uq.propagate(fine, card, pop, post, record, n_draws=20, seed=1, solve_draw=coarse)
    ref = uq.propagate(fine, card, pop, post, record, n_draws=20, seed=1)
    np.testing.assert_allclose(res["measurement"], ref["measurement"], rtol=1e-12)
    factor = res["specimen"] / res["optimum"][None, :]
    assert np.allclose(factor, factor[:, :1]) and np.std(np.log(factor[:, 0])) == pytest.approx(0.112, rel=0.5)
    assert res["population_log_offset"] == pytest.approx(0.0, abs=1e-12)
    assert 0.0 < res["measurement_share"] < 0.5 and res["failed"] == []
    ds = uq.bands_dataset(res, "x", "1", "y", "N", {"experiment": "stand-in"})
    assert set(uq.SOURCES) <= {k.split("_")[0] for k in ds.data_vars} and ds.sizes["draw"] == 20
