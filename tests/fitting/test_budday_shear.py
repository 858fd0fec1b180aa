"""Real human brain data (Budday et al. 2017, read in place from ../shared/data/real): hyperelastic fits to the
simple-shear curves order the regions' initial shear moduli as the paper does, cortex (about 1.2 kPa) >
corona radiata > basal ganglia > corpus callosum."""
from __future__ import annotations

from pathlib import Path

import pytest

from tissuemech import fitting as F
from tissuemech.io.ingest import ingest_dataset
from tissuemech.models.base import initial_shear_modulus
from tissuemech.models.registry import get_model
from tissuemech.pipeline import load_runs

ROOT = Path(__file__).resolve().parents[2]
REGIONS = ("cortex", "corona_radiata", "basal_ganglia", "corpus_callosum")
# Budday et al. 2017 (shared/data/real/README.md): initial shear modulus per region, kPa
PAPER_MU_KPA = {"cortex": 1.2, "corona_radiata": 0.6, "basal_ganglia": 0.56, "corpus_callosum": 0.29}


def _shear_curve(region, tmp_path):
    folder = ROOT / "config" / "external" / f"budday_{region}"
    report = ingest_dataset(folder, tmp_path / region / "runs", tmp_path / region / "report.csv")
    assert (report["status"] == "ok").all(), report
    runs = [r for r in load_runs(tmp_path / region / "runs") if r.attrs["test"] == "simple_shear"]
    assert len(runs) == 1
    return F.curve_from_run(runs[0])


def _initial_moduli(law, tmp_path):
    mu = {}
    for region in REGIONS:
        curve = _shear_curve(region, tmp_path)
        model = get_model(law)
        result = F.fit(F.FitProblem(model=model, curves=[curve], target="none", model_key=law, scope="simple_shear"),
                       n_random=2, seed=11)
        assert result.success
        mu[region] = initial_shear_modulus(model, result.params)
    return mu


def test_initial_shear_moduli_order_with_the_best_ranked_shear_law(shared_real, tmp_path):
    """RP3 ranks first on the simple-shear scope of cortex and corona radiata (pipeline ranking)."""
    mu = _initial_moduli("reduced_polynomial3", tmp_path)
    assert mu["cortex"] > mu["corona_radiata"] > mu["basal_ganglia"] > mu["corpus_callosum"], mu
    assert mu["cortex"] == pytest.approx(1200.0, rel=0.1), mu


def test_one_term_ogden_shear_fit_matches_the_paper(shared_real, tmp_path):
    """The paper's moduli come from one-term Ogden fits; fitted to shear alone they agree within 30 % (corpus callosum: +25 %). Corona
    radiata and basal ganglia are 0.60 and 0.56 kPa in the paper; on the digitised shear curves they tie within
    5 % (their order is not resolved by this law), so only the clear gaps are asserted as an order."""
    mu = _initial_moduli("ogden1", tmp_path)
    for region, paper_kpa in PAPER_MU_KPA.items():
        assert mu[region] == pytest.approx(1e3 * paper_kpa, rel=0.3), (region, mu)
    assert mu["cortex"] > 1.5 * max(mu["corona_radiata"], mu["basal_ganglia"])
    assert min(mu["corona_radiata"], mu["basal_ganglia"]) > 1.5 * mu["corpus_callosum"]
    assert mu["corona_radiata"] == pytest.approx(mu["basal_ganglia"], rel=0.05)
