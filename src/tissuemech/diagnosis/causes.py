"""The one registry of named causes: every id the diagnosis can name, its detector, its signature and what a lab
should do about it.

Each :class:`Cause` holds

``id``          the finding's ``effect``
``title``       the cause in plain words
``detector``    ``detect(ctx) -> finding`` (:class:`~tissuemech.diagnosis.findings.DiagnosisContext`; the finding
                contract is :mod:`.catalogue`'s); None for a cause another engine tests (the multi-mode
                ``tension_compression_asymmetry``, :mod:`.homogeneous`)
``distorts``    test kinds whose curves the cause bends (``"*"``: it scales whole curves and bends none)
``explains``    covariates whose structure across curves the cause accounts for
``remedy``      ``finding -> sentence``: what to do when the cause is named, from the finding's own numbers
``to_test``     what data would test the cause where these data cannot

:data:`CAUSE_IDS` (ordered: the parallel-plate catalogue :data:`CATALOGUE_IDS`, then the causes met on real data)
and :data:`DETECTORS` are what :func:`tissuemech.diagnosis.report.diagnose` runs; :func:`explains` is the
attribution rule of unnamed structure (:mod:`.decision`); :func:`what_to_do` the plain-words line every finding,
every unexplained structure and the ``baseline_inadequate`` entry carry in ``diagnosis.json``.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .findings import DiagnosisContext
from .inertia import (EFFECT as INERTIA_POINTS_ID, RINGING as RINGING_ID, YIELD as YIELD_ID,
                      detect_inertia_dominated_points, detect_inertial_ringing, detect_yield_or_slip)
from .levels import detect_elapsed_time_drift, detect_outlier_specimen, detect_preconditioning
from .oscillation import detect_amplitude_softening, detect_instrument_inertia
from .temperature import EFFECT as TEMPERATURE_ID
from .temperature import detect_temperature_dependence
from .time_domain import (detect_finite_rise_time, detect_nonseparable_relaxation, detect_rim_stress_nonlinearity,
                          detect_torque_offset, detect_unidentified_i2_dependence, detect_wall_slip)


def _fmt(x: float, unit: str = "", digits: int = 2) -> str:
    """A number in plain words: 2 significant digits, '?' when not finite."""
    if not _finite(x):
        return "?"
    return f"{x:.{digits}g}{(' ' + unit) if unit else ''}"


def _finite(x) -> bool:
    try:
        return x is not None and bool(np.isfinite(float(x)))
    except (TypeError, ValueError):
        return False


def _param(finding: dict, name: str) -> float:
    fix = finding.get("fix") or {}
    v = (fix.get("parameters") or {}).get(name, finding.get(name, np.nan))
    try:
        return float(v)
    except (TypeError, ValueError):
        return np.nan


@dataclass(frozen=True)
class Cause:
    id: str
    title: str
    detector: Callable[[DiagnosisContext], dict] | None
    distorts: tuple[str, ...]
    explains: tuple[str, ...]
    remedy: Callable[[dict], str]
    to_test: str


def _nonseparable(f):
    return ("The relaxation depends on the strain (quasi-linear separability fails): use the nonseparable "
            "(Pipkin-Rogers) card in the simulator"
            + (f" ({f['fix']['model']})" if (f.get("fix") or {}).get("model") else "")
            + "; a QLV card is valid only near the strains it was fitted at.")


def _rim(f):
    return (f"Fit through the torque (plate forward model) or use the Rabinowitsch-corrected rim stress "
            f"(n = {_fmt(_param(f, 'n'))}), never the reported 2M/(pi R^3) as if it were the rim stress.")


def _slip(f):
    return (f"Re-run the ramps with roughened or serrated plates and at a second gap (slip depends on the gap, a "
            f"material does not); until then exclude ramp points above {_fmt(f.get('effect_size'), 'Pa')}.")


def _drift(f):
    per = "h" if f.get("effect_size_unit") == "1/h" else "test"
    return (f"The sample changes by {_fmt(100 * _param(f, 'effect_size'), '%')} per {per} during the session: "
            f"keep it hydrated (solvent trap, PBS), shorten the session or repeat a reference test at its start and "
            f"end; meanwhile correct the curves with the fitted trend.")


def _precond(f):
    return ("Precondition each sample (a few loading cycles) before the recorded tests, or discard each sample's "
            f"first test (it is {_fmt(100 * _param(f, 'effect_size'), '%')} stiffer than the repeats).")


def _inertia(f):
    return (f"Re-calibrate the instrument inertia or correct G' by dI omega^2 2h/(pi R^4) with the fitted "
            f"dI = {_fmt(f.get('effect_size'), 'kg m^2')}; the error grows as h/R^4, so a larger plate or a smaller "
            f"gap reduces it.")


def _offset(f):
    return (f"Zero the torque transducer before each test, or subtract the offset M0 = "
            f"{_fmt(f.get('effect_size'), 'uN m')} (a nuisance parameter in the fit); small-strain relaxations are "
            f"the most affected.")


def _outlier(f):
    name = f.get("specimen") or "the outlier"
    return (f"Check specimen {name} (dissection, handling, time post mortem, loading); report the population "
            f"parameters with and without it (a hierarchical or median fit).")


def _softening(f):
    onset = _param(f, "onset_strain")
    return ((f"Keep linear-viscoelastic tests below {_fmt(100 * onset, '%')} strain amplitude (G' has fallen 5 % "
             f"there); " if np.isfinite(onset) else "Keep linear-viscoelastic tests in the amplitude plateau; ")
            + "use an amplitude-softening (Kraus) description for larger amplitudes.")


def _rise(f):
    return (f"Fit the relaxations through the measured strain ramp (ramp-aware), not as ideal steps, or discard "
            f"the first {_fmt(10 * _param(f, 'effect_size'), 's')} (10 rise times) of each hold.")


def _i2(f):
    if f.get("identifiable"):
        return (f"Use a law with an I2 term (Mooney-Rivlin type, C01 = {_fmt(f.get('effect_size'), 'Pa')}) "
                f"calibrated on all the loading modes together.")
    return ("Add normal-force or compression/tension data: shear alone cannot split C10 from C01, so the card's "
            "I2 term is not identified.")


def _temperature(f):
    wlf = f.get("wlf") or {}
    return ("Control the sample temperature, or use the time-temperature superposition card"
            + (f" (WLF C1 = {_fmt(wlf.get('c1'))}, C2 = {_fmt(wlf.get('c2_k'), 'K')})" if wlf.get("success") else "")
            + " for the temperatures of use.")


def _inertia_points(f):
    pts = f.get("points") or []
    w = min((p["angular_frequency_rad_s"] for p in pts), default=np.nan)
    return (f"Exclude the oscillation points above {_fmt(w, 'rad/s')} (raw phase beyond 90 deg: the instrument's "
            f"inertia dominates there); to measure higher frequencies use a larger plate or a stiffer sample.")


def _ringing(f):
    return (f"Exclude the first {_fmt(3 * _param(f, 'decay_s'), 's')} after each step from the fits (the motor and "
            f"sample ring with a period of {_fmt(_param(f, 'period_s'), 's')}), or use a slower step.")


def _yield(f):
    g = _param(f, "yield_strain")
    return ((f"Keep the strain amplitude below {_fmt(100 * g, '%')}: above it the sample yields or slips "
             if np.isfinite(g) else "Keep the strain amplitude below where the sample yields or slips; ")
            + "to tell the two apart, repeat with roughened plates or at a second gap.")


def _asymmetry(f):
    return ("Calibrate on shear together with compression and tension, with an I2 term or a negative-exponent "
            "Ogden law: a law fitted to shear alone mispredicts the other modes.")


CAUSES: dict[str, Cause] = {c.id: c for c in (
    Cause("nonseparable_relaxation", "strain-dependent (non-separable) relaxation", detect_nonseparable_relaxation,
          ("constant_shear_rate", "stress_relaxation", "creep_recovery", "frequency_sweep", "amplitude_sweep"),
          ("strain_x_log_rate", "strain_sq_x_log_rate", "log_rate"), _nonseparable,
          "ramps at >= 2 rates or relaxations at >= 2 strains"),
    Cause("rim_stress_nonlinearity", "reported plate stress taken as the rim stress of a nonlinear material",
          detect_rim_stress_nonlinearity, ("constant_shear_rate", "stress_relaxation", "creep_recovery"),
          ("strain",), _rim, "relaxations at >= 3 strains on >= 3 samples, or >= 3 ramps"),
    Cause("wall_slip", "wall slip above a critical stress", detect_wall_slip,
          ("constant_shear_rate", "creep_recovery"), ("inverse_gap", "channel_gap"), _slip,
          ">= 4 constant-shear-rate ramps, ideally at two gaps"),
    Cause("elapsed_time_drift", "drift of the sample or instrument during the session", detect_elapsed_time_drift,
          ("*",), ("elapsed_time", "test_order"), _drift,
          "started_at or total_time and >= 3 tests per sample (or samples measured over the session)"),
    Cause("preconditioning", "first load stiffer than the repeats (preconditioning)", detect_preconditioning,
          ("*",), ("first_load", "test_order", "elapsed_time"), _precond,
          "the measuring order (order, started_at or total_time) and a repeat of the first test"),
    Cause("instrument_inertia", "instrument inertia correction error in frequency sweeps", detect_instrument_inertia,
          ("frequency_sweep",), ("frequency_sq", "channel_raw_phase"), _inertia,
          ">= 3 frequency sweeps with gap and plate radius"),
    Cause("torque_offset", "torque offset of the transducer", detect_torque_offset,
          ("constant_shear_rate", "stress_relaxation", "creep_recovery"), ("predicted_abs",), _offset,
          ">= 4 small-strain relaxations or ramps"),
    Cause("outlier_specimen", "one specimen unlike the others", detect_outlier_specimen, ("*",), (), _outlier,
          ">= 3 specimens sharing a test condition"),
    Cause("amplitude_softening", "G' falling with strain amplitude (amplitude softening)",
          detect_amplitude_softening, ("amplitude_sweep",), (), _softening,
          "an amplitude sweep above the torque floor"),
    Cause("finite_rise_time", "relaxation ramp analysed as an ideal step", detect_finite_rise_time,
          ("stress_relaxation", "frequency_sweep"), ("log_time",), _rise,
          ">= 3 relaxations with their ramp recorded, analysed as steps"),
    Cause("unidentified_i2_dependence", "I2 (C01) dependence that shear alone cannot see",
          detect_unidentified_i2_dependence, (), ("channel_normal_force",), _i2,
          "normal force above 10 % strain, or compression and tension tests"),
    Cause(TEMPERATURE_ID, "temperature dependence", detect_temperature_dependence,
          ("constant_shear_rate", "stress_relaxation", "creep_recovery", "frequency_sweep", "amplitude_sweep"),
          ("channel_temperature", "covariate_temperature_c", "temperature_c"), _temperature,
          "runs at >= 3 distinct temperatures"),
    Cause(INERTIA_POINTS_ID, "oscillation points dominated by the instrument's inertia",
          detect_inertia_dominated_points, ("frequency_sweep", "amplitude_sweep"),
          ("frequency_sq", "channel_raw_phase"), _inertia_points, "a raw phase channel in the oscillation exports"),
    Cause(RINGING_ID, "inertial ringing after a strain or torque step", detect_inertial_ringing,
          ("stress_relaxation", "creep_recovery"), (), _ringing,
          ">= 3 relaxation or creep curves sampled densely after the step"),
    Cause(YIELD_ID, "large-strain yield or wall slip in amplitude sweeps", detect_yield_or_slip,
          ("amplitude_sweep",), (), _yield, "an amplitude sweep with a raw phase channel or G' and G''"),
    Cause("tension_compression_asymmetry", "tension-compression asymmetry of a shear-calibrated law", None,
          (), (), _asymmetry, "simple shear, compression and tension of the same tissue"),
)}

#: the parallel-plate catalogue of science.md section 3, in its order (the multi-mode engine reports these too)
CATALOGUE_IDS: tuple[str, ...] = (
    "nonseparable_relaxation", "rim_stress_nonlinearity", "wall_slip", "elapsed_time_drift",
    "preconditioning", "instrument_inertia", "torque_offset", "outlier_specimen", "amplitude_softening",
    "finite_rise_time", "unidentified_i2_dependence",
)
#: every cause the parallel-plate diagnosis tests, in the order it reports untested ones
CAUSE_IDS: tuple[str, ...] = tuple(k for k, c in CAUSES.items() if c.detector is not None)
DETECTORS: dict[str, Callable[[DiagnosisContext], dict]] = {k: CAUSES[k].detector for k in CAUSE_IDS}
#: test kinds each cause bends, and the covariates whose across-curve structure it explains
DISTORTS: dict[str, tuple[str, ...]] = {k: c.distorts for k, c in CAUSES.items()}
EXPLAINS: dict[str, tuple[str, ...]] = {k: c.explains for k, c in CAUSES.items()}
assert CAUSE_IDS[:len(CATALOGUE_IDS)] == CATALOGUE_IDS


def explains(effect: str, test: str, covariate: str, level: str,
             confounded: Sequence[Sequence[str]] = ()) -> bool:
    """Whether a named ``effect`` accounts for generic structure in ``covariate`` of ``test`` residuals.

    Curve-level (``across curves``) structure is explained only through the covariates of the cause's own
    signature (:data:`EXPLAINS`) -- a detected drift, preconditioning or outlier does *not* explain every
    across-curve covariate (a significant temperature channel stays unexplained unless a temperature cause
    is named) -- or through a covariate that is confounded with one of them in this design
    (``confounded``: sets of covariate names that the design cannot separate,
    :func:`tissuemech.diagnosis.generic.confounded_covariates`). Within-curve structure is explained by the
    causes that distort the shape of that test's curves.
    """
    own = EXPLAINS.get(effect, ())
    if covariate in own:
        return True
    if level == "within curves":
        return test in DISTORTS.get(effect, ())  # whole-curve causes ("*": drift, first load, outlier) bend no curve
    return any(covariate in group and any(c in own for c in group) for group in confounded)


def what_to_do(finding: dict) -> str:
    """The plain-words next step of a finding (module docstring), from its own numbers where it names any.

    Named cause: its remedy. Significant and relevant but not named: what the diagnosis could not do and the
    remedy to check by hand. Tested and not significant: nothing. Not testable: the data that would test it.
    ``baseline_inadequate`` and ``unexplained_structure`` entries get their own sentences.
    """
    effect = finding.get("effect", "")
    if effect == "baseline_inadequate":
        return ("None of the fitted models describes these data well enough to blame an effect: look at the "
                "ranking and widen the model family (more relaxation times, a nonlinear law) before reading causes.")
    if effect == "unexplained_structure":
        cands = finding.get("candidates") or []
        test = str(finding.get("test", ""))
        where = "across the tests" if test in ("every test", "") else f"in the {test.replace('_', ' ')} tests"
        return (f"Check the lab notes for what changed along {finding.get('covariate', 'this covariate')} {where}"
                + (f"; causes whose signature involves it: {', '.join(cands)}" if cands else "")
                + (f"; a design that would separate it: {finding['separating_design']}"
                   if finding.get("separating_design") else "") + ".")
    cause = CAUSES.get(effect)
    if cause is None:
        return ""
    if finding.get("detected"):
        return cause.remedy(finding)
    if not finding.get("tested"):
        return f"Not testable with these data; it needs {cause.to_test}."
    if finding.get("significant") and finding.get("practical"):
        fix = finding.get("fix") or {}
        why = ("its fix was not scored on held-out data" if not fix or not _finite(fix.get("after"))
               else "its fix did not improve held-out predictions beyond the noise")
        return f"Not named ({why}); check by hand: {cause.remedy(finding)}"
    return "Nothing to do: these data show no relevant sign of it."
