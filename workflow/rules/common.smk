# Shared helpers: dataset discovery, package source hashes (rerun triggers), target lists.
import functools
import sys
from pathlib import Path

import pandas as pd


def script_hash(script):
    """Rerun trigger: hash of every package source file the script reaches by imports.

    Snakemake does not track imported code; tissuemech.sourcehash finds the modules statically and transitively.
    """
    from tissuemech.sourcehash import source_hash

    path = Path(workflow.basedir) / script
    if not path.is_file():  # a partial copy of the workflow that never runs this rule
        return "script-absent"
    return source_hash(path, Path(workflow.basedir) / "src")


def external_source_available(folder):
    """An external dataset runs only when its sample sheet and its read-only source folder exist."""
    import yaml

    folder = Path(folder)
    if (
        not (folder / "samples.csv").is_file()
        or not (folder / "dataset.yaml").is_file()
    ):
        return False
    source = yaml.safe_load((folder / "dataset.yaml").read_text()).get("source_dir")
    return source is None or (folder / source).is_dir()


def discover_datasets():
    """Dataset name -> folder: every raw/<name>/ with a samples.csv, plus configured external folders."""
    found = {}
    raw = Path(config["raw_dir"])
    for sheet in sorted(raw.glob("*/samples.csv")):
        found[sheet.parent.name] = str(sheet.parent)
    for name, folder in config.get("external_datasets", {}).items():
        if external_source_available(folder):
            found[name] = folder
        else:
            logger.warning(
                f"external dataset {name!r}: {folder} or its source_dir not found, skipped"
            )
    wanted = config.get("datasets") or list(found)
    missing = sorted(set(wanted) - set(found))
    if missing:
        raise ValueError(f"configured datasets not found under {raw}/: {missing}")
    return {name: found[name] for name in wanted}


DATASETS = discover_datasets()


wildcard_constraints:
    dataset="|".join(DATASETS) or "NO_DATASET",
    scope="[^/]+",
    model="[^/]+",


def dataset_dir(wildcards):
    return DATASETS[wildcards.dataset]


def dataset_files(wildcards):
    """Every input file of a dataset (sample sheet, description, instrument files) so edits rerun ingest."""
    import yaml

    folder = Path(DATASETS[wildcards.dataset])
    files = sorted(str(p) for p in folder.rglob("*") if p.is_file())
    source = yaml.safe_load((folder / "dataset.yaml").read_text()).get("source_dir")
    if source:
        sheet = sample_sheet_of(folder)
        files += sorted(str(folder / source / f) for f in sheet["file"].dropna())
    return files


@functools.cache
def sample_sheet(name):
    """A dataset's sample sheet, read once per Snakemake process (raw/ does not change during a run; the target
    and input functions asked for it ~350 times per DAG). Callers must not modify it."""
    return sample_sheet_of(DATASETS[name])


def sample_sheet_of(folder):
    """samples.csv as the ingest reads it (comma, semicolon or tab separated; tissuemech.io.samples.load_samples)."""
    from tissuemech.io.samples import load_samples

    return load_samples(folder)


def dataset_tests(name):
    from tissuemech.pipeline import sheet_tests

    return sheet_tests(sample_sheet(name))


def dataset_scopes_of(name):
    """Fit scopes of a dataset; sweeps at >= 2 temperatures get the mastercurve scope instead of frequency_sweep."""
    from tissuemech.scopes import dataset_scopes

    return dataset_scopes(dataset_tests(name), config["fit"], tts=has_tts(name))


def scope_spec(wildcards):
    return dataset_scopes_of(wildcards.dataset)[wildcards.scope]


def fit_scope_inputs(wildcards):
    """averages.nc, and tts.nc for the mastercurve scope (its sweeps are shifted to Tref before the fit)."""
    inputs = {"averages": f"results/{wildcards.dataset}/averages.nc"}
    if scope_spec(wildcards).get("mastercurve"):
        inputs["tts"] = f"results/{wildcards.dataset}/tts.nc"
    return inputs


def scope_rankings(wildcards):
    return [
        f"results/{wildcards.dataset}/ranking/{scope}.csv"
        for scope in dataset_scopes_of(wildcards.dataset)
    ]


def scope_fit_dirs(wildcards):
    return [
        f"results/{wildcards.dataset}/fits/{scope}"
        for scope in dataset_scopes_of(wildcards.dataset)
    ]


def scope_card_dirs(wildcards):
    return [
        f"results/{wildcards.dataset}/cards/{scope}"
        for scope in dataset_scopes_of(wildcards.dataset)
    ]


def diagnosis_scope(name):
    """The scope whose fits the diagnosis reads (tissuemech.pipeline.DIAGNOSIS_SCOPES, shared with
    tissuemech.analysis.analyse_dataset)."""
    from tissuemech.pipeline import diagnosis_scope as first_diagnosis_scope

    return first_diagnosis_scope(dataset_scopes_of(name))


def diagnosis_fits(wildcards):
    return f"results/{wildcards.dataset}/fits/{diagnosis_scope(wildcards.dataset)}"


def is_diagnosed(name):
    """Rheometer or multi-mode data with a diagnosis scope (tissuemech.pipeline.is_diagnosed)."""
    from tissuemech.pipeline import is_diagnosed as diagnosed

    return diagnosed(dataset_tests(name), dataset_scopes_of(name))


def has_shear_ramps(name):
    return "constant_shear_rate" in dataset_tests(name)


def has_diagnosis(name):
    """The dataset gets diagnosis.json (rule diagnose): a diagnosis scope and plate or multi-mode data."""
    return is_diagnosed(name)


def diagnosis_inputs(wildcards):
    """Rule diagnosis: the findings, and the replay's fix.simulation where the dataset's tests are replayed."""
    inputs = {"findings": f"results/{wildcards.dataset}/diagnosis/findings.json"}
    if has_fem_replay(wildcards.dataset):
        inputs["fix_simulation"] = (
            f"results/{wildcards.dataset}/fem/fix_simulation.json"
        )
    return inputs


def has_fem_replay(name):
    """Parallel-plate data with fitted scopes: the FEM replays its measured tests (rule fem_replay)."""
    from tissuemech.pipeline import is_rheometer_dataset

    return is_rheometer_dataset(dataset_tests(name)) and bool(dataset_scopes_of(name))


def tts_temperatures(name):
    """Distinct nominal temperatures (sample sheet ``temperature_c``) of a dataset's frequency sweeps."""
    from tissuemech.pipeline import sweep_temperatures

    return sweep_temperatures(sample_sheet(name))


def has_tts(name):
    """Frequency sweeps at >= 2 distinct temperatures: the dataset gets the TTS scope (rule tts)."""
    return len(tts_temperatures(name)) >= 2


def all_targets():
    targets = []
    for name in DATASETS:
        targets += [
            f"results/{name}/ingest_report.csv",
            f"results/{name}/averages.nc",
            f"results/{name}/lve.csv",
            f"results/{name}/spectrum.nc",
        ]
        if has_tts(name):
            targets.append(f"results/{name}/tts.nc")
        if dataset_scopes_of(name):
            targets += [f"results/{name}/ranking.csv", f"results/{name}/fits.csv"]
        if is_diagnosed(name):
            targets.append(f"results/{name}/diagnosis.json")
        if has_shear_ramps(name):
            targets.append(f"results/{name}/fem/torsion.csv")
        if has_fem_replay(name):
            targets.append(f"results/{name}/fem/replay.csv")
        if name in config["fem"].get("indentation_datasets", []):
            targets.append(f"results/{name}/fem/indentation.nc")
    targets.append("results/fem/timing.csv")
    if BRAIN_INDENTATION:  # defined in fem.smk, read when the target list is built
        targets.append(BRAIN_FILES["brain_indentation"])
    targets.append("results/summary.html")
    return targets


# ---- uncertainty (workflow/rules/uq.smk; rule rank writes fits.csv once the posterior tables exist) ----
POSTERIOR = config.get("posterior", {})


def critical_chain_priority(wildcards):
    """Scheduling priority of a dataset's chain (ingest -> fits -> posterior -> rank -> diagnosis -> replay): the
    datasets with posteriors (posterior.datasets) have the longest chain, so theirs start first, and on few cores
    the run does not end on one long job alone."""
    return (
        10
        if getattr(wildcards, "dataset", None) in POSTERIOR.get("datasets", [])
        else 0
    )


def posterior_scopes_of(name):
    """Scopes of a dataset whose fits get posteriors (config posterior.datasets / .scopes).

    Not the mastercurve scope: uq.run_posterior rebuilds a scope's curves from averages.nc alone, and the
    mastercurve's curve also needs tts.nc (the shift to Tref).
    """
    if name not in POSTERIOR.get("datasets", []):
        return []
    wanted = POSTERIOR.get("scopes") or []
    scopes = dataset_scopes_of(name)
    return [
        s
        for s in scopes
        if (not wanted or s in wanted) and not scopes[s].get("mastercurve")
    ]


def posterior_models_of(name, scope):
    """Models of a scope that are sampled: config posterior.models, or every model the scope fits (so the
    recommended one is always among them); the material scope: its baseline (named ``baseline``; rule posterior
    reads the key from the scope's ranking)."""
    spec = dataset_scopes_of(name)[scope]
    if spec.get("material"):
        # the material scope's candidates are named after the data: its baseline model is sampled
        return ["baseline"]
    fitted = list(spec["models"])
    wanted = POSTERIOR.get("models") or []
    return [m for m in fitted if not wanted or m in wanted]


def posterior_files(wildcards):
    """Posterior files (InferenceData netCDF) of every sampled model of one scope."""
    return [
        f"results/{wildcards.dataset}/posterior/{wildcards.scope}/{m}.nc"
        for m in posterior_models_of(wildcards.dataset, wildcards.scope)
    ]


def posterior_tables(wildcards):
    """Credible-interval tables of every sampled fit of a dataset (inputs of fits.csv)."""
    return [
        f"results/{wildcards.dataset}/posterior/{scope}/{m}.csv"
        for scope in posterior_scopes_of(wildcards.dataset)
        for m in posterior_models_of(wildcards.dataset, scope)
    ]


def uq_targets():
    """Posterior figures (and, with posterior.population, specimen-variability and FEM band) files of every enabled
    dataset and scope (added to the default target in the Snakefile and to the summary's inputs).
    """
    targets = []
    for name in DATASETS:
        for scope in posterior_scopes_of(name):
            for m in posterior_models_of(name, scope):
                targets.append(f"results/{name}/figures/posterior/{scope}/{m}.png")
            if POSTERIOR.get("population", True):
                targets.append(f"results/{name}/population/{scope}.card.json")
                if POSTERIOR.get("fem_draws", 0):
                    targets.append(f"results/{name}/uq/indentation_{scope}.nc")
                    if (
                        scope == "material"
                        and is_diagnosed(name)
                        and has_fem_replay(name)
                    ):
                        # the diagnosis's named extensions pressed beside their baseline (rule
                        # uq_extension_indentation)
                        targets.append(f"results/{name}/uq/extension_indentation.csv")
                    if has_shear_ramps(name):
                        targets.append(f"results/{name}/uq/torsion_{scope}.nc")
    return targets
