"""Generic detection of residual structure that no catalogued cause names.

Every numeric covariate of the residual table that varies *within* curves (strain, log rate and their
products, time within a test, frequency^2, 1/gap, the predicted level, every logged channel and every numeric
``covariate_*`` column of ``samples.csv`` where it changes during a test) is tested, per block of comparable rows
(test kind x quantity), with a regression of the log-residual ln(observed/predicted) on the covariate, both sides
demeaned per curve (the level differences between samples do not enter), standard errors clustered by curve.
A covariate that is constant within each curve (the session clock, sample-sheet columns, channel means) is an
across-curve covariate: it is tested once over every test, with specimen and sample as random effects, in the
covariates table (:mod:`tissuemech.diagnosis.covariates`), not here; so is elapsed time, which within one curve is
the curve's own time axis.

Specimen-to-specimen variability is expected and not scanned (an unusual specimen is the catalogue's
``outlier_specimen``).

``effect_size`` is the change of the log-residual over the covariate's 5-95 % range (about a relative
change; 0.05 = 5 %). A structure is *practically* relevant when |effect_size| >= :data:`MIN_EFFECT`.
The false-alarm rate is controlled by the caller (Holm across every catalogue and generic test,
:mod:`.report`).

Attribution among confounded covariates (:func:`confounded_covariates`): the across-curve covariates
(elapsed time, order, logged temperature/gap/normal-force means, the run temperature, sample-sheet columns,
specimen and text columns as factors) are compared pairwise; sets the design cannot separate (R^2 >=
:data:`CONFOUNDED_R2`, VIF >= 10) are tested jointly and reported with the design that would separate them
(``diagnosis.json`` ``confounded``). A named cause that explains one member of such a set explains the
structure of the others (:func:`tissuemech.diagnosis.catalogue.explains`).
"""
from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import scipy

from ..tts import run_temperature_c
from .. import stats as st
from .evidence import run_id
from .findings import separating_design
from .oscillation import spectrum_shape_basis

#: smallest structured misfit (log-residual change over the covariate range) worth reporting
MIN_EFFECT = 0.03

#: residual-table columns scanned as covariates (plus every ``channel_*`` and ``covariate_*`` column)
COVARIATES = ("strain", "log_rate", "strain_x_log_rate", "strain_sq_x_log_rate", "log_time", "frequency_sq",
              "inverse_gap", "predicted_abs")

#: residual-table columns of the session clock: constant within curves, tested in the covariates table and
#: compared here with the other across-curve covariates for confounding
SESSION_COVARIATES = ("elapsed_time", "test_order", "first_load")

#: smallest number of curves in a block for a test
MIN_CURVES = 3


#: logged channels that are functions of the measured response itself (a stiffer sample has a smaller
#: raw phase and deflection); their correlation with the residual is tautological, so they are not scanned
RESPONSE_CHANNELS = ("channel_raw_phase", "channel_deflection_angle")


def covariate_columns(table: pd.DataFrame) -> list[str]:
    """Covariates present in ``table`` (fixed list, then logged channels and sample-sheet covariates)."""
    cols = [c for c in COVARIATES if c in table]
    cols += sorted(c for c in table.columns if (c.startswith("channel_") and c not in RESPONSE_CHANNELS)
                   or c.startswith("covariate_"))
    return cols


def _demean(values: np.ndarray, codes: np.ndarray) -> np.ndarray:
    n = np.bincount(codes)
    return values - (np.bincount(codes, values) / np.maximum(n, 1))[codes]


def _range(x: np.ndarray) -> float:
    lo, hi = np.nanquantile(x, [0.05, 0.95])
    return float(hi - lo)


def test_covariate(block: pd.DataFrame, cov: str) -> dict | None:
    """Regression test of the block's log-residual on one covariate (module docstring); None if untestable."""
    b = block[np.isfinite(block[cov].to_numpy(float)) & np.isfinite(block["log_ratio"].to_numpy(float))]
    if b["curve"].nunique() < MIN_CURVES or b[cov].nunique() < 3:
        return None
    codes = pd.factorize(b["curve"])[0]
    x = b[cov].to_numpy(float)
    spread = np.zeros(codes.max() + 1)
    np.maximum.at(spread, codes, x)
    low = np.full(codes.max() + 1, np.inf)
    np.minimum.at(low, codes, x)
    total = x.max() - x.min()
    if total > 0 and np.median(spread - low) > 0.05 * total:
        y = _demean(b["log_ratio"].to_numpy(float), codes)
        xd = _demean(x, codes)
        res = st.cluster_regression(y, pd.DataFrame({cov: xd}), groups=codes)
        span = _range(x)
        level = "within curves"
    else:
        # constant within curves: an across-curve covariate, tested once over every test with specimen and sample
        # as random effects in the covariates table (tissuemech.diagnosis.covariates), not per block here
        return None
    t = st.coefficient_test(res, cov)
    return {"covariate": cov, "level": level, "statistic": t["statistic"], "p_value": t["p_value"],
            "log10_p": t["log10_p"], "effect_size": float(t["estimate"] * span), "slope": t["estimate"],
            "n_curves": int(b["curve"].nunique()), "n_points": int(len(b))}


#: the within-curve coordinate along which a test kind's shape is a property of the linear relaxation spectrum
#: alone: a frequency sweep in the linear range is G*(omega), fixed by G(t) (interconversion), so a misfit
#: shape along omega shared by every sweep is a statement about the baseline's spectrum, not a covariate effect
SPECTRUM_COORDINATE = {"frequency_sweep": "frequency_sq"}


def shared_shape(block: pd.DataFrame, coordinate: str) -> tuple[np.ndarray, dict] | None:
    """The misfit shape shared by every curve of a block along its spectrum coordinate, and a summary.

    Fits the per-curve demeaned log-residual with Legendre polynomials in log omega common to all curves
    (:func:`tissuemech.diagnosis.catalogue.spectrum_shape_basis`), with curve-clustered covariance. The degree
    d is chosen by BIC, n ln(RSS_d / n) + d ln n, among 1 .. (distinct coordinate values - 2): how far the
    baseline's spectrum misses the sweeps is a property of the data (a fast mode outside the window the fitted
    tests resolve raises G'' over the last decade by a factor that no fixed-degree polynomial follows). Returns ``(shape, summary)``: ``shape`` (per row, log units,
    mean zero per curve) and ``summary`` with ``range_log`` (max - min of the shape over the block),
    ``degree``, ``n_curves``, ``wald_p`` (joint test of the shape coefficients, NaN when not computable); None
    when the block cannot carry a shape (fewer than :data:`MIN_CURVES` curves or 4 coordinate values).
    """
    w2 = block[coordinate].to_numpy(float)
    y = block["log_ratio"].to_numpy(float)
    ok = np.isfinite(w2) & (w2 > 0) & np.isfinite(y)
    if block.loc[ok, "curve"].nunique() < MIN_CURVES or np.unique(w2[ok]).size < 4:
        return None
    codes = pd.factorize(block["curve"])[0]
    full = spectrum_shape_basis(np.where(ok, w2, np.nan), max_degree=None)
    full_d = np.column_stack([_demean(np.where(ok, b, 0.0), codes) for b in full.T])
    yd = _demean(np.where(ok, y, 0.0), codes)
    n = int(ok.sum())
    bic = []
    for d in range(1, full.shape[1] + 1):
        coef_d, *_ = np.linalg.lstsq(full_d[ok, :d], yd[ok], rcond=None)
        rss = float(np.sum((yd[ok] - full_d[ok, :d] @ coef_d) ** 2))
        bic.append(n * np.log(max(rss, 1e-300) / n) + d * np.log(n))
    degree = int(np.argmin(bic)) + 1
    basis, basis_d = full[:, :degree], full_d[:, :degree]
    names = [f"P{k}" for k in range(1, degree + 1)]
    res = st.cluster_regression(yd[ok], pd.DataFrame(basis_d[ok], columns=names), groups=codes[ok])
    coef = res.params[names].to_numpy(float)
    shape = np.where(ok, _demean(np.where(ok, basis @ coef, 0.0), codes), 0.0)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            wald_p = float(res.wald_test(", ".join(f"{n} = 0" for n in names), scalar=True).pvalue)
    except (ValueError, np.linalg.LinAlgError):
        wald_p = np.nan
    grid = np.polynomial.legendre.legvander(np.linspace(-1, 1, 64), degree)[:, 1:] @ coef
    return shape, {"range_log": float(grid.max() - grid.min()), "degree": degree,
                   "n_curves": int(block.loc[ok, "curve"].nunique()), "wald_p": wald_p}


def structure_tests(table: pd.DataFrame, predicted_tests=(), shapes: list | None = None) -> list[dict]:
    """Every covariate test on every (test kind, quantity) block of the residual table.

    ``predicted_tests``: test kinds the baseline was *not* fitted to (cross-test predictions). In such a block
    of a kind in :data:`SPECTRUM_COORDINATE`, the misfit shape shared by every curve along the coordinate
    (:func:`shared_shape`) is removed before the covariates are tested, so that only structure that differs
    between curves is tested there; the shape is appended to ``shapes`` (when given) with ``test`` and
    ``quantity``, as a statement about the baseline's spectrum.

    Returns a list of dicts with ``test``, ``quantity``, ``covariate``, ``level``, ``statistic``,
    ``p_value``, ``log10_p``, ``effect_size``, ``practical``, ``n_curves``, ``n_points``.
    """
    out = []
    rows = table[np.isfinite(table["log_ratio"])]
    # rows whose predicted magnitude stands 5 sigma above the noise, where the log-residual is defined and
    # nearly unbiased. Not the observed ``above_noise`` column: selecting on the observed value truncates the
    # response (near the threshold only rows with positive noise pass), which biases ln(observed/predicted)
    # upward where the level is low and made spurious loss-modulus structure along predicted_abs and
    # log_time in the constructed designs (tests/diagnosis/test_catalogue.py); the prediction does not
    # depend on one point's noise, so it selects without that bias.
    rows = rows[rows["predicted_abs"] > 5.0 * rows["sigma"]]
    # points the ingest flagged (inertia-dominated, below the declared torque resolution, a frequency sweep
    # beyond its sample's LVE limit) are a fact of the measurement, reported by their own findings; the fits
    # leave them out, and their residuals are not the material's
    if "quality_flag" in rows:
        rows = rows[rows["quality_flag"] == 0]
    covs = covariate_columns(rows)
    for (test, quantity), block in rows.groupby(["test", "quantity"]):
        coordinate = SPECTRUM_COORDINATE.get(str(test))
        if coordinate and str(test) in set(predicted_tests) and coordinate in block:
            found = shared_shape(block, coordinate)
            if found is not None:
                shape, summary = found
                block = block.assign(log_ratio=block["log_ratio"].to_numpy(float) - shape)
                if shapes is not None:
                    shapes.append({"test": str(test), "quantity": str(quantity), "coordinate": coordinate,
                                   **summary})
        # specimen-to-specimen variability is expected (log-normal population); an unusual specimen is the
        # catalogue's outlier_specimen, so the specimen factor is not scanned here
        results = [test_covariate(block, c) for c in covs]
        for r in results:
            if r is None:
                continue
            r.update(test=str(test), quantity=str(quantity), practical=bool(abs(r["effect_size"]) >= MIN_EFFECT))
            out.append(r)
    return out


def serial_structure(table: pd.DataFrame) -> dict:
    """Descriptive serial structure of the residuals per test kind: median Durbin-Watson d, share of
    curves with d < 1.5 and median runs-test z (residuals in the order measured)."""
    out = {}
    for test, block in table.groupby("test"):
        dws, zs = [], []
        for _, g in block.groupby(["curve", "quantity"]):
            e = g.sort_values("point")["residual"].to_numpy()
            if e.size >= 8 and np.any(e != 0):
                dws.append(st.durbin_watson(e))
                zs.append(st.runs_test(e)["statistic"])
        if dws:
            zs = np.asarray(zs, float)
            out[str(test)] = {"n_curves": len(dws), "median_durbin_watson": float(np.median(dws)),
                              "share_dw_below_1_5": float(np.mean(np.asarray(dws) < 1.5)),
                              "median_runs_z": float(np.median(zs[np.isfinite(zs)])) if np.isfinite(zs).any() else np.nan}
    return out


# ------------------------------------------------------------------------------------------------
# attribution among confounded across-curve covariates
# ------------------------------------------------------------------------------------------------
#: two curve-level covariates are confounded in a design when one explains this share of the other's
#: variance across curves: R^2 >= 0.9 is a variance inflation factor >= 10, the usual limit of serious
#: multicollinearity (Kutner, Nachtsheim, Neter & Li 2005, Applied Linear Statistical Models, 5th ed., 10.5)
CONFOUNDED_R2 = 0.9

def curve_covariates(table: pd.DataFrame, runs=()) -> pd.DataFrame:
    """One row per curve (index: curve id) of every covariate that is constant within curves: the numeric
    :func:`covariate_columns` whose within-curve range is < 5 % of their range across curves (curve mean),
    the run temperature ``temperature_c`` (logged channel median, else the attribute; from ``runs``), the
    specimen and every text ``covariate_*`` attribute of ``runs`` as factors (``factor:<name>``)."""
    if table.empty or "curve" not in table:
        return pd.DataFrame()
    rows = table[np.isfinite(table["log_ratio"].astype(float))] if "log_ratio" in table else table
    if rows.empty:
        return pd.DataFrame()
    g = rows.groupby("curve", sort=False)
    out = {}
    for c in [c for c in SESSION_COVARIATES if c in rows] + covariate_columns(rows):
        x = rows[c].astype(float)
        if not np.isfinite(x).any():
            continue
        within = (g[c].max() - g[c].min()).median()
        mean = g[c].mean()
        total = float(mean.max() - mean.min())
        if total > 0 and within <= 0.05 * total:
            out[c] = mean
    frame = pd.DataFrame(out)
    frame["factor:specimen"] = g["specimen"].first()
    for r in runs:
        cid = run_id(r)
        if cid not in frame.index:
            continue
        t = run_temperature_c(r)
        if np.isfinite(t):
            frame.loc[cid, "temperature_c"] = t
        for k, v in r.attrs.items():
            if k.startswith("covariate_") and isinstance(v, str) and v:
                frame.loc[cid, f"factor:{k}"] = v
    return frame


def _r2(frame: pd.DataFrame, a: str, b: str) -> float:
    """Share of variance of one covariate explained by the other across curves (numeric-numeric: r^2;
    factor-numeric: one-way ANOVA eta^2; factor-factor: 1 when the partitions coincide, else 0)."""
    f = frame[[a, b]].dropna()
    if len(f) < 3:
        return np.nan
    fa, fb = a.startswith("factor:"), b.startswith("factor:")
    if fa and fb:
        ca, cb = pd.factorize(f[a])[0], pd.factorize(f[b])[0]
        return float(len(set(zip(ca, cb))) == len(set(ca)) == len(set(cb)) and len(set(ca)) > 1)
    if fa or fb:
        fac, num = (a, b) if fa else (b, a)
        y = f[num].astype(float)
        if y.std() == 0 or f[fac].nunique() < 2:
            return np.nan
        fitted = y.groupby(f[fac]).transform("mean")
        return float(1.0 - ((y - fitted) ** 2).sum() / ((y - y.mean()) ** 2).sum())
    x, y = f[a].astype(float), f[b].astype(float)
    if x.std() == 0 or y.std() == 0:
        return np.nan
    return float(np.corrcoef(x, y)[0, 1] ** 2)


def confounded_covariates(table: pd.DataFrame, runs=(), r2_limit: float = CONFOUNDED_R2) -> list[dict]:
    """Sets of across-curve covariates that this design cannot separate, each tested jointly.

    Covariates (:func:`curve_covariates`) are linked when one explains >= ``r2_limit`` of the other's
    variance across curves; every connected set of >= 2 is reported with ``covariates``, ``r2`` (pairwise,
    ``"a|b"``), the joint F-test of the curve levels (median ln(observed/predicted) per curve, the linearly
    independent numeric members together, specimen and sample as random effects:
    :func:`tissuemech.stats.mixed_coefficient_test`) ``joint_statistic``/``joint_p``, ``unique_p`` (each member's
    partial test given the others; large when the set is collinear: the data cannot say which one it is), and
    ``design`` (what would separate them).
    """
    frame = curve_covariates(table, runs)
    if frame.empty or len(frame) < 4:
        return []
    cols = [c for c in frame.columns if frame[c].nunique(dropna=True) > 1]
    links = {}
    for i, a in enumerate(cols):
        for b in cols[i + 1:]:
            r2 = _r2(frame, a, b)
            if np.isfinite(r2) and r2 >= r2_limit:
                links[(a, b)] = r2
    # connected components
    parent = {c: c for c in cols}

    def root(c):
        while parent[c] != c:
            c = parent[c]
        return c

    for a, b in links:
        parent[root(a)] = root(b)
    groups: dict[str, list[str]] = {}
    for c in cols:
        groups.setdefault(root(c), []).append(c)
    rows = table[np.isfinite(table["log_ratio"])]
    level = rows.groupby("curve")["log_ratio"].median()
    pieces = rows.groupby("curve")[["specimen", "sample"]].first()
    out = []
    for members in groups.values():
        if len(members) < 2:
            continue
        numeric = [m for m in members if not m.startswith("factor:")]
        f = frame.join(level.rename("y")).join(pieces).dropna(subset=["y"] + numeric)
        joint = {"statistic": np.nan, "p_value": np.nan}
        unique = {}
        if numeric and len(f) > len(numeric) + 2:
            # the members are (nearly) collinear by construction: the joint test is on a basis of their span (the
            # linearly independent members, pivoted QR), with specimen and sample as random effects
            z = f[numeric].astype(float)
            z = (z - z.mean()) / z.std().replace(0.0, 1.0)
            _, r, piv = scipy.linalg.qr(z.to_numpy(), mode="economic", pivoting=True)
            d = np.abs(np.diag(r))
            basis = [numeric[i] for i, v in zip(piv, d) if v > 1e-8 * max(d.max(), 1e-300)]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t = st.mixed_coefficient_test(f, "y", basis) if basis else None
                if t is not None:
                    joint = {"statistic": float(t["statistic"]), "p_value": float(t["p_value"])}
                for m in basis:
                    u = st.mixed_coefficient_test(f, "y", m, controls=tuple(b for b in basis if b != m))
                    unique[m] = float(u["p_value"]) if u is not None else 1.0
        designs = list(dict.fromkeys(separating_design(m) for m in members))
        out.append({"covariates": members,
                    "r2": {f"{a}|{b}": r for (a, b), r in links.items() if a in members and b in members},
                    "joint_statistic": joint["statistic"], "joint_p": joint["p_value"], "unique_p": unique,
                    "n_curves": int(len(f)),
                    "design": f"{', '.join(members)} vary together across the {len(frame)} curves of this design "
                              f"(R^2 >= {r2_limit}); to separate them: "
                              + "; ".join(designs) + "."})
    return out
