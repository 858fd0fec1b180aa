"""The CUDA solver against the CPU solver, in numba's CUDA simulator (no GPU needed) and on a GPU if any.

The oracle is the CPU kernel (itself checked against closed forms and FElupe in the other FEM tests): the GPU must
reproduce its explicit steps, reactions, torques, kinetic energy, viscoelastic states, contact and dynamic relaxation.
The simulator runs the kernels as Python in a subprocess (``NUMBA_ENABLE_CUDASIM`` is read when numba.cuda is
first imported), on meshes of a few elements.
"""
import json
import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from tissuemech.fem.mesh import block_mesh
    from tissuemech.fem.materials import make_material
    from tissuemech.fem.tled import (RigidContact, build_model, fixed_group, rotation_group, run_explicit,
                                     solve_quasistatic, translation_group)
    from tissuemech.fem import cuda as fc

    THREADS = int(sys.argv[1])

    def rel(a, b):
        a, b = np.asarray(a, float), np.asarray(b, float)
        scale = np.abs(b).max()
        return float(np.abs(a - b).max() / scale) if scale > 0 else float(np.abs(a).max())

    L = 1e-2
    out = {}
    # explicit: a twisted, shaken column (rotation of the top, fixed bottom, initial shear velocity)
    mesh = block_mesh((L, L, L), (1, 1, 2))
    z = mesh.nodes[:, 2]
    explicit = {
        "neo_hookean-anp-float64": ("neo_hookean", {"mu": 1000.0}, True, "float64", {}),
        "neo_hookean-anp-float32": ("neo_hookean", {"mu": 1000.0}, True, "float32", {}),
        "saint_venant_kirchhoff-float64": ("saint_venant_kirchhoff", {"mu": 1000.0}, False, "float64", {}),
        "qlv2_lopez_pamies2-anp-float64": ("lopez_pamies2", {"mu1": 900.0, "alpha1": 1.2, "mu2": 100.0, "alpha2": 3.0},
                                           True, "float64", dict(prony_g=(0.3, 0.2), prony_tau_s=(3e-5, 1e-4))),
        "qlv2_pipkin_rogers-mooney_rivlin-float64": ("mooney_rivlin", {"C10": 300.0, "C01": 100.0}, False, "float64",
                                                     dict(prony_tau_s=(3e-5, 1e-4), pipkin_rogers={
                                                         "beta": [0.8, 0.4], "kappa": [1.5, -0.5], "gamma_s": 0.1})),
    }
    for case, (key, params, anp, prec, extra) in explicit.items():
        mat = make_material(key, params, poisson_ratio=0.45, density_kg_m3=1000.0, **extra)
        groups = [rotation_group("top", np.flatnonzero(np.isclose(z, L)), [0, 1e-3], [0, 0.3]),
                  fixed_group("bottom", np.flatnonzero(np.isclose(z, 0)))]
        model = build_model(mesh, mat, groups, anp=anp, precision=prec)
        v0 = np.zeros_like(mesh.nodes)
        v0[:, 0] = 0.01 * z / L
        cpu = run_explicit(model, 12e-5, dt_s=1e-5, v0_m_s=v0, n_outputs=4)
        gpu = fc.run_explicit_gpu(model, 12e-5, dt_s=1e-5, v0_m_s=v0, n_outputs=4, batch=5, threads_per_block=THREADS)
        out[case] = {"u": rel(gpu.displacement_m, cpu.displacement_m),
                     "u_previous": rel(gpu.previous_displacement_m, cpu.previous_displacement_m),
                     "u_max": float(np.abs(cpu.displacement_m).max()),
                     "times_equal": bool(np.array_equal(gpu.time_s, cpu.time_s)),
                     "reaction": max(rel(gpu.reaction_force_n[n], cpu.reaction_force_n[n]) for n in ("top", "bottom")),
                     "torque": rel(gpu.torque_nm["top"], cpu.torque_nm["top"]),
                     "kinetic_energy": rel(gpu.kinetic_energy_j, cpu.kinetic_energy_j),
                     "states": max((rel(a, b) for a, b in zip(gpu.state, cpu.state) if b.size), default=0.0),
                     "state_max": max((float(np.abs(b).max()) for b in cpu.state if b.size), default=0.0),
                     "kernel": gpu.kernel}
    # explicit: a rigid sphere pressed into a block under a growing external load on its top
    mesh = block_mesh((L, L, L / 2), (2, 2, 1))
    x = mesh.nodes
    top = np.flatnonzero(np.isclose(x[:, 2], L / 2))
    bottom = fixed_group("bottom", np.flatnonzero(np.isclose(x[:, 2], 0)))
    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45)
    sphere = RigidContact("sphere", (L / 2, L / 2, L / 2 + 3e-3), 3e-3, (0, 0, -1), [0, 1e-3], [0, 2e-3])
    fext = np.zeros_like(x)
    fext[top, 0] = 1e-3
    model = build_model(mesh, mat, [bottom], sphere, external_force_n=fext, external_time_s=[0, 1e-3],
                        external_scale=[0, 1])
    cpu = run_explicit(model, 150 * 2e-6, dt_s=2e-6, n_outputs=3, damping_1_s=50.0)
    gpu = fc.run_explicit_gpu(model, 150 * 2e-6, dt_s=2e-6, n_outputs=3, damping_1_s=50.0, batch=40,
                              threads_per_block=THREADS)
    out["contact-sphere-load"] = {"u": rel(gpu.displacement_m, cpu.displacement_m),
                                  "contact": rel(gpu.contact_force_n, cpu.contact_force_n),
                                  "contact_max": float(np.abs(cpu.contact_force_n).max()),
                                  "kinetic_energy": rel(gpu.kinetic_energy_j, cpu.kinetic_energy_j)}
    # dynamic relaxation: a flat punch (one prescribed node) into a QLV block, two load increments
    center = top[np.argmin(np.linalg.norm(x[top, :2] - L / 2, axis=1))]
    mat = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.45, prony_g=(0.3,), prony_tau_s=(0.5,))
    punch = translation_group("punch", [center], (0, 0, -1), [0, 1.0], [0, 1e-3], dofs=(False, False, True))
    model = build_model(mesh, mat, [punch, bottom])
    cpu = solve_quasistatic(model, [0.5, 1.0])
    gpu = fc.solve_quasistatic_gpu(model, [0.5, 1.0], threads_per_block=THREADS)
    out["relaxation-punch-qlv"] = {"u": float(np.abs(gpu.displacement_m - cpu.displacement_m).max()),
                                   "tol_m": 1e-6 * model.min_altitude_m,
                                   "u_max": float(np.abs(cpu.displacement_m).max()),
                                   "reaction": rel(gpu.reaction_force_n["punch"], cpu.reaction_force_n["punch"]),
                                   "states": max(rel(a, b) for a, b in zip(gpu.state, cpu.state) if b.size),
                                   "iterations_cpu": cpu.iterations.tolist(), "iterations_gpu": gpu.iterations.tolist()}
    json.dump(out, sys.stdout)
""")


def _run(env_extra, threads):
    env = {**os.environ, **env_extra}
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(threads)], capture_output=True, text=True, env=env,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _check(results, device: bool):
    explicit = [c for c in results if c.endswith(("float64", "float32"))]
    assert len(explicit) == 5
    for case in explicit:
        r = results[case]
        assert r["kernel"] == "cuda"
        assert r["times_equal"], case
        assert r["u_max"] > 1e-5, case  # the plate rotation and the initial velocity moved the nodes
        f32 = case.endswith("float32")
        assert r["u"] < (1e-5 if f32 else 1e-10), (case, r)
        assert r["u_previous"] < (1e-5 if f32 else 1e-10), (case, r)
        # reactions are sums of opposing element forces: compared relative to their largest value
        assert r["reaction"] < (1e-3 if f32 else 1e-9), (case, r)
        assert r["torque"] < (1e-4 if f32 else 1e-10), (case, r)
        assert r["kinetic_energy"] < (1e-5 if f32 else 1e-10), (case, r)
        if "qlv" in case:
            assert r["state_max"] > 0, case  # the relaxation states were driven
            assert r["states"] < 1e-10, (case, r)
    c = results["contact-sphere-load"]
    assert c["contact_max"] > 1e-3  # the sphere pressed the block
    assert c["u"] < 1e-10 and c["contact"] < 1e-9 and c["kinetic_energy"] < 1e-10, c
    d = results["relaxation-punch-qlv"]
    assert d["u_max"] > 0.9e-3
    # the GPU sums each iteration's Rayleigh quotient in another order than the CPU: the iterates differ by
    # rounding and may stop an iteration apart, so the solutions agree within the stopping tolerance
    assert d["u"] < 10 * d["tol_m"], d
    assert d["reaction"] < 1e-5 and d["states"] < 1e-5, d
    if not device:  # the simulator runs one block: the sums happen in the CPU's order
        assert d["iterations_gpu"] == d["iterations_cpu"], d


def test_gpu_solver_matches_cpu_in_simulator():
    _check(_run({"NUMBA_ENABLE_CUDASIM": "1"}, threads=4), device=False)


@pytest.mark.gpu
def test_gpu_solver_matches_cpu_on_gpu():
    from tissuemech.fem import cuda as fc

    if not fc.available():
        pytest.skip("no CUDA device")
    _check(_run({}, threads=256), device=True)


def _model(law, params, **kw):
    from tissuemech.fem.materials import make_material
    from tissuemech.fem.mesh import block_mesh
    from tissuemech.fem.tled import build_model

    return build_model(block_mesh((1e-2, 1e-2, 1e-2), (1, 1, 1)), make_material(law, params, poisson_ratio=0.45, **kw))


def test_stretch_laws_are_refused_with_the_reason():
    from tissuemech.fem import cuda as fc

    model = _model("ogden1", {"mu1": 1e3, "alpha1": 5.0})
    assert "Ogden" in fc.unsupported_reason(model)
    with pytest.raises(NotImplementedError, match="stretch-based laws"):
        fc.DeviceProblem(model, 1e-5, 10)


def test_block_size_must_be_a_power_of_two():
    from tissuemech.fem import cuda as fc

    with pytest.raises(ValueError, match="power of two"):
        fc.DeviceProblem(_model("neo_hookean", {"mu": 1e3}), 1e-5, 10, threads_per_block=96)


def test_invariant_and_viscoelastic_laws_are_supported():
    from tissuemech.fem import cuda as fc

    assert fc.unsupported_reason(_model("neo_hookean", {"mu": 1e3}, prony_g=(0.2, 0.1), prony_tau_s=(0.1, 1.0))) is None
    assert fc.unsupported_reason(_model("saint_venant_kirchhoff", {"mu": 1e3})) is None
    assert fc.unsupported_reason(_model("lopez_pamies2", {"mu1": 900.0, "alpha1": 1.2, "mu2": 100.0, "alpha2": 3.0})) \
        is None
