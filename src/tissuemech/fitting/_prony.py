"""Prony weights by NNLS on fixed relaxation times and the Prony start of a fit (part of
:mod:`tissuemech.fitting`, which re-exports every public name)."""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy

from ..models.base import ConstitutiveModel
from ..models.recursion import prony_branch_histories
from ..spectra import prony_oscillation_basis
from ._data import Curve
from ._problem import NoiseModel


# ------------------------------------------------------------------------------------------------
# Prony weights by non-negative least squares (robust start, science.md §4.1)
# ------------------------------------------------------------------------------------------------
def prony_nnls(curves: Sequence[Curve], taus: np.ndarray, elastic: Callable[[np.ndarray], np.ndarray] | None = None,
               noise: NoiseModel | None = None) -> dict[str, np.ndarray | float]:
    """Non-negative Prony weights on fixed relaxation times from shear-history and oscillation curves.

    The (quasi-)linear stress is linear in the weights for fixed taus:
    sigma(t) = a_inf s_e(t) + sum_i a_i h_i[s_e](t), with h_i the exact recursion of ``models.recursion``
    driven by the elastic history s_e = ``elastic(gamma(t))`` (default: s_e = gamma, i.e. moduli in Pa), and
    G*(omega) = a_inf + sum_i a_i i omega tau_i / (1 + i omega tau_i) for frequency sweeps (linear only).
    Rows are weighted by the noise model; NNLS keeps every weight >= 0.

    Returns
    -------
    dict with ``taus`` [s], ``a_inf`` and ``a`` (moduli in Pa for the linear drive, or stress factors
    for a QLV drive), the *relative* weights ``g = a / (a_inf + sum a)`` and ``g_inf`` (reduced relaxation
    function of QLV: G_r = g_inf + sum g_i exp(-t/tau_i)), the instantaneous scale ``a0 = a_inf + sum a``,
    and the weighted ``residual_norm``.
    """

    noise = noise or NoiseModel()
    taus = np.asarray(taus, float)
    rows, rhs = [], []
    for c in curves:
        if c.response == "shear_history":
            t = np.asarray(c.inputs["time"], float)
            g = np.asarray(c.inputs["shear_strain"], float)
            se = g if elastic is None else np.asarray(elastic(g), float)
            h = prony_branch_histories(t, np.repeat(se[None, :], taus.size, axis=0), taus)
            A = np.column_stack([se, h.T])
            if c.obs_index is not None:
                A = A[c.obs_index]
            y = np.asarray(c.observed["shear_stress"], float)
            sig = noise.sigma("shear_stress", y, c.sd.get("shear_stress"))
            rows.append(A / sig[:, None])
            rhs.append(y / sig)
        elif c.response == "oscillation":
            if elastic is not None:
                continue  # oscillation is linear: only informs the linear-moduli variant
            re, im = prony_oscillation_basis(c.obs_inputs("angular_frequency"), taus)
            for part, name in ((re, "storage_modulus"), (im, "loss_modulus")):
                y = np.asarray(c.observed[name], float)
                sig = noise.sigma(name, y, c.sd.get(name))
                rows.append(part / sig[:, None])
                rhs.append(y / sig)
    if not rows:
        raise ValueError("prony_nnls needs shear-history (relaxation/CSR) or frequency-sweep curves")
    A = np.vstack(rows)
    b = np.concatenate(rhs)
    scale = np.linalg.norm(A, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    coef, rnorm = scipy.optimize.nnls(A / scale, b, maxiter=50 * A.shape[1])
    coef = coef / scale
    a0 = float(coef.sum())
    return {"taus": taus, "a_inf": float(coef[0]), "a": coef[1:], "a0": a0,
            "g": coef[1:] / a0 if a0 > 0 else np.zeros(taus.size),
            "g_inf": float(coef[0] / a0) if a0 > 0 else 1.0, "residual_norm": float(rnorm)}


def prony_start(model: ConstitutiveModel, curves: Sequence[Curve], noise: NoiseModel | None = None) -> dict | None:
    """A robust start for a QLV model with fixed relaxation times, from :func:`prony_nnls`.

    The elastic history is the instantaneous law at its default parameters; NNLS gives the overall scale
    ``a0`` (applied to the law's moduli, parameters in Pa) and the branch ratios ``beta_i = a_i / a_inf``.
    Returns ``None`` when the model is not such a QLV model or the curves carry no shear history.
    """
    if model.family != "qlv" or not hasattr(model, "prony_weights") or getattr(model, "free_taus", True):
        return None
    hist = [c for c in curves if c.response == "shear_history"]
    if not hist:
        return None
    p0 = model.default_params()
    inst = model.instantaneous
    ip = {k: p0[k] for k in inst.param_names}
    nn = prony_nnls(hist, model.taus(p0), elastic=lambda g: inst.elastic_shear_stress(ip, g), noise=noise)
    if not (nn["a0"] > 0 and nn["a_inf"] > 0):
        return None
    start = dict(p0)
    for spec in inst.param_specs:
        if spec.unit == "Pa":
            start[spec.name] = ip[spec.name] * nn["a0"]
    for i, a in enumerate(nn["a"]):
        start[f"beta_{i + 1}"] = float(a / nn["a_inf"])
    return start
