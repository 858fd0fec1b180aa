"""Unit strings as rheometers write them -> SI (factor and offset), per column.

``to_si(values, unit)`` returns ``values * factor + offset`` in the canonical unit of
:data:`tissuemech.canonical.CANONICAL_VARIABLES` (temperature stays in degree Celsius). Unknown units raise
:class:`UnknownUnitError`: a column is never assumed to be in seconds or pascal. With ``expected`` (the
canonical unit of the column, e.g. ``"Pa"``) a unit of another quantity (``s`` for a stress, ``Hz`` for an
angular frequency, no unit at all for a modulus) is refused as well.

Spellings understood (after :func:`normalise_unit`): brackets ``[mN·m]``, middle dots and spaces as products
(``N m``, ``Pa·s``), micro as ``µ``/``μ``/``u``, superscripts (``s-¹``), ``°C``/``°``, ``g.cm`` (gram-force
centimetre, TA torque), ``1/MPa`` (compliance), ``min``/``h``, ``%``.
"""
from __future__ import annotations

import re

import numpy as np

GRAM_FORCE_N = 9.80665e-3

#: normalised unit string -> (factor, offset, canonical SI unit it converts to)
_TABLE: dict[str, tuple[float, float, str]] = {
    # dimensionless / strain
    "": (1.0, 0.0, "1"), "1": (1.0, 0.0, "1"), "-": (1.0, 0.0, "1"), "%": (0.01, 0.0, "1"),
    # time
    "s": (1.0, 0.0, "s"), "sec": (1.0, 0.0, "s"), "ms": (1e-3, 0.0, "s"), "min": (60.0, 0.0, "s"),
    "h": (3600.0, 0.0, "s"),
    # stress / modulus
    "pa": (1.0, 0.0, "Pa"), "kpa": (1e3, 0.0, "Pa"), "mpa": (1e6, 0.0, "Pa"), "gpa": (1e9, 0.0, "Pa"),
    "hpa": (100.0, 0.0, "Pa"), "mpa_milli": (1e-3, 0.0, "Pa"),
    # compliance
    "1/pa": (1.0, 0.0, "1/Pa"), "1/kpa": (1e-3, 0.0, "1/Pa"), "1/mpa": (1e-6, 0.0, "1/Pa"),
    "pa^-1": (1.0, 0.0, "1/Pa"),
    # rates and frequencies
    "1/s": (1.0, 0.0, "1/s"), "s^-1": (1.0, 0.0, "1/s"), "s-1": (1.0, 0.0, "1/s"), "1/sec": (1.0, 0.0, "1/s"),
    "1/min": (1 / 60.0, 0.0, "1/s"), "hz": (1.0, 0.0, "Hz"), "rad/s": (1.0, 0.0, "rad/s"),
    # viscosity
    "pa.s": (1.0, 0.0, "Pa s"), "pas": (1.0, 0.0, "Pa s"), "mpa.s": (1e-3, 0.0, "Pa s"),
    "pa.s^n": (1.0, 0.0, "Pa s^n"),
    # torque
    "n.m": (1.0, 0.0, "N m"), "nm": (1.0, 0.0, "N m"), "mn.m": (1e-3, 0.0, "N m"), "un.m": (1e-6, 0.0, "N m"),
    "nn.m": (1e-9, 0.0, "N m"), "g.cm": (GRAM_FORCE_N * 1e-2, 0.0, "N m"),
    "gf.cm": (GRAM_FORCE_N * 1e-2, 0.0, "N m"),
    # force
    "n": (1.0, 0.0, "N"), "mn": (1e-3, 0.0, "N"), "un": (1e-6, 0.0, "N"), "g": (GRAM_FORCE_N, 0.0, "N"),
    "gf": (GRAM_FORCE_N, 0.0, "N"),
    # length
    "m": (1.0, 0.0, "m"), "mm": (1e-3, 0.0, "m"), "um": (1e-6, 0.0, "m"), "cm": (1e-2, 0.0, "m"),
    # angle
    "rad": (1.0, 0.0, "rad"), "mrad": (1e-3, 0.0, "rad"), "urad": (1e-6, 0.0, "rad"),
    "deg": (np.pi / 180.0, 0.0, "rad"),
    # temperature (canonical: degree Celsius)
    "degc": (1.0, 0.0, "degC"), "c": (1.0, 0.0, "degC"), "k": (1.0, -273.15, "degC"),
    # energy density / misc (stiffness, strain constant and 1/temperature appear in TA LIMS exports)
    "j/m3": (1.0, 0.0, "J/m3"), "n.m/rad": (1.0, 0.0, "N m/rad"), "1/rad": (1.0, 0.0, "1/rad"),
    "1/k": (1.0, 0.0, "1/K"),
}

#: normalised unit string -> (factor, offset) to the canonical SI unit
UNITS: dict[str, tuple[float, float]] = {k: (f, o) for k, (f, o, _) in _TABLE.items()}
#: normalised unit string -> the canonical SI unit it converts to
SI_UNIT: dict[str, str] = {k: si for k, (_, _, si) in _TABLE.items()}
#: canonical units that measure the same quantity (a frequency may be written 1/s; rad/s is NOT Hz)
_SAME = {"Hz": {"Hz", "1/s"}, "1/s": {"1/s", "Hz"}}


class UnknownUnitError(ValueError):
    """A unit string that has no known conversion to SI (or to the SI unit a column needs)."""


def normalise_unit(unit: str) -> str:
    """Canonical spelling of a unit string: ``[mN·m]`` -> ``mn.m``, ``s-¹`` -> ``s-1``, ``°C`` -> ``degc``."""
    u = str(unit).strip()
    if u.startswith("[") and u.endswith("]"):
        u = u[1:-1].strip()
    u = (u.replace("µ", "u").replace("μ", "u").replace("·", ".").replace("⋅", ".").replace("*", ".")
         .replace("¹", "1").replace("⁻", "-").replace("°c", "degc").replace("°C", "degc").replace("°", "deg"))
    u = re.sub(r"\s+", ".", u.strip()).lower()
    if u in ("mpa.s", "mpas"):
        return "mpa.s"
    if u in ("1/mpa", "mpa^-1", "mpa-1"):
        return "1/mpa"
    return u


def unit_factor(unit: str, expected: str | None = None) -> tuple[float, float]:
    """``(factor, offset)`` of a unit string; raises :class:`UnknownUnitError`.

    ``expected``: the canonical unit the column must convert to (``"Pa"``, ``"s"`` ...), when known.
    """
    key = normalise_unit(unit)
    if key not in UNITS:
        raise UnknownUnitError(f"unknown unit {unit!r}")
    if expected is not None and SI_UNIT[key] not in _SAME.get(expected, {expected}):
        if key == "":
            raise UnknownUnitError(f"no unit given where {expected} is expected (never assumed)")
        raise UnknownUnitError(f"unit {unit!r} (a {SI_UNIT[key]} quantity) cannot be converted to {expected}")
    return UNITS[key]


def to_si(values, unit: str, expected: str | None = None) -> np.ndarray:
    """Values in ``unit`` converted to the canonical SI unit (checked against ``expected`` when given)."""
    factor, offset = unit_factor(unit, expected)
    return np.asarray(values, dtype=float) * factor + offset
