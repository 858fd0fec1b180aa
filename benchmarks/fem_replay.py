"""FEM replay of a dataset's measured tests: CPU time, element counts and mesh convergence.

Replays every averaged test of ``averages.nc`` with one card (``tissuemech.fem.replay.replay``, the pipeline's
settings except the element size) on several cylinder element sizes, and prints per test: elements, CPU seconds, the
NRMSE against the measured means, and the mesh error -- the NRMSE of the simulated points against those of the
finest mesh. With ``--model`` the card's own fitting model (``models.plate``: the 1-D plate quadrature of the fitted
law, steady-state sweeps) is evaluated on the same replayed histories, and the NRMSE of the replay against it is
printed too (mesh + time thinning + sweep protocol).

Usage (the bundled brain after ``make run``)::

    python benchmarks/fem_replay.py results/porcine_brain_thesis/averages.nc \\
        results/porcine_brain_thesis/cards/material/<baseline model>.json --sizes 2.5e-3,1.5e-3,1e-3
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from tissuemech.numba_cache import use_source_keyed_cache  # noqa: E402 (before anything imports numba)

use_source_keyed_cache(Path(__file__).resolve().parents[1] / ".numba_cache")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from tissuemech.canonical import read_netcdf  # noqa: E402
from tissuemech.fem.replay import ReplayCard, ReplaySettings, plate_tests, replay  # noqa: E402
from tissuemech.models import plate  # noqa: E402
from tissuemech.models.registry import get_model  # noqa: E402
from tissuemech.records import MaterialCard  # noqa: E402
from tissuemech.stats import nrmse  # noqa: E402


def one_d(model, p, test, settings) -> np.ndarray:
    """The fitting model's prediction of a replayed test at its kept points (models.plate)."""
    if test.control == "strain":
        return plate.forward_plate(model, p, np.r_[0.0, test.time_s], np.r_[0.0, test.drive], test.radius_m)[1:][
            test.obs_index]
    if test.control == "torque":
        return plate.creep_rim_strain(model, p, np.r_[0.0, test.time_s], np.r_[0.0, test.drive], test.radius_m)[1:][
            test.obs_index]
    g = np.array([[m[0] for m in plate.oscillation_moduli(model, p, f, a, test.radius_m, n_cycles=10,
                                                           points_per_cycle=64)]
                  for f, a in zip(test.frequency_hz, test.amplitude)])
    return np.concatenate([g[:, 0], g[:, 1]])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("averages")
    ap.add_argument("card")
    ap.add_argument("--sizes", default="2.5e-3,1.5e-3,1e-3", help="element sizes (m), the last is the reference")
    ap.add_argument("--model", action="store_true", help="also compare with the card's 1-D fitting model")
    args = ap.parse_args()
    averages = read_netcdf(args.averages)
    card = MaterialCard.from_json(args.card)
    print(f"CPU: {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; card {args.card}")
    runs = {}
    for size in [float(s) for s in args.sizes.split(",")]:
        settings = ReplaySettings(element_size_m=size)
        cpu: list[float] = []
        last = [time.process_time()]

        def tick(row, cpu=cpu, last=last):
            now = time.process_time()
            cpu.append(now - last[0])
            last[0] = now

        t0 = time.process_time()
        table, points = replay(averages, [ReplayCard(Path(args.card).stem, "baseline", card)], settings, on_row=tick)
        table["cpu_s"] = cpu
        runs[size] = (table, points, settings)
        print(f"\nelement size {size * 1e3:g} mm: {time.process_time() - t0:.1f} CPU s in all")
    ref_size = list(runs)[-1]
    ref_points = runs[ref_size][1]
    rows = []
    for size, (table, points, settings) in runs.items():
        for r in table[table["status"] == "ok"].itertuples():
            key = ["test", "condition", "observable", "x"]
            mine = points[(points["test"] == r.test) & (points["condition"] == r.condition)]
            ref = ref_points.merge(mine, on=key, suffixes=("_ref", ""))
            rows.append({"size_mm": size * 1e3, "test": r.test, "condition": r.condition, "n_elements": r.n_elements,
                         "cpu_s": r.cpu_s, "nrmse_vs_measured": r.nrmse,
                         f"mesh_error_vs_{ref_size * 1e3:g}mm": nrmse(ref["simulated_ref"], ref["simulated"])})
        if args.model:
            model, p = get_model(card.model), card.data["parameters"]
            for test in plate_tests(averages, settings):
                if test.reason:
                    continue
                sim = points[(points["test"] == test.test) & (points["condition"] == test.condition)]
                one = next(i for i, r in enumerate(rows) if r["size_mm"] == size * 1e3 and r["test"] == test.test
                           and r["condition"] == test.condition)
                rows[one]["nrmse_vs_1d_model"] = nrmse(one_d(model, p, test, settings), sim["simulated"])
    pd.set_option("display.width", 200)
    out = pd.DataFrame(rows)
    print(out.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(out.groupby("size_mm")[["cpu_s"]].sum().rename(columns={"cpu_s": "cpu_s_total"}).to_string())


if __name__ == "__main__":
    main()
