"""Constructed runs with known residual structure for the diagnosis unit tests.

Not the virtual rheometer (``tissuemech.synth``): a compact homogeneous-shear QLV generator whose *baseline
prediction* is the population truth without the effect, so each detector can be checked against a residual
structure of known kind and size. Plate physics appears only where an effect needs it (rim stress, slip gap).

Truth: sigma_e = 2 C10 g + 4 C20 g^3 (C10 = 50 Pa, C20 = 100 Pa), reduced relaxation g_inf + sum g_i e^{-t/tau_i}
(g = 0.3, 0.2, 0.15; tau = 0.1, 1, 10 s). Design: specimens x samples, each sample tested in the order AS (1 Hz),
FS (0.1-20 Hz), CSR (0.001, 0.01, 0.1 1/s to 50 %), SR (1, 10, 20, 40 %, rise time 0.02 s; 0.5 s x magnitude
with the finite_rise_time effect, whose baseline is a step analysis).
"""
from __future__ import annotations

import numpy as np

from tissuemech.canonical import make_run_dataset
from tissuemech.diagnosis.evidence import fit_prony_relaxation
from tissuemech.models.recursion import prony_branch_histories

C10, C20 = 50.0, 100.0
G = np.array([0.3, 0.2, 0.15])
TAUS = np.array([0.1, 1.0, 10.0])
RADIUS = 12.5e-3
GAP = 2e-3
RATES = (0.001, 0.01, 0.1)
SR_LEVELS = (0.01, 0.1, 0.2, 0.4)
TAUS_FIT = np.array([0.1, 1.0, 10.0, 100.0])


def sigma_e(g, c20=C20):
    return 2 * C10 * g + 4 * c20 * g ** 3


def g_of_strain(g, delta=0.0, gs=0.15):
    """Strain-dependent Prony weights g_i(gamma) = g_i0 + delta_i g^2/(g^2 + gs^2) (delta scales G)."""
    frac = g ** 2 / (g ** 2 + gs ** 2)
    return G[:, None] * (1.0 + delta * (frac[None, :] - 0.5))


def shear_history(time, strain, nonsep=0.0, c20=C20):
    """QLV (nonsep = 0) or Pipkin-Rogers (branch drives g_i(gamma) sigma_e(gamma)) stress history."""
    se = sigma_e(strain, c20)
    gi = g_of_strain(strain, nonsep) if nonsep else np.repeat(G[:, None], strain.size, axis=1)
    drive = gi * se[None, :]
    h = prony_branch_histories(time, drive, TAUS)
    r_inf = (1.0 - gi.sum(axis=0)) * se
    return r_inf + h.sum(axis=0)


def complex_modulus(omega):
    g0 = 2 * C10
    wt = omega[:, None] * TAUS[None, :]
    return g0 * ((1 - G.sum()) + np.sum(G * (wt ** 2 + 1j * wt) / (1 + wt ** 2), axis=1))


def _noise(rng, x, rel=0.01, floor=0.03):
    return x + rng.normal(0.0, 1.0, x.shape) * np.sqrt((rel * x) ** 2 + floor ** 2)


def make_design(effect: str | None = None, magnitude: float = 1.0, seed: int = 0, n_specimens: int = 6,
                n_samples: int = 3, n_points: int = 30, with_normal_force: bool = False,
                specimen_sd: float = 0.25, temperature_effect: float = 0.0, c20: float = C20):
    """Runs and baseline predictions with one effect injected.

    Parameters
    ----------
    effect : catalogue id (or None for the null design); magnitude scales the effect (1 = typical)
    specimen_sd : log-normal SD of the specimen stiffness (sample SD is 0.1)
    temperature_effect : relative stiffness change per degC of bath temperature (not a catalogue cause)
    c20 : stiffening coefficient of the instantaneous law (Pa); 0 gives a linear instantaneous law

    Returns
    -------
    runs : list of canonical datasets, predictions : list of dicts, fit_info : dict
    """
    rng = np.random.default_rng(seed)
    runs, preds = [], []
    fit_info = {"target": "torque", "relaxation": "ramp"}
    if effect == "rim_stress_nonlinearity":
        fit_info["target"] = "thesis"  # homogeneous law vs reported 2M/(pi R^3): biased for this truth
    if effect == "finite_rise_time":
        fit_info["relaxation"] = "step"
    spec_scale = np.exp(rng.normal(0, specimen_sd, n_specimens))
    if effect == "outlier_specimen":
        spec_scale[0] = np.exp(np.mean(np.log(spec_scale[1:]))) * (1 + 1.5 * magnitude)
    session_t = 0.0
    for b in range(n_specimens):
        session_t = 0.0  # each specimen (brain) is tested in its own session
        for s in range(n_samples):
            scale = spec_scale[b] * np.exp(rng.normal(0, 0.1))
            order = 0
            tests = [("amplitude_sweep", None), ("frequency_sweep", None)]
            tests += [("constant_shear_rate", r) for r in RATES] + [("stress_relaxation", lv) for lv in SR_LEVELS]
            for test, cond in tests:
                order += 1
                session_t += 300.0
                k = scale
                if effect == "elapsed_time_drift":
                    k *= 1 + 0.10 * magnitude * session_t / 3600.0
                if effect == "preconditioning" and order == 1:
                    k *= 1 + 0.2 * magnitude
                attrs = {"dataset": "constructed", "run": f"b{b}s{s}-{order}-{test}", "test": test,
                         "specimen": f"b{b}", "sample": f"b{b}s{s}", "order": order, "source_file": "none",
                         "source_sha256": "0", "radius_m": RADIUS, "gap_m": GAP}
                cols, pred = {}, {}
                if test == "amplitude_sweep":
                    g0 = np.logspace(-3, np.log10(0.2), n_points)
                    gstar = complex_modulus(np.array([2 * np.pi]))[0]
                    true1 = np.full(g0.size, gstar.real)
                    obs1 = true1 * k
                    if effect == "amplitude_softening":
                        r_inf = 1 - 0.3 * magnitude
                        obs1 = obs1 * (r_inf + (1 - r_inf) / (1 + (g0 / 0.03) ** 1.6))
                    cols = {"shear_strain": g0, "storage_modulus": _noise(rng, obs1, floor=0.03 / g0),
                            "loss_modulus": _noise(rng, np.full(g0.size, gstar.imag) * k, floor=0.03 / g0),
                            "frequency": np.full(g0.size, 1.0), "time": np.arange(g0.size) * 10.0}
                    pred = {"storage_modulus": true1, "loss_modulus": np.full(g0.size, gstar.imag)}
                    attrs["frequency_hz"] = 1.0
                elif test == "frequency_sweep":
                    f = np.logspace(-1, np.log10(20), 12)
                    w = 2 * np.pi * f
                    gstar = complex_modulus(w)
                    obs1 = gstar.real * k
                    if effect == "instrument_inertia":
                        obs1 = obs1 - 2e-7 * magnitude * w ** 2 * 2 * GAP / (np.pi * RADIUS ** 4)
                    cols = {"frequency": f, "angular_frequency": w, "shear_strain": np.full(f.size, 0.01),
                            "storage_modulus": _noise(rng, obs1, floor=3.0),
                            "loss_modulus": _noise(rng, gstar.imag * k, floor=3.0), "time": np.arange(f.size) * 5.0}
                    pred = {"storage_modulus": gstar.real, "loss_modulus": gstar.imag}
                    attrs["strain_pct"] = 1.0
                elif test == "constant_shear_rate":
                    gmax = 0.5
                    strain = np.concatenate([[0.0], np.logspace(-2.5, np.log10(gmax), n_points - 1)])
                    time = strain / cond
                    nonsep = 1.2 * magnitude if effect == "nonseparable_relaxation" else 0.0
                    true = shear_history(time, strain, c20=c20)
                    obs_strain = strain
                    if effect == "wall_slip":
                        # u_s = beta max(0, sigma - sigma_c): +20 % apparent strain at 50 % for magnitude 1
                        sig_c, beta = 20.0, 3e-6 * magnitude
                        # fixed point: the slip displacement depends on the stress it relieves; damped, because
                        # the plain iteration oscillates without converging for strong slip (2x at 0.1 1/s)
                        for _ in range(300):
                            sig = k * shear_history(time, obs_strain, c20=c20)
                            update = strain - 2 * beta * np.maximum(0.0, sig - sig_c) / GAP
                            obs_strain = obs_strain + 0.5 * (update - obs_strain)
                            if np.max(np.abs(update - obs_strain)) < 1e-7:
                                break
                    obs = k * shear_history(time, obs_strain, nonsep, c20=c20)
                    if effect == "rim_stress_nonlinearity":
                        # reported 2M/(pi R^3) of a stiffening law sigma = a1 g + a2 g^3 is a1 g + (2 a2/3) g^3;
                        # the baseline fitted to it the thesis way reproduces it
                        true = 2 * C10 * strain + (2.0 / 3.0) * 4 * C20 * (1 + magnitude) * strain ** 3
                        obs = k * true
                    if effect == "torque_offset":
                        obs = obs + 0.1 * magnitude
                    cols = {"time": time, "shear_strain": strain, "shear_rate": np.full(strain.size, cond),
                            "shear_stress": _noise(rng, obs)}
                    if with_normal_force:
                        psi = strain / RADIUS  # twist per length: gamma_R = psi R
                        torque = cols["shear_stress"] * np.pi * RADIUS ** 3 / 2
                        c01 = 30.0 * magnitude if effect == "unidentified_i2_dependence" else 0.0
                        force = psi * torque / 2 + 0.5 * np.pi * psi ** 2 * RADIUS ** 4 * c01
                        cols.update(torque=torque, deflection_angle=strain * GAP / RADIUS,
                                    normal_force=_noise(rng, force, floor=1e-4))
                    pred = {"shear_stress": true}
                    attrs["shear_rate_1_per_s"] = cond
                else:
                    t_r = 0.02 if effect != "finite_rise_time" else 0.5 * magnitude
                    t_ramp = np.linspace(0, t_r, 6)
                    t_hold = np.logspace(np.log10(t_r * 1.2), np.log10(300), n_points - 6)
                    time = np.concatenate([t_ramp, t_hold])
                    strain = np.minimum(time / t_r, 1.0) * cond
                    nonsep = 1.2 * magnitude if effect == "nonseparable_relaxation" else 0.0
                    true = shear_history(time, strain, c20=c20)
                    obs = k * shear_history(time, strain, nonsep, c20=c20)
                    if effect == "torque_offset":
                        obs = obs + 0.1 * magnitude
                    cols = {"time": time, "shear_strain": strain, "shear_stress": _noise(rng, obs)}
                    pred = {"shear_stress": true}
                    if effect == "finite_rise_time":
                        # the baseline of a step analysis: a Prony series fitted to the hold as if the
                        # final strain had been applied at t = 0, predicting every point as gamma0 G(t)
                        step = fit_prony_relaxation(time, true, strain, TAUS_FIT, ramp_aware=False)
                        pred = {"shear_stress": cond * (step["g_inf_pa"] + np.exp(-time[:, None] / TAUS_FIT)
                                                         @ step["g_pa"])}
                    attrs["strain_pct"] = 100 * cond
                n = len(next(iter(cols.values())))
                cols["total_time"] = np.full(n, session_t)
                # the bath temperature of each test wanders by +-1 degC; an effect not in the catalogue
                # (temperature_effect per degC) scales the measured moduli/stresses with it
                temp = 37.0 + rng.uniform(-1.0, 1.0)
                cols["temperature"] = np.full(n, temp) + rng.normal(0, 0.02, n)
                if temperature_effect:
                    for q in ("shear_stress", "storage_modulus", "loss_modulus"):
                        if q in cols:
                            cols[q] = cols[q] * (1.0 - temperature_effect * (temp - 37.0))
                runs.append(make_run_dataset(cols, attrs))
                preds.append(pred)
    return runs, preds, fit_info
