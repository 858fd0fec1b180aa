"""Curve-level detectors (preconditioning, outlier specimen, elapsed-time drift) on designs other than the
bundled one: the first test is a relaxation or varies by sample, orders are shuffled, one sample per
specimen, 2-8 specimens, order known only from ``started_at`` or only from ``order``, no ``total_time``.

The constructed truth is linear viscoelastic (G(t) = G0 (0.4 + 0.6 e^{-t/1 s}), G0 = 1 kPa) and the
baseline prediction is that truth without the effect and without the specimen/sample stiffness scatter
(log-SD 0.15 between specimens and 0.05 between samples unless stated, 2 % curve-to-curve, 1 % per point).
Effects are multiplicative on the curve level: first load x (1 + p), drift x (1 + kappa t_elapsed[h]),
outlier specimen x ratio. Each test asserts the effect by name (significance, size) on the detector's
finding and the null by its absence (p > 0.01 on the same design without the effect); seeds are fixed.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm
from scipy import stats as sps

from tissuemech.canonical import make_run_dataset
from tissuemech.diagnosis.catalogue import (DiagnosisContext, curve_levels, detect_elapsed_time_drift,
                                            detect_outlier_specimen, detect_preconditioning,
                                            paired_first_load_test)
from tissuemech.diagnosis.evidence import residual_table

G0, TAU = 1000.0, 1.0
RADIUS, GAP = 10e-3, 1.5e-3
N_POINTS = 16


def _g_rel(t):
    return G0 * (0.4 + 0.6 * np.exp(-t / TAU))


def _g_star(f):
    wt = 2 * np.pi * f * TAU
    return G0 * (0.4 + 0.6 * wt ** 2 / (1 + wt ** 2)), G0 * 0.6 * wt / (1 + wt ** 2)


def _curve(test: str, cond: float):
    """(columns without noise or scale, predictions, attrs) of one test of the linear truth."""
    if test == "stress_relaxation":
        t = np.concatenate([[0.0], np.logspace(-2, 2, N_POINTS - 1)])
        strain = np.where(t > 0, cond, 0.0)
        cols = {"time": t, "shear_strain": strain, "shear_stress": strain * _g_rel(t)}
        return cols, {"shear_stress": strain * _g_rel(t)}, {"strain_pct": 100 * cond}
    if test == "frequency_sweep":
        f = np.logspace(-1, 1, N_POINTS)
        gp, gpp = _g_star(f)
        cols = {"frequency": f, "angular_frequency": 2 * np.pi * f, "shear_strain": np.full(f.size, 0.01),
                "storage_modulus": gp, "loss_modulus": gpp, "time": np.arange(f.size) * 5.0}
        return cols, {"storage_modulus": gp, "loss_modulus": gpp}, {"strain_pct": 1.0}
    g0 = np.logspace(-3, -1, N_POINTS)
    gp, gpp = _g_star(np.array([cond]))
    cols = {"shear_strain": g0, "frequency": np.full(g0.size, cond), "storage_modulus": np.full(g0.size, gp[0]),
            "loss_modulus": np.full(g0.size, gpp[0]), "time": np.arange(g0.size) * 10.0}
    return cols, {"storage_modulus": cols["storage_modulus"].copy(), "loss_modulus": cols["loss_modulus"].copy()}, \
        {"frequency_hz": cond}


#: (test, condition) menu of the constructed designs: relaxations at 1 and 5 %, a frequency sweep, an
#: amplitude sweep at 1 Hz
MENU = (("stress_relaxation", 0.01), ("stress_relaxation", 0.05), ("frequency_sweep", 0.0),
        ("amplitude_sweep", 1.0))


def make_runs(sequences, *, seed=0, first_load=0.0, drift_per_h=0.0, outlier=1.0, specimen_sd=0.15, sample_sd=0.05,
              order_attr=True, started_at=True, pause_s=None, temperature_per_h=None, samples_per_specimen=1,
              pause_jitter_s=0.0):
    """Canonical runs and residual table of a design given as one test sequence per specimen (one sample
    per specimen): ``sequences[b]`` is the list of MENU indices run on specimen b, in measuring order.
    ``samples_per_specimen``: each specimen's samples run its sequence one after the other on the specimen's clock;
    ``pause_jitter_s``: a fixed ``pause_s`` varies by up to this many seconds either way.

    ``order_attr``/``started_at``: whether the run records its position / its start time (ISO 8601);
    ``pause_s``: seconds between test starts (random 200-1400 s when None); ``temperature_per_h``: a
    logged temperature channel rising by this many degC per hour, +-0.05 degC per test (no effect on the
    stiffness)."""
    rng = np.random.default_rng(seed)
    runs, preds = [], []
    spec_scale = np.exp(rng.normal(0.0, specimen_sd, len(sequences)))
    spec_scale[0] *= outlier
    day = pd.Timestamp("2026-03-02T09:00:00")
    for b, seq in enumerate(sequences):
        t_start = 0.0
        for smp in range(samples_per_specimen):
            k_sample = spec_scale[b] * np.exp(rng.normal(0, sample_sd))
            for pos, m in enumerate(seq, start=1):
                test, cond = MENU[m]
                cols, pred, extra = _curve(test, cond)
                k = k_sample * np.exp(rng.normal(0, 0.02)) * (1 + drift_per_h * t_start / 3600.0)
                if pos == 1:
                    k *= 1 + first_load
                for q in ("shear_stress", "storage_modulus", "loss_modulus"):
                    if q in cols:
                        cols[q] = cols[q] * k * np.exp(rng.normal(0, 0.01, cols[q].size))
                if temperature_per_h is not None:
                    # the bath follows the ramp to within 0.05 degC per test
                    cols["temperature"] = np.full(cols["time"].size, 25.0 + temperature_per_h * t_start / 3600.0
                                                  + rng.normal(0.0, 0.05))
                attrs = {"dataset": "design_agnostic", "run": f"sp{b}-s{smp + 1}-{pos}-{test}@{cond:g}", "test": test,
                         "specimen": f"sp{b}", "sample": f"s{smp + 1}", "radius_m": RADIUS, "gap_m": GAP, **extra}
                if order_attr:
                    attrs["order"] = pos
                if started_at:
                    attrs["started_at"] = (day + pd.Timedelta(days=b, seconds=t_start)).isoformat()
                runs.append(make_run_dataset(cols, attrs))
                preds.append(pred)
                t_start += rng.uniform(200.0, 1400.0) if pause_s is None else pause_s + (
                    rng.uniform(-pause_jitter_s, pause_jitter_s) if pause_jitter_s else 0.0)
    table = residual_table(runs, preds, "lve_constructed")
    return DiagnosisContext(runs=runs, table=table, model="lve_constructed", fit_info={"target": "torque"})


def shuffled(n_specimens, seed, menu=(0, 1, 2, 3), first=None):
    """One random order of ``menu`` per specimen (``first``: the MENU index forced to come first)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_specimens):
        rest = [m for m in menu if m != first] if first is not None else list(menu)
        rest = list(rng.permutation(rest))
        out.append(([first] if first is not None else []) + [int(m) for m in rest])
    return out


# ------------------------------------------------------------------------------------------------
# preconditioning
# ------------------------------------------------------------------------------------------------
#: first test a 1 % relaxation, repeated at the end of each sequence: the model-free paired comparison
RELAX_FIRST = [[0] + s + [0] for s in shuffled(5, 1, menu=(1, 2, 3))]


def test_preconditioning_with_a_relaxation_first_is_found_from_its_repeat():
    ctx = make_runs(RELAX_FIRST, first_load=0.25, order_attr=False)  # order from started_at only
    paired = paired_first_load_test(ctx)
    assert paired is not None and paired["n"] == 5 and paired["kinds"] == ["stress_relaxation"]
    assert paired["estimate"] == pytest.approx(np.log(1.25), abs=0.03)
    f = detect_preconditioning(ctx)
    assert f["tested"] and f["p_value"] < 1e-3
    assert f["effect_size"] == pytest.approx(0.25, abs=0.04) and f["practical"]
    assert "elapsed time" in f["evidence"]  # the order was read from the start times


def test_no_preconditioning_on_the_same_design_without_the_effect():
    f = detect_preconditioning(make_runs(RELAX_FIRST, order_attr=False))
    assert f["tested"] and f["p_value"] > 0.01 and abs(f["effect_size"]) < 0.05


#: 8 specimens, one sample each, every test once in a shuffled order: no repeat, the first-load indicator is
#: separated from the condition because each condition comes first on some samples and later on others
SHUFFLED = shuffled(8, 2)


def test_preconditioning_without_any_repeat_from_shuffled_first_tests():
    assert len({s[0] for s in SHUFFLED}) >= 3  # the design: several kinds of first test
    ctx = make_runs(SHUFFLED, first_load=0.25, seed=3)
    assert paired_first_load_test(ctx) is None or paired_first_load_test(ctx)["n"] < 8
    f = detect_preconditioning(ctx)
    assert f["tested"] and f["p_value"] < 1e-3, f["evidence"]
    assert f["effect_size"] == pytest.approx(0.25, abs=0.06)
    assert f["fix"]["gain"] > 0
    null = detect_preconditioning(make_runs(SHUFFLED, seed=3))
    assert null["p_value"] > 0.01


def test_preconditioning_is_not_called_drift():
    # the first load is also the earliest test: drift must be read controlled for it
    ctx = make_runs(SHUFFLED, first_load=0.25, seed=4)
    drift = detect_elapsed_time_drift(ctx)
    assert drift["tested"] and drift["p_value"] > 0.01, drift["evidence"]
    assert detect_preconditioning(ctx)["p_value"] < 1e-3
    # the oracle that the design does confound them: elapsed time alone (sample + condition fixed effects,
    # no first-load control) is significant on the same data
    lv = curve_levels(ctx.table)
    X = pd.get_dummies(lv[["sample", "condition"]], drop_first=True, dtype=float)
    X.insert(0, "elapsed_h", lv["elapsed_h"])
    naive = sm.OLS(lv["log_scale"].to_numpy(float), sm.add_constant(X).to_numpy(float)).fit()
    assert naive.pvalues[1] < 0.01 and naive.params[1] < 0


def test_preconditioning_not_testable_without_order_or_without_repeat():
    no_order = detect_preconditioning(make_runs(SHUFFLED, order_attr=False, started_at=False))
    assert not no_order["tested"] and "order" in no_order["evidence"] and "unknown" in no_order["evidence"]
    same_first = [[0, 1], [0, 1], [0, 1], [0, 1]]  # relaxation 1 % always first, then 5 %: no comparison
    f = detect_preconditioning(make_runs(same_first, first_load=0.25))
    assert not f["tested"] and "a design that would" in f["evidence"]


# ------------------------------------------------------------------------------------------------
# outlier specimen
# ------------------------------------------------------------------------------------------------
def test_outlier_specimen_among_five_is_named():
    # with 5 specimens the deletion t has 3 df: p < 0.005 after Bonferroni over 5 needs |t| > 12.9, i.e. a
    # 2.6x specimen among others whose log-levels scatter by less than about 0.07
    design = [[0, 2, 1] for _ in range(5)]
    f = detect_outlier_specimen(make_runs(design, outlier=2.6, specimen_sd=0.03, sample_sd=0.02, seed=5))
    assert f["tested"] and f["specimen"] == "sp0" and f["n_specimens"] == 5
    assert f["effect_size"] == pytest.approx(2.6, rel=0.15)
    assert f["p_value"] < 0.005 and f["practical"]
    # Bonferroni over the 5 specimens of the two-sided t_3 p-value of the reported statistic
    assert f["p_value"] == pytest.approx(min(1.0, 5 * 2 * sps.t.sf(abs(f["statistic"]), 3)), rel=1e-6)
    assert f["fix"]["gain"] > 0
    null = detect_outlier_specimen(make_runs(design, specimen_sd=0.03, sample_sd=0.02, seed=5))
    assert null["tested"] and null["p_value"] > 0.01


def test_outlier_rows_list_every_specimen_with_the_ratio_this_design_could_name():
    """A 2.4x specimen among 5 whose log-levels scatter by 0.15: not named (3 df), but listed with its ratio and
    deletion t, next to the ratio this design would need; that ratio is what the test names: a specimen 5 % above it
    passes the threshold, 5 % below it does not (the deletion test run again on the levels, moved)."""
    from tissuemech import stats as st
    from tissuemech.diagnosis.covariates import outlier_rows
    from tissuemech.diagnosis.levels import specimen_levels

    ctx = make_runs([[0, 2, 1] for _ in range(5)], outlier=2.4, specimen_sd=0.15, sample_sd=0.02, seed=5)
    f = detect_outlier_specimen(ctx)
    rows = {r["covariate"]: r for r in outlier_rows(ctx, [f], alpha=0.01)}
    assert set(rows) == {f"sp{b}" for b in range(5)} and rows["sp0"]["kind"] == "outlier specimen"
    r = rows["sp0"]
    assert r["ratio"] == pytest.approx(2.4, rel=0.3) and r["deletion_t"] > 2 and not r["named"]
    assert r["ratio_needed"] > r["ratio"] and "this design names an outlier from about" in r["evidence"]
    levels = specimen_levels(curve_levels(ctx.table))
    others = levels.drop("sp0").to_numpy()
    threshold = 0.01 / 2 / 1          # first Holm step of a family of one tested cause
    for factor, named in ((1.05, True), (0.95, False)):
        moved = np.r_[np.log(factor * r["ratio_needed"]) + np.median(others), others]
        assert (st.deletion_outlier_test(moved)["p_value"] < threshold) is named


@pytest.mark.parametrize("n", [1, 2])
def test_outlier_specimen_not_testable_below_three_specimens(n):
    f = detect_outlier_specimen(make_runs([[0, 2]] * n, outlier=3.0))
    assert not f["tested"] and "at least 3 specimens" in f["evidence"]


def test_outlier_specimen_with_three_specimens_is_tested_with_one_df():
    f = detect_outlier_specimen(make_runs([[2, 0], [0, 2], [2, 0]], outlier=2.6, specimen_sd=0.05, seed=6))
    assert f["tested"] and np.isfinite(f["p_value"]) and "on 1 df" in f["evidence"]


def test_outlier_level_is_read_with_condition_effects_removed():
    # specimens measured on different subsets of tests: a condition misfit must not pass for a specimen
    design = [[0, 2], [1, 3], [0, 3], [1, 2], [0, 1, 2, 3]]
    ctx = make_runs(design, outlier=1.0, specimen_sd=0.03, seed=7)
    ctx.table.loc[ctx.table["test"] == "frequency_sweep", "log_ratio"] += np.log(1.8)  # model off on sweeps
    f = detect_outlier_specimen(ctx)
    assert f["p_value"] > 0.01 and f["effect_size"] < 1.2


# ------------------------------------------------------------------------------------------------
# elapsed-time drift
# ------------------------------------------------------------------------------------------------
DRIFT_DESIGN = shuffled(8, 8, menu=(0, 1, 2, 3, 0, 2))


def test_drift_read_from_started_at_without_order_column():
    ctx = make_runs(DRIFT_DESIGN, drift_per_h=0.10, order_attr=False, seed=9)
    lv = curve_levels(ctx.table)
    assert set(lv["order_source"]) == {"elapsed time"}
    f = detect_elapsed_time_drift(ctx)
    assert f["tested"] and f["time_source"] == "elapsed time" and f["effect_size_unit"] == "1/h"
    assert f["p_value"] < 1e-3 and f["effect_size"] == pytest.approx(0.10, abs=0.03)
    null = detect_elapsed_time_drift(make_runs(DRIFT_DESIGN, order_attr=False, seed=9))
    assert null["tested"] and null["p_value"] > 0.01


def test_drift_confounded_with_temperature_names_the_separating_design():
    ctx = make_runs(DRIFT_DESIGN, drift_per_h=0.10, temperature_per_h=3.0, seed=10)
    f = detect_elapsed_time_drift(ctx)
    assert "temperature_c" in f["confounded_with"]
    assert "temperature" in f["evidence"] and "a design that would" in f["evidence"]


def test_drift_without_recorded_time_says_it_is_an_order_effect():
    ctx = make_runs(DRIFT_DESIGN, drift_per_h=0.10, started_at=False, pause_s=900.0, seed=11)
    f = detect_elapsed_time_drift(ctx)
    assert f["tested"] and f["time_source"] == "test order" and f["effect_size_unit"] == "1/test"
    assert "cannot be told from a test-order effect" in f["evidence"]
    assert f["effect_size"] == pytest.approx(0.10 * 900 / 3600, abs=0.015)


def test_drift_in_a_fixed_test_order_is_reported_as_confounded_with_the_condition():
    # the same 4 tests in the same order on 4 samples: elapsed time is the condition up to the random
    # pauses; the slope is reported as confounded with the condition, naming the design that would separate
    fixed = [[0, 1, 2, 3]] * 4
    f = detect_elapsed_time_drift(make_runs(fixed, drift_per_h=0.10, seed=12))
    assert f["tested"] and "condition" in f["confounded_with"] and "randomise the test order" in f["evidence"]
    # the design it names: the same fixed order with the first and an early test repeated at the end separates time
    # from the condition, and the drift is read
    f6 = detect_elapsed_time_drift(make_runs([[0, 1, 2, 3, 0, 2]] * 6, drift_per_h=0.10, seed=12))
    assert f6["tested"] and "condition" not in f6["confounded_with"], f6["evidence"]
    assert f6["p_value"] < 0.01 and f6["effect_size"] == pytest.approx(0.10, abs=0.05)
    shuffled_f = detect_elapsed_time_drift(make_runs(DRIFT_DESIGN, drift_per_h=0.10, seed=12))
    assert "condition" not in shuffled_f["confounded_with"]


def test_the_covariates_table_reads_the_session_clock_as_the_drift_detector_does():
    """One question, one read: on the fixed order with regular pauses (three samples per specimen) the covariates
    table's elapsed-time row is the drift detector's read between the samples of each specimen, with the same slope
    and p-value (before, the table read it with a rule of its own and kept the within-sample read of the pauses'
    jitter wherever the condition did not explain the clock); with one sample per specimen in a fixed order both
    report the same within-sample slope as confounded with the condition and name the design that would separate
    them, and the table leaves it out of the scan for unnamed structure (its t can be infinite on a null design)."""
    from tissuemech.diagnosis.covariates import covariate_tests, curve_frame

    ctx = make_runs([[0, 1, 2, 3]] * 6, drift_per_h=0.10, pause_s=900.0, pause_jitter_s=5.0, samples_per_specimen=3,
                    sample_sd=0.02, seed=21)
    f = detect_elapsed_time_drift(ctx)
    row = next(e for e in covariate_tests(curve_frame(ctx)) if e["covariate"] == "elapsed_time")
    assert f["design"].startswith("between the samples of each specimen")
    assert row["tested"] and row["variation"].startswith("between the samples of each specimen"), row
    assert row["slope"] == pytest.approx(np.log1p(f["effect_size"]), rel=1e-6)   # the detector reports e^slope - 1
    assert row["p_value"] == pytest.approx(f["p_value"], rel=1e-6)
    fixed = make_runs([[0, 1, 2, 3]] * 4, drift_per_h=0.10, seed=12)
    row = next(e for e in covariate_tests(curve_frame(fixed)) if e["covariate"] == "elapsed_time")
    drift = detect_elapsed_time_drift(fixed)
    assert "condition" in drift["confounded_with"]
    assert not row["tested"] and "confounded with the test condition" in row["variation"]
    assert "randomise the test order" in row["evidence"]
    assert row["slope"] == pytest.approx(np.log1p(drift["effect_size"]), rel=1e-6)


def test_outlier_not_testable_when_specimens_share_no_test():
    f = detect_outlier_specimen(make_runs([[0], [1], [2], [3]], outlier=3.0))
    assert not f["tested"] and "confounded" in f["evidence"] and "common test condition" in f["evidence"]


def test_a_creep_curve_has_a_stiffness_level_read_from_its_strain():
    """A creep's measured quantity is its strain: a sample that creeps to 0.8x the predicted strain is 1.25x as stiff
    (the level every level-based detector reads; before, creep curves had no level and drift, first load and outlier
    specimens were untestable on creep-only designs). A relaxation beside it keeps its stress ratio."""
    from tissuemech.diagnosis.findings import curve_levels

    n = 20
    strain = np.linspace(0.01, 0.05, n)
    common = {"specimen": "S1", "sample": "S1/s1", "first_load": 0, "test_order": 1, "frequency_sq": np.nan,
              "strain": strain, "above_noise": True}
    creep = pd.DataFrame({**common, "curve": "c", "test": "creep_recovery", "condition": "stress=20Pa",
                          "quantity": "shear_strain", "log_ratio": np.log(0.8), "elapsed_time": 0.0})
    relax = pd.DataFrame({**common, "curve": "r", "test": "stress_relaxation", "condition": "strain=5%",
                          "quantity": "shear_stress", "log_ratio": np.log(1.1), "elapsed_time": 3600.0})
    levels = curve_levels(pd.concat([creep, relax], ignore_index=True)).set_index("curve")["log_scale"]
    assert levels["c"] == pytest.approx(np.log(1.25))
    assert levels["r"] == pytest.approx(np.log(1.1))


def test_a_clock_that_follows_the_test_order_is_not_read_as_a_covariate_within_samples():
    """One specimen, four samples, the same three tests in the same order with equal pauses (clock jitter of 0.1 s), a misfit that
    differs by test and no drift: within samples the clock is the condition, so the covariates table must not read
    the condition's misfit as a clock effect (it did: a slope of thousands per hour at t = inf on a development
    null). It is read between samples instead, where there is no trend."""
    from tissuemech.diagnosis.covariates import covariate_tests

    rng = np.random.default_rng(5)
    rows = []
    for k in range(4):
        start = [0.3, 5.1, 2.2, 7.9][k]
        offset = 0.05 * rng.standard_normal()
        for j, (cond, misfit) in enumerate((("a", 0.00), ("b", 0.03), ("c", -0.02))):
            rows.append({"curve": f"s{k}_{cond}", "specimen": "S1", "sample": f"S1/s{k}",
                         "test": "stress_relaxation", "condition": cond,
                         "log_scale": misfit + offset + 0.002 * rng.standard_normal(),
                         "elapsed_time": start + 0.1 * j + 0.1 / 3600 * rng.standard_normal(),
                         "position": j + 1.0, "first_load": float(j == 0)})
    lv = pd.DataFrame(rows)
    entry = next(e for e in covariate_tests(lv) if e["covariate"] == "elapsed_time")
    # read within samples, the slope is the level noise over the clock jitter: 5.5 per hour here
    assert entry["tested"] and "between the samples" in entry["variation"] and abs(entry["slope"]) < 0.05, entry
    assert entry["p_value"] > 0.01


def test_drift_in_a_fixed_order_with_regular_pauses_is_read_between_the_samples_of_a_specimen():
    """Every sample runs the same 4 tests in the same order with 15-minute pauses, three samples per specimen one
    after the other: within a sample the clock is the condition, so the drift can only be read from the later
    samples of a specimen being stiffer. Before, the within-sample read took the slope from the pauses' few seconds
    of jitter (hundreds per hour, never significant); the between-samples read recovers the truth's 10 %/h."""
    design = [[0, 1, 2, 3]] * 6
    f = detect_elapsed_time_drift(make_runs(design, drift_per_h=0.10, pause_s=900.0, pause_jitter_s=5.0,
                                            samples_per_specimen=3, sample_sd=0.02, seed=21))
    assert f["tested"] and f["design"].startswith("between the samples of each specimen"), f["evidence"]
    assert f["p_value"] < 1e-3 and f["effect_size"] == pytest.approx(0.10, abs=0.03)
    assert "condition" not in f["confounded_with"]
    null = detect_elapsed_time_drift(make_runs(design, pause_s=900.0, pause_jitter_s=5.0, samples_per_specimen=3,
                                               sample_sd=0.02, seed=21))
    assert null["tested"] and null["p_value"] > 0.01 and abs(null["effect_size"]) < 0.05
