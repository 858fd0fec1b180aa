"""The CUDA kernel against the CPU kernel, in numba's CUDA simulator (no GPU needed) and on a GPU if any."""
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
    from tissuemech.fem.tled import build_model, fixed_group, rotation_group, run_explicit
    from tissuemech.fem import cuda as fc
    L = 1e-2
    mesh = block_mesh((L, L, L), (1, 1, 2))
    z = mesh.nodes[:, 2]
    out = {}
    cases = [("neo_hookean", {"mu": 1000.0}, True, "float64"),
             ("mooney_rivlin", {"C10": 300.0, "C01": 100.0}, False, "float64"),
             ("saint_venant_kirchhoff", {"mu": 1000.0}, False, "float64"),
             ("neo_hookean", {"mu": 1000.0}, True, "float32")]
    for key, params, anp, prec in cases:
        mat = make_material(key, params, poisson_ratio=0.45, density_kg_m3=1000.0)
        groups = [rotation_group("top", np.flatnonzero(np.isclose(z, L)), [0, 1e-3], [0, 0.3]),
                  fixed_group("bottom", np.flatnonzero(np.isclose(z, 0)))]
        model = build_model(mesh, mat, groups, anp=anp, precision=prec)
        v0 = np.zeros_like(mesh.nodes)
        v0[:, 0] = 0.01 * z / L
        cpu = run_explicit(model, 12e-5, dt_s=1e-5, v0_m_s=v0)
        run = fc.DeviceRun(model, 1e-5, 12, v0_m_s=v0, threads_per_block=16)
        run.advance(12, batch=5)  # three persistent launches
        u, _ = run.displacement()
        ref = cpu.displacement_m
        out[f"{key}-{anp}-{prec}"] = [float(np.abs(u - ref).max() / np.abs(ref).max()), float(np.abs(ref).max())]
    json.dump(out, sys.stdout)
""")


def _run(env_extra):
    env = {**os.environ, **env_extra}
    proc = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _check(results):
    for case, (rel_err, umax) in results.items():
        assert umax > 1e-5, case  # the plate rotation and the initial velocity moved the nodes
        assert rel_err < (5e-6 if case.endswith("float32") else 1e-12), case


def test_persistent_kernel_matches_cpu_in_simulator():
    _check(_run({"NUMBA_ENABLE_CUDASIM": "1"}))


@pytest.mark.gpu
def test_persistent_kernel_matches_cpu_on_gpu():
    from tissuemech.fem import cuda as fc

    if not fc.available():
        pytest.skip("no CUDA device")
    _check(_run({}))


def test_unsupported_features_are_refused():
    from tissuemech.fem import cuda as fc
    from tissuemech.fem.materials import make_material
    from tissuemech.fem.mesh import block_mesh
    from tissuemech.fem.tled import build_model

    model = build_model(block_mesh((1e-2, 1e-2, 1e-2), (1, 1, 1)),
                        make_material("ogden1", {"mu1": 1e3, "alpha1": 5.0}, poisson_ratio=0.45))
    with pytest.raises(NotImplementedError, match="Ogden"):
        fc.DeviceRun(model, 1e-5, 10)
