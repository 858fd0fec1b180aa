"""Causes read from oscillation tests: uncorrected instrument inertia in frequency sweeps (with the
spectrum-shape control and the raw-phase bound) and amplitude softening in amplitude sweeps (read from every sweep
above its noise floor, relative to the baseline where it predicts the sweep). Detectors of the registry
:mod:`.causes`."""
from __future__ import annotations

import numpy as np
import pandas as pd
import scipy

from .. import stats as st
from ..spectra import log_spaced_taus, prony_oscillation_basis, tau_window_from_frequency
from .evidence import booij_thoone, run_id
from .findings import (DiagnosisContext, cv_group_column, describe_log_change, fix_record, group_cv, make_finding, rms,
                       untested_finding)
from .inertia import classify_raw_phase
from .noise import estimate_noise, points_above_floor

# ------------------------------------------------------------------------------------------------
# frequency sweep: inertia
# ------------------------------------------------------------------------------------------------
#: relaxation times per decade of the non-negative spectrum fitted to each sweep by the inertia test
SWEEP_SPECTRUM_PER_DECADE = 4
#: fewest sweeps for the inertia test: the scatter of the per-sweep estimates is its noise (t with n - 1 df)
MIN_INERTIA_SWEEPS = 3


def sweep_spectrum_design(omega: np.ndarray, inertia_x: np.ndarray) -> np.ndarray:
    r"""Design of one frequency sweep for :func:`sweep_inertia_fit`: rows ``[G'; G'']``, columns
    ``[plateau, Maxwell modes..., -x, +x]``.

    The spectrum columns are the Prony series' G'/G'' design (:func:`tissuemech.spectra.prony_oscillation_basis`)
    on :data:`SWEEP_SPECTRUM_PER_DECADE` times per decade over the sweep's identifiable window widened by a
    decade on each side (:func:`tissuemech.spectra.tau_window_from_frequency`): a mode ten times faster than
    1/omega_max is already in its omega^2 regime (G' = G'' omega tau), one ten times slower than 1/omega_min a
    plateau. With :math:`G_e, h_k \ge 0` they give a non-negative spectrum. The inertial error acts on the
    storage modulus only, :math:`G'_{app} = G' - \Delta I\,x` with :math:`x = \omega^2 2h/(\pi R^4)` [1/m^3], and
    enters as two non-negative columns (:math:`\Delta I = c_{+} - c_{-}`, of either sign).
    """
    w = np.asarray(omega, float)
    taus = log_spaced_taus(*tau_window_from_frequency(w), SWEEP_SPECTRUM_PER_DECADE)
    storage, loss = prony_oscillation_basis(w, taus)
    zeros = np.zeros_like(w)
    return np.vstack([np.column_stack([storage, -inertia_x, inertia_x]), np.column_stack([loss, zeros, zeros])])


def sweep_inertia_fit(sweep: pd.DataFrame, delta_i: float | None = None) -> dict:
    """Non-negative relaxation spectrum of one sweep, with the inertial error fitted (``delta_i`` None) or held
    at ``delta_i`` [kg m^2] (:func:`sweep_spectrum_design`, weighted NNLS).

    ``sweep``: one row per frequency with ``omega``, ``x_inertia`` [1/m^3], ``storage``, ``loss`` [Pa] and their
    standard deviations ``sd_storage``, ``sd_loss``. Returns ``{"delta_i", "storage_fit"}`` (the spectrum's G'
    with the inertial term, Pa)."""
    design = sweep_spectrum_design(sweep["omega"].to_numpy(float), sweep["x_inertia"].to_numpy(float))
    y = np.r_[sweep["storage"].to_numpy(float), sweep["loss"].to_numpy(float)]
    sd = np.r_[sweep["sd_storage"].to_numpy(float), sweep["sd_loss"].to_numpy(float)]
    n = len(sweep)
    if delta_i is not None:
        y = y + np.r_[delta_i * sweep["x_inertia"].to_numpy(float), np.zeros(n)]
        design = design[:, :-2]
    a = design / sd[:, None]
    scale = np.linalg.norm(a, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    coef, _ = scipy.optimize.nnls(a / scale, y / sd, maxiter=50 * a.shape[1])
    coef = coef / scale
    fitted = design[:n] @ coef
    if delta_i is None:
        delta_i = float(coef[-2] - coef[-1])
    else:
        fitted = fitted - delta_i * sweep["x_inertia"].to_numpy(float)
    return {"delta_i": float(delta_i), "storage_fit": fitted}


def _sweep_frame(ctx: DiagnosisContext) -> pd.DataFrame:
    """One row per frequency of every sweep with true gap and radius: observed G', G'' and their standard
    deviations, the raw phase where logged. The noise of a reported modulus is that of the torque the instrument
    measured: where the raw phase shows that torque (|G*_raw|, G''/tan(raw phase) as its real part, science.md
    2.5) larger than the reported |G*|, the standard deviation grows in proportion."""
    t = ctx.table[ctx.table["test"] == "frequency_sweep"]
    keys = ["curve", "frequency_sq"]
    g1 = t[t["quantity"] == "storage_modulus"]
    g2 = t[t["quantity"] == "loss_modulus"][keys + ["observed", "sigma"]].rename(
        columns={"observed": "loss", "sigma": "sd_loss"})
    cols = keys + ["observed", "sigma", "inverse_gap", "radius_m", "specimen", "sample", "condition"]
    cols += [c for c in ("channel_raw_phase",) if c in g1]
    f = g1[cols].rename(columns={"observed": "storage", "sigma": "sd_storage"}).merge(g2, on=keys)
    f = f[np.isfinite(f[["storage", "loss", "sd_storage", "sd_loss", "inverse_gap", "radius_m"]]).all(axis=1)
          & (f["sd_storage"] > 0) & (f["sd_loss"] > 0) & (f["frequency_sq"] > 0)]
    f = f.assign(omega=np.sqrt(f["frequency_sq"]),
                 x_inertia=f["frequency_sq"] * 2.0 / (f["inverse_gap"] * np.pi * f["radius_m"] ** 4))
    if "channel_raw_phase" in f:
        phi = np.abs(f["channel_raw_phase"].to_numpy(float))
        with np.errstate(divide="ignore", invalid="ignore"):
            raw_real = np.abs(f["loss"].to_numpy(float)) / np.tan(phi)
            ratio = np.hypot(raw_real, f["loss"]) / np.hypot(f["storage"], f["loss"])
        ratio = np.where(np.isfinite(ratio) & (np.sin(phi) > 1e-3), np.maximum(ratio, 1.0), 1.0)
        f = f.assign(sd_storage=f["sd_storage"] * ratio, sd_loss=f["sd_loss"] * ratio)
    return f


def detect_instrument_inertia(ctx: DiagnosisContext) -> dict:
    """An inertial error of the frequency sweeps, read from the sweeps themselves (not from the baseline).

    The instrument corrects G' for the inertial torque omega^2 I 2h/(pi R^4); an error dI of that correction
    leaves G'_app = G' - dI x (x = omega^2 2h/(pi R^4)) and does not touch G''. Each sweep is fitted with a
    non-negative relaxation spectrum plus the inertial term (:func:`sweep_inertia_fit`): a non-negative
    spectrum makes G' non-decreasing in omega and ties every fast mode's G' rise to its G'' (Kramers-Kronig:
    G'_k = G''_k omega tau_k), so neither a G' fall nor a G' rise without its G'' is a spectrum. This holds
    whatever the baseline predicts: a spectrum the fitted tests do not resolve (a fast mode, a fractional
    relaxation) is not an inertial error. The test is a one-sample t over the per-sweep estimates of dI (the
    instrument's error is shared by its sweeps; their scatter is the noise, so no noise model is assumed).

    Where the sweeps log a raw phase, an over-correction (dI < 0) must also be consistent with it (science.md
    2.5): the raw phase with the reported moduli gives the inertia the instrument corrected for, I_cal
    (:func:`raw_phase_inertia`), and an over-correction cannot exceed it (|dI| <= I_cal); otherwise the
    finding is not practical. The held-out fix: dI from the other specimens (samples, sweeps), each held-out
    sweep refitted with its own spectrum with and without it; the metric is its rms relative G' residual."""
    eff = "instrument_inertia"
    fs = ctx.table[(ctx.table["test"] == "frequency_sweep") & (ctx.table["quantity"] == "storage_modulus")]
    if fs.empty or fs["frequency_sq"].nunique() < 4:
        return untested_finding(eff, "no frequency sweep")
    # the inertial term needs the true gap and plate radius of every sweep: never a default
    fs = fs[np.isfinite(fs["inverse_gap"]) & np.isfinite(fs["radius_m"])]
    if fs.empty or fs["frequency_sq"].nunique() < 4:
        return untested_finding(eff, "not testable here: the frequency sweeps record no gap or no plate radius "
                              "(the inertial term omega^2 2h/(pi R^4) needs both)")
    frame = _sweep_frame(ctx)
    counts = frame.groupby("curve")["frequency_sq"].nunique()
    frame = frame[frame["curve"].isin(counts.index[counts >= 4])]
    n_sweeps = frame["curve"].nunique()
    if n_sweeps < MIN_INERTIA_SWEEPS:
        return untested_finding(eff, f"not testable here: {n_sweeps} frequency sweep(s) with G', G'', gap and "
                                     f"plate radius at 4 or more frequencies; the test needs "
                                     f"{MIN_INERTIA_SWEEPS} (the scatter between sweeps is its noise)")
    per_sweep = {c: sweep_inertia_fit(g)["delta_i"] for c, g in frame.groupby("curve")}
    estimates = np.array(list(per_sweep.values()))
    delta_i = float(np.mean(estimates))
    se = float(np.std(estimates, ddof=1) / np.sqrt(estimates.size))
    stat = delta_i / se if se > 0 else (np.inf if delta_i else 0.0)
    t = st.statistic_result(stat, st.log10_p_from_t(stat, estimates.size - 1))
    x_max = float(frame["x_inertia"].max())
    f_max = float(frame["omega"].max() / (2 * np.pi))
    artefact_at_fmax = float(delta_i * x_max)
    gmax = float(np.median(np.abs(frame.loc[frame["x_inertia"] >= 0.999 * x_max, "storage"])))
    # Booij-Thoone local KK check on the measured sweep, averaged over curves
    kk_txt = ""
    ratios = []
    for r in ctx.runs_of("frequency_sweep"):
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
    i_raw = raw_phase_inertia(ctx.table, frame.rename(columns={"storage": "observed"}))
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

    group = cv_group_column(frame)

    def fit(train):
        return float(np.mean([per_sweep[c] for c in pd.unique(train["curve"])]))

    def error(test, par):
        out = []
        for _, g in test.groupby("curve"):
            pred = sweep_inertia_fit(g, 0.0 if par is None else par)["storage_fit"]
            out.append((g["storage"].to_numpy(float) - pred) / np.abs(pred))
        return np.concatenate(out)

    before, after = group_cv(frame, group, fit, error)
    evidence = (f"Each frequency sweep fitted with its own non-negative relaxation spectrum (G' and G'' together) "
                f"plus an inertial term -dI omega^2/b (b = pi R^4/(2h)): dI = {delta_i:.3g} kg m^2 "
                f"(mean of {n_sweeps} sweeps, t = {stat:.2f} on {n_sweeps - 1} df; per sweep "
                f"{np.min(estimates):.2g} .. {np.max(estimates):.2g}): an inertial error of "
                f"{-artefact_at_fmax:+.3g} Pa at {f_max:.3g} Hz where |G'| ~ {gmax:.3g} Pa.{kk_txt}{raw_txt}")
    fix = fix_record("fitted inertia term G'_app = G' - dI omega^2 2h/(pi R^4)", "rms_rel_residual_storage_modulus",
                     before, after, f"leave-one-{group}-out", delta_inertia_kg_m2=delta_i,
                     n_held_out_points=len(frame))
    practical = abs(artefact_at_fmax) >= 0.05 * gmax and consistent
    return make_finding(eff, t, "t", delta_i, "kg m^2", practical, evidence, fix)


def spectrum_shape_basis(frequency_sq, max_degree: int | None = None) -> np.ndarray:
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


def _kraus_levels(frame: pd.DataFrame, p) -> pd.Series:
    """Each sweep's level ln G'_0 given the Kraus shape ``p`` (least squares: the mean of y - ln K)."""
    k = _kraus(frame["log_g0"].to_numpy(), p) if p is not None else np.zeros(len(frame))
    return pd.Series(frame["y"].to_numpy() - k, index=frame.index).groupby(frame["curve"]).mean()


def kraus_fit(frame: pd.DataFrame) -> np.ndarray:
    """Kraus shape [r_inf, log10 gamma_c, m] of the sweeps of ``frame`` (``curve``, ``log_g0``, ``y`` = ln G' or
    ln(G'/prediction)), each sweep with its own level (profiled)."""
    lg = frame["log_g0"].to_numpy()
    y = frame["y"].to_numpy()
    codes = pd.factorize(frame["curve"])[0]
    counts = np.bincount(codes)

    def resid(p):
        r = y - _kraus(lg, p)
        return r - (np.bincount(codes, r) / counts)[codes]

    sol = scipy.optimize.least_squares(resid, [0.7, float(np.quantile(lg, 0.7)), 0.8],
                                       bounds=([0.01, lg.min() - 1, 0.2], [1.0, lg.max() + 1, 3.0]))
    return sol.x


def _kraus_errors(train: pd.DataFrame, test: pd.DataFrame, p) -> np.ndarray:
    """Held-out ln errors of ``test`` points: the Kraus shape ``p`` (None: constant G') with each sweep's level from
    its training points, or from its own points where the whole sweep is held out (its level is the sample's
    stiffness, not the softening's business)."""
    levels = _kraus_levels(train, p)
    own = _kraus_levels(test, p)
    lv = test["curve"].map(levels).fillna(test["curve"].map(own)).to_numpy(float)
    k = _kraus(test["log_g0"].to_numpy(), p) if p is not None else 0.0
    return test["y"].to_numpy() - lv - k


def onset_strain(p) -> float:
    """Strain amplitude at which the Kraus factor has fallen to 0.95 (NaN when it never does)."""
    r_inf, lgc, m = p
    if r_inf >= 0.95:
        return np.nan
    return float(10 ** lgc * ((1.0 - r_inf) / (0.95 - r_inf) - 1.0) ** (1.0 / (2.0 * m)))


def _sweep_points(ctx: DiagnosisContext, noise: dict) -> tuple[pd.DataFrame, list[str]]:
    """One row per usable amplitude-sweep point: ``curve``, ``strain``, ``log_g0``, ``y`` and where y comes from.

    y = ln(G'/prediction) where the baseline predicts the sweep (its law's own amplitude dependence is then not a
    softening), else ln G' (a linear-viscoelastic material has one G' at one frequency, whatever the amplitude).
    Points whose stress amplitude is not above the noise floor (the data's scatter, or the declared torque
    resolution: :func:`tissuemech.noise.points_above_floor`; never a fixed torque) are left out, and so
    are points beyond a raw phase of 90 deg (inertia-dominated or yielded, :func:`classify_raw_phase`)."""
    rows, sources = [], []
    pred = ctx.table[(ctx.table["test"] == "amplitude_sweep") & (ctx.table["quantity"] == "storage_modulus")] \
        if len(ctx.table) else pd.DataFrame()
    for r in ctx.runs_of("amplitude_sweep"):
        if "shear_strain" not in r or "storage_modulus" not in r:
            continue
        cid = run_id(r)
        amp = np.abs(np.asarray(r["shear_strain"].values, float))
        g1 = np.asarray(r["storage_modulus"].values, float)
        cls = classify_raw_phase(r)
        keep = np.isfinite(amp) & (amp > 0) & np.isfinite(g1) & (g1 > 0) & ~cls["inertia"] & ~cls["yield"]
        keep &= points_above_floor(r, "storage_modulus", noise)
        y = np.log(np.where(g1 > 0, g1, np.nan))
        source = "ln G'"
        p = pred[pred["curve"] == cid] if len(pred) else pred
        if len(p) and np.isfinite(p["log_ratio"]).any():
            lr = np.full(g1.size, np.nan)
            lr[p["point"].to_numpy(int)] = p["log_ratio"].to_numpy(float)
            y = lr
            source = f"ln(G'/{ctx.model})"
        keep &= np.isfinite(y)
        if keep.sum() < 3:
            continue
        sources.append(source)
        rows.append(pd.DataFrame({"curve": cid, "strain": amp[keep], "log_g0": np.log10(amp[keep]), "y": y[keep],
                                  "point": np.flatnonzero(keep)}))
    return (pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()), sources


def detect_amplitude_softening(ctx: DiagnosisContext) -> dict:
    """G' falling with strain amplitude in the amplitude sweeps, read from every sweep above the noise floor.

    Test: within-sweep regression of y (:func:`_sweep_points`) on log amplitude and on amplitude (the latter weighs
    the large amplitudes where softening acts), Bonferroni x 2; standard errors clustered by sweep with >= 3 sweeps,
    heteroscedasticity-robust over the points of fewer sweeps (the points of one sweep against its own scatter).
    Size: the fitted change of G' over the sweep's amplitudes; practical when G' falls by >= 5 %. Fix: a Kraus shape
    (:func:`kraus_fit`) with each sweep's own level, scored leaving one sweep out (>= 3 sweeps) or one point out
    (fewer sweeps). Baseline-free when no sweep is predicted by the baseline."""
    eff = "amplitude_softening"
    sweeps = ctx.runs_of("amplitude_sweep")
    if not sweeps:
        return untested_finding(eff, "not testable here: no amplitude sweep")
    noise = estimate_noise(sweeps)
    a, sources = _sweep_points(ctx, noise)
    if a.empty or a["strain"].nunique() < 4:
        return untested_finding(eff, f"not testable here: {len(sweeps)} amplitude sweep(s), but fewer than 4 "
                                     f"amplitudes stand above the noise floor (the data's own scatter or the declared "
                                     f"torque resolution) below any raw phase of 90 deg")
    a = a.assign(yd=a["y"] - a.groupby("curve")["y"].transform("mean"))
    n_sweeps = a["curve"].nunique()
    groups = a["curve"].to_numpy() if n_sweeps >= 3 else None
    tests = []
    for cov in ("log_g0", "strain"):
        xd = a[cov] - a.groupby("curve")[cov].transform("mean")
        r = st.cluster_regression(a["yd"].to_numpy(), pd.DataFrame({cov: xd.to_numpy()}), groups=groups)
        tt = st.coefficient_test(r, cov)
        tests.append((tt, cov, float(tt["estimate"] * (a[cov].max() - a[cov].min()))))
    t, cov_used, total = min(tests, key=lambda x: x[0]["log10_p"])
    lp = min(0.0, t["log10_p"] + np.log10(2))
    t = dict(t, log10_p=lp, p_value=10 ** lp)
    decades = float(a["log_g0"].max() - a["log_g0"].min())
    change = float(np.expm1(total))
    # held out: whole sweeps with >= 3 of them, else single points of the sweep(s)
    unit = "curve" if n_sweeps >= 3 else "point_key"
    a = a.assign(point_key=a["curve"] + "#" + a["point"].astype(str))
    eb, ea = [], []
    for g in pd.unique(a[unit]):
        test, train = a[a[unit] == g], a[a[unit] != g]
        if train["log_g0"].nunique() < 4:
            continue
        try:
            p = kraus_fit(train)
        except (ValueError, np.linalg.LinAlgError):
            continue
        eb.append(_kraus_errors(train, test, None))
        ea.append(_kraus_errors(train, test, p))
    before = rms(np.concatenate(eb)) if eb else np.nan
    after = rms(np.concatenate(ea)) if ea else np.nan
    full = kraus_fit(a)
    onset = onset_strain(full)
    floor_txt = ("declared torque resolution" if any("torque_resolution_nm" in r.attrs for r in sweeps)
                 else "the sweeps' own scatter")
    evidence = (f"Amplitude-sweep G' falls with strain amplitude ({', '.join(sorted(set(sources)))}; {n_sweeps} "
                f"sweep(s), {len(a)} points above the noise floor of {floor_txt} and below any raw phase of 90 deg): "
                f"within-sweep trend on {'log amplitude' if cov_used == 'log_g0' else 'amplitude'} t = "
                f"{t['statistic']:.2f}: G' {describe_log_change(total).replace('change by', 'changes by').replace('rise by', 'rises by').replace('fall by', 'falls by')} over "
                f"{decades:.1f} decades of amplitude ({100 * a['strain'].min():.2g}-{100 * a['strain'].max():.2g} %); "
                f"Kraus fit G'inf/G'0 = {full[0]:.2f}, gamma_c = {100 * 10 ** full[1]:.2g} %, m = {full[2]:.2f}"
                + (f", G' 5 % below its plateau from {100 * onset:.2g} %" if np.isfinite(onset) else "") + ".")
    fix = fix_record("Kraus amplitude softening G'(g0) = G'inf + (G'0 - G'inf)/(1 + (g0/gc)^(2m))",
                     "rms_log_residual_amplitude_sweep_shape", before, after,
                     "leave-one-sweep-out" if unit == "curve" else "leave-one-point-out",
                     ratio_inf=full[0], gamma_c=10 ** full[1], m=full[2], onset_strain=onset,
                     n_held_out_points=len(a))
    return make_finding(eff, t, "t", change, "relative change of G' over the sweep", change <= -0.05, evidence, fix,
                        baseline_free=all(src == "ln G'" for src in sources))
