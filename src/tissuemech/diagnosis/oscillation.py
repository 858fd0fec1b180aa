"""Causes read from oscillation tests: uncorrected instrument inertia in frequency sweeps (with the
spectrum-shape control and the raw-phase bound) and amplitude softening in amplitude sweeps. Part of
:mod:`.catalogue`."""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.optimize import least_squares

from .. import stats as st
from .evidence import booij_thoone
from .findings import DiagnosisContext, cv_group_column, demean_by, fix_record, group_cv, make_finding, untested_finding

# ------------------------------------------------------------------------------------------------
# frequency sweep: inertia
# ------------------------------------------------------------------------------------------------
def detect_instrument_inertia(ctx: DiagnosisContext) -> dict:
    """G' residual of the frequency sweep regressed on the inertial torque term omega^2 2h/(pi R^4).

    Where the sweeps log a raw phase, an over-correction (dI < 0) must also be consistent with it (science.md
    2.5): the raw phase with the reported moduli gives the inertia the instrument corrected for, I_cal
    (:func:`raw_phase_inertia`), and an over-correction cannot exceed it (|dI| <= I_cal); otherwise the
    omega^2 trend is a misfit of the spectrum and the finding is not practical. An under-correction (dI > 0)
    has no such bound: the true inertia is I_cal + dI."""
    eff = "instrument_inertia"
    fs = ctx.table[(ctx.table["test"] == "frequency_sweep") & (ctx.table["quantity"] == "storage_modulus")]
    if fs.empty or fs["frequency_sq"].nunique() < 4:
        return untested_finding(eff, "no frequency sweep")
    # the inertial term needs the true gap and plate radius of every sweep: never a default
    fs = fs[np.isfinite(fs["inverse_gap"]) & np.isfinite(fs["radius_m"])]
    if fs.empty or fs["frequency_sq"].nunique() < 4:
        return untested_finding(eff, "not testable here: the frequency sweeps record no gap or no plate radius "
                              "(the inertial term omega^2 2h/(pi R^4) needs both)")
    gap = 1.0 / fs["inverse_gap"]
    b_inv = 2.0 * gap / (np.pi * fs["radius_m"] ** 4)          # 1/b = 2h/(pi R^4), 1/m^3
    x_inertia = fs["frequency_sq"] * b_inv                      # Pa per (kg m^2)
    logw = 0.5 * np.log(fs["frequency_sq"])
    frame = fs.assign(x_inertia=x_inertia.to_numpy(), logw=logw.to_numpy())
    # the sample's stiffness scales G' (multiplicative) while the inertial error is additive: rescale each
    # sweep's prediction to its own low-frequency half (where omega^2 terms are negligible) first
    low = frame["frequency_sq"] <= frame.groupby("curve")["frequency_sq"].transform("median")
    scale = (frame["observed"] / frame["predicted"]).where(low).groupby(frame["curve"]).transform("median")
    frame = frame.assign(residual=frame["observed"] - scale * frame["predicted"],
                         predicted=scale * frame["predicted"], predicted_abs=np.abs(scale * frame["predicted"]))
    y = frame["residual"].to_numpy()
    fitted_tests = set(ctx.fit_info.get("fitted_tests") or ())
    cross_test = bool(fitted_tests) and "frequency_sweep" not in fitted_tests
    if cross_test:
        # the sweeps are predicted from tests the baseline was fitted to: a misfit of the spectrum is a
        # relative shape along log omega shared by every sweep (generic.shared_shape), so the control is that
        # shape (predicted x Legendre polynomials in log omega); the additive omega^2/b term must be seen over it
        shape_cols = _relative_shape_columns(frame)
        frame = frame.assign(**shape_cols)
        controls = list(shape_cols)
    else:
        # log(omega) control: a smooth misfit of the spectrum is not an omega^2 artefact
        controls = ["logw"]
    X = frame[["x_inertia", *controls]]
    res = st.cluster_regression(y / frame["sigma"], X.div(frame["sigma"], axis=0).assign(
        inv_sigma=1.0 / frame["sigma"].to_numpy()), groups=frame["curve"].to_numpy())
    t = st.coefficient_test(res, "x_inertia")
    delta_i = -t["estimate"]                                    # G'_app = G' - dI omega^2 / b
    f_max = float(np.sqrt(frame["frequency_sq"].max()) / (2 * np.pi))
    artefact_at_fmax = float(delta_i * frame["x_inertia"].max())
    gmax = float(frame.loc[frame["frequency_sq"].idxmax(), "predicted_abs"])
    # Booij-Thoone local KK check on the measured sweep, averaged over curves
    kk_txt = ""
    fs_runs = ctx.runs_of("frequency_sweep")
    ratios = []
    for r in fs_runs:
        if "storage_modulus" in r and "loss_modulus" in r and "angular_frequency" in r:
            w = r["angular_frequency"].values
            kk = booij_thoone(w, r["storage_modulus"].values)
            hi = w >= np.quantile(w, 0.75)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratios.append(np.nanmedian(r["loss_modulus"].values[hi] / kk[hi]))
    if ratios:
        kk_txt = (f" Booij-Thoone check in the top quarter of frequencies: measured G'' / ((pi/2) dG'/dln w) "
                  f"= {np.nanmedian(ratios):.2g}.")
    raw_txt = ""
    consistent = True
    i_raw = raw_phase_inertia(ctx.table, frame)
    if np.isfinite(i_raw["i_raw_kg_m2"]):
        # science.md 2.5: the raw torque carries the whole inertia I, the reported G' is corrected by I_cal,
        # so G'_rep - G''/tan(raw phase) = I_cal omega^2/b: the raw phase shows the corrected part. An
        # over-correction dI = I - I_cal < 0 is at most I_cal in size; an under-correction is unbounded by it
        consistent = bool(delta_i >= 0 or abs(delta_i) <= i_raw["i_raw_kg_m2"])
        raw_txt = (f" Raw phase reaches {i_raw['max_raw_phase_deg']:.0f} deg; the inertia the instrument "
                   f"corrected for (I_cal omega^2/b = G' - G''/tan(raw phase), top quarter of omega^2/b) is "
                   f"I_cal ~ {i_raw['i_raw_kg_m2']:.3g} kg m^2; the fitted dI is "
                   + ("an under-correction (true inertia I_cal + dI)" if delta_i >= 0 else
                      "an over-correction " + ("within" if consistent else "larger than") + " I_cal") + ".")

    # held-out: leave-one-sample-out fit of dI, applied to the held-out sample's sweep
    frame = frame.assign(rel=frame["residual"] / frame["predicted_abs"])

    shape = [c for c in controls if c != "logw"]

    def fit(train):
        return np.linalg.lstsq(train[["x_inertia", *shape]].to_numpy(), train["residual"].to_numpy(), rcond=None)[0]

    def error(test, par):
        corr = 0.0 if par is None else test[["x_inertia", *shape]].to_numpy() @ par
        return (test["residual"].to_numpy() - corr) / test["predicted_abs"].to_numpy()

    group = cv_group_column(frame)
    if shape:
        # "before" is the baseline with the shared spectrum shape fitted on the training groups (a statement
        # about the baseline, reported by the generic scan), "after" adds the inertia term
        def shape_only(train):
            coef = np.linalg.lstsq(train[shape].to_numpy(), train["residual"].to_numpy(), rcond=None)[0]
            return np.r_[0.0, coef]

        before = group_cv(frame, group, shape_only, error)[1]
        after = group_cv(frame, group, fit, error)[1]
    else:
        before, after = group_cv(frame, group, fit, error)
    control_txt = ("the shared relative spectrum shape of the predicted sweeps as control" if shape
                   else "log-omega control")
    evidence = (f"Frequency-sweep G' residuals of {ctx.model} follow -dI omega^2/b (b = pi R^4/(2h)) with "
                f"dI = {delta_i:.3g} kg m^2 (t = {t['statistic']:.2f}, {frame['curve'].nunique()} sweeps, "
                f"clustered by sweep, {control_txt}): an inertial error of {artefact_at_fmax:+.3g} Pa at "
                f"{f_max:.3g} Hz where |G'| ~ {gmax:.3g} Pa.{kk_txt}{raw_txt}")
    fix = fix_record("fitted inertia term G'_app = G' - dI omega^2 2h/(pi R^4)", "rms_rel_residual_storage_modulus",
               before, after, f"leave-one-{group}-out", delta_inertia_kg_m2=delta_i, n_held_out_points=len(frame))
    practical = abs(artefact_at_fmax) >= 0.05 * gmax and consistent
    return make_finding(eff, t, "t", delta_i, "kg m^2", practical, evidence, fix)


#: polynomial degree (in log omega) of the misfit shape of the relaxation spectrum shared by every predicted
#: frequency sweep that the inertia test uses as its control (the generic scan's shared shape,
#: :func:`tissuemech.diagnosis.generic.shared_shape`, chooses its own degree by BIC)
SPECTRUM_SHAPE_DEGREE = 3


def spectrum_shape_basis(frequency_sq, max_degree: int | None = SPECTRUM_SHAPE_DEGREE) -> np.ndarray:
    """Legendre polynomials P_1..P_d of log omega scaled to [-1, 1] over the given points (rows; 0 where omega^2
    is not finite and positive), d = min(``max_degree``, distinct omegas - 2) (no cap when ``max_degree`` is
    None): the basis of a misfit shape of the relaxation spectrum along a frequency sweep. Shape (n, d); d may
    be 0."""
    w2 = np.asarray(frequency_sq, float)
    ok = np.isfinite(w2) & (w2 > 0)
    logw = np.where(ok, 0.5 * np.log(np.where(ok, w2, 1.0)), np.nan)
    distinct = np.unique(logw[ok]).size - 2
    degree = int(max(0, distinct if max_degree is None else min(max_degree, distinct)))
    lo, hi = (np.min(logw[ok]), np.max(logw[ok])) if ok.any() else (0.0, 1.0)
    z = np.where(ok, 2.0 * (logw - lo) / max(hi - lo, 1e-12) - 1.0, 0.0)
    return np.polynomial.legendre.legvander(z, degree)[:, 1:]


def _relative_shape_columns(frame: pd.DataFrame) -> dict[str, np.ndarray]:
    """predicted x P_k(log omega) (:func:`spectrum_shape_basis`): a relative misfit shape along log omega shared
    by every sweep."""
    basis = spectrum_shape_basis(frame["frequency_sq"])
    pred = frame["predicted"].to_numpy(float)
    return {f"shape_P{k + 1}": pred * basis[:, k] for k in range(basis.shape[1])}


def raw_phase_inertia(table: pd.DataFrame, frame: pd.DataFrame) -> dict:
    """Inertia the instrument corrected for, from the raw phase of the frequency sweeps (science.md 2.5).

    The raw torque is (G* - I omega^2/b) b theta with the whole inertia I, so tan(raw phase) =
    G'' / (G' - I omega^2/b) with the true G'. The reported G' is corrected with the calibrated I_cal,
    G'_rep = G' - (I - I_cal) omega^2/b, so G'_rep - G''/tan(raw phase) = I_cal omega^2/b [Pa]: with the
    reported moduli the raw phase gives I_cal (= I when the correction is exact).
    ``frame``: the storage-modulus rows of the sweeps with ``x_inertia`` = omega^2/b [1/(m^3 s^2)] and
    ``channel_raw_phase`` [rad]; ``table``: the residual table (for the loss-modulus rows).

    Returns ``i_raw_kg_m2`` (median of (I omega^2/b)/(omega^2/b) over the top quarter of omega^2/b, where the
    inertial torque is largest; NaN without a raw phase channel or G'') and ``max_raw_phase_deg``.
    """
    out = {"i_raw_kg_m2": np.nan, "max_raw_phase_deg": np.nan}
    if "channel_raw_phase" not in frame:
        return out
    loss = table[(table["test"] == "frequency_sweep") & (table["quantity"] == "loss_modulus")]
    both = frame[["curve", "frequency_sq", "observed", "x_inertia", "channel_raw_phase"]].merge(
        loss[["curve", "frequency_sq", "observed"]].rename(columns={"observed": "loss"}), on=["curve", "frequency_sq"])
    both = both[np.isfinite(both["channel_raw_phase"]) & np.isfinite(both["loss"]) & (both["x_inertia"] > 0)]
    if both.empty:
        return out
    phi = np.abs(both["channel_raw_phase"].to_numpy(float))
    with np.errstate(divide="ignore", invalid="ignore"):
        inertial_pa = both["observed"].to_numpy(float) - both["loss"].to_numpy(float) / np.tan(phi)
    top = both["x_inertia"].to_numpy(float) >= np.quantile(both["x_inertia"], 0.75)
    i_pts = inertial_pa[top] / both["x_inertia"].to_numpy(float)[top]
    i_pts = i_pts[np.isfinite(i_pts)]
    if i_pts.size:
        out["i_raw_kg_m2"] = float(np.median(i_pts))
    out["max_raw_phase_deg"] = float(np.degrees(phi.max()))
    return out


# ------------------------------------------------------------------------------------------------
# amplitude sweep: Kraus softening
# ------------------------------------------------------------------------------------------------
def _kraus(log_g0, p):
    """log of the Kraus factor r_inf + (1 - r_inf)/(1 + (g0/gc)^(2m)) (p = [r_inf, log10 gc, m])."""
    r_inf, lgc, m = p
    return np.log(r_inf + (1.0 - r_inf) / (1.0 + 10.0 ** (2 * m * (log_g0 - lgc))))


def detect_amplitude_softening(ctx: DiagnosisContext) -> dict:
    """Slope of the amplitude-sweep G' log-residual against log strain amplitude (cluster by sweep)."""
    eff = "amplitude_softening"
    a = ctx.table[(ctx.table["test"] == "amplitude_sweep") & (ctx.table["quantity"] == "storage_modulus")]
    a = a[np.isfinite(a["log_ratio"]) & (a["strain"] > 0) & a.get("above_noise", True)]
    if a.empty or a["strain"].nunique() < 4:
        return untested_finding(eff, "no amplitude sweep above the torque noise floor")
    a = a.assign(log_g0=np.log10(a["strain"]), y=demean_by(a, "log_ratio", "curve"))
    # softening sets in above gamma_c: test the within-sweep trend on log amplitude and on amplitude
    # (the latter weights the large amplitudes where Kraus softening acts), Bonferroni x 2
    tests = []
    for cov in ("log_g0", "strain"):
        xd = a[cov] - a.groupby("curve")[cov].transform("mean")
        r = st.cluster_regression(a["y"].to_numpy(), pd.DataFrame({cov: xd.to_numpy()}), groups=a["curve"].to_numpy())
        tt = st.coefficient_test(r, cov)
        tests.append((tt, cov, float(tt["estimate"] * (a[cov].max() - a[cov].min()))))
    t, cov_used, total = min(tests, key=lambda x: x[0]["log10_p"])
    lp = min(0.0, t["log10_p"] + np.log10(2))
    t = dict(t, log10_p=lp, p_value=10 ** lp)
    decades = float(a["log_g0"].max() - a["log_g0"].min())
    change = float(np.expm1(total))

    def kraus_centred(frame, p):
        k = _kraus(frame["log_g0"].to_numpy(), p)
        return k - pd.Series(k, index=frame.index).groupby(frame["curve"]).transform("mean").to_numpy()

    def fit(train):
        def resid(p):
            return train["y"].to_numpy() - kraus_centred(train, p)
        lg = train["log_g0"].to_numpy()
        sol = least_squares(resid, [0.7, float(np.quantile(lg, 0.7)), 0.8],
                            bounds=([0.05, lg.min() - 1, 0.2], [1.0, lg.max() + 1, 3.0]))
        return sol.x

    def error(test, par):
        # the sweep's level is the sample's stiffness (not the softening's business): compare shapes
        y = test["y"].to_numpy()
        return y if par is None else y - kraus_centred(test, par)

    group = cv_group_column(a)
    before, after = group_cv(a, group, fit, error)
    full = fit(a)
    evidence = (f"Amplitude-sweep G' falls relative to {ctx.model} with strain amplitude: within-sweep trend on "
                f"{'log amplitude' if cov_used == 'log_g0' else 'amplitude'} t = {t['statistic']:.2f} "
                f"({a['curve'].nunique()} sweeps, clustered), a {100 * change:+.0f} % change over {decades:.1f} "
                f"decades of amplitude "
                f"({100 * a['strain'].min():.2g}-{100 * a['strain'].max():.2g} %); Kraus fit G'inf/G'0 = "
                f"{full[0]:.2f}, gamma_c = {100 * 10 ** full[1]:.2g} %, m = {full[2]:.2f}.")
    fix = fix_record("Kraus amplitude softening G'(g0) = G'inf + (G'0 - G'inf)/(1 + (g0/gc)^(2m))",
               "rms_log_residual_amplitude_sweep_shape", before, after, f"leave-one-{group}-out",
               ratio_inf=full[0], gamma_c=10 ** full[1], m=full[2], n_held_out_points=len(a))
    return make_finding(eff, t, "t", change, "relative change of G' over the sweep", change <= -0.05, evidence, fix)
