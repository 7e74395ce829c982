"""Physical quantities in configs: ``"1.0 s"``, ``"12 frames"``, ``"6 Hz"``, ``"20 mm"``.

Cleaner parameters are physical (mm, Hz, s) so that one config means the same thing for a
file in metres and a file in millimetres, at 50 Hz or at 200 Hz. A bare number takes the
parameter's default unit. Values are stored in SI (m, s, Hz) or as frames and converted to
the motion's units and frame rate when a cleaner runs.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from mocapfix.core.errors import ConfigError

_UNIT_KINDS = {
    # length → metres
    "m": ("length", 1.0), "cm": ("length", 0.01), "mm": ("length", 0.001),
    "in": ("length", 0.0254),
    # time → seconds, or frames
    "s": ("time", 1.0), "ms": ("time", 0.001), "frames": ("time", None), "frame": ("time", None),
    # frequency → Hz
    "hz": ("frequency", 1.0),
}
#: fastest frame rate a file may declare (optical systems reach ~10 kHz at reduced
#: resolution); a faster one is a corrupt field, and would turn every time into billions
#: of frames
MAX_FRAME_RATE_HZ = 100_000.0
#: slowest: one frame in 1,000 s (a corrupt rate field, or a Frame Time of 1e308 s)
MIN_FRAME_RATE_HZ = 0.001


def frame_rate(value) -> float:
    """``value`` as a frame rate in Hz (a number, or text of one), finite and from
    :data:`MIN_FRAME_RATE_HZ` to :data:`MAX_FRAME_RATE_HZ`; a ValueError saying why not
    (``--fps`` and the Python API's ``fps=``)."""
    try:
        rate = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{value!r} is not a number of frames per second") from None
    if not (math.isfinite(rate) and MIN_FRAME_RATE_HZ <= rate <= MAX_FRAME_RATE_HZ):
        raise ValueError(f"{value!r} is not a frame rate (a number of Hz from "
                         f"{MIN_FRAME_RATE_HZ:g} to {MAX_FRAME_RATE_HZ:g})")
    return rate

_PATTERN = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z]*)\s*$")


@dataclass(frozen=True)
class Quantity:
    """A value with a kind: ``si`` holds metres/seconds/Hz, or ``frames`` for a frame count."""

    kind: str
    si: float | None = None
    frames: float | None = None
    text: str = ""

    def in_frames(self, fps: float) -> float:
        if self.kind != "time":
            raise TypeError("only times convert to frames")
        return self.frames if self.frames is not None else self.si * fps

    def in_units(self, metres_per_unit: float) -> float:
        """A length in the motion's length unit."""
        if self.kind != "length":
            raise TypeError("only lengths convert to file units")
        return self.si / metres_per_unit

    def __str__(self):
        return self.text


def parse_quantity(value, kind: str, default_unit: str, where: str) -> Quantity:
    """Parse ``value`` (number or "number unit") as a quantity of ``kind``.

    ``where`` names the step and parameter for error messages.
    """
    if isinstance(value, bool):
        raise ConfigError(f"{where}: expected a {kind} like '{default_unit_example(kind, default_unit)}', got {value!r}")
    if isinstance(value, (int, float)):
        number, unit = float(value), default_unit
    elif isinstance(value, str):
        m = _PATTERN.match(value)
        if not m:
            raise ConfigError(f"{where}: cannot read {value!r} as a {kind} "
                              f"(e.g. '{default_unit_example(kind, default_unit)}')")
        number, unit = float(m.group(1)), (m.group(2) or default_unit)
    else:
        raise ConfigError(f"{where}: expected a {kind}, got {type(value).__name__} {value!r}")
    if not math.isfinite(number):
        raise ConfigError(f"{where}: {value!r} is not a finite number")
    key = unit.lower()
    if key not in _UNIT_KINDS or _UNIT_KINDS[key][0] != kind:
        allowed = sorted(u for u, (k, _) in _UNIT_KINDS.items() if k == kind and u != "frame")
        raise ConfigError(f"{where}: unit {unit!r} is not a {kind} unit (use one of {', '.join(allowed)})")
    factor = _UNIT_KINDS[key][1]
    text = f"{number:g} {unit}"
    if factor is None:
        return Quantity(kind, frames=number, text=text)
    return Quantity(kind, si=number * factor, text=text)


def default_unit_example(kind: str, unit: str) -> str:
    return {"length": f"20 {unit}", "time": f"0.5 {unit}", "frequency": f"6 {unit}"}.get(kind, unit)


