"""Snakemake adapter: the baseline's indentation bands + the diagnosis's simulation cards (+ the MNI brain mesh, where
the dataset is the brain-indentation dataset) -> the extensions' force at the bands' depth (extension_indentation.csv)."""
from tissuemech.fem.mesh import read_mesh
from tissuemech.pipeline import job_log
from tissuemech.uq import extension_indentation

with job_log(snakemake.log[0], end_process=True) as log:
    brain = snakemake.input.get("brain_mesh")
    table = extension_indentation(snakemake.input.bands, snakemake.input.cards, snakemake.output.table,
                                  n_threads=snakemake.threads, brain_mesh=read_mesh(brain)[0] if brain else None)
    log.info("extension indentation:\n%s", table.to_string())
