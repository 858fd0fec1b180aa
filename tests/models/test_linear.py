"""Linear viscoelastic, viscous and fractional families against closed forms."""
import numpy as np
import pytest

from tissuemech.models.fractional import mittag_leffler_neg
from tissuemech.spectra import prony_nnls_weights
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
    g_inf, weights, resid = prony_nnls_weights(t, g, taus)
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


# ------------------------------------------------------------------------------------------------------
# generalized Kelvin-Voigt (spring G0 in series with Voigt units G_i, tau_ret_i)
# ------------------------------------------------------------------------------------------------------
GKV3 = {"G0": 800.0, "G_1": 300.0, "G_2": 150.0, "G_3": 400.0, "tau_ret_1": 0.05, "tau_ret_2": 2.0, "tau_ret_3": 80.0}


def _gkv_params(n):
    return {"G0": 500.0, **{f"G_{i}": 100.0 * i for i in range(1, n + 1)},
            **{f"tau_ret_{i}": 0.01 * 10.0 ** (i - 1) for i in range(1, n + 1)}}


def _compliance_parts(p):
    n = sum(1 for k in p if k.startswith("tau_ret_"))
    return p["G0"], np.array([p[f"G_{i}"] for i in range(1, n + 1)]), np.array([p[f"tau_ret_{i}"] for i in range(1, n + 1)])


def _creep_compliance_integral(p, u):
    """K(u) = int_0^u J(s) ds of J(s) = 1/G0 + sum (1 - exp(-s/tau))/G_i (0 for u <= 0)."""
    g0, gv, tau = _compliance_parts(p)
    u = np.maximum(np.asarray(u, float), 0.0)
    return u / g0 + np.sum((u[:, None] - tau * (1 - np.exp(-u[:, None] / tau))) / gv, axis=1)


def test_gkv_registered_for_one_to_six_units_with_units_and_bounds():
    from tissuemech.models.registry import available_models

    assert {f"gkv{n}" for n in range(1, 7)} <= set(available_models())
    m = get_model("gkv4")
    assert m.param_names == ("G0", "G_1", "G_2", "G_3", "G_4", "tau_ret_1", "tau_ret_2", "tau_ret_3", "tau_ret_4")
    units = {s.name: s.unit for s in m.param_specs}
    assert units["G0"] == "Pa" and units["G_3"] == "Pa" and units["tau_ret_2"] == "s"
    assert all(s.log and s.lower > 0 for s in m.param_specs)
    assert m.supports("creep") and m.supports("oscillation") and m.supports("shear_history")


def test_gkv_with_one_unit_is_the_standard_linear_solid():
    """Spring G0 in series with one Voigt unit = SLS I (sls1: G1 = G0, G2 = G_1, eta1 = G_1 tau_ret)."""
    gkv, sls = get_model("gkv1"), get_model("sls1")
    p = {"G0": 3453.0, "G_1": 3225.0, "tau_ret_1": 2.97e7 / 3225.0}
    q = {"G1": 3453.0, "G2": 3225.0, "eta1": 2.97e7}
    t = np.linspace(0.0, 3e4, 301)
    # SLS creep closed form: J(t) = 1/G1 + (1 - exp(-t G2/eta1))/G2
    closed = 40.0 * (1 / 3453.0 + (1 - np.exp(-t * 3225.0 / 2.97e7)) / 3225.0)
    np.testing.assert_allclose(gkv.creep_strain(p, t, np.full_like(t, 40.0)), closed, rtol=1e-12)
    np.testing.assert_allclose(sls.creep_strain(q, t, np.full_like(t, 40.0)), closed, rtol=2e-4)
    # relaxation: G_inf = G1 G2/(G1 + G2), G(0) = G1, relaxation time eta1/(G1 + G2)
    g_inf = 3453.0 * 3225.0 / (3453.0 + 3225.0)
    expected = g_inf + (3453.0 - g_inf) * np.exp(-t * (3453.0 + 3225.0) / 2.97e7)
    np.testing.assert_allclose(gkv.relaxation_modulus(p, t), expected, rtol=1e-10)
    w = np.geomspace(1e-8, 1e-3, 11)
    np.testing.assert_allclose(gkv.complex_modulus(p, w), sls.complex_modulus(q, w), rtol=1e-10)


@pytest.mark.parametrize("n", [2, 3, 6])
def test_gkv_complex_modulus_times_complex_compliance_is_one(n):
    """G*(omega) from the interconverted relaxation spectrum times J*(omega) of the retardation spectrum."""
    m = get_model(f"gkv{n}")
    p = _gkv_params(n)
    g0, gv, tau = _compliance_parts(p)
    w = np.geomspace(1e-5, 1e5, 61)
    j_star = 1 / g0 + np.sum(1 / (gv * (1 + 1j * w[:, None] * tau)), axis=1)
    np.testing.assert_allclose(m.complex_compliance(p, w), j_star, rtol=1e-14)
    np.testing.assert_allclose(m.complex_modulus(p, w) * j_star, 1.0, atol=1e-12)
    # limits: G*(0) = 1/J(inf) (series springs), G*(inf) = G0
    g_inf, g_k, theta, _ = m.spectrum(p)
    assert g_inf == pytest.approx(1 / (1 / g0 + np.sum(1 / gv)), rel=1e-14)
    assert g_inf + g_k.sum() == pytest.approx(g0, rel=1e-12)
    # relaxation times interlace the retardation times: theta_1 < tau_1 < theta_2 < tau_2 < ...
    assert np.all(theta < tau) and np.all(theta[1:] > tau[:-1])


def test_gkv_relaxation_and_creep_are_inverse_in_the_convolution_sense():
    """int_0^t G(s) J(t - s) ds = t: the interconverted relaxation modulus against the closed-form compliance."""
    m = get_model("gkv3")
    g0, gv, tau = _compliance_parts(GKV3)
    from scipy.integrate import quad

    for t in (0.01, 1.0, 30.0, 500.0):
        J = lambda s, t=t: 1 / g0 + np.sum((1 - np.exp(-(t - s) / tau)) / gv)  # noqa: E731
        val = quad(lambda s: m.relaxation_modulus(GKV3, np.array([s]))[0] * J(s), 0.0, t,
                   points=[x for x in (0.05, 2.0, 80.0) if x < t], limit=200, epsabs=0, epsrel=1e-11)[0]
        assert val == pytest.approx(t, rel=1e-8)


def test_gkv_creep_recovery_closed_form():
    """Step to 10 Pa, hold, linear unloading over 0.5 s, recovery: Boltzmann superposition with K = int J."""
    m = get_model("gkv3")
    s0, t1, dt = 10.0, 100.0, 0.5
    t = np.r_[np.linspace(0.0, t1, 401), np.linspace(t1 + dt, 400.0, 601)]
    stress = np.where(t <= t1, s0, 0.0)
    g0, gv, tau = _compliance_parts(GKV3)
    J = 1 / g0 + np.sum((1 - np.exp(-t[:, None] / tau)) / gv, axis=1)
    unload = (s0 / dt) * (_creep_compliance_integral(GKV3, t - t1) - _creep_compliance_integral(GKV3, t - t1 - dt))
    expected = s0 * J - unload
    np.testing.assert_allclose(m.creep_strain(GKV3, t, stress), expected, rtol=1e-10, atol=1e-12 * expected.max())
    # full recovery of a solid: the strain returns towards zero
    assert m.creep_strain(GKV3, t, stress)[-1] < 0.05 * expected[t <= t1].max()


def test_gkv_strain_history_uses_the_relaxation_spectrum():
    m = get_model("gkv2")
    p = _gkv_params(2)
    t = np.r_[0.0, np.geomspace(1e-4, 100.0, 80)]
    stress = m.shear_stress_history(p, t, np.full_like(t, 0.01))
    np.testing.assert_allclose(stress, 0.01 * m.relaxation_modulus(p, t), rtol=1e-12)
    assert stress[0] == pytest.approx(0.01 * p["G0"], rel=1e-12)
    assert stress[-1] == pytest.approx(0.01 / (1 / 500.0 + 1 / 100.0 + 1 / 200.0), rel=1e-6)


def test_gkv2_fit_recovers_a_creep_truth():
    from tissuemech import fitting as F

    m = get_model("gkv2")
    truth = {"G0": 900.0, "G_1": 400.0, "G_2": 250.0, "tau_ret_1": 0.8, "tau_ret_2": 40.0}
    t = np.r_[0.0, np.geomspace(0.01, 400.0, 120)]
    stress = np.full_like(t, 5.0)
    curve = F.Curve(test="creep_recovery", condition="5 Pa", response="creep",
                    inputs={"time": t, "shear_stress": stress},
                    observed={"shear_strain": m.creep_strain(truth, t, stress)})
    start = {k: v * (1.6 if k.startswith("G") else 0.5) for k, v in truth.items()}
    res = F.fit(F.FitProblem(m, [curve], target="none", model_key="gkv2"), starts=[start], n_random=0)
    for k, v in truth.items():
        assert res.params[k] == pytest.approx(v, rel=1e-4), k
