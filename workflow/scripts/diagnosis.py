"""Snakemake adapter: findings + the replay's fix.simulation -> diagnosis.json."""
from tissuemech.diagnosis.simulation_cards import attach_simulation
from tissuemech.pipeline import job_log

with job_log(snakemake.log[0], end_process=True) as log:
    result = attach_simulation(snakemake.input.findings, snakemake.input.get("fix_simulation"),
                               snakemake.output.json)
    log.info("%s: simulation %s", snakemake.wildcards.dataset, result.get("simulation"))
