"""Length units: names and their size in metres.

Physical parameters of cleaners are given in mm / Hz / s and converted to the unit
of the motion with :func:`to_file_units`.
"""
from __future__ import annotations

from mocapfix.core.errors import MocapfixError

METRES_PER_UNIT = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "in": 0.0254,
    "ft": 0.3048,
}

#: CMU ASF files declare ``length 0.45``: one file unit is 1/0.45 inch.
def asf_length_unit(length_scale: float) -> float:
    """Metres per ASF length unit for an ASF ``:units length`` value (inches / scale)."""
    return 0.0254 / length_scale


def normalise_unit_name(name: str) -> str | None:
    """Map spellings found in files ("MM", "millimeters", "m ") to a key of METRES_PER_UNIT."""
    key = name.strip().lower().rstrip("s").replace("metre", "meter")
    aliases = {
        "mm": "mm", "millimeter": "mm", "cm": "cm", "centimeter": "cm",
        "m": "m", "meter": "m", "in": "in", "inch": "in", "inche": "in",
        "ft": "ft", "foot": "ft", "feet": "ft",
    }
    return aliases.get(key)


def metres_per(unit: str) -> float:
    try:
        return METRES_PER_UNIT[unit]
    except KeyError:
        raise MocapfixError(f"unknown length unit {unit!r}") from None
