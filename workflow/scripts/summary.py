"""Snakemake adapter: every dataset's results -> results/summary.html (self-contained, figures embedded)."""
from tissuemech.pipeline import job_log
from tissuemech.summary import build_summary

with job_log(snakemake.log[0], end_process=True) as log:
    page = build_summary("results", snakemake.params.datasets, snakemake.output.html,
                         captions_dir=snakemake.params.captions, config=snakemake.config)
    log.info("summary page %s (%.1f MB)", page, page.stat().st_size / 1e6)
