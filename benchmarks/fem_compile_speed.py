"""Compile CPU seconds of the TLED time loops and their speed after compiling (docs/fem_timing.md, issue 14).

Run once per code version, each with its own empty numba cache, e.g.::

    NUMBA_CACHE_DIR=/tmp/cache_a PYTHONPATH=<version a>/src python benchmarks/fem_compile_speed.py
    NUMBA_CACHE_DIR=/tmp/cache_b PYTHONPATH=<version b>/src python benchmarks/fem_compile_speed.py

The first run of a cache compiles (the ``compile`` rows: dynamic relaxation, with and without rigid contact, and
explicit steps on the one-cell block of ``fem.experiments.precompile_kernels``, both internal-force kernels; a
loop is compiled once, so only its first case shows the compile); later runs load it. Speed: a 16 x 16 x 8-cell
block (12,288 tets), best of 5 explicit runs of 1,000 steps and best of 3 dynamic-relaxation solves with a rigid
flat punch. CPU seconds of this process (``time.process_time``), one numba thread; prints JSON.
"""
from __future__ import annotations

import json
import time

import numpy as np

from tissuemech.fem.materials import make_material
from tissuemech.fem.mesh import block_mesh
from tissuemech.fem.tled import (RigidContact, build_model, fixed_group, run_explicit, solve_quasistatic,
                                 translation_group)


def cases(cells):
    # the cases of fem.experiments.precompile_kernels, written out here (not imported) because this script also
    # runs against older versions of the package, where that function builds other cases or is absent
    mesh = block_mesh((1e-2, 1e-2, 5e-3), cells)
    x = mesh.nodes
    top = np.flatnonzero(np.isclose(x[:, 2], x[:, 2].max()))
    base = [fixed_group("base", np.flatnonzero(np.isclose(x[:, 2], 0.0)))]
    material = make_material("neo_hookean", {"mu": 1000.0}, poisson_ratio=0.49)
    push = translation_group("push", top, (0, 0, -1), [0.0, 1.0], [0.0, 1e-5], dofs=(False, False, True))
    punch = RigidContact("flat_punch", tuple(x[top[0]]), 2e-3, (0.0, 0.0, -1.0), np.array([0.0, 1.0]),
                         np.array([0.0, 1e-5]), nodes=top)
    return {"dr": (build_model(mesh, material, [push, *base]), "dr"),
            "dr_contact": (build_model(mesh, material, base, punch), "dr"),
            "explicit": (build_model(mesh, material, base), "explicit")}


def run(model, loop, kernel, n_steps=1):
    if loop == "dr":
        solve_quasistatic(model, [1.0], n_threads=1, kernel=kernel)
    else:
        run_explicit(model, n_steps * 1e-7, dt_s=1e-7, n_outputs=1, track_energy=False, n_threads=1, kernel=kernel)


def best(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return round(min(times), 4)


def main() -> dict:
    out = {}
    for name, (model, loop) in cases((2, 2, 1)).items():
        for kernel in ("vectorised", "generic"):
            t0 = time.process_time()
            run(model, loop, kernel)
            out[f"compile {name}/{kernel}"] = round(time.process_time() - t0, 3)
    big = cases((16, 16, 8))
    for kernel in ("vectorised", "generic"):
        model = big["explicit"][0]
        out[f"explicit 1000 steps/{kernel}"] = best(lambda: run(model, "explicit", kernel, 1000), 5)
        contact = big["dr_contact"][0]
        out[f"dr contact solve/{kernel}"] = best(lambda: run(contact, "dr", kernel), 3)
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=1))
