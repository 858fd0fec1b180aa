"""Unit strings as rheometers write them -> SI (factor and offset), per column, through pint.

``to_si(values, unit, expected)`` returns ``values * factor + offset`` in the canonical unit of
:data:`tissuemech.canonical.CANONICAL_VARIABLES` (temperature stays in degree Celsius). Parsing and the
conversion factors are pint's (a case-sensitive registry): SI prefixes are case-sensitive, so ``mPa`` is
1e-3 Pa and ``MPa`` 1e6 Pa, ``mN·m`` is 1e-3 N m and ``MN·m`` 1e6 N m, ``1/mPa`` is 1e3 1/Pa. Unknown units
raise :class:`UnknownUnitError`: a column is never assumed to be in seconds or pascal.

With ``expected`` (the canonical unit of the column, e.g. ``"Pa"``, ``"m"``) the unit's dimension is checked
against it: a unit of another quantity (``s`` for a stress or a gap, ``Hz`` for an angular frequency, no
unit at all for a modulus) is refused. Angles are dimensionless in pint, so the check also requires an angle
unit on both sides or on neither: ``rad/s`` and ``Hz`` are never interchangeable; ``Hz`` and ``1/s`` are.

Spellings understood (after :func:`normalise_unit`, which keeps the case): brackets ``[mN·m]``, middle dots,
``*`` and spaces as products (``N m``, ``Pa·s``), micro as ``µ``/``μ``/``u``, superscripts and exponents
(``s-¹``, ``s^-1``, ``m3``), ``°C``/``degC``/``C`` (Celsius), ``K`` (kelvin, offset to degC), ``°``/``deg``,
``%``, ``min``/``h``, ``1/MPa`` (compliance), ``Nm``/``mNm``/``µNm`` (newton-metre). Explicit mappings where
pint would read a rheometer unit otherwise:

* ``g`` is gram-*force* (TA torque ``g·cm``, force ``g``): no rheometer column is a mass;
* ``nm`` is nanometre for a length and newton-metre for a torque: it is resolved by the expected unit and
  refused as ambiguous without one;
* ``C`` is degree Celsius, not coulomb; ``Pa·s^n`` (power-law consistency) is read literally.
"""
from __future__ import annotations

import functools
import re
import tokenize

import numpy as np
import pint
import pint.util

GRAM_FORCE_N = 9.80665e-3

#: canonical unit (as in CANONICAL_VARIABLES) -> pint expression
_CANONICAL_PINT: dict[str, str] = {
    "1": "dimensionless", "s": "s", "Pa": "Pa", "1/s": "1/s", "Hz": "Hz", "rad/s": "rad/s", "Pa s": "Pa*s",
    "N m": "N*m", "rad": "rad", "N": "N", "m": "m", "degC": "degC", "1/Pa": "1/Pa", "J/m3": "J/m**3",
    "N m/rad": "N*m/rad", "1/rad": "1/rad", "1/K": "1/K",
}
#: canonical units a column without ``expected`` is converted to, first dimension match wins
_DEFAULT_TARGETS = ("1", "s", "Pa", "1/s", "rad/s", "Pa s", "N m", "rad", "N", "m", "degC", "1/Pa", "J/m3",
                    "N m/rad", "1/rad", "1/K")
#: canonical units that measure the same quantity (a frequency may be written 1/s; rad/s is NOT Hz)
_SAME = {"Hz": {"Hz", "1/s"}, "1/s": {"1/s", "Hz"}}
_ANGLE_UNITS = ("degree", "turn", "revolution", "arcminute", "arcsecond", "gradian")
_TORQUE_CONCAT = {"Nm": "N*m", "mNm": "mN*m", "uNm": "uN*m", "nNm": "nN*m", "kNm": "kN*m"}


class UnknownUnitError(ValueError):
    """A unit string that has no known conversion to SI (or to the SI unit a column needs)."""


@functools.cache
def registry() -> pint.UnitRegistry:
    """The case-sensitive pint registry used for every conversion (created once)."""
    return pint.UnitRegistry(case_sensitive=True, autoconvert_offset_to_baseunit=False)


def normalise_unit(unit: str) -> str:
    """Canonical spelling of a unit string, case kept: ``[mN·m]`` -> ``mN.m``, ``s-¹`` -> ``s-1``,
    ``°C`` -> ``degC``, ``µ``/``μ`` -> ``u``."""
    u = str(unit).strip()
    if u.startswith("[") and u.endswith("]"):
        u = u[1:-1].strip()
    u = (u.replace("µ", "u").replace("μ", "u").replace("·", ".").replace("⋅", ".").replace("*", ".")
         .replace("¹", "1").replace("²", "2").replace("³", "3").replace("⁻", "-")
         .replace("°C", "degC").replace("°F", "degF").replace("°", "deg"))
    u = re.sub(r"\s*([./])\s*", r"\1", u.strip())
    return re.sub(r"\s+", ".", u)


def _pint_expression(key: str, expected: str | None) -> str:
    """pint expression of a normalised unit string (see the module docstring for the explicit mappings)."""
    if key in ("", "1", "-"):
        return "dimensionless"
    if key == "%":
        return "0.01"
    if key in ("C", "degC"):
        return "degC"
    if key == "nm":
        if expected is None:
            raise UnknownUnitError("ambiguous unit 'nm' (nanometre or newton-metre) without an expected quantity")
        return "N*m" if expected in ("N m", "N m/rad") else "nm"
    factors = []
    for term in re.split(r"(/)", key):
        if term == "/":
            factors.append("/")
            continue
        parts = []
        for tok in term.split("."):
            m = re.fullmatch(r"([A-Za-z_]+)(?:\^?(-?\d+)|-(\d+))?", tok)
            if tok in ("1",):
                parts.append("1")
                continue
            if not m:
                raise UnknownUnitError(f"unknown unit {key!r}")
            name, exp = m.group(1), m.group(2) or (f"-{m.group(3)}" if m.group(3) else None)
            name = _TORQUE_CONCAT.get(name, name)
            if name in ("g", "gf"):
                name = "gram_force"
            elif name == "sec":
                name = "s"
            elif name == "deg":
                name = "degree"
            elif name in ("degC", "C"):  # inside a compound (1/°C): a temperature difference
                name = "kelvin"
            parts.append(f"({name})**{exp}" if exp else f"({name})")
        factors.append("*".join(parts))
    return "".join(factors)


def _angle_exponent(quantity) -> int:
    """Power of angle units in a pint quantity (angles are dimensionless in pint: ``rad/s`` vs ``Hz``)."""
    return int(sum(exp for name, exp in pint.util.to_units_container(quantity.units).items()
                   if name.endswith("radian") or name in _ANGLE_UNITS))


@functools.cache
def _conversion(unit: str, expected: str | None) -> tuple[float, float, str]:
    key = normalise_unit(unit)
    if expected is not None and expected not in _CANONICAL_PINT and expected != "Pa s^n":
        raise UnknownUnitError(f"no canonical unit {expected!r}")
    if key in ("Pa.s^n", "Pa.sn"):
        canonical = "Pa s^n"
        if expected not in (None, canonical):
            raise UnknownUnitError(f"unit {unit!r} (a {canonical} quantity) cannot be converted to {expected}")
        return 1.0, 0.0, canonical
    ureg = registry()
    expr = _pint_expression(key, expected)
    try:
        q_unit = ureg.parse_expression(expr) if expr not in ("dimensionless", "0.01") else None
    except (pint.errors.PintError, AttributeError, SyntaxError, TypeError, ValueError, tokenize.TokenError) as exc:
        raise UnknownUnitError(f"unknown unit {unit!r}") from exc
    if q_unit is None:
        dims, angle = ureg.dimensionless.dimensionality, 0
        factor = 0.01 if expr == "0.01" else 1.0
    else:
        if not isinstance(q_unit, ureg.Quantity):  # a bare number is not a unit
            raise UnknownUnitError(f"unknown unit {unit!r}")
        dims, angle = q_unit.dimensionality, _angle_exponent(q_unit)
    targets = [expected] if expected is not None else list(_DEFAULT_TARGETS)
    for target in targets:
        for same in sorted(_SAME.get(target, {target})):
            t = ureg.parse_expression(_CANONICAL_PINT[same]) if same != "1" else None
            t_dims = ureg.dimensionless.dimensionality if t is None else t.dimensionality
            t_angle = 0 if t is None else _angle_exponent(t)
            if t_dims != dims or t_angle != angle:
                continue
            if q_unit is None:
                return factor, 0.0, target
            scale = float(q_unit.magnitude)
            zero = float(ureg.Quantity(0.0, q_unit.units).to(_CANONICAL_PINT[same]).magnitude)
            one = float(ureg.Quantity(1.0, q_unit.units).to(_CANONICAL_PINT[same]).magnitude)
            return scale * (one - zero), zero, target
    if expected is None:
        raise UnknownUnitError(f"unit {unit!r} has no canonical SI unit (dimension {dims})")
    if key in ("", "1", "-"):
        raise UnknownUnitError(f"no unit given where {expected} is expected (never assumed)")
    try:
        quantity = _conversion(unit, None)[2]
    except UnknownUnitError:
        quantity = str(dims)
    raise UnknownUnitError(f"unit {unit!r} (a {quantity} quantity) cannot be "
                           f"converted to {expected}")



def canonical_unit(unit: str, expected: str | None = None) -> str:
    """The canonical unit (a key of the ``CANONICAL_VARIABLES`` units) a unit string converts to."""
    return _conversion(str(unit), expected)[2]


def unit_factor(unit: str, expected: str | None = None) -> tuple[float, float]:
    """``(factor, offset)`` of a unit string to its canonical SI unit; raises :class:`UnknownUnitError`.

    Parameters
    ----------
    unit : the unit as the export writes it (case-sensitive prefixes)
    expected : the canonical unit the column must convert to (``"Pa"``, ``"s"``, ``"m"`` ...), when known;
        a unit of another dimension is refused.
    """
    factor, offset, _ = _conversion(str(unit), expected)
    return factor, offset


def to_si(values, unit: str, expected: str | None = None) -> np.ndarray:
    """Values in ``unit`` converted to the canonical SI unit (checked against ``expected`` when given)."""
    factor, offset = unit_factor(unit, expected)
    return np.asarray(values, dtype=float) * factor + offset
