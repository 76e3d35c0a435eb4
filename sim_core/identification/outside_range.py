"""A recorded position that lies outside its joint's range: read in another unit or scale than the spec's.

The model's joint cannot leave its range (the URDF's limits are end stops), so a record whose
position lies mostly outside it cannot be explained by any parameter or effect, and what the record
seems to say (a joint moving 57 times faster per volt than its valve: degrees read as radians) is
the unit's doing, not the valve's. The record check measures the share of samples further than
``MARGIN`` outside the range (ingest/joint_range.share); where it is the majority the diagnosis names it
(``cause``) before anything it would infer from the position's size, with the plain units under
which the values lie inside the range.
"""

from __future__ import annotations

import numpy as np

from ..ingest.joint_range import MARGIN, readings_inside
from ..ingest.units import UNITS, parse_unit

MAJORITY = 0.5        # share of the samples outside the range from which the position's unit is named


def named(s: float) -> bool:
    """Whether a share of samples outside the range says the position is in another unit or scale."""
    return s > MAJORITY


def cause(j: str, s: float, y, lo: float, hi: float, unit: str) -> str:
    """What to check, one sentence: joint ``j``'s positions ``y`` (SI, ``unit``) lie outside [lo, hi] on
    a share ``s`` of the samples."""
    kind = "position" if unit == "m" else "angle"
    si = next(iter(UNITS[kind]))
    readings = {n: parse_unit(n, kind, column=f"q_{j}") for n in UNITS[kind] if n != si}
    fits = readings_inside(y, readings, lo, hi)
    hint = "".join(f"; the values read as {n} where they were read as {si} (x {readings[n].scale:.4g}) lie inside it "
                   f"(`--column q_{j}=SOURCE:{n}`)" for n in fits)
    y = np.asarray(y, float)
    return (f"on {j} {100 * s:.3g} % of the recorded positions lie more than {MARGIN:g} {unit} outside the joint's "
            f"range [{lo:.4g}, {hi:.4g}] {unit} (the record spans {np.nanmin(y):.4g} .. {np.nanmax(y):.4g} {unit}), where "
            f"the model's joint cannot go: the position is read in another unit or scale than the spec's (the "
            f"column's unit, the sensor model joints.{j}.sensor.A and B), or the URDF's limits are not the rig's{hint}")
