"""Linear viscoelastic, viscous and fractional families against closed forms."""
import numpy as np
import pytest

from tissuemech.models.fractional import mittag_leffler_neg
from tissuemech.models.linear import nnls_prony_weights
from tissuemech.models.registry import get_model

AGAR_SLS2 = {"G1": 650.0, "G2": 2753.0, "eta1": 7.4e4}


def test_sls2_relaxation_and_oscillation_of_the_thesis_agar_fit():
    m = get_model("sls2")
    t = np.array([0.0, 10.0, 100.0])
    np.testing.assert_allclose(m.relaxation_modulus(AGAR_SLS2, t), 650 + 2753 * np.exp(-t * 2753 / 7.4e4))
    w = np.array([0.1, 1.0, 10.0])
    tau = 7.4e4 / 2753
    expected = 650 + 2753 * 1j * w * tau / (1 + 1j * w * tau)
    np.testing.assert_allclose(m.complex_modulus(AGAR_SLS2, w), expected, rtol=1e-12)


@pytest.mark.parametrize("key", ["sls1", "sls2"])
def test_standard_linear_solid_creep_matches_closed_form(key):
    m = get_model(key)
    p = {"G1": 3453.0, "G2": 3225.0, "eta1": 2.97e7}
    t = np.linspace(0.0, 3e4, 301)
    gamma = m.creep_strain(p, t, np.full_like(t, 40.0))
    g_inf, g_i, taus, _ = m.spectrum(p)
    g0 = g_inf + g_i.sum()
    tau_creep = taus[0] * g0 / g_inf  # retardation time of a one-mode solid
    closed = 40.0 * (1 / g_inf - (1 / g_inf - 1 / g0) * np.exp(-t / tau_creep))
    np.testing.assert_allclose(gamma, closed, rtol=2e-4)


def test_burgers_creep_closed_form():
    m = get_model("burgers")
    p = {"G1": 500.0, "eta1": 5e4, "G2": 200.0, "eta2": 2e3}
    t = np.linspace(0.0, 100.0, 401)
    gamma = m.creep_strain(p, t, np.full_like(t, 10.0))
    closed = 10.0 * (1 / 500 + t / 5e4 + (1 - np.exp(-t * 200 / 2e3)) / 200)
    np.testing.assert_allclose(gamma, closed, rtol=1e-3)


def test_prony_step_response_equals_relaxation_modulus():
    m = get_model("prony2")
    p = {"G_inf": 80.0, "G_1": 60.0, "G_2": 40.0, "tau_1": 0.5, "tau_2": 20.0}
    t = np.linspace(0.0, 100.0, 501)
    stress = m.shear_stress_history(p, t, np.full_like(t, 0.02))
    np.testing.assert_allclose(stress, 0.02 * m.relaxation_modulus(p, t), rtol=1e-12)


def test_nnls_recovers_prony_weights():
    t = np.geomspace(0.01, 1000, 200)
    taus = np.array([0.1, 1.0, 10.0, 100.0])
    true = np.array([30.0, 0.0, 50.0, 20.0])
    g = 80.0 + (true[:, None] * np.exp(-t[None, :] / taus[:, None])).sum(0)
    g_inf, weights, resid = nnls_prony_weights(t, g, taus)
    assert g_inf == pytest.approx(80.0, abs=1e-8)
    np.testing.assert_allclose(weights, true, atol=1e-8)


def test_flow_models():
    rate = np.array([0.01, 0.1, 0.8])
    np.testing.assert_allclose(get_model("power_law").steady_shear_stress({"K": 356.0, "n": 0.1}, rate),
                               356.0 * rate**0.1)
    np.testing.assert_allclose(get_model("bingham").steady_shear_stress({"tau_B": 237.0, "eta_B": 218.0}, rate),
                               237.0 + 218.0 * rate)
    hb = get_model("herschel_bulkley").steady_shear_stress({"tau_y": 10.0, "K": 5.0, "n": 1.0}, rate)
    np.testing.assert_allclose(hb, 10.0 + 5.0 * rate)


def test_mittag_leffler_series_and_integral_agree_and_reduce_to_exponential():
    x = np.array([0.2, 0.9, 1.1, 3.0])
    # alpha -> 1: E_1(-x) = exp(-x)
    np.testing.assert_allclose(mittag_leffler_neg(0.999, x), np.exp(-x), atol=1e-3)  # power-law tail ~ x^-a/Gamma(1-a)
    # continuity across the series/integral switch at x^alpha = 1
    a = 0.5
    lo, hi = mittag_leffler_neg(a, np.array([0.9999, 1.0001]))
    assert lo == pytest.approx(hi, rel=1e-3)
    # E_1/2(-z) = exp(z^2) erfc(z)
    from scipy.special import erfcx
    z = np.sqrt(x)
    np.testing.assert_allclose(mittag_leffler_neg(0.5, x), erfcx(z), rtol=1e-7)


def test_fractional_zener_limits():
    m = get_model("fractional_zener")
    p = {"G_e": 100.0, "G_m": 50.0, "tau": 0.1, "alpha": 0.4}
    g = m.complex_modulus(p, np.array([1e-8, 1e8]))
    assert g[0].real == pytest.approx(100.0, rel=1e-3)
    assert g[1].real == pytest.approx(150.0, rel=1e-3)
