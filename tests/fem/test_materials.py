import numpy as np
import pytest

from tissuemech.fem.materials import available_laws, cauchy_stress, make_material, material_from_card


def _shear(gamma):
    F = np.eye(3)
    F[0, 1] = gamma
    return F


@pytest.mark.parametrize("key, params, w1, w2", [
    ("neo_hookean", {"mu": 800.0}, lambda i1: 400.0, 0.0),
    ("mooney_rivlin", {"C10": 300.0, "C01": 120.0}, lambda i1: 300.0, 120.0),
    ("reduced_polynomial3", {"C10": 300.0, "C20": 150.0, "C30": 80.0},
     lambda i1: 300.0 + 2 * 150.0 * (i1 - 3) + 3 * 80.0 * (i1 - 3) ** 2, 0.0),
    ("lopez_pamies2", {"mu1": 500.0, "alpha1": 1.5, "mu2": 50.0, "alpha2": 4.0},
     lambda i1: sum(0.5 * 3 ** (1 - a) * m * i1 ** (a - 1) for m, a in ((500.0, 1.5), (50.0, 4.0))), 0.0),
])
def test_simple_shear_closed_forms(key, params, w1, w2):
    """sigma12 = 2 (W1 + W2) gamma, N1 = gamma sigma12, N2 = -2 W2 gamma^2 (isochoric, J = 1)."""
    mat = make_material(key, params, bulk_modulus_pa=1e7)
    for gamma in (0.05, 0.4, 1.0):
        s = cauchy_stress(mat, _shear(gamma))
        i1 = 3 + gamma**2
        assert s[0, 1] == pytest.approx(2 * (w1(i1) + w2) * gamma, rel=1e-12)
        assert s[0, 0] - s[1, 1] == pytest.approx(gamma * s[0, 1], rel=1e-10)
        assert s[1, 1] - s[2, 2] == pytest.approx(-2 * w2 * gamma**2, abs=1e-9 * s[0, 1])


def test_ogden_uniaxial_matches_closed_form():
    """Incompressible uniaxial Cauchy stress sum_p 2 mu_p/a_p (l^a - l^(-a/2)) (stretch-based kernel)."""
    mu, a = 600.0, -4.0
    mat = make_material("ogden1", {"mu1": mu, "alpha1": a}, bulk_modulus_pa=1e9)
    assert mat.shear_modulus_pa == pytest.approx(mu, rel=1e-6)
    for lam in (0.7, 1.3):
        s = cauchy_stress(mat, np.diag([lam ** -0.5, lam ** -0.5, lam]))
        assert s[2, 2] - s[0, 0] == pytest.approx(2 * mu / a * (lam**a - lam ** (-a / 2)), rel=1e-9)


def test_svk_is_lame_at_small_strain():
    mat = make_material("saint_venant_kirchhoff", {"mu": 1000.0}, poisson_ratio=0.3)
    lam = mat.bulk_modulus_pa - 2 * 1000.0 / 3
    eps = 1e-7
    s = cauchy_stress(mat, np.diag([1 + eps, 1, 1]))
    assert s[0, 0] / eps == pytest.approx(lam + 2000.0, rel=1e-5)
    assert s[1, 1] / eps == pytest.approx(lam, rel=1e-5)
    assert lam / (2 * (lam + 1000.0)) == pytest.approx(0.3)


def test_card_round_trip_and_errors():
    card = {"model": "neo_hookean", "parameters": {"mu": 900.0}, "poisson_ratio": 0.49,
            "prony": {"g": [0.4, 0.2], "tau": [0.3, 6.0]}}
    mat = material_from_card(card)
    assert mat.bulk_modulus_pa == pytest.approx(2 * 900.0 * 1.49 / (3 * 0.02))
    np.testing.assert_allclose(mat.prony_g, [0.4, 0.2])
    with pytest.raises(KeyError, match="unknown hyperelastic law 'nope'"):
        make_material("nope", {}, poisson_ratio=0.3)
    with pytest.raises(KeyError, match="missing"):
        make_material("mooney_rivlin", {"C10": 1.0}, poisson_ratio=0.3)
    with pytest.raises(ValueError, match="sum < 1"):
        make_material("neo_hookean", {"mu": 1.0}, poisson_ratio=0.3, prony_g=[0.7, 0.4], prony_tau_s=[1, 2])
    with pytest.raises(ValueError, match="exactly one"):
        make_material("neo_hookean", {"mu": 1.0})
    assert {"neo_hookean", "ogden2", "lopez_pamies2", "saint_venant_kirchhoff"} <= set(available_laws())


def test_fitting_law_table_entries_are_used(monkeypatch):
    """Laws of a HYPERELASTIC_LAWS-shaped table reach the FEM with their own parameter names; an entry that
    is not a law (wrong shape) is no law."""
    from numba import njit

    from tissuemech.fem import materials

    @njit(cache=False)
    def w1(p, i1, i2):
        return p[0] + p[1] * (i1 - 3.0)

    @njit(cache=False)
    def w2(p, i1, i2):
        return 0.0

    laws = materials.laws_from_table({"yeoh2_test": ("invariant", w1, w2, ("C10", "C20")),
                                      "broken": ("invariant", "not a function", ("x",))})
    assert "broken" not in laws and laws["yeoh2_test"].param_names == ("C10", "C20")
    monkeypatch.setattr(materials, "available_laws", lambda: laws)
    mat = make_material("yeoh2_test", {"C10": 200.0, "C20": 50.0}, bulk_modulus_pa=1e7)
    F = np.eye(3)
    F[0, 1] = 0.5
    assert cauchy_stress(mat, F)[0, 1] == pytest.approx(2 * (200.0 + 50.0 * 0.25) * 0.5, rel=1e-12)


def test_law_that_does_not_compile_is_an_error():
    """A law whose function does not compile with the kernel signature raises, naming the law (it used to
    drop out of the table silently, so a test of that law skipped)."""
    from numba import njit

    from tissuemech.fem import materials

    @njit(cache=False)
    def wrong_arity(p, i1):
        return p[0]

    with pytest.raises(materials.LawCompileError, match="wrong_law"):
        materials.laws_from_table({"wrong_law": ("invariant", wrong_arity, ("mu",))})


def test_every_registered_law_compiles():
    """The package's own table compiles entirely (a failure here names the broken law)."""
    from tissuemech.fem import materials
    from tissuemech.models.hyperelastic import HYPERELASTIC_LAWS

    laws = materials.laws_from_table(HYPERELASTIC_LAWS)
    assert set(HYPERELASTIC_LAWS) <= set(laws)


def test_full_cards_json_shape_uses_the_elastic_law():
    """A tissuemech.cards card of a QLV fit: elastic_law/elastic_parameters + prony + both nu and K."""
    card = {"model": "qlv_rp2_prony4", "family": "qlv", "parameters": {"C10": 300.0, "C20": 90.0, "beta_1": 0.5},
            "elastic_law": "reduced_polynomial2", "elastic_parameters": {"C10": 300.0, "C20": 90.0},
            "prony": {"g": [0.3, 0.1], "tau": [0.1, 10.0], "g_inf": 0.6}, "poisson_ratio": 0.49,
            "bulk_modulus": 2.0 * 600.0 * 1.49 / (3 * 0.02), "initial_shear_modulus": 600.0}
    mat = material_from_card(card)
    assert mat.law_key == "reduced_polynomial2"
    assert mat.shear_modulus_pa == pytest.approx(600.0, rel=1e-6)
    assert mat.bulk_modulus_pa == pytest.approx(card["bulk_modulus"])
    np.testing.assert_allclose(mat.prony_tau_s, [0.1, 10.0])
    no_prony = material_from_card({**card, "prony": None, "bulk_modulus": float("nan")})
    assert no_prony.prony_g.size == 0 and no_prony.bulk_modulus_pa == pytest.approx(card["bulk_modulus"], rel=1e-6)
