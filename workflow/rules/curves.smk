# Sample averages per test and condition, LVE limits and their figures, relaxation/retardation spectra.


rule average:
    input:
        runs="results/{dataset}/runs",
    output:
        averages="results/{dataset}/averages.nc",
        figures=report(
            directory("results/{dataset}/figures/averages"),
            patterns=["{test}__{condition}__{variable}.png"],
            caption="../report/averages.rst",
            category="{dataset}",
            subcategory="1 raw runs vs averages",
            labels={
                "test": "{test}",
                "condition": "{condition}",
                "variable": "{variable}",
            },
        ),
    log:
        "logs/{dataset}/average.log",
    benchmark:
        "benchmarks/runs/{dataset}/average.tsv"
    params:
        pkg=script_hash("workflow/scripts/average.py"),
    script:
        "../scripts/average.py"


rule lve:
    input:
        runs="results/{dataset}/runs",
        averages="results/{dataset}/averages.nc",
    output:
        lve="results/{dataset}/lve.nc",
        summary=report(
            "results/{dataset}/lve.csv",
            caption="../report/lve_table.rst",
            category="{dataset}",
            subcategory="2 LVE limit",
            labels={"source": "table", "sweep": "all"},
        ),
        figures=report(
            directory("results/{dataset}/figures/lve"),
            patterns=["lve__{source}__{sweep}.png"],
            caption="../report/lve.rst",
            category="{dataset}",
            subcategory="2 LVE limit",
            labels={"source": "{source}", "sweep": "{sweep}"},
        ),
    log:
        "logs/{dataset}/lve.log",
    benchmark:
        "benchmarks/runs/{dataset}/lve.tsv"
    params:
        pkg=script_hash("workflow/scripts/lve.py"),
    script:
        "../scripts/lve.py"


rule spectrum:
    input:
        averages="results/{dataset}/averages.nc",
    output:
        spectrum="results/{dataset}/spectrum.nc",
    log:
        "logs/{dataset}/spectrum.log",
    benchmark:
        "benchmarks/runs/{dataset}/spectrum.tsv"
    params:
        pkg=script_hash("workflow/scripts/spectrum.py"),
    script:
        "../scripts/spectrum.py"
