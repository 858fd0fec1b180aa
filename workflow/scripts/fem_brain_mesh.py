"""Snakemake adapter: MNI brain geometry from the nilearn wheel -> sliver-free fTetWild mesh (VTU) + quality."""
import json
from pathlib import Path

from tissuemech.fem.mesh import MNI_GM, MNI_WM, brain_mesh, mesh_quality, write_mesh
from tissuemech.pipeline import job_log

with job_log(snakemake.log[0], end_process=True) as log:
    mesh = brain_mesh(num_threads=1)
    write_mesh(snakemake.output.mesh, mesh)
    quality = {**mesh_quality(mesh), "source": [MNI_GM, MNI_WM],
               "note": "MNI ICBM152-2009 GM+WM probability > 0.5, smoothed, marching cubes, fTetWild (pytetwild), "
                       "worst elements improved by mesh.improve_min_altitude (surface nodes slid <= 0.5 mm); "
                       "nilearn lists the template's license as unknown"}
    Path(snakemake.output.quality).write_text(json.dumps(quality, indent=2))
    log.info("brain mesh: %s", quality)
