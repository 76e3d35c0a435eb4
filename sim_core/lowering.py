"""Lowering: a validated :class:`RobotSpec` -> the dense arrays the compiled kernel reads."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dynamics.rigid_body import RigidBodyModel
from .effects import get_effect
from .kernel import layout as L
from .model.spec import RobotSpec

P_ATM = 101325.0  # Pa


@dataclass
class Lowered:
    AP: np.ndarray
    DP: np.ndarray
    GP: np.ndarray
    mass: np.ndarray
    com: np.ndarray
    inertia: np.ndarray
    joint_inertia: np.ndarray   # M_ii at the initial pose (kg m^2)
    q0: np.ndarray
    spec: RobotSpec

    def payload_point(self, a: int) -> tuple[int, np.ndarray]:
        """(body index, point in body frame) where a payload on actuator ``a``'s joint attaches."""
        js = self.spec.joints[a]
        tree = self.spec.tree
        frame = js.settings["payload_frame"]
        if frame:
            body, _R, p = tree.link_frames[frame]
            if body < 0:
                raise ValueError(f"payload_frame {frame!r} is fixed to the ground")
            return body, np.array(p)
        i = tree.index(js.dof)
        for c in range(tree.n):
            if tree.parent[c] == i:
                return i, tree.p_tree[c].copy()
        return i, self.com[i].copy()


def initial_positions(spec: RobotSpec) -> np.ndarray:
    q0 = np.zeros(spec.tree.n)
    for j in spec.joints:
        q0[spec.tree.index(j.dof)] = j.settings["initial_position"]
    for dof, s in spec.passive.items():
        q0[spec.tree.index(dof)] = s["initial_position"]
    return q0


def lower(spec: RobotSpec) -> Lowered:
    tree = spec.tree
    n, na = tree.n, len(spec.joints)
    AP = np.zeros((na, L.AP_N))
    DP = np.zeros((n, L.DP_N))
    GP = np.zeros(L.GP_N)
    q0 = initial_positions(spec)
    lw = Lowered(AP, DP, GP, tree.mass.copy(), tree.com.copy(), tree.inertia.copy(), np.zeros(n), q0, spec)
    fluid, supply, integ = spec.fluid, spec.supply, spec.integrator

    # --- actuators
    for a, js in enumerate(spec.joints):
        c = js.components
        i = tree.index(js.dof)
        lo, hi = js.command_range
        AP[a, L.AP_DOF] = i
        AP[a, L.AP_U_MIN], AP[a, L.AP_U_MAX] = lo, hi
        AP[a, L.AP_AMP_GAIN] = c["amplifier"]["gain"]
        AP[a, L.AP_AMP_IMAX] = c["amplifier"]["max_current"]
        AP[a, L.AP_SOL_TAU] = c["solenoid"]["time_constant"]
        AP[a, L.AP_SPOOL_GAIN] = c["spool"]["gain"]
        AP[a, L.AP_SPOOL_WN] = 2.0 * math.pi * c["spool"]["natural_frequency"]
        AP[a, L.AP_SPOOL_ZETA] = c["spool"]["damping_ratio"]
        AP[a, L.AP_SPOOL_LIMIT] = c["spool"]["stroke_limit"]
        v = c["valve"]
        AP[a, L.AP_KV] = v.flow_coefficient
        AP[a, L.AP_OVERLAP] = v["overlap"]
        AP[a, L.AP_NULL_LEAK] = v["null_leakage"]
        AP[a, L.AP_POLY1], AP[a, L.AP_POLY2], AP[a, L.AP_POLY3] = v["characteristic"]
        AP[a, L.AP_DP_TR] = v["transition_pressure"]
        if js.kind == "cylinder":
            cyl = c["cylinder"]
            AP[a, L.AP_KIND] = 0.0
            AP[a, L.AP_AREA_A] = cyl.area_a
            AP[a, L.AP_AREA_B] = cyl.area_b
            c0, d1, d2, lmin, stroke = cyl.linkage(tree.axis[i], tree.lower[i], tree.upper[i])
            AP[a, L.AP_LK_C0], AP[a, L.AP_LK_D1], AP[a, L.AP_LK_D2] = c0, d1, d2
            AP[a, L.AP_LK_LMIN], AP[a, L.AP_STROKE] = lmin, stroke
            AP[a, L.AP_VDEAD_A] = cyl["dead_volume_a"]
            AP[a, L.AP_VDEAD_B] = cyl["dead_volume_b"]
            AP[a, L.AP_VISC] = cyl["viscous_friction"]
            relief = cyl["port_relief_pressure"]
        else:
            rot = c["rotary"]
            AP[a, L.AP_KIND] = 1.0
            AP[a, L.AP_AREA_A] = AP[a, L.AP_AREA_B] = rot["gear_ratio"] * rot["displacement"]
            AP[a, L.AP_VDEAD_A] = AP[a, L.AP_VDEAD_B] = rot["chamber_volume"]
            AP[a, L.AP_VISC] = rot["viscous_friction"]
            relief = rot["port_relief_pressure"]
        AP[a, L.AP_RELIEF_P] = relief
        # a port relief passes the valve's rated flow 0.5 MPa above cracking
        AP[a, L.AP_RELIEF_K] = v["rated_flow"] / 5e5
        hose = c["hose"]
        AP[a, L.AP_HOSE_VOL] = max(hose.volume, 1e-9)  # a zero-length hose still has a port volume
        AP[a, L.AP_HOSE_BETA] = hose["effective_bulk_modulus"]
        AP[a, L.AP_HOSE_I] = hose.inertance(fluid["density"])
        AP[a, L.AP_HOSE_RLAM] = hose.laminar_resistance(fluid.dynamic_viscosity)
        AP[a, L.AP_HOSE_RTURB] = hose.turbulent_resistance(fluid["density"])
        AP[a, L.AP_HOSE_TURB] = 1.0 if hose["flow_regime"] == "turbulent" else 0.0
        if js.sensed:
            s = c["sensor"]
            vmin, vmax = s["range"]
            AP[a, L.AP_SENSED] = 1.0
            AP[a, L.AP_POT_A] = s["A"]
            AP[a, L.AP_POT_B] = s["B"]
            AP[a, L.AP_POT_NOISE] = s["noise"]
            AP[a, L.AP_POT_LSB] = (vmax - vmin) / 2.0 ** s["bits"] if s["bits"] > 0 else 0.0
            AP[a, L.AP_POT_VMIN], AP[a, L.AP_POT_VMAX] = vmin, vmax
        # neutral values of switchable effects
        AP[a, L.AP_SENS_GAIN] = 1.0
        AP[a, L.AP_ASYM_RATIO] = 1.0
        AP[a, L.AP_LAG_TAU] = 0.01
        AP[a, L.AP_COUL_VEL] = 0.01
        AP[a, L.AP_COMP_JA] = 1.0
        AP[a, L.AP_CMD_H] = -1.0
        DP[i, L.DP_ACT] = a

    # --- mechanism: payloads first (they change the inertia), then the rest
    effects = sorted(spec.effects, key=lambda e: e.name != "payload")
    for e in effects:
        if e.name != "payload":
            break
        get_effect(e.name).lower(e.params, lw, spec.joint_names.index(e.joint))
    rb = RigidBodyModel(tree, lw.mass, lw.com, lw.inertia)
    Jd = np.diag(rb.mass_matrix(q0)).copy()
    lw.joint_inertia[:] = Jd
    # end stops: stiff enough that the actuator's full-pressure torque pushes at most
    # end_stop_penetration into them, and never softer than end_stop_frequency on the link
    w = 2.0 * math.pi * integ["end_stop_frequency"]
    tau_max = np.zeros(n)
    for a, js in enumerate(spec.joints):
        i = tree.index(js.dof)
        if AP[a, L.AP_KIND] == 0.0:
            qs = np.linspace(tree.lower[i], tree.upper[i], 50)
            c0, d1, d2 = AP[a, L.AP_LK_C0], AP[a, L.AP_LK_D1], AP[a, L.AP_LK_D2]
            arm = (d1 * np.sin(qs) - d2 * np.cos(qs)) / np.sqrt(c0 - 2 * (d1 * np.cos(qs) + d2 * np.sin(qs)))
            tau_max[i] = supply["pressure"] * AP[a, L.AP_AREA_A] * arm.max()
        else:
            tau_max[i] = supply["pressure"] * AP[a, L.AP_AREA_A]
    for i in range(n):
        k = max(Jd[i] * w * w, tau_max[i] / integ["end_stop_penetration"])
        DP[i, L.DP_LOWER] = tree.lower[i]
        DP[i, L.DP_UPPER] = tree.upper[i]
        DP[i, L.DP_STOP_K] = k
        DP[i, L.DP_STOP_C] = 2.0 * integ["end_stop_damping_ratio"] * math.sqrt(k * Jd[i])
        DP[i, L.DP_DAMPING] = tree.damping[i]
        if not any(spec.tree.index(j.dof) == i for j in spec.joints):
            DP[i, L.DP_ACT] = -1

    # --- globals
    GP[L.GP_P_SUPPLY] = supply["pressure"]
    GP[L.GP_P_TANK] = supply["tank_pressure"]
    GP[L.GP_PUMP_QMAX] = supply["max_flow"]
    GP[L.GP_PUMP_BAND] = supply["compensator_band"]
    GP[L.GP_SUPPLY_C] = supply["line_volume"] / fluid["bulk_modulus"]
    GP[L.GP_SUPPLY_RELIEF_P] = supply["relief_pressure"]
    GP[L.GP_SUPPLY_RELIEF_K] = supply["relief_conductance"]
    GP[L.GP_SUPPLY_SAG] = 1.0
    GP[L.GP_BETA] = fluid["bulk_modulus"]
    GP[L.GP_P_MIN] = fluid["cavitation_pressure"]
    GP[L.GP_P_ATM] = P_ATM
    GP[L.GP_BULK_SCALE] = 1.0
    GP[L.GP_H_MAX] = integ["max_substep"]
    GP[L.GP_RB_EVERY] = integ["rigid_body_refresh"]

    for e in effects:
        if e.name == "payload":
            continue
        a = None if e.joint is None else spec.joint_names.index(e.joint)
        get_effect(e.name).lower(e.params, lw, a)
    return lw
