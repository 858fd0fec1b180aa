"""Schema versions of the fit records and the material cards (records.schema_major): written on every file, a file
without one reads as version 0, a newer major version is refused naming the file."""
from __future__ import annotations

import json

import numpy as np
import pytest

from tissuemech import cards as C
from tissuemech.canonical import read_netcdf, write_netcdf
from tissuemech.records import (CARD_SCHEMA_VERSION, FIT_RECORD_SCHEMA_VERSION, CardError, FitRecord, MaterialCard,
                                SchemaVersionError)


def _record():
    return FitRecord(model_key="neo_hookean", family="hyperelastic", params={"mu": 300.0}, stderr={"mu": 3.0},
                     units={"mu": "Pa"}, varying=["mu"], correlation=np.ones((1, 1)))


def test_fit_records_carry_the_version_and_older_ones_read_as_version_0(tmp_path):
    path = tmp_path / "neo_hookean.nc"
    _record().to_netcdf(path)
    ds = read_netcdf(path)
    assert ds.attrs["schema_version"] == FIT_RECORD_SCHEMA_VERSION == "1.0"
    assert FitRecord.from_netcdf(path).schema_version == "1.0"
    del ds.attrs["schema_version"]
    old = tmp_path / "old.nc"
    write_netcdf(ds, old)
    back = FitRecord.from_netcdf(old)
    assert back.schema_version == "0" and back.params == {"mu": 300.0}


@pytest.mark.parametrize("version, message", [("2.0", r"newer than 1\.0"), ("next", "not a 'major.minor'")])
def test_a_fit_record_of_a_newer_major_version_is_refused_naming_the_file(tmp_path, version, message):
    ds = _record().to_dataset()
    ds.attrs["schema_version"] = version
    path = tmp_path / "future.nc"
    write_netcdf(ds, path)
    with pytest.raises(SchemaVersionError, match=message) as err:
        FitRecord.from_netcdf(path)
    assert "future.nc" in str(err.value)
    ds.attrs["schema_version"] = "1.7"  # a newer minor version of the same major layout reads
    write_netcdf(ds, path)
    assert FitRecord.from_netcdf(path).params == {"mu": 300.0}


def test_cards_carry_the_version_and_a_version_0_card_still_writes_every_format(tmp_path):
    """A card written by this code states its version; a card of version 0 (no schema_version, no MARLOW table in
    the card) reads, and its Abaqus block is rebuilt from its registered law."""
    from tissuemech.models.registry import get_model

    model = get_model("lopez_pamies1")
    card = {"model": "lopez_pamies1", "family": "hyperelastic", "elastic_law": "lopez_pamies1",
            "elastic_parameters": {"mu1": 500.0, "alpha1": 3.0}, "initial_shear_modulus": 500.0,
            "poisson_ratio": 0.49, "bulk_modulus": 24833.3, "prony": None, "abaqus_form": "MARLOW",
            "abaqus_constants": [], "validity": {"marlow_strain_max": 0.6}}
    path = tmp_path / "old.json"
    path.write_text(json.dumps(card))
    old = MaterialCard.from_json(path)
    assert old.schema_version == "0"
    block = C.abaqus_block(old)
    strain, stress = C.marlow_uniaxial_table(model, card["elastic_parameters"], 0.6)
    assert f"{stress[-1]:.10g}, {strain[-1]:.10g}" in block
    written = C.write_card_files(old, tmp_path / "new", stem="lp1")
    assert json.loads(written["json"].read_text())["schema_version"] == CARD_SCHEMA_VERSION
    assert MaterialCard.from_json(written["json"]).schema_version == CARD_SCHEMA_VERSION
    assert written["abaqus"].read_text() == block


def test_a_card_of_a_newer_major_version_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "future.json"
    path.write_text(json.dumps({"model": "neo_hookean", "schema_version": "2.0"}))
    with pytest.raises(SchemaVersionError, match=r"material card .*future\.json has schema_version 2\.0"):
        MaterialCard.from_json(path)
    path.write_text(json.dumps({"model": "neo_hookean", "schema_version": "1.3"}))
    assert MaterialCard.from_json(path).schema_version == "1.3"


@pytest.mark.parametrize("block, what", [
    ({"beta": [0.5], "kappa": [0.1, 0.2], "gamma_s": 0.1}, "as many numbers 'beta' as 'kappa'"),
    ({"beta": [0.5], "kappa": [-1.5], "gamma_s": 0.1}, "kappa_i > -1"),
    ({"beta": [0.5], "kappa": [0.1], "gamma_s": 0.0}, "positive number 'gamma_s'"),
    ({"beta": [0.5, 0.1], "kappa": [0.1, 0.1], "gamma_s": 0.1}, "one time per term"),
])
def test_a_malformed_pipkin_rogers_block_is_refused(block, what):
    card = {"model": "pr_nh", "prony": {"g": [0.3], "tau": [1.0]}, "pipkin_rogers": block}
    with pytest.raises(CardError, match=what):
        MaterialCard.from_dict(card)
