"""The shared Prony recursion against closed forms (science.md section 1.0)."""
import numpy as np

from tissuemech.models.recursion import qlv_stress

G0 = 200.0
TAUS = np.array([0.1, 1.09, 9.91, 100.0])
G = np.array([0.00033, 0.23447, 0.21368, 0.14447])


def test_linear_ramp_matches_closed_form():
    rate = 0.1
    t = np.linspace(0.0, 5.0, 2001)
    gamma = rate * t
    sigma = qlv_stress(t, G0 * gamma, G, TAUS)
    closed = G0 * ((1 - G.sum()) * gamma + np.sum(G[:, None] * rate * TAUS[:, None]
                                                  * (1 - np.exp(-gamma[None, :] / (rate * TAUS[:, None]))), axis=0))
    np.testing.assert_allclose(sigma, closed, rtol=1e-10, atol=1e-10)


def test_thesis_secant_table():
    """science.md section 0: QLV secant moduli of the thesis Prony for a linear instantaneous law."""
    expected = {0.001: [113.6, 104.4, 96.3, 88.1], 0.1: [189.5, 181.5, 170.2, 153.3]}
    for rate, secants in expected.items():
        gammas = np.array([0.05, 0.1, 0.2, 0.5])
        t = np.linspace(0.0, 0.5 / rate, 4001)
        sigma = qlv_stress(t, G0 * rate * t, G, TAUS)
        got = np.interp(gammas, rate * t, sigma) / gammas
        np.testing.assert_allclose(got, secants, atol=0.06)


def test_ramp_hold_matches_closed_form():
    rise, gamma0 = 0.5, 0.2
    rate = gamma0 / rise
    t = np.concatenate([np.linspace(0, rise, 501), np.linspace(rise, 200.0, 4000)[1:]])
    gamma = np.minimum(rate * t, gamma0)
    sigma = qlv_stress(t, G0 * gamma, G, TAUS)
    hold = t >= rise
    closed = G0 * rate * ((1 - G.sum()) * rise
                          + np.sum(G[:, None] * TAUS[:, None] * (np.exp(rise / TAUS[:, None]) - 1)
                                   * np.exp(-t[None, hold] / TAUS[:, None]), axis=0))
    np.testing.assert_allclose(sigma[hold], closed, rtol=1e-9)
