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
