# Sample averages per test and condition, LVE limits and their figures.


rule average:
    input:
        runs="results/{dataset}/runs",
    output:
        averages="results/{dataset}/averages.nc",
        figures=directory("results/{dataset}/figures/averages"),
    log:
        "logs/{dataset}/average.log",
    benchmark:
        "benchmarks/runs/{dataset}/average.tsv"
    params:
        pkg=package_hash("curves.py", "plots.py", "canonical.py"),
    script:
        "../scripts/average.py"


rule lve:
    input:
        runs="results/{dataset}/runs",
        averages="results/{dataset}/averages.nc",
    output:
        lve="results/{dataset}/lve.nc",
        summary="results/{dataset}/lve.csv",
        figures=directory("results/{dataset}/figures/lve"),
    log:
        "logs/{dataset}/lve.log",
    benchmark:
        "benchmarks/runs/{dataset}/lve.tsv"
    params:
        pkg=package_hash("lve.py", "curves.py", "plots.py", "canonical.py"),
    script:
        "../scripts/lve.py"
