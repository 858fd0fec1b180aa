"""Snakemake adapter: posterior + population draws -> flat-punch indentation force-depth bands (netCDF + figure)."""
from tissuemech.pipeline import job_log
from tissuemech.uq import run_uq_indentation

with job_log(snakemake.log[0]) as log:
    p = snakemake.params
    ds = run_uq_indentation(snakemake.input.posterior, snakemake.input.population, snakemake.input.fits,
                            snakemake.output.data, snakemake.output.figure, n_draws=p.n_draws,
                            element_size_m=p.element_size_m, seed=p.seed, n_threads=snakemake.threads)
    log.info("indentation bands: %s", dict(ds.attrs))
