"""The baseline before anything is blamed: adequacy checks, ranking order, the resolved relaxation window,
and the decision rule of diagnosis.json (noise-calibrated margin, fix not evaluated, not testable)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps
from statsmodels.tools.sm_exceptions import MissingDataError

from tissuemech.canonical import make_run_dataset
from tissuemech.diagnosis import report
from tissuemech.diagnosis.decision import fix_margin
from tissuemech.diagnosis.noise import relative_noise_level
from tissuemech.diagnosis.baseline import baseline_adequacy, ranked_candidates, resolved_window_s, window_taus
from tissuemech.models.registry import model_on_times


def _table(log_ratio, sigma_rel=0.01):
    lr = np.asarray(log_ratio, float)
    obs = np.full(lr.size, 100.0)
    pred = obs / np.exp(lr)
    return pd.DataFrame({"log_ratio": lr, "std_residual": (obs - pred) / (sigma_rel * obs)})


def _record(key="qlv_linear_prony4", flags=(), stderr=None, family="qlv", aicc=0.0, scope="csr"):
    return {"model_key": key, "family": family, "aicc": aicc, "scope": scope, "flags": list(flags),
            "varying": ["G0", "beta_1"], "stderr": stderr if stderr is not None else {"G0": 1.0, "beta_1": 0.1},
            "converged": True}


def test_adequate_baseline_passes_every_check():
    a = baseline_adequacy(_record(), _table(np.full(50, 0.05)))
    assert a["adequate"] and a["reasons"] == []
    assert a["misfit_factor"] == pytest.approx(np.exp(0.05))


def test_collapsed_modulus_at_its_bound_is_inadequate_but_an_absent_mode_is_not():
    bound = _record(flags=["at_bound: G0 at its lower bound 0.001"])
    a = baseline_adequacy(bound, _table(np.full(50, 0.05)))
    assert not a["adequate"] and a["at_bound"] == ["G0"] and "G0" in a["reasons"][0]
    absent_mode = _record(flags=["at_bound: beta_4 at its lower bound 0"])
    assert baseline_adequacy(absent_mode, _table(np.full(50, 0.05)))["adequate"]


def test_no_covariance_and_gross_misfit_are_inadequate():
    a = baseline_adequacy(_record(stderr={"G0": np.nan, "beta_1": np.nan}), _table(np.full(50, 0.05)))
    assert not a["adequate"] and a["no_covariance"]
    # a model off by 10^6 (the CNF collapse): the typical point is off by far more than a factor 2
    g = baseline_adequacy(_record(), _table(np.full(50, np.log(1e6))))
    assert not g["adequate"] and g["misfit_factor"] == pytest.approx(1e6)
    assert "gross misfit" in g["reasons"][0] and g["misfit_noise_units"] == pytest.approx(100.0, rel=1e-3)


def test_candidates_follow_the_ranking_qlv_family_first():
    recs = [_record("qlv_linear_prony4", aicc=1.0), _record("qlv_rp3_prony4", aicc=5.0),
            _record("pr_rp3_prony4", family="pipkin_rogers", aicc=-50.0)]
    ranking = pd.DataFrame({"scope": ["csr", "csr", "csr", "other"],
                            "model": ["pr_rp3_prony4", "qlv_rp3_prony4", "qlv_linear_prony4", "qlv_linear_prony4"],
                            "rank": [1, 2, 3, 1]})
    order, source = ranked_candidates(recs, ranking)
    assert [r["model_key"] for r in order] == ["qlv_rp3_prony4", "qlv_linear_prony4", "pr_rp3_prony4"]
    assert "ranking.csv" in source
    order, source = ranked_candidates(recs, None)
    assert [r["model_key"] for r in order][:2] == ["qlv_linear_prony4", "qlv_rp3_prony4"] and "aicc" in source


def _run(test, **cols):
    return make_run_dataset(cols, {"dataset": "t", "run": test, "test": test, "specimen": "b", "sample": "s",
                                   "order": 1, "source_file": "x", "source_sha256": "0"})


def test_window_spans_what_the_tests_resolve():
    f = np.logspace(-1, 1, 11)
    sweep = _run("frequency_sweep", frequency=f, storage_modulus=np.ones(11), loss_modulus=np.ones(11))
    t = np.r_[np.linspace(0, 0.5, 6), np.linspace(1, 3000, 50)]
    relax = _run("stress_relaxation", time=t, shear_strain=np.minimum(t / 0.5, 1) * 0.01,
                 shear_stress=np.ones(t.size))
    w = resolved_window_s([sweep, relax])
    assert w["t_min_s"] == pytest.approx(1 / (2 * np.pi * 10))
    assert w["t_max_s"] == pytest.approx(3000.0)
    taus = window_taus(w)
    assert taus[0] <= w["t_min_s"] and taus[-1] >= w["t_max_s"]
    assert taus[0] == pytest.approx(1e-2) and taus[-1] == pytest.approx(1e4)  # not the fixed 0.1-100 s
    m = model_on_times("qlv_linear_prony4", taus)
    assert m.taus(m.default_params()) == pytest.approx(taus)
    assert window_taus(resolved_window_s([])).size == 0


def test_fix_margin_is_the_noise_standard_error_of_the_metric():
    eps = 0.02
    m = fix_margin({"parameters": {"n_held_out_points": 50}}, eps, alpha=0.01)
    assert m == pytest.approx(sps.norm.ppf(0.99) * eps / np.sqrt(100))
    # a curve-level fix that reports no count: one held-out level per curve
    assert fix_margin(None, eps, 0.01, n_default=12) == pytest.approx(sps.norm.ppf(0.99) * eps / np.sqrt(24))
    assert np.isnan(fix_margin(None, np.nan, n_default=12)) and np.isnan(fix_margin(None, eps))


def test_a_detector_missing_a_quantity_is_not_testable(monkeypatch):
    def broken(ctx):
        raise MissingDataError("exog contains inf or nans")

    monkeypatch.setitem(report.DETECTORS, "instrument_inertia", broken)
    ctx = report.DiagnosisContext(runs=[], table=pd.DataFrame(), model="m", fit_info={})
    out = {f["effect"]: f for f in report.run_detectors(ctx) if f["effect"] == "instrument_inertia"}
    assert out["instrument_inertia"]["tested"] is False
    assert out["instrument_inertia"]["evidence"].startswith("not testable here")


@pytest.mark.slow
def test_inadequate_baseline_is_the_first_finding_and_blocks_blame(diagnosed):
    runs, table, _ = diagnosed("torque_offset", n_specimens=4, n_samples=2, n_points=16)
    fit_info = {"target": "torque", "relaxation": "ramp"}
    bad = baseline_adequacy(_record("qlv_bad", flags=["at_bound: G0 at its lower bound 0.001"]), table)
    good = baseline_adequacy(_record("qlv_constructed"), table)
    assert good["adequate"]
    res = report.diagnose(runs, table, "qlv_constructed", fit_info, adequacy=[bad, good])
    assert res["findings"][0]["effect"] == "baseline_inadequate" and "qlv_bad" in res["findings"][0]["evidence"]
    assert res["baseline"]["adequate"] and "torque_offset" in [f["effect"] for f in res["findings"] if f["detected"]]
    assert res["noise_model"]["relative_level"] > 0 and "differences of order 2-4" in res["noise_model"]["method"]
    none_ok = report.diagnose(runs, table, "qlv_bad", fit_info, adequacy=[bad])
    assert [f["effect"] for f in none_ok["findings"] if f["detected"]] == ["baseline_inadequate"]
    assert none_ok["unexplained"] == [] and none_ok["significant_fix_not_evaluated"] == []
    assert "only causes whose test and fix do not use its predictions may be named" in none_ok["findings"][0]["evidence"]


def test_noise_level_ignores_imposed_inputs_and_reads_the_floor_at_the_typical_magnitude():
    noise = {"blocks": {"a|shear_strain": {"relative": 0.0, "absolute": 0.0, "median_abs": 0.1},
                        "a|shear_stress": {"relative": 0.0, "absolute": 0.5, "median_abs": 25.0},
                        "b|storage_modulus": {"relative": 0.03, "absolute": 0.0, "median_abs": 100.0}}}
    assert relative_noise_level(noise) == pytest.approx(np.median([0.02, 0.03]))


def test_a_model_without_residuals_is_inadequate_and_the_diagnosis_still_returns():
    empty = pd.DataFrame(columns=["model", "curve", "test", "quantity", "observed", "predicted", "residual",
                                  "log_ratio", "sigma"])
    a = baseline_adequacy(_record("qlv_none"), empty)
    assert not a["adequate"] and "no residual" in a["reasons"][-1]
    res = report.diagnose([], empty, "qlv_none", {}, noise={"blocks": {}}, adequacy=[a])
    assert [f["effect"] for f in res["findings"] if f["detected"]] == ["baseline_inadequate"]
    assert res["baseline"]["adequate"] is False and res["unexplained"] == []


def test_the_recommended_qlv_model_is_the_first_candidate():
    """ranking.csv's 'recommended' column (the choice cards and FEM use) orders the QLV family; a recommended
    model outside the QLV family is named in the source but the separable reference still comes first."""
    recs = [_record("qlv_linear_prony4", aicc=1.0), _record("qlv_rp3_prony4", aicc=5.0),
            _record("pr_rp3_prony4", family="pipkin_rogers", aicc=-50.0)]
    ranking = pd.DataFrame({"scope": ["csr"] * 3, "model": ["pr_rp3_prony4", "qlv_rp3_prony4", "qlv_linear_prony4"],
                            "rank": [1, 2, 3], "recommended": [False, False, True]})
    order, source = ranked_candidates(recs, ranking)
    assert [r["model_key"] for r in order] == ["qlv_linear_prony4", "qlv_rp3_prony4", "pr_rp3_prony4"]
    assert "recommended model qlv_linear_prony4 first" in source
    ranking["recommended"] = [True, False, False]
    order, source = ranked_candidates(recs, ranking)
    assert [r["model_key"] for r in order] == ["qlv_rp3_prony4", "qlv_linear_prony4", "pr_rp3_prony4"]
    assert "pr_rp3_prony4 is not QLV-family" in source


PRONY2_TRUTH = {"G_inf": 400.0, "G_1": 600.0, "G_2": 300.0, "tau_1": 0.05, "tau_2": 2.0}


def _prony2_sweeps(n_runs=6, seed=32):
    """Frequency sweeps of the Prony truth :data:`PRONY2_TRUTH` whose loss modulus falls to the torque floor at both
    ends: noise on the complex torque, a floor in stress amplitude (floor / strain amplitude in a modulus) plus 1 %
    relative. Oracle: the closed-form moduli of a Prony series."""
    truth = PRONY2_TRUTH
    omega = np.geomspace(1e-3, 1e4, 30)
    wt = np.outer(omega, [truth["tau_1"], truth["tau_2"]])
    g_star = truth["G_inf"] + (wt ** 2 / (1 + wt ** 2) + 1j * wt / (1 + wt ** 2)) @ [truth["G_1"], truth["G_2"]]
    amplitude, floor_stress_pa, relative = 0.01, 0.06, 0.01
    rng = np.random.default_rng(seed)
    runs = []
    for k in range(n_runs):
        stress = g_star * amplitude
        sd = np.hypot(floor_stress_pa, relative * np.abs(stress)) / np.sqrt(2.0)
        measured = (stress + sd * (rng.standard_normal(omega.size) + 1j * rng.standard_normal(omega.size))) / amplitude
        runs.append(make_run_dataset(
            {"angular_frequency": omega, "frequency": omega / (2 * np.pi), "storage_modulus": measured.real,
             "loss_modulus": measured.imag, "shear_strain": np.full(omega.size, amplitude),
             "shear_stress": np.abs(measured) * amplitude, "time": np.arange(1.0, omega.size + 1)},
            {"test": "frequency_sweep", "strain_pct": 100 * amplitude, "radius_m": 0.01, "gap_m": 0.002,
             "specimen": f"P{k}", "sample": "s1", "run": f"fs{k}"}))
    return runs


def test_the_run_level_fit_weighs_sweep_moduli_by_their_torque_floor():
    """On sweeps whose loss modulus falls to the torque floor (:func:`_prony2_sweeps`) the diagnosis's run-level fit
    recovers the Prony truth and its reduced chi-square is that of the noise. With the fit's own per-observable
    floors (a modulus known to 1 %, whatever the amplitude) tau_1 came out 21 % off; with the loss modulus's noise
    read relative to itself rather than to |G*| the reduced chi-square was 2.6."""
    from tissuemech.diagnosis.baseline import fit_runs

    runs = _prony2_sweeps()
    assert sum(int((r["loss_modulus"].values < 0).sum()) for r in runs) >= 3
    fit = fit_runs("prony2", runs, "torque", n_points=40)
    assert fit.success
    for name, value in PRONY2_TRUTH.items():
        assert fit.params[name] == pytest.approx(value, rel=0.05), name
    assert 0.6 < fit.redchi < 1.6, fit.redchi


def test_quality_flagged_sweep_points_are_left_out_of_the_run_level_fit_and_the_misfit():
    """The top five frequencies of every sweep flagged at ingest (bit 1, inertia-dominated) and corrupted as an
    inertia mis-correction corrupts them (G' down by 70 %, G'' up threefold), and a seventh sweep flagged at every
    point: the run-level fit recovers the truth as
    the fit stage's averages would (they drop flagged points), and the baseline's misfit leaves those rows out."""
    from tissuemech.diagnosis.baseline import fit_runs, predict_runs
    from tissuemech.diagnosis.evidence import residual_table
    from tissuemech.models.registry import get_model

    runs = []
    for k, r in enumerate(_prony2_sweeps(n_runs=7)):
        flags = np.zeros(r.sizes["point"], np.int32)
        flags[-5:] = 1
        if k == 6:  # a sweep flagged at every point is left out, not a crash
            flags[:] = 1
        r = r.assign(quality_flags=("point", flags))
        r["storage_modulus"].values[-5:] *= 0.3
        r["loss_modulus"].values[-5:] *= 3.0
        runs.append(r)
    fit = fit_runs("prony2", runs, "torque", n_points=40)
    for name, value in PRONY2_TRUTH.items():
        assert fit.params[name] == pytest.approx(value, rel=0.05), name
    model = get_model("prony2")
    table = residual_table(runs, predict_runs(model, fit.params, runs, "torque", "measured"), "prony2")
    assert (table["quality_flag"] == 1).sum() == (6 * 5 + 30) * 2
    verdict = baseline_adequacy({"model_key": "prony2", "flags": fit.flags, "stderr": fit.stderr,
                                 "varying": fit.varying, "converged": fit.success}, table)
    assert verdict["misfit_noise_units"] < 1.6, verdict
