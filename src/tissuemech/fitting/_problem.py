"""Plate targets, model predictions and the fit problem (:class:`NoiseModel`, :class:`FitProblem`) (part of
:mod:`tissuemech.fitting`, which re-exports every public name)."""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import lazy_loader
import numpy as np

from ..models.base import ConstitutiveModel, ParamSpec, ResponseNotSupported
from ..models.plate import (PlateHistories, creep_rim_strain, creep_rim_strains, forward_plate, forward_plate_batch,
                            oscillation_moduli, rabinowitsch_rim_stress)
from ._data import Curve

# loaded on first use: jobs that read fit records without fitting skip lmfit's import (~0.5 CPU s with
# scipy.stats and emcee; issue 17)
lmfit = lazy_loader.load("lmfit")

PLATE_TARGETS: tuple[str, ...] = ("thesis", "apparent_stress", "corrected_stress", "torque", "none")

#: responses fitted with log residuals (the data span decades)
LOG_RESPONSES: frozenset[str] = frozenset({"oscillation", "flow", "amplitude_sweep"})
#: a point of a log response is fitted by its log residual only where it stands this many of its noise SDs above
#: zero; nearer the noise (a loss modulus at the torque floor, a noisy point that came out negative) the log is not
#: the scale of its error (ln of a value within noise of 0 is unbounded), and its residual is linear, (f - y) / sd
LOG_RESIDUAL_MIN_SNR = 3.0

#: cycles simulated, cycles analysed and samples per cycle of an ``amplitude_sweep`` prediction: the first harmonic
#: of the last cycle; start-up transients of modes slower than a period are near-linear in time over it and the
#: harmonic analysis absorbs them (:func:`tissuemech.models.plate.first_harmonic_moduli`)
AMPLITUDE_SWEEP_CYCLES = (3, 1, 48)


def describes(model: ConstitutiveModel, response: str) -> bool:
    """Whether ``model`` can predict a curve of ``response`` (a shear history also from a purely elastic law; an
    amplitude sweep from any shear-history model, through its first harmonic)."""
    if response == "shear_history":
        return model.supports("shear_history") or model.supports("elastic_shear")
    if response == "amplitude_sweep":
        return model.supports("shear_history")
    return model.supports(response)


# ------------------------------------------------------------------------------------------------
# plate targets and predictions
# ------------------------------------------------------------------------------------------------
def plate_factor(radius_m: float) -> float:
    """Torque per unit apparent rim stress, pi R^3 / 2 [N m / Pa]."""
    return math.pi * radius_m ** 3 / 2.0


def target_observations(curve: Curve, target: str) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Observed values and SDs a fit compares predictions with, for a plate ``target``.

    Only shear histories (relaxation, CSR) and flow curves measured between plates depend on the target;
    oscillation (linear, where apparent stress is exact), creep, and homogeneous tests are unchanged.
    """
    obs = {k: np.asarray(v, float) for k, v in curve.observed.items()}
    sd = {k: np.asarray(v, float) for k, v in curve.sd.items()}
    if target not in PLATE_TARGETS:
        raise ValueError(f"unknown plate target {target!r}; use one of {PLATE_TARGETS}")
    plate_dependent = curve.response in ("shear_history", "flow") and curve.is_plate
    torque = obs.pop("torque", None)
    torque_sd = sd.pop("torque", None)
    if not plate_dependent:
        return obs, sd
    if target == "none":
        raise ValueError(f"{curve.label} was measured between plates: choose a plate target "
                         f"('thesis', 'apparent_stress', 'corrected_stress' or 'torque')")
    if target in ("thesis", "apparent_stress"):
        return obs, sd
    k = plate_factor(curve.radius_m)
    stress_sd = sd.pop("shear_stress", None)
    stress = obs.pop("shear_stress")
    if torque is None:
        torque = stress * k
    if torque_sd is None and stress_sd is not None:
        torque_sd = stress_sd * k
    if target == "torque":
        obs["torque"] = torque
        if torque_sd is not None:
            sd["torque"] = torque_sd
        return obs, sd
    # corrected_stress: needs a monotone sweep of the rim strain (CSR) or rate (flow)

    x = curve.obs_inputs("shear_strain") if curve.response == "shear_history" else curve.obs_inputs("shear_rate")
    if curve.test == "stress_relaxation" or np.any(np.diff(x) <= 0) or np.any(x <= 0):
        raise ValueError(f"corrected rim stress needs a monotone positive strain/rate sweep; {curve.label} has "
                         f"none (fit it with target='torque' or 'apparent_stress')")
    corrected = rabinowitsch_rim_stress(torque, x, curve.radius_m)
    obs["shear_stress"] = corrected
    if torque_sd is not None:
        sd["shear_stress"] = torque_sd / k * np.abs(corrected / np.where(stress != 0, stress, np.nan))
    return obs, sd


def _shear_history_stress(model: ConstitutiveModel, p, time_s, strain) -> np.ndarray:
    if model.supports("shear_history"):
        return model.shear_stress_history(p, time_s, strain)
    if model.supports("elastic_shear"):
        # a purely elastic (rate-independent) law: the stress follows the current strain
        return model.elastic_shear_stress(p, strain)
    raise ResponseNotSupported(f"model {model.name!r} ({model.family}) does not describe 'shear_history'")


def predict(model: ConstitutiveModel, p: Mapping[str, float], curve: Curve, target: str) -> dict[str, np.ndarray]:
    """Model prediction of every observable of ``curve`` (at its observation points) for a plate target."""
    r = curve.response
    idx = curve.obs_index
    if r == "shear_history":
        t = np.asarray(curve.inputs["time"], float)
        g = np.asarray(curve.inputs["shear_strain"], float)
        if curve.is_plate and target in ("torque", "apparent_stress"):

            full = forward_plate(model, p, t, g, curve.radius_m, curve.gap_m, target=target)
            key = "torque" if target == "torque" else "shear_stress"
            return {key: full if idx is None else full[idx]}
        full = _shear_history_stress(model, p, t, g)
        return {"shear_stress": full if idx is None else full[idx]}
    if r == "oscillation":
        gstar = model.complex_modulus(p, curve.obs_inputs("angular_frequency"))
        return {"storage_modulus": gstar.real, "loss_modulus": gstar.imag}
    if r == "flow":
        rate = curve.obs_inputs("shear_rate")
        if curve.is_plate and target in ("torque", "apparent_stress"):
            # steady flow: each radius sees the rate x r/R; torque by Gauss-Legendre on [0, R]
            xg, wg = np.polynomial.legendre.leggauss(12)
            u = 0.5 * (xg + 1.0)
            stress = model.steady_shear_stress(p, (rate[:, None] * u[None, :]).ravel()).reshape(rate.size, u.size)
            torque = 2.0 * math.pi * curve.radius_m ** 3 * (stress * u[None, :] ** 2) @ (0.5 * wg)
            if target == "torque":
                return {"torque": torque}
            return {"shear_stress": torque / plate_factor(curve.radius_m)}
        return {"shear_stress": model.steady_shear_stress(p, rate)}
    if r == "creep":
        t, stress = np.asarray(curve.inputs["time"], float), np.asarray(curve.inputs["shear_stress"], float)
        try:
            if curve.is_plate and target in ("torque", "apparent_stress") and getattr(model, "separable", False):
                # the torque-controlled plate: each radius its own history (equal to creep_strain for a linear law)
                full = creep_rim_strain(model, p, t, stress, curve.radius_m)
            else:
                full = model.creep_strain(p, t, stress)
        except ValueError:
            # the law cannot carry the imposed stress at any strain (a locking or softening law at these
            # parameters): no prediction, which a fit treats as a region to leave
            full = np.full(t.size, np.nan)
        return {"shear_strain": full if idx is None else full[idx]}
    if r == "amplitude_sweep":
        g1, g2 = amplitude_sweep_moduli(model, p, curve, curve.obs_inputs("shear_strain"))
        return {"storage_modulus": g1, "loss_modulus": g2}
    if r == "elastic_shear":
        return {"shear_stress": model.elastic_shear_stress(p, curve.obs_inputs("shear_strain"))}
    if r == "uniaxial":
        return {"nominal_stress": model.uniaxial_nominal_stress(p, curve.obs_inputs("stretch"))}
    raise ValueError(f"unknown response kind {r!r}")


def amplitude_sweep_moduli(model: ConstitutiveModel, p: Mapping[str, float], curve: Curve,
                           amplitudes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """G', G'' (Pa) of an amplitude sweep at rim-strain ``amplitudes``, at ``curve``'s frequency and on its plate,
    analysed as the instrument does (:data:`AMPLITUDE_SWEEP_CYCLES`; apparent stress on a plate, else the true
    stress); ``amplitudes`` may hold those of several sweeps sharing that frequency and plate."""
    n_cycles, n_analysed, per_cycle = AMPLITUDE_SWEEP_CYCLES
    return oscillation_moduli(model, p, curve.nominal["frequency_hz"], amplitudes, curve.radius_m, n_cycles=n_cycles,
                              n_analysed=n_analysed, points_per_cycle=per_cycle,
                              target="apparent_stress" if curve.is_plate else "corrected_stress")


def oscillation_window_bounds(model: ConstitutiveModel, curves: Sequence[Curve],
                              margin_decades: float = 1.0) -> dict[str, tuple[float, float]]:
    """Parameter bounds of ``model`` widened (never narrowed) to the window of oscillation ``curves``.

    The registry's bounds suit a rheometer window (relaxation times 1e-6..1e6 s, moduli <= 1e9 Pa); a TTS
    mastercurve spans far more decades of reduced angular frequency (the real TA LIMS series: 1e-3..1e11 rad/s).
    With omega in [w_lo, w_hi] rad/s and moduli up to G_max Pa (max of G', G''), ``margin_decades`` = m:

    * times (unit ``s``): [min(lower, 10^-m / w_hi), max(upper, 10^m / w_lo)];
    * moduli (unit ``Pa``): upper max(upper, 10^m G_max);
    * quasi-properties and viscosities (units ``Pa s^alpha``, ``Pa s``): lower min(lower, 10^-m G_min min(1, 1/w_hi)),
      upper max(upper, 10^m G_max max(1, 1/w_lo)) (c = |G*| / omega^alpha with 0 < alpha <= 1).

    Other parameters keep their bounds. Returns ``{name: (lower, upper)}`` for :class:`FitProblem` ``bounds``
    (empty when no curve is an oscillation).
    """
    osc = [c for c in curves if c.response == "oscillation"]
    if not osc:
        return {}
    w = np.concatenate([np.asarray(c.obs_inputs("angular_frequency"), float) for c in osc])
    g = np.concatenate([np.abs(np.asarray(v, float)) for c in osc for k, v in c.observed.items()
                        if k in ("storage_modulus", "loss_modulus")])
    w, g = w[np.isfinite(w) & (w > 0)], g[np.isfinite(g) & (g > 0)]
    if not (w.size and g.size):
        return {}
    m = 10.0 ** margin_decades
    w_lo, w_hi, g_lo, g_hi = float(w.min()), float(w.max()), float(g.min()), float(g.max())
    out: dict[str, tuple[float, float]] = {}
    for s in model.param_specs:
        unit = s.unit.replace(" ", "")
        if unit == "s":
            out[s.name] = (min(s.lower, 1.0 / (m * w_hi)), max(s.upper, m / w_lo))
        elif unit == "Pa":
            out[s.name] = (s.lower, max(s.upper, m * g_hi))
        elif unit.startswith("Pas"):
            out[s.name] = (min(s.lower, g_lo * min(1.0, 1.0 / w_hi) / m), max(s.upper, m * g_hi * max(1.0, 1.0 / w_lo)))
    return out


# ------------------------------------------------------------------------------------------------
# noise model and problem
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NoiseModel:
    """Floor of the per-point standard deviation: ``floor = sqrt(absolute^2 + (relative |y|)^2)``;
    the weight of a point is ``1 / max(sample SD, floor)``.

    ``absolute`` maps observable -> absolute floor in its unit; default: 0.03 Pa for stresses (the
    ~0.05 uN m torque resolution of a 10 mm plate), 0.05 uN m for torque, 1e-5 for strain.
    ``relative`` is the relative floor (1 % = instrument accuracy); ``relative_by`` maps an observable to its own
    relative floor (e.g. the within-curve scatter the diagnosis measures, :func:`tissuemech.diagnosis.noise.fit_noise`).
    """

    relative: float = 0.01
    absolute: Mapping[str, float] = field(default_factory=lambda: {
        "shear_stress": 0.03, "torque": 5e-8, "storage_modulus": 0.03, "loss_modulus": 0.03,
        "shear_strain": 1e-5, "nominal_stress": 0.03})
    relative_by: Mapping[str, float] = field(default_factory=dict)

    def sigma(self, name: str, y: np.ndarray, sd: np.ndarray | None) -> np.ndarray:
        y = np.asarray(y, float)
        relative = self.relative_by.get(name, self.relative)
        floor = np.sqrt(self.absolute.get(name, 0.0) ** 2 + (relative * np.abs(y)) ** 2)
        floor = np.where(floor > 0, floor, np.finfo(float).tiny)
        if sd is None:
            return floor
        sd = np.where(np.isfinite(sd), np.asarray(sd, float), 0.0)
        return np.maximum(sd, floor)


def _log_residual_scale(observed: np.ndarray, sd: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """``(tiny, log observed, relative SD)`` of a log-residual observable: the parts of
    :meth:`FitProblem.curve_terms`'s log residual that do not depend on the parameters."""
    tiny = 1e-12 * max(float(np.max(np.abs(observed))), 1e-300)
    return tiny, np.log(np.maximum(observed, tiny)), sd / np.maximum(np.abs(observed), tiny)


@dataclass
class FitProblem:
    """A model and the curves it is fitted to jointly.

    Attributes
    ----------
    model : the constitutive model (structure fixed)
    curves : curves fitted jointly; each must be describable by the model
    target : plate target (see module docstring); homogeneous curves ignore it
    model_key : registry key recorded with the fit
    noise : :class:`NoiseModel`
    fixed : parameter name -> value held fixed
    bounds : parameter name -> (lower, upper) overriding the model's bounds
    scope : label of the data scope (e.g. ``"csr+relaxation"``), recorded with the fit
    relaxation : strain-history treatment of the relaxation curves (:func:`relaxation_history`), recorded
    """

    model: ConstitutiveModel
    curves: list[Curve]
    target: str = "apparent_stress"
    model_key: str = ""
    noise: NoiseModel = field(default_factory=NoiseModel)
    fixed: Mapping[str, float] = field(default_factory=dict)
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    scope: str = ""
    relaxation: str = "measured"

    def __post_init__(self):
        if self.target not in PLATE_TARGETS:
            raise ValueError(f"unknown plate target {self.target!r}; use one of {PLATE_TARGETS}")
        if not self.curves:
            raise ValueError("a fit needs at least one curve")
        if not self.model_key:
            self.model_key = self.model.name
        self._parameter_names = [(s.name, self.internal_name(s), self.is_log(s)) for s in self.model.param_specs]
        self.observations = []
        self._near_noise = []
        self._log_observed = []
        for c in self.curves:
            if not describes(self.model, c.response):
                raise ValueError(f"model {self.model_key!r} ({self.model.family}) cannot describe {c.label} "
                                 f"(needs {c.response})")
            obs, sd = target_observations(c, self.target)
            sig = {k: self.noise.sigma(k, v, sd.get(k)) for k, v in obs.items()}
            self.observations.append((obs, sig))
            self._near_noise.append({k: ~(v > LOG_RESIDUAL_MIN_SNR * sig[k]) for k, v in obs.items()}
                                    if c.response in LOG_RESPONSES else {})
            self._log_observed.append({k: _log_residual_scale(v, sig[k]) for k, v in obs.items()}
                                      if c.response in LOG_RESPONSES else {})
        # the plate-torsion histories are predicted in one compiled pass when the model takes concatenated
        # histories: per curve, the Python layers around the kernels cost more than the kernels (issue 17)
        self._plate_curves = [i for i, c in enumerate(self.curves)
                              if c.response == "shear_history" and c.is_plate and self.target in ("torque", "apparent_stress")]
        self._plate_histories = None
        # the frequency sweeps in one call of the model's G*(omega): each call pays the model's Python layers and
        # its G0 (a compiled law's slope), whatever the number of frequencies
        self._oscillation_curves = [i for i, c in enumerate(self.curves) if c.response == "oscillation"]
        self._oscillation_frequencies = None
        if len(self._oscillation_curves) > 1:
            self._oscillation_frequencies = [self.curves[i].obs_inputs("angular_frequency")
                                             for i in self._oscillation_curves]
        # amplitude sweeps at one frequency on one plate in one call; QLV creep tests on plates in one inversion
        groups: dict[tuple, list[int]] = {}
        for i, c in enumerate(self.curves):
            if c.response == "amplitude_sweep" and np.isfinite(c.nominal.get("frequency_hz", np.nan)):
                key = (float(c.nominal["frequency_hz"]), float(c.radius_m) if c.is_plate else None, c.is_plate)
                groups.setdefault(key, []).append(i)
        self._amplitude_sweep_groups = [members for members in groups.values() if len(members) > 1]
        self._plate_creep_curves = [i for i, c in enumerate(self.curves)
                                    if c.response == "creep" and c.is_plate and getattr(self.model, "separable", False)
                                    and self.target in ("torque", "apparent_stress")]
        if len(self._plate_creep_curves) < 2:
            self._plate_creep_curves = []
        if self.model.concatenated_histories and len(self._plate_curves) > 1:
            self._plate_histories = PlateHistories.of(
                [(self.curves[i].inputs["time"], self.curves[i].inputs["shear_strain"], self.curves[i].radius_m)
                 for i in self._plate_curves])

    # --- parameters -------------------------------------------------------------------------------
    def spec(self, name: str) -> ParamSpec:
        return next(s for s in self.model.param_specs if s.name == name)

    def param_bounds(self, s: ParamSpec) -> tuple[float, float]:
        return tuple(self.bounds.get(s.name, (s.lower, s.upper)))

    def is_log(self, s: ParamSpec) -> bool:
        lo, _ = self.param_bounds(s)
        return bool(s.log and lo >= 0 and s.init > 0)

    def internal_name(self, s: ParamSpec) -> str:
        return f"log10_{s.name}" if self.is_log(s) else s.name

    def make_params(self, start: Mapping[str, float] | None = None) -> lmfit.Parameters:
        """lmfit parameters in the internal (log10 for moduli/times) space."""
        start = dict(start or {})
        pars = lmfit.Parameters()
        for s in self.model.param_specs:
            lo, hi = self.param_bounds(s)
            value = float(self.fixed.get(s.name, start.get(s.name, s.init)))
            vary = s.name not in self.fixed
            if self.is_log(s):
                tiny = 1e-300
                ilo = math.log10(lo) if lo > 0 else -np.inf
                ihi = math.log10(hi) if np.isfinite(hi) else np.inf
                iv = math.log10(max(value, tiny))
                iv = min(max(iv, ilo), ihi)
                pars.add(self.internal_name(s), value=iv, min=ilo, max=ihi, vary=vary)
            else:
                value = min(max(value, lo), hi)
                pars.add(s.name, value=value, min=lo, max=hi, vary=vary)
        return pars

    def natural(self, pars: lmfit.Parameters | Mapping[str, float]) -> dict[str, float]:
        """Natural-unit parameter values from internal ones."""
        out = {}
        for name, internal, log in self._parameter_names:
            v = pars[internal]
            v = float(v.value if isinstance(v, lmfit.Parameter) else v)
            out[name] = 10.0 ** v if log else v
        return out

    # --- residuals --------------------------------------------------------------------------------
    def curve_terms(self, p: Mapping[str, float]) -> list[dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]]:
        """Per curve and observable: (observed, predicted, weighted residual)."""
        batched = {}
        if self._plate_histories is not None:
            key = "torque" if self.target == "torque" else "shear_stress"
            full = forward_plate_batch(self.model, p, self._plate_histories, target=self.target)
            for i, f in zip(self._plate_curves, full):
                idx = self.curves[i].obs_index
                batched[i] = {key: f if idx is None else f[idx]}
        if self._oscillation_frequencies is not None:
            gstar = self.model.complex_modulus(p, np.concatenate(self._oscillation_frequencies))
            ends = np.cumsum([w.size for w in self._oscillation_frequencies])[:-1]
            for i, g in zip(self._oscillation_curves, np.split(gstar, ends)):
                batched[i] = {"storage_modulus": g.real, "loss_modulus": g.imag}
        for members in self._amplitude_sweep_groups:
            amplitudes = [self.curves[i].obs_inputs("shear_strain") for i in members]
            g1, g2 = amplitude_sweep_moduli(self.model, p, self.curves[members[0]], np.concatenate(amplitudes))
            ends = np.cumsum([a.size for a in amplitudes])[:-1]
            for i, a, b in zip(members, np.split(g1, ends), np.split(g2, ends)):
                batched[i] = {"storage_modulus": a, "loss_modulus": b}
        if self._plate_creep_curves:
            try:
                strains = creep_rim_strains(self.model, p, [(self.curves[i].inputs["time"],
                                                             self.curves[i].inputs["shear_stress"])
                                                            for i in self._plate_creep_curves])
            except ValueError:
                strains = None      # each test on its own: only those out of the law's reach lose their prediction
            for i, full in zip(self._plate_creep_curves, strains or ()):
                idx = self.curves[i].obs_index
                batched[i] = {"shear_strain": full if idx is None else full[idx]}
        out = []
        for i, (c, (obs, sig), near, logs) in enumerate(zip(self.curves, self.observations, self._near_noise,
                                                             self._log_observed)):
            pred = batched[i] if i in batched else predict(self.model, p, c, self.target)
            terms = {}
            for k, y in obs.items():
                f = np.asarray(pred[k], float)
                if c.response in LOG_RESPONSES:
                    # log residual with the relative SD as its scale; linear near the noise (LOG_RESIDUAL_MIN_SNR)
                    tiny, log_y, scale = logs[k]
                    w = (np.log(np.maximum(f, tiny)) - log_y) / scale
                    w = np.where(near[k], (f - y) / sig[k], w)
                else:
                    w = (f - y) / sig[k]
                terms[k] = (y, f, w)
            out.append(terms)
        return out

    def residual(self, pars: lmfit.Parameters) -> np.ndarray:
        p = self.natural(pars)
        res = np.concatenate([w for terms in self.curve_terms(p) for (_, _, w) in terms.values()])
        # a non-finite prediction is a region the optimizer must leave, not a crash
        return np.where(np.isfinite(res), res, 1e10)

    @property
    def n_obs(self) -> int:
        return int(sum(v.size for obs, _ in self.observations for v in obs.values()))
