"""Unit strings as rheometers write them -> SI (factor and offset), per column.

``to_si(values, unit)`` returns ``values * factor + offset`` in the canonical unit of
:data:`tissuemech.canonical.CANONICAL_VARIABLES` (temperature stays in degree Celsius). Unknown units raise
:class:`UnknownUnitError`: a column is never assumed to be in seconds or pascal.
"""
from __future__ import annotations

import re

import numpy as np

GRAM_FORCE_N = 9.80665e-3

#: normalised unit string -> (factor, offset) to the canonical SI unit
UNITS: dict[str, tuple[float, float]] = {
    # dimensionless / strain
    "": (1.0, 0.0), "1": (1.0, 0.0), "-": (1.0, 0.0), "%": (0.01, 0.0),
    # time
    "s": (1.0, 0.0), "sec": (1.0, 0.0), "ms": (1e-3, 0.0), "min": (60.0, 0.0), "h": (3600.0, 0.0),
    # stress / modulus
    "pa": (1.0, 0.0), "kpa": (1e3, 0.0), "mpa": (1e6, 0.0), "gpa": (1e9, 0.0), "hpa": (100.0, 0.0),
    "mpa_milli": (1e-3, 0.0),
    # compliance
    "1/pa": (1.0, 0.0), "1/kpa": (1e-3, 0.0), "1/mpa": (1e-6, 0.0), "pa^-1": (1.0, 0.0),
    # rates and frequencies
    "1/s": (1.0, 0.0), "s^-1": (1.0, 0.0), "s-1": (1.0, 0.0), "1/min": (1 / 60.0, 0.0), "hz": (1.0, 0.0),
    "rad/s": (1.0, 0.0), "1/sec": (1.0, 0.0),
    # viscosity
    "pa.s": (1.0, 0.0), "pas": (1.0, 0.0), "mpa.s": (1e-3, 0.0), "pa.s^n": (1.0, 0.0),
    # torque
    "n.m": (1.0, 0.0), "nm": (1.0, 0.0), "mn.m": (1e-3, 0.0), "un.m": (1e-6, 0.0), "nn.m": (1e-9, 0.0),
    "g.cm": (GRAM_FORCE_N * 1e-2, 0.0), "gf.cm": (GRAM_FORCE_N * 1e-2, 0.0),
    # force
    "n": (1.0, 0.0), "mn": (1e-3, 0.0), "un": (1e-6, 0.0), "g": (GRAM_FORCE_N, 0.0), "gf": (GRAM_FORCE_N, 0.0),
    # length
    "m": (1.0, 0.0), "mm": (1e-3, 0.0), "um": (1e-6, 0.0), "cm": (1e-2, 0.0),
    # angle
    "rad": (1.0, 0.0), "mrad": (1e-3, 0.0), "urad": (1e-6, 0.0), "deg": (np.pi / 180.0, 0.0),
    # temperature (canonical: degree Celsius)
    "degc": (1.0, 0.0), "c": (1.0, 0.0), "k": (1.0, -273.15),
    # energy density / misc
    "j/m3": (1.0, 0.0),
}


class UnknownUnitError(ValueError):
    """A unit string that has no known conversion to SI."""


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


def unit_factor(unit: str) -> tuple[float, float]:
    """``(factor, offset)`` of a unit string; raises :class:`UnknownUnitError`."""
    key = normalise_unit(unit)
    if key not in UNITS:
        raise UnknownUnitError(f"unknown unit {unit!r}")
    return UNITS[key]


def to_si(values, unit: str) -> np.ndarray:
    """Values in ``unit`` converted to the canonical SI unit."""
    factor, offset = unit_factor(unit)
    return np.asarray(values, dtype=float) * factor + offset
