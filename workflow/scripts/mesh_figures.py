"""Snakemake adapter: VTU files of the FEM experiments -> pictures of the deformed meshes."""
from tissuemech.pipeline import job_log
from tissuemech.summary import plot_meshes

with job_log(snakemake.log[0], end_process=True) as log:
    written = plot_meshes(snakemake.params.vtu_dirs, snakemake.output.figures)
    log.info("%s: %d mesh pictures", snakemake.wildcards.dataset, len(written))
