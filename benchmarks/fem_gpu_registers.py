"""Compile the GPU solver's kernels for a Hopper GPU (sm_90) on a machine without one; registers and spills per kernel.

Needs numba-cuda (the ``gpu`` extra), NVRTC (``pip install "nvidia-cuda-nvrtc>=13,<14"``), libNVVM (a CUDA toolkit's,
e.g. ``CUDA_HOME=/usr/local/cuda-13.0``, or ``pip install nvidia-nvvm``) and ``ptxas`` on the PATH. numba-cuda asks
the current device for its compute capability when it compiles a device function; without a GPU this script answers
9.0 for it. Every kernel of :func:`tissuemech.fem.cuda._kernels` is compiled to PTX for each law and storage precision
and assembled by ``ptxas -arch=sm_90 -c -v``; printed: registers per thread, stack frame and spill bytes. Usage::

    CUDA_HOME=/usr/local/cuda-13.0 python benchmarks/fem_gpu_registers.py [NH QLV4 ...]
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

import numba.cuda.dispatcher as _dispatcher  # noqa: E402

_dispatcher.get_current_device = lambda: SimpleNamespace(compute_capability=(9, 0))

import numpy as np  # noqa: E402
from numba import cuda, typeof  # noqa: E402

import tissuemech.fem.cuda as fem_cuda  # noqa: E402
from tissuemech.fem.materials import make_material  # noqa: E402
from tissuemech.fem.mesh import block_mesh  # noqa: E402
from tissuemech.fem.tled import build_model, fixed_group  # noqa: E402

LAWS = {"SVK": ("saint_venant_kirchhoff", {"mu": 1000.0}, {}),
        "NH": ("neo_hookean", {"mu": 1000.0}, {}),
        "MR": ("mooney_rivlin", {"C10": 300.0, "C01": 100.0}, {}),
        "LP2": ("lopez_pamies2", {"mu1": 900.0, "alpha1": 1.2, "mu2": 100.0, "alpha2": 3.0}, {}),
        "QLV4": ("neo_hookean", {"mu": 1000.0}, dict(prony_g=(0.3, 0.2, 0.1, 0.05), prony_tau_s=(0.01, 0.1, 1.0, 10.0))),
        "PR4": ("neo_hookean", {"mu": 1000.0}, dict(prony_tau_s=(0.01, 0.1, 1.0, 10.0), pipkin_rogers={
            "beta": [0.3 / 0.35, 0.2 / 0.35, 0.1 / 0.35, 0.05 / 0.35], "kappa": [0.537] * 4, "gamma_s": 0.1223}))}


class _HostArray(np.ndarray):
    """A host array standing in for a device array (typeof gives the same C-contiguous array type)."""

    def copy_to_device(self, values):
        self[...] = values

    def copy_to_host(self):
        return np.asarray(self).copy()


def _host(a):
    return np.ascontiguousarray(a).view(_HostArray)


def problem_arrays(model):
    """A :class:`~tissuemech.fem.cuda.DeviceProblem` of ``model`` whose arrays stay on the host."""
    saved = cuda.to_device, cuda.device_array
    cuda.to_device = _host
    cuda.device_array = lambda shape, dtype=np.float64: np.zeros(shape, dtype).view(_HostArray)
    try:
        return fem_cuda.DeviceProblem(model, 1e-5, 10)
    finally:
        cuda.to_device, cuda.device_array = saved


def main(names: list[str]) -> None:
    mesh = block_mesh((1e-2,) * 3, (2, 2, 2))
    bottom = fixed_group("bottom", np.flatnonzero(mesh.nodes[:, 2] == 0))
    print("law | precision | kernel | registers | stack / spill stores / spill loads (bytes)")
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            key, params, extra = LAWS[name]
            for precision in ("float32", "float64"):
                model = build_model(mesh, make_material(key, params, poisson_ratio=0.49, **extra), [bottom],
                                    precision=precision)
                run = problem_arrays(model)
                g = type(run.g)(*(np.asarray(a) for a in run.g))
                U = np.asarray(run.U)
                arguments = {
                    "explicit_steps": (0, 1, U, g), "evaluate_forces": (U[0], True, g),
                    "relaxation_start": (U[0], U[1], 0.5, True, g.hv, g),
                    "relaxation_iterations": (0, 1, 2, 1e-9, 1.0, 0.0, U, np.zeros((2,) + U.shape[1:], U.dtype),
                                              np.zeros((3, 4)), np.zeros(4), g),
                    "outputs": (U[0], U[1], 1e-5, g, np.zeros((3, 4)))}
                for kernel, args in arguments.items():
                    ptx, _ = cuda.compile_ptx(run.kernels[kernel].py_func, tuple(typeof(a) for a in args), cc=(9, 0))
                    path = Path(tmp) / f"{name}_{precision}_{kernel}.ptx"
                    path.write_text(ptx)
                    # -c: the cooperative kernels call the device runtime's grid sync, resolved at link time
                    out = subprocess.run(["ptxas", "-arch=sm_90", "-c", "-v", str(path), "-o", str(path.with_suffix(".o"))],
                                         capture_output=True, text=True)
                    if out.returncode:
                        print(name, precision, kernel, "ptxas failed:", out.stderr[-500:])
                        continue
                    lines = out.stderr.splitlines()
                    regs = [ln.split("Used ")[1].split(" registers")[0] for ln in lines if "registers" in ln][-1]
                    spill = [ln.split(":")[-1].strip() for ln in lines if "spill" in ln][0]
                    print(f"{name} | {precision} | {kernel} | {regs} | {spill}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or list(LAWS))
