"""Pressure -> colour: one map shared by the 3D scene and the panel's legend.

A rainbow-like ("turbo") scale over 0..nominal supply pressure (clipped above): tank blue, cyan,
half supply green, amber, supply red. A cylinder at rest sits near half supply on both sides (green);
under load one side turns amber/red and the other cyan/blue, so the load direction reads at a glance.
"""

from __future__ import annotations

import numpy as np

# (fraction of supply pressure, RGB 0..255)
STOPS = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
RGB = np.array([
    [35, 60, 190],
    [30, 170, 220],
    [60, 190, 90],
    [245, 190, 40],
    [215, 40, 30],
], dtype=float)


def pressure_rgb(p, p_max: float) -> np.ndarray:
    """uint8 RGB rows for pressures ``p`` (Pa) on the scale 0..``p_max``."""
    f = np.clip(np.asarray(p, dtype=float) / max(p_max, 1.0), 0.0, 1.0)
    out = np.empty(f.shape + (3,))
    for c in range(3):
        out[..., c] = np.interp(f, STOPS, RGB[:, c])
    return np.rint(out).astype(np.uint8)


def legend_html(p_max: float) -> str:
    stops = ", ".join(f"rgb({r:.0f},{g:.0f},{b:.0f}) {s * 100:.0f}%" for s, (r, g, b) in zip(STOPS, RGB))
    return (
        "<div style='font-size:0.8em;padding:0 0.5em'>Cylinder colour = chamber pressure "
        "(cap side A from the base, rod side B towards the rod)"
        f"<div style='height:10px;border-radius:3px;background:linear-gradient(to right, {stops})'></div>"
        f"<div style='display:flex;justify-content:space-between'><span>0 bar</span>"
        f"<span>{p_max / 2e5:.0f}</span><span>{p_max / 1e5:.0f} bar (supply)</span></div></div>"
    )
