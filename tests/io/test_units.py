"""Unit conversion through pint: case-sensitive SI prefixes and a dimension check per column.

Oracles are hand-written SI factors (the definitions of the prefixes and of gram-force), never the code.
"""
import numpy as np
import pytest

from tissuemech.units import UnknownUnitError, canonical_unit, normalise_unit, to_si, unit_factor

G_FORCE = 9.80665e-3  # N, by definition


@pytest.mark.parametrize("unit, expected, factor", [
    # stress: milli vs mega
    ("mPa", "Pa", 1e-3), ("MPa", "Pa", 1e6), ("kPa", "Pa", 1e3), ("GPa", "Pa", 1e9), ("hPa", "Pa", 1e2),
    # viscosity
    ("mPa·s", "Pa s", 1e-3), ("MPa·s", "Pa s", 1e6), ("mPa s", "Pa s", 1e-3), ("[mPa·s]", "Pa s", 1e-3),
    # torque
    ("mN·m", "N m", 1e-3), ("MN·m", "N m", 1e6), ("µN·m", "N m", 1e-6), ("μN.m", "N m", 1e-6),
    ("uN.m", "N m", 1e-6), ("nN.m", "N m", 1e-9), ("[mNm]", "N m", 1e-3), ("Nm", "N m", 1.0),
    ("g·cm", "N m", G_FORCE * 1e-2), ("g.cm", "N m", G_FORCE * 1e-2), ("gf·cm", "N m", G_FORCE * 1e-2),
    # compliance
    ("1/mPa", "1/Pa", 1e3), ("1/MPa", "1/Pa", 1e-6), ("1/kPa", "1/Pa", 1e-3), ("MPa^-1", "1/Pa", 1e-6),
    # force, length, angle
    ("mN", "N", 1e-3), ("MN", "N", 1e6), ("g", "N", G_FORCE), ("mm", "m", 1e-3), ("µm", "m", 1e-6),
    ("Mm", "m", 1e6), ("mrad", "rad", 1e-3), ("µrad", "rad", 1e-6), ("°", "rad", np.pi / 180),
    # rates, frequencies, time
    ("s-¹", "1/s", 1.0), ("1/s", "1/s", 1.0), ("s^-1", "1/s", 1.0), ("1/min", "1/s", 1 / 60), ("Hz", "Hz", 1.0),
    ("1/s", "Hz", 1.0), ("mHz", "Hz", 1e-3), ("MHz", "Hz", 1e6), ("rad/s", "rad/s", 1.0), ("min", "s", 60.0),
    ("h", "s", 3600.0), ("ms", "s", 1e-3), ("Ms", "s", 1e6),
    # strain
    ("%", "1", 0.01), ("", "1", 1.0), ("-", "1", 1.0),
])
def test_prefix_case_and_factor(unit, expected, factor):
    f, offset = unit_factor(unit, expected)
    assert f == pytest.approx(factor, rel=1e-12)
    assert offset == 0.0
    assert float(to_si(2.5, unit, expected)) == pytest.approx(2.5 * factor, rel=1e-12)


def test_milli_and_mega_differ_by_1e9():
    assert unit_factor("MPa", "Pa")[0] / unit_factor("mPa", "Pa")[0] == pytest.approx(1e9)
    assert unit_factor("1/mPa", "1/Pa")[0] / unit_factor("1/MPa", "1/Pa")[0] == pytest.approx(1e9)


@pytest.mark.parametrize("unit, value, celsius", [("°C", 37.0, 37.0), ("degC", 37.0, 37.0), ("C", 20.0, 20.0),
                                                  ("K", 310.15, 37.0), ("[°C]", -5.0, -5.0)])
def test_temperature_offsets(unit, value, celsius):
    assert float(to_si(value, unit, "degC")) == pytest.approx(celsius, abs=1e-9)


@pytest.mark.parametrize("unit, expected, message", [
    ("Hz", "rad/s", r"unit 'Hz' \(a 1/s quantity\) cannot be converted to rad/s"),
    ("rad/s", "Hz", r"unit 'rad/s' \(a rad/s quantity\) cannot be converted to Hz"),
    ("s", "m", r"unit 's' \(a s quantity\) cannot be converted to m"),        # a gap in seconds
    ("mm", "s", r"cannot be converted to s"),
    ("rad", "1", r"unit 'rad' \(a rad quantity\) cannot be converted to 1"),
    ("", "Pa", r"no unit given where Pa is expected \(never assumed\)"),
    ("pa", "Pa", r"cannot be converted to Pa|unknown unit"),                  # lower-case pascal is not Pa
    ("PA", "Pa", r"cannot be converted to Pa|unknown unit"),
    ("Pascal", "Pa", r"unknown unit 'Pascal'"),
    ("g", "Pa", r"cannot be converted to Pa"),
])
def test_units_of_another_dimension_are_refused(unit, expected, message):
    with pytest.raises(UnknownUnitError, match=message):
        to_si(1.0, unit, expected)


def test_nm_is_resolved_by_the_expected_dimension():
    assert unit_factor("nm", "m") == (pytest.approx(1e-9), 0.0)      # nanometre gap
    assert unit_factor("nm", "N m") == (1.0, 0.0)                     # newton-metre torque
    with pytest.raises(UnknownUnitError, match="ambiguous unit 'nm'"):
        unit_factor("nm")


def test_without_expected_the_canonical_unit_is_named():
    assert canonical_unit("1/MPa") == "1/Pa"
    assert canonical_unit("g·cm") == "N m"
    assert canonical_unit("rad/s") == "rad/s"
    assert canonical_unit("1/°C") == "1/K"
    assert normalise_unit("[mN·m]") == "mN.m"
    assert normalise_unit("MPa") != normalise_unit("mPa")
