"""Several plate measurements predicted in one compiled pass equal the measurements predicted one by one."""
from __future__ import annotations

import numpy as np
import pytest

from tissuemech.models.beyond_qlv import SchaperyModel
from tissuemech.models.plate import PlateHistories, forward_plate, forward_plate_batch
from tissuemech.models.registry import get_model


def _histories(seed=3, n_curves=7):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_curves):
        n = int(rng.integers(20, 120))
        t = np.cumsum(rng.uniform(0.005, 0.8, n)) - 0.005
        rise = rng.uniform(0.05, 2.0)
        out.append((t, np.minimum(t / rise, 1.0) * rng.uniform(0.01, 0.4), rng.uniform(0.004, 0.025)))
    return out


def _params(model, rng):
    p = model.default_params()
    for name in p:
        if name.startswith("beta_"):
            p[name] = rng.uniform(0.1, 2.0)
        if name.startswith("kappa"):
            p[name] = rng.uniform(-0.5, 3.0)
    return p


@pytest.mark.parametrize("key", ["qlv_rp3_prony4", "pr_rp3_prony4", "qlv_neo_hookean_prony4"])
@pytest.mark.parametrize("target", ["apparent_stress", "torque"])
def test_batched_plate_prediction_equals_one_measurement_at_a_time(key, target):
    model = get_model(key)
    assert model.concatenated_histories
    p = _params(model, np.random.default_rng(1))
    histories = _histories()
    batched = forward_plate_batch(model, p, PlateHistories.of(histories), target=target)
    assert len(batched) == len(histories)
    for (t, rim, radius), got in zip(histories, batched):
        want = forward_plate(model, p, t, rim, radius, target=target)
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())


def test_a_restart_forgets_the_previous_history():
    # the same rim history twice in a row, the second after a long hold at large strain: with the restart the
    # second copy is the first one again, bit for bit
    model = get_model("pr_rp3_prony4")
    p = _params(model, np.random.default_rng(2))
    t, rim, radius = _histories(n_curves=1)[0]
    hold = (np.concatenate([t, t[-1] + [10.0, 20.0]]), np.concatenate([rim, [0.5, 0.5]]), radius)
    first, again = forward_plate_batch(model, p, PlateHistories.of([hold, (t, rim, radius)]))
    np.testing.assert_array_equal(again, first[:t.size])


def test_models_without_concatenated_histories_are_predicted_one_by_one():
    model = SchaperyModel(2)
    assert not model.concatenated_histories
    p = model.default_params()
    histories = _histories(n_curves=3)
    for (t, rim, radius), got in zip(histories, forward_plate_batch(model, p, PlateHistories.of(histories))):
        np.testing.assert_array_equal(got, forward_plate(model, p, t, rim, radius))


def test_pipkin_rogers_weights_follow_the_published_law():
    # g_i = beta_i m_i / (1 + sum beta_j m_j), m_i = 1 + kappa_i gamma^2 / (gamma^2 + gamma_s^2)
    model = get_model("pr_rp3_prony4")
    p = _params(model, np.random.default_rng(4))
    p["gamma_s"] = 0.3
    gamma = np.linspace(-0.6, 0.6, 13).reshape(13, 1)
    beta = np.array([p[f"beta_{i}"] for i in range(1, 5)])
    kappa = np.array([p["kappa"]] * 4)
    m = 1.0 + kappa[:, None, None] * (gamma ** 2 / (gamma ** 2 + 0.09))[None]
    denom = 1.0 + np.sum(beta[:, None, None] * m, axis=0)
    g_inf, g = model.weights(p, gamma)
    np.testing.assert_allclose(g, beta[:, None, None] * m / denom, rtol=1e-14)
    np.testing.assert_allclose(g_inf, 1.0 / denom, rtol=1e-14)


@pytest.mark.parametrize("target", ["apparent_stress", "torque"])
def test_fit_residual_with_batched_plate_curves_equals_the_per_curve_prediction(target):
    from tissuemech.fitting import Curve, FitProblem
    from tissuemech.fitting._problem import predict

    model = get_model("qlv_rp3_prony4")
    p = _params(model, np.random.default_rng(5))
    curves = []
    for i, (t, rim, radius) in enumerate(_histories(n_curves=4)):
        idx = np.arange(0, t.size, 3)
        stress = forward_plate(model, p, t, rim, radius) * (1.0 + 0.01 * np.sin(np.arange(t.size)))
        curves.append(Curve("stress_relaxation", f"strain={i}", "shear_history", {"time": t, "shear_strain": rim},
                            {"shear_stress": stress[idx]}, obs_index=idx, radius_m=radius, gap_m=2e-3))
    problem = FitProblem(model, curves, target=target)
    assert problem._plate_histories is not None        # the batched path is the one under test
    terms = problem.curve_terms(p)
    for curve, term in zip(curves, terms):
        (key, (_, predicted, _)), = term.items()
        np.testing.assert_allclose(predicted, predict(model, p, curve, target)[key], rtol=1e-13)


def _linear_models():
    from tissuemech.models.registry import available_models
    return sorted(k for k in available_models() if get_model(k).linear_in_strain and get_model(k).supports("shear_history"))


def test_linear_models_are_the_linear_viscoelastic_and_fractional_families():
    keys = _linear_models()
    assert "prony4" in keys and "fractional_zener" in keys and "maxwell" in keys
    assert {get_model(k).family for k in keys} == {"linear_viscoelastic", "fractional"}


@pytest.mark.parametrize("key", _linear_models())
def test_models_declared_linear_are_linear_and_their_torque_is_the_full_quadrature(key):
    from tissuemech.models.plate import gauss_radii, stress_histories, torque_from_history

    model = get_model(key)
    p = model.default_params()
    t, rim, radius = _histories(seed=8, n_curves=1)[0]
    once = stress_histories(model, p, t, rim[None, :])[0]
    np.testing.assert_allclose(stress_histories(model, p, t, 2.5 * rim[None, :])[0], 2.5 * once,
                               rtol=1e-12, atol=1e-12 * np.abs(once).max())
    r, w = gauss_radii(8, radius)
    every_radius = stress_histories(model, p, t, (r / radius)[:, None] * rim[None, :])
    full = 2.0 * np.pi * np.sum((w * r * r)[:, None] * every_radius, axis=0)
    np.testing.assert_allclose(torque_from_history(model, p, t, rim, radius), full, rtol=1e-12,
                               atol=1e-12 * np.abs(full).max())
