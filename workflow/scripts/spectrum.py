"""Snakemake adapter: averages.nc -> spectrum.nc (relaxation spectra of sweeps and relaxations, KK discrepancy)."""
from tissuemech.pipeline import job_log
from tissuemech.stages import run_spectrum

with job_log(snakemake.log[0]) as log:
    ds = run_spectrum(snakemake.input.averages, snakemake.output.spectrum)
    log.info("relaxation spectra of %d averaged curves", ds.sizes.get("curve", 0))
