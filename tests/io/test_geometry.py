"""Geometry as the files state it: measuring-system names, value+unit cells, dataset.yaml, precedence."""
import math

import pytest

from tissuemech.io.geometry import dataset_geometry, measuring_system, resolve_geometry, value_with_unit
from tissuemech.units import UnknownUnitError


@pytest.mark.parametrize("name, kind, radius_m", [
    ("PP25", "parallel plate", 12.5e-3), ("PP08", "parallel plate", 4e-3), ("PP50", "parallel plate", 25e-3),
    ("PP25/S", "parallel plate", 12.5e-3), ("CP50-1", "cone-plate", 25e-3),
    ("8.0mm parallel plate, Peltier plate Sandblasted  - 93704", "parallel plate", 4e-3),
    ("40.0mm CrossHatched Parallel Plates", "parallel plate", 20e-3),
])
def test_measuring_system_names(name, kind, radius_m):
    geo = measuring_system(name)
    assert geo["measuring_system"] == name and geo["geometry_type"] == kind
    assert geo["radius_m"] == pytest.approx(radius_m)


def test_cone_angle_and_cylinders_without_radius():
    assert measuring_system("CP50-1")["cone_angle_rad"] == pytest.approx(math.pi / 180)
    assert "gap_m" not in measuring_system("CP50-1")              # truncation gap is not in the name
    assert "radius_m" not in measuring_system("CC27")
    assert "radius_m" not in measuring_system("DIN concentric cylinders, Peltier Aluminium 987549")


def test_value_with_unit_is_dimension_checked():
    assert value_with_unit("40.0 mm") == pytest.approx(0.04)
    assert value_with_unit("1000 µm") == pytest.approx(1e-3)
    assert value_with_unit("500 nm") == pytest.approx(5e-7)          # nanometre for a length
    with pytest.raises(UnknownUnitError, match=r"unit 's' \(a s quantity\) cannot be converted to m"):
        value_with_unit("2 s")


@pytest.mark.parametrize("geometry, radius_m, gap_m", [
    ("parallel plate, 25 mm", 12.5e-3, None), ("PP25", 12.5e-3, None),
    ({"type": "parallel plate", "radius_mm": 12.5, "gap_mm": [2.0, 4.0]}, 12.5e-3, None),   # a range: no gap
    ({"diameter_mm": 8, "gap_mm": 3}, 4e-3, 3e-3), (None, None, None),
])
def test_dataset_yaml_geometry(geometry, radius_m, gap_m):
    geo = dataset_geometry(geometry)
    assert geo.get("radius_m") == (pytest.approx(radius_m) if radius_m else None)
    assert geo.get("gap_m") == (pytest.approx(gap_m) if gap_m else None)


def test_precedence_absence_and_conflicts():
    attrs, notes = resolve_geometry({"radius_m": 12.5e-3}, {"radius_m": 12.5e-3}, {"radius_m": 4e-3, "gap_m": 3e-3})
    assert attrs == {"radius_m": 12.5e-3, "radius_source": "samples.csv", "gap_m": 3e-3, "gap_source": "export"}
    assert notes == ["radius conflict: samples.csv 12.5 mm vs export 4 mm (samples.csv used)"]
    attrs, notes = resolve_geometry({}, {"radius_m": 25e-3}, {"radius_m": 25.1e-3})   # 0.4 % apart: no conflict
    assert attrs == {"radius_m": 25e-3, "radius_source": "dataset.yaml"} and notes == ["no gap"]
    attrs, notes = resolve_geometry({}, {}, {})
    assert attrs == {} and notes == ["no plate radius", "no gap"]
