"""Valve-model feedforward, Papadopoulos, Mu & Frenette (2003), Sec. VI, eqs. (19)-(21) and Fig. 10.

From the desired joint speed the actuator's desired flows follow from its geometry; with the
measured pressures the pressure drop across the metering edges follows; inverting the identified
valve characteristic (Fig. 5, deadband included, see :mod:`.valve_model`) gives the voltage. The
paper's equations were lost in the text extraction; as implemented here:

(19) pressure drop, tank pressure p_T (the paper takes p_T = 0). Both metering edges of the spool
     carry the actuator's flows in series, supply -> inlet chamber and outlet chamber -> tank:

        extension (q' > 0):  dP_v = (p_S - p_A) + (p_B - p_T)
        retraction (q' < 0): dP_v = (p_S - p_B) + (p_A - p_T)

(20) orifice law of each edge, Q = g sqrt(dp) with the same conductance g on both edges (one spool
     opens both); summing the two drops:

        dP_v = (Q_A^2 + Q_B^2) / g^2   ->   g_d = sqrt((Q_A^2 + Q_B^2) / dP_v)

     desired flows: cylinder  Q_A = A_A |dL/dq q'_d|, Q_B = A_B |dL/dq q'_d|  (dL/dq from the mounts);
                    motor     Q_A = Q_B = N D |q'_d|   (gear ratio x displacement)

(21) u_ff = sign(q'_d) g^-1(g_d)  (inverse characteristic: |u| >= the deadband width when moving)

and the joint command is u = kappa u_ff + u_PID with kappa < 1 (Fig. 10). The drop is floored at
``min_drop`` (an overrunning load can make it tiny or negative, where the model says "open fully").
"""

from __future__ import annotations

import math

from sim_core.components.cylinder import cylinder_length
from sim_core.model.spec import RobotSpec

from .valve_model import ValveModel


class JointFeedforward:
    def __init__(self, spec: RobotSpec, joint: str, min_drop: float = 0.5e6):
        js = spec.joint(joint)
        tree = spec.tree
        self.joint = joint
        self.valve = ValveModel(spec, joint)
        self.p_supply = float(spec.get("supply.pressure"))       # Pa
        self.p_tank = float(spec.get("supply.tank_pressure"))    # Pa
        self.min_drop = float(min_drop)                          # Pa
        self.kind = js.kind
        if self.kind == "cylinder":
            cyl = js.components["cylinder"]
            i = tree.index(js.dof)
            self.area_a, self.area_b = cyl.area_a, cyl.area_b    # m^2
            self.direct = cyl.direct
            self.c0, self.d1, self.d2 = (0.0, 0.0, 0.0) if cyl.direct else cyl.linkage(tree.axis[i], tree.lower[i], tree.upper[i])[:3]
            cylinder_length(0.5 * (tree.lower[i] + tree.upper[i]), self.c0, self.d1, self.d2)  # load the compiled
            # function now: its first call takes ~1 s, which a realtime loop must not spend mid-run
        else:
            rot = js.components["rotary"]
            self.flow_per_rad = float(rot["gear_ratio"]) * float(rot["displacement"])   # m^3/rad at the joint

    def flows(self, q: float, qd: float) -> tuple[float, float]:
        """Desired flows (m^3/s, >= 0) into/out of chambers A and B for joint speed ``qd`` (rad/s) at ``q`` (rad)."""
        if self.kind == "cylinder":
            arm = 1.0 if self.direct else cylinder_length(q, self.c0, self.d1, self.d2)[1]
            v = abs(arm * qd)
            return self.area_a * v, self.area_b * v
        f = self.flow_per_rad * abs(qd)
        return f, f

    def pressure_drop(self, qd: float, p_a: float, p_b: float) -> float:
        """Eq. (19): drop across the two metering edges in use (Pa), floored at ``min_drop``."""
        if qd >= 0.0:
            dp = (self.p_supply - p_a) + (p_b - self.p_tank)
        else:
            dp = (self.p_supply - p_b) + (p_a - self.p_tank)
        return max(dp, self.min_drop)

    def voltage(self, q: float, qd: float, p_a: float, p_b: float) -> float:
        """Eqs. (19)-(21): feedforward voltage (V) for desired speed ``qd`` (rad/s) at angle ``q`` (rad)."""
        if qd == 0.0 or not math.isfinite(qd):
            return 0.0
        qa, qb = self.flows(q, qd)
        g = math.sqrt((qa * qa + qb * qb) / self.pressure_drop(qd, p_a, p_b))
        return math.copysign(self.valve.voltage_for_conductance(g), qd)
