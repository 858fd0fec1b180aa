# Instrument exports -> canonical netCDF runs (one job per dataset; bad runs are reported, not fatal).


rule ingest:
    input:
        dataset_files,
    output:
        runs=directory("results/{dataset}/runs"),
        report=report(
            "results/{dataset}/ingest_report.csv",
            caption="../report/ingest.rst",
            category="{dataset}",
            subcategory="0 ingest",
            labels={"table": "ingest report"},
        ),
    log:
        "logs/{dataset}/ingest.log",
    benchmark:
        "benchmarks/runs/{dataset}/ingest.tsv"
    priority: critical_chain_priority
    params:
        folder=dataset_dir,
        pkg=script_hash("workflow/scripts/ingest.py"),
    script:
        "../scripts/ingest.py"
