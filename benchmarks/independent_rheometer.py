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

Entry point: :func:`generate` ``(seed, effects=None) -> (runs, truth)``.
"""
from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field

import numpy as np
from scipy.special import gamma as gamma_fn

from tissuemech.canonical import make_run_dataset

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
    settings = {
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
    effects = dict(effects or {})
    unknown = set(effects) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown effects {sorted(unknown)}; known: {EFFECTS}")
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
