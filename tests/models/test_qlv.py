"""QLV model against closed forms (science.md sections 0 and 1.0)."""
import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from tissuemech.models.base import ConstitutiveModel, ParamSpec
from tissuemech.models.qlv import LinearElasticShear, QLVModel, invert_monotone, qlv_params
from tissuemech.models.registry import available_models, get_model

G0 = 200.0
TAUS = np.array([0.1, 1.09, 9.91, 100.0])
G = np.array([0.00033, 0.23447, 0.21368, 0.14447])


class OddPolynomialShear(ConstitutiveModel):
    """sigma_e = sum a_k gamma^(2k-1) (reduced-polynomial shear law, a_k = 2k C_k0), N1 = gamma sigma, N2 = 0."""

    def __init__(self, order=3):
        super().__init__(name=f"poly{order}", family="hyperelastic",
                         param_specs=tuple(ParamSpec(f"a{k + 1}", "Pa", 1.0) for k in range(order)),
                         responses=frozenset({"elastic_shear", "normal_stress"}))
        self.order = order

    def elastic_shear_stress(self, p, strain):
        g = np.asarray(strain, float)
        return sum(p[f"a{k + 1}"] * g ** (2 * k + 1) for k in range(self.order))

    def normal_stress_differences(self, p, strain):
        g = np.asarray(strain, float)
        return g * self.elastic_shear_stress(p, g), np.zeros_like(g)


def thesis_model():
    model = QLVModel(LinearElasticShear(), 4, taus_s=TAUS)
    return model, qlv_params(model, {"G0": G0}, G)


def test_parametrisation_round_trip_and_constraint():
    model, p = thesis_model()
    g_inf, g, taus = model.prony_weights(p)
    np.testing.assert_allclose(g, G, rtol=1e-12)
    assert g_inf == pytest.approx(1 - G.sum())
    assert model.param_names == ("G0", "beta_1", "beta_2", "beta_3", "beta_4")
    # any admissible beta gives sum g < 1
    g_inf, g, _ = model.prony_weights({"G0": 1.0, "beta_1": 1e3, "beta_2": 1e3, "beta_3": 0, "beta_4": 5})
    assert g.sum() < 1 and g_inf > 0
    with pytest.raises(ValueError, match="sum < 1"):
        qlv_params(model, {"G0": G0}, [0.5, 0.3, 0.2, 0.1])
    with pytest.raises(ValueError, match="fixed taus"):
        qlv_params(model, {"G0": G0}, G, taus_s=[1, 2, 3, 4])


def test_linear_ramp_closed_form():
    model, p = thesis_model()
    rate = 0.05
    t = np.linspace(0.0, 10.0, 1001)
    gamma = rate * t
    closed = G0 * ((1 - G.sum()) * gamma + np.sum(G[:, None] * rate * TAUS[:, None]
                                                  * (1 - np.exp(-gamma / (rate * TAUS[:, None]))), axis=0))
    np.testing.assert_allclose(model.shear_stress_history(p, t, gamma), closed, rtol=1e-10, atol=1e-12)


def test_thesis_secant_table_to_a_tenth_of_a_pascal():
    model, p = thesis_model()
    expected = {0.001: [113.6, 104.4, 96.3, 88.1], 0.1: [189.5, 181.5, 170.2, 153.3]}
    gammas = np.array([0.05, 0.1, 0.2, 0.5])
    for rate, secants in expected.items():
        t = np.concatenate([[0.0], gammas / rate])        # exact recursion: the nodes alone suffice
        sigma = model.shear_stress_history(p, t, rate * t)
        np.testing.assert_allclose(sigma[1:] / gammas, secants, atol=0.1)


def test_ramp_hold_closed_form():
    model, p = thesis_model()
    rise, gamma0 = 0.4, 0.1
    rate = gamma0 / rise
    t = np.concatenate([np.linspace(0, rise, 41), np.geomspace(rise, 300.0, 200)[1:]])
    sigma = model.shear_stress_history(p, t, np.minimum(rate * t, gamma0))
    hold = t >= rise
    closed = G0 * rate * ((1 - G.sum()) * rise + np.sum(G[:, None] * TAUS[:, None] * np.expm1(rise / TAUS[:, None])
                                                        * np.exp(-t[hold] / TAUS[:, None]), axis=0))
    np.testing.assert_allclose(sigma[hold], closed, rtol=1e-10)


def _monomial_convolution(x, c, m):
    """int_0^x exp(-(x-u)/c) u^m du (science.md section 1.0)."""
    s = sum((-1) ** j * math.factorial(m) / math.factorial(m - j) * x ** (m - j) * c ** (j + 1) for j in range(m + 1))
    return s - (-1) ** m * math.factorial(m) * c ** (m + 1) * np.exp(-x / c)


def test_nonlinear_ramp_closed_form():
    law = OddPolynomialShear(3)
    model = QLVModel(law, 4, taus_s=TAUS)
    a = {"a1": 80.0, "a2": 400.0, "a3": 2000.0}
    p = qlv_params(model, a, G)
    rate = 0.1
    gamma = np.linspace(0, 0.5, 2001)
    t = gamma / rate
    sigma = model.shear_stress_history(p, t, gamma)
    # sigma_e' = a1 + 3 a2 u^2 + 5 a3 u^4
    closed = (1 - G.sum()) * law.elastic_shear_stress(a, gamma)
    for gi, tau in zip(G, TAUS):
        c = rate * tau
        conv = (a["a1"] * _monomial_convolution(gamma, c, 0) + 3 * a["a2"] * _monomial_convolution(gamma, c, 2)
                + 5 * a["a3"] * _monomial_convolution(gamma, c, 4))
        closed = closed + gi * conv
    # the recursion is exact for sigma_e linear in time; sigma_e(gamma(t)) is a quintic -> O(dt^2)
    np.testing.assert_allclose(sigma, closed, rtol=2e-5, atol=1e-6)


def test_step_separability_and_closed_form():
    law = OddPolynomialShear(3)
    model = QLVModel(law, 4, taus_s=TAUS)
    p = qlv_params(model, {"a1": 80.0, "a2": 400.0, "a3": 2000.0}, G)
    t = np.concatenate([[0.0], np.geomspace(1e-3, 200, 300)])
    shapes = []
    for gamma0 in (0.01, 0.4):
        sigma = model.shear_stress_history(p, t, np.full(t.size, gamma0))   # ideal step at t = 0
        np.testing.assert_allclose(sigma, model.step_relaxation_stress(p, t, gamma0), rtol=1e-12)
        shapes.append(sigma / sigma[0])
    np.testing.assert_allclose(shapes[0], shapes[1], rtol=1e-12)


def qlv_creep_by_ode(model, p, t, stress):
    """Independent oracle: QLV creep as the branch-stress ODE integrated by scipy (Radau, rtol 1e-11).

    ``sigma = g_inf sigma_e + sum h_i``, ``h_i' = -h_i/tau_i + g_i sigma_e'``, hence
    ``sigma_e' = sigma' + sum h_i/tau_i``, with the stress linear between samples and a step from rest at t[0].
    """
    from scipy.integrate import solve_ivp
    _, g, taus = model.prony_weights(p)
    slope = np.diff(stress) / np.diff(t)

    def rhs(time, y):
        k = min(np.searchsorted(t, time, side="right") - 1, slope.size - 1)
        se_rate = slope[k] + np.sum(y[:-1] / taus)
        return np.append(-y[:-1] / taus + g * se_rate, se_rate)

    y = np.append(g * stress[0], stress[0])
    elastic = [stress[0]]
    for k in range(t.size - 1):   # one interval at a time: the stress rate jumps at the samples
        sol = solve_ivp(rhs, (t[k], t[k + 1]), y, method="Radau", rtol=1e-11, atol=1e-12 * abs(stress).max())
        y = sol.y[:, -1]
        elastic.append(y[-1])
    return invert_monotone(lambda x: model.elastic_shear_stress(p, x), np.array(elastic))


def test_creep_standard_linear_solid_closed_form():
    """One branch, linear law: creep compliance J = 1/G_inf - (1/G_inf - 1/G0) exp(-t G_inf/(G0 tau)), exact on a
    sparse grid (the imposed stress is constant between samples)."""
    model = QLVModel(LinearElasticShear(), 1, taus_s=[2.0])
    p = qlv_params(model, {"G0": 150.0}, [0.4], [2.0])
    t = np.geomspace(1e-3, 30, 12) - 1e-3
    stress = np.full(t.size, 10.0)
    g_inf = 0.6 * 150.0
    closed = 10.0 * (1 / g_inf - (1 / g_inf - 1 / 150.0) * np.exp(-t * g_inf / (150.0 * 2.0)))
    np.testing.assert_allclose(model.creep_strain(p, t, stress), closed, rtol=1e-12)


def test_creep_recovery_nonlinear_against_an_ode_solver():
    """Thesis Prony series on a stiffening law, creep and recovery logged at 12 points a decade: the creep strain
    equals scipy's integration of the branch ODE; the forward model on that strain returns the imposed stress to
    second order in the sampling step (the forward recursion takes sigma_e, not sigma, linear between samples)."""
    law = OddPolynomialShear(3)
    model = QLVModel(law, 4, taus_s=TAUS)
    p = qlv_params(model, {"a1": 80.0, "a2": 400.0, "a3": 2000.0}, G)

    def history(per_decade):
        n = 4 * per_decade
        t = np.concatenate([np.linspace(0, 0.05, 6), 0.05 + np.geomspace(0.01, 100, n),
                            100.06 + np.linspace(0, 0.05, 6)[1:], 100.11 + np.geomspace(0.01, 100, n)])
        return t, np.interp(t, [0, 0.05, 100.06, 100.11, 300], [0, 10, 10, 0, 0])

    t, stress = history(12)
    strain = model.creep_strain(p, t, stress)
    np.testing.assert_allclose(strain, qlv_creep_by_ode(model, p, t, stress), rtol=1e-7, atol=1e-10)
    assert strain.max() > 0.1 and strain[-1] < 0.35 * strain.max()   # creeps, then recovers
    misfit = []
    for per_decade in (12, 48):
        t, stress = history(per_decade)
        misfit.append(np.abs(model.shear_stress_history(p, t, model.creep_strain(p, t, stress)) - stress).max())
    assert misfit[1] < misfit[0] / 10 and misfit[1] < 1e-3


def test_invert_monotone_reports_unreachable_targets():
    with pytest.raises(ValueError, match="cannot invert"):
        invert_monotone(lambda x: np.tanh(x), np.array([2.0]))


def test_complex_modulus_uses_initial_slope():
    model = QLVModel(OddPolynomialShear(3), 4, taus_s=TAUS)
    p = qlv_params(model, {"a1": 200.0, "a2": 400.0, "a3": 2000.0}, G)
    w = 2 * np.pi * np.array([0.1, 1.0, 20.0])
    gstar = model.complex_modulus(p, w)
    # science.md section 0 table (G0 = 200 Pa thesis Prony)
    np.testing.assert_allclose(gstar.real, [166.9, 199.0, 200.0], atol=0.06)
    np.testing.assert_allclose(gstar.imag, [29.0, 7.5, 0.4], atol=0.06)


def test_normal_stress_history_step():
    model = QLVModel(OddPolynomialShear(1), 4, taus_s=TAUS)
    p = qlv_params(model, {"a1": 100.0}, G)
    t = np.linspace(0, 50, 101)
    n1, n2 = model.normal_stress_difference_histories(p, t, np.full((1, t.size), 0.3))
    g_r = 1 - G.sum() + np.sum(G[:, None] * np.exp(-t / TAUS[:, None]), axis=0)
    np.testing.assert_allclose(n1[0], 100.0 * 0.09 * g_r, rtol=1e-12)
    np.testing.assert_allclose(n2, 0.0)
    n1_e, _ = model.normal_stress_differences(p, np.array([0.3]))
    assert n1_e[0] == pytest.approx(9.0)


def test_recover_parameters_from_csr_and_relaxation():
    """Noise-free CSR ramps (two rates) + ramp-hold: a least-squares fit recovers the true parameters."""
    model = QLVModel(OddPolynomialShear(2), 4)
    true = qlv_params(model, {"a1": 150.0, "a2": 500.0}, [0.05, 0.25, 0.2, 0.15])
    runs = []
    for rate in (0.001, 0.1):
        t = np.linspace(0, 0.5 / rate, 200)
        runs.append((t, rate * t))
    t = np.concatenate([np.linspace(0, 0.2, 20), np.geomspace(0.2, 300, 120)[1:]])
    runs.append((t, np.minimum(t / 0.2, 1.0) * 0.2))
    data = [model.shear_stress_history(true, t, g) for t, g in runs]
    names = model.param_names

    def residual(x):
        p = dict(zip(names, x))
        return np.concatenate([(model.shear_stress_history(p, t, g) - d) / (1 + np.abs(d))
                               for (t, g), d in zip(runs, data)])

    x0 = [100.0, 100.0, 0.3, 0.3, 0.3, 0.3]
    fit = least_squares(residual, x0, bounds=([0, 0, 0, 0, 0, 0], [1e4, 1e4, 1e3, 1e3, 1e3, 1e3]), xtol=1e-14,
                        ftol=1e-14, gtol=1e-14)
    got = dict(zip(names, fit.x))
    for name in names:
        assert got[name] == pytest.approx(true[name], rel=1e-5), name


def test_registry_keys_and_structure():
    assert {"qlv_linear_prony4", "qlv_linear_prony4_free"} <= set(available_models())
    model = get_model("qlv_linear_prony4")
    assert model.family == "qlv" and model.structure["taus_s"] == [0.1, 1.0, 10.0, 100.0]
    free = get_model("qlv_linear_prony4_free")
    assert "tau_3" in free.param_names and free.taus(free.default_params())[2] == 10.0
    with pytest.raises(ValueError, match="no elastic_shear"):
        QLVModel(ConstitutiveModel(name="x"))


@pytest.mark.parametrize("tag", ["neo_hookean", "rp2", "rp3", "rp4", "lp2", "ogden1"])
def test_hyperelastic_instantaneous_laws(tag):
    key = f"qlv_{tag}_prony4"
    assert key in available_models()
    model = get_model(key)
    p = model.default_params()
    t = np.linspace(0, 5, 501)
    gamma = 0.1 * t
    sigma = model.shear_stress_history(p, t, gamma)
    g_inf, g, taus = model.prony_weights(p)
    # at each instant QLV lies between the relaxed and the instantaneous elastic response
    se = model.elastic_shear_stress(p, gamma)
    assert np.all(sigma <= se + 1e-9) and np.all(sigma >= g_inf * se - 1e-9)
    # the forward recursion is exact for sigma_e linear between samples, the creep for sigma: second order apart
    np.testing.assert_allclose(model.creep_strain(p, t, sigma), gamma, atol=2e-7)


def test_stepwise_creep_solver_converges_to_exact_qlv_creep():
    """The generic per-step solver (Pipkin-Rogers, Maxwell branches) takes each branch's drive linear between
    samples: second order against the exact QLV creep (4x the points, > 8x closer)."""
    from tissuemech.models.qlv import stress_controlled_strain
    model = QLVModel(OddPolynomialShear(3), 4, taus_s=TAUS)
    p = qlv_params(model, {"a1": 80.0, "a2": 400.0, "a3": 2000.0}, G)
    drives, taus = model.branch_drives(p)
    errors = []
    for n in (50, 200):
        t = np.concatenate([np.linspace(0, 0.05, 6), np.geomspace(0.05, 100, n)[1:]])
        stress = np.minimum(t / 0.05, 1.0) * 10.0
        exact = model.creep_strain(p, t, stress)
        errors.append(np.abs(stress_controlled_strain(drives, taus, t, stress) - exact).max() / exact.max())
    assert errors[1] < errors[0] / 8 and errors[1] < 2e-4


def test_instantaneous_laws_are_the_hyperelastic_family_laws():
    """Every QLV instantaneous tag names a registered hyperelastic law, and the QLV elastic response is that law."""
    from tissuemech.models import hyperelastic
    from tissuemech.models import qlv as qlv_module
    tags = qlv_module.available_instantaneous_tags()
    assert tags[0] == "linear" and set(tags[1:]) == set(qlv_module.INSTANTANEOUS_KEYS)
    law = qlv_module.instantaneous_law("rp3")
    assert law.param_names == hyperelastic.MODELS["reduced_polynomial3"]().param_names == ("C10", "C20", "C30")
    gamma = np.linspace(0.01, 0.5, 7)
    p = {"C10": 300.0, "C20": 50.0, "C30": 20.0}
    np.testing.assert_allclose(law.elastic_shear_stress(p, gamma),
                               2 * p["C10"] * gamma + 4 * p["C20"] * gamma**3 + 6 * p["C30"] * gamma**5, rtol=1e-12)


def test_the_qlv_linear_law_is_the_one_linear_elastic_law():
    """models.qlv.LinearElasticShear is hyperelastic.LinearElasticShear with the QLV defaults (modulus G0, elastic
    shear only), not a second law: the same stress from the same modulus, the registry's law under its own name."""
    from tissuemech.models import hyperelastic

    qlv_law, registry_law = LinearElasticShear(), get_model("linear_elastic")
    assert isinstance(qlv_law, hyperelastic.LinearElasticShear) and type(registry_law) is hyperelastic.LinearElasticShear
    assert qlv_law.param_names == ("G0",) and registry_law.param_names == ("G",)
    assert qlv_law.name == "linear_elastic_shear" and qlv_law.responses == frozenset({"elastic_shear"})
    gamma = np.linspace(-0.2, 0.3, 7)
    assert np.array_equal(qlv_law.elastic_shear_stress({"G0": 123.0}, gamma),
                          registry_law.elastic_shear_stress({"G": 123.0}, gamma))
    assert np.array_equal(registry_law.elastic_shear_stress({"G": 123.0}, gamma), 123.0 * gamma)
    assert not qlv_law.supports("normal_stress") and registry_law.supports("normal_stress")
    assert get_model("qlv_linear_prony4").instantaneous.param_names == ("G0",)
