# TLED experiments driven by the material cards: rheometer torsion, flat-punch indentation, timing.


rule fem_torsion:
    input:
        ranking="results/{dataset}/ranking.csv",
        averages="results/{dataset}/averages.nc",
    output:
        table=report(
            "results/{dataset}/fem/torsion.csv",
            caption="../report/fem_torsion_table.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "torsion", "item": "error table"},
        ),
        data="results/{dataset}/fem/torsion.nc",
        figure=report(
            "results/{dataset}/figures/fem_torsion.png",
            caption="../report/fem_torsion.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "torsion", "item": "torque vs rim strain"},
        ),
        vtu=directory("results/{dataset}/fem/torsion_vtu"),
    log:
        "logs/{dataset}/fem_torsion.log",
    benchmark:
        "benchmarks/runs/{dataset}/fem_torsion.tsv"
    params:
        cards_root="results/{dataset}/cards",
        element_size_m=config["fem"]["cylinder_element_size_m"],
        pkg=package_hash("fem", "stages.py", "plots.py"),
    script:
        "../scripts/fem_torsion.py"


rule fem_indentation:
    input:
        ranking="results/{dataset}/ranking.csv",
    output:
        data="results/{dataset}/fem/indentation.nc",
        figure=report(
            "results/{dataset}/figures/fem_indentation.png",
            caption="../report/fem_indentation.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "indentation", "item": "force vs depth"},
        ),
        vtu=directory("results/{dataset}/fem/indentation_vtu"),
    log:
        "logs/{dataset}/fem_indentation.log",
    benchmark:
        "benchmarks/runs/{dataset}/fem_indentation.tsv"
    params:
        cards_root="results/{dataset}/cards",
        element_size_m=config["fem"]["block_element_size_m"],
        pkg=package_hash("fem", "stages.py", "plots.py"),
    script:
        "../scripts/fem_indentation.py"


rule fem_timing:
    output:
        table=report(
            "results/fem/timing.csv",
            caption="../report/timing_table.rst",
            category="FEM timing",
            labels={"figure": "table"},
        ),
    log:
        "logs/fem_timing.log",
    benchmark:
        "benchmarks/runs/fem_timing.tsv"
    params:
        python=sys.executable,
        pkg=package_hash("fem"),
    shell:
        "{params.python} benchmarks/fem_timing.py --threads 1 --max-elements 20000 --out {output.table} > {log} 2>&1"
