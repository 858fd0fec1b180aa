"""Measuring geometry as the files state it, and its precedence: ``samples.csv`` > ``dataset.yaml`` > export.

Nothing here defaults a plate radius or gap: a value is taken from a source that states it, or it is absent.

* :func:`measuring_system` reads a measuring-system name: Anton Paar ``PP25`` (parallel plate, 25 mm
  diameter -> 12.5 mm radius), ``PP08``, ``PP50``, ``CP50-1`` (cone-plate, 50 mm diameter, 1 degree cone; the
  cone truncation gap is not in the name), ``CC27`` (concentric cylinders: no plate radius), with suffixes
  (``PP25/S``, ``PP25-SN12345``) ignored; and TA geometry names that start with the plate diameter and say
  ``parallel plate`` (``8.0mm parallel plate, Peltier plate Sandblasted``, ``40.0mm CrossHatched Parallel
  Plates``). Names that state no plate diameter (``DIN concentric cylinders``) give no radius.
* :func:`value_with_unit` reads a geometry cell with value and unit (``40.0 mm``, ``1000 µm``) and checks
  the unit is a length (a gap in ``s`` is refused; ``nm`` is nanometre here).
* :func:`dataset_geometry` reads ``dataset.yaml``'s ``geometry``: a mapping (``radius_mm``, ``diameter_mm``,
  ``gap_mm``, ``measuring_system``, ``type``) or a string (``parallel plate, 25 mm`` is a *diameter*;
  ``PP25``). A list of gaps (a range) is not one gap and gives none.
* :func:`resolve_geometry` applies the precedence and names conflicts (> 1 % apart).
* :func:`axial_step_gap` reads the gap of a TA ``Axial`` pre-step that ends right before a step that logs no
  gap (the TRIOS exports of ``instrument_formats.md`` 2.3): the last recorded gap, with a note saying whether it
  was still changing when the step ended.
"""
from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence

import numpy as np

from ..canonical import GEOMETRY_SOURCES
from ..units import to_si

#: relative difference above which two sources of the same geometry value conflict
CONFLICT_REL = 0.01
SOURCES = GEOMETRY_SOURCES

_ANTON_PAAR = re.compile(r"^\s*(PP|CP|CC|PPR|CPR)\s*0*(\d+(?:[.,]\d+)?)(?:\s*-\s*(\d+(?:[.,]\d+)?))?", re.IGNORECASE)
_TA_PLATE = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*mm\b.*\bparallel\s+plates?\b", re.IGNORECASE)
_VALUE_UNIT = re.compile(r"^\s*([-+]?(?:\d+(?:[.,]\d*)?|[.,]\d+)(?:[eE][-+]?\d+)?)\s*(\S.*?)\s*$")
_STRING_DIAMETER = re.compile(r"(\d+(?:[.,]\d+)?)\s*mm\b", re.IGNORECASE)
#: a TA step name: the step and its 1-based position in the procedure ("Axial - 1", "Frequency sweep - 2")
_TA_STEP = re.compile(r"^(?P<step>.+?) - (?P<number>\d{1,6})$")
#: the source label of a gap read from a preceding axial step
AXIAL_STEP_SOURCE = "export (axial step)"
#: the gap moved by more than this fraction over the last tenth of the axial step: "still changing"
SETTLED_REL = 1e-3


def measuring_system(name: str) -> dict:
    """Geometry stated by a measuring-system name (see module docstring).

    Returns
    -------
    dict with ``measuring_system`` (the name as written), ``geometry_type`` (``parallel plate``,
    ``cone-plate``, ``concentric cylinders``) when recognised, ``radius_m`` (plate or cone radius, m) when
    the name states a diameter, ``cone_angle_rad`` for a cone. Empty for an empty name.
    """
    text = str(name or "").strip()
    if not text:
        return {}
    out: dict = {"measuring_system": text}
    m = _ANTON_PAAR.match(text)
    if m:
        kind = m.group(1).upper()
        diameter_mm = float(m.group(2).replace(",", "."))
        if kind.startswith("PP"):
            out.update(geometry_type="parallel plate", radius_m=diameter_mm / 2 * 1e-3)
        elif kind.startswith("CP"):
            out.update(geometry_type="cone-plate", radius_m=diameter_mm / 2 * 1e-3)
            if m.group(3):
                out["cone_angle_rad"] = math.radians(float(m.group(3).replace(",", ".")))
        else:
            out["geometry_type"] = "concentric cylinders"
        return out
    m = _TA_PLATE.match(text)
    if m:
        out.update(geometry_type="parallel plate", radius_m=float(m.group(1)) / 2 * 1e-3)
    elif "concentric cylinder" in text.lower():
        out["geometry_type"] = "concentric cylinders"
    return out


def value_with_unit(cell: str) -> float:
    """A length written with its unit in one cell (``40.0 mm``, ``1000 µm``) in metres.

    Raises
    ------
    ValueError : no number and unit in the cell
    UnknownUnitError : the unit is unknown or not a length (e.g. a gap in ``s``)
    """
    m = _VALUE_UNIT.match(str(cell))
    if not m:
        raise ValueError(f"not a value with a unit: {cell!r}")
    return float(to_si(float(m.group(1).replace(",", ".")), m.group(2), expected="m"))


def dataset_geometry(geometry) -> dict:
    """``radius_m``/``gap_m``/``measuring_system`` stated by ``dataset.yaml``'s ``geometry`` entry.

    Parameters
    ----------
    geometry : mapping (``radius_mm``, ``diameter_mm``, ``gap_mm``, ``measuring_system``, ``type``) or a
        string (``"parallel plate, 25 mm"``: 25 mm is the plate *diameter*; ``"PP25"``); None when absent.

    Raises
    ------
    ValueError : a value that is not a positive number
    """
    if geometry is None:
        return {}
    if isinstance(geometry, str):
        out = measuring_system(geometry)
        if "radius_m" not in out and "parallel plate" in geometry.lower():
            m = _STRING_DIAMETER.search(geometry)
            if m:
                out.update(geometry_type="parallel plate", radius_m=float(m.group(1).replace(",", ".")) / 2 * 1e-3)
        return out
    if not isinstance(geometry, Mapping):
        raise ValueError(f"geometry must be a mapping or a string, not {type(geometry).__name__}")
    out = measuring_system(geometry["measuring_system"]) if geometry.get("measuring_system") else {}
    for key, scale in (("radius_mm", 1e-3), ("diameter_mm", 0.5e-3), ("gap_mm", 1e-3)):
        value = geometry.get(key)
        if value is None or isinstance(value, (list, tuple)):  # a list of gaps is a range, not one gap
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise ValueError(f"geometry/{key}: {value!r} is not a positive number")
        out["gap_m" if key == "gap_mm" else "radius_m"] = float(value) * scale
    if geometry.get("type"):
        out["geometry_type"] = str(geometry["type"])
    return out


def resolve_geometry(sheet: Mapping, dataset: Mapping, export: Mapping) -> tuple[dict, list[str]]:
    """Plate radius and gap of a run by precedence ``samples.csv`` > ``dataset.yaml`` > export.

    Parameters
    ----------
    sheet, dataset, export : ``radius_m``/``gap_m`` (m) each source states (absent keys: not stated)

    Returns
    -------
    attrs : ``radius_m``, ``radius_source``, ``gap_m``, ``gap_source`` for the values some source states
        (absent otherwise, never NaN or a default)
    notes : ``no plate radius`` / ``no gap`` when no source states it, and one line per conflict
        (sources more than :data:`CONFLICT_REL` apart), e.g.
        ``radius conflict: samples.csv 12.5 mm vs export 4 mm (samples.csv used)``
    """
    attrs, notes = {}, []
    stated = dict(zip(SOURCES, (sheet, dataset, export)))
    for key, word, missing in (("radius_m", "radius", "no plate radius"), ("gap_m", "gap", "no gap")):
        values = [(src, float(m[key])) for src, m in stated.items()
                  if m.get(key) is not None and math.isfinite(float(m[key])) and float(m[key]) > 0]
        if not values:
            notes.append(missing)
            continue
        src, value = values[0]
        attrs[key], attrs[f"{word}_source"] = value, src
        for other, v in values[1:]:
            if abs(v - value) > CONFLICT_REL * abs(value):
                notes.append(f"{word} conflict: {src} {value * 1e3:g} mm vs {other} {v * 1e3:g} mm ({src} used)")
    return attrs, notes


def axial_step_gap(blocks: Sequence, block) -> tuple[float, str] | None:
    """The gap [m] an ``Axial`` pre-step leaves for the step that follows it, and the report note saying so.

    Used only when ``block`` is a TA step (``<step> - <k>``) directly preceded in the export by ``Axial - <k-1>``
    (the procedure goes on to ``block`` right after the axial step ends, with nothing in between) and that step
    logs a ``gap`` channel: the rheometer holds the gap where the axial step left it, so the last recorded gap is
    the gap of ``block``. When the gap moved by more than :data:`SETTLED_REL` of its value over the last tenth of
    the axial step's records (at least 3), the note says it was still closing or opening at the end, at what
    rate, and how much one more record interval of that motion would change it (the step may end up to one
    interval after its last record): the value is then the last one recorded, not a settled one.

    Parameters
    ----------
    blocks : every block of the export (``name``, ``index``, ``data`` with ``gap`` [m] and ``time`` [s])
    block : the block that needs a gap

    Returns
    -------
    ``(gap_m, note)``, or None when no such axial step precedes ``block``.
    """
    this = _TA_STEP.match(str(block.name).strip())
    previous = [b for b in blocks if b.index == block.index - 1]
    if not this or not previous:
        return None
    axial = previous[0]
    step = _TA_STEP.match(str(axial.name).strip())
    if (not step or not step["step"].strip().lower().startswith("axial")
            or int(step["number"]) != int(this["number"]) - 1 or "gap" not in axial.data):
        return None
    gap = axial.data["gap"].to_numpy(float)
    keep = np.isfinite(gap) & (gap > 0)
    if not keep.any():
        return None
    gap = gap[keep]
    time = axial.data["time"].to_numpy(float)[keep] if "time" in axial.data else None
    last = float(gap[-1])
    where = f"at {time[-1]:.4g} s" if time is not None else f"record {gap.size}"
    note = (f"gap {last * 1e3:.5g} mm: the last record ({where}) of the preceding step {axial.name!r} "
            f"(source: {AXIAL_STEP_SOURCE})")
    n = max(3, int(np.ceil(0.1 * gap.size)))
    if gap.size >= n:
        change = float(gap[-1] - gap[-n])
        if abs(change) > SETTLED_REL * last:
            note += (f"; the gap was still {'closing' if change < 0 else 'opening'} when that step ended "
                     f"({change * 1e6:+.3g} µm over its last {n} records")
            if time is not None and time[-1] > time[-n]:
                rate = abs(change) / (time[-1] - time[-n])
                interval = float(np.median(np.diff(time)))
                note += (f", {rate * 1e6:.3g} µm/s; one record interval, {interval:.3g} s, more of it would be "
                         f"{rate * interval * 1e6:.3g} µm, {rate * interval / last:.2%}")
            note += "): the value is the last one recorded, not a settled one"
    return last, note


__all__ = ["AXIAL_STEP_SOURCE", "CONFLICT_REL", "SOURCES", "axial_step_gap", "dataset_geometry",
           "measuring_system", "resolve_geometry", "value_with_unit"]
