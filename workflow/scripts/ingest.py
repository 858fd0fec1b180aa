"""Snakemake adapter: raw/<dataset>/ (sample sheet + instrument exports) -> canonical runs + ingest report."""
from pathlib import Path

from tissuemech.io.ingest import ingest_dataset
from tissuemech.pipeline import job_log

with job_log(snakemake.log[0], end_process=True) as log:
    Path(snakemake.output.runs).mkdir(parents=True, exist_ok=True)
    report = ingest_dataset(snakemake.params.folder, snakemake.output.runs, snakemake.output.report)
    bad = report[report["status"] != "ok"]
    log.info("ingested %d runs, %d rejected", int((report["status"] == "ok").sum()), len(bad))
    for _, row in bad.iterrows():
        log.warning("rejected %s: %s", row.get("file"), row.get("reason"))
