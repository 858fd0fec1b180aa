"""Timing of the QLV / beyond-QLV parallel-plate forward model and of a QLV fit on thesis-sized data.

Run: NUMBA_CACHE_DIR=.numba_cache .venv/bin/python benchmarks/bench_qlv_plate.py
Prints per-evaluation times (8 Gauss radii, every radius with its own history), QLV's creep and amplitude sweep
through the plate per radius against one pass of the plate's apparent elastic law, side by side, and the wall time of a
least-squares fit of QLV (odd-polynomial instantaneous law, 4 fixed Prony times) to noise-free apparent
rim stress of CSR ramps at 0.001/0.01/0.05/0.1 1/s to 50 % plus ramp-hold relaxation at 1/10/20/40 %.
"""
from __future__ import annotations

import time

import numpy as np
from scipy.optimize import least_squares

from tissuemech.models.base import ConstitutiveModel, ParamSpec
from tissuemech.models.beyond_qlv import MaxwellBranchModel, PipkinRogersModel, SchaperyModel
from tissuemech.models.plate import forward_plate, oscillation_moduli
from tissuemech.models.qlv import LinearElasticShear, QLVModel, qlv_params

R = 0.01


class OddPolynomialShear(ConstitutiveModel):
    def __init__(self):
        super().__init__(name="poly3", family="hyperelastic",
                         param_specs=tuple(ParamSpec(f"a{k}", "Pa", 1.0) for k in (1, 2, 3)),
                         responses=frozenset({"elastic_shear"}))

    def elastic_shear_stress(self, p, strain):
        g = np.asarray(strain, float)
        return p["a1"] * g + p["a2"] * g ** 3 + p["a3"] * g ** 5


def thesis_runs():
    runs = []
    for rate in (0.001, 0.01, 0.05, 0.1):
        t = np.linspace(0.0, 0.5 / rate, 250)
        runs.append((t, rate * t))
    for gamma0 in (0.01, 0.1, 0.2, 0.4):
        t = np.concatenate([np.linspace(0.0, 0.1, 20), np.geomspace(0.1, 300.0, 300)[1:]])
        runs.append((t, np.minimum(t / 0.1, 1.0) * gamma0))
    return runs


def timed(fn, repeat=20):
    fn()                                   # compile / warm
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t0) / repeat


def main():
    runs = thesis_runs()
    n_points = sum(t.size for t, _ in runs)
    qlv = QLVModel(OddPolynomialShear(), 4)
    true = qlv_params(qlv, {"a1": 160.0, "a2": 400.0, "a3": 2000.0}, [0.05, 0.25, 0.2, 0.15])
    data = [forward_plate(qlv, true, t, g, R) for t, g in runs]

    def evaluate(model, p):
        return [forward_plate(model, p, t, g, R) for t, g in runs]

    print(f"data: {len(runs)} runs, {n_points} points, 8 Gauss radii")
    print(f"QLV (poly3, prony4)        one evaluation of all runs: {1e3 * timed(lambda: evaluate(qlv, true)):.2f} ms")
    pr = PipkinRogersModel(OddPolynomialShear(), 4)
    p_pr = dict(true, kappa=1.0, gamma_s=0.2)
    print(f"Pipkin-Rogers (poly3)      one evaluation of all runs: {1e3 * timed(lambda: evaluate(pr, p_pr)):.2f} ms")
    sch = SchaperyModel(4)
    p_s = qlv_params(QLVModel(LinearElasticShear(), 4), {"G0": 160.0}, [0.05, 0.25, 0.2, 0.15])
    p_s.update(c_shift=2.0, e_e=1.0, e_2=1.0)
    print(f"Schapery (prony4)          one evaluation of all runs: {1e3 * timed(lambda: evaluate(sch, p_s)):.2f} ms")
    mx = MaxwellBranchModel(OddPolynomialShear(), 4, "ogden")
    p_m = {"a1": 60.0, "a2": 400.0, "a3": 2000.0, "mu_b1": 10.0, "mu_b2": 40.0, "mu_b3": 30.0, "mu_b4": 20.0,
           "alpha_b": -5.0}
    print(f"Maxwell Ogden branches x4  one evaluation of all runs: "
          f"{1e3 * timed(lambda: evaluate(mx, p_m), repeat=3):.2f} ms")
    mx_lin = MaxwellBranchModel(OddPolynomialShear(), 4, "neo_hookean")
    print(f"Maxwell linear branches x4 one evaluation of all runs: "
          f"{1e3 * timed(lambda: evaluate(mx_lin, p_m)):.2f} ms")
    amps = np.geomspace(1e-3, 0.5, 20)
    print(f"QLV amplitude sweep (20 amplitudes, 10 cycles x 128 points, 8 radii): "
          f"{1e3 * timed(lambda: oscillation_moduli(qlv, true, 1.0, amps, R), repeat=5):.1f} ms")

    t_cr = np.concatenate([np.linspace(0, 0.05, 6), 0.05 + np.geomspace(0.01, 150, 150),
                           150.06 + np.linspace(0, 0.05, 6)[1:], 150.11 + np.geomspace(0.01, 150, 150)])
    s_cr = np.interp(t_cr, [0, 0.05, 150.06, 150.11, 400], [0, 10, 10, 0, 0])
    print(f"creep-recovery ({t_cr.size} points): QLV exact one-pass {1e3 * timed(lambda: qlv.creep_strain(true, t_cr, s_cr)):.2f} ms, "
          f"Pipkin-Rogers stepper {1e3 * timed(lambda: pr.creep_strain(p_pr, t_cr, s_cr), repeat=3):.1f} ms, "
          f"Maxwell (generic O(n^2)) {1e3 * timed(lambda: mx.creep_strain(p_m, t_cr, s_cr), repeat=1):.0f} ms")
    from tissuemech.models.plate import creep_rim_strain
    print(f"torque-controlled plate creep ({t_cr.size} points, 8 radii): QLV "
          f"{1e3 * timed(lambda: creep_rim_strain(qlv, true, t_cr, s_cr, R), repeat=3):.1f} ms")
    side_by_side_plate_paths(qlv, true, t_cr, s_cr, amps)

    names = qlv.param_names
    scale = np.concatenate([np.full(d.size, 1.0) / (0.05 + 0.01 * np.abs(d)) for d in data])
    target = np.concatenate(data)

    def residual(x):
        p = dict(zip(names, x))
        return (np.concatenate(evaluate(qlv, p)) - target) * scale

    x0 = [100.0, 100.0, 100.0, 0.3, 0.3, 0.3, 0.3]
    t0 = time.perf_counter()
    fit = least_squares(residual, x0, bounds=(0, [1e5, 1e5, 1e5, 1e3, 1e3, 1e3, 1e3]), x_scale="jac")
    wall = time.perf_counter() - t0
    rel = max(abs(fit.x[i] / true[n] - 1) for i, n in enumerate(names))
    print(f"QLV fit (7 parameters, {n_points} points through the plate integral): {wall:.2f} s, "
          f"{fit.nfev} residual evaluations (+ finite-difference Jacobians), max relative parameter error {rel:.1e}")


def side_by_side_plate_paths(qlv, p, t_cr, s_cr, amps):
    """QLV through the plate two ways, timed in one run: every Gauss radius with its own history (the generic paths:
    the branch-drive stepper for creep, one history per radius and amplitude for the sweep) against one relaxation
    pass of the plate's apparent elastic stress (``models.plate.apparent_elastic_stress``, what the fit runs)."""
    from tissuemech.models.plate import (apparent_rim_stress, creep_rim_strain, first_harmonic_moduli, gauss_radii,
                                         stress_histories)
    from tissuemech.models.qlv import stress_controlled_strain

    r, w = gauss_radii(8, R)

    def creep_per_radius():
        drives, taus = qlv.branch_drives(p)
        return stress_controlled_strain(drives, taus, t_cr, s_cr, strain_factors=r / R, weights=4 * w * r * r / R ** 3)

    t = np.linspace(0.0, 3.0, 3 * 48 + 1)
    rim = amps[:, None] * np.sin(2 * np.pi * t)[None, :]
    sel = t >= 2.0 - 1e-12

    def sweep_per_radius():
        strain = ((r / R)[None, :, None] * rim[:, None, :]).reshape(-1, t.size)
        sigma = stress_histories(qlv, p, t, strain).reshape(amps.size, r.size, t.size)
        stress = apparent_rim_stress(2 * np.pi * np.einsum("j,ajn->an", w * r * r, sigma), R)
        return first_harmonic_moduli(t[sel][:-1], rim[:, sel][:, :-1], stress[:, sel][:, :-1], 1.0)

    def sweep_apparent():
        return oscillation_moduli(qlv, p, 1.0, amps, R, n_cycles=3, n_analysed=1, points_per_cycle=48)

    for label, slow, fast in (("plate creep", creep_per_radius, lambda: creep_rim_strain(qlv, p, t_cr, s_cr, R)),
                              ("amplitude sweep (3 cycles x 48)", sweep_per_radius, sweep_apparent)):
        a, b = slow(), fast()
        diff = max(float(np.max(np.abs(np.asarray(x) - np.asarray(y)) / np.maximum(np.abs(np.asarray(x)), 1e-300)))
                   for x, y in zip(np.atleast_2d(a), np.atleast_2d(b)))
        ts, tf = timed(slow, repeat=3), timed(fast, repeat=10)
        print(f"QLV {label}: per radius {1e3 * ts:.2f} ms, apparent elastic law {1e3 * tf:.2f} ms, "
              f"{ts / tf:.1f}x; largest relative difference {diff:.1e}")


if __name__ == "__main__":
    main()
