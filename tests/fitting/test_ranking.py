"""Ranking: cross-validation selects the generating model, the thesis rule is applied and disagreements are stated."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from doubles import ProxyReducedPolynomial

from tissuemech import fitting as F
from tissuemech import ranking as R
from tissuemech.canonical import read_netcdf
from tissuemech.models.qlv import LinearElasticShear, QLVModel, qlv_params
from tissuemech.models.registry import get_model

RATES = (0.001, 0.01, 0.1, 1.0)
G_PRONY = [0.10, 0.23, 0.21, 0.14]


def csr_curves(model, p, gmax, noise=0.01, seed=0, n=25, specimen="mean"):
    rng = np.random.default_rng(seed)
    out = []
    for rate in RATES:
        t = np.linspace(0.0, gmax / rate, n + 1)
        y = model.shear_stress_history(p, t, rate * t) if model.supports("shear_history") else \
            model.elastic_shear_stress(p, rate * t)
        y = y[1:] * (1 + noise * rng.standard_normal(n))
        out.append(F.Curve(test="constant_shear_rate", condition=f"rate={rate:g}/s", response="shear_history",
                           inputs={"time": t, "shear_strain": rate * t}, observed={"shear_stress": y},
                           obs_index=np.arange(1, n + 1), nominal={"shear_rate_1_per_s": rate}, specimen=specimen))
    return out


def candidates(*extra):
    base = [R.Candidate("linear_elastic_shear", LinearElasticShear),
            R.Candidate("qlv_linear_prony4", lambda: get_model("qlv_linear_prony4"))]
    return base + list(extra)


def test_folds():
    curves = csr_curves(LinearElasticShear(), {"G0": 100.0}, 0.05)
    folds = R.leave_one_condition_out(curves)
    assert len(folds) == 4 and all(len(f.test) == 1 and len(f.train) == 3 for f in folds)
    assert R.train_on_tests(curves) == []  # no relaxation curve to train on
    assert R.leave_one_specimen_out(curves) == []
    two = curves + csr_curves(LinearElasticShear(), {"G0": 100.0}, 0.05, specimen="b2")
    assert len(R.leave_one_specimen_out(two)) == 2


def test_rate_dependent_small_strain_selects_qlv_by_cv_and_rule():
    qlv = get_model("qlv_linear_prony4")
    truth = qlv_params(qlv, {"G0": 200.0}, G_PRONY)
    curves = csr_curves(qlv, truth, gmax=0.05, seed=1)
    rd = R.rate_dependence(curves)
    assert rd["rate_dependent"] and rd["slope_median"] > 0
    table, fits, cv, rec = R.rank_scope(candidates(), curves, target="none", scope="csr",
                                        folds=R.leave_one_condition_out(curves), n_random=1)
    assert table.iloc[0]["model"] == "qlv_linear_prony4"
    assert table.iloc[0]["rank_criterion"] == "cv_nrmse"
    best = table.set_index("model")
    assert best.loc["qlv_linear_prony4", "cv_nrmse"] < 0.5 * best.loc["linear_elastic_shear", "cv_nrmse"]
    assert best.loc["linear_elastic_shear", "delta_aicc"] > 10
    assert rec["rule_family"] == "qlv" and rec["agree"] and rec["recommended"] == "qlv_linear_prony4"
    assert "rate/time-dependent (csr_rates)" in rec["statement"]
    assert set(cv["design"]) == {"leave_one_condition_out"} and (cv["status"] == "ok").all()
    assert np.isclose(table["akaike_weight"].sum(), 1.0)
    # the one recommendation column: exactly one row, the recommended model
    assert table.loc[table["recommended"], "model"].tolist() == ["qlv_linear_prony4"]


def test_rate_independent_large_strain_selects_hyperelastic():
    rp3 = ProxyReducedPolynomial(order=3)
    truth = {"C10": 40.0, "C20": 100.0, "C30": 400.0}
    curves = csr_curves(rp3, truth, gmax=0.5, seed=2)
    assert R.rate_dependence(curves)["rate_dependent"] is False
    table, fits, cv, rec = R.rank_scope(candidates(R.Candidate("reduced_polynomial3", lambda: ProxyReducedPolynomial(order=3))),
                                        curves, target="none", scope="csr", folds=R.leave_one_condition_out(curves),
                                        n_random=1)
    assert table.iloc[0]["model"] == "reduced_polynomial3"
    assert rec["rule_family"] == "hyperelastic" and rec["agree"]
    # the recommendation is stored with every row of the scope
    assert (table["recommendation"] == rec["statement"]).all() and table["recommended"].sum() == 1


def test_data_that_contradict_the_rule_are_reported():
    """Strain <= 10 % and rate-independent -> the thesis rule says linear elastic, but a strongly stiffening
    law is measurably better: the recommendation follows the data and says so."""
    rp3 = ProxyReducedPolynomial(order=3)
    truth = {"C10": 40.0, "C20": 4000.0, "C30": 4.0e5}
    curves = csr_curves(rp3, truth, gmax=0.1, seed=3, noise=0.003)
    table, _, _, rec = R.rank_scope([R.Candidate("linear_elastic_shear", LinearElasticShear),
                                     R.Candidate("reduced_polynomial3", lambda: ProxyReducedPolynomial(order=3))],
                                    curves, target="none", scope="csr", folds=R.leave_one_condition_out(curves),
                                    n_random=1)
    assert rec["rule_family"] == "linear_elastic"
    assert not rec["agree"] and rec["recommended"] == "reduced_polynomial3"
    # the rule's linear law is not even supported (its misfit is far beyond the noise): the statement says so and
    # that the data's choice is used
    assert "linear_elastic_shear (misfit" in rec["statement"] and "the data's choice is used" in rec["statement"]


def test_qlv_with_nonlinear_law_wins_at_large_strain_and_rate_dependence():
    law = ProxyReducedPolynomial(order=3)
    model = QLVModel(law, n_prony=4, name="qlv_rp3_prony4")
    truth = qlv_params(model, {"C10": 40.0, "C20": 100.0, "C30": 400.0}, G_PRONY)
    curves = [F.thin(c, 15) for c in csr_curves(model, truth, gmax=0.4, seed=4)]
    cands = [R.Candidate("reduced_polynomial3", lambda: ProxyReducedPolynomial(order=3)),
             R.Candidate("qlv_linear_prony4", lambda: get_model("qlv_linear_prony4")),
             R.Candidate("qlv_rp3_prony4", lambda: QLVModel(ProxyReducedPolynomial(order=3), 4, name="qlv_rp3_prony4"))]
    table, fits, cv, rec = R.rank_scope(cands, curves, target="none", scope="csr", n_random=1)
    assert table.iloc[0]["model"] == "qlv_rp3_prony4" and table.iloc[0]["rank_criterion"] == "aicc"
    assert rec["rule_family"] == "qlv" and rec["agree"]


def test_paired_comparison_and_plot(tmp_path):
    cv = pd.DataFrame({"fold": ["a", "b", "c", "a", "b", "c"], "model": ["m1"] * 3 + ["m2"] * 3,
                       "nrmse": [0.1, 0.12, 0.11, 0.3, 0.25, 0.4], "status": ["ok"] * 6})
    pc = R.paired_comparison(cv).set_index("model")
    assert pc.loc["m1", "cv_best"] == "m1" and np.isnan(pc.loc["m1", "cv_p_vs_best"])
    assert 0 < pc.loc["m2", "cv_p_vs_best"] <= 0.5
    model = LinearElasticShear()
    curves = csr_curves(model, {"G0": 100.0}, 0.05)
    table, *_ = R.rank_scope([R.Candidate("linear_elastic_shear", LinearElasticShear)], curves, target="none",
                             scope="csr", n_random=0)
    path = tmp_path / "ranking.png"
    R.plot_ranking(table, path)
    assert path.stat().st_size > 1000


@pytest.mark.parametrize("strain,rate,nonsep,expected", [
    (0.05, False, False, "linear_elastic"), (0.5, False, False, "hyperelastic"),
    (0.05, True, False, "qlv"), (0.5, True, False, "qlv"), (0.5, True, True, "beyond_qlv")])
def test_thesis_rule(strain, rate, nonsep, expected):
    assert R.thesis_rule(strain, rate, nonsep) == expected


def test_rule_choice_stands_when_the_top_model_is_not_decisively_better():
    table = pd.DataFrame({"model": ["beyond", "qlv_a"], "family": ["beyond_qlv", "qlv"], "aicc": [10.0, 11.0],
                          "cv_nrmse": [0.050, 0.052], "strain_max": [0.5, 0.5], "rank_criterion": ["cv_nrmse"] * 2})
    qlv = get_model("qlv_linear_prony4")
    curves = csr_curves(qlv, qlv_params(qlv, {"G0": 200.0}, G_PRONY), gmax=0.5, seed=5)
    rec = R.recommend(table, curves)
    assert rec["rule_family"] == "qlv" and not rec["agree"] and rec["recommended"] == "qlv_a"
    assert "not decisively better" in rec["statement"]
    table.loc[0, "cv_nrmse"] = 0.02
    rec = R.recommend(table, curves)
    assert rec["recommended"] == "beyond" and "The data say otherwise" in rec["statement"]


def test_a_fit_at_a_bound_or_without_covariance_is_never_recommended():
    """The ranking may put a flagged fit first; the recommendation passes over it and says why, and names none
    when no fit qualifies."""
    table = pd.DataFrame({"model": ["qlv_a", "qlv_b", "qlv_c"], "family": ["qlv"] * 3, "aicc": [1.0, 5.0, 9.0],
                          "cv_nrmse": [0.05, 0.06, 0.07], "strain_max": [0.5] * 3, "rank_criterion": ["cv_nrmse"] * 3,
                          "converged": [True] * 3, "at_bound": ["G0", "", ""], "has_covariance": [True, False, True],
                          "recommendable": [False, False, True]})
    qlv = get_model("qlv_linear_prony4")
    curves = csr_curves(qlv, qlv_params(qlv, {"G0": 200.0}, G_PRONY), gmax=0.5, seed=5)
    rec = R.recommend(table, curves)
    assert rec["recommended"] == "qlv_c"
    assert "qlv_a (G0 at a bound)" in rec["statement"] and "qlv_b (no covariance)" in rec["statement"]
    table["recommendable"] = False
    rec = R.recommend(table, curves)
    assert rec["recommended"] is None and "No model is supported" in rec["statement"]


def test_at_bound_parameters_and_covariance_from_flags():
    flags = ["at_bound: G0 at its upper bound 1e+06", "at_bound: beta_2 at its lower bound 0",
             "at_bound: beta_3 at its upper bound 1000", "correlated: a~b (rho=+0.990)"]
    assert F.at_bound_parameters(flags) == ["G0", "beta_3"]  # an absent Prony mode (beta_i = 0) is no collapse
    # 0-based indices of the Prony ratios at their *upper* bound only (beta_3 -> 2; not G0, not beta_2 at 0)
    assert F.weights_at_upper_bound(flags + ["at_bound: beta_1 at its upper bound 1000"]) == [0, 2]
    assert F.weights_at_upper_bound(["at_bound: beta_10 at its upper bound 1000"]) == [9]
    assert F.weights_at_upper_bound(flags[:2]) == []
    assert F.has_covariance([], {"a": 1.0, "b": np.nan}, ["a", "b"])
    assert not F.has_covariance([], {"a": np.nan}, ["a"])
    assert not F.has_covariance(["no_covariance: the Jacobian is singular"], {"a": 1.0}, ["a"])


def test_select_cards_takes_the_recommended_card_of_each_scope(tmp_path):
    from tissuemech import stages

    for scope, model, law in (("constant_shear_rate", "neo_hookean", "neo_hookean"),
                              ("constant_shear_rate", "ogden1", "ogden1"),
                              ("stress_relaxation", "maxwell", "maxwell"),
                              ("material", "qlv_rp3_prony4", "reduced_polynomial3")):
        (tmp_path / "cards" / scope).mkdir(parents=True, exist_ok=True)
        (tmp_path / "cards" / scope / f"{model}.json").write_text(f'{{"model": "{model}", "elastic_law": "{law}"}}')
    ranking = tmp_path / "ranking.csv"
    # ogden1 ranks first in its scope but the ranking recommends neo_hookean; no FEM law for maxwell
    pd.DataFrame({"scope": ["constant_shear_rate", "constant_shear_rate", "stress_relaxation", "material",
                            "creep_recovery"],
                  "model": ["ogden1", "neo_hookean", "maxwell", "qlv_rp3_prony4", None],
                  "rank": [1, 2, 1, 1, np.nan], "recommended": [False, True, True, True, False]}).to_csv(ranking)
    chosen = stages.select_cards(ranking, tmp_path / "cards")
    assert [(p.parent.name, p.stem) for p in chosen] == [("material", "qlv_rp3_prony4"),
                                                         ("constant_shear_rate", "neo_hookean")]
    assert R.recommended_models(ranking) == {"constant_shear_rate": "neo_hookean", "stress_relaxation": "maxwell",
                                             "material": "qlv_rp3_prony4"}


def test_time_dependence_from_relaxation_and_sweep():
    t = np.geomspace(0.1, 100, 30)
    relax = F.Curve(test="stress_relaxation", condition="s", response="shear_history", inputs={"time": t, "shear_strain": 0.01 + 0 * t},
                    observed={"shear_stress": 2.0 * (0.4 + 0.6 * np.exp(-t / 5))})
    assert R.time_dependence([relax])["evidence"] == "relaxation_decay"
    assert R.time_dependence([relax])["rate_dependent"]
    w = np.geomspace(0.6, 120, 10)
    fs = F.Curve(test="frequency_sweep", condition="f", response="oscillation", inputs={"angular_frequency": w},
                 observed={"storage_modulus": 200 + 0 * w, "loss_modulus": 0.5 + 0 * w})
    assert R.time_dependence([fs])["rate_dependent"] is False


def _write_csr_averages(folder, rates, truth, model):
    """Canonical CSR runs (2 samples per rate, 12.5 mm plate, apparent rim stress of the model) and their
    ``averages.nc``, as the workflow's average rule writes it."""
    from tissuemech.canonical import make_run_dataset
    from tissuemech.curves import average_runs, write_averages
    from tissuemech.models import plate

    runs = []
    for i, rate in enumerate(rates):
        for s in range(2):
            t = np.linspace(0, 0.05 / rate, 31)
            y = plate.forward_plate(model, truth, t, rate * t, 0.0125) * (1 + 0.002 * s)
            runs.append(make_run_dataset({"time": t[1:], "shear_strain": rate * t[1:], "shear_stress": y[1:]},
                                         {"test": "constant_shear_rate", "shear_rate_1_per_s": rate,
                                          "radius_m": 0.0125, "gap_m": 0.003, "specimen": "b1", "sample": f"s{s}",
                                          "run": f"r{i}{s}"}))
    write_averages(average_runs(runs), folder / "averages.nc")
    return folder / "averages.nc"


def test_fit_stage_writes_fits_ranking_cards(tmp_path):
    """The workflow's fit stage (``stages``: scopes from the config, ``run_fit_scope`` per scope,
    ``collect_scopes``) on averaged CSR runs: fit records, cards, ranking with its recommendation, CV records,
    the one ``fits.csv`` schema; plate geometry from the averages; the generating parameter is recovered."""
    from tissuemech import stages

    scope_test = "constant_shear_rate"
    qlv = get_model("qlv_linear_prony4")
    truth = qlv_params(qlv, {"G0": 200.0}, G_PRONY)
    averages = _write_csr_averages(tmp_path, RATES, truth, qlv)
    config = {"models": {"constant_shear_rate": ["qlv_linear_prony4"], "flow_curve": ["newton"]}}
    scopes = stages.dataset_scopes(["constant_shear_rate"], config)
    # flow curves: no data, no scope; the ramps also get the material model (a QLV of every shear test)
    assert list(scopes) == ["constant_shear_rate", "material"] and scopes["material"]["tests"] == [scope_test]
    with pytest.raises(KeyError, match="no_such_model"):  # a config typo is an error
        stages.dataset_scopes(["constant_shear_rate"], {"models": {"constant_shear_rate": ["no_such_model"]}})
    curves = stages.scope_curves(read_netcdf(averages), ["constant_shear_rate"])
    assert {c.radius_m for c in curves} == {0.0125} and {c.gap_m for c in curves} == {0.003}

    scope = "constant_shear_rate"
    fits_dir, cards_dir = tmp_path / "fits" / scope, tmp_path / "cards" / scope
    table = stages.run_fit_scope(averages, scope, scopes[scope], target="apparent_stress", seed=0, multistart=1,
                                 fits_dir=fits_dir, cards_dir=cards_dir, ranking_path=tmp_path / "ranking" / f"{scope}.csv",
                                 dataset="demo", poisson_ratio=0.49)
    assert list(table["rank"]) == [1] and table["recommendation"].notna().all() and table["recommended"].all()
    assert (fits_dir / "qlv_linear_prony4.nc").exists() and (cards_dir / "qlv_linear_prony4.inp").exists()
    assert (tmp_path / "ranking" / f"{scope}.recommendation.json").exists()
    assert len(pd.read_csv(tmp_path / "ranking" / f"{scope}.cv.csv")) == len(RATES)

    stages.collect_scopes([tmp_path / "ranking" / f"{scope}.csv"], tmp_path / "ranking.csv", tmp_path / "ranking.png")
    stages.write_fits_table([fits_dir], "demo", tmp_path / "fits.csv")
    fits = pd.read_csv(tmp_path / "fits.csv")
    assert list(fits["model"]) == ["qlv_linear_prony4"] and (fits["dataset"] == "demo").all()
    assert fits.loc[0, "target"] == "apparent_stress" and fits.loc[0, "param_G0"] == pytest.approx(200.0, rel=0.02)
    assert list(pd.read_csv(tmp_path / "ranking.csv")["rank"]) == [1]
    assert R.recommended_models(tmp_path / "ranking.csv") == {scope: "qlv_linear_prony4"}
    assert (tmp_path / "ranking.png").exists()
