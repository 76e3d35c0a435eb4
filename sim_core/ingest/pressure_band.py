"""Whether a chamber pressure column is in the unit it is read in: the band a hydraulic circuit allows.

A chamber's pressure lies between the oil's cavitation pressure and the relief valve's setting (a
rod-side chamber under an overrunning load goes above the relief by its area ratio; ``RELIEF_FACTOR``
leaves room for that), and a chamber the valve connects to the supply reaches a good share of it. A
log in bar read as Pa holds 70 "Pa" on a 140 bar circuit, one in Pa read as bar 1e11 Pa: the
calibration then fits supply and loads to pressures no pump makes. The named units of pressure lie
7-100 times apart, so a column outside the band, or never above ``SMALL_SHARE`` of the supply where
another unit would fit it, is in another unit, and the units under which it lies inside the band and
reaches ``REACH_SHARE`` of the supply are the ones to read it in.
"""

from __future__ import annotations

import numpy as np

from .units import UNITS, Unit, parse_unit

RELIEF_FACTOR = 3.0      # above this many times the relief setting no chamber of the circuit goes
CAVITATION_MARGIN = 1e5  # Pa below the cavitation pressure: a transducer's offset, not the oil
OUTSIDE_SHARE = 0.5      # of the samples outside the band from which the column is in another unit
SMALL_SHARE = 0.01       # of the supply pressure a column must exceed somewhere to be read as given
REACH_SHARE = 0.1        # of the supply pressure a suggested reading must reach
INSIDE_SHARE = 0.99      # of the samples a suggested reading must put inside the band


def band(spec) -> tuple[float, float]:
    """The gauge pressures (Pa) a chamber of ``spec``'s circuit can hold."""
    relief = max(float(spec.get("supply.relief_pressure")), float(spec.get("supply.pressure")))
    return float(spec.get("fluid.cavitation_pressure")) - CAVITATION_MARGIN, RELIEF_FACTOR * relief


def implausible(p, spec, fits: list[str]) -> str | None:
    """Why the pressures ``p`` (Pa) cannot be a chamber's of ``spec``'s circuit, else None. ``fits``: the
    units under which the column would fit (:func:`alternatives`); a column only small is flagged only
    with one (a chamber that stays at tank, or a transducer left unconnected, is not a unit's doing)."""
    p = np.asarray(p, float)
    p = p[np.isfinite(p)]
    if not p.size:
        return None
    lo, hi = band(spec)
    supply = float(spec.get("supply.pressure"))
    outside = float(np.mean((p < lo) | (p > hi)))
    if outside > OUTSIDE_SHARE:
        return (f"{100 * outside:.3g} % of the samples lie outside [{lo:.4g}, {hi:.4g}] Pa (from the oil's cavitation "
                f"to {RELIEF_FACTOR:g} x the relief setting)")
    top = float(np.max(np.abs(p)))
    if top < SMALL_SHARE * supply and fits:
        return f"the largest is {top:.4g} Pa, {100 * top / supply:.2g} % of the supply pressure {supply:.4g} Pa"
    return None


def plausible_readings(raw, readings: dict[str, Unit], spec) -> list[str]:
    """Of ``readings`` (a unit's text -> its Unit), those under which ``raw`` lies inside the band on
    INSIDE_SHARE of the samples and reaches REACH_SHARE of the supply pressure."""
    raw = np.asarray(raw, float)
    raw = raw[np.isfinite(raw)]
    lo, hi = band(spec)
    supply = float(spec.get("supply.pressure"))
    out = []
    for text, unit in readings.items():
        p = unit.convert(raw)
        if p.size and np.mean((p >= lo) & (p <= hi)) >= INSIDE_SHARE and np.max(np.abs(p)) >= REACH_SHARE * supply:
            out.append(text)
    return out


def alternatives(raw, spec, used: str) -> list[str]:
    """The named units other than ``used`` under which a column's ``raw`` values fit the circuit."""
    return plausible_readings(raw, {n: parse_unit(n, "pressure", column="p") for n in UNITS["pressure"] if n != used},
                              spec)


def hint(fits: list[str], column: str, source) -> str:
    """The readings ``fits`` (:func:`alternatives`) as options."""
    return "; read as " + " or ".join(f"{n} (`--column {column}={source}:{n}`)" for n in fits) + " it fits" if fits else ""


def causes(found: dict[str, tuple[str, np.ndarray]], spec) -> list[str]:
    """What to check, one sentence per group of pressure columns that no chamber of ``spec``'s circuit
    holds and that the same units would fit (``found``: column -> (why, :func:`implausible`; its values
    in Pa))."""
    readings = {n: parse_unit(n, "pressure", column="p") for n in UNITS["pressure"] if n != "Pa"}
    groups: dict[tuple[str, ...], list[str]] = {}
    for column, (_, p) in found.items():
        groups.setdefault(tuple(alternatives(p, spec, "Pa")), []).append(column)
    lines = []
    for fits, columns in groups.items():
        said = "".join(f"; the values x {readings[n].scale:.6g} ({n} read as Pa) fit (`--column COLUMN=SOURCE:{n}` "
                       f"where it was read in Pa)" for n in fits)
        first = columns[0]
        lines.append(f"{', '.join(columns)}: {found[first][0]}" + (" (on the first; the others alike)" if len(columns) > 1
                                                                    else "")
                     + f", where no chamber of the circuit can be: the pressure is read in another unit than it was "
                       f"logged in (or the transducer is not connected){said}")
    return lines
