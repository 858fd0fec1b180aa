"""Snakemake adapter: TLED timing table -> step-time and real-time-factor figures."""
from tissuemech.pipeline import job_log
from tissuemech.summary import plot_timing

with job_log(snakemake.log[0], end_process=True) as log:
    written = plot_timing(snakemake.input.table, snakemake.output.step, snakemake.output.realtime)
    log.info("timing figures: %s", ", ".join(str(p) for p in written))
