"""Causes read from ramps and relaxations: a torque offset, the within-ramp signature regression of
non-separable relaxation, rim-stress nonlinearity and wall slip, the finite rise time of a relaxation step
and an unidentified I2 dependence (normal force). Part of :mod:`.catalogue`."""
from __future__ import annotations

import numpy as np
import pandas as pd
import scipy
from statsmodels.regression.linear_model import OLS

from .. import stats as st
from ..spectra import decade_aligned_taus, prony_complex_modulus
from .evidence import fit_prony_relaxation, nominal_strain, run_id
from .noise import estimate_noise, noise_sd
from .findings import (DiagnosisContext, TIME_DOMAIN, cv_group_column, demean_by, fix_record, group_cv,
                       make_finding, rms, untested_finding)

# ------------------------------------------------------------------------------------------------
# torque offset
# ------------------------------------------------------------------------------------------------
def _offset_design(g: pd.DataFrame) -> np.ndarray:
    """Per-curve design of the offset regression: [1, predicted] plus, for relaxation holds, time in the
    test (a drifting offset M0 + dM/dt t; in a ramp time and strain are collinear, so it is left out)."""
    cols = [np.ones(len(g)), g["predicted"].to_numpy(float)]
    if g["test"].iloc[0] == "stress_relaxation" and np.isfinite(g["time_in_test"]).all():
        t = g["time_in_test"].to_numpy(float)
        cols.append(t / max(t.max(), 1e-12))
    return np.column_stack(cols)


def offset_rows(table: pd.DataFrame) -> pd.DataFrame:
    """The residual rows an additive torque offset is read from: the shear stress of every relaxation hold and
    of the small-strain part (<= 20 %) of the ramps."""
    td = table[table["test"].isin(TIME_DOMAIN) & (table["quantity"] == "shear_stress")]
    return td[(td["test"] == "stress_relaxation") | (td["strain"] <= 0.2)]


def offset_intercept(table: pd.DataFrame) -> dict | None:
    """Common additive intercept [Pa] of the stress residuals of :func:`offset_rows`, the estimator of
    :func:`detect_torque_offset`.

    Per curve, residual = c_k + (s_k - 1) predicted (+ a linear drift in relaxation holds); across curves,
    c_k = c + d level_k (a shape misfit of the model leaves intercepts proportional to the curve's stress
    level, an offset is the same on every curve), precision-weighted, cluster-robust. Returns the
    :func:`tissuemech.stats.coefficient_test` dict of c (``estimate`` [Pa]) with ``curves`` (the curves used),
    or None with fewer than 4 usable curves.
    """
    td = offset_rows(table)
    td = td[np.isfinite(td["residual"]) & np.isfinite(td["predicted"]) & np.isfinite(td["sigma"]) & (td["sigma"] > 0)]
    intercepts, ses, levels_pa, curves = [], [], [], []
    for c, g in td.groupby("curve"):
        if len(g) < 8 or g["predicted"].max() < 1.5 * g["predicted"].min():
            continue
        A = _offset_design(g)
        w = 1.0 / g["sigma"].to_numpy()
        Aw, yw = A * w[:, None], g["residual"].to_numpy() * w
        coef, *_ = np.linalg.lstsq(Aw, yw, rcond=None)
        dof = max(len(g) - A.shape[1], 1)
        s2 = float(np.sum((yw - Aw @ coef) ** 2) / dof)
        cov = s2 * np.linalg.pinv(Aw.T @ Aw)
        intercepts.append(coef[0])
        ses.append(float(np.sqrt(max(cov[0, 0], 1e-30))))
        levels_pa.append(float(g["predicted_abs"].median()))
        curves.append(c)
    if len(intercepts) < 4:
        return None
    stage2 = st.cluster_regression(np.asarray(intercepts), pd.DataFrame({"level": levels_pa}),
                                   weights=1.0 / np.asarray(ses) ** 2)
    return dict(st.coefficient_test(stage2, "const"), curves=curves)


def detect_torque_offset(ctx: DiagnosisContext) -> dict:
    """Per-curve intercept of the stress residual on the predicted stress (small-strain time-domain data).

    An additive torque offset gives residual = c + (s - 1) * predicted with c the same on every curve,
    while specimen variability only changes the slope s; the per-curve intercepts are t-tested across curves
    (:func:`offset_intercept`). Practical only when the intercept is at least 2 % of the lowest curve's level and
    no larger than that level (an offset is part of every observed stress), and, where both kinds are measured,
    when the ramp starts and the relaxation holds give the same intercept (:func:`offset_consistency`: not
    significantly different, or of one sign and within a factor :data:`OFFSET_AGREEMENT`; a misfit of the
    baseline's shape, e.g. a strain-dependent relaxation, gives them different ones). The fix is the baseline refitted with the offset removed, scored on held-out
    conditions (``fit_info["fixes"]["torque_offset"]``, :func:`tissuemech.diagnosis.report.with_model_fixes`)
    when it was scored, else the held-out curves' residuals less the offset estimated on the other curves.
    """
    eff = "torque_offset"
    td = offset_rows(ctx.table)
    t = offset_intercept(ctx.table)
    if t is None:
        return untested_finding(eff, "fewer than 4 small-strain relaxation/ramp curves with a usable stress range")
    curves = t.pop("curves")
    tval = t["statistic"]
    radius = float(td["radius_m"].median())
    offset_pa = float(t["estimate"])
    offset_unm = offset_pa * np.pi * radius ** 3 / 2.0 * 1e6
    small = td[td["curve"].isin(curves)]
    sr = small[small["test"] == "stress_relaxation"]
    # scale the offset against the lowest curve level, read from the OBSERVED stresses (median |observed| per
    # curve, relaxation holds when there are any): a model that collapses to a near-zero prediction must not
    # turn a small offset into an absurd percentage
    lowest = sr if not sr.empty else small
    late_level = float(lowest.groupby("curve")["observed"].apply(lambda v: np.median(np.abs(v))).min())

    def fit(train):
        est = offset_intercept(train)
        if est is None:
            raise ValueError("too few training curves")
        return float(est["estimate"])

    def error(test, par):
        # each held-out curve keeps its own stress level (a free factor on the prediction, with and without the
        # offset): the baseline was fitted to offset data and has already moved its levels and long-time plateau
        # towards the offset, so only the part of the offset that no change of level can give is scored
        out = []
        for _, g in test.groupby("curve"):
            y = g["residual"].to_numpy(float) - (0.0 if par is None else par)
            p = g["predicted"].to_numpy(float)
            pp = float(np.dot(p, p))
            y = y - (float(np.dot(p, y)) / pp) * p if pp > 0 else y
            out.append(y / g["predicted_abs"].to_numpy(float))
        return np.concatenate(out) if out else np.array([])

    group = "condition" if small["condition"].nunique() >= 3 else cv_group_column(small)
    before, after = group_cv(small, group, fit, error)
    share = abs(offset_pa) / late_level if late_level > 0 else np.inf
    where = (f"torque offset M0 = {offset_unm:+.3g} uN m at R = {1e3 * radius:.1f} mm" if np.isfinite(radius)
             else "no plate radius in the data: not convertible to a torque")
    if not share <= 1.0:
        offset_txt = "an intercept"
    else:
        offset_txt = f"a common additive intercept of {offset_pa:+.3g} Pa ({where}; t = {tval:.2f} across curves)"
    size = (f"{100 * share:.3g} % of the lowest curve level (median observed stress of that curve, "
            f"{late_level:.3g} Pa)" if share <= 1.0 else
            f"more than the lowest curve level itself ({late_level:.3g} Pa, median observed stress of that curve): an "
            f"intercept an offset of the transducer cannot make, so the baseline's misfit, not an offset"
            if late_level > 0 else "the observed stresses of these curves have no positive median level")
    evidence = (f"Stress residuals of {ctx.model} on {len(curves)} relaxation holds and ramp starts (<= 20 %) "
                f"have {offset_txt}, i.e. {size}"
                + (": G(t, gamma0) = sigma/gamma0 diverges as 1/gamma0." if share <= 1.0 else
                   f" (t = {tval:.2f} across curves)."))
    fix = ctx.fit_info.get("fixes", {}).get(eff) or fix_record(
        "torque offset M0 as a nuisance parameter (stress + 2 M0/(pi R^3))", "rms_rel_residual_small_strain",
        before, after, f"leave-one-{group}-out", offset_pa=offset_pa, offset_uNm=offset_unm,
        n_held_out_points=len(small))
    # an offset of the transducer is part of every observed stress, so it cannot exceed the lowest curve's level
    practical = bool(late_level > 0 and 0.02 <= share <= 1.0)
    # and it is one torque, the same in the ramps and the relaxation holds: a misfit of the baseline's shape (a
    # strain-dependent relaxation changes the holds, not the start of a ramp) gives them different intercepts
    consistency = offset_consistency(ctx.table)
    if consistency is not None:
        evidence += (f" Ramp starts alone give {consistency['ramps']:+.3g} Pa, relaxation holds alone "
                     f"{consistency['holds']:+.3g} Pa (z = {consistency['z']:.2f} for their difference)")
        r_, h_ = consistency["ramps"], consistency["holds"]
        apart = np.sign(r_) != np.sign(h_) or max(abs(r_), abs(h_)) > OFFSET_AGREEMENT * min(abs(r_), abs(h_))
        if consistency["p_value"] < st.ALPHA and apart:
            practical = False
            evidence += (": one transducer offset gives the same intercept in both, so this is a misfit of the "
                         "baseline's shape (e.g. a strain-dependent relaxation), not an offset.")
        else:
            evidence += ": consistent with one offset."
    return make_finding(eff, t, "t", offset_unm, "uN m", practical, evidence, fix, consistency=consistency)


#: largest ratio between the ramps' and the holds' intercepts still read as one offset: a baseline fitted to data with
#: an offset absorbs part of it, differently in the two kinds (the independent generator: 2.8 against 2.1 Pa for one
#: injected offset), while a misfit of the baseline's shape gives intercepts a factor 15 apart (the constructed
#: nonseparable design)
OFFSET_AGREEMENT = 3.0


def offset_consistency(table: pd.DataFrame) -> dict | None:
    """Intercepts of :func:`offset_intercept` read from the ramp starts alone and from the relaxation holds alone, and
    the z-test of their difference (two-sided, normal); None unless both have their 4 curves."""
    r = offset_intercept(table[table["test"] == "constant_shear_rate"])
    h = offset_intercept(table[table["test"] == "stress_relaxation"])
    if r is None or h is None:
        return None
    se = float(np.hypot(r["std_error"], h["std_error"]))
    z = (r["estimate"] - h["estimate"]) / se if se > 0 else 0.0
    return {"ramps": float(r["estimate"]), "holds": float(h["estimate"]), "z": float(z),
            "p_value": float(10 ** st.log10_p_from_z(z))}


# ------------------------------------------------------------------------------------------------
# time-domain signature regression: non-separability, rim-stress error, wall slip
# ------------------------------------------------------------------------------------------------
def _csr_frame(ctx: DiagnosisContext) -> pd.DataFrame:
    c = ctx.table[(ctx.table["test"] == "constant_shear_rate") & (ctx.table["quantity"] == "shear_stress")]
    c = c[np.isfinite(c["log_ratio"]) & np.isfinite(c["log_rate"]) & (c["strain"] >= 0.02)]
    if c.empty:
        return c
    return c.assign(y=demean_by(c, "log_ratio", "curve"))


def _slip_covariate(c: pd.DataFrame, sigma_c: float) -> np.ndarray:
    # no gap recorded -> NaN covariate (the detector is then not testable), never a default gap
    gap = (1.0 / c["inverse_gap"]).to_numpy()
    return np.maximum(0.0, c["observed"].to_numpy() - sigma_c) / (gap * 1e3) / c["strain"].to_numpy()


def _signature_regression(c: pd.DataFrame, sigma_c: float | None, slip_control: float | None = None):
    """Within-curve regression of the ramp log-residual on the signatures of science.md 4.4.

    Always: strain^2 and strain^3 (rate-independent: rim error), strain^2 x log-rate (non-separability),
    1/stress (offset). With ``sigma_c`` the slip covariate is added together with strain x log-rate, so
    that a smooth rate-dependent misfit cannot pass for a stress threshold."""
    cols = {"strain_sq": c["strain_sq"].to_numpy(), "strain_cu": c["strain"].to_numpy() ** 3,
            "strain_sq_x_log_rate": c["strain_sq_x_log_rate"].to_numpy(),
            "inv_stress": 1.0 / c["predicted_abs"].to_numpy()}
    if sigma_c is not None:
        cols["strain_x_log_rate"] = c["strain_x_log_rate"].to_numpy()
        cols["slip"] = _slip_covariate(c, sigma_c)
    if slip_control is not None:
        cols["slip_control"] = _slip_covariate(c, slip_control)
    X = pd.DataFrame(cols, index=c.index)
    X = X - X.groupby(c["curve"]).transform("mean")          # within-curve, as y
    return st.cluster_regression(c["y"].to_numpy(), X, groups=c["curve"].to_numpy())


def _best_slip(c: pd.DataFrame):
    best = None
    grid = np.quantile(c["observed"], [0.3, 0.5, 0.7, 0.85])
    for sc in grid:
        if np.count_nonzero(c["observed"] > sc) < 10:
            continue
        res = _signature_regression(c, sc)
        t = st.coefficient_test(res, "slip")
        if t["statistic"] < 0 and (best is None or t["statistic"] < best[1]["statistic"]):
            best = (sc, t, res)
    return best, len(grid)


def detect_nonseparable_relaxation(ctx: DiagnosisContext) -> dict:
    """Rate-dependent residual sign at large strain (strain^2 x log-rate interaction in the CSR residuals)
    and strain-specific relaxation shapes in the relaxation residuals (level x log-time interaction)."""
    eff = "nonseparable_relaxation"
    parts, texts, ev_size = [], [], np.nan
    c = _csr_frame(ctx)
    if not c.empty and c["log_rate"].nunique() >= 2 and c["curve"].nunique() >= 4:
        # the best stress-threshold (slip) covariate is a control: a rate-dependent misfit that a stress
        # threshold explains is not evidence of non-separability
        best_slip, _ = _best_slip(c)
        res = _signature_regression(c, None, slip_control=best_slip[0] if best_slip else None)
        t3 = st.coefficient_test(res, "strain_sq_x_log_rate")
        parts.append(t3)
        rates = np.sort(c["log_rate"].unique())
        gmax = float(c["strain"].max())
        ev_size = float(t3["estimate"] * gmax ** 2 * (rates[-1] - rates[0]))
        fast = c[c["log_rate"] == rates[-1]]
        slow = c[c["log_rate"] == rates[0]]
        big_f = fast.loc[fast["strain"] >= 0.5 * gmax, "log_ratio"].mean()
        big_s = slow.loc[slow["strain"] >= 0.5 * gmax, "log_ratio"].mean()
        texts.append(f"constant-shear-rate residuals of {ctx.model} change sign with rate at large strain "
                     f"(strain^2 x log10-rate coefficient {t3['estimate']:.3g}, t = {t3['statistic']:.2f}, "
                     f"{c['curve'].nunique()} ramps, clustered): above {50 * gmax:.0f} % strain the model is "
                     f"{100 * np.expm1(-big_f):+.0f} % off at {10 ** rates[-1]:g} 1/s and "
                     f"{100 * np.expm1(-big_s):+.0f} % at {10 ** rates[0]:g} 1/s (model minus data)")
    sr = ctx.table[(ctx.table["test"] == "stress_relaxation") & (ctx.table["quantity"] == "shear_stress")]
    sr = sr[np.isfinite(sr["log_ratio"]) & (sr["time_in_test"] > 0)]
    shape_change = np.nan
    if not sr.empty:
        levels = sr.groupby("curve")["strain"].max().round(4)
        sr = sr.assign(level=sr["curve"].map(levels))
        # hold segment only: from 2x the ramp end onwards
        ramp_end = sr[sr["strain"] >= 0.98 * sr["level"]].groupby("curve")["time_in_test"].min()
        sr = sr[sr["time_in_test"] >= 2.0 * sr["curve"].map(ramp_end).clip(lower=1e-3)]
        if sr["level"].nunique() >= 2 and sr["curve"].nunique() > sr["level"].nunique():
            lt = np.log10(sr["time_in_test"])
            edges = np.linspace(lt.min(), lt.max() + 1e-9, 9)
            sr = sr.assign(bin=np.digitize(lt, edges))
            sr = sr.assign(inv_stress=1.0 / sr["predicted_abs"])
            cell = sr.groupby(["curve", "bin"]).agg(y=("log_ratio", "mean"), level=("level", "first"),
                                                    inv_stress=("inv_stress", "mean")).reset_index()
            # 1/stress: a torque offset also makes small-strain holds decay differently; it is not this cause
            r0 = OLS.from_formula("y ~ C(curve) + C(bin) + inv_stress", cell).fit()
            r1 = OLS.from_formula("y ~ C(curve) + C(bin) + C(level):C(bin) + inv_stress", cell).fit()
            dk = int(r1.df_model - r0.df_model)
            if dk > 0 and r1.df_resid > 0:
                f = st.nested_f_test(r0.ssr, r1.ssr, r1.nobs, int(r1.df_model) + 1, dk)
                parts.append(f)
                lv = np.sort(cell["level"].unique())
                last = cell["bin"].max()
                first = cell["bin"].min()
                decay = cell.pivot_table(index="curve", columns="bin", values="y")
                lvl = cell.groupby("curve")["level"].first()
                shape = (decay[last] - decay[first]).groupby(lvl).mean()
                shape_change = float(shape.get(lv[-1], np.nan) - shape.get(lv[0], np.nan))
                texts.append(f"relaxation residuals have strain-specific shapes (level x log-time interaction "
                             f"F = {f['statistic']:.2f}, df = {dk}, {sr['curve'].nunique()} holds at "
                             f"{', '.join(f'{100 * x:g} %' for x in lv)}): from early to late hold the "
                             f"{100 * lv[-1]:g} % curve decays {100 * shape_change:+.1f} % relative to the "
                             f"{100 * lv[0]:g} % curve beyond what the shared QLV shape allows")
    if not parts:
        return untested_finding(eff, "needs constant-shear-rate ramps at >= 2 rates or relaxation at >= 2 strain levels")
    t = st.strongest_component(parts)
    effect = ev_size if np.isfinite(ev_size) else shape_change
    fix = ctx.fit_info.get("fixes", {}).get(eff)
    evidence = "Non-separable (strain-dependent) relaxation: " + "; ".join(texts) + "."
    ramp_strongest = min(parts, key=lambda p: p["log10_p"]) is parts[0]
    return make_finding(eff, t, "t" if ramp_strongest and np.isfinite(ev_size) else "F", effect,
                    "log residual change across rates at max strain" if np.isfinite(ev_size) else
                    "relative shape change", abs(effect) >= 0.03, evidence, fix)


#: plate targets that compare the homogeneous law at the rim strain with the reported 2M/(pi R^3) (the thesis
#: method, :mod:`tissuemech.fitting`): the only ones a nonlinear material biases
RIM_BIASED_TARGETS = ("thesis",)


def _isochrone_exponents(ctx: DiagnosisContext, rim_strain: float) -> np.ndarray:
    """n = d ln M / d ln gamma_R at ``rim_strain`` from the relaxation isochrones of every sample.

    A relaxation hold is a scaled step at every radius, so the Rabinowitsch exponent is the slope of the
    reported stress against the step strain *at a fixed time* (science.md 2.1): per sample with >= 3 strain
    levels, ln sigma is read at times 2-10x the longest ramp, sigma = a g + b g^3 fitted over the levels
    (relative least squares) and n = (a + 3 b g^2) / (a + b g^2) evaluated at ``rim_strain``. Early in the
    hold the reduced relaxation is still close to 1, so strain-dependent relaxation weights barely move it;
    a ramp's log slope would mix the relaxation of the material (n < 1 for any linear viscoelastic ramp)
    into the exponent."""
    by_sample: dict[tuple, list] = {}
    for r in ctx.runs_of("stress_relaxation"):
        if "shear_stress" in r and "shear_strain" in r and "time" in r:
            by_sample.setdefault((str(r.attrs.get("specimen")), str(r.attrs.get("sample"))), []).append(r)
    out = []
    for runs in by_sample.values():
        if len(runs) < 3:
            continue
        levels, ramp_end = [], 0.0
        for r in runs:
            g = np.abs(r["shear_strain"].values)
            t = r["time"].values - r["time"].values[0]
            g0 = float(np.nanmax(g))
            levels.append((g0, t, np.abs(r["shear_stress"].values)))
            ramp_end = max(ramp_end, float(t[np.argmax(g >= 0.98 * g0)]))
        t_read = np.geomspace(max(2.0 * ramp_end, 0.05), max(10.0 * ramp_end, 1.0), 5)
        g0s, sig = [], []
        for g0, t, s in levels:
            ok = (t > 0) & (s > 0)
            if ok.sum() < 4 or t[ok].max() < t_read[-1]:
                continue
            g0s.append(g0)
            sig.append(float(np.exp(np.mean(np.interp(np.log(t_read), np.log(t[ok]), np.log(s[ok]))))))
        if len(g0s) < 3:
            continue
        g0s, sig = np.asarray(g0s), np.asarray(sig)
        X = np.column_stack([g0s, g0s ** 3]) / sig[:, None]
        a, b = np.linalg.lstsq(X, np.ones_like(sig), rcond=None)[0]
        if a <= 0:
            continue
        out.append((a + 3 * b * rim_strain ** 2) / (a + b * rim_strain ** 2))
    return np.asarray(out, float)


def _ramp_exponents(ctx: DiagnosisContext) -> np.ndarray:
    """n = d ln M / d ln gamma_R over the top 70 % of each constant-shear-rate ramp (exact for rate-independent
    ramps; in a relaxing material the log slope also carries the relaxation, see :func:`_isochrone_exponents`)."""
    ns = []
    for r in ctx.runs_of("constant_shear_rate"):
        if "shear_stress" not in r or "shear_strain" not in r:
            continue
        g = np.abs(r["shear_strain"].values)
        s = np.abs(r["shear_stress"].values)
        m = (g >= 0.3 * np.nanmax(g)) & (s > 0)
        if m.sum() >= 4:
            ns.append(np.polyfit(np.log(g[m]), np.log(s[m]), 1)[0])
    return np.asarray(ns, float)


def detect_rim_stress_nonlinearity(ctx: DiagnosisContext) -> dict:
    """Rabinowitsch exponent n = dlnM/dln(gamma_R) at the largest ramp strain; a baseline fitted the thesis way
    (homogeneous law vs the reported 2M/(pi R^3)) is biased there by 4/(n+3) - 1."""
    eff = "rim_stress_nonlinearity"
    target = ctx.fit_info.get("target", "thesis")
    csr = [r for r in ctx.runs_of("constant_shear_rate") if "shear_strain" in r]
    strains = [float(np.nanmax(np.abs(r["shear_strain"].values))) for r in csr + ctx.runs_of("stress_relaxation")
               if "shear_strain" in r]
    gmax = max(strains) if strains else np.nan
    ns = _isochrone_exponents(ctx, gmax) if np.isfinite(gmax) else np.asarray([])
    source = f"relaxation isochrones of {ns.size} samples (stress at 2-10x the ramp time vs step strain)"
    if ns.size < 3:
        ns = _ramp_exponents(ctx)
        source = f"log slope over the top 70 % of strain of {ns.size} constant-shear-rate ramps"
    if ns.size < 3:
        return untested_finding(eff, "fewer than 3 samples with relaxation at >= 3 strains and fewer than 3 "
                              "constant-shear-rate ramps to estimate n = dlnM/dln(gamma_R)")
    n_mean = float(ns.mean())
    se = float(ns.std(ddof=1) / np.sqrt(ns.size))
    bias = 4.0 / (n_mean + 3.0) - 1.0
    # practical null: |n - 1| <= 0.2, i.e. a rim-stress bias within 5 %
    tval = (abs(n_mean - 1.0) - 0.2) / se if se > 0 else np.inf
    lp = float(np.log10(max(scipy.stats.t.sf(tval, ns.size - 1), 1e-300)))
    t = st.statistic_result(tval, lp)
    if target not in RIM_BIASED_TARGETS:
        evidence = (f"n = dlnM/dln(gamma_R) = {n_mean:.2f} +- {se:.2f} at {100 * gmax:.0f} % ({source}), but the "
                    f"baseline was fitted through {target}, which already accounts for the radial strain field.")
        return make_finding(eff, st.statistic_result(tval, 0.0), "t", 0.0, "relative stress bias", False, evidence, None)
    evidence = (f"The material {'stiffens' if n_mean > 1 else 'softens'} (n = dlnM/dln(gamma_R) = {n_mean:.2f} +- "
                f"{se:.2f} at {100 * gmax:.0f} %, {source}) while {ctx.model} was fitted to the reported "
                f"2M/(pi R^3) as if it were the rim stress: the reported stress is {100 * bias:+.0f} % off the rim "
                f"stress at {100 * gmax:.0f} %, rate-independent and growing with strain; the stiffening "
                f"parameters are biased (C20 -> 2/3, C30 -> 1/2 of the truth for a reduced polynomial).")
    # the correction is exact for the power-law segment; its residual bias is the n uncertainty
    after = abs(4.0 / (n_mean + 3.0) - 4.0 / (n_mean + se + 3.0))
    fix = fix_record("torque forward model (radial Gauss-Legendre integral) or Rabinowitsch-corrected rim stress "
               "sigma_R = M/(2 pi R^3) (3 + n)", "rim_stress_bias_at_max_strain (not held-out)", abs(bias), after,
               "none (bias correction)", n=n_mean)
    return make_finding(eff, t, "t", bias, "relative stress bias at max strain", abs(bias) >= 0.05, evidence, fix)


def detect_wall_slip(ctx: DiagnosisContext) -> dict:
    """Stress-threshold (and gap-scaled) loss of stress in the ramps, with the non-separability and
    rim-stress signatures as controls; sigma_c profiled over a grid (Bonferroni)."""
    eff = "wall_slip"
    c = _csr_frame(ctx)
    if c.empty or c["curve"].nunique() < 4:
        return untested_finding(eff, "needs >= 4 constant-shear-rate ramps")
    best, k = _best_slip(c)
    if best is None:
        return make_finding(eff, st.statistic_result(0.0, 0.0), "t", 0.0, "Pa", False,
                        "No stress-threshold loss of stress in the ramps.", None)
    sigma_c, t, res = best
    lp = min(0.0, t["log10_p"] + np.log10(k))
    t = dict(t, p_value=10 ** lp, log10_p=lp)
    # size: the fitted stress loss at the most slipped point (largest stress over gap x strain)
    x_slip = _slip_covariate(c, sigma_c)
    loss = float(np.expm1(t["estimate"] * (x_slip.max() - np.median(x_slip))))
    gaps = np.unique(np.round(1e3 / c["inverse_gap"].dropna(), 1))
    gap_txt = (f"; gaps {gaps.min():.1f}-{gaps.max():.1f} mm ({gaps.size} values) enter through 1/h"
               if gaps.size > 1 else "; single gap (no Mooney gap regression possible)")

    def centred_slip(frame):
        x = _slip_covariate(frame, sigma_c)
        return x - pd.Series(x, index=frame.index).groupby(frame["curve"]).transform("mean").to_numpy()

    def fit(train):
        y = train["y"].to_numpy()
        x = centred_slip(train)
        return float(np.dot(x, y) / np.dot(x, x)) if np.dot(x, x) > 0 else 0.0

    def error(test, par):
        # the curve level (sample variability) is not the slip's business: compare within-curve shapes
        y = test["y"].to_numpy()
        return y if par is None else y - par * centred_slip(test)

    group = "condition" if c["condition"].nunique() >= 3 else cv_group_column(c)
    before, after = group_cv(c, group, fit, error)
    evidence = (f"Above a critical stress sigma_c ~ {sigma_c:.3g} Pa the ramps lose stress relative to "
                f"{ctx.model} at every rate (up to {100 * loss:+.0f} % at the largest stress; slip covariate "
                f"max(0, sigma - sigma_c)/(h gamma), t = {t['statistic']:.2f}, controls strain^2 and "
                f"strain^2 x log-rate, Bonferroni over {k} thresholds){gap_txt}.")
    fix = fix_record("slip-corrected strain gamma = gamma_app - 2 beta_s max(0, sigma - sigma_c)/h",
               "rms_log_residual", before, after, f"leave-one-{group}-out", sigma_c_pa=sigma_c,
               n_held_out_points=len(c))
    return make_finding(eff, t, "t", sigma_c, "Pa (critical stress)", loss <= -0.03, evidence, fix)


# ------------------------------------------------------------------------------------------------
# relaxation rise time and cross-test consistency
# ------------------------------------------------------------------------------------------------
def _measured_sweep(ctx: DiagnosisContext):
    ws, g1, g2 = [], [], []
    for r in ctx.runs_of("frequency_sweep"):
        if all(k in r for k in ("storage_modulus", "loss_modulus")):
            w = r["angular_frequency"].values if "angular_frequency" in r else 2 * np.pi * r["frequency"].values
            ws.append(w), g1.append(r["storage_modulus"].values), g2.append(r["loss_modulus"].values)
    if not ws:
        return None
    frame = pd.DataFrame({"w": np.concatenate(ws), "g1": np.concatenate(g1), "g2": np.concatenate(g2)})
    frame["w"] = frame["w"].round(6)
    return frame.groupby("w").median().reset_index()


def detect_finite_rise_time(ctx: DiagnosisContext) -> dict:
    """A relaxation ramp analysed as a step: (a) cross-test -- the frequency sweep predicted from the
    step-analysed Prony spectrum of each small-strain relaxation vs from the ramp-aware one (paired over
    tests; model-free, so it also says whether a ramp-aware baseline was needed); (b) when the baseline was
    fitted as a step (``fit_info["relaxation"] == "step"``), its early-hold residuals (t <= 10 t_r) against
    the later hold. Bonferroni over the components. Tested only when the baseline was fitted as a step: a
    baseline fitted through the measured strain history (``"measured"``) does not commit the error, so the
    cause cannot explain its misfit (the finding is then untested, with that reason)."""
    eff = "finite_rise_time"
    sr = [r for r in ctx.runs_of("stress_relaxation") if all(k in r for k in ("time", "shear_stress", "shear_strain"))]
    if len(sr) < 3:
        return untested_finding(eff, "fewer than 3 relaxation tests")
    lv = min(nominal_strain(r) for r in sr)
    small = [r for r in sr if nominal_strain(r) <= 1.5 * lv]
    ramps = []
    for r in small:
        g = np.abs(r["shear_strain"].values)
        t_ = r["time"].values
        ramps.append(t_[np.argmax(g >= 0.98 * g.max())] - t_[0])
    t_r = float(np.median(ramps))
    if t_r <= 0:
        return untested_finding(eff, "the relaxation data contain no ramp (ideal step in the export): the rise time "
                              "cannot be checked from these files")
    step_baseline = ctx.fit_info.get("relaxation", "measured") == "step"
    if not step_baseline:
        # the cause is an analysis error (a ramp treated as a step), not a property of the data: a baseline
        # fitted through the measured strain history does not commit it, so it cannot explain that
        # baseline's misfit. The model-free cross-test below would still show that *a* step analysis of
        # these data is biased whenever the fast modes are comparable to the rise time (true of any
        # sample), which is no finding about this diagnosis.
        return untested_finding(eff, f"not applicable: the baseline was fitted through the measured strain "
                                     f"history (relaxation ramps of {t_r:.3g} s are modelled, not treated as "
                                     f"steps)")
    parts, texts, fix = [], [], None
    sweep = _measured_sweep(ctx)
    tmax = max(float(r["time"].values.max()) for r in small)
    taus = decade_aligned_taus(t_r / 10.0, tmax)
    # weights from the noise of these relaxations themselves (evidence.estimate_noise), not an instrument constant
    relax_noise = estimate_noise(small)
    fits = []
    for r in small:
        g = np.abs(r["shear_strain"].values)
        s_ = np.abs(r["shear_stress"].values)
        t_ = r["time"].values - r["time"].values[0]
        sd = noise_sd(relax_noise, "stress_relaxation", "shear_stress", s_)
        w = np.where(np.isfinite(sd) & (sd > 0), 1.0 / sd, 0.0) if np.isfinite(sd).any() else np.ones_like(s_)
        fits.append((fit_prony_relaxation(t_, s_, g, taus, ramp_aware=False, weights=w),
                     fit_prony_relaxation(t_, s_, g, taus, ramp_aware=True, weights=w)))
    g_fast = [np.mean([p[k]["g_pa"][p[k]["taus_s"] <= 10 * t_r].sum() for p in fits]) for k in (0, 1)]
    if sweep is not None:
        w_ = sweep["w"].to_numpy()

        def sweep_err(f):
            gs = prony_complex_modulus(f["g_inf_pa"], f["g_pa"], f["taus_s"], w_)
            return rms(np.r_[np.log(np.maximum(np.abs(gs.real), 1e-9) / sweep["g1"]),
                              np.log(np.maximum(np.abs(gs.imag), 1e-9) / sweep["g2"])])
        e_step = np.array([sweep_err(p[0]) for p in fits])
        e_ramp = np.array([sweep_err(p[1]) for p in fits])
        d = e_step - e_ramp
        tval = d.mean() / (d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 and d.std(ddof=1) > 0 else 0.0
        parts.append(st.statistic_result(tval, st.log10_p_from_t(tval, max(d.size - 1, 1))))
        before, after = float(np.mean(e_step)), float(np.mean(e_ramp))
        fix = fix_record("ramp-aware relaxation fit (exact recursion over the measured strain history)",
                   "rms_log_error_frequency_sweep_predicted_from_relaxation", before, after,
                   "cross-test (relaxation -> frequency sweep)", rise_time_s=t_r)
        texts.append(f"the frequency sweep predicted from each {100 * lv:g} % relaxation is off by "
                     f"{100 * before:.0f} % (rms log error of G', G'') with the step analysis and "
                     f"{100 * after:.0f} % with a ramp-aware analysis of the same data (paired over {d.size} "
                     f"tests, t = {tval:.2f})")
    early = ctx.table[(ctx.table["test"] == "stress_relaxation") & (ctx.table["quantity"] == "shear_stress")]
    early = early[np.isfinite(early["log_ratio"]) & (early["time_in_test"] > 0)]
    if step_baseline and not early.empty and early["curve"].nunique() >= 3:
        ind = (early["time_in_test"] <= 10 * t_r).astype(float)
        if 0 < ind.sum() < len(ind):
            y = demean_by(early.assign(ind=ind), "log_ratio", "curve")
            x = (ind - ind.groupby(early["curve"]).transform("mean")).to_numpy()
            res = st.cluster_regression(y, pd.DataFrame({"early": x}), groups=early["curve"].to_numpy())
            te = st.coefficient_test(res, "early")
            parts.append(te)
            texts.append(f"the baseline's residuals in the first {10 * t_r:.3g} s of the holds differ by "
                         f"{100 * te['estimate']:+.1f} % from the later hold (t = {te['statistic']:.2f})")
    if not parts:
        return untested_finding(eff, "no frequency sweep to cross-check and no early-hold residuals")
    t = st.strongest_component(parts)
    how = ("that the baseline analysis treated as a step" if step_baseline else
           "(the baseline was fitted through the measured strain history, which is the fix; a step analysis "
           "of these data would be biased)")
    evidence = (f"Relaxation tests have a {t_r:.3g} s ramp {how}: "
                + "; ".join(texts) + f". The step analysis puts {g_fast[0]:.3g} Pa in modes with tau <= 10 t_r "
                f"(ramp-aware: {g_fast[1]:.3g} Pa).")
    if fix is not None:
        practical = bool(np.isfinite(fix["gain"]) and fix["gain"] >= 0.1)
    else:
        practical = abs(parts[-1].get("estimate", 0.0)) >= 0.03
    return make_finding(eff, t, "t", t_r, "s (rise time)", bool(practical), evidence, fix)


# ------------------------------------------------------------------------------------------------
# I2 dependence
# ------------------------------------------------------------------------------------------------
def detect_unidentified_i2_dependence(ctx: DiagnosisContext) -> dict:
    """Thrust excess F - psi M / 2 = 2 pi psi^2 int W2 r^3 dr (zero for any W(I1) material) regressed on
    (pi/2) psi^2 R^4: the slope is C01. Without normal force (or non-shear modes) C01 is not identifiable."""
    eff = "unidentified_i2_dependence"
    rows = []
    for r in ctx.runs:
        if r.attrs.get("test") not in TIME_DOMAIN:
            continue
        if not all(k in r for k in ("normal_force", "torque", "deflection_angle")):
            continue
        h = r["gap"].values if "gap" in r else np.full(r.sizes["point"], float(r.attrs.get("gap_m", np.nan)))
        R = float(r.attrs.get("radius_m", np.nan))
        psi = np.abs(r["deflection_angle"].values) / h
        rows.append(pd.DataFrame({"curve": run_id(r), "F": r["normal_force"].values,
                                  "half_psi_M": 0.5 * psi * np.abs(r["torque"].values),
                                  "x": 0.5 * np.pi * psi ** 2 * R ** 4, "strain": psi * R}))
    corr = {k: v for k, v in ctx.fit_info.get("correlations", {}).items()
            if ("C01" in k or "c01" in k.lower()) and ("C10" in k or "c10" in k.lower())}
    corr_txt = (f" The fitted C10-C01 correlation is {list(corr.values())[0]:+.3f}." if corr else "")
    modes = {str(r.attrs.get("test")) for r in ctx.runs}
    if not rows:
        finding = untested_finding(eff, "")
        finding.update(identifiable=False, evidence=(
            "Not identifiable from these data: in simple shear/torsion I1 = I2 = 3 + gamma^2, so the torque "
            "depends on W1 + W2 only; the C10 and C01 Jacobian columns are identical (correlation -> -1, flat "
            f"profile likelihood).{corr_txt} Only the normal force in torsion (W1 + 2 W2) or compression/"
            f"tension tests identify an I2 dependence; the runs ({', '.join(sorted(modes))}) record neither."))
        return finding
    d = pd.concat(rows, ignore_index=True)
    d = d[np.isfinite(d["F"]) & np.isfinite(d["x"]) & (d["strain"] >= 0.1)]
    if len(d) < 10 or d["curve"].nunique() < 2:
        finding = untested_finding(eff, "normal force recorded only below 10 % strain, where the thrust is at the "
                                 "resolution of the transducer: C01 is not identifiable")
        finding["identifiable"] = False
        return finding
    y = (d["F"] - d["half_psi_M"]).to_numpy()
    res = st.cluster_regression(y, d[["x"]], groups=d["curve"].to_numpy())
    t = st.coefficient_test(res, "x")
    c01 = t["estimate"]
    # C10 + C01 = mu/2 from the torque of a Mooney-Rivlin disc, M = (pi/2) mu psi R^4 = 2 x * (mu/2) / psi
    c_sum = float(np.median(d["half_psi_M"] / d["x"]))
    evidence = (f"The normal force exceeds the W(I1) thrust psi M/2 by (pi/2) psi^2 R^4 C01 with C01 = {c01:.3g} Pa "
                f"(t = {t['statistic']:.2f}, {d['curve'].nunique()} ramps/holds above 10 % strain, clustered): "
                f"an I2 (C01) dependence invisible in the torque (which carries only W1 + W2); C01/(C10 + C01) = "
                f"{c01 / c_sum:.2f}.{corr_txt}")
    fix = ctx.fit_info.get("fixes", {}).get(eff)
    # the thrust relation is exact for elastic laws; viscoelastic normal-stress histories depart from it by
    # a few % of C10 + C01, so only a larger C01 is a finding
    return make_finding(eff, t, "t", c01, "Pa (C01)", abs(c01) >= 0.1 * abs(c_sum), evidence, fix, identifiable=True,
                    c10_plus_c01_pa=c_sum)
