"""The TLED solver on a GPU (issue 18): agreement with the CPU kernel on the device, and the timing table.

Two stages, because device time is scarce and the GPU machine has none of the meshing dependencies:

``reference`` (here, on the CPU): writes to ``--data`` the brain meshes (the pipeline's ~10k-tet MNI mesh, a
~100k-tet one, and a ~1M-tet one made by :func:`tissuemech.fem.mesh.subdivide` of a ~123k-tet one) and the CPU
kernel's results of every agreement case (explicit runs of a cube and the 10k brain, neo-Hookean / Lopez-Pamies /
QLV / Pipkin-Rogers, float64 and float32, rigid contact, dynamic relaxation): displacements, reactions, torques,
kinetic energy, viscoelastic states.

``device`` (on the GPU machine, ``PYTHONPATH=src``): runs the same cases on the GPU and compares; then times the
explicit step (persistent cooperative kernel, and one launch per step) on cubes of 1e3-1e6 tets for neo-Hookean,
LP2 and QLV with 4 Prony terms in float32 and float64, the register-limit variants, the brains (real-time factor at
the critical step, nu = 0.49 and 0.499), dynamic relaxation, and the memory traffic of each step against the
measured device-to-device copy bandwidth. A background process times the CPU kernel on the same machine (side by
side). Results are appended to ``--out``/gpu_results.json after every case (a run cut short keeps what it measured),
and the cases run in order of priority until ``--deadline-s``.

Usage::

    python benchmarks/fem_gpu.py reference --data .gpu_data
    PYTHONPATH=src python benchmarks/fem_gpu.py device --data .gpu_data --out $OUT --deadline-s 400
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402

#: material laws of the timing table (fem_timing.LAWS, repeated here so that the device stage imports no benchmark
#: module that needs the CPU cache set-up) and of the agreement cases
LAWS = {
    "NH": ("neo_hookean", {"mu": 1000.0}, {}),
    "LP2": ("lopez_pamies2", {"mu1": 900.0, "alpha1": 1.2, "mu2": 100.0, "alpha2": 3.0}, {}),
    "QLV4-NH": ("neo_hookean", {"mu": 1000.0}, dict(prony_g=(0.3, 0.2, 0.1, 0.05), prony_tau_s=(0.01, 0.1, 1.0, 10.0))),
    "PR2-MR": ("mooney_rivlin", {"C10": 300.0, "C01": 100.0}, dict(
        prony_tau_s=(1e-3, 1e-2), pipkin_rogers={"beta": [0.8, 0.4], "kappa": [1.5, -0.5], "gamma_s": 0.1})),
}
#: agreement cases: (name, mesh, law, precision, extra)
AGREEMENT = (
    ("cube-NH-f64", "cube", "NH", "float64", {}),
    ("cube-NH-f32", "cube", "NH", "float32", {}),
    ("cube-QLV4-f64", "cube", "QLV4-NH", "float64", {}),
    ("cube-QLV4-f32", "cube", "QLV4-NH", "float32", {}),
    ("cube-LP2-f64", "cube", "LP2", "float64", {}),
    ("cube-PR2-f64", "cube", "PR2-MR", "float64", {}),
    ("cube-punch-contact-f64", "cube", "NH", "float64", {"contact": True}),
    ("brain10k-NH-f64", "brain10k", "NH", "float64", {}),
    ("brain10k-QLV4-f64", "brain10k", "QLV4-NH", "float64", {}),
    ("brain10k-QLV4-f32", "brain10k", "QLV4-NH", "float32", {}),
)
AGREEMENT_STEPS = 400
RELAXATION_TIMES = (0.05, 0.1, 0.2)
#: ``FEM_GPU_SMOKE=1``: every mesh a cube of ~50 tets and a few steps, to run both stages in numba's CUDA simulator
SMOKE = os.environ.get("FEM_GPU_SMOKE") == "1"
THREADS = 256
if SMOKE:
    AGREEMENT_STEPS = 6
    THREADS = 4


def cube(n_elements: float):
    from tissuemech.fem.mesh import block_mesh

    n = min(n_elements, 50) if SMOKE else n_elements
    cells = max(1, int(round((n / 6.0) ** (1.0 / 3.0))))
    return block_mesh((1e-2, 1e-2, 1e-2), (cells, cells, cells))


def load_mesh(data: Path, name: str):
    from tissuemech.fem.mesh import TetMesh

    if name == "cube" or SMOKE:
        return cube(1e4)
    d = np.load(data / f"{name}.npz")
    return TetMesh(d["nodes"], d["elements"])


def material(law: str, nu: float = 0.49):
    from tissuemech.fem.materials import make_material

    key, params, extra = LAWS[law]
    return make_material(key, params, poisson_ratio=nu, density_kg_m3=1040.0, **extra)


def explicit_problem(mesh, law: str, precision: str, nu: float = 0.49, contact: bool = False):
    """The support of the indentation experiment (lowest 5 % fixed), an initial shear velocity; with ``contact`` a
    rigid flat punch of a third of the width pressed into the top at 10 mm/s."""
    from tissuemech.fem.tled import RigidContact, build_model, critical_time_step, fixed_group

    x = mesh.nodes
    height = (x[:, 2] - x[:, 2].min()) / np.ptp(x[:, 2])
    rigid = None
    if contact:
        top = x[:, 2].max()
        centre = (x[:, 0].mean(), x[:, 1].mean(), top)
        rigid = RigidContact("flat_punch", centre, np.ptp(x[:, 0]) / 6, (0, 0, -1), [0, 0.03], [0, 0.3e-3])
    model = build_model(mesh, material(law, nu), [fixed_group("bottom", np.flatnonzero(height < 0.05))], rigid,
                        precision=precision)
    v0 = np.zeros_like(x)
    v0[:, 0] = 1e-3 * height
    return model, v0, critical_time_step(model)


def relaxation_problem(precision: str = "float64"):
    """Quasi-static indentation of the 10k cube (QLV, 4 terms): the top nodes within 2.5 mm of the centre pushed
    down 1 mm over 0.2 s (frictionless), the bottom fixed."""
    from tissuemech.fem.tled import build_model, fixed_group, translation_group

    mesh = cube(1e4)
    x = mesh.nodes
    top = np.isclose(x[:, 2], x[:, 2].max())
    under = np.flatnonzero(top & (np.linalg.norm(x[:, :2] - 5e-3, axis=1) < 2.5e-3))
    groups = [translation_group("punch", under, (0, 0, -1), [0, 0.2], [0, 1e-3], dofs=(False, False, True)),
              fixed_group("bottom", np.flatnonzero(np.isclose(x[:, 2], 0)))]
    return build_model(mesh, material("QLV4-NH"), groups, precision=precision)


# ----------------------------------------------------------------------------------------------------------------
# reference stage (CPU)
# ----------------------------------------------------------------------------------------------------------------
def reference(data: Path, cache: Path) -> None:
    from tissuemech.fem.mesh import brain_mesh, reorder_for_locality, subdivide
    from tissuemech.fem.tled import run_explicit, solve_quasistatic

    data.mkdir(parents=True, exist_ok=True)
    for name, points, refine in (("brain10k", 1400, False), ("brain100k", 7300, False), ("brain1m", 8560, True)):
        path = data / f"{name}.npz"
        if not path.is_file() and not SMOKE:
            mesh = brain_mesh(surface_points=points, cache_dir=cache)
            if refine:
                mesh = reorder_for_locality(subdivide(mesh))
            np.savez_compressed(path, nodes=mesh.nodes, elements=mesh.elements)
            print(name, mesh.n_elements, "tets", flush=True)
    for name, mesh_name, law, precision, extra in AGREEMENT:
        model, v0, dt = explicit_problem(load_mesh(data, mesh_name), law, precision, contact=bool(extra.get("contact")))
        t0 = time.perf_counter()
        res = run_explicit(model, AGREEMENT_STEPS * dt, dt_s=dt, v0_m_s=v0, n_outputs=8, damping_1_s=20.0)
        np.savez_compressed(data / f"ref-{name}.npz", dt=dt, u=res.displacement_m, u_previous=res.previous_displacement_m,
                            time=res.time_s, reaction=res.reaction_force_n["bottom"], torque=res.torque_nm["bottom"],
                            contact=res.contact_force_n, kinetic=res.kinetic_energy_j,
                            **{f"state{i}": s for i, s in enumerate(res.state)})
        print(name, f"{time.perf_counter() - t0:.1f} s", res.kernel, flush=True)
    model = relaxation_problem()
    t0 = time.perf_counter()
    res = solve_quasistatic(model, RELAXATION_TIMES)
    np.savez_compressed(data / "ref-relaxation-QLV4-f64.npz", u=res.displacement_m, reaction=res.reaction_force_n["punch"],
                        iterations=res.iterations, tol=1e-6 * model.min_altitude_m,
                        **{f"state{i}": s for i, s in enumerate(res.state)})
    print("relaxation", res.iterations, f"{time.perf_counter() - t0:.1f} s", flush=True)


# ----------------------------------------------------------------------------------------------------------------
# device stage (GPU)
# ----------------------------------------------------------------------------------------------------------------
class Recorder:
    """Appends result rows to a JSON file after each case; stops taking new cases after the deadline."""

    def __init__(self, out: Path, deadline_s: float):
        self.path = out / "gpu_results.json"
        self.t0 = time.perf_counter()
        self.deadline = deadline_s
        self.rows: list[dict] = []

    def left(self) -> float:
        return self.deadline - (time.perf_counter() - self.t0)

    def add(self, row: dict) -> None:
        row["elapsed_s"] = round(time.perf_counter() - self.t0, 1)
        self.rows.append(row)
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.rows, indent=1, default=float))
        tmp.replace(self.path)
        print(json.dumps(row, default=lambda v: round(float(v), 6)), flush=True)

    def run(self, label: str, fn, *args, need_s: float = 10.0, **kw) -> None:
        if self.left() < need_s:
            self.add({"case": label, "skipped": f"deadline ({self.left():.0f} s left, {need_s:.0f} needed)"})
            return
        try:
            fn(self, *args, **kw)
        except Exception as exc:  # noqa: BLE001 - one failed case must not lose the others
            self.add({"case": label, "error": f"{type(exc).__name__}: {exc}"[:600],
                      "traceback": traceback.format_exc()[-1500:]})


def rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = np.abs(b).max()
    return float(np.abs(a - b).max() / scale) if scale > 0 else float(np.abs(a).max())


def device_info() -> dict:
    from numba import cuda

    import numba

    dev = cuda.get_current_device()
    name = getattr(dev, "name", "simulator")
    info = {"device": name.decode() if isinstance(name, bytes) else str(name),
            "compute_capability": list(dev.compute_capability),
            "multiprocessors": getattr(dev, "MULTIPROCESSOR_COUNT", 1), "numba": numba.__version__}
    try:
        import numba_cuda

        info["numba_cuda"] = numba_cuda.__version__
    except (ImportError, AttributeError):
        pass
    try:
        info["nvidia_smi"] = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version,memory.total,clocks.max.sm",
                                             "--format=csv,noheader"], capture_output=True, text=True,
                                            timeout=20).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return info


def copy_bandwidth(rec: Recorder) -> None:
    """Device-to-device copy of 2 GiB, bytes read plus written per second (the memory ceiling)."""
    from numba import cuda

    n = 2**10 if SMOKE else 2**28  # float64: 2 GiB
    a = cuda.to_device(np.random.default_rng(0).random(n))
    b = cuda.device_array_like(a)
    times = []
    for _ in range(6):
        cuda.synchronize()
        t0 = time.perf_counter()
        b.copy_to_device(a)
        cuda.synchronize()
        times.append(time.perf_counter() - t0)
    bw = 2 * 8 * n / np.median(times[1:])
    rec.bandwidth = bw
    rec.add({"case": "copy_bandwidth", "bytes_per_s": bw, "times_s": times})


def agreement(rec: Recorder, data: Path) -> None:
    """Every reference case on the GPU; relative differences of the results."""
    from tissuemech.fem import cuda as fc

    for name, mesh_name, law, precision, extra in AGREEMENT:
        ref = np.load(data / f"ref-{name}.npz")
        model, v0, dt = explicit_problem(load_mesh(data, mesh_name), law, precision, contact=bool(extra.get("contact")))
        t0 = time.perf_counter()
        res = fc.run_explicit_gpu(model, AGREEMENT_STEPS * dt, dt_s=float(ref["dt"]), v0_m_s=v0, n_outputs=8,
                                  damping_1_s=20.0, threads_per_block=THREADS)
        row = {"case": f"agree-{name}", "elements": model.mesh.n_elements, "steps": AGREEMENT_STEPS,
               "wall_s_with_compile": time.perf_counter() - t0, "u": rel(res.displacement_m, ref["u"]),
               "u_previous": rel(res.previous_displacement_m, ref["u_previous"]), "u_max": float(np.abs(ref["u"]).max()),
               "times_equal": bool(np.array_equal(res.time_s, ref["time"])),
               "reaction": rel(res.reaction_force_n["bottom"], ref["reaction"]),
               "torque": rel(res.torque_nm["bottom"], ref["torque"]),
               "kinetic": rel(res.kinetic_energy_j, ref["kinetic"])}
        if extra.get("contact"):
            row["contact"] = rel(res.contact_force_n, ref["contact"])
            row["contact_max_n"] = float(np.abs(ref["contact"]).max())
        states = [rel(s, ref[f"state{i}"]) for i, s in enumerate(res.state) if ref[f"state{i}"].size]
        if states:
            row["states"] = max(states)
        tol = 1e-10 if precision == "float64" else 1e-4
        row["pass"] = bool(row["times_equal"] and row["u"] < tol and row["u_previous"] < tol
                           and row["kinetic"] < tol and row.get("states", 0.0) < max(tol, 1e-9)
                           and row["reaction"] < (1e-8 if precision == "float64" else 1e-2))
        rec.add(row)


def relaxation_agreement(rec: Recorder, data: Path) -> None:
    from tissuemech.fem import cuda as fc

    ref = np.load(data / "ref-relaxation-QLV4-f64.npz")
    model = relaxation_problem()
    fc.solve_quasistatic_gpu(model, RELAXATION_TIMES[:1], max_iter=50, min_iter=1, tol_m=1.0,
                             threads_per_block=THREADS)  # compile
    t0 = time.perf_counter()
    res = fc.solve_quasistatic_gpu(model, RELAXATION_TIMES, threads_per_block=THREADS)
    wall = time.perf_counter() - t0
    du = float(np.abs(res.displacement_m - ref["u"]).max())
    row = {"case": "agree-relaxation-QLV4-f64", "elements": model.mesh.n_elements, "wall_s": wall,
           "iterations_gpu": res.iterations.tolist(), "iterations_cpu": ref["iterations"].tolist(),
           "u_abs_m": du, "tol_m": float(ref["tol"]), "reaction": rel(res.reaction_force_n["punch"], ref["reaction"]),
           "states": max(rel(s, ref[f"state{i}"]) for i, s in enumerate(res.state) if ref[f"state{i}"].size),
           "us_per_iteration": 1e6 * wall / max(1, int(res.iterations.sum()))}
    row["pass"] = bool(du < 10 * row["tol_m"] and row["reaction"] < 1e-5)
    rec.add(row)


def step_bytes(model, anp: bool) -> int:
    """Memory traffic of one explicit step as the kernel moves it (each array access of each phase counted once;
    gathers of node values counted once per node, element forces once per incidence)."""
    ne, nn = model.kernel_mesh.n_elements, model.kernel_mesh.n_nodes
    w = model.dtype.itemsize
    nt = model.material.prony_g.size
    element = ne * (16 + 9 * w + w + 12 * w) + nn * (3 * w + 8)  # conn, d9, vol0, forces; u, p_node
    if nt:
        element += ne * 2 * (6 + 6 * nt) * w  # states read and written
    if model.material.pipkin_rogers:
        element += ne * 2 * nt * w  # previous weights
    node = ne * (4 + 12 * w) + nn * (4 + 3 * 2 * w + 3 * w + 3 * w + 3 * 8 + 3 + 8)  # incidences, forces; u (2 read,
    # 1 written), fint, coefficients, free flags, group
    pressure = (ne * (16 + 9 * w + w + w) + nn * 3 * w) + (ne * (4 + w) + nn * (4 + 8 + 8)) if anp else 0
    return int(element + node + pressure)


def timed_steps(run, target_s: float, batch: int) -> tuple[float, int]:
    """(seconds per step, steps) of explicit steps timed after a warm-up, about ``target_s`` in all."""
    run.advance(min(batch, 20), batch)
    n = 20
    while True:
        t0 = time.perf_counter()
        run.advance(n, batch)
        wall = time.perf_counter() - t0
        if wall > 0.25 * target_s or n >= run.n_steps_max // 4:
            break
        n *= 4
    n2 = int(min(max(n, target_s / max(wall / n, 1e-9)), run.n_steps_max + 1 - run.k))
    t0 = time.perf_counter()
    run.advance(n2, batch)
    return (time.perf_counter() - t0) / n2, n2


def timing(rec: Recorder, mesh_name: str, mesh, law: str, precision: str, *, nu: float = 0.49, batch: int = 2000,
           launches: bool = False, max_registers=None, models: dict | None = None, target_s: float = 0.4) -> None:
    from tissuemech.fem import cuda as fc

    key = (mesh_name, precision, nu)
    if models is not None and key in models:
        base, v0, dt = models[key]
        model = dataclasses.replace(base, material=material(law, nu))
    else:
        model, v0, dt = explicit_problem(mesh, law, precision, nu)
        if models is not None:
            models[key] = (model, v0, dt)
    t0 = time.perf_counter()
    run = fc.DeviceProblem(model, dt, 200 if SMOKE else 2_000_000, v0_m_s=v0, max_registers=max_registers,
                           threads_per_block=THREADS)
    run.advance(1, batch)  # compile
    compile_s = time.perf_counter() - t0
    per_step, n = timed_steps(run, target_s, 1 if launches else batch)
    ne = model.kernel_mesh.n_elements
    nbytes = step_bytes(model, model.use_anp)
    row = {"case": f"time-{mesh_name}-{law}-{precision}" + ("-launch_per_step" if launches else "")
           + (f"-maxreg{max_registers}" if max_registers else ""),
           "elements": ne, "nodes": model.kernel_mesh.n_nodes, "law": law, "precision": precision, "nu": nu,
           "anp": bool(model.use_anp), "us_per_step": 1e6 * per_step, "steps": n,
           "element_updates_per_s": ne / per_step, "dt_cr_s": dt, "realtime_factor": dt / per_step,
           "grid_blocks": run.cooperative_blocks("explicit_steps", (0, 1, run.U, run.g)),
           "step_bytes": nbytes, "bytes_per_s": nbytes / per_step, "compile_and_first_step_s": compile_s,
           "batch": 1 if launches else batch, "min_altitude_m": model.min_altitude_m}
    if getattr(rec, "bandwidth", None):
        row["fraction_of_copy_bandwidth"] = row["bytes_per_s"] / rec.bandwidth
    u, _ = run.displacements()
    row["finite"] = bool(np.isfinite(u).all())
    rec.add(row)


def relaxation_timing(rec: Recorder, n_elements: float) -> None:
    """Dynamic relaxation of a punch indentation of a cube of ``n_elements`` tets (QLV4, float64 and float32):
    iterations and wall time per load increment on the GPU."""
    from tissuemech.fem import cuda as fc
    from tissuemech.fem.tled import build_model, fixed_group, translation_group

    mesh = cube(n_elements)
    x = mesh.nodes
    top = np.isclose(x[:, 2], x[:, 2].max())
    under = np.flatnonzero(top & (np.linalg.norm(x[:, :2] - 5e-3, axis=1) < 2.5e-3))
    groups = [translation_group("punch", under, (0, 0, -1), [0, 0.2], [0, 1e-3], dofs=(False, False, True)),
              fixed_group("bottom", np.flatnonzero(np.isclose(x[:, 2], 0)))]
    for precision in ("float32", "float64"):
        model = build_model(mesh, material("QLV4-NH"), groups, precision=precision)
        fc.solve_quasistatic_gpu(model, [0.05], max_iter=30, min_iter=1, tol_m=1.0, threads_per_block=THREADS)
        t0 = time.perf_counter()
        res = fc.solve_quasistatic_gpu(model, [0.1, 0.2], threads_per_block=THREADS)
        wall = time.perf_counter() - t0
        rec.add({"case": f"time-relaxation-cube{mesh.n_elements}-QLV4-{precision}", "elements": mesh.n_elements,
                 "iterations": res.iterations.tolist(), "wall_s": wall,
                 "us_per_iteration": 1e6 * wall / max(1, int(res.iterations.sum())),
                 "punch_force_n": res.reaction_force_n["punch"][:, 2].tolist()})


CPU_SCRIPT = r"""
import json, sys, time
sys.path.insert(0, "src")
import numpy as np
import numba
sys.path.insert(0, "benchmarks")
from fem_gpu import cube, explicit_problem
from tissuemech.fem.tled import run_explicit
rows = []
for n in (1e5, 1e6):
    for law, prec in (("NH", "float32"), ("QLV4-NH", "float32")):
        model, v0, dt = explicit_problem(cube(n), law, prec)
        for threads in (2, int(sys.argv[1])):
            steps = 40 if n > 5e5 else 200
            run_explicit(model, 3 * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False, n_threads=threads)
            t0 = time.perf_counter()
            run_explicit(model, steps * dt, dt_s=dt, v0_m_s=v0, n_outputs=1, track_energy=False, n_threads=threads)
            per = (time.perf_counter() - t0) / steps
            rows.append({"case": f"cpu-cube{model.mesh.n_elements}-{law}-{prec}-{threads}threads",
                         "elements": model.mesh.n_elements, "threads": threads, "us_per_step": 1e6 * per,
                         "element_updates_per_s": model.mesh.n_elements / per, "realtime_factor": dt / per})
            print(json.dumps(rows[-1]), flush=True)
json.dump(rows, open(sys.argv[2], "w"))
"""


def device(data: Path, out: Path, deadline_s: float, cpu_threads: int, stages: set[str]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    rec = Recorder(out, deadline_s)
    rec.add({"case": "device", **device_info()})
    cpu = None
    if "cpu" in stages:  # the CPU kernel on the same machine, side by side (own process, own cores)
        env = {**os.environ, "NUMBA_NUM_THREADS": str(cpu_threads), "PYTHONPATH": str(ROOT / "src")}
        cpu = subprocess.Popen([sys.executable, "-c", CPU_SCRIPT, str(cpu_threads), str(out / "cpu_results.json")],
                               cwd=ROOT, env=env, stdout=open(out / "cpu_log.txt", "w"), stderr=subprocess.STDOUT)
    tests = None
    if "pytest" in stages:  # the test suite's own GPU agreement test (its CPU references compile on this machine)
        tests = subprocess.Popen([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                                  "tests/fem/test_cuda.py", "-k", "on_gpu or refused or power"], cwd=ROOT,
                                 env={**os.environ, "PYTHONPATH": str(ROOT / "src")},
                                 stdout=open(out / "pytest_gpu.txt", "w"), stderr=subprocess.STDOUT)
    rec.run("copy_bandwidth", copy_bandwidth)
    if "agree" in stages:
        rec.run("agreement", agreement, data, need_s=60)
        rec.run("relaxation", relaxation_agreement, data, need_s=30)
    models: dict = {}
    big = cube(1e6)
    order = [("cube1m", big, "NH", "float32"), ("cube1m", big, "QLV4-NH", "float32"),
             ("cube1m", big, "NH", "float64"), ("cube1m", big, "QLV4-NH", "float64")]
    brains = {n: load_mesh(data, n) for n in ("brain10k", "brain100k", "brain1m")} if "brain" in stages else {}
    if "time" in stages:
        for mesh_name, mesh, law, prec in order:
            rec.run(mesh_name, timing, mesh_name, mesh, law, prec, models=models, need_s=20)
    if brains:
        rec.run("brain100k", timing, "brain100k", brains["brain100k"], "QLV4-NH", "float32", nu=0.499, need_s=15)
        rec.run("brain100k", timing, "brain100k", brains["brain100k"], "QLV4-NH", "float64", nu=0.499, need_s=15)
        rec.run("brain1m", timing, "brain1m", brains["brain1m"], "QLV4-NH", "float32", need_s=20)
        rec.run("brain1m", timing, "brain1m", brains["brain1m"], "NH", "float32", need_s=20)
        for law in ("NH", "QLV4-NH"):
            rec.run("brain10k", timing, "brain10k", brains["brain10k"], law, "float32", need_s=15)
    if "time" in stages:
        for n, name in ((1e3, "cube1k"), (1e4, "cube10k"), (1e5, "cube100k")):
            mesh = cube(n)
            for law in ("NH", "QLV4-NH"):
                for prec in ("float32", "float64"):
                    rec.run(name, timing, name, mesh, law, prec, models=models, need_s=10)
        for n, name in ((1e3, "cube1k"), (1e4, "cube10k"), (1e5, "cube100k"), (1e6, "cube1m")):
            mesh = big if n == 1e6 else cube(n)
            rec.run(name, timing, name, mesh, "NH", "float32", models=models, launches=True, need_s=10,
                    target_s=0.2)
        for name, mesh in (("cube1m", big), ("cube100k", cube(1e5))):
            for prec in ("float32", "float64"):
                rec.run(name, timing, name, mesh, "LP2", prec, models=models, need_s=10)
    if "registers" in stages:
        # NH uses 109-118 registers (2 blocks of 256 per multiprocessor), QLV4 208-226 (1 block): limits that let 3-4 and 2
        for law, limits in (("NH", (64, 80)), ("QLV4-NH", (128, 64))):
            for regs in limits:
                rec.run("cube1m", timing, "cube1m", big, law, "float32", models=models, max_registers=regs, need_s=15)
    if "relax" in stages:
        rec.run("relaxation_timing", relaxation_timing, 1e5, need_s=30)
    if cpu is not None:
        try:
            cpu.wait(timeout=max(1.0, rec.left()))
        except subprocess.TimeoutExpired:
            cpu.kill()
        path = out / "cpu_results.json"
        rec.add({"case": "cpu", "rows": json.loads(path.read_text()) if path.is_file() else
                 (out / "cpu_log.txt").read_text()[-1500:]})
    if tests is not None:
        try:
            tests.wait(timeout=max(1.0, rec.left()))
        except subprocess.TimeoutExpired:
            tests.kill()
        rec.add({"case": "pytest_gpu", "returncode": tests.returncode,
                 "tail": (out / "pytest_gpu.txt").read_text()[-600:]})
    print_table(rec.rows)


def print_table(rows: list[dict]) -> None:
    print("\n case | elements | us/step | updates/s | RT | GB/s (frac) | check")
    for r in rows:
        if "us_per_step" in r:
            print(f" {r['case']} | {r.get('elements', '')} | {r['us_per_step']:.1f} | "
                  f"{r.get('element_updates_per_s', 0):.3g} | {r.get('realtime_factor', 0):.2f} | "
                  f"{r.get('bytes_per_s', 0) / 1e9:.0f} ({r.get('fraction_of_copy_bandwidth', 0):.2f})")
        elif "pass" in r:
            print(f" {r['case']} | {r.get('elements', '')} | pass={r['pass']} u={r.get('u', r.get('u_abs_m')):.2e}")
        elif "error" in r or "skipped" in r:
            print(f" {r['case']} | {r.get('error', r.get('skipped'))[:200]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="stage", required=True)
    r = sub.add_parser("reference")
    r.add_argument("--data", type=Path, default=ROOT / ".gpu_data")
    r.add_argument("--cache", type=Path, default=ROOT / ".gpu_data" / "mesh_cache")
    d = sub.add_parser("device")
    d.add_argument("--data", type=Path, default=ROOT / ".gpu_data")
    d.add_argument("--out", type=Path, default=Path(os.environ.get("OUT", "gpu_out")))
    d.add_argument("--deadline-s", type=float, default=400.0)
    d.add_argument("--cpu-threads", type=int, default=8)
    d.add_argument("--stages", default="agree,time,brain,registers,relax,cpu,pytest")
    a = ap.parse_args()
    if a.stage == "reference":
        reference(a.data, a.cache)
    else:
        device(a.data, a.out, a.deadline_s, a.cpu_threads, set(a.stages.split(",")))


if __name__ == "__main__":
    main()
