# Human-readable summary page (figures + tables); `snakemake --report results/report.html` adds provenance.


rule summary:
    input:
        targets=[t for t in all_targets() if t != "results/summary.html"],
    output:
        html="results/summary.html",
    log:
        "logs/summary.log",
    benchmark:
        "benchmarks/runs/summary.tsv"
    params:
        datasets=list(DATASETS),
        pkg=package_hash("summary.py"),
    script:
        "../scripts/summary.py"
