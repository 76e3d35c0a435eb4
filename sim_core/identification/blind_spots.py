"""What a record cannot test for, given what the calibration had to estimate beside the effects.

Without chamber pressures a valve-driven joint shows a Coulomb friction only through the speed it
reaches per volt of command, one figure each way. The valve's flow gain (always calibrated), the
supply pressure and the load set those same figures, so with the supply or the load estimated as
well, a friction is one more unknown than the record has figures for: the calibration takes it up,
and "no significant discrepancy" says nothing about friction. Measured supply and load (their
[estimated] lines deleted) or recorded chamber pressures make it testable (README, "Diagnose your
own rig").
"""

from __future__ import annotations


def friction(free_keys: list[str], joints: list[str], has_pressures: bool, bank: list[str] | None,
             named: set[tuple[str, str | None]]) -> list[str]:
    """One sentence per joint where a Coulomb friction could not be told from what was calibrated."""
    if has_pressures or (bank is not None and "coulomb_friction" not in bank):
        return []
    out = []
    for j in joints:
        if ("coulomb_friction", j) in named:
            continue
        unknown = [k for k in ("supply.pressure", f"effects.payload.{j}.mass", "links.mass_scale") if k in free_keys]
        if unknown:
            out.append(f"{j}: a Coulomb friction cannot be told here from the valve flow gain, "
                       f"{' and '.join(unknown)}, which the calibration estimated (without chamber pressures "
                       f"each sets the same speeds per volt); measure {'it' if len(unknown) == 1 else 'them'} "
                       f"and delete the [estimated] line{'' if len(unknown) == 1 else 's'}, or record the "
                       f"chamber pressures, to test for one")
    return out
