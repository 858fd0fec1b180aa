r"""One model of the material from every viscoelastic shear test of a dataset (the fit stage's ``material`` scope).

In the linear range G*(omega), G(t), J(t) and the small-strain ramp response are one function; beyond it, a
quasi-linear viscoelastic (QLV) model adds one instantaneous elastic law. So every shear test a dataset has --
constant-rate ramps at any rates, relaxations (their measured strain history, rise included), creep-recovery
(stress-controlled: the strain response of the same model), frequency sweeps (the same relaxation function) and
amplitude sweeps (the first harmonic of the model at each amplitude, within and beyond the LVE range) -- constrains
one QLV model, compared with the measurement through the plate (:func:`tissuemech.fitting.predict`: torque
quadrature over the radius for histories, the torque-controlled plate for creep, the instrument's first-harmonic
analysis for amplitude sweeps). Flow curves of fluids stay in their own scope.

How the model is chosen
-----------------------
1. **The relaxation times the tests resolve** (:func:`resolved_window_s`, :func:`nnls_relaxation_times`): the
   window spanned by the tests (1/omega of the sweeps, rise time to duration of relaxations and creep, the
   ramps' durations); non-negative least squares on a dense log grid from a decade below the window to its end
   selects the active times (NNLS solutions are sparse), a pair of neighbouring grid times merged
   (:func:`merged_times`). Never a fixed grid. When NNLS gives the equilibrium modulus no weight, a **fluid**
   variant (no equilibrium modulus, :class:`tissuemech.models.qlv.QLVModel` ``fluid=True``) is fitted too.
2. **The instantaneous law by AICc on the joint data** among :data:`tissuemech.scopes.MATERIAL_LAWS` (neo-Hookean, reduced
   polynomial 2 and 3, one-term Ogden started at either sign of alpha, Gent, two-term Lopez-Pamies, exponential).
   Mooney-Rivlin is not a separate candidate: in simple shear it is neo-Hookean with mu = 2 (C10 + C01), so shear
   tests cannot tell its two constants apart. The times are chosen again with the best law's parameters
   (a stiffening law changes what the ramps ask of the spectrum) and the law refitted when they change.
3. **Determined parameters** (:func:`tissuemech.adequacy.determined`): a parameter whose standard error exceeds
   its value is not determined. Branches with undetermined weights are pruned (the law refitted on the remaining
   times) and the pruned model joins the candidates.
4. **The verdict** (:func:`tissuemech.adequacy.verdict`, the one rule of every scope): the lowest-AICc fit that is
   determined, adequate against the measured noise and better than the curves' means is recommended
   (``supported``); otherwise ``no_model_supported`` with the reason, and no card.

Fit one test kind, predict the others: :func:`cross_test` refits the chosen model without each test kind and scores
it on the held-out kind (``results/<dataset>/cross_test.csv``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
import scipy

from . import fitting as F
from .adequacy import add_assessment, assess, determined, misfit_in_noise_units, undetermined, verdict
from .models.base import ConstitutiveModel, initial_shear_modulus
from .models import qlv
from .models.recursion import prony_branch_histories
from .models.registry import FIXED_TIME_KEY, model_on_times
from .ranking import Candidate, fit_candidate, ranking_table
from .scopes import MATERIAL_LAWS, MATERIAL_TESTS  # noqa: F401 (MATERIAL_TESTS re-exported)
from .spectra import decade_aligned_taus, kelvin_voigt_to_prony


#: grid density of :func:`nnls_relaxation_times` (times per decade): a mode lies within 0.125 decade of a grid time
NNLS_TIMES_PER_DECADE = 4
#: decades the NNLS grid reaches below the fastest resolved time. A mode much faster than a ramp's rise acts on it as
#: a viscosity (stress h tau d(gamma)/dt while the strain rises): the data resolve its product h tau, not tau, and a
#: time a tenth of the rise carries it within 10 % after the first tenth of the rise
NNLS_GRID_BELOW_DECADES = 1.0
#: the largest start value of a branch ratio beta (NNLS can give the equilibrium share 0)
MAX_START_BETA = 100.0
#: significance of the adequacy test (:func:`adequacy_limit`)
ADEQUACY_ALPHA = 1e-3
#: AICc difference within which a simpler determined candidate is preferred to an undetermined one
AICC_TOLERANCE = 2.0


# ----------------------------------------------------------------------------------------------------------
# the window and the relaxation times the tests resolve
# ----------------------------------------------------------------------------------------------------------
def resolved_window_s(curves: Sequence[F.Curve]) -> dict:
    """Relaxation-time window [s] the tests resolve, from the curves' own inputs.

    * frequency sweeps: 1/omega_max .. 1/omega_min; amplitude sweeps: 1/omega of their frequency;
    * relaxations: the rise time (first time the strain reaches 98 % of its hold value; the first sampling
      interval for an ideal step) .. the hold duration; creep: first observed time .. duration;
    * constant-rate ramps: the first sampling interval .. the ramp duration.

    Returns ``{"t_min_s", "t_max_s", "sources": [sentences]}``; NaN bounds when no curve gives a time scale.
    """
    lo, hi, src = [], [], []
    for c in curves:
        if c.response in ("oscillation", "amplitude_sweep"):
            w = (c.obs_inputs("angular_frequency") if c.response == "oscillation"
                 else np.array([2.0 * np.pi * c.nominal.get("frequency_hz", np.nan)]))
            w = np.abs(np.asarray(w, float))
            w = w[np.isfinite(w) & (w > 0)]
            if w.size:
                lo.append(1.0 / w.max())
                hi.append(1.0 / w.min())
                src.append(f"{c.test}: 1/omega {1 / w.max():.3g}-{1 / w.min():.3g} s")
            continue
        if c.response not in ("shear_history", "creep"):
            continue
        t = np.asarray(c.obs_inputs("time"), float)
        t = t[np.isfinite(t) & (t > 0)]
        if t.size < 2:
            continue
        first, span = float(t.min()), float(t.max())
        if c.test == "stress_relaxation":
            th, g = np.asarray(c.inputs["time"], float), np.abs(np.asarray(c.inputs["shear_strain"], float))
            if np.isfinite(g).any() and np.nanmax(g) > 0:
                rise = float(th[np.argmax(g >= 0.98 * np.nanmax(g))] - th[0])
                first = rise if rise > 0 else first
        if first > 0 and span > first:
            lo.append(first)
            hi.append(span)
            src.append(f"{c.test}: {first:.3g}-{span:.3g} s")
    return {"t_min_s": float(min(lo)) if lo else np.nan, "t_max_s": float(max(hi)) if hi else np.nan,
            "sources": sorted(set(src))}


def window_taus(window: Mapping, per_decade: float = 1.0) -> np.ndarray:
    """Log-spaced relaxation times [s] spanning ``window`` (:func:`resolved_window_s`), ``per_decade`` per
    decade, from the decade at or below ``t_min_s`` to the one at or above ``t_max_s``; empty without a window."""
    t0, t1 = window.get("t_min_s", np.nan), window.get("t_max_s", np.nan)
    if not (np.isfinite(t0) and np.isfinite(t1) and 0 < t0 <= t1):
        return np.array([])
    # at least one decade: up to the decade above t_min's
    return decade_aligned_taus(t0, max(t1, 10.0 ** (np.floor(np.log10(t0)) + 1.0)), per_decade)


def merged_times(grid: np.ndarray, weights: np.ndarray, per_decade: float | None = None) -> np.ndarray:
    """Active relaxation times of an NNLS solution on ``grid``, a pair of neighbouring active times merged.

    One mode between two grid times shows in NNLS as weight on both neighbours and nowhere else; the data do
    not resolve two modes a grid step apart, so such a pair is one time, at the weight-averaged log time (a
    0.25-decade pair of exponentials and one exponential at its weighted geometric mean differ by well under
    the noise of a relaxation). Three or more consecutive active times are a broad spectrum (a fractional
    relaxation activates a whole band of the grid): without ``per_decade`` they are kept, since one exponential
    cannot stand for a band; with ``per_decade`` a band keeps that many times per decade of it (consecutive groups
    of grid times, each at its weighted log mean: one Prony time per decade follows a smooth spectrum within a few
    per cent, and a model fitted on every grid time of a 14-decade mastercurve has no determined weight).
    Returns the times [s], ascending.
    """
    weights = np.asarray(weights, float)
    active = np.flatnonzero(weights > 0)
    if active.size == 0:
        return np.array([])
    grid = np.asarray(grid, float)
    logs = np.log(grid)
    step = float(np.median(np.diff(np.log10(grid)))) if grid.size > 1 else 1.0
    out = []
    for run in np.split(active, np.flatnonzero(np.diff(active) > 1) + 1):
        if run.size == 2:
            out.append(float(np.exp(np.average(logs[run], weights=weights[run]))))
        elif per_decade is None or run.size == 1:
            out.extend(float(np.exp(logs[i])) for i in run)
        else:
            size = max(int(round(1.0 / (per_decade * step))), 1)
            for chunk in np.array_split(run, int(np.ceil(run.size / size))):
                out.append(float(np.exp(np.average(logs[chunk], weights=weights[chunk]))))
    return np.array(out)


#: relaxation times per decade of a band of active NNLS times kept by the material model (:func:`merged_times`)
MATERIAL_TIMES_PER_DECADE = 1.0


def as_strain_controlled(curve: F.Curve) -> F.Curve:
    """A creep curve read the other way round: the measured strain as the imposed history and the imposed stress
    as the observation (other curves unchanged).

    The QLV prediction of a strain history is linear in the branch weights, its creep strain is not; the
    relaxation-time selection (:func:`nnls_relaxation_times`) needs the linear form. The torque-controlled
    plate imposes the apparent rim stress, which is what a strain-controlled plate prediction returns.

    The imposed history is the strain at the observation points, so only the loaded part is read this way: the
    observations are the points under load (stress above half its largest magnitude), and the history ends with the
    last of them. A recovery's stress is zero to within noise, and the strain between the points of a thinned
    recovery (:func:`tissuemech.fitting.thin`) is not known well enough to predict it.
    """
    if curve.response != "creep":
        return curve
    t = np.asarray(curve.obs_inputs("time"), float)
    g = np.asarray(curve.observed["shear_strain"], float)
    s = np.asarray(curve.obs_inputs("shear_stress"), float)
    ok = np.isfinite(t) & np.isfinite(g) & np.isfinite(s)
    t, g, s = t[ok], g[ok], s[ok]
    loaded = np.abs(s) > 0.5 * np.max(np.abs(s)) if s.size and np.max(np.abs(s)) > 0 else np.ones(s.size, bool)
    end = int(np.flatnonzero(loaded)[-1]) + 1 if loaded.any() else s.size
    t, g, s, loaded = t[:end], g[:end], s[:end], loaded[:end]
    start = 1 if t[0] > 0 else 0
    th, gh = (np.r_[0.0, t], np.r_[0.0, g]) if start else (t, g)
    return replace(curve, response="shear_history", inputs={"time": th, "shear_strain": gh},
                   observed={"shear_stress": s[loaded]}, sd={},
                   obs_index=np.arange(start, start + t.size)[loaded])


def nnls_with_levels(design: np.ndarray, rhs: np.ndarray, row_unit: np.ndarray | None,
                     power: float = 1.0) -> tuple[np.ndarray, dict[str, float]]:
    """Non-negative least squares with one modulus level per loaded piece, alternating until the levels settle.

    Row ``i`` of piece ``u`` is fitted as ``c_u**power (design @ coef)_i`` (``power`` 1 for a stress answering an
    imposed strain, -1 for a strain answering an imposed stress); each level is the median log ratio of its piece's
    points, the geometric mean of all levels 1, at most :data:`LEVEL_ITERATIONS` rounds, until the levels change
    by < 0.1 %. ``row_unit`` None: one level for all. Columns are scaled to unit norm for NNLS and ``coef`` is
    returned in the design's units. Returns ``(coef, {unit: c_u})``."""
    norm = np.linalg.norm(design, axis=0)
    norm = np.where(norm > 0, norm, 1.0)
    names = sorted({str(u) for u in row_unit}) if row_unit is not None else []
    level = {u: 1.0 for u in names}
    for _ in range(LEVEL_ITERATIONS):
        c_row = np.array([level[u] ** power for u in row_unit]) if names else np.ones(rhs.size)
        coef, _ = scipy.optimize.nnls(design * c_row[:, None] / norm, rhs, maxiter=100 * design.shape[1])
        pred = design @ (coef / norm)
        if not coef.sum() > 0 or len(names) < 2:
            break
        new = {}
        for u in names:
            sel = (row_unit == u) & (pred > 0) & (rhs > 0)
            new[u] = float(np.exp(power * np.median(np.log(rhs[sel] / pred[sel])))) if sel.any() else 1.0
        centre = float(np.exp(np.mean(np.log(list(new.values())))))
        new = {u: v / centre for u, v in new.items()}
        change = max(abs(new[u] / level[u] - 1.0) for u in names)
        level = new
        if change < 1e-3:
            break
    return coef / norm, level


#: a creep observation's weight in :func:`creep_relaxation_times` is capped at that of a strain this fraction of its
#: curve's largest: the relative noise model gives a recovery's near-zero strains unbounded weight
CREEP_WEIGHT_FLOOR = 0.01


def creep_relaxation_times(curves: Sequence[F.Curve], window: Mapping, per_decade: float = NNLS_TIMES_PER_DECADE,
                           units: Sequence[str] | None = None,
                           merge_per_decade: float | None = MATERIAL_TIMES_PER_DECADE) -> dict:
    r"""Relaxation times of the creep-recovery curves, from a retardation NNLS on their creep *and* recovery.

    A linear material answers an imposed stress history with

    .. math:: \gamma(t) = J_g \sigma(t) + \sum_k j_k [\sigma(t) - q_k(t)] + \phi \int_0^t \sigma\,dt',
              \qquad q_k = \int_0^t e^{-(t - s)/\lambda_k}\,d\sigma(s),

    linear in the retardation spectrum ``(J_g, j_k >= 0, phi >= 0)``; each column is exact for the stress linear
    between samples (:func:`tissuemech.models.recursion.prony_branch_histories`). Read in this direction, the
    strain -- what the test measures -- is the observation (weighted by the relative noise model, capped at
    :data:`CREEP_WEIGHT_FLOOR` of the curve's largest strain), and the recovery, which carries most of what a creep
    says about its slow modes, takes part. (Read the other way round, :func:`as_strain_controlled`, the recovery's
    zero stress has no usable weight; on a development creep-only null with modes at 1, 9 and 48 s that reading
    gave 0.56, 1, 1.8 and 210 s, and the diagnosis's model on those times misfit by 15x the noise variance.)

    With ``units`` each piece gets a compliance level (alternating with NNLS, as in
    :func:`nnls_relaxation_times`). The retardation spectrum on the window's grid (a decade below it to its end,
    ``per_decade`` per decade; neighbouring active times merged by :func:`merged_times` with ``merge_per_decade``)
    is converted exactly to a Prony series (:func:`tissuemech.spectra.kelvin_voigt_to_prony`; a retardation faster
    than the first observation counts as glassy compliance);
    its times with a weight above the noise model's relative floor (1 %) of the instantaneous modulus, from the
    grid's start, are returned, a time beyond the grid's end (a flow term, or modes far beyond the creep's duration)
    at its end.

    Returns
    -------
    ``{"taus_s": relaxation times [s] ascending (empty without creep, window or active mode), "retardation_s":
    the active retardation times [s], "flow": whether the flow term is active, "levels": {unit: modulus level}}``
    """
    out = {"taus_s": np.array([]), "retardation_s": np.array([]), "flow": False, "levels": {}}
    kept = [i for i, c in enumerate(curves) if c.response == "creep"]
    grid = window_taus({**window, "t_min_s": window.get("t_min_s", np.nan) / 10.0 ** NNLS_GRID_BELOW_DECADES},
                       per_decade)
    if not kept or grid.size == 0:
        return out
    noise = F.NoiseModel()
    blocks, rhs, row_unit = [], [], []
    for i in kept:
        c = curves[i]
        t = np.asarray(c.inputs["time"], float)
        stress = np.asarray(c.inputs["shear_stress"], float)
        idx = np.arange(t.size) if c.obs_index is None else np.asarray(c.obs_index)
        strain = np.asarray(c.observed["shear_strain"], float)
        ok = np.isfinite(strain) & np.isfinite(t[idx]) & np.isfinite(stress[idx])
        if ok.sum() < 2 or not np.all(np.isfinite(stress)) or not np.all(np.diff(t) > 0):
            continue
        branches = prony_branch_histories(t, np.tile(stress, (grid.size, 1)), grid)
        flow = np.concatenate([[0.0], np.cumsum(0.5 * (stress[1:] + stress[:-1]) * np.diff(t))])
        cols = np.column_stack([stress, (stress[None, :] - branches).T, flow])[idx][ok]
        y = strain[ok]
        scale = noise.sigma("shear_strain", np.maximum(np.abs(y), CREEP_WEIGHT_FLOOR * np.max(np.abs(y))), None)
        blocks.append(cols / scale[:, None])
        rhs.append(y / scale)
        row_unit.append(np.full(y.size, units[i] if units is not None else "", dtype=object))
    if not blocks:
        return out
    design, rhs, row_unit = np.vstack(blocks), np.concatenate(rhs), np.concatenate(row_unit)
    # a piece c times stiffer creeps 1/c as far
    coef, level = nnls_with_levels(design, rhs, row_unit if units is not None else None, power=-1.0)
    j_g, j, fluidity = float(coef[0]), coef[1:-1].copy(), float(coef[-1])
    # a retardation faster than the first observation is complete before it: the glassy compliance (left apart, it
    # would convert to a relaxation faster than anything measured)
    early = grid < window.get("t_min_s", 0.0)
    j_g += float(j[early].sum())
    j[early] = 0.0
    if not (j.sum() > 0 or fluidity > 0):
        return out
    if not j_g > 0:
        # no instantaneous compliance resolved: the fastest retardation stands in for the glassy response
        j_g = 1e-3 * float(j.sum() + fluidity * grid[-1])
    # one mode between two grid times shows as weight on both: merged as the relaxation NNLS's times are
    retardation = merged_times(grid, j, merge_per_decade)
    nearest = np.abs(np.log(grid)[:, None] - np.log(retardation)[None, :]).argmin(axis=1) if retardation.size else []
    merged_j = np.bincount(np.asarray(nearest, int)[j > 0], weights=j[j > 0], minlength=retardation.size)
    g_e, g_k, tau_k = kelvin_voigt_to_prony(j_g, merged_j, retardation, fluidity)
    # a mode under the noise model's relative floor (1 %, the instrument's accuracy) of the instantaneous modulus
    # moves no strain by more than that floor
    keep = (g_k * j_g > noise.relative) & (tau_k >= grid[0])
    # a relaxation slower than the window (a flow term, or modes far beyond the creep's duration) acts on these
    # data as one mode at the window's end
    taus = np.unique(np.minimum(tau_k[keep], grid[-1]))
    out.update(taus_s=taus, retardation_s=retardation, flow=bool(fluidity > 0), levels=level)
    return out


@dataclass(frozen=True)
class SpectrumFactory:
    """Picklable factory of a fixed-time QLV model on data-chosen times (``models.registry.model_on_times``)."""

    key: str
    taus_s: tuple[float, ...]

    def __call__(self) -> ConstitutiveModel:
        return model_on_times(self.key, self.taus_s)


#: at most this many alternations of NNLS and per-piece levels in :func:`nnls_relaxation_times`
LEVEL_ITERATIONS = 8


def nnls_relaxation_times(curves: Sequence[F.Curve], window: Mapping | None = None, law_tag: str = "neo_hookean",
                          law_params: Mapping[str, float] | None = None,
                          per_decade: float = NNLS_TIMES_PER_DECADE, target: str = "apparent_stress",
                          units: Sequence[str] | None = None,
                          merge_per_decade: float | None = MATERIAL_TIMES_PER_DECADE) -> dict:
    r"""Relaxation times the data ask for: NNLS on a dense log grid over the resolved window.

    For a QLV model with fixed times the plate prediction is linear in the branch moduli: with the instantaneous
    law at fixed parameters (``law_params``; the law's defaults when None; the overall modulus is absorbed by the
    weights),

    .. math:: y(t) = a_\infty B_\infty(t) + \sum_k a_k B_k(t),\qquad a \ge 0,

    :math:`B_\infty` the elastic response (all branch ratios 0) and :math:`B_k` the response of the single mode
    :math:`e^{-t/\tau_k}` (from the prediction with :math:`\beta_k = 1`: :math:`B_k = 2 y_{\beta_k=1} - B_\infty`).
    Every column is the package's own forward model (:func:`tissuemech.fitting.predict`: apparent rim stress
    through the radius quadrature for plate histories, the first harmonic for amplitude sweeps, G*(omega) for
    frequency sweeps; creep read as strain-controlled, :func:`as_strain_controlled`), scaled by the fit's noise
    model; :func:`scipy.optimize.nnls` selects the times.

    With ``units`` (the loaded piece of every curve, e.g. ``specimen/sample``) each piece *u* gets a modulus level
    :math:`c_u` (:math:`y_u = c_u [a_\infty B_\infty + \sum_k a_k B_k]`): specimens differ in stiffness, and
    without it the shape common to all pieces (the spectrum, the law's curvature) would be fitted to whichever
    piece is stiffest. NNLS and the levels alternate (each level: the median log ratio of its piece's points,
    geometric mean of all levels 1) until the levels change by < 0.1 %.

    Parameters
    ----------
    curves : the curves (creep read as strain-controlled; flow curves are ignored)
    window : :func:`resolved_window_s` of the curves (computed when None)
    law_tag, law_params : the instantaneous law driving the basis and its parameters (others ignored)
    per_decade : grid density (times per decade) of :func:`window_taus`
    target : plate target of :mod:`tissuemech.fitting` (``apparent_stress`` or ``torque``)
    units : one loaded-piece label per curve, or None (one level for all)
    merge_per_decade : ``per_decade`` of :func:`merged_times` (None keeps every time of a band)

    Returns
    -------
    ``{"taus_s": active times [s] (pairs merged, :func:`merged_times`; empty without a window or an active mode),
    "grid_s", "weights" (first entry the equilibrium share, relative to the instantaneous modulus), "modulus_pa"
    (the instantaneous modulus the weights imply), "equilibrium_share", "levels" ({unit: c_u}; empty without
    ``units``), "method"}``
    """
    units = list(units) if units is not None else None
    if units is not None and len(units) != len(curves):
        raise ValueError(f"units: {len(units)} labels for {len(curves)} curves")
    originals = list(curves)
    curves = [as_strain_controlled(c) for c in curves]
    window = resolved_window_s(curves) if window is None else window
    grid = window_taus({**window, "t_min_s": window.get("t_min_s", np.nan) / 10.0 ** NNLS_GRID_BELOW_DECADES},
                       per_decade)
    out = {"taus_s": np.array([]), "grid_s": grid, "weights": np.array([]), "modulus_pa": np.nan,
           "equilibrium_share": np.nan, "levels": {},
           "method": f"NNLS on {per_decade:g} relaxation times per decade from {NNLS_GRID_BELOW_DECADES:g} decade "
                     f"below the resolved window to its end ({law_tag} instantaneous law"
                     + (", one modulus level per loaded piece)" if units is not None else ")")}
    usable = ("shear_history", "oscillation", "amplitude_sweep")
    kept = [i for i, c in enumerate(curves) if c.response in usable]
    curves = [curves[i] for i in kept]
    if grid.size == 0 or not curves:
        return out
    model = model_on_times(f"qlv_{law_tag}_prony{grid.size}", grid)
    noise = F.NoiseModel()
    observed = [F.target_observations(c, target) for c in curves]
    scales = [{k: noise.sigma(k, y, sd.get(k)) for k, y in obs.items()} for obs, sd in observed]

    def column(p: Mapping[str, float]) -> np.ndarray:
        parts = []
        for c, (obs, _), sig in zip(curves, observed, scales):
            pred = F.predict(model, p, c, target)
            parts += [np.asarray(pred[k], float) / sig[k] for k in obs]
        return np.concatenate(parts)

    rhs = np.concatenate([np.asarray(y, float) / sig[k] for (obs, _), sig in zip(observed, scales)
                          for k, y in obs.items()])
    row_unit = np.concatenate([np.full(np.size(y), units[i] if units is not None else "", dtype=object)
                               for i, (obs, _) in zip(kept, observed) for y in obs.values()])
    elastic = dict(model.default_params())
    elastic.update({k: float(v) for k, v in (law_params or {}).items() if k in model.instantaneous.param_names})
    elastic.update({f"beta_{i + 1}": 0.0 for i in range(grid.size)})
    b_inf = column(elastic)
    cols = [b_inf] + [2.0 * column({**elastic, f"beta_{i + 1}": 1.0}) - b_inf for i in range(grid.size)]
    design = np.column_stack(cols)
    ok = np.isfinite(design).all(axis=1) & np.isfinite(rhs)
    design, rhs, row_unit = design[ok], rhs[ok], row_unit[ok]
    coef, level = nnls_with_levels(design, rhs, row_unit if units is not None else None)
    total = coef.sum()
    if total > 0:
        g0 = initial_shear_modulus(model.instantaneous, model.instantaneous_params(elastic))
        out.update(taus_s=merged_times(grid, coef[1:], merge_per_decade), weights=coef / total,
                   modulus_pa=float(g0 * total), equilibrium_share=float(coef[0] / total), levels=level)
    return _with_creep_times(out, originals, window, per_decade, units, merge_per_decade)


#: a time of the creep's retardation NNLS joins the other tests' NNLS times only this far (factor) from every one
CREEP_TIME_SEPARATION = 10 ** 0.5


def _with_creep_times(spectrum: dict, curves: Sequence[F.Curve], window: Mapping, per_decade: float,
                      units: Sequence[str] | None, merge_per_decade: float | None) -> dict:
    """``spectrum`` with the creep curves' relaxation times (:func:`creep_relaxation_times`): they replace the
    times (and levels) when creep is the only history or sweep among ``curves``, and otherwise join them where
    they are more than :data:`CREEP_TIME_SEPARATION` from every one."""
    creep = creep_relaxation_times(curves, window, per_decade, units, merge_per_decade)
    extra = creep["taus_s"]
    if not extra.size:
        return spectrum
    note = "; creep-recovery read in its own direction (retardation NNLS on creep and recovery, exact conversion)"
    others = [c for c in curves if c.response in ("shear_history", "oscillation", "amplitude_sweep")]
    taus = np.asarray(spectrum["taus_s"], float)
    if not others or not taus.size:
        levels = creep["levels"] if not others else spectrum["levels"]
        return {**spectrum, "taus_s": extra, "levels": levels, "method": spectrum["method"] + note}
    far = np.array([np.min(np.abs(np.log(t / taus))) > np.log(CREEP_TIME_SEPARATION) for t in extra])
    if not far.any():
        return spectrum
    return {**spectrum, "taus_s": np.sort(np.r_[taus, extra[far]]), "method": spectrum["method"] + note}


# ----------------------------------------------------------------------------------------------------------
# candidates
# ----------------------------------------------------------------------------------------------------------
def candidate_key(law_tag: str, n_times: int, fluid: bool = False) -> str:
    """Key of the QLV candidate on ``n_times`` data-chosen times (``qlv_<law>_prony<n>`` or ``..._fluid<n>``)."""
    return f"qlv_{law_tag}_{'fluid' if fluid else 'prony'}{n_times}"


def spectrum_starts(model, spectrum: Mapping) -> list[dict]:
    """Starts of a QLV candidate from an NNLS spectrum: the law's moduli scaled to the spectrum's instantaneous
    modulus, the branch ratios from the NNLS weights (merged times: the weights of the nearest grid times); for a
    one-term Ogden law one start at each sign of alpha."""
    p = model.default_params()
    law = model.instantaneous
    g0 = initial_shear_modulus(law, model.instantaneous_params(p))
    target = float(spectrum.get("modulus_pa", np.nan))
    if np.isfinite(target) and target > 0 and g0 > 0:
        for s in law.param_specs:
            if s.unit == "Pa":
                p[s.name] = p[s.name] * target / g0
    grid, w = np.asarray(spectrum.get("grid_s", [])), np.asarray(spectrum.get("weights", []))
    taus = model.taus(p)
    if grid.size and w.size == grid.size + 1:
        share = np.array([w[1:][np.abs(np.log(grid) - np.log(t)) <= np.log(10) / NNLS_TIMES_PER_DECADE * 1.01].sum()
                          for t in taus])
        if getattr(model, "fluid", False):
            ref = max(share[-1], 1e-3 * share.sum(), 1e-12)
            ratios = share[:-1] / ref
        else:
            ref = max(w[0], 1e-3 * w.sum(), 1e-12)
            ratios = share / ref
        p.update({f"beta_{i + 1}": float(min(max(r, 1e-3), MAX_START_BETA)) for i, r in enumerate(ratios)})
    starts = [p]
    if "alpha1" in p and "alpha2" not in p:
        starts.append({**p, "alpha1": -p["alpha1"]})
    return starts


@dataclass(frozen=True)
class SpectrumStarts:
    """Picklable start rule of a candidate: :func:`spectrum_starts` of the candidate's model and a spectrum."""

    factory: SpectrumFactory
    spectrum: tuple

    def __call__(self, curves) -> list[dict]:
        return spectrum_starts(self.factory(), dict(self.spectrum))


def candidates(spectrum: Mapping, laws: Sequence[str], fluid: bool) -> list:
    """Ranking candidates (:class:`tissuemech.ranking.Candidate`) of every law on the spectrum's times; with
    ``fluid`` also the fluid variant of each law."""
    taus = tuple(float(t) for t in spectrum["taus_s"])
    frozen = tuple((k, tuple(np.asarray(v, float).tolist()) if isinstance(v, np.ndarray) else v)
                   for k, v in spectrum.items() if k in ("grid_s", "weights", "modulus_pa"))
    out = []
    for tag in laws:
        for is_fluid in ((False, True) if fluid else (False,)):
            key = candidate_key(tag, len(taus), is_fluid)
            factory = SpectrumFactory(key, taus)
            out.append(Candidate(key, factory, starts=SpectrumStarts(factory, frozen)))
    return out


# ----------------------------------------------------------------------------------------------------------
# the fit: times, law, pruning, verdict
# ----------------------------------------------------------------------------------------------------------
@dataclass
class MaterialFit:
    """Outcome of :func:`fit_material`.

    Attributes
    ----------
    table : the ranking table (:func:`tissuemech.ranking.ranking_table` columns, with ``determined``,
        ``undetermined``, ``misfit_noise_units``, ``adequate``, ``skill``, ``verdict``, ``verdict_reason``,
        ``recommended``, ``recommendation``, ``relaxation_times_s``; :mod:`tissuemech.adequacy`)
    fits : key -> :class:`tissuemech.fitting.FitResult` of every candidate fitted
    spectrum : the NNLS spectrum of the chosen times (:func:`nnls_relaxation_times`) and the window
    recommendation : :func:`tissuemech.adequacy.verdict` and its ``statement``
    factories : key -> model factory (rebuilds each candidate's model)
    failures : key -> why a candidate could not be fitted
    """

    table: pd.DataFrame
    fits: dict
    spectrum: dict
    recommendation: dict
    factories: dict
    failures: dict


#: how far (decades) a refined relaxation time may move from its NNLS time, at most; it never passes the log
#: midpoint to a neighbouring time, so the branches keep their order
REFINE_DECADES = 0.5


def refined_times(key: str, curves: Sequence[F.Curve], target: str, taus_s: Sequence[float], fit: F.FitResult,
                  noise: F.NoiseModel | None = None) -> np.ndarray | None:
    """The relaxation times of a fixed-time QLV solid ``key`` fitted with the rest of the model, from its NNLS
    times ``taus_s`` and its fit ``fit`` on ``curves``; None for other keys (fluid, Pipkin-Rogers) or a failed fit.

    NNLS picks times on a grid (a few per decade, neighbours merged); a slow mode between grid points shows where
    the data see it most precisely, e.g. in the tail of a creep recovery, far below the creep strain but well above
    the strain noise. The model is refitted with free times (:class:`tissuemech.models.qlv.QLVModel` ``free_taus``),
    each bounded to :data:`REFINE_DECADES` around its NNLS time and to the log midpoints to its neighbours.
    """
    taus = np.asarray(taus_s, float)
    m = FIXED_TIME_KEY.fullmatch(key)
    if m is None or m.group(1) != "qlv" or m.group(3) == "fluid" or taus.size == 0 or not fit.success:
        return None
    model = qlv.QLVModel(qlv.instantaneous_law(m.group(2)), n_prony=taus.size, taus_s=taus, free_taus=True,
                         name=key)
    log_t = np.log10(taus)
    mid = 0.5 * (log_t[1:] + log_t[:-1])
    lower = np.maximum(np.r_[-np.inf, mid], log_t - REFINE_DECADES)
    upper = np.minimum(np.r_[mid, np.inf], log_t + REFINE_DECADES)
    bounds = {f"tau_{i + 1}": (10.0 ** lower[i], 10.0 ** upper[i]) for i in range(taus.size)}
    problem = F.FitProblem(model=model, curves=list(curves), target=target, model_key=key, scope="refine",
                           noise=noise or F.NoiseModel(), bounds=bounds)
    start = {**fit.params, **{f"tau_{i + 1}": float(t) for i, t in enumerate(taus)}}
    free = F.fit(problem, starts=[start], n_random=0)
    if not free.success:
        return None
    return np.array([free.params[f"tau_{i + 1}"] for i in range(taus.size)])



def _fit_candidates(cands, curves, target, scope, n_random, seed, failures) -> dict:
    fits = {}
    for cand in cands:
        try:
            fits[cand.key] = fit_candidate(cand, curves, target, scope=scope, n_random=n_random, seed=seed)
        except (ValueError, RuntimeError, FloatingPointError) as exc:  # recorded, never silently dropped
            failures[cand.key] = f"{type(exc).__name__}: {exc}"
    return fits


def _best(fits: Mapping) -> str | None:
    ok = [k for k, r in fits.items() if r.success and np.isfinite(r.aicc)]
    return min(ok, key=lambda k: fits[k].aicc) if ok else None


def law_tag(key: str) -> str:
    """The instantaneous-law tag of a fixed-time QLV key (``qlv_rp3_prony4_v2`` -> ``rp3``)."""
    m = FIXED_TIME_KEY.fullmatch(key)
    if m is None:
        raise KeyError(f"{key!r} is not a fixed-time QLV key")
    return m.group(2)


def pruned_times(result: F.FitResult, taus_s: Sequence[float], fluid: bool) -> np.ndarray:
    """The times of a QLV fit whose branch ratios are determined (the undetermined or zero ones dropped); a
    fluid's reference (slowest) branch is always kept."""
    taus = np.asarray(taus_s, float)
    bad = set(undetermined(result)) | {n for n in F.at_bound_parameters(result.flags)}
    n_beta = taus.size - 1 if fluid else taus.size
    keep = [i for i in range(n_beta) if f"beta_{i + 1}" not in bad and result.params.get(f"beta_{i + 1}", 0.0) > 0]
    if fluid:
        keep.append(taus.size - 1)
    return taus[keep]


def fit_material(curves: Sequence[F.Curve], target: str, laws: Sequence[str] = MATERIAL_LAWS, seed: int = 0,
                 n_random: int = 0, scope: str = "material", dataset: str = "") -> MaterialFit:
    """Fit the material model of a dataset's shear tests (module docstring, steps 1-4).

    Parameters
    ----------
    curves : the averaged shear-test curves (amplitude sweeps whole: ``fitting.curves_from_averages(...,
        amplitude="full")``), with their plate geometry
    target : plate target of :mod:`tissuemech.fitting` (the pipeline's ``fit.plate_target``)
    laws : instantaneous-law tags to choose among
    seed, n_random : seeded random starts per candidate beyond the spectrum's starts
    """
    failures: dict[str, str] = {}
    window = resolved_window_s(curves)
    spectrum = nnls_relaxation_times(curves, window)
    if not len(spectrum["taus_s"]):
        rec = {"recommended": None, "verdict": "no_model_supported",
               "reason": "the tests resolve no relaxation time (no time window, or no active mode in it)",
               "statement": "no_model_supported: the tests resolve no relaxation time"}
        return MaterialFit(pd.DataFrame(), {}, {**spectrum, "window": window}, rec, {}, failures)
    fluid = not spectrum["equilibrium_share"] > 0
    cands = candidates(spectrum, laws, fluid)
    fits = _fit_candidates(cands, curves, target, scope, n_random, seed, failures)
    factories = {c.key: c.factory for c in cands}

    def add(tag: str, times: np.ndarray, is_fluid: bool, source: Mapping) -> None:
        for key, factory in factories.items():
            # the same law on the same times is the same candidate
            if (law_tag(key) == tag and ("_fluid" in key) == is_fluid and len(factory.taus_s) == len(times)
                    and np.allclose(factory.taus_s, times, rtol=1e-6)):
                return
        cand = candidates({**source, "taus_s": times}, [tag], is_fluid)[-1 if is_fluid else 0]
        key, variant = cand.key, 1
        while key in fits or key in failures:
            variant += 1
            key = f"{cand.key}_v{variant}"
        cand = replace(cand, key=key, factory=SpectrumFactory(key, cand.factory.taus_s))
        fits.update(_fit_candidates([cand], curves, target, scope, n_random, seed, failures))
        factories[key] = cand.factory

    best = _best(fits)
    if best is not None:
        # the times again with the chosen law: a stiffening law changes what the ramps ask of the spectrum
        tag, is_fluid = law_tag(best), "_fluid" in best
        law_params = {k: v for k, v in fits[best].params.items() if not k.startswith("beta_")}
        second = nnls_relaxation_times(curves, window, law_tag=tag, law_params=law_params)
        first = np.asarray(factories[best].taus_s)
        same = second["taus_s"].size == first.size and np.allclose(second["taus_s"], first, rtol=1e-6)
        if second["taus_s"].size and not same:
            add(tag, second["taus_s"], is_fluid, second)
            if _best(fits) != best:
                spectrum = second
    # pruning: the best fits with undetermined branch weights, refitted on their determined branches
    for key in sorted((k for k in fits if fits[k].success), key=lambda k: fits[k].aicc)[:3]:
        if determined(fits[key]):
            continue
        taus = np.asarray(factories[key].taus_s)
        kept = pruned_times(fits[key], taus, "_fluid" in key)
        if 0 < kept.size < taus.size:
            add(law_tag(key), kept, "_fluid" in key, spectrum)
    table = ranking_table(fits, None, scope=scope, dataset=dataset)
    table = table.sort_values("aicc").reset_index(drop=True)
    table["rank"] = np.arange(1, len(table) + 1)
    table["rank_criterion"] = "aicc"
    table = add_assessment(table, {k: assess(factories[k](), fits[k], curves, target) for k in fits})
    rec = verdict(table)
    times = ", ".join(f"{t:.3g}" for t in spectrum.get("taus_s", []))
    rec["statement"] = (f"{rec['verdict']}: {rec['recommended'] or 'no model'} (resolved window "
                        f"{window['t_min_s']:.3g}-{window['t_max_s']:.3g} s, relaxation times {times} s); "
                        f"{rec['reason']}")
    table["verdict"] = rec["verdict"]
    table["verdict_reason"] = rec["reason"]
    table["recommendation"] = rec["statement"]
    table["recommended"] = table["model"] == rec["recommended"]
    table["relaxation_times_s"] = [" ".join(f"{t:.4g}" for t in factories[k].taus_s) for k in table["model"]]
    table["baseline"] = table["model"] == baseline_model(table)
    return MaterialFit(table, fits, {**spectrum, "window": window}, rec, factories, failures)


def baseline_model(table: pd.DataFrame) -> str | None:
    """The material model the data are compared with (the diagnosis's baseline, the simulator's baseline card):
    the recommended model when the scope has one, else the lowest-AICc fit that is recommendable and better than
    the curves' means, a determined one first. None without such a fit."""
    if table.empty or "model" not in table:
        return None
    if "baseline" in table and table["baseline"].astype(bool).any():
        return str(table[table["baseline"].astype(bool)]["model"].iloc[0])
    if "recommended" in table and table["recommended"].astype(bool).any():
        return str(table[table["recommended"].astype(bool)]["model"].iloc[0])
    usable = table[table["recommendable"].astype(bool) & (table["skill"] > 0)]
    if usable.empty:
        return None
    usable = usable.assign(_undetermined=~usable["determined"].astype(bool)).sort_values(["_undetermined", "aicc"])
    return str(usable["model"].iloc[0])


# ----------------------------------------------------------------------------------------------------------
# fit one test kind, predict the others
# ----------------------------------------------------------------------------------------------------------
def cross_test(factory, result: F.FitResult, curves: Sequence[F.Curve], target: str, seed: int = 0) -> pd.DataFrame:
    """Refit ``result``'s model without each test kind and score it on the held-out kind.

    Returns one row per held-out test kind: ``held_out_test``, ``model``, ``nrmse`` (held-out, the fit stage's
    NRMSE), ``n_points``, ``misfit_noise_units`` (held-out, :func:`misfit_in_noise_units`), ``skill``,
    ``train_tests``, ``status`` (``ok``, or why the kind was not scored: the only test kind, or a failed refit).
    """
    kinds = sorted({c.test for c in curves})
    rows = []
    for kind in kinds:
        held = [c for c in curves if c.test == kind]
        train = [c for c in curves if c.test != kind]
        row = {"held_out_test": kind, "model": result.model_key, "nrmse": np.nan,
               "n_points": int(sum(c.n_points for c in held)), "misfit_noise_units": np.nan, "skill": np.nan,
               "train_tests": " ".join(sorted({c.test for c in train})), "status": "ok"}
        if not train:
            row["status"] = "not scored: the only test kind"
            rows.append(row)
            continue
        try:
            refit = fit_candidate(Candidate(result.model_key, factory, starts=lambda _c: [dict(result.params)]),
                                  train, target, scope="cross_test", n_random=0, seed=seed)
            row.update(held_out_score(factory(), refit.params, held, target))
        except (ValueError, RuntimeError, FloatingPointError) as exc:
            row["status"] = f"failed: {exc}"
        rows.append(row)
    return pd.DataFrame(rows)


def held_out_score(model: ConstitutiveModel, params, curves: Sequence[F.Curve], target: str) -> dict:
    """How fixed parameters predict curves they were not fitted to: ``nrmse`` (:func:`tissuemech.fitting.evaluate`),
    ``misfit_noise_units`` and ``skill`` (:func:`tissuemech.adequacy.misfit_in_noise_units`)."""
    ev = F.evaluate(model, params, curves, target)
    m = misfit_in_noise_units(model, params, curves, target)
    return {"nrmse": ev["nrmse"], "misfit_noise_units": m["misfit"], "skill": m["skill"]}
