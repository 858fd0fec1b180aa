"""Snakemake adapter: every dataset's results -> results/summary.html + results/<dataset>/summary.html."""
from tissuemech.pipeline import job_log
from tissuemech.summary import build_summary

with job_log(snakemake.log[0], end_process=True) as log:
    page = build_summary("results", snakemake.params.datasets, snakemake.output.html,
                         captions_dir=snakemake.params.captions, config=snakemake.config)
    log.info("summary page %s (%.0f kB) and %d dataset pages", page, page.stat().st_size / 1e3,
             len(snakemake.output.pages))
