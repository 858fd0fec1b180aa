"""Snakemake adapter: runs + fits -> diagnosis.json, residuals.nc, figures."""
from tissuemech.diagnosis.report import run_diagnosis
from tissuemech.pipeline import job_log

with job_log(snakemake.log[0]) as log:
    result = run_diagnosis(snakemake.input.runs, snakemake.input.fits, snakemake.output.json,
                           snakemake.output.residuals, snakemake.output.figures, dataset=snakemake.wildcards.dataset,
                           alpha=snakemake.params.alpha)
    named = [f["effect"] for f in result.get("findings", []) if f.get("detected")]
    log.info("diagnosis of %s: %s", snakemake.wildcards.dataset, ", ".join(named) or "no named cause")
