"""Template variables derived from the knobs, one function per template (geometry, masses, sensor
scale, the values that follow the chosen sizes). Everything else is text in ``templates/``."""

from __future__ import annotations

import math


def num(v: float) -> str:
    """A float as TOML/XML text: short, exact enough (6 significant digits), never an integer token."""
    v = float(v)
    if abs(v) < 1e-12:
        return "0.0"
    s = f"{v:.6g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")
    return s if any(c in s for c in ".en") else s + ".0"


def vec(vs) -> str:
    return "[" + ", ".join(num(v) for v in vs) + "]"


def _area(d: float) -> float:
    return math.pi * d * d / 4.0


def _shared(k: dict) -> dict:
    supply = k["supply_pressure"]
    return {
        "supply_pressure": num(supply),
        "relief_pressure": num(round(1.1 * supply, -4)),
        "rated_flow": num(k["rated_flow"]),
        "amp_gain": "0.08", "amp_max": "0.8", "spool_hz": "15.0", "spool_gain": "1.25",
        "hose_length": "1.5", "hose_id": "8.0e-3",
        "load_kg": num(k["load_kg"]),
    }


def cylinder(k: dict) -> dict:
    if k["orientation"] == "vertical" and not k.get("_incline_given"):
        a = 90.0
    elif k["orientation"] == "horizontal" and not k.get("_incline_given"):
        a = 0.0
    else:
        a = k["incline_deg"]
    rad = math.radians(a)
    axis = " ".join(num(round(x, 9)) for x in (math.cos(rad), 0.0, math.sin(rad)))
    stroke, bore, rod = k["stroke"], k["bore"], k["rod"]
    aa = _area(bore)
    words = "vertical" if a == 90.0 else "horizontal" if a == 0.0 else f"{a:g} deg inclined"
    verb = "lifting" if a > 0 else "pushing" if a == 0 else "lowering"
    return {
        **_shared(k),
        "title": f"A double-acting cylinder on a {words} slide ({stroke:g} m stroke) {verb} a {k['load_kg']:g} kg load",
        "incline_deg": f"{a:g}", "axis": axis, "base_height": "0.3",
        "stroke": num(stroke), "bore": num(bore), "rod": num(rod),
        "effort": num(round(aa * k["supply_pressure"])),
        "dead_a": num(max(1e-5, aa * 0.02)), "dead_b": num(max(1e-5, (aa - _area(rod)) * 0.02)),
        "viscous": "2000.0",
        "initial_position": num(round(0.4 * stroke, 4)),
        "sensor_A": num(stroke / 10.0), "sensor_B": "0.0",
        "carriage_kg": num(k["carriage_kg"]),
        "carriage_I": num(k["carriage_kg"] * (0.3 ** 2 + 0.15 ** 2) / 12.0),
    }


def boom(k: dict) -> dict:
    L, m = k["boom_length"], k["boom_kg"]
    bore, rod = k["bore"], k["rod"]
    aa = _area(bore)
    s = L / 2.0     # the cylinder's pins scale with the boom: rod eye at L/2, base 0.5 L below the pivot
    return {
        **_shared(k),
        "title": f"A {L:g} m boom on a pivot raised by a cylinder through its mounts, {k['load_kg']:g} kg at the tip",
        "pivot_height": num(k["pivot_height"]), "half_pivot": num(k["pivot_height"] / 2.0),
        "boom_length": num(L), "half_length": num(L / 2.0), "boom_kg": num(m),
        "boom_Iyy": num(m * L * L / 12.0), "boom_Ixx": num(m * 0.12 ** 2 / 6.0),
        "lower": "-0.2", "upper": "0.9", "initial_position": "0.2",
        "base_mount": vec((0.15 * s, 0.0, -s)),
        "rod_mount": vec((s, 0.0, 0.0)),
        "bore": num(bore), "rod": num(rod),
        "effort": num(round(aa * k["supply_pressure"] * 0.5 * s)),
        "dead_a": num(max(2e-5, aa * 0.02)), "dead_b": num(max(2e-5, (aa - _area(rod)) * 0.02)),
        "viscous": "5000.0",
        "sensor_A": "0.5236", "sensor_B": "-2.618",
    }


def rotary(k: dict) -> dict:
    L, m = k["arm_length"], k["arm_kg"]
    horizontal = k["axis"] == "horizontal"
    d = k["displacement"]
    motor = k["actuator"] == "motor"
    return {
        **_shared(k),
        "title": (f"A {'hydraulic motor' if motor else 'rotary vane actuator'} turning a {L:g} m arm about a "
                  f"{k['axis']} axis, {k['load_kg']:g} kg at its end"),
        "axis": "0 -1 0" if horizontal else "0 0 1",
        "axis_words": "a horizontal axis (y): the arm lifts against gravity for q > 0" if horizontal
                      else "a vertical axis (z): a turntable, no gravity torque",
        "shaft_height": "1.0",
        "arm_length": num(L), "half_length": num(L / 2.0), "arm_kg": num(m),
        "arm_I": num(m * L * L / 12.0), "arm_Ixx": num(m * 0.08 ** 2 / 6.0),
        "lower": "-3.1" if motor else "-1.5", "upper": "3.1" if motor else "1.5", "initial_position": "0.0",
        "rotary_type": k["actuator"], "displacement": num(d),
        "chamber_volume": num(max(1e-5, 1.5 * d)),
        "viscous": "20.0",
        "effort": num(round(d * k["supply_pressure"])),
        "sensor_A": "0.5236" if not motor else "0.6283", "sensor_B": "-2.618" if not motor else "-3.1416",
    }


DERIVE = {"cylinder": cylinder, "boom": boom, "rotary": rotary}
