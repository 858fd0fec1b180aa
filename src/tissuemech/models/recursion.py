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



def history_starts(n: int, restart: np.ndarray | None) -> np.ndarray:
    """``restart`` as a boolean array of length ``n`` whose first entry is set (one history when ``None``).

    A batch of *concatenated* histories (several measurements evaluated in one compiled pass) marks the first
    sample of each history; there the hereditary states restart as a step from zero and the time step to the
    previous sample (another history) is never used.
    """
    out = np.zeros(n, dtype=np.bool_)
    if restart is not None:
        restart = np.asarray(restart, dtype=np.bool_)
        if restart.shape != (n,):
            raise ValueError(f"restart has shape {restart.shape}, the histories have {n} samples")
        out[:] = restart
    if n:
        out[0] = True
    return out


@njit(cache=True)
def _prony_branch_sum_kernel(time_s, branch_drive, taus, restart):
    k_hist, m, n = branch_drive.shape
    out = np.zeros((k_hist, n))
    h = np.empty((k_hist, m))
    e = np.empty(m)
    f = np.empty(m)
    for k in range(n):
        if restart[k]:
            for j in range(k_hist):
                acc = 0.0
                for i in range(m):
                    h[j, i] = branch_drive[j, i, k]
                    acc += h[j, i]
                out[j, k] = acc
            continue
        for i in range(m):
            e[i], f[i] = relaxation_factors(time_s[k] - time_s[k - 1], taus[i])
        for j in range(k_hist):
            acc = 0.0
            for i in range(m):
                h[j, i] = e[i] * h[j, i] + f[i] * (branch_drive[j, i, k] - branch_drive[j, i, k - 1])
                acc += h[j, i]
            out[j, k] = acc
    return out


def prony_branch_sum_batch(time_s: np.ndarray, branch_drive: np.ndarray, taus: np.ndarray,
                           restart: np.ndarray | None = None) -> np.ndarray:
    """Sum over branches of the hereditary states, for a batch of histories on one time grid.

    The same exact exponential update as :func:`prony_branch_histories`, without storing each branch:
    used by the parallel-plate quadrature (one history per Gauss radius) and the beyond-QLV models.

    Parameters
    ----------
    time_s : (n,) increasing times in s (or any increasing "clock", e.g. a reduced time); with ``restart``,
        increasing within each history
    branch_drive : (k, m, n) elastic drive of branch ``i`` for history ``j`` (Pa); the first value is
        applied as a step from zero
    taus : (m,) relaxation times in the units of ``time_s``
    restart : optional (n,) booleans: samples where a new (concatenated) history starts, see
        :func:`history_starts`

    Returns
    -------
    (k, n) ``sum_i h_i`` in Pa.
    """
    drive = np.ascontiguousarray(branch_drive, dtype=float)
    return _prony_branch_sum_kernel(np.ascontiguousarray(time_s, dtype=float), drive,
                                    np.ascontiguousarray(taus, dtype=float), history_starts(drive.shape[2], restart))


@njit(cache=True)
def _qlv_batch_kernel(time_s, elastic_stress, g, taus, restart):
    k_hist, n = elastic_stress.shape
    m = g.shape[0]
    g_inf = 1.0 - g.sum()
    out = g_inf * elastic_stress
    h = np.empty((k_hist, m))
    gf = np.empty(m)
    e = np.empty(m)
    for k in range(n):
        if restart[k]:
            for j in range(k_hist):
                for i in range(m):
                    h[j, i] = g[i] * elastic_stress[j, k]
                    out[j, k] += h[j, i]
            continue
        # the factors depend on the time step only: once per step for every history
        for i in range(m):
            e[i], f = relaxation_factors(time_s[k] - time_s[k - 1], taus[i])
            gf[i] = g[i] * f
        for j in range(k_hist):
            ds = elastic_stress[j, k] - elastic_stress[j, k - 1]
            acc = 0.0
            for i in range(m):
                h[j, i] = e[i] * h[j, i] + gf[i] * ds
                acc += h[j, i]
            out[j, k] += acc
    return out


def qlv_stress_batch(time_s: np.ndarray, elastic_stress: np.ndarray, g: np.ndarray, taus: np.ndarray,
                     restart: np.ndarray | None = None) -> np.ndarray:
    """:func:`qlv_stress` for a batch of elastic-stress histories sharing one time grid.

    Parameters
    ----------
    time_s : (n,) s
    elastic_stress : (k, n) instantaneous elastic stress histories in Pa (e.g. one per plate radius)
    g : (m,) Prony weights, ``sum(g) < 1``
    taus : (m,) relaxation times in s
    restart : optional (n,) booleans: samples where a new (concatenated) history starts, see
        :func:`history_starts`

    Returns
    -------
    (k, n) QLV stress in Pa.
    """
    elastic_stress = np.ascontiguousarray(np.atleast_2d(elastic_stress), dtype=float)
    return _qlv_batch_kernel(np.ascontiguousarray(time_s, dtype=float), elastic_stress,
                             np.ascontiguousarray(g, dtype=float), np.ascontiguousarray(taus, dtype=float),
                             history_starts(elastic_stress.shape[1], restart))
