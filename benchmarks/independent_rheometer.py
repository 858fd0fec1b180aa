"""An independently written parallel-plate rheometer for calibrating the diagnosis (issue #12 item 7).

This generator shares no code with :mod:`tissuemech.synth`, :mod:`tissuemech.models` or
:mod:`tissuemech.fitting`: the physics below is written from the textbook relations with numpy/scipy, so the
truth is one the detectors were not written for. Its only contact with the package is the public run
contract :func:`tissuemech.canonical.make_run_dataset` (canonical SI variables and run attributes).

Physics
-------
* **Instantaneous law in simple shear** (incompressible, isotropic; shear stress tau_e(gamma) [Pa]):
  neo-Hookean ``mu*gamma``; Mooney-Rivlin ``2*(C10 + C01)*gamma``; one-term Ogden
  ``2*mu/alpha * (l1**alpha - l2**alpha)/(l1 + l2)`` with ``l1 = gamma/2 + sqrt(1 + gamma**2/4)``, ``l2 = 1/l1``
  (sigma_12 = (l1 W_l1 - l2 W_l2)/(l1 + l2)); Gent ``mu*gamma/(1 - gamma**2/Jm)``; exponential
  (Demiray/Fung) ``mu*gamma*exp(b*gamma**2)``. Every law is normalised to the small-strain shear modulus mu.
* **Relaxation** (QLV, tau(t) = int g(t - s) d tau_e(gamma(s))): reduced relaxation function either a
  Prony series ``g_inf + sum g_i exp(-t/tau_i)`` (1-5 modes, tau_i from 1 ms to 1000 s) or a fractional
  Zener/fractional Maxwell function ``g_inf + (1 - g_inf) E_alpha(-(t/tau)**alpha)``. The Mittag-Leffler
  function of a negative argument is the completely monotone integral
  ``E_alpha(-x**alpha) = int_0^inf K_alpha(r) exp(-r x) dr``,
  ``K_alpha(r) = sin(alpha*pi)/pi * r**(alpha-1) / (r**(2 alpha) + 2 r**alpha cos(alpha*pi) + 1)``
  (the spectral representation of Gorenflo & Mainardi 1997, "Fractional calculus: integral and differential
  equations of fractional order"; also Mainardi 2010, *Fractional calculus and waves in linear
  viscoelasticity*, ch. 3), evaluated by the trapezoid rule in log r (:func:`ml_spectrum`); the result
  is a dense continuous Prony spectrum, so every kernel runs through the same exact recursive update
  (piecewise-linear tau_e in time, :func:`qlv_stress`).
* **Plate**: the rim strain is ``theta*R/h``; the strain at radius r is ``gamma_R * r/R``; the torque is
  ``M = 2*pi * int_0^R tau(r) r**2 dr`` by Gauss-Legendre quadrature (:func:`plate_torque`); the reported
  stress is ``2*M/(pi*R**3)``. Oscillation moduli are the first harmonic of the steady QLV response: the
  kernel's ``G*(omega)/G0`` (closed form for Prony; ``G_inf + (G0 - G_inf)(i w tau)^a/(1 + (i w tau)^a)`` for
  fractional Zener) times the first Fourier sine coefficient of the elastic stress ``sigma_e(gamma_0 r/R sin)``
  integrated over the plate (:func:`first_harmonic_factor`; exact for QLV, whose convolution filters each
  harmonic of ``sigma_e`` alone), as the instrument reports it: first-harmonic torque over ``gamma_0 pi R^3/2``.
  A stiffening law therefore stiffens the amplitude sweep as it stiffens the ramps.
* **Noise**: torque noise ``sqrt((s_rel*M)**2 + floor**2)`` with s_rel 0.2-3 % and a torque floor drawn per
  dataset; moduli noise from the complex torque amplitude.

Effects (``effects={name: magnitude}``, magnitude 1 = the "1x" size written in :data:`EFFECT_SIZES`)
--------------------------------------------------------------------------------------------------
``elapsed_time_drift`` (moduli x (1 + k * elapsed_h)), ``torque_offset`` (a constant torque added to ramps
and relaxations), ``wall_slip`` (above a critical strain the sample sees only h/(h + 2b) of the imposed
strain increment, slip length b per wall), ``outlier_specimen`` (one specimen's moduli x factor),
``preconditioning`` (the first test of each sample, whatever it is, is stiffer), ``nonseparable_relaxation``
(relaxing weights grow with the current strain), ``temperature_dependence`` (samples run at several
temperatures; time scales shifted by WLF), ``instrument_inertia`` (a motor-inertia calibration error,
frequency sweeps extended to high frequency, raw phase channel always written).

Entry points: :func:`generate` ``(seed, effects=None) -> (runs, truth)`` (canonical runs, the runs-only studies of
issue 12) and :func:`write_dataset_folder` ``(seed, folder, effects=None) -> truth`` (a folder as a user drops it in
``raw/``, for the pipeline-path calibration of issue 32).

Dataset folders
---------------
:func:`write_dataset_folder` draws the truth as :func:`generate` does (plate diameters 8-50 mm) and a design
(:func:`draw_folder_design`) that varies every choice a detector could key on:

* **test subsets** (:data:`FAMILIES`): any subset of the five kinds; sweeps, ramps and creep without relaxation;
  sweeps and ramps only; creep only; creep and relaxations only;
* **creep-recovery** (stress-controlled, :func:`creep_response`): the motor torque ramped to the stress an operator
  would set (2 digits, the truth's nominal material taken to a target strain of 1-15 %), held 30-300 s and removed;
  at every time the torque balances the plate torque of the QLV material (exact per-step QLV update, Brent's method
  per step) plus, with creep ringing, the rotor's ``I theta''`` (average-acceleration Newmark rule);
* **specimens and sequence**: 1 specimen (20 %) or 2-8, 1-3 samples each, measured in blocks (all samples of a
  specimen in a row) or interleaved (round robin); the tests of a sample in a random order per sample or one fixed
  order for all; one to three days (``started_at`` resets to each day's start, days may be apart);
* **instrument and files** (:data:`FORMATS`): RheoCompass CSV (UTF-16 LE, tab, CRLF, decimal comma, simple header),
  RheoCompass text (UTF-8, decimal point, project header), TA TRIOS text (one file per sample, one ``[step]`` per
  test, selected by the sheet's ``block``); torque in N·m, mN·m or µN·m; frequency in Hz or rad/s; strain in % or 1;
  the plate radius stated in ``samples.csv``, in ``dataset.yaml`` or by the export (``Measuring System: PP25``,
  TRIOS ``Geometry name``/``Diameter``/``Gap``; the gap then from the export's gap channel or header); a
  normal-force channel in half the datasets (a 0.02-0.5 N preload per sample), a raw-phase channel in 70 %;
* **truth** written beside the folder (``<folder>.truth.json``), never inside what the pipeline reads.

Effects of the folders (:data:`FOLDER_EFFECT_SIZES`): those above, plus ``creep_ringing`` (the motor inertia in
the creep torque balance; a null creep is the inertia-free response), ``temperature_spread`` (each sample at
T + U(-1, 1) x 4 K in its logged temperature channel only, WLF time shift), ``normal_force_preload`` (each sample's
moduli x (F / 0.1 N)^0.15 with F its logged preload). The elapsed-time drift runs on each day's session clock.
A power dataset's design is drawn among those that hold a test showing its effect (:data:`SHOWN_BY`,
:data:`MIN_SAMPLES`; an outlier specimen among 4-6); every random draw is made whatever the effects, so one seed
gives the same design and noise at every magnitude.
"""
from __future__ import annotations

import datetime as dt
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.special import gamma as gamma_fn

from tissuemech.canonical import atomic_write, make_run_dataset, write_json, write_text

LAWS = ("neo_hookean", "mooney_rivlin", "ogden1", "gent", "exponential")
TESTS = ("amplitude_sweep", "frequency_sweep", "constant_shear_rate", "stress_relaxation")
#: the 1x size of every effect (magnitude scales the departure from "no effect")
EFFECT_SIZES = {
    "elapsed_time_drift": {"per_hour": 0.10},          # +10 %/h of the moduli
    "torque_offset": {"fraction": 0.05},              # 5 % of the median ramp/relaxation torque
    "wall_slip": {"slip_length_m": 0.25e-3, "critical_strain": 0.02},
    "outlier_specimen": {"factor_minus_1": 1.5},      # one specimen 2.5x stiffer
    "preconditioning": {"first_load_excess": 0.30},   # first test 30 % stiffer
    "nonseparable_relaxation": {"weight_slope": 2.0},  # relaxing weights x (1 + 2*|gamma|)
    "temperature_dependence": {"wlf_c1": 8.86, "wlf_c2_k": 101.6, "spread_k": 6.0},
    "instrument_inertia": {"calibration_error": 0.3},  # 30 % of the motor inertia not subtracted
}
EFFECTS = tuple(EFFECT_SIZES)


# --------------------------------------------------------------------------------------------- kernels
def shear_law(law: str, gamma: np.ndarray, mu: float, p: dict) -> np.ndarray:
    """Instantaneous (elastic) shear stress [Pa] of an incompressible law in simple shear.

    Parameters
    ----------
    law : one of :data:`LAWS`
    gamma : shear strain [1]
    mu : small-strain shear modulus [Pa]
    p : law parameters (``c01_share`` for Mooney-Rivlin, ``alpha`` Ogden, ``jm`` Gent, ``b`` exponential)
    """
    g = np.asarray(gamma, float)
    if law in ("neo_hookean", "mooney_rivlin"):
        # Mooney-Rivlin: 2 (C10 + C01) gamma with 2 (C10 + C01) = mu; the C01 share changes no shear stress
        return mu * g
    if law == "ogden1":
        a = p["alpha"]
        l1 = g / 2.0 + np.sqrt(1.0 + g * g / 4.0)
        l2 = 1.0 / l1
        # mu_ogden = mu (small strain); sigma_12 = 2 mu/a (l1^a - l2^a)/(l1 + l2)
        return 2.0 * mu / a * (l1 ** a - l2 ** a) / (l1 + l2)
    if law == "gent":
        return mu * g / (1.0 - g * g / p["jm"])
    if law == "exponential":
        return mu * g * np.exp(p["b"] * g * g)
    raise ValueError(f"unknown law {law!r}")


def ml_spectrum(alpha: float, h: float = 0.25, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Discrete spectrum (rates r_j, weights w_j) with ``E_alpha(-x**alpha) ~= sum w_j exp(-r_j x)``.

    Trapezoid rule in u = ln r on the Gorenflo-Mainardi spectral density K_alpha (module docstring),
    0 < alpha < 1; the tails decay like exp(-alpha |u|) and are cut where they fall below ``tol`` (absolute
    error about 1e-9 with the defaults: step 0.25 in ln r, e.g. 333 modes at alpha = 0.5).
    """
    if not 0.0 < alpha < 1.0:
        raise ValueError("the spectral representation needs 0 < alpha < 1")
    umax = np.log(1.0 / tol) / alpha
    u = np.arange(-umax, umax + h, h)
    r = np.exp(u)
    ra = r ** alpha
    k = np.sin(alpha * np.pi) / np.pi * ra / (ra * ra + 2.0 * ra * np.cos(alpha * np.pi) + 1.0)  # K(r) * r
    return r, k * h


def mittag_leffler_neg(alpha: float, x: np.ndarray) -> np.ndarray:
    """``E_alpha(-x)`` for x >= 0 [1]: power series ``sum (-x)^k / Gamma(alpha k + 1)`` for x <= 1 (and
    alpha = 1, where it is exp(-x)), the spectral integral (:func:`ml_spectrum`) otherwise."""
    x = np.asarray(x, float)
    out = np.empty_like(x)
    small = (x <= 1.0) | (alpha == 1.0)
    if np.any(small):
        k = np.arange(0, 80)
        xs = x[small][:, None]
        out[small] = np.sum((-xs) ** k / gamma_fn(alpha * k + 1.0), axis=1) if alpha != 1.0 else np.exp(-x[small])
    if np.any(~small):
        r, w = ml_spectrum(alpha)
        t = x[~small] ** (1.0 / alpha)
        out[~small] = np.exp(-np.outer(t, r)) @ w
    return out


@dataclass
class Kernel:
    """Reduced relaxation function as a (possibly dense) Prony spectrum: g(t) = g_inf + sum g_i exp(-t/tau_i)."""
    g_inf: float
    g: np.ndarray
    tau: np.ndarray
    kind: str = "prony"
    alpha: float = 1.0
    tau_c: float = 1.0

    def relax(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, float)
        return self.g_inf + np.exp(-np.divide.outer(t, self.tau)) @ self.g

    def complex_modulus(self, omega: np.ndarray) -> np.ndarray:
        """G*(omega)/G0 of the linear response (closed form for the fractional kernel)."""
        w = np.asarray(omega, float)
        if self.kind == "fractional":
            z = (1j * w * self.tau_c) ** self.alpha
            return self.g_inf + (1.0 - self.g_inf) * z / (1.0 + z)
        iwt = 1j * np.multiply.outer(w, self.tau)
        return self.g_inf + (iwt / (1.0 + iwt)) @ self.g


def prony_kernel(g_inf: float, g: np.ndarray, tau: np.ndarray) -> Kernel:
    return Kernel(float(g_inf), np.asarray(g, float), np.asarray(tau, float))


def fractional_kernel(g_inf: float, alpha: float, tau_c: float) -> Kernel:
    """Fractional Zener (g_inf > 0) / fractional Maxwell (g_inf = 0): g_inf + (1 - g_inf) E_a(-(t/tau)^a)."""
    r, w = ml_spectrum(alpha)
    keep = (w > 1e-14)
    return Kernel(float(g_inf), (1.0 - g_inf) * w[keep], tau_c / r[keep], "fractional", float(alpha), float(tau_c))


def qlv_stress(t: np.ndarray, tau_e: np.ndarray, kernel: Kernel, weight_scale: np.ndarray | None = None) -> np.ndarray:
    """QLV shear stress [Pa] at the times t [s] for the elastic-stress histories tau_e [Pa] (shape (..., T)),
    virgin before t[0].

    Exact for tau_e piecewise linear between the given times: each mode obeys
    ``h_i(t_n) = exp(-dt/tau_i) h_i(t_{n-1}) + rate * tau_i (1 - exp(-dt/tau_i))``. ``weight_scale``
    (shape of tau_e less one time step: one value per interval) multiplies the relaxing weights
    (strain-dependent weights, non-separable); the rest of sum(g_i) then joins the equilibrium part.
    """
    t = np.asarray(t, float)
    te = np.atleast_2d(np.asarray(tau_e, float))
    out = np.empty_like(te)
    out[:, 0] = te[:, 0]
    h = te[:, :1] * np.ones(kernel.tau.size)
    g_total = float(np.sum(kernel.g))
    ws = None if weight_scale is None else np.atleast_2d(weight_scale)
    for n in range(1, t.size):
        dt_ = t[n] - t[n - 1]
        d = (te[:, n] - te[:, n - 1])[:, None]
        if dt_ > 0:
            h = np.exp(-dt_ / kernel.tau) * h + d / dt_ * kernel.tau * -np.expm1(-dt_ / kernel.tau)
        else:
            h = h + d
        relaxing = h @ kernel.g
        if ws is None:
            out[:, n] = kernel.g_inf * te[:, n] + relaxing
        else:
            s_ = ws[:, n - 1]
            out[:, n] = (kernel.g_inf + (1.0 - s_) * g_total) * te[:, n] + s_ * relaxing
    return out.reshape(np.shape(tau_e))


def gauss_radii(n: int, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes/weights on [0, R]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return (x + 1.0) * radius_m / 2.0, w * radius_m / 2.0


def first_harmonic_factor(law: str, strain_amplitude: np.ndarray, p: dict, n_theta: int = 64,
                          n_gauss: int = 12) -> np.ndarray:
    """First-harmonic plate torque of the elastic law under rim strain ``gamma_0 sin(theta)``, relative to the
    linear law's ``pi R^3 mu gamma_0 / 2`` [1] (independent of R and mu).

    ``a_1(gamma) = (1/pi) int_0^{2 pi} sigma_e(gamma sin th) sin th d th`` (trapezoid rule, spectrally exact for
    a periodic integrand), at each radius ``gamma_0 r/R``, and ``M_1 = 2 pi int_0^R a_1 r^2 dr``."""
    g0 = np.atleast_1d(np.asarray(strain_amplitude, float))
    th = 2.0 * np.pi * np.arange(n_theta) / n_theta
    x, w = gauss_radii(n_gauss, 1.0)                      # r/R on [0, 1]
    gamma = g0[:, None, None] * x[None, :, None] * np.sin(th)[None, None, :]
    a1 = 2.0 * np.mean(shear_law(law, gamma, 1.0, p) * np.sin(th), axis=-1)    # per (amplitude, radius)
    return 2.0 * np.pi * (a1 * x * x) @ w / (np.pi * g0 / 2.0)


def plate_torque(shear_stress_of_radius, radius_m: float, n_gauss: int = 12) -> np.ndarray:
    """M = 2 pi int_0^R tau(r) r^2 dr [N m] by Gauss-Legendre quadrature.

    ``shear_stress_of_radius(r) -> array`` takes the column of node radii r [m] (shape (n, 1)) and returns
    the stress at each (shape (n, ...))."""
    r, w = gauss_radii(n_gauss, radius_m)
    tau = np.asarray(shear_stress_of_radius(r[:, None]))
    return 2.0 * np.pi * np.tensordot(w * r * r, tau, axes=(0, 0))


# --------------------------------------------------------------------------------------------- datasets
@dataclass
class Truth:
    law: str
    law_params: dict
    mu: float
    kernel: Kernel
    radius_m: float
    gap_m: list
    noise_rel: float
    torque_floor_nm: float
    motor_inertia: float
    temperature_c: float
    effects: dict = field(default_factory=dict)
    specimens: dict = field(default_factory=dict)
    #: sizes of injected effects that follow from the design (e.g. the offset torque, set by the first run)
    injected: dict = field(default_factory=dict)

    def summary(self) -> dict:
        k = self.kernel
        return {"law": self.law, "law_params": self.law_params, "mu_pa": self.mu,
                "kernel": k.kind, "g_inf": k.g_inf,
                "modes": ({"g": k.g.tolist(), "tau_s": k.tau.tolist()} if k.kind == "prony"
                          else {"alpha": k.alpha, "tau_s": k.tau_c}),
                "radius_mm": self.radius_m * 1e3, "gap_mm": [g * 1e3 for g in self.gap_m],
                "noise_rel": self.noise_rel, "torque_floor_nm": self.torque_floor_nm,
                "motor_inertia_kg_m2": self.motor_inertia, "temperature_c": self.temperature_c,
                "effects": self.effects, "specimens": self.specimens, "injected": self.injected}


def _log_uniform(rng, lo, hi):
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def draw_truth(rng: np.random.Generator) -> Truth:
    """Material, geometry and instrument of one dataset (ranges in the module docstring)."""
    law = str(rng.choice(LAWS))
    lp = {"neo_hookean": {}, "mooney_rivlin": {"c01_share": float(rng.uniform(0.1, 0.6))},
          "ogden1": {"alpha": float(rng.choice([-1, 1]) * rng.uniform(1.0, 15.0))},
          "gent": {"jm": float(rng.uniform(0.5, 10.0))}, "exponential": {"b": float(rng.uniform(0.1, 2.0))}}[law]
    mu = _log_uniform(rng, 100.0, 20e3)
    if rng.uniform() < 0.3:
        kernel = fractional_kernel(float(rng.choice([0.0, rng.uniform(0.05, 0.5)])), float(rng.uniform(0.15, 0.85)),
                                   _log_uniform(rng, 1e-2, 1e2))
    else:
        n = int(rng.integers(1, 6))
        tau = np.sort(np.exp(rng.uniform(np.log(1e-3), np.log(1e3), size=n)))
        w = rng.dirichlet(np.ones(n + 1)) * rng.uniform(0.5, 0.95)
        kernel = prony_kernel(1.0 - w[:n].sum(), w[:n], tau)
    gaps = sorted({round(float(g), 2) for g in rng.uniform(1.0, 4.0, size=int(rng.integers(1, 3)))})
    return Truth(law, lp, mu, kernel, radius_m=float(rng.uniform(4.0, 25.0)) * 1e-3, gap_m=[g * 1e-3 for g in gaps],
                 noise_rel=_log_uniform(rng, 0.002, 0.03), torque_floor_nm=_log_uniform(rng, 1e-9, 1e-7),
                 motor_inertia=_log_uniform(rng, 5e-6, 5e-5), temperature_c=float(rng.choice([20.0, 25.0, 37.0])))


def draw_test_settings(rng: np.random.Generator, f_max: float) -> dict:
    """Settings of the sweeps, ramps and relaxations of a design (ranges in the module docstring)."""
    return {
        "amplitude_sweep": {"frequency_hz": float(rng.choice([0.5, 1.0, 2.0])), "n": int(rng.integers(8, 16)),
                            "strain_max": _log_uniform(rng, 0.01, 0.1)},
        "frequency_sweep": {"strain": _log_uniform(rng, 0.001, 0.01), "f_min": _log_uniform(rng, 0.01, 0.2),
                            "f_max": f_max, "n": int(rng.integers(8, 16))},
        "constant_shear_rate": {"rates": sorted(_log_uniform(rng, 1e-3, 0.5) for _ in range(int(rng.integers(1, 3)))),
                                "strain_max": float(rng.uniform(0.1, 0.5)), "n": int(rng.integers(12, 25))},
        "stress_relaxation": {"strains": sorted(float(rng.uniform(0.01, 0.4)) for _ in range(int(rng.integers(1, 4)))),
                              "rise_s": _log_uniform(rng, 0.02, 0.5), "hold_s": _log_uniform(rng, 30.0, 300.0),
                              "n": int(rng.integers(12, 25))},
    }


def draw_design(rng: np.random.Generator, effects: dict) -> list[dict]:
    """Per sample, a random subset of the tests in a random order, with random settings."""
    n_spec = int(rng.integers(1, 7))
    if "outlier_specimen" in effects:
        n_spec = max(n_spec, 2)        # an outlier needs other specimens (no extra draw: null designs unchanged)
    min_samples = 1
    if "temperature_dependence" in effects:   # at least 3 samples in all, so all 3 temperatures are run
        min_samples = -(-3 // n_spec)
    tests = []
    f_max = _log_uniform(rng, 1.0, 20.0) if "instrument_inertia" not in effects else _log_uniform(rng, 50.0, 100.0)
    settings = draw_test_settings(rng, f_max)
    kinds = [k for k in TESTS if rng.uniform() < 0.7] or [str(rng.choice(TESTS[2:]))]
    if not any(k in kinds for k in ("constant_shear_rate", "stress_relaxation")):
        kinds.append(str(rng.choice(TESTS[2:])))          # the baseline is fitted to ramps/relaxations
    if "instrument_inertia" in effects and "frequency_sweep" not in kinds:
        kinds.append("frequency_sweep")
    if "nonseparable_relaxation" in effects and "stress_relaxation" not in kinds:
        kinds.append("stress_relaxation")
    for s in range(n_spec):
        for j in range(max(int(rng.integers(1, 4)), min_samples)):
            items = []
            for k in kinds:
                if k == "constant_shear_rate":
                    items += [(k, {"rate": r}) for r in settings[k]["rates"]]
                elif k == "stress_relaxation":
                    items += [(k, {"strain": e}) for e in settings[k]["strains"]]
                else:
                    items.append((k, {}))
            order = rng.permutation(len(items))
            tests.append({"specimen": f"S{s + 1}", "sample": f"s{j + 1}",
                          "tests": [(items[i][0], {**settings[items[i][0]], **items[i][1]}) for i in order]})
    return tests


def _noise(rng, torque, truth):
    sd = np.sqrt((truth.noise_rel * np.abs(torque)) ** 2 + truth.torque_floor_nm ** 2)
    return torque + sd * rng.normal(size=np.shape(torque))


def _shift_kernel(kernel: Kernel, a_t: float) -> Kernel:
    return Kernel(kernel.g_inf, kernel.g, kernel.tau * a_t, kernel.kind, kernel.alpha, kernel.tau_c * a_t)


def _strain_run(kind, st, truth, kernel, factor, gap, effects):
    """Constant-rate ramp or relaxation: reported (time, rim strain, torque) and the internal history."""
    if kind == "constant_shear_rate":
        dur = st["strain_max"] / st["rate"]
        t = np.linspace(0.0, dur, 400)
        rim = st["rate"] * t
        rep = np.unique(np.linspace(0, t.size - 1, st["n"] + 1).astype(int))[1:]
    else:
        rise, hold = st["rise_s"], st["hold_s"]
        t = np.unique(np.r_[np.linspace(0.0, rise, 30), rise + np.geomspace(1e-4, hold, 300)])
        rim = st["strain"] * np.clip(t / rise, 0.0, 1.0)
        t_rep = np.r_[np.linspace(rise / 4, rise, 4), rise + np.geomspace(min(0.05, hold / 100), hold, st["n"])]
        rep = np.unique(np.searchsorted(t, t_rep).clip(0, t.size - 1))
    slip = effects.get("wall_slip")
    nonsep = effects.get("nonseparable_relaxation")

    def stress_at(r):
        g = rim * r / truth.radius_m
        if slip:
            b = EFFECT_SIZES["wall_slip"]["slip_length_m"] * slip
            gc = EFFECT_SIZES["wall_slip"]["critical_strain"]
            g = np.where(g > gc, gc + (g - gc) * gap / (gap + 2.0 * b), g)
        te = shear_law(truth.law, g, truth.mu * factor, truth.law_params)
        scale = None
        if nonsep:
            gm = 0.5 * (g[..., 1:] + g[..., :-1])
            total = float(np.sum(kernel.g))
            scale = np.minimum(1.0 + EFFECT_SIZES["nonseparable_relaxation"]["weight_slope"] * nonsep * np.abs(gm),
                               0.98 / max(total, 1e-9))
        return qlv_stress(t, te, kernel, scale)

    torque = plate_torque(stress_at, truth.radius_m)
    return t, rim, torque, rep


def _oscillation(kind, st, truth, kernel, factor, gap, effects, rng):
    if kind == "amplitude_sweep":
        strain = np.geomspace(1e-4, st["strain_max"], st["n"])
        freq = np.full(st["n"], st["frequency_hz"])
    else:
        freq = np.geomspace(st["f_min"], st["f_max"], st["n"])
        strain = np.full(st["n"], st["strain"])
    omega = 2.0 * np.pi * freq
    g_star = truth.mu * factor * kernel.complex_modulus(omega) * first_harmonic_factor(truth.law, strain,
                                                                                          truth.law_params)
    pf = np.pi * truth.radius_m ** 3 / 2.0          # torque per unit (modulus x rim strain)
    m_sample = g_star * strain * pf
    theta = strain * gap / truth.radius_m
    m_inertia = -truth.motor_inertia * omega ** 2 * theta            # I * theta_ddot amplitude (in phase with -theta)
    m_raw = m_sample + m_inertia
    err = EFFECT_SIZES["instrument_inertia"]["calibration_error"] * effects.get("instrument_inertia", 0.0)
    m_corr = m_sample + err * m_inertia
    sd = np.sqrt((truth.noise_rel * np.abs(m_raw)) ** 2 + truth.torque_floor_nm ** 2) / np.sqrt(2.0)
    noise = sd * (rng.normal(size=freq.size) + 1j * rng.normal(size=freq.size))
    m_corr = m_corr + noise
    m_raw = m_raw + noise
    g_meas = m_corr / (strain * pf)
    ch = {"time": np.cumsum(np.maximum(3.0 / freq, 5.0)), "frequency": freq, "angular_frequency": omega,
          "shear_strain": strain, "shear_stress": np.abs(g_meas) * strain, "storage_modulus": g_meas.real,
          "loss_modulus": g_meas.imag, "phase_angle": np.angle(g_meas), "torque": np.abs(m_corr),
          "deflection_angle": theta, "complex_modulus": np.abs(g_meas)}
    if "instrument_inertia" in effects or rng.uniform() < 0.7:
        ch["raw_phase"] = np.angle(m_raw)
    return ch


def checked_effects(effects: dict | None, known) -> dict:
    """``effects`` as a dict, every name among ``known`` (``ValueError`` naming the others)."""
    effects = dict(effects or {})
    unknown = set(effects) - set(known)
    if unknown:
        raise ValueError(f"unknown effects {sorted(unknown)}; known: {tuple(known)}")
    return effects


def generate(seed: int, effects: dict | None = None, dataset: str | None = None):
    """One seeded dataset of canonical runs.

    Parameters
    ----------
    seed : integer seed (the whole dataset, truth and design, follows from it)
    effects : ``{effect name: magnitude}`` (names of :data:`EFFECTS`; magnitude 1 = :data:`EFFECT_SIZES`)

    Returns
    -------
    (runs, truth) : list of canonical run datasets (``make_run_dataset``) and a JSON-able truth summary
    """
    effects = checked_effects(effects, EFFECTS)
    rng = np.random.default_rng(seed)
    truth = draw_truth(rng)
    truth.effects = effects
    design = draw_design(rng, effects)
    name = dataset or f"indep_{seed}"
    spec_names = sorted({d["specimen"] for d in design})
    spec_sd = float(rng.uniform(0.05, 0.3))
    spec_log = {s: float(rng.normal() * spec_sd) for s in spec_names}
    if "outlier_specimen" in effects and len(spec_names) > 1:
        out = str(rng.choice(spec_names))
        excess = EFFECT_SIZES["outlier_specimen"]["factor_minus_1"] * effects["outlier_specimen"]
        spec_log[out] += float(np.log1p(excess))
        truth.specimens["outlier"] = out
    truth.specimens["log_factor"] = spec_log
    temps = [truth.temperature_c]
    if "temperature_dependence" in effects:
        sp = EFFECT_SIZES["temperature_dependence"]["spread_k"]
        temps = [truth.temperature_c - sp, truth.temperature_c, truth.temperature_c + sp]
    start = dt.datetime(2026, 3, 2, 8, 0, 0) + dt.timedelta(minutes=int(rng.integers(0, 240)))
    pause = float(rng.uniform(30.0, 600.0))
    runs = []
    clock = 0.0
    offset_torque = None
    for si, smp in enumerate(design):
        gap = float(rng.choice(truth.gap_m))
        temp = float(temps[si % len(temps)])
        a_t = 1.0
        if "temperature_dependence" in effects:
            c = EFFECT_SIZES["temperature_dependence"]
            c1 = c["wlf_c1"] * effects["temperature_dependence"]
            a_t = 10.0 ** (-c1 * (temp - truth.temperature_c) / (c["wlf_c2_k"] + temp - truth.temperature_c))
        kernel = _shift_kernel(truth.kernel, a_t)
        sample_log = float(rng.normal() * 0.05)
        clock += float(rng.uniform(120.0, 600.0))   # loading / trimming / equilibration
        for order, (kind, st) in enumerate(smp["tests"], start=1):
            elapsed_h = clock / 3600.0
            factor = float(np.exp(spec_log[smp["specimen"]] + sample_log))
            if "elapsed_time_drift" in effects:
                per_h = EFFECT_SIZES["elapsed_time_drift"]["per_hour"] * effects["elapsed_time_drift"]
                factor *= 1.0 + per_h * elapsed_h
            if "preconditioning" in effects and order == 1:
                factor *= 1.0 + EFFECT_SIZES["preconditioning"]["first_load_excess"] * effects["preconditioning"]
            run_rng = np.random.default_rng([seed, si, order])
            attrs = {"dataset": name, "test": kind, "specimen": smp["specimen"], "sample": smp["sample"],
                     "order": order, "source_sha256": "independent-generator", "radius_m": truth.radius_m,
                     "gap_m": gap, "temperature_c": temp,
                     "started_at": (start + dt.timedelta(seconds=clock)).isoformat(timespec="seconds")}
            if kind in ("constant_shear_rate", "stress_relaxation"):
                t, rim, torque, rep = _strain_run(kind, st, truth, kernel, factor, gap, effects)
                m = torque[rep]
                if "torque_offset" in effects:
                    if offset_torque is None:   # 5 % (1x) of this dataset's first ramp/relaxation median torque
                        offset_torque = EFFECT_SIZES["torque_offset"]["fraction"] * effects["torque_offset"] * float(
                            np.median(np.abs(m)))
                        truth.injected["torque_offset_nm"] = offset_torque
                    m = m + offset_torque
                m = _noise(run_rng, m, truth)
                ch = {"time": t[rep], "shear_strain": rim[rep], "shear_rate": np.gradient(rim, t)[rep], "torque": m,
                      "shear_stress": 2.0 * m / (np.pi * truth.radius_m ** 3),
                      "deflection_angle": rim[rep] * gap / truth.radius_m}
                if kind == "constant_shear_rate":
                    attrs["shear_rate_1_per_s"] = float(st["rate"])
                    tag = f"csr{st['rate']:.3g}"
                else:
                    attrs["strain_pct"] = float(100.0 * st["strain"])
                    ch["relaxation_modulus"] = ch["shear_stress"] / st["strain"]
                    tag = f"sr{100 * st['strain']:.3g}pct"
                dur = float(t[-1])
            else:
                ch = _oscillation(kind, st, truth, kernel, factor, gap, effects, run_rng)
                if kind == "amplitude_sweep":
                    attrs["frequency_hz"] = float(st["frequency_hz"])
                tag = "as" if kind == "amplitude_sweep" else "fs"
                dur = float(ch["time"][-1])
            n = ch["time"].size
            ch["total_time"] = clock + ch["time"]
            ch["temperature"] = np.round(temp + 0.02 * run_rng.normal(size=n), 2)
            ch["gap"] = np.round(gap + 0.5e-6 * run_rng.normal(size=n), 7)
            fname = f"{smp['specimen']}_{smp['sample']}_{order:02d}_{tag}.csv"
            attrs.update(run=fname, source_file=fname)
            runs.append(make_run_dataset(ch, attrs))
            clock += dur + pause
    return runs, truth.summary()


# ============================================================================ dataset folders (what a user drops in raw/)
#: effects of the folder generator (:func:`write_dataset_folder`): those of :func:`generate` plus creep ringing, a
#: held-back temperature spread read only from the logged temperature channel, and a normal-force preload (1x sizes)
FOLDER_EFFECT_SIZES = {
    **EFFECT_SIZES,
    # the creep torque balance carries the motor inertia (x magnitude); a null creep is the inertia-free response
    "creep_ringing": {"inertia_share": 1.0},
    # each sample at T + U(-1, 1) x 4 K (logged channel only; the sample sheet states the nominal T), WLF time shift
    "temperature_spread": {"spread_k": 4.0, "wlf_c1": 8.86, "wlf_c2_k": 101.6},
    # moduli x (F / 0.1 N)**0.15 for a preload F of 0.02-0.5 N per sample (logged in the normal-force channel)
    "normal_force_preload": {"exponent": 0.15, "reference_n": 0.1},
}
FOLDER_EFFECTS = tuple(FOLDER_EFFECT_SIZES)
FOLDER_TESTS = TESTS + ("creep_recovery",)
#: the test subsets of a design family: ``random`` keeps each kind with probability 0.6; ``no_relaxation`` draws
#: from the sweeps, ramps and creep (0.7 each); ``sweeps_ramps`` has ramps and at least one sweep kind;
#: ``creep_only`` and ``creep_relaxation`` have exactly those kinds
FAMILIES = {
    "random": FOLDER_TESTS,
    "no_relaxation": ("amplitude_sweep", "frequency_sweep", "constant_shear_rate", "creep_recovery"),
    "sweeps_ramps": ("amplitude_sweep", "frequency_sweep", "constant_shear_rate"),
    "creep_only": ("creep_recovery",),
    "creep_relaxation": ("stress_relaxation", "creep_recovery"),
}
#: the test kinds in which each effect shows: a power dataset's design family is drawn among those that hold one,
#: and one of them is added when the drawn subset lacks it
SHOWN_BY = {
    "elapsed_time_drift": FOLDER_TESTS,
    "torque_offset": ("constant_shear_rate", "stress_relaxation", "creep_recovery"),
    "wall_slip": ("constant_shear_rate", "creep_recovery"),
    "outlier_specimen": FOLDER_TESTS,
    "preconditioning": FOLDER_TESTS,
    "nonseparable_relaxation": ("constant_shear_rate", "stress_relaxation", "creep_recovery"),
    "temperature_dependence": FOLDER_TESTS,
    "instrument_inertia": ("frequency_sweep",),
    "creep_ringing": ("creep_recovery",),
    "temperature_spread": FOLDER_TESTS,
    "normal_force_preload": FOLDER_TESTS,
}
#: the least number of samples in all an effect needs to show between samples
MIN_SAMPLES = {"temperature_dependence": 3, "temperature_spread": 4, "normal_force_preload": 4}
#: plate diameters [mm] of the measuring systems drawn (radius 4-25 mm)
PLATE_DIAMETERS_MM = (8.0, 10.0, 15.0, 20.0, 25.0, 35.0, 40.0, 50.0)
#: export formats: RheoCompass CSV as UTF-16 with decimal commas and the simple header, RheoCompass UTF-8 text with
#: decimal points and the project header, TA TRIOS text (one file per sample, one ``[step]`` per test)
FORMATS = ("rheocompass_utf16", "rheocompass_utf8", "trios_text")
TORQUE_UNITS = {"N·m": 1.0, "mN·m": 1e3, "µN·m": 1e6}
PRELOAD_RANGE_N = (0.02, 0.5)


def draw_folder_design(rng: np.random.Generator, effects: dict) -> dict:
    """Design of one dataset folder: test subset (family), specimens and samples, their sequence (blocks or
    interleaved), test order, days, export format and units, where the geometry is stated, logged channels, and
    the settings of every test kind (module docstring, "Dataset folders")."""
    shown = set(FOLDER_TESTS)
    for e in effects:
        shown &= set(SHOWN_BY[e])
    if not shown:
        raise ValueError(f"no test kind shows all of {sorted(effects)} at once")
    # every draw is made whatever the effects, so that a seed gives the same design with and without them
    names = [f for f in FAMILIES if set(FAMILIES[f]) & shown]
    family = names[int(rng.integers(len(names)))]
    pool = FAMILIES[family]
    keep, pick = rng.uniform(size=len(FOLDER_TESTS)), int(rng.integers(64))
    if family == "random":
        kinds = [k for k, u in zip(pool, keep) if u < 0.6]
    elif family == "no_relaxation":
        kinds = [k for k, u in zip(pool, keep) if u < 0.7]
    elif family == "sweeps_ramps":
        kinds = [k for k, u in zip(pool[:2], keep) if u < 0.7] or [pool[pick % 2]]
        kinds.append("constant_shear_rate")
    else:
        kinds = list(pool)
    if not kinds:
        kinds = [pool[pick % len(pool)]]
    if not set(kinds) & shown:
        allowed = sorted(set(pool) & shown)
        kinds.append(allowed[pick % len(allowed)])
    kinds = [k for k in FOLDER_TESTS if k in kinds]
    one, n_any, n_out = rng.uniform(), int(rng.integers(2, 9)), int(rng.integers(4, 7))
    n_spec = n_out if "outlier_specimen" in effects else (1 if one < 0.2 else n_any)   # an outlier among 4-6
    per_spec = [int(k) for k in rng.integers(1, 4, size=8)[:n_spec]]
    need = max([MIN_SAMPLES.get(e, 1) for e in effects] + [1])
    while sum(per_spec) < need:
        per_spec[int(np.argmin(per_spec))] += 1
    layout = "blocks" if rng.uniform() < 0.5 else "interleaved"
    pieces = ([(s, j) for s in range(n_spec) for j in range(per_spec[s])] if layout == "blocks" else
              [(s, j) for j in range(max(per_spec)) for s in range(n_spec) if j < per_spec[s]])
    days = int(min(len(pieces), rng.choice([1, 1, 1, 2, 2, 3])))
    f_low, f_high = _log_uniform(rng, 1.0, 20.0), _log_uniform(rng, 50.0, 100.0)
    f_max = f_high if "instrument_inertia" in effects else f_low
    n_creep = int(rng.integers(1, 3))
    if "preconditioning" in effects and kinds == ["creep_recovery"]:
        n_creep = 2
    settings = {
        **draw_test_settings(rng, f_max),
        "creep_recovery": {"target_strains": sorted(_log_uniform(rng, 0.01, 0.15) for _ in range(n_creep)),
                           "rise_s": _log_uniform(rng, 0.002, 0.05), "creep_s": _log_uniform(rng, 30.0, 300.0),
                           "per_decade": int(rng.integers(10, 21))},
    }
    if "preconditioning" in effects and kinds != ["creep_recovery"]:   # a first test to compare with
        conditions = {"constant_shear_rate": len(settings["constant_shear_rate"]["rates"]),
                      "stress_relaxation": len(settings["stress_relaxation"]["strains"])}
        if sum(conditions.get(k, 1) for k in kinds) < 2:
            extra = next(k for k in ("amplitude_sweep", "frequency_sweep") if k not in kinds)
            kinds = [k for k in FOLDER_TESTS if k in kinds or k == extra]
    fixed = rng.permutation(64)
    u_force, u_phase = rng.uniform(size=2)
    return {
        "family": family, "kinds": kinds, "n_specimens": n_spec, "samples_per_specimen": per_spec,
        "layout": layout, "sequence": pieces, "days": days,
        "order": "random" if rng.uniform() < 0.5 else "fixed", "fixed_permutation": fixed,
        "format": str(rng.choice(FORMATS)), "torque_unit": str(rng.choice(list(TORQUE_UNITS))),
        "frequency_unit": str(rng.choice(["Hz", "rad/s"])), "strain_unit": str(rng.choice(["%", "1"])),
        "geometry_source": str(rng.choice(["samples", "yaml", "export"])),
        "logs_normal_force": bool(u_force < 0.5 or "normal_force_preload" in effects),
        "logs_raw_phase": bool(u_phase < 0.7 or "instrument_inertia" in effects),
        "settings": settings,
    }


def _sample_tests(design: dict, rng: np.random.Generator) -> list[tuple[str, dict]]:
    """The tests of one sample (each condition of a ramp, relaxation or creep kind is one test) in design order."""
    st = design["settings"]
    items = []
    for k in design["kinds"]:
        if k == "constant_shear_rate":
            items += [(k, {**st[k], "rate": r}) for r in st[k]["rates"]]
        elif k == "stress_relaxation":
            items += [(k, {**st[k], "strain": e}) for e in st[k]["strains"]]
        elif k == "creep_recovery":
            items += [(k, {**st[k], "target_strain": e}) for e in st[k]["target_strains"]]
        else:
            items.append((k, dict(st[k])))
    if design["order"] == "random":
        order = rng.permutation(len(items))
    else:   # the same order for every sample
        order = [i for i in design["fixed_permutation"] if i < len(items)]
    return [items[i] for i in order]


def _slip_strain(g: np.ndarray, gap: float, slip: float) -> np.ndarray:
    """Strain the sample sees when the walls slip above the critical strain (slip length ``b`` per wall)."""
    b = EFFECT_SIZES["wall_slip"]["slip_length_m"] * slip
    gc = EFFECT_SIZES["wall_slip"]["critical_strain"]
    return np.where(np.abs(g) > gc, np.sign(g) * (gc + (np.abs(g) - gc) * gap / (gap + 2.0 * b)), g)


def creep_response(t: np.ndarray, torque_nm: np.ndarray, truth: Truth, kernel: Kernel, factor: float, gap: float,
                   effects: dict, inertia: float = 0.0, n_gauss: int = 12) -> np.ndarray:
    """Rim strain [1] of a stress-controlled test: at every time the motor torque ``torque_nm`` [N m] balances
    the plate torque of the QLV material ``2 pi int tau(r) r^2 dr`` plus, with ``inertia`` I [kg m^2], the
    rotor's ``I theta''``; ``theta = gamma_R h / R``.

    Per time step the QLV state is updated exactly for a linear elastic-stress increment (as :func:`qlv_stress`),
    so the plate torque is a monotone function of the unknown rim strain, solved by Brent's method; the inertia
    term is integrated by the average-acceleration (trapezoidal) Newmark rule, which adds no numerical damping
    to the ringing. Wall slip and strain-dependent relaxing weights (``effects``) act per radius as in
    :func:`_strain_run`."""
    from scipy.optimize import brentq

    x, w = gauss_radii(n_gauss, 1.0)
    radius = truth.radius_m
    mu = truth.mu * factor
    gw = 2.0 * np.pi * w * x * x * radius ** 3           # torque weights of the stress at each node
    slip = effects.get("wall_slip")
    nonsep = effects.get("nonseparable_relaxation")
    slope = EFFECT_SIZES["nonseparable_relaxation"]["weight_slope"] * (nonsep or 0.0)
    g_total = float(np.sum(kernel.g))
    cap = 0.98 / max(g_total, 1e-9)
    limit = 0.999 * np.sqrt(truth.law_params["jm"]) if truth.law == "gent" else np.inf
    h_state = np.zeros((n_gauss, kernel.tau.size))
    te_prev = np.zeros(n_gauss)
    g_prev = np.zeros(n_gauss)
    out = np.zeros(t.size)
    theta_of = gap / radius
    v_prev = a_prev = 0.0
    for n in range(1, t.size):
        dt_ = t[n] - t[n - 1]
        decay = np.exp(-dt_ / kernel.tau)
        gain = kernel.tau / dt_ * -np.expm1(-dt_ / kernel.tau)
        carried = (h_state * decay) @ kernel.g                 # relaxing stress carried over, per node
        gain_g = gain @ kernel.g

        def stress(rim):
            g = rim * x
            if slip:
                g = _slip_strain(g, gap, slip)
            te = shear_law(truth.law, g, mu, truth.law_params)
            relaxing = carried + (te - te_prev) * gain_g
            if not nonsep:
                return kernel.g_inf * te + relaxing, te, g
            s_ = np.minimum(1.0 + slope * np.abs(0.5 * (g + g_prev)), cap)
            return (kernel.g_inf + (1.0 - s_) * g_total) * te + s_ * relaxing, te, g

        def residual(rim):
            m_mat = float(gw @ stress(rim)[0])
            if inertia <= 0.0:
                return m_mat - torque_nm[n]
            theta = rim * theta_of
            return (theta - out[n - 1] * theta_of - dt_ * v_prev - dt_ * dt_ / 4.0 * a_prev
                    - dt_ * dt_ / (4.0 * inertia) * (torque_nm[n] - m_mat))

        step = max(abs(out[n - 1] - (out[n - 2] if n > 1 else 0.0)), 1e-7, 1e-4 * abs(out[n - 1]))
        lo, hi = out[n - 1] - step, out[n - 1] + step
        r_lo, r_hi = residual(lo), residual(hi)
        while r_lo > 0.0:
            lo = max(lo - 4.0 * (hi - lo), -limit)
            r_lo = residual(lo)
        while r_hi < 0.0:
            hi = min(hi + 4.0 * (hi - lo), limit)
            r_hi = residual(hi)
        rim = brentq(residual, lo, hi, xtol=1e-15, rtol=1e-11)
        _, te, g = stress(rim)
        h_state = h_state * decay + np.outer(te - te_prev, gain)
        if inertia > 0.0:
            a_new = (torque_nm[n] - float(gw @ stress(rim)[0])) / inertia
            v_prev += dt_ / 2.0 * (a_prev + a_new)
            a_prev = a_new
        te_prev, g_prev = te, g
        out[n] = rim
    return out


def _creep_run(st, truth, kernel, factor, gap, effects, offset_torque):
    """Creep and recovery at the apparent stress the sample sheet states: reported (time, rim strain, torque set)
    and the nominal stress. The stress is the one that takes the truth's nominal material to the design's target
    strain at the end of the creep (2 significant digits, as an operator types it)."""
    radius = truth.radius_m
    t_c = st["creep_s"]
    g_end = float(kernel.relax(np.array([t_c]))[0])
    stress_pa = float(f"{st['target_strain'] * truth.mu * max(g_end, 0.02):.2g}")
    rise = st["rise_s"]
    per = st["per_decade"]
    first = 2e-3
    t_rep_c = np.geomspace(first, t_c, int(per * np.log10(t_c / first)) + 1)
    t_rep = np.r_[t_rep_c, t_c + t_rep_c]
    grid = [np.linspace(0.0, rise, 21), rise + np.geomspace(1e-5, t_c, 400), t_c + np.linspace(0.0, rise, 21),
            t_c + rise + np.geomspace(1e-5, t_c, 400), t_rep]
    inertia = 0.0
    if "creep_ringing" in effects:
        inertia = truth.motor_inertia * FOLDER_EFFECT_SIZES["creep_ringing"]["inertia_share"] * effects[
            "creep_ringing"]
        stiffness = truth.mu * factor * np.pi * radius ** 4 / (2.0 * gap)   # instantaneous, the shortest period
        period = 2.0 * np.pi * np.sqrt(inertia / stiffness)
        span = min(40.0 * period, t_c)
        fine = np.arange(0.0, span, min(period / 40.0, span / 20.0))[:4000]
        grid += [fine, t_c + fine]
    t = np.unique(np.concatenate(grid))
    t = t[t <= 2.0 * t_c]
    load = np.clip(t / rise, 0.0, 1.0) - np.clip((t - t_c) / rise, 0.0, 1.0)
    m_set = stress_pa * np.pi * radius ** 3 / 2.0 * load
    m_sample = m_set - (offset_torque or 0.0) * (load != 0.0)   # the instrument regulates its (offset) reading
    rim = creep_response(t, m_sample, truth, kernel, factor, gap, effects, inertia)
    rep = np.searchsorted(t, t_rep).clip(0, t.size - 1)
    return t[rep], rim[rep], m_set[rep], stress_pa


def simulate_folder(seed: int, effects: dict | None = None, dataset: str | None = None):
    """The runs of one dataset folder, before they are written: ``(records, truth, design)``.

    ``records``: one dict per test with ``channels`` (canonical SI arrays: what the instrument measured and
    reports) and ``meta`` (specimen, sample, test, order, nominal condition, gap, nominal and logged temperature,
    preload, ``started_at``); see :func:`write_dataset_folder`."""
    effects = checked_effects(effects, FOLDER_EFFECTS)
    rng = np.random.default_rng(seed)
    truth = draw_truth(rng)
    truth.radius_m = float(rng.choice(PLATE_DIAMETERS_MM)) / 2.0 * 1e-3
    truth.effects = effects
    design = draw_folder_design(rng, effects)
    name = dataset or f"indep_{seed}"
    n_spec = design["n_specimens"]
    spec_names = [f"S{s + 1}" for s in range(n_spec)]
    spec_sd = float(rng.uniform(0.05, 0.3))
    spec_log = {s: float(rng.normal() * spec_sd) for s in spec_names}
    out = str(rng.choice(spec_names))
    if "outlier_specimen" in effects:
        spec_log[out] += float(np.log1p(EFFECT_SIZES["outlier_specimen"]["factor_minus_1"] * effects["outlier_specimen"]))
        truth.specimens["outlier"] = out
    truth.specimens["log_factor"] = spec_log
    truth.specimens["log_sd"] = spec_sd
    pieces = design["sequence"]
    day_of = np.repeat(np.arange(design["days"]), np.diff(np.linspace(0, len(pieces), design["days"] + 1).round()
                                                          .astype(int)))
    day0 = dt.datetime(2026, 3, 2, 8, 0, 0)
    day_starts = [day0 + dt.timedelta(days=int(d) + int(d > 0) * int(rng.integers(0, 3)),
                                      minutes=int(rng.integers(0, 120))) for d in range(design["days"])]
    pause = float(rng.uniform(30.0, 600.0))
    records = []
    offset_torque = None
    clock, day = 0.0, -1
    nominal_t = truth.temperature_c
    for si, (s, j) in enumerate(pieces):
        if day_of[si] != day:
            day, clock = int(day_of[si]), 0.0
        spec, smp = spec_names[s], f"s{j + 1}"
        gap = float(rng.choice(truth.gap_m))
        control, spread = float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-1.0, 1.0))
        temp_nominal, temp_logged, a_t = nominal_t, nominal_t + control, 1.0
        if "temperature_dependence" in effects:
            c = EFFECT_SIZES["temperature_dependence"]
            temp_nominal = nominal_t + c["spread_k"] * (si % 3 - 1)
            temp_logged = temp_nominal + control
            c1 = c["wlf_c1"] * effects["temperature_dependence"]
            a_t = 10.0 ** (-c1 * (temp_nominal - nominal_t) / (c["wlf_c2_k"] + temp_nominal - nominal_t))
        if "temperature_spread" in effects:
            c = FOLDER_EFFECT_SIZES["temperature_spread"]
            d_t = c["spread_k"] * effects["temperature_spread"] * spread
            temp_logged = nominal_t + d_t
            a_t = 10.0 ** (-c["wlf_c1"] * d_t / (c["wlf_c2_k"] + d_t))
        preload = _log_uniform(rng, *PRELOAD_RANGE_N)
        preload_factor = 1.0
        if "normal_force_preload" in effects:
            c = FOLDER_EFFECT_SIZES["normal_force_preload"]
            preload_factor = (preload / c["reference_n"]) ** (c["exponent"] * effects["normal_force_preload"])
        kernel = _shift_kernel(truth.kernel, a_t)
        sample_log = float(rng.normal() * 0.05)
        clock += float(rng.uniform(120.0, 600.0))   # loading, trimming, equilibration
        for order, (kind, st) in enumerate(_sample_tests(design, rng), start=1):
            factor = float(np.exp(spec_log[spec] + sample_log)) * preload_factor
            if "elapsed_time_drift" in effects:     # hours since the day's session started
                factor *= 1.0 + EFFECT_SIZES["elapsed_time_drift"]["per_hour"] * effects["elapsed_time_drift"] * (
                    clock / 3600.0)
            if "preconditioning" in effects and order == 1:
                factor *= 1.0 + EFFECT_SIZES["preconditioning"]["first_load_excess"] * effects["preconditioning"]
            run_rng = np.random.default_rng([seed, si, order])
            meta = {"specimen": spec, "sample": smp, "test": kind, "order": order, "gap_m": gap,
                    "temperature_c": temp_nominal, "temperature_logged_c": temp_logged, "preload_n": preload,
                    "started_at": (day_starts[day] + dt.timedelta(seconds=clock)).isoformat(timespec="seconds")}
            if kind in ("constant_shear_rate", "stress_relaxation"):
                t, rim, torque, rep = _strain_run(kind, st, truth, kernel, factor, gap, effects)
                m = torque[rep]
                if "torque_offset" in effects:
                    if offset_torque is None:
                        offset_torque = _offset(effects, m, truth)
                    m = m + offset_torque
                m = _noise(run_rng, m, truth)
                ch = {"time": t[rep], "shear_strain": rim[rep], "shear_rate": np.gradient(rim, t)[rep], "torque": m,
                      "shear_stress": 2.0 * m / (np.pi * truth.radius_m ** 3)}
                if kind == "constant_shear_rate":
                    meta["shear_rate_1_per_s"] = float(st["rate"])
                else:
                    meta["strain_pct"] = float(100.0 * st["strain"])
                    ch["relaxation_modulus"] = ch["shear_stress"] / st["strain"]
            elif kind == "creep_recovery":
                if "torque_offset" in effects and offset_torque is None:
                    g_end = float(kernel.relax(np.array([st["creep_s"]]))[0])
                    m_typ = st["target_strain"] * truth.mu * max(g_end, 0.02) * np.pi * truth.radius_m ** 3 / 2.0
                    offset_torque = _offset(effects, np.array([m_typ]), truth)
                t, rim, m_set, stress_pa = _creep_run(st, truth, kernel, factor, gap, effects, offset_torque)
                floor = 1e-7 * truth.radius_m / gap            # 0.1 urad of angle resolution
                sd = np.sqrt((truth.noise_rel * rim) ** 2 + floor ** 2)
                ch = {"time": t, "shear_strain": rim + sd * run_rng.normal(size=t.size), "torque": m_set,
                      "shear_stress": 2.0 * m_set / (np.pi * truth.radius_m ** 3)}
                meta["stress_pa"] = stress_pa
            else:
                ch = _oscillation(kind, st, truth, kernel, factor, gap, effects, run_rng)
                ch.pop("complex_modulus")
                if not design["logs_raw_phase"]:
                    ch.pop("raw_phase", None)
                if kind == "amplitude_sweep":
                    meta["frequency_hz"] = float(st["frequency_hz"])
            n = ch["time"].size
            ch["deflection_angle"] = ch["shear_strain"] * gap / truth.radius_m
            ch["total_time"] = clock + ch["time"]
            ch["temperature"] = np.round(temp_logged + 0.02 * run_rng.normal(size=n), 2)
            ch["gap"] = np.round(gap + 0.5e-6 * run_rng.normal(size=n), 7)
            if design["logs_normal_force"]:
                ch["normal_force"] = preload * (1.0 + 0.02 * run_rng.normal(size=n))
            records.append({"channels": ch, "meta": meta})
            clock += float(ch["time"][-1]) + pause
    summary = truth.summary()
    summary.update(dataset=name, seed=seed, design={k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                                    for k, v in design.items() if k != "fixed_permutation"})
    return records, summary, design


def _offset(effects, torques, truth):
    """The torque offset [N m]: 5 % (1x) of the median torque of the dataset's first ramp, relaxation or creep."""
    m0 = EFFECT_SIZES["torque_offset"]["fraction"] * effects["torque_offset"] * float(np.median(np.abs(torques)))
    truth.injected["torque_offset_nm"] = m0
    return m0


# ------------------------------------------------------------------------------------------ export writers
#: TRIOS step names and RheoCompass result names of each test kind
STEP_NAMES = {"amplitude_sweep": ("Amplitude sweep", "Amplitude Sweep"),
              "frequency_sweep": ("Frequency sweep", "Frequency Sweep"),
              "constant_shear_rate": ("Peak hold", "Rotation"), "stress_relaxation": ("Stress relaxation", "Step Strain"),
              "creep_recovery": ("Creep", "Creep Recovery")}


def _columns(ch: dict, design: dict, trios: bool, oscillation: bool) -> list[tuple[str, str, np.ndarray]]:
    """(label, unit, values in that unit) of an export, in the instrument's labels and the design's units."""
    strain_pct = design["strain_unit"] == "%"
    torque_unit = design["torque_unit"]
    torque_factor = TORQUE_UNITS[torque_unit]
    deg = 180.0 / np.pi
    if trios:
        torque_unit = torque_unit.replace("·", ".")
        spec = [("Step time", "s", "time", 1.0), ("Time", "s", "total_time", 1.0)]
        if oscillation:
            spec += [("Storage modulus", "Pa", "storage_modulus", 1.0), ("Loss modulus", "Pa", "loss_modulus", 1.0),
                     ("Tan(delta)", "", "loss_factor", 1.0),
                     ("Oscillation strain", "%" if strain_pct else "", "shear_strain", 100.0 if strain_pct else 1.0),
                     ("Oscillation stress", "Pa", "shear_stress", 1.0),
                     ("Frequency", "Hz", "frequency", 1.0) if design["frequency_unit"] == "Hz"
                     else ("Angular frequency", "rad/s", "angular_frequency", 1.0),
                     ("Oscillation torque", torque_unit, "torque", torque_factor),
                     ("Oscillation displacement", "rad", "deflection_angle", 1.0),
                     ("Phase angle", "°", "phase_angle", deg), ("Raw phase", "°", "raw_phase", deg)]
        else:
            spec += [("Stress", "Pa", "shear_stress", 1.0),
                     ("Strain", "%" if strain_pct else "", "shear_strain", 100.0 if strain_pct else 1.0),
                     ("Shear rate", "1/s", "shear_rate", 1.0), ("Modulus", "Pa", "relaxation_modulus", 1.0),
                     ("Torque", torque_unit, "torque", torque_factor), ("Displacement", "rad", "deflection_angle", 1.0)]
        spec += [("Temperature", "°C", "temperature", 1.0), ("Normal force", "N", "normal_force", 1.0),
                 ("Gap", "µm", "gap", 1e6)]
    else:
        spec = [("Time", "[s]", "total_time", 1.0), ("Interval Time", "[s]", "time", 1.0)]
        if oscillation:
            spec.append(("Frequency", "[Hz]", "frequency", 1.0) if design["frequency_unit"] == "Hz"
                        else ("Angular Frequency", "[rad/s]", "angular_frequency", 1.0))
        spec += [("Shear Strain", "[%]" if strain_pct else "[1]", "shear_strain", 100.0 if strain_pct else 1.0),
                 ("Shear Rate", "[1/s]", "shear_rate", 1.0), ("Shear Stress", "[Pa]", "shear_stress", 1.0),
                 ("Storage Modulus", "[Pa]", "storage_modulus", 1.0), ("Loss Modulus", "[Pa]", "loss_modulus", 1.0),
                 ("Loss Factor", "[1]", "loss_factor", 1.0), ("Phase Shift Angle", "[°]", "phase_angle", deg),
                 ("Raw Phase", "[°]", "raw_phase", deg), ("Relaxation Modulus", "[Pa]", "relaxation_modulus", 1.0),
                 ("Torque", f"[{torque_unit}]", "torque", torque_factor),
                 ("Deflection Angle", "[mrad]", "deflection_angle", 1e3), ("Normal Force", "[N]", "normal_force", 1.0),
                 ("Gap", "[mm]", "gap", 1e3), ("Temperature", "[°C]", "temperature", 1.0)]
    values = dict(ch)
    if oscillation:
        with np.errstate(divide="ignore", invalid="ignore"):
            values["loss_factor"] = ch["loss_modulus"] / ch["storage_modulus"]
    return [(label, unit, np.asarray(values[key], float) * f) for label, unit, key, f in spec if key in values]


def _cell(value: float, comma: bool) -> str:
    """A number as the instrument prints it (7 significant digits; decimal comma where the locale has one)."""
    if not np.isfinite(value):
        return ""
    text = f"{value:.7G}" if comma else f"{value:.7g}"
    return text.replace(".", ",") if comma else text


def rheocompass_text(record: dict, design: dict, test_name: str, measuring_system: str | None = None) -> str:
    """A RheoCompass export of one test (``instrument_formats.md`` 2.5): ``rheocompass_utf16`` is the simple header
    (``Test:``/``Result:``/``Interval:``, column, sub-label and ``[unit]`` rows, ``Point No.`` ... ``Status``,
    decimal comma), ``rheocompass_utf8`` the project header (``Interval and data points:``, ``Interval data:``,
    decimal point). CRLF line ends; a ``Measuring System:`` row when given."""
    kind = record["meta"]["test"]
    cols = _columns(record["channels"], design, False, kind in ("amplitude_sweep", "frequency_sweep"))
    comma = design["format"] == "rheocompass_utf16"
    labels = ["Point No."] + [c[0] for c in cols] + ["Status"]
    units = [""] + [c[1] for c in cols] + [""]
    n = cols[0][2].size
    result = STEP_NAMES[kind][1]
    lines = []
    if comma:
        lines += [f"Test:\t{test_name}", f"Result:\t{result}"]
        if measuring_system:
            lines.append(f"Measuring System:\t{measuring_system}")
        lines += ["Interval:\t1", "\t".join(labels), "\t" * (len(labels) - 1), "\t".join(units)]
        lead = ""
    else:
        lines += ["Project:\tindependent rheometer", "", f"Test:\t{test_name}", ""]
        if measuring_system:
            lines += [f"Measuring System:\t{measuring_system}", ""]
        lines += [f"Result:\t{result}", "", f"Interval and data points:\t1\t{n}", "Interval data:\t" + "\t".join(labels),
                  "\t" * len(labels), "\t" + "\t".join(units)]
        lead = "\t"
    for i in range(n):
        lines.append(lead + "\t".join([str(i + 1)] + [_cell(c[2][i], comma) for c in cols] + ["Dy_auto"]))
    return "\r\n".join(lines) + "\r\n"


def trios_text(records: list[dict], design: dict, file_name: str, diameter_mm: float, gap_m: float) -> str:
    """A TA TRIOS "Export -> Text" file of one sample (``instrument_formats.md`` 2.1): header, geometry section,
    one ``[step]`` per test (name, column row, unit row, tab-separated data with decimal points)."""
    steps = [STEP_NAMES[r["meta"]["test"]][0] for r in records]
    meta = records[0]["meta"]
    lines = [f"Filename\t{file_name}", "Instrument name\tDHR-2 0000-0000 (independent generator)",
             "Operator\tcalibration", f"rundate\t{meta['started_at'][8:10]}/{meta['started_at'][5:7]}/"
             f"{meta['started_at'][:4]}", f"Sample name\t{meta['specimen']} {meta['sample']}",
             f"Geometry name\t{diameter_mm:.1f}mm parallel plate", "Procedure name\tindependent protocol"]
    lines += [f"\t{s}" for s in steps] + ["proceduresegments\t" + "#".join(steps), "[Geometry Parameters]",
                                           f"Diameter\t{diameter_mm:.1f} mm", f"Gap\t{gap_m * 1e6:.1f} µm"]
    for k, r in enumerate(records, start=1):
        cols = _columns(r["channels"], design, True, r["meta"]["test"] in ("amplitude_sweep", "frequency_sweep"))
        lines += ["[step]", f"{steps[k - 1]} - {k}", "\t".join(c[0] for c in cols), "\t".join(c[1] for c in cols)]
        lines += ["\t".join(_cell(c[2][i], False) for c in cols) for i in range(cols[0][2].size)]
    return "\n".join(lines) + "\n"


def _write_bytes(path, data: bytes):
    def _w(tmp):
        with open(tmp, "wb") as fh:
            fh.write(data)
    return atomic_write(path, _w)


def write_dataset_folder(seed: int, folder, effects: dict | None = None, truth_path=None) -> dict:
    """Write one generated dataset as a user drops it in ``raw/``: instrument exports, ``samples.csv`` and
    ``dataset.yaml`` in ``folder`` (its name is the dataset name); the truth (law, kernel, design, effects and
    what was injected) goes to ``truth_path`` (default ``<folder>.truth.json`` beside the folder, outside what
    the pipeline reads) and is returned."""
    folder = Path(folder)
    records, truth, design = simulate_folder(seed, effects, folder.name)
    diameter_mm = truth["radius_mm"] * 2.0
    source = design["geometry_source"]
    rows = []
    if design["format"] == "trios_text":
        by_sample: dict = {}
        for r in records:
            by_sample.setdefault((r["meta"]["specimen"], r["meta"]["sample"]), []).append(r)
        for (spec, smp), recs in by_sample.items():
            name = f"{spec}_{smp}.txt"
            _write_bytes(folder / name, trios_text(recs, design, name, diameter_mm, recs[0]["meta"]["gap_m"])
                         .encode("utf-8"))
            rows += [_sheet_row(r, name, source, truth, block=k) for k, r in enumerate(recs, start=1)]
    else:
        system = f"PP{diameter_mm:02.0f}" if source == "export" else None
        for r in records:
            m = r["meta"]
            name = f"{m['specimen']}_{m['sample']}_{m['order']:02d}_{m['test']}.csv"
            text = rheocompass_text(r, design, name[:-4], system)
            data = (b"\xff\xfe" + text.encode("utf-16-le")) if design["format"] == "rheocompass_utf16" else (
                text.encode("utf-8"))
            _write_bytes(folder / name, data)
            rows.append(_sheet_row(r, name, source, truth))
    sheet = "\n".join([",".join(SHEET_COLUMNS)] + [",".join(row.get(c, "") for c in SHEET_COLUMNS) for row in rows])
    write_text(sheet + "\n", folder / "samples.csv")
    # quoted: a folder named off, no or yes is a string, not a YAML 1.1 boolean
    yaml_lines = [f"name: {json.dumps(folder.name)}", "material: generated soft solid (independent generator; truth withheld)",
                  f"temperature_c: {truth['temperature_c']}", "instrument: independent parallel-plate rheometer "
                  f"({design['format']})", "license: CC0-1.0",
                  "citation: generated by benchmarks/independent_rheometer.py"]
    if source == "yaml":
        yaml_lines += ["geometry:", "  type: parallel plate", f"  diameter_mm: {diameter_mm:g}"]
    write_text("\n".join(yaml_lines) + "\n", folder / "dataset.yaml")
    truth_path = Path(truth_path) if truth_path else folder.parent / f"{folder.name}.truth.json"
    write_json(truth, truth_path)
    return truth


SHEET_COLUMNS = ("file", "block", "specimen", "sample", "test", "order", "shear_rate_1_per_s", "strain_pct",
                 "stress_pa", "frequency_hz", "radius_mm", "gap_mm", "temperature_c", "started_at")


def _sheet_row(record: dict, file_name: str, source: str, truth: dict, block: int | None = None) -> dict:
    m = record["meta"]
    row = {"file": file_name, "block": "" if block is None else str(block), "specimen": m["specimen"],
           "sample": m["sample"], "test": m["test"], "order": str(m["order"]),
           "temperature_c": f"{m['temperature_c']:g}", "started_at": m["started_at"]}
    for key in ("shear_rate_1_per_s", "strain_pct", "stress_pa", "frequency_hz"):
        if key in m:
            row[key] = f"{m[key]:.6g}"
    if source != "export":
        row["gap_mm"] = f"{m['gap_m'] * 1e3:.6g}"
    if source == "samples":
        row["radius_mm"] = f"{truth['radius_mm']:.6g}"
    return row
