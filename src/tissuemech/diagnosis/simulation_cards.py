"""The cards the simulator replays to score a named cause's material extension on tests it was not fitted to.

A model-level fix (:data:`tissuemech.diagnosis.report.MODEL_FIXES`, e.g. ``nonseparable_relaxation``: QLV ->
Pipkin-Rogers) is scored by refitting the baseline and the extension on the training runs of each fold
(:func:`tissuemech.diagnosis.baseline.extension_gain`). Those fits become cards here, so that the FEM replay
(:mod:`tissuemech.fem.replay`, rule ``fem_replay``) runs the same comparison in the simulator:

* ``<cause>.json`` -- the extension fitted to every run (the card a simulation of the material would use), and
  ``<cause>.baseline.json`` -- the baseline fitted to the same runs by the same path (the pair the simulator
  compares on a new experiment, e.g. :func:`tissuemech.uq.extension_indentation`);
* ``<cause>.<fold>.baseline.json`` / ``<cause>.<fold>.extension.json`` -- both models fitted without the fold's
  held-out runs; their ``valid_range.tests``/``conditions`` list the averaged curves (``test|condition``, the
  labels of ``averages.nc``) the fits saw, so the replay marks every other curve ``held_out``;
* ``index.json`` -- what was written: per cause the two full-data cards (``card``, ``baseline_card``), and per fold
  the two cards and the held-out curves.

Nothing is written for a cause that was not named (``detected``), whose fix was not scored, or whose fix kept no
fits (a fix that is not a refit: an offset, a shift, a correction of the data). The folder itself is always
written, so the workflow's output exists.
"""
from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import xarray as xr

from ..canonical import write_json
from ..cards import make_card, write_card_files
from ..curves import condition_label, condition_of
from ..models.registry import model_on_times
from ..records import SIMULATION_CARDS_INDEX
from .findings import write_diagnosis_json



def curve_key(run: xr.Dataset) -> str:
    """The averaged curve a run belongs to, as ``averages.nc`` and the replay name it: ``test|condition``."""
    return f"{run.attrs.get('test', '')}|{condition_label(condition_of(run))}"


def fold_stem(cause: str, label: str) -> str:
    """A file-name stem for one fold of a cause (``nonseparable_relaxation.csr_0.001_1_s``)."""
    return f"{cause}.{re.sub(r'[^A-Za-z0-9.]+', '_', label).strip('_')}"


def _card(result, key: str, taus: Sequence[float], train: Sequence[xr.Dataset], poisson_ratio: float,
          dataset: str, role: str) -> dict:
    card = make_card(result, model_on_times(key, taus), poisson_ratio=poisson_ratio, dataset=dataset)
    valid = dict(card.get("valid_range") or {})
    valid["tests"] = sorted({str(r.attrs.get("test", "")) for r in train})
    valid["conditions"] = sorted({curve_key(r) for r in train})
    card["valid_range"] = valid
    card["simulation_role"] = role
    return card


def write_simulation_cards(result: Mapping, simulation_fits: Mapping[str, Sequence[Mapping]], out_dir,
                           poisson_ratio: float | None, dataset: str = "") -> dict:
    """Write the simulation cards of every named cause with a scored model-level fix (module docstring).

    Parameters
    ----------
    result : the diagnosis result (``findings`` with ``detected`` and ``fix``; ``model``: the baseline key)
    simulation_fits : cause -> the fits its fix kept (:func:`~tissuemech.diagnosis.baseline.extension_gain`
        ``fits_out``: ``label``, ``train``, ``held_out`` runs, ``baseline`` and ``extension`` fit results)
    out_dir : the folder (created)
    poisson_ratio : the configuration's ``fem.poisson_ratio``; without it no card is written (the index says so)
    dataset : the dataset name recorded in the cards

    Returns
    -------
    The index written to ``<out_dir>/index.json``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    index: dict = {"baseline": result.get("model"), "causes": {}}
    for finding in result.get("findings", []) or []:
        cause, fix = finding.get("effect"), finding.get("fix") or {}
        fits = simulation_fits.get(cause) or []
        if not finding.get("detected") or not fits:
            continue
        if poisson_ratio is None:
            index["causes"][cause] = {"note": "no Poisson's ratio given: no card written"}
            continue
        taus = fix.get("relaxation_times_s") or []
        entry = {"extension_model": fix.get("model"), "baseline_model": result.get("model"), "folds": []}
        for f in fits:
            if f["label"] == "all":
                card = _card(f["extension"], fix["model"], taus, f["train"], poisson_ratio, dataset, cause)
                write_card_files(card, out, stem=cause)
                entry["card"] = f"{cause}.json"
                write_card_files(_card(f["baseline"], str(result.get("model")), taus, f["train"], poisson_ratio,
                                       dataset, f"{cause}:baseline"), out, stem=f"{cause}.baseline")
                entry["baseline_card"] = f"{cause}.baseline.json"
                continue
            stem = fold_stem(cause, f["label"])
            write_card_files(_card(f["baseline"], str(result.get("model")), taus, f["train"], poisson_ratio, dataset,
                                   f"{cause}:baseline"), out, stem=f"{stem}.baseline")
            write_card_files(_card(f["extension"], fix["model"], taus, f["train"], poisson_ratio, dataset, cause), out,
                             stem=f"{stem}.extension")
            entry["folds"].append({"label": f["label"], "baseline": f"{stem}.baseline.json",
                                   "extension": f"{stem}.extension.json",
                                   "held_out": sorted({curve_key(r) for r in f["held_out"]})})
        index["causes"][cause] = entry
    write_json(index, out / SIMULATION_CARDS_INDEX)
    return index


def attach_simulation(core_json, fix_json, out_json) -> dict:
    """The final ``diagnosis.json``: the diagnosis (``core_json``) with ``fix.simulation`` on each named cause the
    simulator scored (``fix_json``, the replay's :func:`tissuemech.stages.simulation_fixes`; None where the dataset
    has no replay) and a top-level ``simulation`` saying what was replayed."""
    result = json.loads(Path(core_json).read_text())
    dataset = result.pop("dataset", "")
    fixes = json.loads(Path(fix_json).read_text()) if fix_json is not None and Path(fix_json).is_file() else None
    for finding in result.get("findings", []):
        record = (fixes or {}).get(finding.get("effect"))
        if record is not None and isinstance(finding.get("fix"), dict):
            finding["fix"]["simulation"] = record
    result["simulation"] = ("the dataset's tests are not replayed in the simulator" if fixes is None else
                            {"replayed_causes": sorted(fixes)})
    write_diagnosis_json(result, out_json, dataset=dataset)
    return result
