import numpy as np
import pytest

from tissuemech import canonical


def test_make_run_dataset_units_and_attrs(tmp_path):
    ds = canonical.make_run_dataset(
        {"time": [0.0, 1.0], "shear_stress": [1.0, 2.0]},
        {"test": "stress_relaxation", "flag": True, "missing": None},
    )
    assert ds["time"].attrs["units"] == "s"
    assert ds["shear_stress"].attrs["units"] == "Pa"
    assert ds.attrs["flag"] == 1 and "missing" not in ds.attrs
    path = canonical.write_netcdf(ds, tmp_path / "run.nc")
    back = canonical.read_netcdf(path)
    np.testing.assert_array_equal(back["shear_stress"].values, [1.0, 2.0])


def test_unknown_variable_is_rejected():
    with pytest.raises(KeyError, match="not a canonical variable"):
        canonical.make_run_dataset({"strain_pct": [1.0]}, {})


def test_atomic_write_leaves_no_partial_file(tmp_path):
    target = tmp_path / "out.txt"

    def failing_writer(tmp):
        with open(tmp, "w") as fh:
            fh.write("half")
        raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError):
        canonical.atomic_write(target, failing_writer)
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_to_jsonable_is_the_one_json_sanitiser(tmp_path):
    """numpy scalars and arrays become Python values, NaN/inf become null (or stay, for allow_nan files), keys
    become strings, Path and other objects their str, dataclasses dicts of their fields."""
    import dataclasses
    import json
    from pathlib import Path

    @dataclasses.dataclass
    class Point:
        x: float
        tags: tuple

    obj = {1: np.float32(0.5), "i": np.int64(3), "b": np.bool_(True), "a": np.array([[1.0, np.nan], [np.inf, 2.0]]),
           "t": (np.float64(-np.inf), None, "s"), "p": Path("a/b.nc"), "d": Point(np.float64(1.5), ("u",))}
    got = canonical.to_jsonable(obj)
    assert got == {"1": 0.5, "i": 3, "b": True, "a": [[1.0, None], [None, 2.0]], "t": [None, None, "s"],
                   "p": "a/b.nc", "d": {"x": 1.5, "tags": ["u"]}}
    assert type(got["i"]) is int and type(got["b"]) is bool and type(got["1"]) is float
    kept = canonical.to_jsonable(obj, nonfinite_as_null=False)
    assert np.isnan(kept["a"][0][1]) and kept["a"][1][0] == np.inf and kept["t"][0] == -np.inf
    path = canonical.write_json(obj, tmp_path / "x.json")
    assert path.read_text().endswith("}\n") and json.loads(path.read_text()) == got
