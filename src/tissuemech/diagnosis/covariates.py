"""The ``covariates`` table of ``diagnosis.json``: every sample-sheet column, every logged channel and the session
clock tested against the curve levels, significant or not, and the specimens and samples that stand out.

One level per curve (:func:`tissuemech.diagnosis.findings.curve_levels`: the median ln(observed/predicted) of the
quantity that carries the curve's stiffness) is modelled with the test condition as fixed effects and specimen and
sample as random effects (:func:`tissuemech.stats.mixed_coefficient_test`: statsmodels MixedLM, REML; degrees of
freedom by the between-within rule, so that a covariate that follows the specimens is judged on the specimens;
cluster-robust OLS where the mixed model cannot be fitted, and the entry's ``method`` says which). So a block design,
in which the specimens are measured one after the other, cannot turn the specimens' differences into a trend of a
covariate that follows them.

* the session clock -- elapsed time (``elapsed_time``, hours) and the position in each sample's sequence
  (``test_order``) -- is read as the drift detector reads it (:func:`tissuemech.diagnosis.levels.clock_test`):
  within samples (the covariate centred on its sample mean) unless the test condition explains the clock there (a
  fixed test order), and between the samples of each specimen (sample means centred on the specimen's mean), the
  read with the smaller standard error kept: a drift follows the clock inside a specimen, the specimens'
  differences do not;
* the logged channels (``channel_temperature``, ``channel_gap``: the curve's mean; ``channel_normal_force``: the
  force at the curve's smallest strains, the preload, since the thrust during a test is a response), the
  run temperature (``temperature_c``, from the channel or the sample sheet), the gap and plate radius of the sample
  sheet (``gap_mm``, ``radius_mm``) and every extra sample-sheet column (``covariate_<name>``; text columns are
  factors, tested by a joint Wald F over their levels) are tested on all the variation they have; a positive one
  that spans a decade is also tested on a log scale (the stronger, Bonferroni x 2; :data:`LOG_SCALE_SPAN`);
* ``first_load`` (the first test of each sample) within samples.

Each entry: ``covariate``, ``kind`` (``session clock``, ``logged channel``, ``sample sheet``, ``factor``), ``source``,
``n_levels`` (distinct values), ``n_curves``, ``tested`` (with the reason where not), ``statistic`` (t or F),
``p_value``, ``p_holm`` (Holm over every test of the diagnosis, :mod:`.decision`), ``effect_size`` (the change of
the curve level, in ln, over the covariate's 5-95 % range; for a factor the range of its level means),
``practical`` (>= :data:`tissuemech.diagnosis.generic.MIN_EFFECT`), ``level`` (where the covariate varies),
``method``. The entries are part of the scan for unnamed structure: a significant, relevant one that no named
cause explains is also an ``unexplained`` entry.

Outlier rows (``kind`` ``outlier specimen`` / ``outlier sample``, not part of the scan: the outlier specimen is a
catalogue cause): every specimen's level relative to the median of the others (``ratio``), its externally
studentised deletion t against the other specimens (``deletion_t``, t_{n-2}, Bonferroni over the n specimens:
:func:`tissuemech.stats.deletion_outlier_test`), and the ratio this design would need to name it
(``ratio_needed``: the deletion t at the first Holm step of the catalogue family, from the null distribution of
the largest deletion t of n specimens, :data:`DELETION_T_CALIBRATION`); for samples, the most extreme sample of each
specimen, its deviation from its specimen's mean tested against every sample's deviation (deletion t).
"""
from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pandas as pd
import scipy

from .. import stats as st
from ..tts import run_temperature_c
from .evidence import run_id
from .findings import DiagnosisContext, curve_levels, describe_log_change, separating_design
from .generic import MIN_EFFECT, RESPONSE_CHANNELS
from .levels import clock_test, specimen_levels

#: channels of the residual table tested as covariates (their curve mean); response channels are not
CHANNELS = ("channel_temperature", "channel_gap", "channel_normal_force")

#: Calibration of the deletion-t threshold of an outlier specimen (docs/diagnosis.md, "Outlier specimens";
#: ``benchmarks/outlier_calibration.py --draws 40000 --seed 20261201``): the rejection rate of
#: :func:`tissuemech.stats.deletion_outlier_test` (Bonferroni over n) on 40000 seeded draws of n normal specimen
#: levels without an outlier, at its nominal level. The Bonferroni bound is the level of the largest of n deletion
#: t's within Monte Carlo error (SE 0.0011, 0.0005, 0.00016) for every n measured, so the threshold needs no further
#: correction: {n: {nominal: measured}}
DELETION_T_CALIBRATION = {
    3: {0.05: 0.0494, 0.01: 0.0106, 0.001: 0.0010},
    4: {0.05: 0.0499, 0.01: 0.0099, 0.001: 0.0010},
    5: {0.05: 0.0503, 0.01: 0.0098, 0.001: 0.0005},
    6: {0.05: 0.0510, 0.01: 0.0104, 0.001: 0.0012},
    8: {0.05: 0.0508, 0.01: 0.0105, 0.001: 0.0009},
}


def curve_frame(ctx: DiagnosisContext) -> pd.DataFrame:
    """One row per curve of the residual table: the curve level (NaN for a curve with no point above the noise
    floor) and every covariate of the table (module docstring)."""
    t = ctx.table
    if t.empty or "curve" not in t:
        return pd.DataFrame()
    g = t.groupby("curve", sort=False)
    lv = pd.DataFrame({"curve": list(g.groups), "specimen": g["specimen"].first().to_numpy(),
                       "sample": g["sample"].first().to_numpy(), "test": g["test"].first().to_numpy(),
                       "condition": g["condition"].first().to_numpy()})
    levels = curve_levels(t).set_index("curve")
    for c in ("log_scale", "elapsed_h", "position", "first_load"):
        lv[c] = lv["curve"].map(levels[c]) if c in levels else np.nan
    for ch in CHANNELS:
        if ch in t and ch not in RESPONSE_CHANNELS:
            lv[ch] = lv["curve"].map(g[ch].mean())
    if "channel_normal_force" in t and "strain" in t:
        # the normal force of a torsion test is also a response (the Poynting thrust grows with the strain and the
        # stiffness): the covariate is the force the sample is held at, read at the curve's smallest strains
        small = t[np.isfinite(t["channel_normal_force"]) & np.isfinite(t["strain"])]
        small = small[small["strain"] <= small.groupby("curve")["strain"].transform(lambda s: s.quantile(0.2))]
        lv["channel_normal_force"] = lv["curve"].map(small.groupby("curve")["channel_normal_force"].median())
    for c in t.columns:
        if c.startswith("covariate_"):
            lv[c] = lv["curve"].map(g[c].first())
    if "inverse_gap" in t:
        lv["gap_mm"] = lv["curve"].map(1e3 / g["inverse_gap"].mean())
    if "radius_m" in t:
        lv["radius_mm"] = lv["curve"].map(1e3 * g["radius_m"].first())
    by_id = {run_id(r): r for r in ctx.runs}
    temps, texts = {}, {}
    for cid in lv["curve"]:
        r = by_id.get(cid)
        if r is None:
            continue
        temps[cid] = run_temperature_c(r)
        for k, v in r.attrs.items():
            if k.startswith("covariate_") and isinstance(v, str) and v:
                texts.setdefault(k, {})[cid] = v
    lv["temperature_c"] = lv["curve"].map(temps).astype(float)
    for k, m in texts.items():
        lv[k] = lv["curve"].map(m)
    lv["elapsed_time"] = lv["elapsed_h"]
    lv["test_order"] = lv["position"]
    return lv


def _candidates(lv: pd.DataFrame) -> list[tuple[str, str, str, bool]]:
    """(column, kind, source, categorical) of every covariate of the frame, in the order they are reported."""
    out = [("elapsed_time", "session clock", "started_at / total_time (hours), within samples", False),
           ("test_order", "session clock", "position in each sample's sequence, within samples", False),
           ("first_load", "session clock", "first test of each sample, within samples", False)]
    out += [(c, "logged channel", f"logged {c[len('channel_'):].replace('_', ' ')} channel ("
             + ("at the curve's smallest strains: the preload" if c == "channel_normal_force" else "curve mean") + ")",
             False) for c in CHANNELS if c in lv]
    if "channel_temperature" not in lv:   # the run temperature is the channel's median where there is one
        out.append(("temperature_c", "sample sheet", "run temperature (sample sheet or export)", False))
    out += [("gap_mm", "sample sheet", "gap (sample sheet, dataset.yaml or export)", False),
            ("radius_mm", "sample sheet", "plate radius (sample sheet, dataset.yaml or export)", False)]
    for c in sorted(c for c in lv.columns if c.startswith("covariate_")):
        cat = lv[c].dtype == object
        out.append((c, "factor" if cat else "sample sheet", f"sample-sheet column {c[len('covariate_'):]!r}"
                    + (" (text: a factor)" if cat else ""), cat))
    return [o for o in out if o[0] in lv]


#: a positive covariate whose values span at least this ratio is also tested on a log scale (Bonferroni x 2):
#: a preload, a rate or a concentration often acts as a power of itself, and a decade-wide linear regressor puts
#: all its leverage on its largest values
LOG_SCALE_SPAN = 10.0


def _log_scale_test(lv: pd.DataFrame, column: str, factors) -> dict | None:
    """The mixed-model test of ln(``column``) where every value is positive and they span :data:`LOG_SCALE_SPAN`."""
    x = pd.to_numeric(lv[column], errors="coerce")
    known = x[x.notna()]
    if known.empty or not (known > 0).all() or known.max() / known.min() < LOG_SCALE_SPAN:
        return None
    return st.mixed_coefficient_test(lv.assign(**{column: np.log(x)}), "log_scale", column, factors)


def _effect_size(lv: pd.DataFrame, column: str, test: dict, categorical: bool, log_scale: bool = False) -> float:
    if categorical:
        means = (lv["log_scale"] - lv.groupby("condition")["log_scale"].transform("mean")).groupby(lv[column]).mean()
        return float(means.max() - means.min()) if len(means) > 1 else 0.0
    values = lv[column].astype(float)
    lo, hi = np.nanquantile(np.log(values) if log_scale else values, [0.05, 0.95])
    return float(test.get("estimate", np.nan) * (hi - lo))


def _entry(column, kind, source, n_levels, n_curves, **kw) -> dict:
    return {"effect": "covariate", "covariate": column, "kind": kind, "source": source, "n_levels": int(n_levels),
            "n_curves": int(n_curves), "test": "every test", "quantity": "curve level", "level": "across curves",
            **kw}


def covariate_tests(lv: pd.DataFrame) -> list[dict]:
    """The tested (or untestable) covariate entries of a :func:`curve_frame` (module docstring)."""
    out = []
    if lv.empty:
        return out
    n_all = len(lv)
    lv = lv[np.isfinite(lv["log_scale"].astype(float))]
    factors = ("condition",) if lv["condition"].nunique() > 1 else ()
    for column, kind, source, categorical in _candidates(lv):
        if len(lv) < 4:
            out.append(_entry(column, kind, source, 0, len(lv), tested=False,
                              evidence=f"{len(lv)} of the {n_all} curves have a level above the noise floor; a "
                                       f"covariate test needs 4"))
            continue
        vals = lv[column]
        n_levels = int(vals.nunique(dropna=True))
        if n_levels < 2:
            out.append(_entry(column, kind, source, n_levels, int(vals.notna().sum()), tested=False,
                              evidence=f"{column} does not vary over these curves ({n_levels} value)"
                              if n_levels else f"{column} is not recorded for these curves"))
            continue
        variation, log_read = "", False
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if kind == "session clock":
                got = clock_test(lv[lv[column].notna()], column)
                t = got[0] if got else None
                variation = got[1].split(" (")[0] if got else ""
                if t is not None and t.get("confounded_with_condition"):
                    # the drift detector's read, reported with its confounding; not in the scan: within samples the
                    # clock is the condition up to the pauses' jitter, and its t can be infinite on a null design
                    out.append(_entry(column, kind, source, n_levels, int(t["n"]), tested=False,
                                      slope=t.get("estimate", np.nan), variation=variation + ", confounded with the "
                                      "test condition",
                                      evidence=f"{column} is read only within samples, where the test condition "
                                               f"explains it (slope {t.get('estimate', np.nan):.3g} in log level per "
                                               f"{'hour' if column == 'elapsed_time' else 'unit'}, not "
                                               f"tested: a misfit that differs by condition would pass for it); a "
                                               f"design that would separate them: {separating_design('condition')}"))
                    continue
            else:
                t = st.mixed_coefficient_test(lv, "log_scale", column, factors, categorical=categorical)
                logged = _log_scale_test(lv, column, factors) if not categorical else None
                if logged is not None and (t is None or logged["log10_p"] < t["log10_p"]):
                    t, log_read = logged, True
                if logged is not None and t is not None:
                    lp = min(0.0, t["log10_p"] + np.log10(2.0))
                    t = dict(t, p_value=10 ** lp, log10_p=lp)
        if t is None:
            why = (f"{column} cannot be read within samples or within specimens apart from the test conditions "
                   f"(a trend of the session clock is never read from the specimens' differences); a design that "
                   f"would: {separating_design(column)}" if kind == "session clock" else
                   f"{column} is collinear with the test conditions in this design, or leaves too few degrees of "
                   f"freedom (not separable from a misfit that differs by condition)")
            out.append(_entry(column, kind, source, n_levels, int(vals.notna().sum()), tested=False, evidence=why))
            continue
        size = _effect_size(lv, column, t, categorical, log_scale=log_read)
        out.append(_entry(column, kind, source, n_levels, int(t["n"]), tested=True, statistic=t["statistic"],
                          statistic_name="F" if categorical else "t", p_value=t["p_value"], log10_p=t["log10_p"],
                          effect_size=size, slope=t.get("estimate", np.nan), df=t.get("df", t.get("df2", np.nan)),
                          variation=(f"varies at the {t['level']} level; read on a log scale" if log_read
                                     else variation or f"varies at the {t['level']} level"),
                          method=t["method"], practical=bool(abs(size) >= MIN_EFFECT),
                          evidence=(f"curve levels {describe_log_change(size)} over the range of {column} "
                                    + (f"(read on a log scale, Bonferroni x 2 with the linear scale; "
                                       if log_read else "(")
                                    + f"{'F' if categorical else 't'} = {t['statistic']:.2f}, p = {t['p_value']:.2g}; "
                                    f"{t['method']})")))
    return out


def _critical_t(n: int, alpha: float) -> float:
    """Two-sided critical deletion t of the most extreme of n values at family level ``alpha`` (Bonferroni over n,
    exact within Monte Carlo error: :data:`DELETION_T_CALIBRATION`)."""
    return float(scipy.stats.t.isf(alpha / (2.0 * n), n - 2)) if n >= 3 else np.inf


def outlier_rows(ctx: DiagnosisContext, findings: Sequence[dict], alpha: float = st.ALPHA) -> list[dict]:
    """The outlier-specimen and outlier-sample rows of the table (module docstring); empty below 3 specimens."""
    levels = curve_levels(ctx.table)
    out = []
    if levels["specimen"].nunique() >= 3:
        try:
            spec = specimen_levels(levels)
        except ValueError:
            spec = None
        if spec is not None:
            n_cat = max(sum(1 for f in findings if f.get("tested") and np.isfinite(f.get("p_value", np.nan))), 1)
            # the first Holm step of the catalogue family: alpha/2 over its tested causes
            t_crit = _critical_t(spec.size, alpha / 2 / n_cat)
            outlier = next((f for f in findings if f.get("effect") == "outlier_specimen"), {})
            out += _deletion_rows(spec, "outlier specimen", t_crit, outlier)
    if "sample" in levels and (levels.groupby("specimen")["sample"].nunique() >= 2).any():
        resid = levels["log_scale"] - levels.groupby("condition")["log_scale"].transform("mean")
        per_sample = resid.groupby(levels["sample"]).mean()
        spec_of = levels.groupby("sample")["specimen"].first()
        within = per_sample - per_sample.groupby(spec_of).transform("mean")
        within = within[spec_of.map(spec_of.value_counts()) >= 2]
        if within.size >= 3:
            rows = _deletion_rows(within, "outlier sample", _critical_t(within.size, alpha / 2), {})
            # the most extreme sample of each specimen (all of them would be one row per sample)
            by_spec: dict[str, dict] = {}
            for r in rows:
                s = str(spec_of[r["covariate"]])
                if s not in by_spec or abs(r["deletion_t"]) > abs(by_spec[s]["deletion_t"]):
                    by_spec[s] = r
            out += list(by_spec.values())
    return out


def _deletion_rows(values: pd.Series, kind: str, t_crit: float, finding: dict) -> list[dict]:
    x = values.to_numpy(float)
    n = x.size
    rows = []
    for i, name in enumerate(values.index):
        rest = np.delete(x, i)
        sd = rest.std(ddof=1)
        scale = sd * np.sqrt(1.0 + 1.0 / rest.size)
        t = (x[i] - rest.mean()) / scale if scale > 0 else np.nan
        lp = min(0.0, st.log10_p_from_t(t, n - 2) + np.log10(n)) if np.isfinite(t) else np.nan
        ratio = float(np.exp(x[i] - np.median(rest)))
        needed = float(np.exp(t_crit * scale + rest.mean() - np.median(rest))) if np.isfinite(t_crit) else np.inf
        named = bool(finding.get("detected")) and str(finding.get("specimen")) == str(name)
        rows.append({"effect": "covariate", "covariate": str(name), "kind": kind,
                     "source": "curve levels with the condition effects removed", "n_levels": int(n),
                     "tested": True, "ratio": ratio, "deletion_t": float(t), "df": float(n - 2),
                     "p_value": 10 ** lp if np.isfinite(lp) else np.nan, "log10_p": lp,
                     "p_holm": float(finding["p_holm"]) if finding.get("specimen") == str(name)
                     and np.isfinite(finding.get("p_holm", np.nan)) else np.nan,
                     "ratio_needed": needed, "named": named,
                     "evidence": (f"{kind.split()[1]} {name}: {ratio:.2f}x the median of the other {n - 1} "
                                  f"(deletion t = {t:.2f} on {n - 2} df, Bonferroni p = "
                                  f"{10 ** lp if np.isfinite(lp) else np.nan:.2g}); this design names an outlier "
                                  f"from about {needed:.3g}x" if np.isfinite(needed) else "")})
    return rows


def covariates_table(ctx: DiagnosisContext, findings: Sequence[dict], alpha: float = st.ALPHA) -> list[dict]:
    """Every covariate entry (:func:`covariate_tests`) followed by the outlier rows (:func:`outlier_rows`)."""
    lv = curve_frame(ctx)
    if lv.empty or len(lv) < 4:
        return []
    return covariate_tests(lv) + outlier_rows(ctx, findings, alpha)
