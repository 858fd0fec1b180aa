"""Snakemake adapter: recommended card (ranking.csv) of the first indentation dataset -> flat punches (8, 15 mm) into the MNI brain."""
import time
from pathlib import Path

import numpy as np
import xarray as xr

from tissuemech.canonical import write_netcdf
from tissuemech.fem.experiments import brain_indentation
from tissuemech.fem.mesh import read_mesh
from tissuemech.pipeline import job_log
from tissuemech.stages import card_for_fem, select_cards

with job_log(snakemake.log[0], end_process=True) as log:
    card_path = Path(select_cards(snakemake.input.ranking, snakemake.params.cards_root)[0])
    mesh = read_mesh(snakemake.input.brain_mesh)[0]
    Path(snakemake.output.vtu).mkdir(parents=True, exist_ok=True)
    cases, depth, force, attrs = [], [], [], {}
    for diameter in (8e-3, 15e-3):
        t0 = time.perf_counter()
        ds = brain_indentation(card_for_fem(card_path), diameter, 2e-3, mesh=mesh, n_increments=8,
                                n_threads=snakemake.threads,
                               vtu_path=Path(snakemake.output.vtu) / f"brain__{diameter * 1e3:g}mm.vtu")
        wall = time.perf_counter() - t0
        label = f"{diameter * 1e3:g}mm"
        cases.append(f"{card_path.parent.name}/{card_path.stem} brain {label}")
        depth.append(ds["displacement"].values)
        force.append(ds["force"].values)
        attrs.update({f"{k}_{label}": v for k, v in ds.attrs.items() if k.startswith(("fem_", "punch_"))})
        attrs[f"wall_s_{label}"] = wall
        log.info("brain %s: force at 2 mm %.4g N, %d punch nodes, %.1f s", label, force[-1][-1],
                 ds.attrs["punch_nodes_at_max_depth"], wall)
    write_netcdf(xr.Dataset({"depth": (("case", "point"), np.array(depth), {"units": "m"}),
                             "force": (("case", "point"), np.array(force), {"units": "N"})},
                            coords={"case": cases}, attrs={"card": str(card_path), **attrs}), snakemake.output.data)
