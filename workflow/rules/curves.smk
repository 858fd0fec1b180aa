# Sample averages per test and condition with their LVE limits, figures and relaxation/retardation spectra (one
# job), time-temperature superposition of sweeps at several temperatures.


rule average:
    # averages, their LVE limits and spectra in one job: each is seconds of work, and a job of its own paid the
    # start-up (Python, xarray, numba) again (issue 17)
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
        lve="results/{dataset}/lve.nc",
        lve_summary=report(
            "results/{dataset}/lve.csv",
            caption="../report/lve_table.rst",
            category="{dataset}",
            subcategory="2 LVE limit",
            labels={"source": "table", "sweep": "all"},
        ),
        lve_figures=report(
            directory("results/{dataset}/figures/lve"),
            patterns=["lve__{source}__{sweep}.png"],
            caption="../report/lve.rst",
            category="{dataset}",
            subcategory="2 LVE limit",
            labels={"source": "{source}", "sweep": "{sweep}"},
        ),
        spectrum="results/{dataset}/spectrum.nc",
    log:
        "logs/{dataset}/average.log",
    benchmark:
        "benchmarks/runs/{dataset}/average.tsv"
    priority: critical_chain_priority
    params:
        exclude_flagged=config["fit"].get("exclude_flagged", True),
        pkg=script_hash("workflow/scripts/average.py"),
    script:
        "../scripts/average.py"


rule tts:
    input:
        runs="results/{dataset}/runs",
    output:
        tts="results/{dataset}/tts.nc",
        card="results/{dataset}/tts_card.json",
        abaqus="results/{dataset}/tts_card.inp",
        figure=report(
            "results/{dataset}/figures/tts_mastercurve.png",
            caption="../report/tts.rst",
            category="{dataset}",
            subcategory="2 time-temperature superposition",
            labels={"figure": "mastercurve"},
        ),
    log:
        "logs/{dataset}/tts.log",
    benchmark:
        "benchmarks/runs/{dataset}/tts.tsv"
    params:
        t_ref_c=config.get("tts", {}).get("t_ref_c"),
        vertical=config.get("tts", {}).get("vertical", False),
        exclude_flagged=config["fit"].get("exclude_flagged", True),
        pkg=script_hash("workflow/scripts/tts.py"),
    script:
        "../scripts/tts.py"
