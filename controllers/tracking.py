"""Joint-level tracking for every actuated joint: one :class:`~.pid.JointPID` per joint plus the
valve-model feedforward (Fig. 10 of Papadopoulos et al. 2003), and the generic control loop that runs
any controller against any :class:`~.plant.PlantClient` and records a trace.
"""

from __future__ import annotations

import math

import numpy as np

from sim_core.model.spec import RobotSpec

from .feedforward import JointFeedforward
from .pid import JointPID, PidGains
from .plant import Observation, PlantClient


class JointTracker:
    """u_j = kappa u_ff,j(q'_d, p_A, p_B) + PID_j(q_d - q_m) for each joint with gains; 0 V (valve neutral)
    for joints without gains or without a sensor (their angle is not available)."""

    def __init__(self, spec: RobotSpec, gains: dict[str, PidGains], kappa: float = 0.0, pressure_filter_s: float = 0.1):
        self.joints = list(spec.joint_names)
        unknown = sorted(set(gains) - set(self.joints))
        if unknown:
            raise ValueError(f"no such joint(s) {unknown}; joints: {', '.join(self.joints)}")
        self.pids = {j: JointPID(g) for j, g in gains.items()}
        self.kappa = float(kappa)
        self.ff = {j: JointFeedforward(spec, j) for j in gains} if kappa > 0.0 else {}
        self.tau_p = float(pressure_filter_s)
        self.p_a = self.p_b = None
        self.t_prev = 0.0

    def start(self, obs: Observation, t: float) -> None:
        self.p_a, self.p_b, self.t_prev = obs.p_a.copy(), obs.p_b.copy(), t
        for a, j in enumerate(self.joints):
            if j in self.pids:
                self.pids[j].reset(obs.angle[a], t)

    def command(self, t: float, obs: Observation, q_d: np.ndarray, qd_d: np.ndarray) -> dict:
        na = len(self.joints)
        # pressures for the feedforward through a first-order low-pass: the feedforward's pressure
        # dependence would otherwise feed the ~2.5 Hz hose/boom mode back into the valve command
        a = (t - self.t_prev) / (self.tau_p + (t - self.t_prev)) if self.tau_p > 0.0 else 1.0
        self.p_a += a * (obs.p_a - self.p_a)
        self.p_b += a * (obs.p_b - self.p_b)
        self.t_prev = t
        out = {"u": np.zeros(na), "u_fb": np.zeros(na), "u_ff": np.zeros(na), "vel_est": np.zeros(na),
               "settled": np.zeros(na)}
        for a, j in enumerate(self.joints):
            pid = self.pids.get(j)
            if pid is None or not math.isfinite(obs.angle[a]):
                continue
            u_ff = self.ff[j].voltage(q_d[a], qd_d[a], self.p_a[a], self.p_b[a]) if j in self.ff else 0.0
            terms = pid.update(t, obs.angle[a], q_d[a], qd_d[a], u_ff, self.kappa)
            out["u"][a] = terms.u
            out["u_fb"][a] = terms.feedback
            out["u_ff"][a] = terms.feedforward
            out["vel_est"][a] = terms.velocity
            out["settled"][a] = terms.settled
        return out


class Controller:
    """A closed-loop controller: ``start(obs)`` once, then ``step(t, obs)`` per control period returns a
    dict with at least ``u`` (V per actuated joint) and whatever else it wants recorded."""

    duration: float = 0.0    # s

    def start(self, obs: Observation) -> None:
        raise NotImplementedError

    def step(self, t: float, obs: Observation) -> dict:
        raise NotImplementedError


def run_loop(plant: PlantClient, controller: Controller, duration: float) -> dict[str, np.ndarray]:
    """Run ``controller`` on ``plant`` for ``duration`` s of plant time; the trace holds, per control
    period, the observation (at time ``t``, s since the first observation) and what the controller
    computed from it (applied over the following period)."""
    obs = plant.start()
    t0 = obs.t
    controller.start(obs)
    rows: dict[str, list] = {}
    while True:
        t = obs.t - t0
        if t >= duration - 1e-9:
            break
        out = controller.step(t, obs)
        rec = {"t": t, "angle": obs.angle, "velocity": obs.velocity, "p_a": obs.p_a, "p_b": obs.p_b,
               "u_applied": obs.u_applied, "spool": obs.spool, "status": obs.status}
        rec.update(out)
        for k, v in rec.items():
            rows.setdefault(k, []).append(np.array(v, dtype=float, copy=True))
        obs = plant.exchange(out["u"])
    trace = {k: np.array(v) for k, v in rows.items()}
    trace["joints"] = np.array(plant.joints)
    return trace
