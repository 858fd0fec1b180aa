"""Canonical run representation shared by every stage.

A *run* is one test (one block/interval/step of an instrument export) on one sample. After ingest it is an
:class:`xarray.Dataset` with a single dimension ``point`` and the variables below, always in SI units
(temperature in degree Celsius, the unit every rheometer reports). Variables absent from an export are
simply absent from the dataset. Oscillatory tests store *amplitudes* in ``shear_strain``/``shear_stress``.

The table :data:`CANONICAL_VARIABLES` is the single source of names and units: readers map instrument
labels onto it, the synthetic rheometer writes it, models and fits read it.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import xarray as xr

#: canonical variable name -> (units, long name). Strain is dimensionless (0.01 = 1 %).
CANONICAL_VARIABLES: dict[str, tuple[str, str]] = {
    "time": ("s", "time since start of the test (interval/step)"),
    "total_time": ("s", "time since start of the measurement session (elapsed time)"),
    "shear_strain": ("1", "rim shear strain (amplitude for oscillation)"),
    "shear_stress": ("Pa", "rim shear stress as reported by the instrument, 2M/(pi R^3) (amplitude for oscillation)"),
    "shear_rate": ("1/s", "rim shear rate"),
    "viscosity": ("Pa s", "shear viscosity"),
    "torque": ("N m", "torque (amplitude for oscillation)"),
    "deflection_angle": ("rad", "plate deflection angle (amplitude for oscillation)"),
    "normal_force": ("N", "normal (axial) force, positive when the sample pushes the plates apart"),
    "gap": ("m", "measuring gap"),
    "temperature": ("degC", "sample temperature"),
    "frequency": ("Hz", "oscillation frequency"),
    "angular_frequency": ("rad/s", "oscillation angular frequency"),
    "storage_modulus": ("Pa", "storage modulus G'"),
    "loss_modulus": ("Pa", "loss modulus G''"),
    "complex_modulus": ("Pa", "magnitude of the complex modulus |G*|"),
    "loss_factor": ("1", "tan(delta) = G''/G'"),
    "phase_angle": ("rad", "phase angle delta of the sample"),
    "raw_phase": ("rad", "raw (uncorrected) phase between torque and displacement"),
    "complex_viscosity": ("Pa s", "complex viscosity |eta*|"),
    "relaxation_modulus": ("Pa", "relaxation modulus G(t) = stress / step strain"),
    "creep_compliance": ("1/Pa", "creep compliance J(t) = strain / stress"),
    "stretch": ("1", "stretch ratio lambda (uniaxial)"),
    "nominal_stress": ("Pa", "first Piola-Kirchhoff (nominal) stress P11 (uniaxial) or P12 (simple shear)"),
    "force": ("N", "indentation/uniaxial force"),
    "displacement": ("m", "indenter or crosshead displacement"),
}

#: test kinds accepted in samples.csv ``test``
TEST_KINDS: tuple[str, ...] = (
    "amplitude_sweep",
    "frequency_sweep",
    "constant_shear_rate",
    "stress_relaxation",
    "creep_recovery",
    "flow_curve",
    "simple_shear",
    "uniaxial",
    "indentation",
)

#: run attributes always present after ingest
REQUIRED_RUN_ATTRS: tuple[str, ...] = (
    "dataset", "run", "test", "specimen", "sample", "order", "source_file", "source_sha256",
)


#: optional geometry run attributes, present only when a source states them (never NaN, never a default):
#: ``radius_m``/``gap_m`` in metres, ``radius_source``/``gap_source`` one of :data:`GEOMETRY_SOURCES` (or
#: ``export (axial step)``: a gap read from the TA ``Axial`` step before the block, ``io.geometry.axial_step_gap``),
#: ``measuring_system`` as the export or dataset.yaml names it (e.g. ``PP25``)
GEOMETRY_RUN_ATTRS: tuple[str, ...] = ("radius_m", "radius_source", "gap_m", "gap_source", "measuring_system")
#: where a run's geometry came from, in order of precedence
GEOMETRY_SOURCES: tuple[str, ...] = ("samples.csv", "dataset.yaml", "export")


def sha256_of(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def make_run_dataset(columns: Mapping[str, np.ndarray], attrs: Mapping[str, object]) -> xr.Dataset:
    """Build a canonical run dataset.

    Parameters
    ----------
    columns : mapping of canonical name -> 1-D array (SI units, see :data:`CANONICAL_VARIABLES`)
    attrs : run attributes (test, specimen, sample, order, geometry ``radius_m``/``gap_m``, provenance ...).
        ``None`` values are dropped; booleans are stored as int (netCDF has no bool attribute).

    Returns
    -------
    xarray.Dataset with dimension ``point``.
    """
    data_vars = {}
    for name, values in columns.items():
        if name not in CANONICAL_VARIABLES:
            raise KeyError(f"{name!r} is not a canonical variable; known: {sorted(CANONICAL_VARIABLES)}")
        units, long_name = CANONICAL_VARIABLES[name]
        data_vars[name] = ("point", np.asarray(values, dtype=float), {"units": units, "long_name": long_name})
    ds = xr.Dataset(data_vars)
    clean = {}
    for k, v in attrs.items():
        if v is None:
            continue
        if isinstance(v, (bool, np.bool_)):
            v = int(v)
        clean[k] = v
    ds.attrs.update(clean)
    return ds


def atomic_write(path: str | os.PathLike, writer) -> Path:
    """Write a file atomically: ``writer(tmp_path)`` writes a temporary sibling, then it is renamed.

    An interrupted job therefore never leaves a half-written output under the final name.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        writer(tmp)
        # mkstemp creates 0600 files; outputs get the permissions a plain open() would give (umask applies)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


#: xarray engine of every netCDF file the package writes and reads: netCDF4-python (the C library) writes and reads
#: our many small files 7-9x faster than h5netcdf (65 vs 10 ms written, 72 vs 8 ms read for a 15-variable run
#: file, issue 17); the files are the same netCDF4/HDF5 format either way
NETCDF_ENGINE = "netcdf4"


def write_netcdf(ds: xr.Dataset, path: str | os.PathLike) -> Path:
    """Atomically write a dataset as netCDF4/HDF5 (engine :data:`NETCDF_ENGINE`)."""
    return atomic_write(path, lambda tmp: ds.to_netcdf(tmp, engine=NETCDF_ENGINE))


def write_text(text: str, path: str | os.PathLike) -> Path:
    """Atomically write a UTF-8 text file."""
    def _w(tmp):
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
    return atomic_write(path, _w)


def to_jsonable(obj, *, nonfinite_as_null: bool = True):
    """A JSON-safe copy of ``obj`` (the one JSON sanitiser of the package).

    Mappings become dicts with string keys; lists, tuples and numpy arrays become lists; numpy scalars become
    Python ``bool``/``int``/``float``; dataclass instances become dicts of their fields; ``Path`` and any other
    object become their ``str``. Non-finite floats (NaN, +-inf) become ``None`` (JSON ``null``) by default;
    with ``nonfinite_as_null=False`` they stay floats, for files written with ``allow_nan`` (material cards,
    fit-record attributes) or as YAML (``.nan``).
    """
    def conv(o):
        if isinstance(o, Mapping):
            return {str(k): conv(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [conv(v) for v in o]
        if isinstance(o, np.ndarray):
            return [conv(v) for v in o.tolist()]
        if isinstance(o, (bool, np.bool_)):
            return bool(o)
        if isinstance(o, (int, np.integer)):
            return int(o)
        if isinstance(o, (float, np.floating)):
            return float(o) if (math.isfinite(float(o)) or not nonfinite_as_null) else None
        if o is None or isinstance(o, str):
            return o
        if dataclasses.is_dataclass(o) and not isinstance(o, type):
            return conv({f.name: getattr(o, f.name) for f in dataclasses.fields(o)})
        return str(o)
    return conv(obj)


def write_json(obj, path: str | os.PathLike, *, indent: int | None = 2, sort_keys: bool = False,
               nonfinite_as_null: bool = True, newline: bool = True) -> Path:
    """Atomically write ``obj`` as JSON through :func:`to_jsonable` (``newline``: end the file with one)."""
    text = json.dumps(to_jsonable(obj, nonfinite_as_null=nonfinite_as_null), indent=indent, sort_keys=sort_keys)
    return write_text(text + ("\n" if newline else ""), path)


def read_netcdf(path: str | os.PathLike) -> xr.Dataset:
    """Read a netCDF file fully into memory and close it (never keep an output path open lazily)."""
    with xr.open_dataset(path, engine=NETCDF_ENGINE) as ds:
        return ds.load()
