"""records.MaterialCard: the one card reader (validated), and the FEM's view of a card."""
from __future__ import annotations

import json

import pytest

from tissuemech import cards as C
from tissuemech import stages
from tissuemech.records import CardError, MaterialCard


def test_a_written_card_reads_back_field_by_field(qlv_rp3_fit, tmp_path):
    model, result = qlv_rp3_fit
    card = C.make_card(result, model, poisson_ratio=0.45)
    paths = C.write_card_files(card, tmp_path, stem="qlv_rp3_prony4")
    raw = json.loads(paths["json"].read_text())
    read = MaterialCard.from_json(paths["json"])
    assert read.data == raw
    assert read.model == "qlv_rp3_prony4" and read.elastic_law == "reduced_polynomial3"
    assert read.elastic_parameters == raw["elastic_parameters"] and set(read.elastic_parameters) == {"C10", "C20", "C30"}
    assert read.poisson_ratio == 0.45 and read.bulk_modulus == raw["bulk_modulus"] > 0
    assert read.initial_shear_modulus == pytest.approx(2 * raw["elastic_parameters"]["C10"], rel=1e-6)
    assert read.prony["g"] == raw["prony"]["g"] and len(read.prony["tau"]) == 4
    assert read.fem_law == "reduced_polynomial3" and read.for_fem() == raw  # not a linear law: unchanged


@pytest.mark.parametrize("card, what", [
    ({"elastic_law": "neo_hookean"}, "'model'"),
    ({"model": "m", "elastic_law": 3}, "'elastic_law'"),
    ({"model": "m", "elastic_parameters": {"mu": "100"}}, "'elastic_parameters'"),
    ({"model": "m", "poisson_ratio": "0.49"}, "'poisson_ratio'"),
    ({"model": "m", "prony": {"g": [0.1, 0.2], "tau": [1.0]}}, "'prony'"),
    ({"model": "m", "prony": {"g": [0.1], "tau": [-1.0]}}, "'prony'"),
    ([1, 2], "JSON object"),
])
def test_a_malformed_card_is_refused_naming_the_field(card, what):
    with pytest.raises(CardError, match=what):
        MaterialCard.from_dict(card)


def test_the_card_writer_refuses_what_the_reader_refuses(tmp_path):
    with pytest.raises(CardError, match="'prony'"):
        C.write_card_files({"model": "m", "prony": {"g": [0.1], "tau": [1.0, 2.0]}}, tmp_path)
    assert not list(tmp_path.iterdir())


def test_a_linear_shear_card_runs_as_neo_hookean_with_mu_g0(tmp_path):
    """A card that still names the linear shear law (cards.material_fields writes neo-Hookean instead): the FEM
    runs the neo-Hookean law with mu = the initial shear modulus, else the law's own G0 / G."""
    for law, params, mu0, expected in (("linear_elastic_shear", {"G0": 250.0}, 240.0, 240.0),
                                       ("linear_elastic_shear", {"G0": 250.0}, None, 250.0),
                                       ("linear_elastic", {"G": 180.0}, None, 180.0)):
        path = tmp_path / f"{law}.json"
        card = {"model": "qlv_linear_prony4", "elastic_law": law, "elastic_parameters": params,
                "poisson_ratio": 0.49, "prony": {"g": [0.2], "tau": [1.0], "g_inf": 0.8}}
        if mu0 is not None:
            card["initial_shear_modulus"] = mu0
        path.write_text(json.dumps(card))
        read = MaterialCard.from_json(path)
        assert read.fem_law == "neo_hookean"
        fem = stages.card_for_fem(path)
        assert fem["elastic_law"] == "neo_hookean" and fem["elastic_parameters"] == {"mu": expected}
        assert fem["prony"] == card["prony"] and fem["poisson_ratio"] == 0.49
        assert read.data == card  # the record keeps the card as written
