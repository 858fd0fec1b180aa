"""Fractional models in the time domain against closed forms and independent oracles (quadrature, SLS limit)."""
import numpy as np
import pytest
from scipy.integrate import quad
from pymittagleffler import mittag_leffler as garrappa
from scipy.special import erfcx, gamma

from tissuemech import fitting as F
from tissuemech.models import fractional as fr
from tissuemech.models.registry import get_model

FZ = {"G_e": 100.0, "G_m": 50.0, "tau": 0.1, "alpha": 0.4}


def test_every_time_response_is_declared():
    for key in ("springpot", "fractional_kelvin_voigt", "fractional_zener"):
        assert get_model(key).responses == {"oscillation", "shear_history", "creep"}
    assert {"shear_history", "creep", "oscillation", "elastic_shear"} <= get_model("qlv_linear_fzener").responses


def test_mittag_leffler_half_is_the_scaled_complementary_error_function():
    x = np.array([0.0, 0.05, 0.7, 3.0, 40.0])
    # E_{1/2}(-x) = exp(x^2) erfc(x)
    np.testing.assert_allclose(fr.mittag_leffler(-x, 0.5), erfcx(x), rtol=1e-12)


def test_fractional_zener_tends_to_the_standard_linear_solid_as_alpha_tends_to_one():
    t = np.array([0.0, 0.01, 0.1, 0.5, 2.0])
    sls = get_model("sls2").relaxation_modulus({"G1": 100.0, "G2": 50.0, "eta1": 50.0 * 0.1}, t)
    np.testing.assert_allclose(fr.mittag_leffler(-t / 0.1, 1.0), np.exp(-t / 0.1), rtol=1e-12)
    np.testing.assert_allclose(get_model("fractional_zener").relaxation_modulus({**FZ, "alpha": 1.0}, t), sls,
                               rtol=1e-12)
    near = get_model("fractional_zener").relaxation_modulus({**FZ, "alpha": 0.9999}, t)
    np.testing.assert_allclose(near, sls, rtol=2e-3)


def test_springpot_relaxation_and_its_history_response():
    m = get_model("springpot")
    p = {"c": 30.0, "alpha": 0.3}
    t = np.array([0.01, 1.0, 50.0])
    np.testing.assert_allclose(m.relaxation_modulus(p, t), 30.0 * t ** -0.3 / gamma(0.7), rtol=1e-14)
    # an ideal step through the generic history path
    th = np.r_[0.0, t]
    stress = m.shear_stress_history(p, th, np.full(th.size, 0.02))
    np.testing.assert_allclose(stress[1:], 0.02 * 30.0 * t ** -0.3 / gamma(0.7), rtol=1e-12)


def test_fractional_zener_limits_in_time():
    m = get_model("fractional_zener")
    g = m.relaxation_modulus(FZ, np.array([0.0, 1e-12, 1e12]))
    assert g[0] == pytest.approx(150.0, rel=1e-12)
    assert g[1] == pytest.approx(150.0, rel=1e-3)  # 1 - x^a/Gamma(1+a) with x^a = 1.6e-4
    assert g[2] == pytest.approx(100.0, rel=1e-3)  # power-law tail G_m x^-a/Gamma(1-a)
    j = m.creep_compliance(FZ, np.array([0.0, 1e14]))
    np.testing.assert_allclose(j, [1 / 150.0, 1 / 100.0], rtol=1e-3)


@pytest.mark.parametrize("key,p", [("fractional_zener", FZ), ("springpot", {"c": 30.0, "alpha": 0.3}),
                                   ("fractional_kelvin_voigt", {"G_e": 40.0, "c": 30.0, "alpha": 0.6})])
def test_ramp_and_hold_equals_quadrature_of_the_hereditary_integral(key, p):
    m = get_model(key)
    rise, rate = 0.3, 0.05  # ramp at 0.05/s for 0.3 s, then hold
    t = np.r_[np.linspace(0.0, rise, 7), np.geomspace(0.35, 20.0, 9)]
    strain = rate * np.minimum(t, rise)
    got = m.shear_stress_history(p, t, strain)
    g = lambda u: float(m.relaxation_modulus(p, np.array([u]))[0])  # noqa: E731
    for tk, yk in zip(t[1:], got[1:]):
        ref, _ = quad(lambda s: rate * g(tk - s), 0.0, min(tk, rise), epsabs=0, epsrel=1e-12, limit=200)
        assert yk == pytest.approx(ref, rel=1e-6)


def test_fractional_kelvin_voigt_creep_tends_to_the_springpot_compliance():
    # closed forms: G_e = 0 gives t^a/(c Gamma(1+a)); a large G_e saturates at 1/G_e
    np.testing.assert_allclose(fr.fkv_creep(np.array([1e12]), 40.0, 30.0, 0.6), 1 / 40.0, rtol=1e-3)
    t = np.array([0.001, 0.1, 3.0])
    springpot = t ** 0.6 / (30.0 * gamma(1.6))
    np.testing.assert_allclose(fr.fkv_creep(t, 0.0, 30.0, 0.6), springpot, rtol=1e-14)
    # the Mittag-Leffler form with a vanishing equilibrium modulus reaches the same closed form
    np.testing.assert_allclose(fr.fkv_creep(t, 1e-9, 30.0, 0.6), springpot, rtol=1e-7)
    m = get_model("fractional_kelvin_voigt")
    th = np.r_[0.0, t]
    np.testing.assert_allclose(m.creep_strain({"G_e": 1e-9, "c": 30.0, "alpha": 0.6}, th, np.full(th.size, 5.0))[1:],
                               5.0 * springpot, rtol=1e-7)


def test_creep_then_relaxation_kernels_invert_each_other():
    """The creep strain (through J) driven back through G returns the imposed stress (creep-recovery).

    Only for a kernel finite at t = 0 (Zener): with the springpot's singular G the piecewise-linear strain
    between samples is not accurate enough near the start for this round trip."""
    m, p = get_model("fractional_zener"), FZ
    t = np.linspace(0.0, 4.0, 81)
    stress = np.where(t <= 2.0, 10.0, 0.0)
    stress[41] = 10.0 * (2.05 - t[41]) / 0.05 if t[41] > 2.0 else stress[41]
    strain = m.creep_strain(p, t, stress)
    back = m.shear_stress_history(p, t, strain)
    # the strain is exact at the samples but only piecewise linear in between: agreement to the grid error
    np.testing.assert_allclose(back[1:], stress[1:], atol=0.05)
    assert strain[-1] < strain[40]  # recovery


def test_fractional_qlv_on_a_linear_law_is_the_linear_fractional_zener():
    q = get_model("qlv_linear_fzener")
    m = get_model("fractional_zener")
    p = {"G0": 150.0, "beta_fz": 0.5, "tau_fz": 0.1, "alpha_fz": 0.4}
    t = np.linspace(0.0, 3.0, 31)
    strain = 0.1 * np.minimum(t, 0.5)
    np.testing.assert_allclose(q.shear_stress_history(p, t, strain), m.shear_stress_history(FZ, t, strain), rtol=1e-12)
    w = np.array([0.1, 10.0])
    np.testing.assert_allclose(q.complex_modulus(p, w), m.complex_modulus(FZ, w), rtol=1e-6)
    np.testing.assert_allclose(q.creep_strain(p, t, np.full(t.size, 5.0)), m.creep_strain(FZ, t, np.full(t.size, 5.0)),
                               rtol=1e-9)


def test_fractional_qlv_on_neo_hookean_separates_for_a_step():
    q = get_model("qlv_neo_hookean_fzener")
    p = {"mu": 200.0, "beta_fz": 1.0, "tau_fz": 1.0, "alpha_fz": 0.5}
    t = np.array([0.0, 0.5, 2.0, 10.0])
    stress = q.shear_stress_history(p, t, np.full(t.size, 0.3))
    # sigma_e(0.3) G_r(t), neo-Hookean simple shear sigma_e = mu gamma; G_r = 1/2 + 1/2 erfcx(sqrt t)
    np.testing.assert_allclose(stress, 200.0 * 0.3 * (0.5 + 0.5 * erfcx(np.sqrt(t))), rtol=1e-12)


def test_fit_recovers_fractional_zener_from_noisy_relaxation():
    m = get_model("fractional_zener")
    truth = {"G_e": 120.0, "G_m": 300.0, "tau": 2.0, "alpha": 0.55}
    rise = 0.2  # finite-rise ramp to 5 %, uniform sampling (one Mittag-Leffler evaluation per distinct lag)
    t = np.arange(0.0, 60.0 + 1e-9, 0.1)
    strain = 0.05 * np.minimum(t / rise, 1.0)
    clean = m.shear_stress_history(truth, t, strain)
    rng = np.random.default_rng(7)
    noisy = clean * (1.0 + 0.01 * rng.standard_normal(t.size))
    curve = F.Curve(test="stress_relaxation", condition="strain=5%", response="shear_history",
                    inputs={"time": t, "shear_strain": strain}, observed={"shear_stress": noisy[1:]},
                    obs_index=np.arange(1, t.size))
    res = F.fit(F.FitProblem(m, [F.thin(curve, 60)], target="none", model_key="fractional_zener"), n_random=0)
    assert res.ok
    for k, v in truth.items():
        assert res.params[k] == pytest.approx(v, rel=0.08), k
    assert np.isfinite(res.aicc)


def test_fractional_zener_creep_at_alpha_one_is_the_sls_creep():
    t = np.array([0.0, 0.05, 0.3, 2.0])
    g1, g2, eta1 = 100.0, 50.0, 50.0 * 0.1  # sls2 with tau = eta1/G2 = 0.1 s
    sls = 1 / g1 - (1 / g1 - 1 / (g1 + g2)) * np.exp(-t * g1 * g2 / (eta1 * (g1 + g2)))
    np.testing.assert_allclose(get_model("fractional_zener").creep_compliance({**FZ, "alpha": 1.0}, t), sls, rtol=1e-12)


def test_fractional_qlv_is_fitted_jointly_to_relaxation_and_constant_rate_ramps():
    m = get_model("qlv_neo_hookean_fzener")
    truth = {"mu": 250.0, "beta_fz": 1.5, "tau_fz": 1.0, "alpha_fz": 0.5}
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 30.0 + 1e-9, 0.1)
    g = 0.2 * np.minimum(t / 0.5, 1.0)  # relaxation at 20 % with a 0.5 s rise
    y = m.shear_stress_history(truth, t, g) * (1 + 0.01 * rng.standard_normal(t.size))
    curves = [F.thin(F.Curve(test="stress_relaxation", condition="strain=20%", response="shear_history",
                             inputs={"time": t, "shear_strain": g}, observed={"shear_stress": y[1:]},
                             obs_index=np.arange(1, t.size)), 40)]
    for rate in (0.01, 0.1):
        t = np.linspace(0.0, 0.3 / rate, 101)
        y = m.shear_stress_history(truth, t, rate * t) * (1 + 0.01 * rng.standard_normal(t.size))
        curves.append(F.thin(F.Curve(test="constant_shear_rate", condition=f"rate={rate}/s", response="shear_history",
                                     inputs={"time": t, "shear_strain": rate * t}, observed={"shear_stress": y[1:]},
                                     obs_index=np.arange(1, t.size)), 30))
    res = F.fit(F.FitProblem(m, curves, target="none", model_key="qlv_neo_hookean_fzener"), n_random=0)
    assert res.success
    for k, v in truth.items():
        assert res.params[k] == pytest.approx(v, rel=0.05), k
    assert np.isfinite(res.aicc)


@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.7, 0.99])
@pytest.mark.parametrize("beta_offset", [0.0, 1.0])
def test_mittag_leffler_of_many_negative_arguments_matches_garrappa_everywhere(alpha, beta_offset):
    # tens of thousands of distinct lags (a hereditary integral over a noisy measured strain) go through the spline
    beta = 1.0 + beta_offset
    x = np.sort(10.0 ** np.random.default_rng(3).uniform(-7.0, 4.0, 20_000))
    z = np.r_[0.0, -x]
    exact = np.real(np.asarray(garrappa(np.ascontiguousarray(z), alpha, beta)))
    exact[0] = 1.0 / gamma(beta)
    fr._ML_CACHE.clear()
    got = fr.mittag_leffler(z, alpha, beta)
    assert got.shape == z.shape
    np.testing.assert_allclose(got, exact, rtol=0, atol=2e-9)
    assert not np.array_equal(got[1:], exact[1:])  # the spline path ran (exact evaluation would be bit-equal)


def test_mittag_leffler_spline_is_refused_for_positive_arguments_and_failed_checks(monkeypatch):
    z = -np.linspace(1e-3, 50.0, 5000)
    exact = np.real(np.asarray(garrappa(np.ascontiguousarray(z), 0.6, 1.0)))
    fr._ML_CACHE.clear()
    monkeypatch.setattr(fr, "_ML_SPLINE_TOLERANCE", 0.0)  # no spline can pass: evaluated exactly
    np.testing.assert_array_equal(fr.mittag_leffler(z, 0.6, 1.0), exact)
    assert fr._mittag_leffler_negative_spline(np.r_[z, 1.0], 0.6, 1.0) is None


def test_mittag_leffler_half_of_many_arguments_is_still_the_complementary_error_function():
    x = np.sort(10.0 ** np.random.default_rng(4).uniform(-6.0, 3.0, 30_000))
    fr._ML_CACHE.clear()
    np.testing.assert_allclose(fr.mittag_leffler(-x, 0.5), erfcx(x), rtol=0, atol=2e-9)
