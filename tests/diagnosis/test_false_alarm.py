"""Root causes of false alarms on null data (issue #12 item 7), each against an independent oracle."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tissuemech import stats as st
from tissuemech.diagnosis.catalogue import DiagnosisContext, raw_phase_inertia
from tissuemech.diagnosis.inertia import detect_inertial_ringing, hold_rise_sds


def test_few_curves_of_autocorrelated_residuals_do_not_reject_at_alpha():
    # null: three curves whose residuals are random walks (a smooth misfit, no covariate effect); the points of
    # a curve are not independent, so the within-curve slope test must hold its level with 3 clusters
    rng = np.random.default_rng(7)
    n_rep, g, n = 200, 3, 40
    rejected = 0
    for _ in range(n_rep):
        codes = np.repeat(np.arange(g), n)
        x = np.tile(np.linspace(0.0, 1.0, n), g)
        e = np.concatenate([np.cumsum(rng.normal(size=n)) for _ in range(g)])
        xd = x - np.bincount(codes, x)[codes] / n
        ed = e - np.bincount(codes, e)[codes] / n
        res = st.cluster_regression(ed, pd.DataFrame({"x": xd}), groups=codes)
        rejected += st.coefficient_test(res, "x")["p_value"] < st.ALPHA
    # binomial(200, 0.01): P(>= 7) < 0.005; treating the 120 points as independent rejects in most replicates
    assert rejected <= 6
    assert st.coefficient_test(res, "x")["df"] == g - 1


def test_raw_phase_inertia_recovers_the_instrument_inertia():
    # oracle: the raw torque (G* - I w^2/b) b theta of a Maxwell-like sample with I = 2e-6 kg m^2 (science.md 2.5)
    inertia, b_inv = 2e-6, 2.0 * 1e-3 / (np.pi * 0.01 ** 4)
    w = np.geomspace(1.0, 300.0, 12)
    g1, g2 = 200.0 + 0.0 * w, 60.0 * (w / w[0]) ** 0.2
    raw = np.angle((g1 - inertia * w ** 2 * b_inv) + 1j * g2)
    frame = pd.DataFrame({"curve": "fs1", "frequency_sq": w ** 2, "observed": g1, "x_inertia": w ** 2 * b_inv,
                          "channel_raw_phase": raw})
    table = pd.DataFrame({"curve": "fs1", "test": "frequency_sweep", "quantity": "loss_modulus",
                          "frequency_sq": w ** 2, "observed": g2})
    got = raw_phase_inertia(table, frame)
    assert got["i_raw_kg_m2"] == pytest.approx(inertia, rel=1e-6)
    assert got["max_raw_phase_deg"] == pytest.approx(np.degrees(np.abs(raw).max()))
    # the raw phase of a sample without inertia equals its own phase: no inertia to be wrong about
    none = frame.assign(channel_raw_phase=np.arctan2(g2, g1))
    assert raw_phase_inertia(table, none)["i_raw_kg_m2"] == pytest.approx(0.0, abs=1e-12)
    # without a raw phase channel the consistency check is not testable (NaN), never a default
    assert np.isnan(raw_phase_inertia(table, frame.drop(columns="channel_raw_phase"))["i_raw_kg_m2"])


def _relaxation_rows(residual_of, observed_of, n_curves=6, seed=3):
    rng = np.random.default_rng(seed)
    t = np.r_[np.arange(0.01, 0.5, 0.01), np.geomspace(0.5, 100.0, 40)]
    rows = []
    for c in range(n_curves):
        level = 100.0 * (1 + 0.2 * c)
        obs = observed_of(t, level) + 0.002 * level * rng.standard_normal(t.size)
        res = residual_of(t, level)
        rows.append(pd.DataFrame({"curve": f"sr{c}", "test": "stress_relaxation", "quantity": "shear_stress",
                                  "time_in_test": t, "observed": obs, "predicted": obs - res, "residual": res,
                                  "sigma": 0.002 * level, "strain": 0.1}))
    return pd.concat(rows, ignore_index=True)


def test_coherent_residual_bump_over_a_monotone_stress_is_not_ringing():
    # the measured stress relaxes monotonically (two exponential modes); the baseline misses it near the step
    # by the same damped-sine-shaped amount in every curve: coherent, significant, but no stress rises again
    def monotone(t, level):
        return level * (1.0 + 0.5 * np.exp(-t / 0.05) + 0.3 * np.exp(-t / 0.3))

    def bump(t, level):
        return 0.12 * level * np.exp(-(t - t[0]) / 0.2) * np.sin(2 * np.pi * t / 0.4)
    f = detect_inertial_ringing(DiagnosisContext(runs=[], table=_relaxation_rows(bump, monotone)))
    assert f["tested"] and f["p_value"] < 1e-3        # the coherence test alone would name it
    assert f["hold_rise_share"] == 0.0 and not f["practical"]
    assert "not a ring" in f["evidence"]


def test_a_ringing_stress_rises_again_during_the_hold():
    def ring(t, level):
        return 0.3 * level * np.exp(-(t - t[0]) / 0.1) * np.sin(2 * np.pi * t / 0.1)

    def ringing(t, level):
        return level * (1.0 + 0.2 * np.exp(-t / 1.0)) + ring(t, level)
    table = _relaxation_rows(ring, ringing)
    rise, n = hold_rise_sds(table[table["curve"] == "sr0"])
    assert n == 89 and rise > 20          # 0.3 x level ring against 0.2 % noise
    f = detect_inertial_ringing(DiagnosisContext(runs=[], table=table))
    assert f["practical"] and f["hold_rise_share"] == 1.0


def test_raw_phase_with_reported_moduli_gives_the_calibrated_inertia():
    """science.md 2.5: the raw torque carries the whole inertia I; the reported G' is corrected with I_cal only,
    G'_rep = G' - (I - I_cal) w^2/b. With the reported moduli the raw phase gives I_cal, not I, so it cannot
    bound an under-correction dI = I - I_cal (here dI = 1.5 I_cal, which the old bound |dI| <= I_raw refused)."""
    i_total, i_cal = 5e-6, 2e-6
    b_inv = 2.0 * 2e-3 / (np.pi * 0.0125 ** 4)
    w = np.geomspace(1.0, 400.0, 14)
    g1, g2 = 500.0 * (w / w[0]) ** 0.1, 80.0 * (w / w[0]) ** 0.2
    raw = np.angle((g1 - i_total * w ** 2 * b_inv) + 1j * g2)
    reported = g1 - (i_total - i_cal) * w ** 2 * b_inv
    frame = pd.DataFrame({"curve": "fs1", "frequency_sq": w ** 2, "observed": reported, "x_inertia": w ** 2 * b_inv,
                          "channel_raw_phase": raw})
    table = pd.DataFrame({"curve": "fs1", "test": "frequency_sweep", "quantity": "loss_modulus",
                          "frequency_sq": w ** 2, "observed": g2})
    assert raw_phase_inertia(table, frame)["i_raw_kg_m2"] == pytest.approx(i_cal, rel=1e-6)
