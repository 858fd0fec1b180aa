"""Snakemake adapter: compile the TLED time loops once into numba's cache, before the FEM jobs that run them."""
import os

from tissuemech.canonical import write_json
from tissuemech.fem.experiments import precompile_kernels
from tissuemech.pipeline import job_log

with job_log(snakemake.log[0], end_process=True) as log:
    seconds = precompile_kernels(n_threads=snakemake.threads)
    log.info("compiled TLED loops (CPU s): %s", seconds)
    write_json({"numba_cache_dir": os.environ.get("NUMBA_CACHE_DIR", ""), "cpu_s": seconds}, snakemake.output.stamp)
