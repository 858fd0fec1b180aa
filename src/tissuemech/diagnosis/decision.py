"""The decision rule: which tested cause is named, for the parallel-plate and the multi-mode diagnosis alike.

:data:`DECISION_RULE` is the sentence both engines write into ``diagnosis.json``; :func:`apply_rule` applies it to
the findings of the detectors and to the scan for unnamed structure (Holm at alpha/2 within each, the margin of
:func:`fix_margin` on each scored fix); :func:`unexplained_structure` keeps the significant structure that no named
cause accounts for (:func:`tissuemech.diagnosis.causes.explains`); :func:`ordered` puts the named causes first.
Every finding leaves with ``p_holm``, ``significant``, ``detected``, a ``decision`` (why it is or is not named) and
the plain-words ``what_to_do`` of the registry (:func:`tissuemech.diagnosis.causes.what_to_do`).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy

from .. import stats as st
from .causes import CAUSE_IDS, explains, what_to_do
from .findings import describe_fix, describe_log_change, separating_design

DECISION_RULE = (
    "A cause is named (detected) only when (1) its test is significant after Holm at the family-wise alpha (alpha/2 "
    "is shared by the named causes and alpha/2 by the scan for unnamed structure; p_holm is reported on the alpha "
    "scale), (2) its effect size passes the cause's practical threshold, and (3) its fix, scored on held-out data "
    "with the baseline refitted or re-estimated inside every fold, lowers the held-out error (before - after, in "
    "the fix's relative metric) by more than the noise-calibrated margin z_(1-alpha) * eps / sqrt(2 n), where eps "
    "is the typical relative noise SD of the measured responses (noise_model.relative_level) and n the held-out "
    "values the fix's metric pools (the number of curves for curve-level fixes that do not report it): the "
    "standard error of an RMS of n noise values of SD eps is eps / sqrt(2 n). A cause that passes (1) and (2) but "
    "whose fix was not scored is listed in significant_fix_not_evaluated and not named; a fix that was scored "
    "and does not beat the margin does not name its cause either. An inadequate baseline (parameters at a bound, "
    "no covariance, no convergence, or the typical point off by more than a factor 2) is the first finding, "
    "baseline_inadequate; the next adequate model is diagnosed, and when none is adequate no cause is named "
    "except a baseline-free one (baseline_free: its test and fix do not use the baseline's predictions, e.g. "
    "temperature_dependence by time-temperature superposition on held-out temperatures, "
    "inertia_dominated_points, yield_or_slip, amplitude_softening read from the sweep itself). The same rule "
    "holds for the multi-mode diagnosis of homogeneous specimens (simple shear with compression and tension), "
    "whose fixes are scored by leaving one loading mode out.")


def fix_margin(fix: dict | None, eps: float, alpha: float = st.ALPHA, n_default: float = np.nan) -> float:
    """Noise-calibrated margin [metric units, relative] that a fix's held-out improvement must exceed.

    ``z_(1-alpha) eps / sqrt(2 n)``: eps the relative noise SD of the data, n the held-out values the fix's
    metric pools (``fix["parameters"]["n_held_out_points"]``), else ``n_default`` (the number of curves: a
    curve-level fix holds out about one level per curve, and the per-point eps overstates a level's noise,
    so this is conservative). NaN without a noise estimate or a count (the fix is then not credited).
    """
    n = (fix or {}).get("parameters", {}).get("n_held_out_points", np.nan)
    n = float(n) if n is not None and np.isfinite(n) and n > 0 else float(n_default)
    if not (np.isfinite(eps) and np.isfinite(n) and n > 0):
        return np.nan
    return float(scipy.stats.norm.ppf(1.0 - alpha) * eps / np.sqrt(2.0 * n))


def _finite(x) -> bool:
    try:
        return x is not None and bool(np.isfinite(float(x)))
    except (TypeError, ValueError):
        return False


def apply_rule(findings: Sequence[dict], structure: Sequence[dict], alpha: float, eps: float,
               n_default: float = np.nan, usable: bool = True) -> list[dict]:
    """Apply :data:`DECISION_RULE` in place to the findings of the detectors and to the structure tests.

    ``eps``: the relative noise level of the data (:func:`tissuemech.noise.relative_noise_level`);
    ``n_default``: the count of held-out values of a fix that does not report one (the number of curves);
    ``usable``: False when no adequate baseline is left (only ``baseline_free`` causes may then be named).
    Sets ``p_holm``, ``significant``, ``detected``, ``decision`` and ``what_to_do`` on every finding (and
    ``margin``/``improvement``/``beats_margin`` on every scored fix), ``p_holm``/``significant`` on every structure
    test. Returns the ``significant_fix_not_evaluated`` entries.
    """
    tested = [f for f in findings if f.get("tested") and _finite(f.get("p_value"))]
    reject_c, adjusted_c = st.holm([f["p_value"] for f in tested], alpha / 2)
    reject_g, adjusted_g = st.holm([g["p_value"] for g in structure], alpha / 2)
    not_evaluated = []
    for f, r, a in zip(tested, reject_c, adjusted_c):
        fix = f.get("fix") or {}
        scored = bool(fix) and _finite(fix.get("before")) and _finite(fix.get("after"))
        if fix:
            fix.setdefault("summary", describe_fix(fix.get("before"), fix.get("after")))
        if scored:
            margin = fix_margin(fix, eps, alpha, n_default)
            fix["margin"] = margin
            fix["improvement"] = float(fix["before"] - fix["after"])
            fix["beats_margin"] = bool(np.isfinite(margin) and fix["before"] - fix["after"] > margin)
        f["p_holm"] = float(min(2 * a, 1.0))
        f["significant"] = bool(r)
        admissible = usable or bool(f.get("baseline_free"))
        relevant = bool(r and f.get("practical"))
        f["detected"] = bool(admissible and relevant and scored and fix["beats_margin"])
        if f["detected"]:
            f["decision"] = "named: significant, relevant, and its fix beats the noise margin on held-out data"
        elif not r:
            f["decision"] = "not named: not significant after Holm"
        elif not f.get("practical"):
            f["decision"] = "not named: significant, but below the cause's practical threshold"
        elif not admissible:
            f["decision"] = "not named: no adequate baseline to blame it on"
        elif not scored:
            f["decision"] = "not named: significant and relevant, but its fix was not scored on held-out data"
        else:
            f["decision"] = "not named: its fix does not beat the noise margin on held-out data"
        if admissible and relevant and not scored:
            not_evaluated.append({"effect": f["effect"], "p_holm": f["p_holm"], "effect_size": f.get("effect_size"),
                                  "effect_size_unit": f.get("effect_size_unit", ""), "evidence": f["evidence"]})
    for f in findings:
        f.setdefault("detected", False)
        f.setdefault("p_holm", np.nan)
        f.setdefault("significant", False)
        f.setdefault("decision", "not testable with these data" if not f.get("tested") else
                     "not named: no p-value")
        f["what_to_do"] = what_to_do(f)
    for e in not_evaluated:
        e["what_to_do"] = next(f["what_to_do"] for f in findings if f["effect"] == e["effect"])
    for g, r, a in zip(structure, reject_g, adjusted_g):
        g["p_holm"] = float(min(2 * a, 1.0))
        g["significant"] = bool(r)
    return not_evaluated


def ordered(findings: Sequence[dict]) -> list[dict]:
    """The named causes first (strongest first), then the others by p-value (untested last)."""
    detected = sorted([f for f in findings if f["detected"]], key=lambda f: f["log10_p"])
    rest = sorted([f for f in findings if not f["detected"]],
                  key=lambda f: f["log10_p"] if _finite(f.get("log10_p")) else 1.0)
    return detected + rest


def unexplained_structure(structure: Sequence[dict], findings: Sequence[dict], model: str,
                          confounded: Sequence[Sequence[str]] = (), fitted: Sequence[str] = ()) -> list[dict]:
    """Significant, practically relevant structure tests that no named cause explains, as ``diagnosis.json``
    ``unexplained`` entries (``effect`` ``unexplained_structure``, the test's numbers, ``candidates``: causes whose
    signature involves that covariate, ``evidence``, ``separating_design`` for structure across curves,
    ``what_to_do``), strongest first.

    A test the baseline did not fit (``fitted``: the kinds it was fitted to) is a cross-test prediction: a named
    cause that distorts the fitted tests distorts the fitted parameters and therefore that prediction too."""
    detected = [f for f in findings if f.get("detected")]
    fitted = set(fitted)

    def explained(g):
        if any(explains(f["effect"], g["test"], g["covariate"], g["level"], confounded) for f in detected):
            return True
        return bool(fitted) and g["test"] not in fitted and any(
            explains(f["effect"], t, g["covariate"], g["level"]) for f in detected for t in fitted)

    out = []
    for g in structure:
        if not (g.get("significant") and g.get("practical")) or explained(g):
            continue
        candidates = [e for e in CAUSE_IDS if explains(e, g["test"], g["covariate"], g["level"])]
        what = ("the curve levels (every test)" if g["test"] == "every test" else
                f"{g['test']} {g['quantity']} residuals")
        entry = {"effect": "unexplained_structure", **{k: g[k] for k in (
            "covariate", "test", "quantity", "level", "statistic", "p_value", "p_holm", "effect_size", "n_curves")
            if k in g}, "candidates": candidates,
            "evidence": (f"{what} of {model} {describe_log_change(g['effect_size'])} "
                         f"over the range of {g['covariate']} ({g['level']}"
                         + (f", {g['variation']}" if g.get("variation") else "")
                         + f", t/F = {g['statistic']:.2f}, Holm p = {g['p_holm']:.2g}); no named cause explains it"
                         + (f" (causes whose signature involves it: {', '.join(candidates)})" if candidates else "")
                         + ".")}
        if g["level"] == "across curves":
            entry["separating_design"] = separating_design(g["covariate"])
        entry["what_to_do"] = what_to_do(entry)
        out.append(entry)
    return sorted(out, key=lambda u: u["p_value"])


def top_finding(result: dict) -> str | None:
    """Id of the strongest named cause (None when nothing is named)."""
    det = [f for f in result["findings"] if f["detected"]]
    return det[0]["effect"] if det else None
