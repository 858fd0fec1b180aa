"""Snakemake adapter: runs + fits + ranking -> the findings, the simulation cards of the named extensions,
residuals.nc, figures."""
from tissuemech.diagnosis.report import run_diagnosis
from tissuemech.pipeline import job_log

with job_log(snakemake.log[0], end_process=True) as log:
    result = run_diagnosis(snakemake.input.runs, snakemake.input.fits, snakemake.output.json,
                           snakemake.output.residuals, snakemake.output.figures, dataset=snakemake.wildcards.dataset,
                           alpha=snakemake.params.alpha, ranking=snakemake.input.ranking,
                           extension_cards_dir=snakemake.output.extension_cards,
                           poisson_ratio=snakemake.params.poisson_ratio)
    named = [f["effect"] for f in result.get("findings", []) if f.get("detected")]
    log.info("diagnosis of %s (baseline %s): %s", snakemake.wildcards.dataset, result.get("model"),
             ", ".join(named) or "no named cause")
