"""Units of a measured column and their conversion to the dataset's SI units.

Every conversion is linear, ``si = scale * raw + offset``: named units (ms, mV, deg, mm, bar, psi,
...), ``sensor_volts`` (the joint's sensor model ``position = A * raw + B`` from the robot spec) and
``*SCALE+OFFSET`` for raw converter counts. Pressures are gauge, as in the model; an absolute
pressure log needs an offset (``*1e5-101325`` for bar absolute).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

# what a dataset column holds -> {unit: factor to SI}; the first unit is the SI one
UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3},
    "command": {"V": 1.0, "mV": 1e-3},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0},
    "position": {"m": 1.0, "mm": 1e-3},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "bar": 1e5, "MPa": 1e6, "psi": 6894.757293168361},
}
KIND_TEXT = {"time": "time", "command": "a valve command", "angle": "the angle of a revolute joint",
             "position": "the position of a prismatic joint", "pressure": "a chamber pressure"}
SENSOR_VOLTS = "sensor_volts"
_UNUM = r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"     # unsigned decimal number
_SCALE = re.compile(rf"^\*\s*([+-]?{_UNUM})\s*(?:([+-])\s*({_UNUM}))?$")


def si_unit(kind: str) -> str:
    return next(iter(UNITS[kind]))


@dataclass(frozen=True)
class Unit:
    """A column's unit as given and the linear map to SI."""

    text: str             # as written after the ':' ('bar', 'sensor_volts', '*0.01+2'), or the SI unit
    kind: str             # time | command | angle | position | pressure
    scale: float
    offset: float = 0.0
    counts: bool = False  # '*SCALE+OFFSET': raw converter counts (saturation at a converter code)
    sensor_range: tuple[float, float] | None = None  # sensor_volts: the sensor's input range (V)

    @property
    def si(self) -> str:
        return si_unit(self.kind)

    def convert(self, raw):
        return raw * self.scale + self.offset if (self.scale != 1.0 or self.offset != 0.0) else raw

    def describe(self) -> str:
        """How the column was converted, for summaries."""
        if self.text == SENSOR_VOLTS:
            return f"sensor volts: {self.scale:g} {self.si}/V * v {self.offset:+g} {self.si} (the joint's sensor model)"
        if self.counts:
            return f"counts: {self.scale:g} * raw {self.offset:+g} -> {self.si}"
        if self.text == self.si:
            return self.si
        return f"{self.text} -> {self.si} (x {self.scale:g})"


def allowed(kind: str, sensed: bool = True) -> list[str]:
    """Units a column of this kind accepts (for messages)."""
    out = list(UNITS[kind])
    if kind in ("angle", "position") and sensed:
        out.append(SENSOR_VOLTS)
    return out + ["*SCALE+OFFSET"]


def parse_unit(text: str | None, kind: str, *, column: str, sensor: dict | None = None) -> Unit:
    """``text`` (None: the SI unit) for a column of ``kind``. ``sensor``: the joint's sensor model
    (A, B, range) for ``sensor_volts``. Raises ValueError with the allowed units."""
    if text is None or not text.strip():
        return Unit(si_unit(kind), kind, 1.0)
    t = text.strip()
    m = _SCALE.match(t)
    if m:
        scale = float(m.group(1))
        offset = float(m.group(3)) * (-1.0 if m.group(2) == "-" else 1.0) if m.group(3) else 0.0
        if scale == 0.0 or not math.isfinite(scale) or not math.isfinite(offset):
            raise ValueError(f"column {column}: unit {t!r}: the scale must be a finite non-zero number")
        return Unit(t, kind, scale, offset, counts=True)
    if t.startswith("*"):
        raise ValueError(f"column {column}: unit {t!r}: expected *SCALE, *SCALE+OFFSET or *SCALE-OFFSET (numbers)")
    if t.lower() == SENSOR_VOLTS:
        if kind not in ("angle", "position"):
            raise ValueError(f"column {column}: unit sensor_volts fits a position column (q_<joint>), not "
                             f"{KIND_TEXT[kind]}; units for {column}: {', '.join(allowed(kind))}")
        if sensor is None:
            raise ValueError(f"column {column}: unit sensor_volts needs the joint's sensor model (joints.<joint>.sensor.A "
                             f"and .B in robot.toml), and this joint has none; give the position as "
                             f"{' or '.join(UNITS[kind])}, or as *SCALE+OFFSET")
        lo, hi = sensor.get("range", (None, None))
        rng = (float(lo), float(hi)) if lo is not None else None
        return Unit(SENSOR_VOLTS, kind, float(sensor["A"]), float(sensor["B"]), sensor_range=rng)
    for name, factor in UNITS[kind].items():
        if t.lower() == name.lower():
            return Unit(name, kind, factor)
    other = [k for k, u in UNITS.items() if any(t.lower() == n.lower() for n in u)]
    why = f" ({t} is a unit of {KIND_TEXT[other[0]]})" if other else ""
    raise ValueError(f"column {column}: unit {t!r} does not fit {KIND_TEXT[kind]}{why}; "
                     f"units for {column}: {', '.join(allowed(kind, sensor is not None))}")

