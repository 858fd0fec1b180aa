"""Time of each pass of the vectorised explicit step, and of the whole step, on a cube (issue 17).

Neo-Hookean with average nodal pressure (the 8e7 updates/s target case): ``kinematics_pass``,
``nodal_pressure_pass``, ``invariant_force_pass`` and ``gather_nodal_forces`` are each run ``--calls`` times in a
row (so each finds its own data in cache: a lower bound of its share of a step), alternating over ``--repeats``
rounds; then the whole explicit step through ``run_explicit`` (``fem_timing.time_cpu``, best of ``--repeats``).
Printed per thread count and storage precision: the median microseconds per pass and the element updates per
second. Compare two checkouts by running this script in each (e.g. a ``git worktree`` of the older commit), one
after the other, more than once. Usage::

    python benchmarks/fem_passes.py --elements 1e4 --threads 1,2 --precisions float64,float32
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from tissuemech.numba_cache import use_source_keyed_cache  # noqa: E402 (before anything imports numba)

use_source_keyed_cache(Path(__file__).resolve().parents[1] / ".numba_cache")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from fem_timing import cube_with_n_elements, machine, setup, time_cpu  # noqa: E402

from tissuemech.fem import vectorised  # noqa: E402
# the vectorised workspace is internal to the solver; a benchmark of its passes builds it the way run_explicit does
from tissuemech.fem.tled import _vector_setup, initial_states, numba_threads  # noqa: E402


def pass_times(model, calls: int, repeats: int) -> dict[str, float]:
    """Median microseconds per call of each pass of the NH + ANP step at a random small displacement."""
    h_state, s_prev, w_prev = initial_states(model, None)
    vec, _, _ = _vector_setup(model, "vectorised", h_state, s_prev, w_prev)
    (conn, d9, vol0, node_ptr, inc_elem, inc_slot, inv_vnode, elo, nlo, g, pe, p_node, fe, n_bad, n_far,
     _sprev, _hstate, jm23a, _s_relaxed, w1a, w2a, _wprev) = vec[1]
    nn = model.kernel_mesh.n_nodes
    u = np.random.default_rng(0).normal(scale=1e-5, size=(nn, 3)).astype(fe.dtype)
    fint = np.zeros((nn, 3), fe.dtype)
    kappa = model.material.bulk_modulus_pa
    passes = {
        "kinematics": lambda: vectorised.kinematics_pass(u, conn, d9, vol0, kappa, pe, jm23a, *g, n_bad, n_far, elo),
        "nodal_pressure": lambda: vectorised.nodal_pressure_pass(pe, node_ptr, inc_elem, inv_vnode, p_node, nlo),
        "force": lambda: vectorised.invariant_force_pass(*g, jm23a, conn, d9, vol0, p_node, w1a, w2a, kappa, 1.0,
                                                         *fe, elo),
        "gather": lambda: vectorised.gather_nodal_forces(fe.reshape(-1), node_ptr, inc_slot, vol0.size, fint, nlo),
    }
    for run in passes.values():
        run()
    times = {name: [] for name in passes}
    for _ in range(repeats):
        for name, run in passes.items():
            t0 = time.perf_counter()
            for _ in range(calls):
                run()
            times[name].append((time.perf_counter() - t0) / calls * 1e6)
    return {name: float(np.median(v)) for name, v in times.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--elements", type=float, default=1e4)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--precisions", default="float64,float32")
    ap.add_argument("--calls", type=int, default=300)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--steps", type=int, default=2000, help="explicit steps per whole-step measurement")
    args = ap.parse_args()
    print("#", machine())
    mesh = cube_with_n_elements(args.elements)
    for precision in args.precisions.split(","):
        model, v0 = setup(mesh, "NH", precision, anp=True)
        for threads in map(int, args.threads.split(",")):
            with numba_threads(threads):
                us = pass_times(model, args.calls, args.repeats)
            step = min(time_cpu(model, v0, args.steps, threads, "vectorised")[0] for _ in range(args.repeats))
            per_step_us = step / args.steps * 1e6
            print(f"{mesh.n_elements} tets {precision} {threads} thr: "
                  + ", ".join(f"{k} {v:.1f}" for k, v in us.items())
                  + f" us (sum {sum(us.values()):.1f}); whole step {per_step_us:.1f} us = "
                  f"{mesh.n_elements / per_step_us:.1f} M updates/s", flush=True)


if __name__ == "__main__":
    main()
