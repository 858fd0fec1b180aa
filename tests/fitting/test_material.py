"""The material scope: one QLV model from every shear test, on designs without a relaxation test, without a ramp, or
with sweeps and creep only.

The truth is written out here in closed form, independent of the package's models, plate code and recursion:

* QLV on a reduced-polynomial-2 law ``sigma_e = 2 C10 g + 4 C20 g^3`` with ``G_r(t) = g_inf + sum g_i exp(-t/tau_i)``;
* a constant-rate ramp ``g = r t``: the convolution integrals of ``1`` and ``s^2`` against ``exp(-(t - s)/tau)``;
* a relaxation with a linear rise: the ramp's hereditary integral at the end of the rise, decayed since;
* the plate's apparent rim stress ``4 int_0^1 sigma(x g_R) x^2 dx``: the linear part is kept, the cubic part x 2/3;
* a sweep at small strain: ``G* = 2 C10 G_r*(omega)``; an amplitude sweep (first harmonic, apparent):
  ``G*(g0) = G_r*(omega) (2 C10 + 2 C20 g0^2)``;
* creep-recovery of the neo-Hookean case (a linear material): the compliance from the partial fractions of
  ``J(s) = 1 / (s^2 G(s))``, whose poles are the roots of a polynomial (numpy).
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

from tissuemech import fitting as F
from tissuemech.adequacy import ADEQUACY_FACTOR, verdict
from tissuemech.material import fit_material
from tissuemech.models.registry import build_model

RADIUS_M = 0.0125
TRUTH = {"C10": 100.0, "C20": 150.0, "g": np.array([0.45, 0.25]), "tau": np.array([0.5, 20.0])}
REPLICATE_SD = 0.03      # relative replicate scatter of the averaged curves
NOISE = 0.004            # relative point noise


def g_inf(truth=TRUTH) -> float:
    return 1.0 - truth["g"].sum()


def reduced_relaxation(t, truth=TRUTH):
    t = np.asarray(t, float)
    return g_inf(truth) + np.sum(truth["g"][:, None] * np.exp(-t[None, :] / truth["tau"][:, None]), axis=0)


def _ramp_integrals(t, tau):
    """int_0^t exp(-(t-s)/tau) ds and int_0^t exp(-(t-s)/tau) s^2 ds."""
    e = np.exp(-t / tau)
    return tau * (1 - e), tau * (t ** 2 - 2 * tau * t + 2 * tau ** 2) - 2 * tau ** 3 * e


def apparent_ramp_stress(t, rate, truth=TRUTH):
    """Apparent rim stress [Pa] of a constant-rate ramp of the rim strain ``rate * t`` from rest."""
    t = np.asarray(t, float)
    lin = g_inf(truth) * t
    cub = g_inf(truth) * t ** 3 / 3
    for g, tau in zip(truth["g"], truth["tau"]):
        i0, i2 = _ramp_integrals(t, tau)
        lin = lin + g * i0
        cub = cub + g * i2
    return 2 * truth["C10"] * rate * lin + (2.0 / 3.0) * 12 * truth["C20"] * rate ** 3 * cub


def apparent_relaxation_stress(t, strain, rise_s, truth=TRUTH):
    """Apparent rim stress [Pa] of a linear rise to ``strain`` in ``rise_s``, then a hold."""
    t = np.asarray(t, float)
    rate = strain / rise_s
    out = apparent_ramp_stress(np.minimum(t, rise_s), rate, truth)
    hold = t > rise_s
    if hold.any():
        th = t[hold]
        lin = g_inf(truth) * rise_s * np.ones_like(th)
        cub = g_inf(truth) * rise_s ** 3 / 3 * np.ones_like(th)
        for g, tau in zip(truth["g"], truth["tau"]):
            i0, i2 = _ramp_integrals(rise_s, tau)
            decay = np.exp(-(th - rise_s) / tau)
            lin = lin + g * i0 * decay
            cub = cub + g * i2 * decay
        out[hold] = 2 * truth["C10"] * rate * lin + (2.0 / 3.0) * 12 * truth["C20"] * rate ** 3 * cub
    return out


def reduced_complex(omega, truth=TRUTH):
    iwt = 1j * np.asarray(omega, float)[None, :] * truth["tau"][:, None]
    return g_inf(truth) + np.sum(truth["g"][:, None] * iwt / (1 + iwt), axis=0)


def creep_compliance(t, truth=TRUTH):
    """J(t) [1/Pa] of the linear material G(t) = 2 C10 G_r(t): J(s) = D(s) / (s N(s)) by partial fractions."""
    g0 = 2 * truth["C10"]
    rates = 1.0 / truth["tau"]
    d = np.poly(-rates)                              # D(s) = prod (s + 1/tau_i)
    n = g0 * g_inf(truth) * d                        # N(s) = s G(s) D(s)
    for i, gi in enumerate(truth["g"]):
        n = np.polyadd(n, g0 * gi * np.polymul([1.0, 0.0], np.poly(-np.delete(rates, i))))
    poles = np.roots(n)
    j = np.polyval(d, 0.0) / np.polyval(n, 0.0) * np.ones_like(np.asarray(t, float))
    dn = np.polyder(n)
    for r in poles:
        j = j + (np.polyval(d, r) / (r * np.polyval(dn, r))).real * np.exp(r.real * np.asarray(t, float))
    return j


def _noisy(y, rng):
    return np.asarray(y, float) * (1 + NOISE * rng.standard_normal(np.shape(y)))


def ramp_curves(rng, rates=(0.01, 0.1, 1.0), strain_max=0.4):
    out = []
    for r in rates:
        t = np.linspace(0, strain_max / r, 41)
        y = apparent_ramp_stress(t[1:], r)
        out.append(F.Curve(test="constant_shear_rate", condition=f"rate={r:g}/s", response="shear_history",
                           inputs={"time": t, "shear_strain": r * t}, observed={"shear_stress": _noisy(y, rng)},
                           sd={"shear_stress": REPLICATE_SD * np.abs(y)}, obs_index=np.arange(1, t.size),
                           n_samples=6, radius_m=RADIUS_M, gap_m=0.002, nominal={"shear_rate_1_per_s": r}))
    return out


def relaxation_curves(rng, strains=(0.01, 0.1, 0.3), rise_s=0.1):
    out = []
    for s in strains:
        t = np.concatenate([np.linspace(0, rise_s, 6), np.geomspace(0.15, 300, 35)])
        g = s * np.minimum(t / rise_s, 1.0)
        y = apparent_relaxation_stress(t[1:], s, rise_s)
        out.append(F.Curve(test="stress_relaxation", condition=f"strain={100 * s:g}%", response="shear_history",
                           inputs={"time": t, "shear_strain": g}, observed={"shear_stress": _noisy(y, rng)},
                           sd={"shear_stress": REPLICATE_SD * np.abs(y)}, obs_index=np.arange(1, t.size),
                           n_samples=6, radius_m=RADIUS_M, gap_m=0.002, nominal={"strain_pct": 100 * s}))
    return out


def frequency_curve(rng, truth=TRUTH):
    w = 2 * np.pi * np.geomspace(0.01, 20, 25)
    gs = 2 * truth["C10"] * reduced_complex(w, truth)
    return F.Curve(test="frequency_sweep", condition="strain=0.5%", response="oscillation",
                   inputs={"angular_frequency": w},
                   observed={"storage_modulus": _noisy(gs.real, rng), "loss_modulus": _noisy(gs.imag, rng)},
                   sd={"storage_modulus": REPLICATE_SD * gs.real, "loss_modulus": REPLICATE_SD * gs.imag},
                   n_samples=6, radius_m=RADIUS_M, gap_m=0.002, nominal={"strain_pct": 0.5})


def amplitude_curve(rng, truth=TRUTH, f_hz=1.0):
    amps = np.geomspace(1e-3, 0.4, 20)
    gs = reduced_complex(np.array([2 * np.pi * f_hz]), truth)[0] * (2 * truth["C10"] + 2 * truth["C20"] * amps ** 2)
    return F.Curve(test="amplitude_sweep", condition="f=1Hz", response="amplitude_sweep",
                   inputs={"shear_strain": amps},
                   observed={"storage_modulus": _noisy(gs.real, rng), "loss_modulus": _noisy(gs.imag, rng)},
                   sd={"storage_modulus": REPLICATE_SD * gs.real, "loss_modulus": REPLICATE_SD * gs.imag},
                   n_samples=6, radius_m=RADIUS_M, gap_m=0.002, nominal={"frequency_hz": f_hz})


def creep_curves(rng, truth, stresses=(20.0, 40.0), t_load=100.0):
    """Creep-recovery curves sampled as the exports of the shared data and the independent generator are (~60
    points per phase, log-spaced): the QLV creep prediction integrates on the measured time grid, with an error of
    order dt^2 that grows in the recovery's tail on sparser grids (25 points over 200 s of recovery: ~5 noise SDs at
    the truth, at 3 % replicate scatter)."""
    out = []
    for s0 in stresses:
        t = np.unique(np.concatenate([np.geomspace(1e-3, t_load, 60), t_load + np.geomspace(1e-3, 200, 50)]))
        stress = np.where(t <= t_load, s0, 0.0)
        j = creep_compliance(t, truth)
        strain = s0 * j - np.where(t > t_load, s0 * creep_compliance(np.maximum(t - t_load, 0.0), truth), 0.0)
        th, sh = np.r_[0.0, t], np.r_[0.0, stress]
        out.append(F.Curve(test="creep_recovery", condition=f"stress={s0:g}Pa", response="creep",
                           inputs={"time": th, "shear_stress": sh}, observed={"shear_strain": _noisy(strain, rng)},
                           sd={"shear_strain": REPLICATE_SD * np.abs(strain)}, obs_index=np.arange(1, th.size),
                           n_samples=6, radius_m=RADIUS_M, gap_m=0.002, nominal={"stress_pa": s0}))
    return out


def _recovered(mf):
    key = mf.recommendation["recommended"]
    assert key is not None, mf.recommendation["statement"]
    model = build_model(key, mf.fits[key].structure)
    return key, model, mf.fits[key].params


def _check_relaxation_function(model, params, truth, times=(0.1, 1.0, 10.0, 60.0), rtol=0.04):
    g_inf_fit, g, taus = model.prony_weights(params)
    fitted = g_inf_fit + np.sum(g[:, None] * np.exp(-np.asarray(times)[None, :] / taus[:, None]), axis=0)
    np.testing.assert_allclose(fitted, reduced_relaxation(times, truth), rtol=rtol)


def test_the_closed_forms_are_consistent():
    """The oracle itself: the relaxation limit of a slow ramp, the creep compliance's limits, G* at low frequency."""
    assert apparent_relaxation_stress(np.array([1e4]), 0.01, 0.1)[0] == pytest.approx(
        2 * TRUTH["C10"] * g_inf() * 0.01 + 8 / 3 * TRUTH["C20"] * g_inf() * 0.01 ** 3, rel=1e-9)
    g0 = 2 * TRUTH["C10"]
    assert creep_compliance(np.array([0.0]))[0] == pytest.approx(1 / g0, rel=1e-9)
    assert creep_compliance(np.array([1e6]))[0] == pytest.approx(1 / (g0 * g_inf()), rel=1e-9)
    assert reduced_complex(np.array([1e-9]))[0].real == pytest.approx(g_inf(), rel=1e-6)


@pytest.mark.slow
def test_no_relaxation_test_ramps_and_sweeps_recover_the_truth():
    """Ramps at three rates, a frequency sweep and an amplitude sweep beyond the LVE range: the law's two constants
    and the relaxation function come back."""
    rng = np.random.default_rng(11)
    curves = ramp_curves(rng) + [frequency_curve(rng), amplitude_curve(rng)]
    mf = fit_material(curves, "torque")
    key, model, p = _recovered(mf)
    assert mf.recommendation["verdict"] == "supported"
    assert key.startswith("qlv_rp2_"), mf.table[["model", "aicc", "determined"]]
    assert p["C10"] == pytest.approx(TRUTH["C10"], rel=0.04)
    assert p["C20"] == pytest.approx(TRUTH["C20"], rel=0.08)
    # inside the window the tests resolve (the slowest ramp lasts 40 s, the slowest sweep point 1/omega = 16 s)
    _check_relaxation_function(model, p, TRUTH, times=(0.1, 1.0, 10.0, 30.0))


@pytest.mark.slow
def test_no_ramp_relaxations_and_sweeps_recover_the_truth():
    rng = np.random.default_rng(12)
    curves = relaxation_curves(rng) + [frequency_curve(rng), amplitude_curve(rng)]
    mf = fit_material(curves, "torque")
    key, model, p = _recovered(mf)
    assert key.startswith("qlv_rp2_"), mf.table[["model", "aicc", "determined"]]
    assert p["C10"] == pytest.approx(TRUTH["C10"], rel=0.04)
    assert p["C20"] == pytest.approx(TRUTH["C20"], rel=0.08)
    _check_relaxation_function(model, p, TRUTH)


@pytest.mark.slow
def test_sweeps_and_creep_only_recover_a_linear_material():
    """A frequency sweep and creep-recovery at two stresses (torque-controlled), no strain-controlled test: the
    neo-Hookean truth's modulus and relaxation function."""
    truth = {**TRUTH, "C20": 0.0}
    rng = np.random.default_rng(13)
    curves = [frequency_curve(rng, truth)] + creep_curves(rng, truth)
    mf = fit_material(curves, "torque")
    key, model, p = _recovered(mf)
    g0 = float(model.complex_modulus(p, np.array([1e6])).real[0])
    assert g0 == pytest.approx(2 * truth["C10"], rel=0.04)
    _check_relaxation_function(model, p, truth)


def test_creep_recovery_gives_its_relaxation_times_read_in_its_own_direction():
    """Creep-recovery only, three modes (1, 8, 50 s; the slow two shape mostly the recovery), two pieces of which
    one is 1.5x stiffer: the retardation NNLS on creep and recovery, converted exactly, gives each true relaxation
    time within 0.15 decade and nothing else, and the stiffer piece's level."""
    from dataclasses import replace

    from tissuemech.material import creep_relaxation_times, nnls_relaxation_times, resolved_window_s
    truth = {**TRUTH, "C20": 0.0, "g": np.array([0.24, 0.1, 0.15]), "tau": np.array([1.0, 8.0, 50.0])}
    soft, stiff = creep_curves(np.random.default_rng(14), truth, stresses=(20.0, 30.0), t_load=90.0)
    # the oracle's load is a step at t = 0: so is the imposed history's (a step from rest at the first sample)
    soft, stiff = (replace(c, inputs={k: v[1:] for k, v in c.inputs.items()}, obs_index=None) for c in (soft, stiff))
    stiff = replace(stiff, observed={"shear_strain": stiff.observed["shear_strain"] / 1.5})
    window = resolved_window_s([soft, stiff])
    out = creep_relaxation_times([soft, stiff], window, units=["soft", "stiff"], merge_per_decade=None)
    found = np.asarray(out["taus_s"])
    assert found.size == 3, found
    np.testing.assert_allclose(np.log10(found), np.log10(truth["tau"]), atol=0.15)
    assert out["levels"]["stiff"] / out["levels"]["soft"] == pytest.approx(1.5, rel=0.02)
    # the material NNLS takes them where creep is the only history
    spectrum = nnls_relaxation_times([soft, stiff], window, units=["soft", "stiff"], merge_per_decade=None)
    np.testing.assert_allclose(spectrum["taus_s"], found)


def test_a_flagged_fit_is_never_recommended():
    """The verdict rule: an undetermined, inadequate or unskilled fit is never chosen, even with the lowest AICc; with
    no supported fit the verdict is no_model_supported with the reason."""
    table = pd.DataFrame({
        "model": ["a", "b", "c", "d"], "aicc": [1.0, 2.0, 3.0, 4.0],
        "recommendable": [True, True, True, True], "determined": [False, True, True, True],
        "undetermined": ["beta_1", "", "", ""], "misfit_noise_units": [0.5, 3.0, 0.8, 1.0],
        "adequate": [True, False, True, True], "skill": [0.99, 0.99, -0.1, 0.9],
        "signal_to_scatter": [10.0] * 4})
    assert verdict(table)["recommended"] == "d"
    only_bad = table.iloc[:3]
    v = verdict(only_bad)
    assert v["recommended"] is None and v["verdict"] == "no_model_supported"
    assert "undetermined parameters (beta_1)" in v["reason"] and "best determined fit, b" in v["reason"]
    assert f"adequate: <= {ADEQUACY_FACTOR:g}" in verdict(table.iloc[[1]])["reason"]


def test_the_real_cnf_replicates_support_no_model_and_export_no_recommended_card(shared_real, repo_root, tmp_path):
    """The ten real CNF relaxations (config/external/rheocompass_cnf_hydrogel, read in place): the relaxation sits at
    the replicate scatter, so the material scope says no_model_supported with the reason, recommends nothing, and
    writes no card of a model that predicts worse than the curves' means."""
    import yaml

    from tissuemech.curves import average_runs, write_averages
    from tissuemech.io.ingest import ingest_dataset
    from tissuemech.pipeline import load_runs
    from tissuemech.stages import dataset_scopes, run_fit_scope

    report = ingest_dataset(repo_root / "config" / "external" / "rheocompass_cnf_hydrogel", tmp_path / "runs",
                            tmp_path / "ingest_report.csv")
    assert (report["status"] == "ok").sum() == 10
    config = yaml.safe_load((repo_root / "config" / "config.yaml").read_text())
    write_averages(average_runs(load_runs(tmp_path / "runs"), exclude_flagged=True), tmp_path / "averages.nc")
    spec = dataset_scopes(["stress_relaxation"], config["fit"])["material"]
    table = run_fit_scope(tmp_path / "averages.nc", "material", spec, target=config["fit"]["plate_target"],
                          seed=0, multistart=1, fits_dir=tmp_path / "fits", cards_dir=tmp_path / "cards",
                          ranking_path=tmp_path / "ranking.csv", poisson_ratio=config["fem"]["poisson_ratio"],
                          dataset="cnf")
    assert (table["verdict"] == "no_model_supported").all() and not table["recommended"].any()
    assert "replicate scatter" in table["verdict_reason"].iloc[0]
    for card in (tmp_path / "cards").glob("*.json"):
        assert json.loads(card.read_text())["fit_quality"]["skill"] > 0


def test_an_amplitude_sweep_without_a_frequency_is_left_out_and_said(caplog):
    """No frequency in the sheet or a channel: the material fit cannot predict the sweep's first harmonic, so the
    curve is left out with a warning naming it (nothing assumed in its place); a sweep with one is kept."""
    import logging

    from tissuemech.canonical import make_run_dataset
    from tissuemech.curves import average_runs

    amps = np.geomspace(1e-3, 0.3, 12)

    def sweep(run, **attrs):
        data = {"shear_strain": amps, "storage_modulus": 200.0 + 0 * amps, "loss_modulus": 20.0 + 0 * amps}
        return make_run_dataset(data, {"test": "amplitude_sweep", "run": run, "specimen": "s", "sample": run,
                                       "order": 1, **attrs})
    averages = average_runs([sweep("a"), sweep("b")])
    with caplog.at_level(logging.WARNING):
        assert F.curves_from_averages(averages, tests=["amplitude_sweep"], amplitude="full") == []
    assert "left out of the fit" in caplog.text and "has no frequency" in caplog.text
    given = average_runs([sweep("a", frequency_hz=1.0), sweep("b", frequency_hz=1.0)])
    kept = F.curves_from_averages(given, tests=["amplitude_sweep"], amplitude="full")
    assert len(kept) == 1 and kept[0].nominal["frequency_hz"] == 1.0


@pytest.mark.parametrize("key", ["qlv_rp2_prony2", "pr_rp2_prony2"])
def test_a_fit_predicts_its_sweeps_and_creep_tests_together_as_it_does_one_at_a_time(key):
    """The fit problem predicts its frequency sweeps, its amplitude sweeps at one frequency and its QLV creep tests
    on plates in one call each (one G*(omega), one harmonic analysis, one inversion of the apparent elastic law);
    each curve must get what :func:`tissuemech.fitting.predict` gives it alone."""
    from tissuemech.models.registry import model_on_times
    rng = np.random.default_rng(3)
    model = model_on_times(key, TRUTH["tau"])
    curves = [frequency_curve(rng), frequency_curve(rng, {**TRUTH, "C10": 80.0}),
              amplitude_curve(rng), amplitude_curve(rng, f_hz=2.0),
              *creep_curves(rng, TRUTH, stresses=(20.0, 40.0, 5.0))]
    stronger = amplitude_curve(rng)
    curves.insert(3, dataclasses.replace(stronger, inputs={"shear_strain": 1.5 * stronger.inputs["shear_strain"]}))
    problem = F.FitProblem(model=model, curves=curves, target="apparent_stress")
    p = {"C10": 100.0, "C20": 150.0, "beta_1": 1.2, "beta_2": 0.6, "kappa": 0.5, "gamma_s": 0.2}
    p = {k: v for k, v in p.items() if k in model.param_names}
    together = problem.curve_terms(p)
    for curve, terms in zip(curves, together):
        alone = F.predict(model, p, curve, "apparent_stress")
        assert set(terms) == set(alone)
        for k, (_, predicted, _) in terms.items():
            np.testing.assert_allclose(predicted, alone[k], rtol=1e-9, atol=0, err_msg=f"{curve.label} {k}")
