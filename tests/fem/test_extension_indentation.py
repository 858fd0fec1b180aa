"""What a named extension changes in the flat-punch force, against the baseline's bands
(:func:`tissuemech.uq.extension_indentation`).

Oracle: scaling. A card whose moduli (shear and bulk) are all 1.3 times the baseline's, at the same Poisson's ratio
and relaxation spectrum, gives 1.3 times every stress of the same displacement-controlled run, so the indentation
force is 1.3 times the baseline's: relative difference 0.3, whatever the mesh or the punch."""
import json

import numpy as np
import pytest
import xarray as xr

from tissuemech.canonical import write_netcdf
from tissuemech.uq import EXTENSION_INDENTATION_COLUMNS, extension_indentation

MU, NU = 1000.0, 0.45


def _card(mu):
    bulk = 2.0 * mu * (1.0 + NU) / (3.0 * (1.0 - 2.0 * NU))
    return {"schema_version": "1.0", "model": "qlv_neo_hookean_prony2", "family": "qlv",
            "elastic_law": "neo_hookean", "elastic_parameters": {"mu": mu}, "initial_shear_modulus": mu,
            "poisson_ratio": NU, "bulk_modulus": bulk,
            "prony": {"g": [0.3, 0.2], "tau": [0.5, 5.0], "g_inf": 0.5}}


def _bands(path, optimum_n, measurement, specimen):
    depth = np.linspace(0.25e-3, 1.5e-3, 6)
    scale = depth / depth[-1]
    data = {"force_optimum": ("point", optimum_n * scale)}
    for src, (lo, hi) in (("measurement", measurement), ("specimen", specimen)):
        data[f"{src}_q05"] = ("point", lo * optimum_n * scale)
        data[f"{src}_q95"] = ("point", hi * optimum_n * scale)
    ds = xr.Dataset(data, coords={"depth": ("point", depth)},
                    attrs={"punch_diameter_m": 8e-3, "max_depth_m": 1.5e-3, "speed_m_s": 1e-4,
                           "element_size_m": 4e-3, "n_increments": 3})
    write_netcdf(ds, path)


@pytest.fixture
def cards(tmp_path):
    folder = tmp_path / "simulation_cards"
    folder.mkdir()
    (folder / "cause_x.baseline.json").write_text(json.dumps(_card(MU)))
    (folder / "cause_x.json").write_text(json.dumps(_card(1.3 * MU)))
    (folder / "index.json").write_text(json.dumps(
        {"baseline": "qlv_neo_hookean_prony2",
         "causes": {"cause_x": {"extension_model": "stiffer", "baseline_model": "qlv_neo_hookean_prony2",
                                "card": "cause_x.json", "baseline_card": "cause_x.baseline.json", "folds": []},
                    "no_card": {"note": "no Poisson's ratio given: no card written"}}}))
    return folder


def test_the_extension_force_against_the_baselines_bands(tmp_path, cards):
    # bands around an optimum that is not the baseline card's force: they are applied relative to it
    _bands(tmp_path / "bands.nc", 0.01, measurement=(0.95, 1.05), specimen=(0.5, 1.6))
    table = extension_indentation(tmp_path / "bands.nc", cards, tmp_path / "out.csv")
    assert list(table.columns) == list(EXTENSION_INDENTATION_COLUMNS)
    assert table["cause"].tolist() == ["cause_x"]   # a cause without cards has no row
    row = table.iloc[0]
    assert row["status"] == "ok" and row["depth_m"] == 1.5e-3
    assert row["baseline_force_n"] > 0
    assert row["relative_difference"] == pytest.approx(0.3, rel=1e-6)
    assert row["extension_force_n"] == pytest.approx(1.3 * row["baseline_force_n"], rel=1e-6)
    assert row["measurement_q95_n"] == pytest.approx(1.05 * row["baseline_force_n"])
    assert bool(row["outside_measurement_band"]) and not bool(row["outside_specimen_band"])
    assert (tmp_path / "out.csv").read_text().startswith("cause,")


def test_nothing_named_writes_an_empty_table(tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    (folder / "index.json").write_text(json.dumps({"baseline": "x", "causes": {}}))
    _bands(tmp_path / "bands.nc", 0.01, (0.95, 1.05), (0.5, 1.6))
    table = extension_indentation(tmp_path / "bands.nc", folder, tmp_path / "out.csv")
    assert table.empty and list(table.columns) == list(EXTENSION_INDENTATION_COLUMNS)


def test_the_extension_in_the_brain_geometry_scales_too(tmp_path, cards):
    """With a mesh for the brain, both cards are also pressed into it: the same scaling oracle, the flat punch's
    bands taken relative, and the contact resolution reported."""
    from tissuemech.fem.mesh import block_mesh
    from tissuemech.uq import BRAIN_GEOMETRY, FLAT_PUNCH_GEOMETRY

    # a stand-in for the brain, taller than the supported 25 mm base
    mesh = block_mesh((0.03, 0.03, 0.04), (3, 3, 4))
    _bands(tmp_path / "bands.nc", 0.01, measurement=(0.95, 1.05), specimen=(0.5, 1.6))
    table = extension_indentation(tmp_path / "bands.nc", cards, tmp_path / "out.csv", brain_mesh=mesh)
    assert table["geometry"].tolist() == [FLAT_PUNCH_GEOMETRY, BRAIN_GEOMETRY]
    brain = table.set_index("geometry").loc[BRAIN_GEOMETRY]
    assert brain["status"] == "ok" and brain["baseline_force_n"] > 0
    assert brain["relative_difference"] == pytest.approx(0.3, rel=1e-6)
    assert brain["specimen_q05_n"] == pytest.approx(0.5 * brain["baseline_force_n"])
    assert brain["punch_nodes"] >= 1
    assert np.isnan(table.set_index("geometry").loc[FLAT_PUNCH_GEOMETRY, "punch_nodes"])
