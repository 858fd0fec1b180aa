# Report figures the stages do not draw (meshes, timing; fit_scope draws the fit figures, rank the card figures)
# and the summary pages: results/summary.html (a verdict card per dataset) and results/<dataset>/summary.html.
# `snakemake --report results/report.html` collects every output marked report(...) with its caption
# (workflow/report/*.rst); the summary page is the same content without Snakemake, built by the default target.


def report_figure_targets():
    """Figure folders/files of the report rules for every dataset (inputs of the summary, so in the default target)."""
    targets = ["results/fem/figures/timing_step.png"]
    for name in DATASETS:
        for scope in dataset_scopes_of(name):
            targets.append(f"results/{name}/figures/fits/{scope}")
        if dataset_scopes_of(name):
            targets.append(f"results/{name}/figures/cards")
        if fem_vtu_dirs_of(name):
            targets.append(f"results/{name}/figures/meshes")
    return targets


def fem_vtu_dirs_of(name):
    """FEM experiment name -> VTU folder of the experiments run on a dataset."""
    dirs = {}
    if has_shear_ramps(name):
        dirs["torsion"] = f"results/{name}/fem/torsion_vtu"
    if name in config["fem"].get("indentation_datasets", []):
        dirs["indentation"] = f"results/{name}/fem/indentation_vtu"
    return dirs


rule mesh_figures:
    input:
        vtu=lambda wildcards: list(fem_vtu_dirs_of(wildcards.dataset).values()),
    output:
        figures=report(
            directory("results/{dataset}/figures/meshes"),
            patterns=["{experiment}__{case}.png"],
            caption="../report/meshes.rst",
            category="{dataset}",
            subcategory="8 FEM meshes",
            labels={"experiment": "{experiment}", "case": "{case}"},
        ),
    log:
        "logs/{dataset}/mesh_figures.log",
    benchmark:
        "benchmarks/runs/{dataset}/mesh_figures.tsv"
    params:
        vtu_dirs=lambda wildcards: fem_vtu_dirs_of(wildcards.dataset),
        pkg=script_hash("workflow/scripts/mesh_figures.py"),
    script:
        "../scripts/mesh_figures.py"


rule timing_figures:
    input:
        table="results/fem/timing.csv",
    output:
        step=report(
            "results/fem/figures/timing_step.png",
            caption="../report/timing.rst",
            category="FEM timing",
            labels={"figure": "step time"},
        ),
        step_svg="results/fem/figures/timing_step.svg",
        realtime=report(
            "results/fem/figures/timing_realtime.png",
            caption="../report/timing.rst",
            category="FEM timing",
            labels={"figure": "real-time factor"},
        ),
        realtime_svg="results/fem/figures/timing_realtime.svg",
    log:
        "logs/timing_figures.log",
    benchmark:
        "benchmarks/runs/timing_figures.tsv"
    params:
        pkg=script_hash("workflow/scripts/timing_figures.py"),
    script:
        "../scripts/timing_figures.py"


rule summary:
    input:
        targets=[t for t in all_targets() if t != "results/summary.html"],
        figures=report_figure_targets(),
        uq=lambda wildcards: uq_targets(),
    output:
        html="results/summary.html",
        pages=[f"results/{name}/summary.html" for name in DATASETS],
    log:
        "logs/summary.log",
    benchmark:
        "benchmarks/runs/summary.tsv"
    params:
        datasets=list(DATASETS),
        captions=f"{workflow.basedir}/workflow/report",
        pkg=script_hash("workflow/scripts/summary.py"),
    script:
        "../scripts/summary.py"
