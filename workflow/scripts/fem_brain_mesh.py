"""Snakemake adapter: MNI brain geometry from the nilearn wheel -> explicit-dynamics tet mesh (VTU) + quality."""
import json
from pathlib import Path

from tissuemech.fem.mesh import MNI_GM, MNI_WM, brain_mesh, brain_surface, mesh_quality, surface_deviation, write_mesh
from tissuemech.pipeline import job_log

with job_log(snakemake.log[0], end_process=True) as log:
    surface = brain_surface()
    mesh = brain_mesh(surface=surface)
    write_mesh(snakemake.output.mesh, mesh)
    quality = {**mesh_quality(mesh), "surface_deviation": surface_deviation(mesh, surface),
               "source": [MNI_GM, MNI_WM],
               "note": "MNI ICBM152-2009 GM+WM probability > 0.5, smoothed, marching cubes, remeshed to uniform "
                       "triangles (ACVD, pyacvd), filled by gmsh (Delaunay + Netgen optimisation), worst elements "
                       "improved by mesh.improve_min_altitude (surface nodes slid <= 0.5 mm); surface_deviation: "
                       "distances between the mesh boundary and the marching-cubes surface; nilearn lists the "
                       "template's license as unknown"}
    Path(snakemake.output.quality).write_text(json.dumps(quality, indent=2))
    log.info("brain mesh: %s", quality)
