"""Snakemake adapter: posterior + population draws -> FEM bands (rule uq_indentation: flat-punch force-depth;
rule uq_torsion: rheometer torque-rim strain against the measured torque), netCDF + figure."""
from tissuemech.pipeline import job_log
from tissuemech.uq import run_uq_indentation, run_uq_torsion

with job_log(snakemake.log[0], end_process=True) as log:
    i, p = snakemake.input, snakemake.params
    common = dict(n_draws=p.n_draws, element_size_m=p.element_size_m, seed=p.seed, n_threads=snakemake.threads)
    if snakemake.rule == "uq_torsion":
        ds = run_uq_torsion(i.posterior, i.population, i.fits, i.averages, snakemake.output.data,
                            snakemake.output.figure, **common)
    else:
        ds = run_uq_indentation(i.posterior, i.population, i.fits, snakemake.output.data, snakemake.output.figure,
                                **common)
    log.info("%s bands: %s", snakemake.rule, dict(ds.attrs))
