"""The 3x3 symmetric eigen-decomposition of stretch-based laws (Ogden): closed form against Jacobi rotations.

For random ``b = F F^T`` with ``F = I + scale N(0, 1)`` at each ``--scales`` value, both
``kinematics.symmetric_eigen3`` (closed form, Jacobi below ``CLOSED_FORM_MIN_GAP``) and ``kinematics.jacobi_eigen3``
decompose the same matrices in one compiled loop each, alternating, ``--repeats`` times. Printed per scale: the
median nanoseconds per matrix of each, the share of matrices that fall back to Jacobi, and the largest
reconstruction error ``|V diag(l) V^T - b|`` relative to ``|b|`` of each. Then, with ``--indentation``, the CPU
seconds of a dynamic-relaxation flat-punch indentation (8 mm punch to 2 mm, 2 mm elements, 1 thread) with a one-term
Ogden law of Budday-cortex-like parameters, the case that runs this decomposition per element and iteration.
Usage::

    python benchmarks/fem_eigen.py --scales 1e-3,3e-2,0.2 --indentation
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
from fem_timing import machine  # noqa: E402
from numba import njit  # noqa: E402

from tissuemech.fem.kinematics import CLOSED_FORM_MIN_GAP, jacobi_eigen3, symmetric_eigen3  # noqa: E402


@njit
def _decompose_all(decompose, b6, out):
    for i in range(b6.shape[0]):
        out[i] = decompose(b6[i, 0], b6[i, 1], b6[i, 2], b6[i, 3], b6[i, 4], b6[i, 5])


@njit
def _closed_form_share(b6):
    """Share of the matrices whose smallest relative eigenvalue gap is at least ``CLOSED_FORM_MIN_GAP``."""
    n = 0
    for i in range(b6.shape[0]):
        lam = np.linalg.eigvalsh(np.array([[b6[i, 0], b6[i, 3], b6[i, 5]], [b6[i, 3], b6[i, 1], b6[i, 4]],
                                           [b6[i, 5], b6[i, 4], b6[i, 2]]]))
        n += min(lam[1] - lam[0], lam[2] - lam[1]) >= CLOSED_FORM_MIN_GAP * (lam[2] - lam[0])
    return n / b6.shape[0]


def _worst_reconstruction(b6: np.ndarray, out: np.ndarray) -> float:
    lam = out[:, :3]
    vec = out[:, 3:].reshape(-1, 3, 3).transpose(0, 2, 1)  # columns are eigenvectors
    rebuilt = np.einsum("nij,nj,nkj->nik", vec, lam, vec)
    b = np.empty_like(rebuilt)
    b[:, 0, 0], b[:, 1, 1], b[:, 2, 2] = b6[:, 0], b6[:, 1], b6[:, 2]
    b[:, 0, 1] = b[:, 1, 0] = b6[:, 3]
    b[:, 1, 2] = b[:, 2, 1] = b6[:, 4]
    b[:, 0, 2] = b[:, 2, 0] = b6[:, 5]
    return float(np.max(np.abs(rebuilt - b).max(axis=(1, 2)) / np.abs(b).max(axis=(1, 2))))


def decomposition_table(scales: list[float], n: int, repeats: int) -> None:
    rng = np.random.default_rng(0)
    print(f"{'strain scale':>12} {'closed form ns':>15} {'Jacobi ns':>10} {'closed-form share':>18} "
          f"{'worst rel. rebuild (closed / Jacobi)':>38}")
    for scale in scales:
        F = np.eye(3) + scale * rng.standard_normal((n, 3, 3))
        b = F @ F.transpose(0, 2, 1)
        b6 = np.ascontiguousarray(np.stack([b[:, 0, 0], b[:, 1, 1], b[:, 2, 2], b[:, 0, 1], b[:, 1, 2], b[:, 0, 2]], 1))
        outs = {"closed": np.empty((n, 12)), "jacobi": np.empty((n, 12))}
        funcs = {"closed": symmetric_eigen3, "jacobi": jacobi_eigen3}
        times = {k: [] for k in funcs}
        for k in funcs:
            _decompose_all(funcs[k], b6[:10], outs[k][:10])  # compile
        for _ in range(repeats):
            for k, f in funcs.items():
                t0 = time.perf_counter()
                _decompose_all(f, b6, outs[k])
                times[k].append((time.perf_counter() - t0) / n * 1e9)
        print(f"{scale:12.0e} {np.median(times['closed']):15.0f} {np.median(times['jacobi']):10.0f} "
              f"{_closed_form_share(b6):18.3f} {_worst_reconstruction(b6, outs['closed']):18.1e} / "
              f"{_worst_reconstruction(b6, outs['jacobi']):.1e}", flush=True)


def indentation_seconds() -> None:
    from tissuemech.fem.experiments import flat_punch_indentation

    # the one-term Ogden card the pipeline fits to the Budday cortex data (all modes), in the card's own keys; its
    # Poisson ratio is the configuration's fem.poisson_ratio
    card = {"model": "ogden1", "elastic_law": "ogden1", "elastic_parameters": {"mu1": 1337.19, "alpha1": -20.715}, "poisson_ratio": 0.49}
    for call in ("first call (with any numba compile not in the cache)", "second call"):
        t0 = time.process_time()
        ds = flat_punch_indentation(card, 8e-3, element_size_m=2e-3, n_threads=1)
        print(f"Ogden flat punch 8 mm, {ds.attrs['fem_n_elements']} tets, {ds.attrs['fem_dr_iterations_total']} DR "
              f"iterations, {call}: {time.process_time() - t0:.2f} CPU s; force at 2 mm {float(ds.force[-1]):.4g} N",
              flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scales", default="1e-3,3e-2,0.2")
    ap.add_argument("--matrices", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--indentation", action="store_true")
    args = ap.parse_args()
    print("#", machine())
    decomposition_table([float(s) for s in args.scales.split(",")], args.matrices, args.repeats)
    if args.indentation:
        indentation_seconds()


if __name__ == "__main__":
    main()
