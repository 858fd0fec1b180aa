"""Snakemake adapter: fit records + posterior credible-interval tables -> the tidy fits.csv."""
from tissuemech.pipeline import job_log
from tissuemech.stages import write_fits_table

with job_log(snakemake.log[0]) as log:
    table = write_fits_table(snakemake.input.fits, snakemake.wildcards.dataset, snakemake.output.fits,
                             posterior_tables=snakemake.input.posterior)
    log.info("fits.csv: %d records, %d with credible intervals", len(table),
             int(table["posterior_rhat_max"].notna().sum()) if "posterior_rhat_max" in table else 0)
