"""Exact recursive (exponential) update of Prony-type hereditary integrals.

One implementation shared by the QLV and beyond-QLV 1-D models, the virtual rheometer and the TLED FEM
material routines (``science.md`` section 1.0). For a branch with weight ``g`` and time constant ``tau``
driven by an elastic quantity ``s_e`` that is piecewise linear in time, the hereditary state
``h(t) = int_0^t g exp(-(t-s)/tau) ds_e/ds ds`` obeys exactly

    h_{n+1} = exp(-x) h_n + g (1 - exp(-x))/x (s_e,{n+1} - s_e,n),     x = dt / tau.

The beyond-QLV (Pipkin-Rogers / modified superposition) law replaces ``g * delta s_e`` by the branch's
own increment ``delta R_i``; the kernels therefore take the branch increments directly.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def relaxation_factors(dt: float, tau: float) -> tuple[float, float]:
    """Return ``(exp(-x), (1 - exp(-x))/x)`` with ``x = dt/tau``, series-safe for small ``x``."""
    x = dt / tau
    e = np.exp(-x)
    if x < 1e-8:
        return e, 1.0 - 0.5 * x
    return e, (1.0 - e) / x


@njit(cache=True)
def prony_branch_histories(time_s: np.ndarray, branch_drive: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """Hereditary branch states for arbitrary drives.

    Parameters
    ----------
    time_s : (n,) increasing times in s
    branch_drive : (m, n) elastic drive of each branch (Pa), e.g. ``g_i * sigma_e(gamma(t))`` for QLV or
        ``R_i(gamma(t))`` for Pipkin-Rogers; the value at ``time_s[0]`` is applied as an instantaneous step
        from zero (so the state starts at the drive's first value).
    taus : (m,) relaxation times in s

    Returns
    -------
    (m, n) branch states ``h_i(t)`` in Pa.
    """
    m, n = branch_drive.shape
    h = np.empty((m, n))
    for i in range(m):
        h[i, 0] = branch_drive[i, 0]
        for k in range(n - 1):
            e, f = relaxation_factors(time_s[k + 1] - time_s[k], taus[i])
            h[i, k + 1] = e * h[i, k] + f * (branch_drive[i, k + 1] - branch_drive[i, k])
    return h


def qlv_stress(time_s: np.ndarray, elastic_stress: np.ndarray, g: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """Fung QLV stress ``g_inf sigma_e(t) + sum_i h_i(t)`` from a precomputed elastic stress history.

    Parameters
    ----------
    time_s : (n,) s
    elastic_stress : (n,) instantaneous elastic stress sigma_e(gamma(t)) in Pa
    g : (m,) Prony weights of the reduced relaxation function, ``sum(g) < 1``
    taus : (m,) relaxation times in s
    """
    g = np.asarray(g, float)
    drive = g[:, None] * np.asarray(elastic_stress, float)[None, :]
    h = prony_branch_histories(np.asarray(time_s, float), drive, np.asarray(taus, float))
    return (1.0 - g.sum()) * elastic_stress + h.sum(axis=0)
