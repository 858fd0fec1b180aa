"""Detectors that missed on the labs' designs, each on a design other than the bundled one, with its null.

Designs are built here (creep curves with and without a ring; one sample per specimen with a held-back temperature
spread or a normal-force preload logged as a channel) or drawn from the independent generator
(``benchmarks/independent_rheometer.py``, written without the package's models). The oracles are the injected
truths: the effect is named (or attributed to the covariate that carries it) on the design with it, and nothing
is named on the same design without it.
"""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tissuemech.canonical import make_run_dataset
from tissuemech.diagnosis.decision import apply_rule
from tissuemech.diagnosis.evidence import residual_table
from tissuemech.diagnosis.findings import DiagnosisContext
from tissuemech.diagnosis.inertia import creep_fall_sds, creep_hold_mask, detect_inertial_ringing
from tissuemech.diagnosis.report import diagnose, diagnose_runs

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import independent_rheometer as ir  # noqa: E402


# ------------------------------------------------------------------------------------------------
# creep: inertial ringing after a torque step
# ------------------------------------------------------------------------------------------------
def creep_runs(ring: float, n: int = 4, seed: int = 0, unloading_s: float = 0.0) -> list:
    """Creep-recovery curves of a Burgers-like gel, J(t) = J0 + J1 (1 - e^{-t/tau}) + t/eta under 10 Pa for 60 s,
    then recovery; sampled every 2 ms for the first 0.5 s, then log-spaced. ``ring``: amplitude, relative to the
    instantaneous strain, of the damped oscillation of motor and sample after the torque step (period 50 ms,
    decay 0.1 s; the same instrument, so the same for every curve up to 2 %). ``unloading_s``: duration of a
    linear unloading ramp sampled every 0.5 ms at the end of the creep (0: a sudden unloading)."""
    rng = np.random.default_rng(seed)
    runs = []
    for k in range(n):
        j0, j1, tau, eta = 1e-3 * np.exp(rng.normal(0, 0.1)), 5e-4, 2.0, 2e5
        t_creep = np.r_[np.arange(0.002, 0.5, 0.002), np.geomspace(0.5, 60.0, 60)[1:]]
        t = np.r_[t_creep, 60.0 + np.geomspace(0.01, 60.0, 40)]
        stress = np.where(t <= 60.0, 10.0, 0.0)
        tc = np.minimum(t, 60.0)
        strain = 10.0 * (j0 + j1 * (1 - np.exp(-tc / tau)) + tc / eta)
        period = 0.05 * (1 + 0.02 * rng.normal())
        strain = strain + np.where(t <= 60.0, ring * 10.0 * j0 * np.exp(-t / 0.1) * np.sin(2 * np.pi * t / period), 0.0)
        rec = t > 60.0
        strain[rec] = strain[~rec][-1] - 10.0 * (j0 + j1 * (1 - np.exp(-(t[rec] - 60.0) / tau)))
        if unloading_s > 0:
            # the controller takes the torque down over unloading_s: the strain follows elastically
            t_un = 60.0 + np.arange(0.0005, unloading_s, 0.0005)
            s_un = 10.0 * (1.0 - (t_un - 60.0) / unloading_s)
            g_un = strain[~rec][-1] - (10.0 - s_un) * j0
            t, stress, strain = np.r_[t[~rec], t_un, t[rec] + unloading_s], np.r_[stress[~rec], s_un, stress[rec]], \
                np.r_[strain[~rec], g_un, strain[rec]]
        strain = strain * (1 + 0.003 * rng.normal(size=t.size))
        runs.append(make_run_dataset({"time": t, "shear_strain": strain, "shear_stress": stress},
                                     {"dataset": "creep", "run": f"cr{k}", "test": "creep_recovery",
                                      "specimen": f"g{k}", "sample": "a", "order": 1, "stress_pa": 10.0,
                                      "source_file": "none", "source_sha256": "0"}))
    return runs


def _ringing(runs):
    f = detect_inertial_ringing(DiagnosisContext(runs=runs, table=pd.DataFrame()))
    apply_rule([f], [], alpha=0.01, eps=0.003, n_default=len(runs))
    return f


def test_creep_ringing_after_a_torque_step_is_named():
    runs = creep_runs(ring=0.2)
    fall, n = creep_fall_sds(runs[0]["time"].values[:300], runs[0]["shear_strain"].values[:300])
    assert fall > 20     # the ringing strain falls back by far more than its noise
    f = _ringing(runs)
    assert f["tested"] and f["ringing_in"] == "creep" and f["detected"], f["evidence"]
    assert f["period_s"] == pytest.approx(0.05, rel=0.1)
    assert f["fix"]["after"] < f["fix"]["before"]


def test_creep_without_a_ring_names_nothing():
    f = _ringing(creep_runs(ring=0.0))
    assert not f["detected"] and f["hold_rise_share"] == 0.0


def test_the_unloading_ramp_of_a_creep_is_not_read_as_a_ring():
    """A controller that takes the torque down over 10 ms: the strain falls with the stress, beyond its noise, at
    the points where the stress is still above 90 % of the hold. Those points are unloading, not creep."""
    runs = creep_runs(ring=0.0, unloading_s=0.01)
    stress = runs[0]["shear_stress"].values
    hold = creep_hold_mask(stress)
    assert hold.sum() == (stress == 10.0).sum() and not hold[stress < 10.0].any()
    assert (stress[~hold] > 9.0).sum() >= 1            # the ramp does reach above 90 % of the hold
    f = _ringing(runs)
    assert not f["detected"] and f["hold_rise_share"] == 0.0, f["evidence"]
    assert _ringing(creep_runs(ring=0.2, unloading_s=0.01))["detected"]


# ------------------------------------------------------------------------------------------------
# a held-back temperature spread and a normal-force preload, logged as channels
# ------------------------------------------------------------------------------------------------
def logged_design(temperature_per_degc: float = 0.0, preload_per_n: float = 0.0, seed: int = 0, n_specimens: int = 10):
    """``n_specimens`` (10) x 3 samples x (two relaxations at 2 and 10 %, a frequency sweep), one session each; the bath
    is 37 +- 4 degC (uniform, per sample, logged) and each sample is held at a preload of 0.05-0.5 N (logged normal
    force). Linear truth G(t) = G0 (0.4 + 0.6 e^{-t}), specimen log-SD 0.2, sample 0.02 (a homogeneous gel); the baseline predicts the
    truth without specimen, temperature or preload. Effects: stiffness x (1 + a (T - 37)), x (1 + b F0)."""
    rng = np.random.default_rng(seed)
    runs, preds = [], []
    start = pd.Timestamp("2026-05-04T09:00:00")
    for s in range(n_specimens):
        k_spec = np.exp(rng.normal(0, 0.2))
        for j in range(3):
            temp = 37.0 + rng.uniform(-4.0, 4.0)
            preload = rng.uniform(0.05, 0.5)
            k = k_spec * np.exp(rng.normal(0, 0.02)) * (1 + temperature_per_degc * (temp - 37.0)) \
                * (1 + preload_per_n * preload)
            tests = [("stress_relaxation", 0.02), ("stress_relaxation", 0.10), ("frequency_sweep", 0.01)]
            for pos, i in enumerate(rng.permutation(len(tests)), start=1):
                test, cond = tests[i]
                if test == "stress_relaxation":
                    t = np.r_[np.linspace(0, 0.05, 4), np.geomspace(0.06, 100.0, 20)]
                    g = cond * np.minimum(t / 0.05, 1.0)
                    true = 1000.0 * g * (0.4 + 0.6 * np.exp(-np.maximum(t - 0.05, 0.0)))
                    cols = {"time": t, "shear_strain": g, "shear_stress": k * true * (1 + 0.01 * rng.normal(size=t.size))}
                    pred, extra = {"shear_stress": true}, {"strain_pct": 100 * cond}
                else:
                    w = 2 * np.pi * np.geomspace(0.1, 10.0, 12)
                    gp, gpp = 1000.0 * (0.4 + 0.6 * w ** 2 / (1 + w ** 2)), 600.0 * w / (1 + w ** 2)
                    t = np.arange(w.size) * 5.0
                    cols = {"time": t, "angular_frequency": w, "shear_strain": np.full(w.size, cond),
                            "storage_modulus": k * gp * (1 + 0.01 * rng.normal(size=w.size)),
                            "loss_modulus": k * gpp * (1 + 0.01 * rng.normal(size=w.size))}
                    pred, extra = {"storage_modulus": gp, "loss_modulus": gpp}, {"strain_pct": 100 * cond}
                cols["temperature"] = temp + 0.02 * rng.normal(size=t.size)
                cols["normal_force"] = preload + 0.002 * rng.normal(size=t.size)
                attrs = {"dataset": "logged", "run": f"s{s}{'abc'[j]}-{pos}", "test": test, "specimen": f"s{s}",
                         "sample": "abc"[j], "order": pos, "radius_m": 0.0125, "gap_m": 2e-3, "source_file": "none",
                         "source_sha256": "0", **extra,
                         "started_at": (start + pd.Timedelta(days=s, hours=2 * j, minutes=15 * pos)).isoformat()}
                runs.append(make_run_dataset(cols, attrs))
                preds.append(pred)
    table = residual_table(runs, preds, "lve")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return diagnose(runs, table, "lve", {"target": "torque", "relaxation": "measured"})


def kelvin_solid_creep_runs(n_specimens: int = 4, seed: int = 3) -> list:
    """Creep-recovery curves of a linear solid with two retardation times, in closed form (superposition):
    gamma(t) = sigma [J(t) - J(t - t1) H(t - t1)], J(t) = J0 + sum_i J_i (1 - exp(-t/lambda_i)), J0 = 2e-3/Pa,
    J_i = 1e-3 and 2e-3/Pa, lambda_i = 3 and 70 s (between the NNLS grid's times), 10 Pa for 120 s then 120 s of
    recovery, sampled log-spaced from 2 ms in each phase, two samples per specimen whose compliance differs by
    ~10 %, 0.3 % relative noise. Rim strain below 5 %: the small-strain QLV solid of two relaxation times is
    this material exactly."""
    rng = np.random.default_rng(seed)
    j0, j, lam, sigma, t1 = 2e-3, np.array([1e-3, 2e-3]), np.array([3.0, 70.0]), 10.0, 120.0

    def compliance(t):
        t = np.maximum(t, 0.0)
        return j0 + np.sum(j[:, None] * (1.0 - np.exp(-t[None, :] / lam[:, None])), axis=0)
    t = np.r_[np.geomspace(0.002, t1, 300), t1 + np.geomspace(0.002, 120.0, 300)]
    stress = np.where(t <= t1, sigma, 0.0)
    shape = sigma * (compliance(t) - np.where(t > t1, compliance(t - t1), 0.0))
    runs = []
    for k in range(n_specimens):
        level = np.exp(rng.normal(0.0, 0.1))
        for sample in ("a", "b"):
            strain = level * np.exp(rng.normal(0.0, 0.02)) * shape * (1.0 + 0.003 * rng.normal(size=t.size))
            runs.append(make_run_dataset(
                {"time": t, "shear_strain": strain, "shear_stress": stress},
                {"dataset": "kelvin", "run": f"s{k}{sample}", "test": "creep_recovery", "specimen": f"s{k}",
                 "sample": sample, "order": 1, "stress_pa": sigma, "radius_m": 0.0125, "gap_m": 0.002,
                 "source_file": "none", "source_sha256": "0"}))
    return runs


def test_a_two_time_solid_creep_recovery_leaves_no_structure():
    """The null of the creep designs: a solid whose creep and recovery the baseline family describes exactly. The
    recovery, thinned with the whole test, kept two points, and the NNLS times on the grid missed the slower
    retardation: the residuals moved by ~10 % within each curve, read as unexplained structure along log time,
    strain and the predicted strain. Thinned by phase, with the times fitted with the model, nothing is left."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = diagnose_runs(kelvin_solid_creep_runs(), fitted_tests=("creep_recovery",))
    assert [f["effect"] for f in res["findings"] if f["detected"]] == []
    assert res["unexplained"] == [], [u["evidence"] for u in res["unexplained"]]
    # the relaxation times of that compliance: the zeros of s J(s) = J0 + sum_i J_i / (1 + lambda_i s), at -1/tau
    j0, j, lam = 2e-3, (1e-3, 2e-3), (3.0, 70.0)
    s_j = np.polynomial.polynomial.polyadd(
        j0 * np.polynomial.polynomial.polymul([1, lam[0]], [1, lam[1]]),
        np.add(np.multiply(j[0], [1, lam[1]]), np.multiply(j[1], [1, lam[0]])))
    truth = np.sort(-1.0 / np.polynomial.polynomial.polyroots(s_j).real)       # 1.98 and 42.4 s
    assert np.asarray(res["fit_info"]["taus_s"]) == pytest.approx(truth, rel=0.05)


def prony_sweeps_and_ramps(n_specimens: int = 3, seed: int = 5) -> list:
    """Frequency sweeps (0.1-10 Hz at 0.5 % strain) and constant-rate ramps (0.01 and 0.1 1/s to 5 %) of a linear
    solid G(t) = G_inf + sum_i G_i exp(-t/tau_i) with modes at 10 ms and 30 s, in closed form: G*(omega) =
    G_inf + sum_i G_i i omega tau_i / (1 + i omega tau_i); a ramp at rate r: sigma(t) = r [G_inf t + sum_i G_i
    tau_i (1 - exp(-t/tau_i))] (the apparent stress 2M/(pi R^3) is the rim stress of a linear material). The
    ramps are logged from 0.5 s: the 10 ms mode adds r G_1 tau_1 (0.02 Pa at 0.01 1/s) to them, and only the
    sweeps resolve it. 0.5 % relative noise, specimens differ by ~10 %."""
    rng = np.random.default_rng(seed)
    g_inf, g, tau = 300.0, np.array([200.0, 150.0]), np.array([0.01, 30.0])
    omega = 2 * np.pi * np.geomspace(0.1, 10.0, 15)
    gstar = g_inf + np.sum(g[:, None] * 1j * omega * tau[:, None] / (1 + 1j * omega * tau[:, None]), axis=0)
    geometry = {"radius_m": 0.0125, "gap_m": 0.002, "source_file": "none", "source_sha256": "0"}
    runs = []
    for k in range(n_specimens):
        level = np.exp(rng.normal(0.0, 0.1))
        noisy = lambda y: y * (1.0 + 0.005 * rng.normal(size=y.size))  # noqa: E731
        runs.append(make_run_dataset(
            {"angular_frequency": omega, "storage_modulus": noisy(level * gstar.real),
             "loss_modulus": noisy(level * gstar.imag), "shear_strain": np.full(omega.size, 0.005)},
            {"dataset": "ps", "run": f"fs{k}", "test": "frequency_sweep", "specimen": f"s{k}", "sample": "a",
             "order": 1, "strain_pct": 0.5, **geometry}))
        for j, rate in enumerate((0.01, 0.1)):
            t = np.geomspace(0.5, 0.05 / rate, 40)
            stress = rate * (g_inf * t + np.sum((g * tau)[:, None] * (1 - np.exp(-t[None, :] / tau[:, None])), axis=0))
            runs.append(make_run_dataset(
                {"time": t, "shear_strain": rate * t, "shear_stress": noisy(level * stress)},
                {"dataset": "ps", "run": f"r{k}{j}", "test": "constant_shear_rate", "specimen": f"s{k}",
                 "sample": "a", "order": 2 + j, "shear_rate_1_per_s": rate, **geometry}))
    return runs


def test_a_mode_only_the_sweeps_resolve_joins_the_baseline_from_the_fit_stage():
    """Sweeps + ramps: the diagnosis's NNLS reads the ramps only, so the 10 ms mode was missing and its shape was
    left along every frequency sweep as unexplained structure. With the fit stage's times (the material model,
    fitted to the sweeps too) the baseline gets it, and nothing is left."""
    runs = prony_sweeps_and_ramps()
    tests = ("constant_shear_rate", "frequency_sweep")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        before = diagnose_runs(runs, "qlv_linear_prony4", fitted_tests=tests)
        after = diagnose_runs(runs, "qlv_linear_prony4", fitted_tests=tests, fit_stage_taus_s=(0.01, 30.0))
    assert any(u["test"] == "frequency_sweep" for u in before["unexplained"])
    assert "only the sweeps resolve" in after["fit_info"]["relaxation_times"]["method"]
    assert min(after["fit_info"]["taus_s"]) == pytest.approx(0.01, rel=0.1)     # the 10 ms mode
    assert [f["effect"] for f in after["findings"] if f["detected"]] == []
    assert after["unexplained"] == [], [u["evidence"] for u in after["unexplained"]]


def _cov(result, name):
    return next(c for c in result["covariates"] if c["covariate"] == name)


def test_a_held_back_temperature_spread_is_attributed_to_temperature():
    """-2 %/degC (brain stiffness between 22 and 37 degC, Rashid et al. 2013) over a +-4 degC bath: named as the
    temperature dependence, with its level fix scored leaving each sample out of its specimen (the temperature changes
    between samples, whose sweeps differ by their stiffness too: no mastercurve)."""
    res = logged_design(temperature_per_degc=-0.02)
    named = [f["effect"] for f in res["findings"] if f["detected"]]
    assert named == ["temperature_dependence"], named
    f = res["findings"][0]
    assert f["fix"]["cv"] == "leave-one-sample-out" and f["fix"]["after"] < f["fix"]["before"]
    assert f["effect_size"] == pytest.approx(-0.02 * (f["temperatures_c"][-1] - f["temperatures_c"][0]), rel=0.35)
    assert _cov(res, "channel_temperature")["p_holm"] < 0.01
    assert res["unexplained"] == []          # the channel's structure is the named cause's


def test_a_normal_force_preload_is_attributed_to_the_normal_force():
    """+40 % stiffness per newton of preload (0.05-0.5 N, logged): no catalogue cause, so the normal-force channel
    carries it in the covariates table and as unexplained structure -- not the temperature, not the clock."""
    res = logged_design(preload_per_n=0.4)
    assert [f["effect"] for f in res["findings"] if f["detected"]] == []
    assert [u["covariate"] for u in res["unexplained"]] == ["channel_normal_force"]
    c = _cov(res, "channel_normal_force")
    assert c["p_holm"] < 0.01 and c["effect_size"] == pytest.approx(np.log((1 + 0.4 * 0.48) / (1 + 0.4 * 0.07)), rel=0.4)
    assert not _cov(res, "channel_temperature")["significant"]


def test_the_logged_design_without_effects_names_nothing():
    res = logged_design()
    assert [f["effect"] for f in res["findings"] if f["detected"]] == []
    assert res["unexplained"] == []
    tested = [c for c in res["covariates"] if c.get("tested") and c["kind"] not in ("outlier specimen", "outlier sample")]
    assert {c["covariate"] for c in tested} >= {"channel_temperature", "channel_normal_force", "elapsed_time"}
    assert not any(c["significant"] for c in tested)


# ------------------------------------------------------------------------------------------------
# the independent generator: a drift and a torque offset, each against the same design without it
# ------------------------------------------------------------------------------------------------
def _generated(seed: int, effects: dict | None):
    runs, truth = ir.generate(seed, effects)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return diagnose_runs(runs), truth


@pytest.mark.slow
def test_a_drift_is_named_not_only_unexplained_elapsed_time():
    """+12 %/h of the moduli (seed 101: 3 specimens, 25 tests in shuffled orders over 4 h): the drift is named, with
    its rate, and elapsed time is not left over as unexplained structure; without the drift nothing is named. (Read
    within samples with standard errors clustered by sample, 2 df, it was significant only before Holm and came out
    as unexplained elapsed time; the mixed model reads it on the curves within samples.)"""
    res, truth = _generated(101, {"elapsed_time_drift": 1.2})
    drift = next(f for f in res["findings"] if f["effect"] == "elapsed_time_drift")
    assert drift["detected"] and drift["effect_size_unit"] == "1/h", drift["evidence"]
    assert drift["effect_size"] == pytest.approx(0.12, abs=0.04)
    assert not [u for u in res["unexplained"] if u["covariate"] in ("elapsed_time", "test_order")]
    null, _ = _generated(101, None)
    assert [f["effect"] for f in null["findings"] if f["detected"]] == [] and null["unexplained"] == []


@pytest.mark.slow
def test_a_torque_offset_on_a_23_mm_plate_is_named():
    """5 % of the first relaxation's median torque (98 uN m on R = 23.5 mm, seed 202), scored by refitting the
    baseline without it on held-out conditions; the same design without it names nothing."""
    res, truth = _generated(202, {"torque_offset": 1.0})
    assert truth["radius_mm"] > 20
    f = next(f for f in res["findings"] if f["effect"] == "torque_offset")
    assert f["detected"], f["evidence"]
    assert f["effect_size"] == pytest.approx(1e6 * truth["injected"]["torque_offset_nm"], rel=0.5)
    null, _ = _generated(202, None)
    assert "torque_offset" not in [g["effect"] for g in null["findings"] if g["detected"]]
