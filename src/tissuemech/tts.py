"""Time-temperature superposition (TTS): shift factors, WLF and Arrhenius fits, mastercurve prediction.

Conventions (Dealy & Plazek 2009, *Rheol. Bull.* 78:16; Ferry 1980, ch. 11)
--------------------------------------------------------------------------
A sweep measured at temperature T is moved onto the reference temperature ``t_ref_c`` by

* a **horizontal** shift: reduced angular frequency ``omega_r = a_T * omega`` [rad/s]; ``log_aT`` is
  log10(a_T), zero at ``t_ref_c``, positive below it for a thermorheologically simple material;
* an optional **vertical** shift: reduced modulus ``G_r = b_T * G`` [Pa]; ``log_bT`` = log10(b_T).

Criterion of the automatic shift (documented, no free thresholds)
-----------------------------------------------------------------
Sweeps are sorted by temperature. For each pair of *adjacent* temperatures the shift of the colder sweep
relative to the warmer one is the value that minimises the mean squared difference of log10 G' **and**
log10 G'' between the shifted points of one sweep and the piecewise-linear log-log interpolant of the other,
on their overlapping log10-omega range, **symmetrically** (points of A on B's interpolant and points of B
on A's interpolant; both must overlap in at least :data:`MIN_OVERLAP` points). The minimum is found by a
grid over every shift that leaves the overlap (four grid points per finer point spacing) and a
bounded scalar refinement (:func:`scipy.optimize.minimize_scalar`). Pairwise shifts are chained (summed)
from the reference temperature outwards. With ``vertical=True`` the pair discrepancy is minimised over
(log aT, log bT) jointly (same criterion, :func:`scipy.optimize.least_squares`).

Uncertainty: each pairwise shift is a one- (or two-) parameter least-squares estimate; its standard error
is ``sqrt(s^2 (J^T J)^-1)`` with ``s^2`` the residual variance of the pair (n - p degrees of freedom) and
``J`` the numerical Jacobian of the residuals at the optimum. Variances of chained shifts add (pairs are
treated as independent), so the standard error grows with the distance from the reference temperature.

Shift functions (lmfit, weighted by 1/stderr of log aT where finite)
--------------------------------------------------------------------
* WLF: ``log aT = -C1 (T - Tref) / (C2 + T - Tref)`` (T in degC, C1 [1], C2 [K]);
* Arrhenius: ``log aT = Ea / (R ln 10) (1/T - 1/Tref)`` (T in K, Ea [J/mol], R = 8.314462618 J/(mol K)).

Both return parameters, standard errors and the residual RMS in decades; neither is preferred here (the
caller compares them).

Entry points: :func:`sweeps_from_runs` (canonical runs -> :class:`Sweep`), :func:`shift_factors`,
:func:`fit_wlf`, :func:`fit_arrhenius`, :func:`wlf_log_aT`, :func:`arrhenius_log_aT`,
:func:`mastercurve`, :func:`predict_from_mastercurve`, :func:`mastercurve_curve` (the sweeps as one fit curve at
Tref: what the fit stage's ``mastercurve`` scope fits with the model library); the pipeline's TTS scope: :func:`run_tts` (runs ->
``tts.nc`` via :func:`tts_dataset`, the shift-function card :func:`tts_card` with its Abaqus ``*TRS`` block
:func:`trs_abaqus_block`, the mastercurve figure) and :func:`distinct_temperatures` (when the scope runs).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import lazy_loader
import numpy as np
import scipy
import xarray as xr

from .canonical import read_netcdf, write_json, write_netcdf, write_text
from .curves import distinct_temperatures, drop_flagged  # noqa: F401 (distinct_temperatures re-exported)
from .stats import information_criteria

# loaded on first use (why: tissuemech.fitting._problem)
lmfit = lazy_loader.load("lmfit")

#: gas constant, J/(mol K)
GAS_CONSTANT = 8.314462618
#: 0 degC in K
KELVIN_OFFSET = 273.15
#: fewest shifted points that must fall inside the other sweep's range, on each side of a pair
MIN_OVERLAP = 3


@dataclass
class Sweep:
    """One frequency sweep at one temperature.

    Attributes
    ----------
    temperature_c : temperature of the sweep [degC] (mean of the logged channel, else the nominal one)
    omega : angular frequency [rad/s]
    storage, loss : G', G'' [Pa]
    label : name of the run it came from
    """

    temperature_c: float
    omega: np.ndarray
    storage: np.ndarray
    loss: np.ndarray
    label: str = ""

    def __post_init__(self):
        w, g1, g2 = (np.asarray(a, float) for a in (self.omega, self.storage, self.loss))
        ok = np.isfinite(w) & (w > 0) & np.isfinite(g1) & (g1 > 0) & np.isfinite(g2) & (g2 > 0)
        order = np.argsort(w[ok])
        self.omega, self.storage, self.loss = w[ok][order], g1[ok][order], g2[ok][order]

    @property
    def log_w(self) -> np.ndarray:
        return np.log10(self.omega)

    @property
    def log_g(self) -> np.ndarray:
        """(n, 2) array of log10 G', log10 G''."""
        return np.column_stack([np.log10(self.storage), np.log10(self.loss)])


@dataclass
class TTSResult:
    """Shift factors of a set of sweeps.

    Attributes
    ----------
    temperatures_c : sorted temperatures [degC]
    log_aT, log_aT_stderr : horizontal shifts (decades) and standard errors (0 at the reference)
    log_bT, log_bT_stderr : vertical shifts (decades; zeros when not fitted)
    t_ref_c : reference temperature [degC]
    pair_rms : RMS log10 discrepancy of each adjacent pair after shifting (len = n - 1), decades
    vertical : whether vertical shifts were fitted
    labels : run labels in temperature order
    """

    temperatures_c: np.ndarray
    log_aT: np.ndarray
    log_aT_stderr: np.ndarray
    log_bT: np.ndarray
    log_bT_stderr: np.ndarray
    t_ref_c: float
    pair_rms: np.ndarray
    vertical: bool = False
    labels: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"t_ref_c": float(self.t_ref_c), "vertical": self.vertical,
                "temperature_c": [float(t) for t in self.temperatures_c],
                "log_aT": [float(v) for v in self.log_aT], "log_aT_stderr": [float(v) for v in self.log_aT_stderr],
                "log_bT": [float(v) for v in self.log_bT], "log_bT_stderr": [float(v) for v in self.log_bT_stderr],
                "pair_rms_decades": [float(v) for v in self.pair_rms]}


# ------------------------------------------------------------------------------------------------
# sweeps from canonical runs
# ------------------------------------------------------------------------------------------------
def run_temperature_c(run: xr.Dataset) -> float:
    """Temperature of a run [degC]: median of the logged ``temperature`` channel, else ``temperature_c``
    attribute, else NaN (never a default)."""
    if "temperature" in run:
        t = np.asarray(run["temperature"].values, float)
        if np.isfinite(t).any():
            return float(np.nanmedian(t))
    v = run.attrs.get("temperature_c")
    try:
        return float(v)
    except (TypeError, ValueError):
        return np.nan


def sweeps_from_runs(runs: Sequence[xr.Dataset]) -> list[Sweep]:
    """Every frequency-sweep run with G', G'', angular frequency (or frequency) and a known temperature."""
    out = []
    for r in runs:
        if r.attrs.get("test") != "frequency_sweep" or "storage_modulus" not in r or "loss_modulus" not in r:
            continue
        if "angular_frequency" in r:
            w = np.asarray(r["angular_frequency"].values, float)
        elif "frequency" in r:
            w = 2.0 * np.pi * np.asarray(r["frequency"].values, float)
        else:
            continue
        t = run_temperature_c(r)
        if not np.isfinite(t):
            continue
        sw = Sweep(t, w, r["storage_modulus"].values, r["loss_modulus"].values, str(r.attrs.get("run", "")))
        if sw.omega.size >= MIN_OVERLAP:
            out.append(sw)
    return out


# ------------------------------------------------------------------------------------------------
# pairwise shift
# ------------------------------------------------------------------------------------------------
def _one_way(src: Sweep, dst: Sweep, shift: float, vshift: float, inside: np.ndarray | None = None) -> np.ndarray:
    """Residuals (decades) of ``src`` shifted by (shift, vshift) against the interpolant of ``dst``
    (points of ``src`` inside ``dst``'s range, or the fixed point set ``inside``)."""
    x = src.log_w + shift
    if inside is None:
        inside = (x >= dst.log_w[0]) & (x <= dst.log_w[-1])
    if inside.sum() == 0:
        return np.empty(0)
    y = src.log_g[inside] + vshift
    ref = np.column_stack([np.interp(x[inside], dst.log_w, dst.log_g[:, k]) for k in range(2)])
    return (y - ref).ravel()


def _overlap_masks(cold: Sweep, warm: Sweep, shift: float) -> tuple[np.ndarray, np.ndarray]:
    xa = cold.log_w + shift
    xb = warm.log_w - shift
    return ((xa >= warm.log_w[0]) & (xa <= warm.log_w[-1]), (xb >= cold.log_w[0]) & (xb <= cold.log_w[-1]))


def _pair_residuals(cold: Sweep, warm: Sweep, shift: float, vshift: float = 0.0, masks=None) -> np.ndarray:
    """Symmetric residuals of the cold sweep shifted by ``shift`` (decades of omega) and ``vshift``
    (decades of modulus) onto the warm one; empty when either side overlaps in < MIN_OVERLAP points.
    ``masks``: fixed overlapping point sets (for derivatives and the joint fit, so that the residual
    vector keeps its length)."""
    ma, mb = _overlap_masks(cold, warm, shift) if masks is None else masks
    if ma.sum() < MIN_OVERLAP or mb.sum() < MIN_OVERLAP:
        return np.empty(0)
    return np.concatenate([_one_way(cold, warm, shift, vshift, ma), _one_way(warm, cold, -shift, -vshift, mb)])


def _objective(cold, warm, shift, vshift=0.0) -> float:
    r = _pair_residuals(cold, warm, shift, vshift)
    return float(np.mean(r ** 2)) if r.size else np.inf


def _stderr(fun, x: np.ndarray, h: float = 1e-4) -> tuple[np.ndarray, float]:
    """Least-squares standard errors of ``x`` from the numerical Jacobian of ``fun`` (residual vector)."""
    r0 = fun(x)
    n, p = r0.size, x.size
    J = np.empty((n, p))
    for j in range(p):
        dx = np.zeros(p)
        dx[j] = h
        rp, rm = fun(x + dx), fun(x - dx)
        J[:, j] = (rp - rm) / (2 * h)
    dof = max(n - p, 1)
    s2 = float(r0 @ r0) / dof
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        se = np.full(p, np.nan)
    return se, float(np.sqrt(np.mean(r0 ** 2)))


def pair_shift(cold: Sweep, warm: Sweep, vertical: bool = False) -> dict:
    """Shift of ``cold`` onto ``warm`` (module docstring criterion).

    Returns
    -------
    dict with ``log_a`` (decades of omega to add to the cold sweep's log10 omega), ``log_a_stderr``,
    ``log_b``, ``log_b_stderr`` (decades of modulus; 0/0 unless ``vertical``), ``rms`` (decades),
    ``n`` (residuals used). NaN shift when no shift gives enough overlap.
    """
    dw = min(np.min(np.diff(cold.log_w)) if cold.omega.size > 1 else 0.1,
             np.min(np.diff(warm.log_w)) if warm.omega.size > 1 else 0.1)
    step = max(dw / 4.0, 1e-3)
    lo = warm.log_w[0] - cold.log_w[-1]
    hi = warm.log_w[-1] - cold.log_w[0]
    grid = np.arange(lo, hi + step, step)
    vals = np.array([_objective(cold, warm, s) for s in grid])
    nan = {"log_a": np.nan, "log_a_stderr": np.nan, "log_b": 0.0, "log_b_stderr": 0.0, "rms": np.nan, "n": 0}
    if not np.isfinite(vals).any():
        return nan
    s0 = float(grid[int(np.argmin(vals))])
    best = scipy.optimize.minimize_scalar(lambda s: _objective(cold, warm, s), bounds=(s0 - step, s0 + step),
                                          method="bounded")
    s = float(best.x) if np.isfinite(best.fun) and best.fun <= vals.min() else s0
    masks = _overlap_masks(cold, warm, s)
    if not vertical:
        se, rms = _stderr(lambda x: _pair_residuals(cold, warm, float(x[0]), masks=masks), np.array([s]))
        return {"log_a": s, "log_a_stderr": float(se[0]), "log_b": 0.0, "log_b_stderr": 0.0, "rms": rms,
                "n": int(_pair_residuals(cold, warm, s, masks=masks).size)}
    # joint (log a, log b): alternate the overlap set and the least-squares fit on it until it is stable
    x = np.array([s, 0.0])
    for _ in range(5):
        fit = scipy.optimize.least_squares(lambda v: _pair_residuals(cold, warm, float(v[0]), float(v[1]), masks), x)
        x = fit.x
        new_masks = _overlap_masks(cold, warm, float(x[0]))
        if all(np.array_equal(a, b) for a, b in zip(new_masks, masks)):
            break
        masks = new_masks
    se, rms = _stderr(lambda v: _pair_residuals(cold, warm, float(v[0]), float(v[1]), masks), x)
    return {"log_a": float(x[0]), "log_a_stderr": float(se[0]), "log_b": float(x[1]),
            "log_b_stderr": float(se[1]), "rms": rms, "n": int(_pair_residuals(cold, warm, *x, masks).size)}


def shift_factors(sweeps: Sequence[Sweep], t_ref_c: float | None = None, vertical: bool = False,
                  cache: dict | None = None) -> TTSResult:
    """Automatic shift factors of sweeps at several temperatures (module docstring).

    Parameters
    ----------
    sweeps : at least two sweeps at distinct temperatures (sweeps sharing a temperature are shifted like
        any other pair; their shift is then estimated, not assumed zero)
    t_ref_c : reference temperature [degC]; must be one of the sweep temperatures. None: the measured
        temperature closest to the median of the measured temperatures.
    vertical : also fit vertical shifts log bT
    cache : optional dict reused across calls (e.g. leave-one-temperature-out): pairwise shifts are stored
        under (cold label, cold T, warm label, warm T, vertical) and not recomputed

    Returns
    -------
    TTSResult (sorted by temperature). A pair without overlap at any shift breaks the chain: the
    temperatures beyond it get NaN shifts (reported, never filled).
    """
    sw = sorted(sweeps, key=lambda s: s.temperature_c)
    if len(sw) < 2:
        raise ValueError(f"time-temperature superposition needs sweeps at >= 2 temperatures, got {len(sw)}")
    temps = np.array([s.temperature_c for s in sw], float)
    if t_ref_c is None:
        i_ref = int(np.argmin(np.abs(temps - np.median(temps))))
    else:
        i_ref = int(np.argmin(np.abs(temps - float(t_ref_c))))
        if abs(temps[i_ref] - float(t_ref_c)) > 0.5:
            raise ValueError(f"reference temperature {t_ref_c} degC is not among the sweep temperatures "
                             f"{temps.round(1).tolist()}")
    # pair k: sweep k (colder) onto sweep k+1 (warmer); log a of the colder relative to the warmer
    # is *minus* the omega shift that moves it: omega_r = a_T omega -> log_w + log_aT(cold) - log_aT(warm)
    pairs = []
    for k in range(len(sw) - 1):
        key = (sw[k].label, sw[k].temperature_c, sw[k + 1].label, sw[k + 1].temperature_c, vertical)
        if cache is None or key not in cache:
            p = pair_shift(sw[k], sw[k + 1], vertical)
            if cache is None:
                pairs.append(p)
                continue
            cache[key] = p
        pairs.append(cache[key])
    n = len(sw)
    la, la_var = np.full(n, np.nan), np.full(n, np.nan)
    lb, lb_var = np.full(n, np.nan), np.full(n, np.nan)
    la[i_ref] = lb[i_ref] = la_var[i_ref] = lb_var[i_ref] = 0.0
    for k in range(i_ref - 1, -1, -1):   # colder than the reference
        p = pairs[k]
        la[k] = la[k + 1] + p["log_a"]
        lb[k] = lb[k + 1] + p["log_b"]
        la_var[k] = la_var[k + 1] + p["log_a_stderr"] ** 2
        lb_var[k] = lb_var[k + 1] + p["log_b_stderr"] ** 2
    for k in range(i_ref + 1, n):        # warmer than the reference
        p = pairs[k - 1]
        la[k] = la[k - 1] - p["log_a"]
        lb[k] = lb[k - 1] - p["log_b"]
        la_var[k] = la_var[k - 1] + p["log_a_stderr"] ** 2
        lb_var[k] = lb_var[k - 1] + p["log_b_stderr"] ** 2
    return TTSResult(temperatures_c=temps, log_aT=la, log_aT_stderr=np.sqrt(la_var), log_bT=lb,
                     log_bT_stderr=np.sqrt(lb_var), t_ref_c=float(temps[i_ref]),
                     pair_rms=np.array([p["rms"] for p in pairs], float), vertical=vertical,
                     labels=[s.label for s in sw])


# ------------------------------------------------------------------------------------------------
# shift functions
# ------------------------------------------------------------------------------------------------
def wlf_log_aT(temperature_c, c1: float, c2_k: float, t_ref_c: float):
    """WLF: log10 aT = -C1 (T - Tref) / (C2 + T - Tref) (T, Tref in degC, C2 in K)."""
    d = np.asarray(temperature_c, float) - t_ref_c
    return -c1 * d / (c2_k + d)


def arrhenius_log_aT(temperature_c, ea_j_per_mol: float, t_ref_c: float):
    """Arrhenius: log10 aT = Ea / (R ln 10) (1/T - 1/Tref) (temperatures in degC, converted to K)."""
    t = np.asarray(temperature_c, float) + KELVIN_OFFSET
    return ea_j_per_mol / (GAS_CONSTANT * np.log(10.0)) * (1.0 / t - 1.0 / (t_ref_c + KELVIN_OFFSET))


def _fit_shift_model(func, temps, log_at, stderr, params: lmfit.Parameters, t_ref_c: float) -> dict:
    ok = np.isfinite(temps) & np.isfinite(log_at)
    if ok.sum() <= len([p for p in params.values() if p.vary]):
        return {"success": False, "message": "too few finite shift factors"}
    se = np.asarray(stderr, float)[ok]
    w = None
    if np.isfinite(se).all() and (se > 0).any():
        floor = np.nanmedian(se[se > 0])
        w = 1.0 / np.maximum(se, floor)   # the reference (stderr 0) gets the typical weight
    model = lmfit.Model(func, independent_vars=["temperature_c"])
    params = params.copy()
    params.add("t_ref_c", value=t_ref_c, vary=False)
    res = model.fit(np.asarray(log_at, float)[ok], params, temperature_c=np.asarray(temps, float)[ok], weights=w)
    resid = res.best_fit - np.asarray(log_at, float)[ok]
    out = {"success": bool(res.success), "t_ref_c": float(t_ref_c), "rms_decades": float(np.sqrt(np.mean(resid ** 2))),
           "n": int(ok.sum()), "aic": information_criteria(res.chisqr, res.ndata, res.nvarys)["aic"],
           "message": str(res.message)}
    for name, p in res.params.items():
        if name == "t_ref_c":
            continue
        out[name] = float(p.value)
        out[f"{name}_stderr"] = float(p.stderr) if p.stderr is not None else np.nan
    return out


def fit_wlf(temperatures_c, log_aT, log_aT_stderr, t_ref_c: float) -> dict:
    """lmfit WLF fit of log aT(T): ``c1``, ``c2_k`` with ``*_stderr``, ``rms_decades``, ``success``.

    C2 is bounded to (T_min - Tref, inf) + 1 K so that the WLF pole lies below every fitted temperature."""
    temps = np.asarray(temperatures_c, float)
    p = lmfit.Parameters()
    c2_min = float(t_ref_c - np.nanmin(temps)) + 1.0
    p.add("c1", value=10.0, min=0.0, max=1e3)
    p.add("c2_k", value=max(100.0, c2_min + 50.0), min=c2_min, max=1e4)
    return _fit_shift_model(wlf_log_aT, temps, log_aT, log_aT_stderr, p, t_ref_c)


def fit_arrhenius(temperatures_c, log_aT, log_aT_stderr, t_ref_c: float) -> dict:
    """lmfit Arrhenius fit of log aT(T): ``ea_j_per_mol`` with ``ea_j_per_mol_stderr``, ``rms_decades``."""
    p = lmfit.Parameters()
    p.add("ea_j_per_mol", value=1e5, min=0.0, max=5e6)
    return _fit_shift_model(arrhenius_log_aT, temperatures_c, log_aT, log_aT_stderr, p, t_ref_c)


# ------------------------------------------------------------------------------------------------
# mastercurve
# ------------------------------------------------------------------------------------------------
def mastercurve(sweeps: Sequence[Sweep], log_aT: Sequence[float], log_bT: Sequence[float] | None = None):
    """Reduced data of ``sweeps`` (same order as the shifts): (log10 omega_r, log10 G'_r, log10 G''_r),
    sorted by reduced frequency; sweeps with a NaN shift are left out."""
    lb = np.zeros(len(sweeps)) if log_bT is None else np.asarray(log_bT, float)
    xs, ys = [], []
    for s, a, b in zip(sweeps, log_aT, lb):
        if np.isfinite(a) and np.isfinite(b):
            xs.append(s.log_w + a)
            ys.append(s.log_g + b)
    if not xs:
        return np.empty(0), np.empty((0, 2))
    x = np.concatenate(xs)
    y = np.vstack(ys)
    order = np.argsort(x, kind="stable")
    return x[order], y[order]


def predict_from_mastercurve(master_x: np.ndarray, master_y: np.ndarray, log_w: np.ndarray, log_aT: float,
                             log_bT: float = 0.0, window_decades: float = 0.25) -> np.ndarray:
    """Predicted log10 G', log10 G'' [(n, 2), decades of Pa] at ``log_w`` for a temperature with shift
    (log_aT, log_bT): the local linear regression (window +- ``window_decades`` in reduced log omega) of
    the mastercurve at log_w + log_aT, moved back by -log_bT. NaN outside the mastercurve's range or where
    the window holds fewer than 2 points."""
    x = np.asarray(log_w, float) + log_aT
    out = np.full((x.size, 2), np.nan)
    for i, xi in enumerate(x):
        if xi < master_x[0] or xi > master_x[-1]:
            continue
        sel = np.abs(master_x - xi) <= window_decades
        if sel.sum() < 2:
            continue
        mx = master_x[sel]
        for k in range(2):
            my = master_y[sel, k]
            if np.ptp(mx) > 0:
                c = np.polyfit(mx - xi, my, 1)
                out[i, k] = c[1]
            else:
                out[i, k] = np.mean(my)
    return out - log_bT


def mastercurve_curve(curves: Sequence, temperatures_c: Sequence[float], tts_ds: xr.Dataset,
                      tolerance_c: float = 0.5):
    """The frequency sweeps of several temperatures as one fit curve at the reference temperature.

    This is how the model library fits a mastercurve: the fit stage (:func:`tissuemech.stages.run_fit_scope`,
    scope ``mastercurve``) fits this one curve like any other, so a fitted model describes the material at
    ``t_ref_c`` in reduced angular frequency, and the shift function of ``tts_ds`` carries it to other
    temperatures (the card's ``*TRS`` block).

    Parameters
    ----------
    curves : oscillation :class:`tissuemech.fitting.Curve` objects of one frequency sweep per temperature (inputs
        ``angular_frequency`` [rad/s], observed ``storage_modulus``/``loss_modulus`` [Pa], optional ``sd``)
    temperatures_c : temperature of each curve [degC] (the averaged curve's nominal temperature)
    tts_ds : the ``tts.nc`` dataset (:func:`tts_dataset`): ``temperature_c``, ``log_aT``, ``log_bT``, attribute
        ``t_ref_c``
    tolerance_c : a curve takes the shift of the ``tts_ds`` temperature nearest its own when they differ by at
        most this much [degC] (the averaging rounds set points to 0.5 degC, the shift uses the logged channel)

    Returns
    -------
    (curve, record): the reduced curve -- inputs ``angular_frequency`` = a_T omega [rad/s], observed and SDs
    multiplied by b_T, sorted by reduced frequency, only the points with positive G' and G'' (those the shift
    criterion uses; a log-residual fit cannot take a negative modulus), condition ``mastercurve Tref=<t_ref_c>degC``, ``nominal``
    ``{"t_ref_c": t_ref_c}`` -- and ``{"temperatures_c": used, "left_out": {label: reason}}``.
    Raises ``ValueError`` when no curve has a finite shift.
    """
    from dataclasses import replace

    temps = np.asarray(tts_ds["temperature_c"].values, float)
    log_at = np.asarray(tts_ds["log_aT"].values, float)
    log_bt = np.asarray(tts_ds["log_bT"].values, float) if "log_bT" in tts_ds else np.zeros(temps.size)
    t_ref = float(tts_ds.attrs["t_ref_c"])
    parts, used, left_out = [], [], {}
    for curve, t in zip(curves, temperatures_c):
        if curve.response != "oscillation":
            left_out[curve.label] = f"response {curve.response!r} is not an oscillation"
            continue
        t = float(t) if t is not None else np.nan
        i = int(np.argmin(np.abs(temps - t))) if np.isfinite(t) and temps.size else -1
        if i < 0 or abs(temps[i] - t) > tolerance_c:
            left_out[curve.label] = f"no shift factor within {tolerance_c:g} degC of {t:g} degC"
            continue
        if not (np.isfinite(log_at[i]) and np.isfinite(log_bt[i])):
            left_out[curve.label] = f"shift factor at {temps[i]:g} degC is not finite"
            continue
        a, b = 10.0 ** log_at[i], 10.0 ** log_bt[i]
        idx = np.arange(curve.n_points) if curve.obs_index is None else np.asarray(curve.obs_index)
        omega = np.asarray(curve.inputs["angular_frequency"], float)[idx]
        # the points the shift criterion uses (:class:`Sweep`): finite, positive omega, G' and G''
        ok = np.isfinite(omega) & (omega > 0)
        for v in curve.observed.values():
            ok &= np.isfinite(np.asarray(v, float)) & (np.asarray(v, float) > 0)
        if not ok.any():
            left_out[curve.label] = "no point with positive G' and G''"
            continue
        parts.append((omega[ok] * a, {k: np.asarray(v, float)[ok] * b for k, v in curve.observed.items()},
                      {k: np.asarray(v, float)[ok] * b for k, v in curve.sd.items()}, curve))
        used.append(float(t))
    if not parts:
        raise ValueError(f"no sweep has a finite shift factor: {left_out}")
    omega = np.concatenate([p[0] for p in parts])
    order = np.argsort(omega, kind="stable")
    observed = {k: np.concatenate([p[1][k] for p in parts])[order] for k in parts[0][1]
                if all(k in p[1] for p in parts)}
    sd = {k: np.concatenate([p[2][k] for p in parts])[order] for k in parts[0][2] if all(k in p[2] for p in parts)}
    first = parts[0][3]
    curve = replace(first, condition=f"mastercurve Tref={t_ref:.4g}degC", inputs={"angular_frequency": omega[order]},
                    observed=observed, sd=sd, obs_index=None, n_samples=min(p[3].n_samples for p in parts),
                    nominal={"t_ref_c": t_ref})
    return curve, {"temperatures_c": sorted(used), "left_out": left_out}


# ------------------------------------------------------------------------------------------------
# the pipeline's TTS scope: tts.nc, the shift-function card, the Abaqus *TRS block
# ------------------------------------------------------------------------------------------------
def tts_dataset(sweeps: Sequence[Sweep], t_ref_c: float | None = None, vertical: bool = False) -> xr.Dataset:
    """Shift factors, WLF and Arrhenius fits and the mastercurve of ``sweeps`` as one dataset (``tts.nc``).

    Layout: dim ``temperature`` (sorted) with ``temperature_c`` [degC], ``shift_factor`` (a_T, reduced
    omega = a_T omega), ``log_aT`` and ``log_aT_stderr`` [decades], ``log_bT`` and ``log_bT_stderr`` (vertical
    shifts; zeros when not fitted), ``log_aT_wlf`` and ``log_aT_arrhenius`` (the fitted shift functions),
    ``run`` (source run); dim ``pair`` (adjacent temperatures) with ``pair_rms`` [decades]; dim ``master``
    with the reduced data ``log_omega_reduced``, ``log_storage_reduced``, ``log_loss_reduced`` (log10 of
    rad/s and Pa) and ``master_temperature_c``. Attributes: ``t_ref_c``, ``vertical``, ``n_temperatures``,
    ``n_shifted`` (finite shifts), ``wlf_<key>`` and ``arrhenius_<key>`` (parameters, ``*_stderr``,
    ``rms_decades``, ``success``, ``n``) and ``criterion`` (where the shift criterion is documented).
    """
    sw = sorted(sweeps, key=lambda s: s.temperature_c)
    res = shift_factors(sw, t_ref_c=t_ref_c, vertical=vertical)
    wlf = fit_wlf(res.temperatures_c, res.log_aT, res.log_aT_stderr, res.t_ref_c)
    arr = fit_arrhenius(res.temperatures_c, res.log_aT, res.log_aT_stderr, res.t_ref_c)
    temps = res.temperatures_c
    nan = np.full(temps.size, np.nan)
    la_wlf = wlf_log_aT(temps, wlf["c1"], wlf["c2_k"], res.t_ref_c) if wlf.get("success") else nan
    la_arr = arrhenius_log_aT(temps, arr["ea_j_per_mol"], res.t_ref_c) if arr.get("success") else nan
    mx, my, mt = [], [], []
    for s, a, b in zip(sw, res.log_aT, res.log_bT):
        if np.isfinite(a) and np.isfinite(b):
            mx.append(s.log_w + a)
            my.append(s.log_g + b)
            mt.append(np.full(s.omega.size, s.temperature_c))
    mx, mt = (np.concatenate(v) if v else np.empty(0) for v in (mx, mt))
    my = np.vstack(my) if my else np.empty((0, 2))
    order = np.argsort(mx, kind="stable")
    attrs = {"t_ref_c": res.t_ref_c, "vertical": int(vertical), "n_temperatures": int(temps.size),
             "n_shifted": int(np.isfinite(res.log_aT).sum()),
             "criterion": "tissuemech.tts module docstring (adjacent pairs, symmetric log G', log G'' misfit)"}
    for prefix, fit in (("wlf", wlf), ("arrhenius", arr)):
        for key, value in fit.items():
            if key == "t_ref_c":
                continue
            attrs[f"{prefix}_{key}"] = int(value) if isinstance(value, bool) else value
    return xr.Dataset(
        {"shift_factor": ("temperature", 10.0 ** res.log_aT, {"units": "1", "long_name": "a_T (omega_r = a_T omega)"}),
         "log_aT": ("temperature", res.log_aT, {"units": "1", "long_name": "log10 a_T"}),
         "log_aT_stderr": ("temperature", res.log_aT_stderr, {"units": "1"}),
         "log_bT": ("temperature", res.log_bT, {"units": "1", "long_name": "log10 b_T (G_r = b_T G)"}),
         "log_bT_stderr": ("temperature", res.log_bT_stderr, {"units": "1"}),
         "log_aT_wlf": ("temperature", la_wlf, {"units": "1", "long_name": "fitted WLF log10 a_T"}),
         "log_aT_arrhenius": ("temperature", la_arr, {"units": "1", "long_name": "fitted Arrhenius log10 a_T"}),
         "run": ("temperature", np.array(res.labels, dtype=str)),
         "pair_rms": ("pair", res.pair_rms, {"units": "1", "long_name": "RMS log10 misfit of adjacent sweeps"}),
         "log_omega_reduced": ("master", mx[order], {"units": "log10(rad/s)"}),
         "log_storage_reduced": ("master", my[order, 0] if my.size else my[:, 0], {"units": "log10(Pa)"}),
         "log_loss_reduced": ("master", my[order, 1] if my.size else my[:, 1], {"units": "log10(Pa)"}),
         "master_temperature_c": ("master", mt[order], {"units": "degC"})},
        coords={"temperature_c": ("temperature", temps, {"units": "degC"})}, attrs=attrs)


def trs_abaqus_block(t_ref_c: float, c1: float, c2_k: float) -> str:
    """Abaqus ``*TRS, DEFINITION=WLF`` block (data line ``theta_0, C1, C2``).

    Abaqus's WLF form is log10 A = -C1 (theta - theta_0) / (C2 + theta - theta_0), the one of
    :func:`wlf_log_aT`; theta in the model's temperature unit (degC here; C2 is a temperature difference, so K =
    degC). In an input file the block follows the ``*VISCOELASTIC`` option of the same ``*MATERIAL``, whose
    Prony times are those at theta_0."""
    return ("** time-temperature shift (WLF), fitted by tissuemech.tts; place after *VISCOELASTIC\n"
            f"*TRS, DEFINITION=WLF\n{t_ref_c:.6g}, {c1:.8g}, {c2_k:.8g}\n")


def tts_card(ds: xr.Dataset, dataset: str = "") -> dict:
    """Shift-function card (JSON-ready dict) of a :func:`tts_dataset` result: WLF (the card's form), Arrhenius
    for comparison, standard errors, the temperature range it was fitted on and the Abaqus ``*TRS`` text
    (None when the WLF fit failed, with the reason in ``notes``)."""
    a = ds.attrs
    temps = ds["temperature_c"].values
    ok = np.isfinite(ds["log_aT"].values)
    wlf_ok = bool(a.get("wlf_success"))
    card = {
        "kind": "time_temperature_shift", "dataset": dataset, "shift_function": "WLF" if wlf_ok else None,
        "t_ref_c": float(a["t_ref_c"]), "vertical_shift": bool(a.get("vertical")),
        "wlf": {k: a.get(f"wlf_{k}") for k in ("c1", "c1_stderr", "c2_k", "c2_k_stderr", "rms_decades", "n")},
        "arrhenius": {k: a.get(f"arrhenius_{k}") for k in ("ea_j_per_mol", "ea_j_per_mol_stderr", "rms_decades",
                                                            "n")},
        "formula": {"wlf": "log10 aT = -C1 (T - Tref) / (C2 + T - Tref), T in degC, C2 in K",
                    "arrhenius": "log10 aT = Ea / (R ln 10) (1/T - 1/Tref), T in K"},
        "valid_range": {"temperature_c": [float(temps[ok].min()), float(temps[ok].max())] if ok.any() else None,
                        "n_temperatures": int(temps.size), "n_shifted": int(ok.sum())},
        "abaqus_trs": trs_abaqus_block(float(a["t_ref_c"]), float(a["wlf_c1"]), float(a["wlf_c2_k"]))
        if wlf_ok else None,
        "notes": [] if wlf_ok else [f"WLF fit failed: {a.get('wlf_message', '')}; no *TRS block"],
    }
    for key in ("wlf", "arrhenius"):   # JSON has no NaN: a missing or non-finite value is null
        card[key] = {k: (None if v is None or not np.isfinite(float(v)) else int(v) if k == "n" else float(v))
                     for k, v in card[key].items()}
    return card


def run_tts(runs_dir, out_nc, card_json, card_inp, figure=None, *, dataset: str = "", t_ref_c: float | None = None,
            vertical: bool = False, exclude_flagged: bool = True,
            held_out: Callable[[Sequence[Sweep]], dict] | None = None) -> xr.Dataset:
    """The pipeline's TTS scope of one dataset (rule ``tts``).

    Every frequency-sweep run of ``runs_dir`` (quality-flagged points dropped when ``exclude_flagged``) at its
    logged temperature -> ``out_nc`` (:func:`tts_dataset`), the shift-function card ``card_json``
    (:func:`tts_card`), its Abaqus ``*TRS`` block ``card_inp`` and the mastercurve figure (``figure``; none when
    None). ``held_out``: a leave-one-temperature-out check, ``sweeps -> {"after", "before", "n_folds",
    "per_temperature": {T: [before, after]}}`` (the workflow passes
    :func:`tissuemech.diagnosis.temperature.leave_one_temperature_out`, which sits above this module), stored as
    ``held_out_rms`` per temperature and the attributes ``held_out_rms_decades`` (shifted),
    ``held_out_rms_unshifted_decades`` and ``held_out_folds``. Raises ``ValueError`` when the sweeps carry fewer
    than two temperatures.
    """
    runs = [read_netcdf(p) for p in sorted(Path(runs_dir).glob("*.nc"))]
    sweeps = sweeps_from_runs([drop_flagged(r) if exclude_flagged else r for r in runs])
    ds = tts_dataset(sweeps, t_ref_c=t_ref_c, vertical=vertical)
    ds.attrs["dataset"] = dataset
    if held_out is not None:
        held = held_out(sweeps)
        per_t = {round(float(t), 1): v[1] for t, v in held["per_temperature"].items()}
        ds["held_out_rms"] = ("temperature", np.array([per_t.get(round(float(t), 1), np.nan)
                                                       for t in ds["temperature_c"].values]),
                              {"units": "1", "long_name": "RMS log10 error of the temperature predicted from the "
                                                          "mastercurve of the others (leave-one-temperature-out)"})
        ds.attrs.update(held_out_rms_decades=held["after"], held_out_rms_unshifted_decades=held["before"],
                        held_out_folds=held["n_folds"])
    write_netcdf(ds, out_nc)
    card = tts_card(ds, dataset)
    write_json(card, card_json)
    write_text(card["abaqus_trs"] or "** no WLF shift function: " + "; ".join(card["notes"]) + "\n", card_inp)
    if figure is not None:
        from .plots import plot_mastercurve

        plot_mastercurve(ds, figure, title=f"{dataset}: {ds.attrs['n_shifted']} of {ds.attrs['n_temperatures']} "
                                           "temperatures shifted")
    return ds
