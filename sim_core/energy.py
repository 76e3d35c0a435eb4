"""Energy bookkeeping: the kernel's ledger of hydraulic input and dissipation, and stored energy.

Balance over any interval (all pressures gauge, so energies are relative to the tank datum):

    E_supply + E_compress  =  E_tank + E_valve + E_hose + E_leak + E_mech + E_relief  +  dE_stored

E_compress = int p^2/(2 beta) dV is the second-order defect of the constant-beta continuity equation
(V/beta dp/dt = Q - dV/dt has no exact stored-energy function when the piston moves); booking it
makes the balance a test of the integration, not of that known model property.

E_stored = kinetic (1/2 qd' M qd) + gravitational + compressed oil (1/2 C p^2 per node) + hose
fluid kinetic (1/2 I q^2) + end-stop and compliance springs + actuator-side kinetic energy.
The kernel integrates the ledger only while ``Context.energy_ledger`` is on (it costs ~10 %).
"""

from __future__ import annotations

from dataclasses import dataclass

from .components.chambers import P_A, P_B
from .components.hose import HOSE_BETA, HOSE_VOL
from .components.joint import stop_energy
from .components.pump import P_S, PUMP_QMAX, SUPPLY_C
from .effects import EFFECTS
from .kernel import layout as L


@dataclass
class EnergyLedger:
    supply: float
    tank: float
    valve: float
    hose: float
    leak: float
    mech: float
    relief: float
    actuator_work: float = 0.0
    compressibility: float = 0.0

    @property
    def dissipated(self) -> float:
        return self.tank + self.valve + self.hose + self.leak + self.mech + self.relief


def ledger(ctx) -> EnergyLedger:
    X = ctx.XG
    return EnergyLedger(X[L.XG_E_SUPPLY], X[L.XG_E_TANK], X[L.XG_E_VALVE], X[L.XG_E_HOSE],
                        X[L.XG_E_LEAK], X[L.XG_E_MECH], X[L.XG_E_RELIEF_PUMP], X[L.XG_E_ACT],
                        X[L.XG_E_COMPRESS])


def stored_energy(ctx) -> dict[str, float]:
    """Energy stored in the state of ``ctx`` (J), by kind: the rigid bodies, end stops, the oil in
    every chamber and hose (lumped), and what each effect stores in its own states."""
    rb = ctx.rigid_body()
    q, qd = ctx.XQ[0], ctx.XQ[1]
    AP, GP, XS = ctx.AP, ctx.GP, ctx.XS
    out = {"kinetic": rb.kinetic_energy(q, qd), "gravity": rb.potential_energy(q), "oil": 0.0,
           "hose_flow": 0.0, "springs": stop_energy(ctx.DP, q)}
    beta, G = ctx.bulk_functions()
    for a in range(AP.shape[0]):
        oil_done = False
        for eff in EFFECTS.values():
            if ctx.effect_on(eff, a):
                oil_done |= eff.stored_energy(ctx, a, out)
        if not oil_done:   # chamber and hose as one node per side
            va, vb = ctx.chamber_volumes(a)
            pa, pb = XS[a, P_A], XS[a, P_B]
            vh, bh = AP[a, HOSE_VOL], AP[a, HOSE_BETA]
            out["oil"] += (va / beta + vh / bh) * G(pa) + (vb / beta + vh / bh) * G(pb)
    if GP[PUMP_QMAX] > 0.0:
        out["oil"] += 0.5 * GP[SUPPLY_C] * ctx.XG[P_S] ** 2
    out["total"] = float(sum(out.values()))
    return out


def balance(ctx, e0: dict, l0: EnergyLedger | None = None) -> dict[str, float]:
    """Closure of the energy balance since the stored energy ``e0`` (and ledger ``l0``) were taken."""
    l1 = ledger(ctx)
    if l0 is None:
        l0 = EnergyLedger(0, 0, 0, 0, 0, 0, 0)
    e1 = stored_energy(ctx)
    e_in = l1.supply - l0.supply + (l1.compressibility - l0.compressibility)
    e_out = l1.dissipated - l0.dissipated
    d_stored = e1["total"] - e0["total"]
    residual = e_in - e_out - d_stored
    # mechanical side alone: actuator work = mechanical dissipation + change of kinetic,
    # gravitational and spring energy
    w_act = l1.actuator_work - l0.actuator_work
    d_mech = sum(e1[k] - e0[k] for k in ("kinetic", "gravity", "springs"))
    mech_res = w_act - (l1.mech - l0.mech) - d_mech
    return {"supply": e_in, "dissipated": e_out, "stored_change": d_stored, "residual": residual,
            "relative_residual": abs(residual) / max(abs(e_in), 1e-12),
            "actuator_work": w_act, "mechanical_dissipation": l1.mech - l0.mech, "mechanical_stored_change": d_mech,
            "mechanical_residual": mech_res,
            "mechanical_relative_residual": abs(mech_res) / max(abs(w_act), abs(d_mech), 1e-12)}


def with_ledger(ctx) -> None:
    """Switch the kernel's energy ledger on for ``ctx`` (and start it from zero)."""
    ctx.energy_ledger = True
    ctx.GP[L.GP_ENERGY] = 1.0
    for c in L.XG.owned_by("energy"):
        ctx.XG[c.index] = 0.0
