"""Joint-space PID of Papadopoulos et al. (2003), Fig. 10, for one valve-driven joint.

    e     = q_d - q_m                            (rad; q_m the measured, calibrated sensor angle)
    q'_m  = low-pass((q_m[k] - q_m[k-1]) / dt)   (rad/s; the velocity is computed from the angle, as the
                                                  paper did with its resolvers, first-order filter tau_d)
    v     = K_p e + K_i I + K_d (q'_d - q'_m)    (V; I the conditioned integral of e)
    u     = kappa u_ff + comp(v)                 (V; u_ff the valve-model feedforward, see .feedforward)

Options, all off by default (the paper's plain PID):

* ``deadband_comp`` w_c (V) with ``comp_ramp`` v_r (V): comp(v) = v + w_c sat(v / v_r) jumps the
  feedback over the valve's overlap instead of letting the integrator wind through it; the ramp keeps
  it continuous, so a tiny correction gives a tiny opening.
* conditioned integrator: the integral stops while the output is saturated in the direction of the
  error (clamping anti-windup), only runs while |e| < ``i_band`` (integrator separation: it trims the
  last millimetres instead of winding up during a move) and its authority is limited to ``i_limit`` (V).
* ``settle_band`` / ``release_band`` (rad): for point-to-point moves (q'_d = 0), once |e| is inside the
  settle band the valve is commanded neutral and the integral is cleared; control resumes when |e|
  leaves the (wider) release band. A closed-centre valve with zero leakage holds the load by itself,
  so this removes the integrator/deadband limit cycle ("hunting") instead of just slowing it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class PidGains:
    kp: float                      # V/rad
    ki: float = 0.0                # V/(rad s)
    kd: float = 0.0                # V s/rad
    tau_d: float = 0.02            # s: velocity (derivative) filter time constant
    u_limit: float = 10.0          # V: command saturation (the valve command range)
    i_limit: float = 10.0          # V: largest integral contribution K_i I
    i_band: float = 0.0            # rad: integrate only while |e| < i_band (0: always)
    deadband_comp: float = 0.0     # V: compensated deadband width w_c
    comp_ramp: float = 0.1         # V: feedback over which the compensation ramps in
    settle_band: float = 0.0       # rad: |e| below which a stationary target counts as reached (0: off)
    release_band: float = 0.0      # rad: |e| above which a settled joint is controlled again


@dataclass
class PidTerms:
    u: float = 0.0                 # V: command sent
    feedback: float = 0.0          # V: v (before deadband compensation)
    feedforward: float = 0.0       # V: kappa u_ff
    p: float = 0.0
    i: float = 0.0
    d: float = 0.0
    velocity: float = 0.0          # rad/s: computed joint velocity
    settled: bool = False


class JointPID:
    def __init__(self, gains: PidGains):
        self.g = gains
        self.integral = 0.0        # rad s
        self.q_prev = math.nan
        self.t_prev = math.nan
        self.velocity = 0.0        # rad/s
        self.settled = False
        self.last_u = 0.0

    def reset(self, q: float, t: float) -> None:
        self.integral = 0.0
        self.q_prev = q
        self.t_prev = t
        self.velocity = 0.0
        self.settled = False
        self.last_u = 0.0

    def update(self, t: float, q: float, q_d: float, qd_d: float = 0.0, u_ff: float = 0.0, kappa: float = 1.0) -> PidTerms:
        """One control step at time ``t`` (s) with measured angle ``q`` (rad), desired angle/speed
        ``q_d`` (rad) / ``qd_d`` (rad/s) and feedforward ``u_ff`` (V, weighted by ``kappa``)."""
        g = self.g
        if not math.isfinite(self.q_prev):
            self.reset(q, t)
        dt = t - self.t_prev
        if dt > 0.0:
            raw = (q - self.q_prev) / dt
            a = dt / (g.tau_d + dt)
            self.velocity += a * (raw - self.velocity)
        e = q_d - q
        terms = PidTerms(velocity=self.velocity)
        # settle band (stationary targets only)
        if g.settle_band > 0.0 and qd_d == 0.0:
            if self.settled and abs(e) > g.release_band:
                self.settled = False
            elif not self.settled and abs(e) < g.settle_band:
                self.settled = True
                self.integral = 0.0
        else:
            self.settled = False
        self.q_prev, self.t_prev = q, t
        if self.settled:
            terms.settled = True
            self.last_u = 0.0
            return terms
        # conditioned integral: clamp while the output saturates in the error's direction
        if dt > 0.0 and g.ki > 0.0:
            sat = abs(self.last_u) >= g.u_limit and self.last_u * e > 0.0
            if not sat and (g.i_band <= 0.0 or abs(e) < g.i_band):
                self.integral += e * dt
                lim = g.i_limit / g.ki
                self.integral = min(max(self.integral, -lim), lim)
        terms.p = g.kp * e
        terms.i = g.ki * self.integral
        terms.d = g.kd * (qd_d - self.velocity)
        v = terms.p + terms.i + terms.d
        terms.feedback = v
        if g.deadband_comp > 0.0:
            v = v + g.deadband_comp * max(-1.0, min(1.0, v / g.comp_ramp))
        terms.feedforward = kappa * u_ff
        u = terms.feedforward + v
        u = max(-g.u_limit, min(g.u_limit, u))
        terms.u = u
        self.last_u = u
        return terms
