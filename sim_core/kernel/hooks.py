"""The phases of a substep where effects take part: each phase's hook arguments and composition.

An effect lists its hooks by phase in ``HOOKS`` (phase -> name of a numba function in its own
file). ``kernel.compose`` turns every phase into one function ``fx_<phase>`` that calls the hooks
of the registered effects in ``ORDER``, each where its switch is on (``AP[a, switch]`` per
actuator, ``GP[switch]`` for a global effect); ``<phase>_off`` hooks run where it is off, to keep
the effect's states in step so that switching it on later starts from a consistent state. The
kernel skeleton (``kernel.skeleton``) calls the ``fx_<phase>`` functions.

Composition modes:

* ``chain``: each hook transforms the phase's value(s) in turn (the command path, the sensed position).
* ``override``: one effect may replace the nominal computation (``default``, a component's function
  or an expression); two effects overriding one phase is an error at composition.
* ``sum``: the hooks' values are added, starting from zero (leakage flows, friction torques).
* ``notify``: the hooks update states and return nothing.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Phase:
    name: str
    args: str          # the hook's parameters
    mode: str          # chain | override | sum | notify
    values: str = ""   # chain: the transformed argument(s); override/sum: what the hook returns
    default: str = ""  # override: the nominal expression
    scope: str = "joint"
    doc: str = ""


PHASES: tuple[Phase, ...] = (
    Phase("command", "u, a, t, h, AP, XS, XG, HT, HU", "chain", "u",
          doc="command path: the command voltage (V) on its way to the amplifiers; off hook: (u, a, AP, XS)"),
    Phase("metering", "a, AP, XS", "override", "x", "spool_position(a, AP, XS)",
          doc="the spool position the valve meters with (stroke fraction)"),
    Phase("actuator_motion", "a, dof, q, qd, AP, XS", "override", "th, om", "q[dof], qd[dof]",
          doc="position and rate the actuator sees (rad or m, per s); off hook: same arguments"),
    Phase("coupling", "a, dof, h, tau_h, visc, q, qd, AP, XS, XG, energy", "override", "f, dlin, work",
          "tau_h - visc * qd[dof], visc, tau_h",
          doc="force on the link (N m or N), its slope -d/dqd, and the actuator force for the work ledger"),
    Phase("after_mechanics", "a, dof, h, q, qd, qd_old, AP, XS, XG", "notify",
          doc="energy ledger only: after the joints moved (qd_old: velocities before the substep)"),
    Phase("joint_friction", "a, qd_dof, AP", "sum", "tf, slope",
          doc="friction on the joint (N m or N) and its slope d/dqd"),
    Phase("negative_gain", "kv, a, AP", "override", "kvn", "kv",
          doc="flow coefficient of the negative-travel edges (m^3/s/sqrt(Pa))"),
    Phase("edge_limit", "q_pa, dq_pa, q_pb, dq_pb, a, AP", "chain", "q_pa, dq_pa, q_pb, dq_pb",
          doc="the supply edges' flows (m^3/s) and slopes"),
    Phase("leakage", "pa, pb, p_t, a, AP", "sum", "lk_a, lk_b, dlk_a, dlk_b",
          doc="flows leaving the chambers (m^3/s) and their slopes d/dp_own"),
    Phase("bulk", "p, GP", "override", "f", "1.0", scope="global",
          doc="multiplier on the oil's bulk modulus at gauge pressure p"),
    Phase("compression_energy", "p, GP", "override", "g", "0.5 * p * p", scope="global",
          doc="G(p) = int_0^p p'/f(p') dp' (Pa^2): compressed oil stores V G(p) / beta"),
    Phase("port_pressures", "a, pa, pb, AP, XS", "override", "ua, ub", "pa, pb",
          doc="pressures at the valve ports (Pa)"),
    Phase("pressures", "a, h, ua, ub, pa, pb, qva, dqva, qvb, dqvb, va, vb, qdisp_a, qdisp_b, "
          "lk_a, dlk_a, lk_b, dlk_b, beta0, bulk, GP, AP, XS, XG, energy", "override",
          "pa_n, pb_n, ua_n, ub_n, fa, fb",
          "lumped_pressures(a, h, ua, ub, pa, pb, qva, dqva, qvb, dqvb, va, vb, qdisp_a, qdisp_b, "
          "lk_a, dlk_a, lk_b, dlk_b, beta0, bulk, GP, AP, XS, XG, energy)",
          doc="new chamber and port pressures over the substep, and the bulk factors used"),
    Phase("after_pressures", "a, ua_n, ub_n, qa_e, qb_e, AP, XS", "notify",
          doc="after the pressure update: new port pressures and the valve flows applied"),
    Phase("sensor_position", "th, a, q_dof, AP, XS", "chain", "th",
          doc="the position the sensor sees (rad or m)"),
    Phase("after_substep", "a, q_dof, AP, XS", "notify", doc="end of the substep"),
    Phase("reference_coupling", "a, dof, tau_h, visc, q, qd, AP, XS, dXS", "override", "f",
          "tau_h - visc * qd[dof]", doc="reference solver: force on the link; writes the effect's derivatives"),
    Phase("reference_pressures", "a, ua, ub, pa, pb, qva, qvb, va, vb, qdisp_a, qdisp_b, lk_a, lk_b, "
          "beta0, bulk, GP, AP, XS, dXS", "override", "dpa, dpb",
          "lumped_derivatives(a, pa, pb, qva, qvb, va, vb, qdisp_a, qdisp_b, lk_a, lk_b, beta0, bulk, GP, AP, XS, dXS)",
          doc="reference solver: chamber pressure derivatives; writes the effect's own derivatives"),
)
PHASE = {p.name: p for p in PHASES}


def hook_phase(hook: str) -> tuple[Phase, bool]:
    """The phase a hook name belongs to, and whether it is the phase's ``_off`` hook."""
    if hook in PHASE:
        return PHASE[hook], False
    if hook.endswith("_off") and hook[:-4] in PHASE:
        return PHASE[hook[:-4]], True
    raise KeyError(f"unknown kernel phase {hook!r}; phases: {', '.join(PHASE)}")


OFF_ARGS = {"command": "u, a, AP, XS"}  # off hooks that take fewer arguments than the phase's hook
