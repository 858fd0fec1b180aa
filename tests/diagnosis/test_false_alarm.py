"""Root causes of false alarms on null data (issue #12 item 7), each against an independent oracle."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tissuemech.diagnosis import stats as st
from tissuemech.diagnosis.catalogue import raw_phase_inertia


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
