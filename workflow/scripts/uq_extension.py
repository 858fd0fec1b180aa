"""Snakemake adapter: the baseline's indentation bands + the diagnosis's simulation cards -> the extensions' force at
the bands' depth (extension_indentation.csv)."""
from tissuemech.pipeline import job_log
from tissuemech.uq import extension_indentation

with job_log(snakemake.log[0], end_process=True) as log:
    table = extension_indentation(snakemake.input.bands, snakemake.input.cards, snakemake.output.table,
                                  n_threads=snakemake.threads)
    log.info("extension indentation:\n%s", table.to_string())
