"""CI subset of the diagnosis calibration (issue #12 item 7; full study: benchmarks/diagnosis_calibration.py).

* the independent generator (benchmarks/independent_rheometer.py) against independent oracles: the torque
  integral of a linear material, closed-form Prony ramp-and-hold responses, the Mittag-Leffler function at
  alpha = 1 (exp) and alpha = 1/2 (erfcx), the fractional-Zener complex modulus, small-strain slopes;
* the run contract (canonical variables, required attributes, reproducibility, no package physics imported);
* a handful of small seeded null datasets on which the diagnosis must name nothing;
* the dataset folders of the pipeline-path calibration: creep through the plate's torque balance against closed
  forms, the round trip of every export format and unit through the package's ingest, the spread of designs;
* the CI subset of the pipeline-path calibration (slow): 20 null folders and one folder per cause through
  ``tissuemech.analysis.analyse_dataset`` (benchmarks/pipeline_calibration.py; docs/calibration.md).
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.special import erfcx

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import independent_rheometer as ir  # noqa: E402
from diagnosis_calibration import alarms, diagnose_runs  # noqa: E402

from tissuemech.canonical import CANONICAL_VARIABLES, REQUIRED_RUN_ATTRS  # noqa: E402


# ------------------------------------------------------------------------------------------ oracles
def test_torque_of_linear_material_is_g_theta_pi_r4_over_2h():
    g_mod, theta, radius, gap = 850.0, 0.013, 0.0125, 0.0021
    torque = ir.plate_torque(lambda r: ir.shear_law("neo_hookean", theta * r / gap, g_mod, {}), radius)
    assert torque.item() == pytest.approx(g_mod * theta * np.pi * radius ** 4 / (2 * gap), rel=1e-12)
    # the reported stress 2M/(pi R^3) is then the rim stress G theta R / h
    assert 2 * torque.item() / (np.pi * radius ** 3) == pytest.approx(g_mod * theta * radius / gap, rel=1e-12)


def test_torque_of_cubic_stress_needs_the_radial_integral():
    # tau = c gamma^3 at gamma = gamma_R r/R: M = 2 pi c gamma_R^3 R^3 / 6, i.e. reported stress = (2/3) c gamma_R^3
    c, g_r, radius = 1e4, 0.3, 0.008
    torque = ir.plate_torque(lambda r: c * (g_r * r / radius) ** 3, radius)
    assert 2 * torque.item() / (np.pi * radius ** 3) == pytest.approx(2.0 / 3.0 * c * g_r ** 3, rel=1e-12)


def test_prony_ramp_and_hold_matches_closed_form():
    g_inf, g, tau = 0.3, np.array([0.5, 0.2]), np.array([0.002, 40.0])
    k = ir.prony_kernel(g_inf, g, tau)
    rise, e0 = 0.1, 200.0   # elastic stress ramps linearly to e0 [Pa] over rise [s]
    t = np.unique(np.r_[np.linspace(0, rise, 50), rise + np.geomspace(1e-5, 5000.0, 200)])
    te = e0 * np.clip(t / rise, 0, 1)
    s = ir.qlv_stress(t, te, k)
    hold = t > rise
    # Boltzmann integral of a linear ramp:
    # g_inf e0 + sum g_i e0 tau_i/rise (1 - exp(-rise/tau_i)) exp(-(t - rise)/tau_i)
    decay = np.exp(-(t[hold] - rise)[:, None] / tau)
    exact = g_inf * e0 + (e0 / rise * g * tau * -np.expm1(-rise / tau) * decay).sum(1)
    np.testing.assert_allclose(s[hold], exact, rtol=1e-10)
    assert s[-1] == pytest.approx(g_inf * e0, rel=1e-6)          # t -> inf: the equilibrium part only


def test_prony_step_gives_instantaneous_stress_then_relaxes():
    k = ir.prony_kernel(0.25, np.array([0.45, 0.3]), np.array([0.001, 1000.0]))
    t = np.array([0.0, 1e-12, 1e-9, 1e6])
    s = ir.qlv_stress(t, np.array([0.0, 1.0, 1.0, 1.0]), k)
    assert s[1] == pytest.approx(1.0, rel=1e-8)               # t = 0+: g(0) = g_inf + sum g_i = 1
    assert s[-1] == pytest.approx(0.25, rel=1e-8)              # t -> inf: g_inf
    np.testing.assert_allclose(k.relax(np.array([0.0, 1e7])), [1.0, 0.25])


def test_mittag_leffler_alpha_one_is_exp_and_alpha_half_is_erfcx():
    x = np.r_[0.0, np.geomspace(1e-4, 50.0, 40)]
    np.testing.assert_allclose(ir.mittag_leffler_neg(1.0, x), np.exp(-x), rtol=1e-12, atol=1e-300)
    # E_{1/2}(-x) = exp(x^2) erfc(x) (Gorenflo & Mainardi): both branches (series x <= 1,
    # spectrum x > 1, whose tails are cut at 1e-9 absolute)
    x = np.geomspace(1e-3, 1e3, 60)
    np.testing.assert_allclose(ir.mittag_leffler_neg(0.5, x), erfcx(x), rtol=1e-7, atol=2e-9)


def test_mittag_leffler_series_and_spectrum_agree_at_the_switch():
    for alpha in (0.2, 0.5, 0.8):
        r, w = ir.ml_spectrum(alpha)
        series = ir.mittag_leffler_neg(alpha, np.array([1.0]))[0]
        assert np.exp(-r) @ w == pytest.approx(series, rel=1e-7)


def test_fractional_kernel_matches_closed_form_modulus_and_ml_relaxation():
    k = ir.fractional_kernel(0.2, 0.4, 0.5)
    t = np.geomspace(1e-4, 1e4, 30)
    np.testing.assert_allclose(k.relax(t), 0.2 + 0.8 * ir.mittag_leffler_neg(0.4, (t / 0.5) ** 0.4), rtol=1e-6)
    # the dense spectrum's Prony modulus vs the closed form G_inf + dG (iwt)^a / (1 + (iwt)^a)
    w = np.geomspace(1e-3, 1e3, 20)
    dense = ir.Kernel(k.g_inf, k.g, k.tau).complex_modulus(w)
    np.testing.assert_allclose(dense, k.complex_modulus(w), rtol=1e-6)


@pytest.mark.parametrize("law,p", [("neo_hookean", {}), ("mooney_rivlin", {"c01_share": 0.4}),
                                   ("ogden1", {"alpha": -7.0}), ("gent", {"jm": 0.8}), ("exponential", {"b": 1.5})])
def test_every_law_has_small_strain_modulus_mu(law, p):
    assert ir.shear_law(law, np.array([1e-7]), 500.0, p)[0] / 1e-7 == pytest.approx(500.0, rel=1e-6)


def test_ogden_alpha_two_is_neo_hookean_and_gent_stiffens():
    g = np.linspace(0, 0.8, 9)
    np.testing.assert_allclose(ir.shear_law("ogden1", g, 300.0, {"alpha": 2.0}), 300.0 * g, rtol=1e-12, atol=1e-12)
    assert ir.shear_law("gent", np.array([0.5]), 1.0, {"jm": 1.0})[0] == pytest.approx(0.5 / 0.75)


def test_first_harmonic_factor_matches_the_series_of_each_law():
    """The sweeps' amplitude factor: first Fourier sine coefficient of the law's stress under gamma0 r/R sin(th),
    integrated over the plate, over the linear law's. For sigma = mu gamma (1 + c gamma^2 + e gamma^4 + ...) the
    sine coefficients of sin^3 and sin^5 are 3/4 and 5/8 and the plate weights of gamma^3 and gamma^5 are
    int x^5 / int x^3 = 2/3 and int x^7 / int x^3 = 1/2, so the factor is
    1 + c gamma0^2 / 2 + 5 e gamma0^4 / 16 + O(gamma0^6)
    (below 1e-6 at gamma0 <= 0.1 here)."""
    g0 = np.array([0.02, 0.05, 0.1])
    np.testing.assert_allclose(ir.first_harmonic_factor("neo_hookean", g0, {}), 1.0, rtol=1e-12)
    b = 2.0   # exponential: mu gamma exp(b gamma^2) -> c = b, e = b^2 / 2
    np.testing.assert_allclose(ir.first_harmonic_factor("exponential", g0, {"b": b}),
                               1 + b * g0 ** 2 / 2 + 5 * (b * b / 2) * g0 ** 4 / 16, rtol=1e-6)
    jm = 0.8  # Gent: mu gamma / (1 - gamma^2/jm) -> c = 1/jm, e = 1/jm^2
    np.testing.assert_allclose(ir.first_harmonic_factor("gent", g0, {"jm": jm}),
                               1 + g0 ** 2 / (2 * jm) + 5 * g0 ** 4 / (16 * jm * jm), rtol=2e-6)


# ------------------------------------------------------------------------------------------ contract
def test_generator_imports_no_package_physics():
    tree = ast.parse((ROOT / "benchmarks" / "independent_rheometer.py").read_text())
    mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} | {
        a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not {m for m in mods if m and m.startswith(("tissuemech.synth", "tissuemech.models", "tissuemech.fitting"))}
    assert {m for m in mods if m and m.startswith("tissuemech")} == {"tissuemech.canonical"}


def test_generated_runs_follow_the_run_contract_and_are_reproducible():
    runs, truth = ir.generate(107)
    again, _ = ir.generate(107)
    assert len(runs) == len(again) > 0
    for r, q in zip(runs, again):
        assert set(REQUIRED_RUN_ATTRS) <= set(r.attrs)
        assert set(r.data_vars) <= set(CANONICAL_VARIABLES)
        assert r.attrs["radius_m"] == pytest.approx(truth["radius_mm"] * 1e-3)
        np.testing.assert_array_equal(r["shear_stress"].values, q["shear_stress"].values)
        # the reported stress is the instrument's 2M/(pi R^3)
        np.testing.assert_allclose(r["shear_stress"], 2 * r["torque"] / (np.pi * r.attrs["radius_m"] ** 3)
                                   if r.attrs["test"] in ("constant_shear_rate", "stress_relaxation")
                                   else r["shear_stress"])
    assert 4.0 <= truth["radius_mm"] <= 25.0 and all(1.0 <= g <= 4.0 for g in truth["gap_mm"])
    assert 0.002 <= truth["noise_rel"] <= 0.03


def test_designs_vary_order_subset_and_counts():
    firsts, counts, laws = set(), set(), set()
    for seed in range(40):
        rng = np.random.default_rng(seed)
        laws.add(ir.draw_truth(rng).law)
        design = ir.draw_design(rng, {})
        firsts.add(design[0]["tests"][0][0])
        counts.add(len({d["specimen"] for d in design}))
    assert firsts == set(ir.TESTS)            # any test can come first
    assert counts == set(range(1, 7)) and laws == set(ir.LAWS)


def test_preconditioning_makes_the_first_test_of_each_sample_stiffer():
    base, _ = ir.generate(112)
    pre, _ = ir.generate(112, {"preconditioning": 1.0})
    ratio = {(r.attrs["specimen"], r.attrs["sample"], r.attrs["order"]):
             float(np.median(p["shear_stress"] / r["shear_stress"])) for r, p in zip(base, pre)}
    firsts = [v for k, v in ratio.items() if k[2] == 1]
    later = [v for k, v in ratio.items() if k[2] > 1]
    assert firsts and later
    np.testing.assert_allclose(firsts, 1.3, rtol=0.1)            # 30 % at 1x (same noise draw, hence ~exact)
    np.testing.assert_allclose(later, 1.0, rtol=1e-9)


def test_elapsed_time_drift_scales_moduli_with_the_session_clock():
    base, _ = ir.generate(129)
    drift, _ = ir.generate(129, {"elapsed_time_drift": 2.0})
    for r, d in zip(base, drift):
        hours = float(r["total_time"][0] - r["time"][0]) / 3600.0       # the session clock at the test start
        q = "storage_modulus" if "storage_modulus" in r else "shear_stress"
        # same seed, same noise draws: the ratio is the drift factor 1 + 2 x 10 %/h (up to the torque floor)
        assert float(np.median(d[q] / r[q])) == pytest.approx(1.0 + 0.2 * hours, rel=1e-2)


def test_unknown_effect_is_refused_by_name():
    with pytest.raises(ValueError, match="unknown effects \\['gravity'\\]"):
        ir.generate(1, {"gravity": 1.0})


# ------------------------------------------------------------------------------------------ null diagnosis
#: small seeded null datasets (4-10 runs each) whose truths and designs differ from the project's generator
NULL_SEEDS = [107, 112, 103, 124, 129]
#: seeds on which the current diagnosis raises something (measured; see docs/calibration.md). A detected
#: ``baseline_inadequate`` is not a cause and does not fail the test (diagnosis_calibration.NOT_A_CAUSE).
#: Seed 129 (one-term Ogden alpha -13.6, modes at 15 ms-609 s) raised 9 unexplained entries under the fixed
#: linear-law baseline; with the law chosen by AICc (report.RUNS_BASELINE_CANDIDATES) it names nothing.
XFAIL_NULL: dict[int, str] = {}


@pytest.mark.parametrize("seed", [pytest.param(s, marks=pytest.mark.xfail(reason=XFAIL_NULL[s], strict=False))
                                  if s in XFAIL_NULL else s for s in NULL_SEEDS])
def test_null_dataset_names_nothing(seed):
    runs, truth = ir.generate(seed)
    detected, unexplained = alarms(diagnose_runs(runs))
    assert detected == [] and unexplained == [], f"{truth['law']}/{truth['kernel']}: {detected} {unexplained}"



def test_the_times_fitted_with_the_model_leave_no_ratio_at_its_bound():
    """Null seed 20266011 (development seed of docs/calibration.md; Ogden truth, one mode at 167 s): on its NNLS
    times the Ogden candidate left the ratio of a 704 s time -- beyond what the relaxations resolve -- at its upper
    bound, and was refitted without that time. With the times fitted with the model (within half a decade of the
    NNLS times), the first fit is adequate, its faster time is the truth's within 10 %, and nothing is named."""
    runs, truth = ir.generate(20266011)
    result = diagnose_runs(runs)
    assert result["model"] == "qlv_ogden1_prony4" and len(result["baseline"]["tried"]) == 1
    assert result["baseline"]["tried"][0]["adequate"]
    taus = result["fit_info"]["taus_s"]
    assert "times then fitted with the model" in result["fit_info"]["relaxation_times"]["method"]
    assert min(taus) == pytest.approx(truth["modes"]["tau_s"][0], rel=0.1) and max(taus) < 704
    assert alarms(result) == ([], [])


# ------------------------------------------------------------------------------------ baseline spectrum
@pytest.mark.parametrize("seed", [20261199, 20261184])
def test_nnls_relaxation_times_find_the_generators_modes(seed):
    """The baseline's relaxation times come from the data (issue #12 item 2): NNLS on a dense grid over the
    resolved window puts an active time within 0.3 decade of every mode of the independent generator's Prony
    truth that carries >= 5 % of the modulus and lies inside the window. Seed 20261199 has two modes at 33 and
    43 ms, between the decades of a one-per-decade grid (which left -3 % structure along the predicted level);
    seed 20261184 has modes at 26, 43 and 477 s."""
    from tissuemech.diagnosis.baseline import nnls_relaxation_times, resolved_window_s

    runs, truth = ir.generate(seed, None)
    assert truth["kernel"] == "prony"
    fitted = [r for r in runs if r.attrs["test"] in ("constant_shear_rate", "stress_relaxation")]
    window = resolved_window_s(fitted)
    found = nnls_relaxation_times(fitted, "torque", "measured", window)
    active = np.log10(found["taus_s"])
    assert 0 < active.size < found["grid_s"].size / 2  # sparse: the support of the spectrum, not the grid
    for g, tau in zip(truth["modes"]["g"], truth["modes"]["tau_s"]):
        if g < 0.05 or not window["t_min_s"] <= tau <= window["t_max_s"]:  # g: share of the reduced function
            continue
        assert np.min(np.abs(active - np.log10(tau))) <= 0.3, (tau, found["taus_s"])


def test_nonseparable_relaxation_is_named_in_a_design_with_two_shear_rates():
    """Power case of the independent generator (seed 20366124: 2 specimens, 2 CSR rates, relaxations at 11.7 %
    and 34 %, relaxing weights x (1 + 4|gamma|) at 2x): the Pipkin-Rogers fix cannot be scored on held-out
    rates (fewer than 3), so it is scored on the relaxations at the lowest and highest strain, and the cause is
    named with a held-out gain (before this fold choice the fix was never evaluated and nothing was named)."""
    runs, truth = ir.generate(20366124, {"nonseparable_relaxation": 2.0})
    rates = {r.attrs["shear_rate_1_per_s"] for r in runs if r.attrs["test"] == "constant_shear_rate"}
    assert len(rates) < 3
    result = diagnose_runs(runs)
    found = next(f for f in result["findings"] if f["effect"] == "nonseparable_relaxation")
    assert found["detected"], found
    assert found["fix"]["model"].startswith("pr_") and "relaxation at" in found["fix"]["cv"]
    assert found["fix"]["gain"] > 0.05


@pytest.mark.parametrize("seed", [20261217, 20262036])
def test_nnls_levels_recover_the_generators_specimen_stiffness(seed):
    """One modulus level per loaded piece (specimen/sample) alternates with NNLS, so that the baseline fits the
    shape common to all pieces. Averaged per specimen and centred, the log levels match the independent
    generator's specimen log factors (sample log-SD 0.05 on top) within 0.1; seed 20261217 has two specimens
    0.66 apart in log, seed 20262036 four specimens with one 0.25 below the others."""
    from tissuemech.diagnosis.baseline import nnls_relaxation_times, resolved_window_s

    runs, truth = ir.generate(seed, None)
    fitted = [r for r in runs if r.attrs["test"] in ("constant_shear_rate", "stress_relaxation")]
    levels = nnls_relaxation_times(fitted, "torque", "measured", resolved_window_s(fitted))["levels"]
    assert all(isinstance(u, str) for u in levels)
    est = {}
    for unit, level in levels.items():
        est.setdefault(unit.split("/")[0], []).append(np.log(level))
    est = {k: np.mean(v) for k, v in est.items()}
    true = truth["specimens"]["log_factor"]
    e_mean, t_mean = np.mean(list(est.values())), np.mean([true[k] for k in est])
    for k in est:
        assert abs((est[k] - e_mean) - (true[k] - t_mean)) < 0.1, (k, est, true)


def test_a_pair_of_neighbouring_active_grid_times_merges_into_one_time():
    """One mode between two grid times shows in NNLS as weight on both neighbours: one time at the
    weight-averaged log time (hand-computed geometric mean); a band of three or more active times (a broad,
    e.g. fractional, spectrum) and isolated times are kept."""
    from tissuemech.material import merged_times

    grid = np.array([0.1, 0.2, 0.4, 1.0, 10.0, 20.0, 40.0, 80.0])
    weights = np.array([0.0, 1.0, 3.0, 0.0, 2.0, 2.0, 1.0, 0.0])
    merged = merged_times(grid, weights)
    assert merged == pytest.approx([(0.2 * 0.4 ** 3) ** 0.25, 10.0, 20.0, 40.0])
    assert merged_times(grid, np.r_[1.0, np.zeros(7)]) == pytest.approx([0.1])
    assert merged_times(grid, np.zeros(8)).size == 0


# ------------------------------------------------------------------------------------ power on other designs
# (seed, cause, truth of the effect size read from the generator's own constants or its record of what it
# injected, tolerance: absolute for the drift per hour, relative otherwise); the designs are the independent
# generator's (not the virtual rheometer's): power-study seeds at 1x
OTHER_DESIGNS = [
    (20461123, "elapsed_time_drift", lambda truth: ir.EFFECT_SIZES["elapsed_time_drift"]["per_hour"], 0.05),
    (20468123, "instrument_inertia",
     lambda truth: ir.EFFECT_SIZES["instrument_inertia"]["calibration_error"] * truth["motor_inertia_kg_m2"], 0.1),
    # six relaxations at two strains on one sample of an Ogden truth with a fractional kernel; uN m
    (20472128, "torque_offset", lambda truth: 1e6 * truth["injected"]["torque_offset_nm"], 0.1),
]


@pytest.mark.parametrize("seed, cause, size, tol", OTHER_DESIGNS, ids=[c for _, c, _, _ in OTHER_DESIGNS])
def test_cause_injected_in_another_labs_design_is_named_with_its_size(seed, cause, size, tol):
    """The hidden-effect suite on designs other than ours: the independent generator injects the cause at 1x;
    it is named (significant, practical, held-out gain beyond the margin), nothing else is blamed, and its size
    matches the generator's (drift per hour absolute; inertia error and offset torque relative). The offset is
    named only through its model-level fix: the baseline refitted without it predicts held-out strains better."""
    runs, truth = ir.generate(seed, {cause: 1.0})
    result = diagnose_runs(runs)
    named = [f["effect"] for f in result["findings"] if f.get("detected")]
    facts = {"baseline_inadequate", "inertia_dominated_points"}  # statements about the baseline / raw channels
    assert [e for e in named if e not in facts] == [cause], named
    f = next(f for f in result["findings"] if f["effect"] == cause)
    assert f["fix"]["beats_margin"] and f["fix"]["gain"] > 0
    expected = size(truth)
    rel = tol / expected if cause == "elapsed_time_drift" else tol
    assert f["effect_size"] == pytest.approx(expected, rel=rel), (f["effect_size"], expected)


# ------------------------------------------------------------------------------ dataset folders (pipeline input)
def _linear_truth(g_inf, g, tau, mu=1000.0, radius=0.0125, gap=2e-3, law="neo_hookean", law_params=None):
    kernel = ir.prony_kernel(g_inf, np.asarray(g, float), np.asarray(tau, float))
    return ir.Truth(law, law_params or {}, mu, kernel, radius_m=radius, gap_m=[gap], noise_rel=0.01,
                    torque_floor_nm=1e-9, motor_inertia=2e-5, temperature_c=20.0), kernel


def test_creep_of_a_standard_linear_solid_is_its_creep_compliance():
    """Stress ramped to sigma over 10 ms, then held, on a linear standard linear solid (G0 = mu, G_inf = 0.4 mu,
    tau = 2 s): the torque balance gives gamma(t) = sigma/r int_0^min(t, r) J(t - s) ds with the closed-form
    compliance J(t) = 1/G_inf - (1/G_inf - 1/G0) exp(-t/tau_ret), tau_ret = tau G0/G_inf (a linear plate: the
    apparent stress 2M/(pi R^3) is the rim stress)."""
    mu, g_inf, tau, rise, sigma = 1000.0, 0.4, 2.0, 0.01, 50.0
    truth, kernel = _linear_truth(g_inf, [1 - g_inf], [tau], mu=mu)
    t = np.unique(np.r_[np.linspace(0, rise, 21), rise + np.geomspace(1e-5, 100.0, 400)])
    torque = sigma * np.pi * truth.radius_m ** 3 / 2 * np.clip(t / rise, 0, 1)
    strain = ir.creep_response(t, torque, truth, kernel, 1.0, 2e-3, {})
    g0, g_eq = mu, mu * g_inf
    t_ret = tau * g0 / g_eq
    integral = lambda u: u / g_eq + (1 / g_eq - 1 / g0) * t_ret * np.exp(-u / t_ret)  # noqa: E731 (int J du)
    exact = sigma / rise * (integral(t) - integral(np.maximum(t - rise, 0.0)))
    np.testing.assert_allclose(strain[1:], exact[1:], rtol=1e-4)
    assert strain[-1] == pytest.approx(sigma / g_eq, rel=1e-6)


def test_creep_ringing_of_an_elastic_sample_is_the_undamped_oscillator():
    """An elastic sample (no relaxation) under a torque ramped over 2 ms, with rotor inertia I: I theta'' + K theta
    = M(t), K = G pi R^4/(2h); the ramp response theta = M0/(K r) (t - sin(wt)/w) for t <= r and
    M0/(K r) (r - (sin wt - sin w(t - r))/w) after, w^2 = K/I (the Newmark rule adds no damping)."""
    mu, radius, gap, inertia, rise, m0 = 1000.0, 0.0125, 2e-3, 2e-5, 0.002, 1e-4
    truth, kernel = _linear_truth(1.0, [0.0], [1.0], mu=mu, radius=radius, gap=gap)
    stiffness = mu * np.pi * radius ** 4 / (2 * gap)
    w = np.sqrt(stiffness / inertia)
    t = np.arange(0.0, 0.5, 2 * np.pi / w / 200)
    strain = ir.creep_response(t, m0 * np.clip(t / rise, 0, 1), truth, kernel, 1.0, gap, {}, inertia=inertia)
    a = m0 / (stiffness * rise)
    exact = np.where(t <= rise, a * (t - np.sin(w * t) / w), a * (rise - (np.sin(w * t) - np.sin(w * (t - rise))) / w))
    assert np.max(np.abs(strain * gap / radius - exact)) < 1e-3 * np.max(exact)


def _runs_by_key(runs_dir):
    from tissuemech.pipeline import load_runs

    return {(r.attrs["specimen"], r.attrs["sample"], r.attrs["test"], int(r.attrs["order"])): r
            for r in load_runs(runs_dir)}


#: seeds whose folders cover the three export formats, the three torque units, Hz and rad/s, strain in % and 1,
#: and the three places the geometry is stated (sample sheet, dataset.yaml, export)
ROUND_TRIP_SEEDS = [70, 77, 172, 51, 58]


@pytest.mark.parametrize("seed", ROUND_TRIP_SEEDS)
def test_dataset_folder_round_trips_through_ingest(seed, tmp_path):
    """The folder is what a user drops in raw/: the package's ingest reads every export (RheoCompass UTF-16 with
    decimal commas, RheoCompass UTF-8 with the project header, TRIOS text with one step per test) and returns the
    generated channels in SI (7 printed digits), the plate radius and gap from wherever the design states them."""
    from tissuemech.io.ingest import ingest_dataset

    records, truth, design = ir.simulate_folder(seed, None, f"rt{seed}")
    ir.write_dataset_folder(seed, tmp_path / "raw" / f"rt{seed}")
    assert (tmp_path / "raw" / f"rt{seed}.truth.json").is_file()        # beside the folder, not in it
    report = ingest_dataset(tmp_path / "raw" / f"rt{seed}", tmp_path / "runs", tmp_path / "report.csv")
    assert (report["status"] == "ok").all(), report[report["status"] != "ok"].to_dict("records")
    runs = _runs_by_key(tmp_path / "runs")
    assert len(runs) == len(records)
    for rec in records:
        m = rec["meta"]
        run = runs[(m["specimen"], m["sample"], m["test"], m["order"])]
        assert run.attrs["radius_m"] == pytest.approx(truth["radius_mm"] * 1e-3, rel=1e-9)
        assert run.attrs["gap_m"] == pytest.approx(m["gap_m"], rel=1e-3)
        for name, values in rec["channels"].items():
            twin = {"frequency": ("angular_frequency", 2 * np.pi), "angular_frequency": ("frequency", 0.5 / np.pi)}
            if name not in run and name in twin:      # the export writes one of Hz and rad/s
                name, values = twin[name][0], values * twin[name][1]
            got = run[name].values
            scale = np.max(np.abs(values))
            np.testing.assert_allclose(got, values, rtol=1e-6, atol=1e-6 * scale, err_msg=f"{name} of {m}")
    assert {r.attrs["format"] for r in runs.values()} == {
        {"trios_text": "ta_trios_text"}.get(design["format"], "anton_paar_rheocompass")}


def test_folder_designs_vary_every_choice_a_detector_could_key_on():
    seen = {k: set() for k in ("family", "layout", "days", "order", "format", "torque_unit", "frequency_unit",
                               "strain_unit", "geometry_source", "n_specimens", "first_test")}
    for seed in range(120):
        rng = np.random.default_rng(seed)
        ir.draw_truth(rng)
        rng.choice(ir.PLATE_DIAMETERS_MM)
        d = ir.draw_folder_design(rng, {})
        for k in seen:
            if k == "first_test":
                seen[k].add(ir._sample_tests(d, rng)[0][0])
            else:
                seen[k].add(d[k])
    assert seen["family"] == set(ir.FAMILIES) and seen["layout"] == {"blocks", "interleaved"}
    assert seen["days"] == {1, 2, 3} and seen["order"] == {"random", "fixed"}
    assert seen["format"] == set(ir.FORMATS) and seen["torque_unit"] == set(ir.TORQUE_UNITS)
    assert seen["frequency_unit"] == {"Hz", "rad/s"} and seen["strain_unit"] == {"%", "1"}
    assert seen["geometry_source"] == {"samples", "yaml", "export"}
    assert seen["n_specimens"] == set(range(1, 9)) and seen["first_test"] == set(ir.FOLDER_TESTS)


@pytest.mark.parametrize("effect", ir.FOLDER_EFFECTS)
def test_power_designs_hold_a_test_that_shows_the_effect(effect):
    for seed in range(25):
        rng = np.random.default_rng(seed)
        d = ir.draw_folder_design(rng, {effect: 1.0})
        assert set(d["kinds"]) & set(ir.SHOWN_BY[effect]), (seed, d["kinds"])
        assert sum(d["samples_per_specimen"]) >= ir.MIN_SAMPLES.get(effect, 1)
        if effect == "outlier_specimen":
            assert 4 <= d["n_specimens"] <= 6


def test_creep_ringing_makes_the_creep_strain_oscillate():
    """Seed 20 (creep only): the null creep strain rises monotonically (up to noise) during the hold; with the motor
    inertia in the torque balance the same creep overshoots and rings (a falling strain beyond the noise)."""
    def creep_strains(effects):
        records, truth, _ = ir.simulate_folder(20, effects)
        rec = next(r for r in records if r["meta"]["test"] == "creep_recovery")
        return rec["channels"]["shear_strain"], truth

    null, truth = creep_strains(None)
    ring, _ = creep_strains({"creep_ringing": 2.0})
    half = null.size // 2
    noise = 4 * truth["noise_rel"] * np.abs(null[:half])
    assert np.all(np.diff(null[:half]) > -noise[1:])
    assert np.any(np.diff(ring[:half]) < -noise[1:])


def test_temperature_spread_and_preload_show_only_in_the_logged_channels():
    """The temperature spread moves the logged temperature (not the sample sheet's nominal one) by up to 4 K at 1x,
    and the preload scales each sample's moduli as (F / 0.1 N)^0.15 with F its logged normal force; the nulls log
    the same kind of channels (a preload without effect, a temperature within 0.1 K)."""
    def by_key(effects):
        records, _, design = ir.simulate_folder(436, effects)
        return {(r["meta"]["specimen"], r["meta"]["sample"], r["meta"]["order"]): r for r in records}, design

    null, design = by_key(None)
    assert design["logs_normal_force"]
    spread, _ = by_key({"temperature_spread": 1.0})
    preload, _ = by_key({"normal_force_preload": 1.0})
    for key, rec in null.items():
        assert abs(float(np.median(rec["channels"]["temperature"])) - rec["meta"]["temperature_c"]) < 0.15
        moved = spread[key]
        assert moved["meta"]["temperature_c"] == rec["meta"]["temperature_c"]
        assert abs(moved["meta"]["temperature_logged_c"] - rec["meta"]["temperature_c"]) <= 4.0
        f_n = preload[key]["meta"]["preload_n"]
        q = "storage_modulus" if "storage_modulus" in rec["channels"] else "shear_stress"
        ratio = float(np.median(preload[key]["channels"][q] / null[key]["channels"][q]))
        assert ratio == pytest.approx((f_n / 0.1) ** 0.15, rel=0.02)


# ------------------------------------------------------------------- CI subset of the pipeline-path calibration
# Seeds never used in development (benchmarks/pipeline_calibration.DEVELOPMENT_SEEDS lists them so that no
# calibration run reuses them): 20 null folders and one folder per cause at 1x, each analysed by the pipeline's path
# (tissuemech.analysis.analyse_dataset through pipeline_calibration.one) with the repository's configuration but one
# fit start per model instead of three (the fits are 80-90 % of a dataset's time; multistart 1 saves 25-35 %).
# Measured 2026-11-28 on the shared 2-core machine (load 5-10): 7-180 s per dataset, median 31 s with multistart 3.
CI_NULL_SEEDS = [32500000 + i for i in range(20)]
CI_CAUSE_SEEDS = {e: 32600000 + 1000 * k for k, e in enumerate(ir.FOLDER_EFFECTS)}


@pytest.fixture(scope="module")
def pipeline_config():
    import yaml

    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    config["fit"]["multistart"] = 1
    return config


def _ci_design(seed, effects):
    rng = np.random.default_rng(seed)
    ir.draw_truth(rng)
    rng.choice(ir.PLATE_DIAMETERS_MM)
    return ir.draw_folder_design(rng, effects)


def test_ci_subset_spans_designs():
    """The CI subset's seeds are outside every seed range a calibration run may use, the cause folders cover at
    least three test families and the nulls all five."""
    from pipeline_calibration import DEVELOPMENT_SEEDS

    for s in CI_NULL_SEEDS + list(CI_CAUSE_SEEDS.values()):
        assert any(a <= s <= b for a, b in DEVELOPMENT_SEEDS)
    assert len({_ci_design(s, {e: 1.0})["family"] for e, s in CI_CAUSE_SEEDS.items()}) >= 3
    assert {_ci_design(s, {})["family"] for s in CI_NULL_SEEDS} == set(ir.FAMILIES)


def _what(row: dict) -> str:
    """One line on a CI-subset dataset: its design, truth, baseline and what the diagnosis said."""
    d = row["design"]
    return (f"{d['family']} {d['kinds']}, {d['n_specimens']} specimens / {d['n_samples']} samples; truth "
            f"{row['law']}/{row['kernel']}; diagnosed on {row['diagnosis_scope']} with {row['model']}; "
            f"verdict {row.get('verdict')}; detected {row['detected']}; unexplained {row['unexplained']}")


@pytest.mark.slow
@pytest.mark.calibration
@pytest.mark.parametrize("seed", CI_NULL_SEEDS)
def test_pipeline_path_names_nothing_on_a_null_folder(seed, tmp_path, pipeline_config):
    """No detected cause, no unexplained entry, no rejected export and no crash on a null dataset folder (the
    family-wise false-alarm count of the 20 is the number of these cases that fail; the target rate is 1 %)."""
    from pipeline_calibration import one

    row = one((None, 0.0, seed), tmp_path, pipeline_config)
    assert row["error"] is None, row.get("trace", row["error"])
    assert row["detected"] == [] and row["unexplained"] == [], _what(row)


@pytest.mark.slow
@pytest.mark.calibration
@pytest.mark.parametrize("effect", list(CI_CAUSE_SEEDS))
def test_pipeline_path_names_the_injected_cause(effect, tmp_path, pipeline_config):
    """The cause injected at 1x is named (the preload: attributed to the normal-force channel), no other cause is
    named, nothing crashes."""
    from pipeline_calibration import NAMED_AS, one

    row = one((effect, 1.0, CI_CAUSE_SEEDS[effect]), tmp_path, pipeline_config)
    assert row["error"] is None, row.get("trace", row["error"])
    assert row["named"], _what(row)
    assert [e for e in row["detected"] if e != NAMED_AS[effect]] == [], _what(row)


def test_a_folder_named_like_a_yaml_boolean_keeps_its_name(tmp_path):
    """dataset.yaml's name is written quoted: a folder named ``off`` (YAML 1.1 reads it as false) ingests under its
    own name; unquoted, the ingest stopped at 'dataset.yaml, line 1, column 7: name: False is not of type
    'string''."""
    from tissuemech.io.ingest import ingest_dataset

    ir.write_dataset_folder(70, tmp_path / "raw" / "off")
    report = ingest_dataset(tmp_path / "raw" / "off", tmp_path / "runs", tmp_path / "report.csv")
    assert (report["status"] == "ok").all(), report[report["status"] != "ok"].to_dict("records")
    assert {r.attrs["dataset"] for r in _runs_by_key(tmp_path / "runs").values()} == {"off"}
