"""The identified valve characteristic of one joint and its inverse (Papadopoulos et al. 2003, Fig. 5).

The paper identified, for its proportional valves, the valve coefficient as a third-order polynomial
of the command voltage with a 0-1.2 V deadband. The controller's "identified characteristic" here is
the emulator's valve model as identified, read from the robot spec (never copied numbers):

    u_e   = |u| - w                        deadband effect (w in V; 0 if the joint has none)
    i     = min(K_a u_e, I_max)            amplifier (A)
    s     = min(K_x i, s_lim)              spool, steady state (fraction of the metering stroke)
    s'    = max(s - o, 0) / (1 - o)        overlap o
    a(s') = c1 s' + c2 s'^2 + c3 s'^3      opening characteristic
    g(u)  = K_v a(s')                      conductance of one metering edge (m^3/s/sqrt(Pa)):
                                           Q = g sqrt(dp) in the turbulent regime

so that for the harvester |u| = 1.2 V + 8.8 V * s' with a(s') the Fig. 5 fit. The spool and coil
dynamics (25 Hz, 4 ms) are left out, as the paper's valve model leaves them out.
"""

from __future__ import annotations

import math

from sim_core.model.spec import RobotSpec


class ValveModel:
    def __init__(self, spec: RobotSpec, joint: str):
        js = spec.joint(joint)
        self.joint = joint
        amp, spool, valve = js.components["amplifier"], js.components["spool"], js.components["valve"]
        self.deadband_v = 0.0
        for e in spec.effects:
            if e.name == "deadband" and e.joint == joint and e.params.get("enabled", True):
                self.deadband_v = float(e.params["width"])
        self.amp_gain = float(amp["gain"])                      # A/V
        self.max_current = float(amp["max_current"])            # A
        self.spool_gain = float(spool["gain"])                  # 1/A
        self.spool_limit = float(spool["stroke_limit"])         # -
        self.overlap = float(valve["overlap"])                  # -
        self.kv = valve.flow_coefficient                        # m^3/s/sqrt(Pa) per edge, full opening
        self.c1, self.c2, self.c3 = (float(c) for c in valve["characteristic"])
        self.u_min, self.u_max = js.command_range               # V
        # largest useful command: where the amplifier or the spool end stop saturates
        s_sat = min(self.spool_gain * self.max_current, self.spool_limit)
        self.s_sat = s_sat
        self.u_sat = min(self.deadband_v + s_sat / (self.spool_gain * self.amp_gain), max(-self.u_min, self.u_max))

    # ---- forward --------------------------------------------------------------------------------
    def spool(self, u: float) -> float:
        """Steady-state spool position (signed stroke fraction) for command ``u`` (V)."""
        ue = max(abs(u) - self.deadband_v, 0.0)
        s = min(self.spool_gain * min(self.amp_gain * ue, self.max_current), self.spool_limit)
        return math.copysign(s, u)

    def opening(self, s: float) -> float:
        """Relative opening a(s') of the edges a spool travel ``|s|`` opens (0..1)."""
        s = abs(s)
        if s <= self.overlap:
            return 0.0
        x = (s - self.overlap) / (1.0 - self.overlap)
        if x > 1.0:
            return 1.0 + (x - 1.0) * (self.c1 + 2.0 * self.c2 + 3.0 * self.c3)
        return x * (self.c1 + x * (self.c2 + x * self.c3))

    def conductance(self, u: float) -> float:
        """Edge conductance g(u) = K_v a(s'(u)) (m^3/s/sqrt(Pa)), >= 0."""
        return self.kv * self.opening(self.spool(u))

    # ---- inverse --------------------------------------------------------------------------------
    def voltage_for_conductance(self, g: float) -> float:
        """Smallest |u| (V, >= 0) whose edge conductance is ``g``; the saturation voltage if g is out of reach.
        g = 0 gives 0 V (valve neutral); any g > 0 gives at least the deadband width."""
        if g <= 0.0:
            return 0.0
        a_max = self.opening(self.s_sat)
        a = g / self.kv
        if a >= a_max:
            return self.u_sat
        # a(x) is increasing on [0, x_max]: bisection then Newton polish (cheap, robust)
        x_max = (self.s_sat - self.overlap) / (1.0 - self.overlap)
        lo, hi = 0.0, x_max
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if self._poly(mid) < a:
                lo = mid
            else:
                hi = mid
        x = 0.5 * (lo + hi)
        s = self.overlap + x * (1.0 - self.overlap)
        return self.deadband_v + s / (self.spool_gain * self.amp_gain)

    def _poly(self, x: float) -> float:
        if x > 1.0:
            return 1.0 + (x - 1.0) * (self.c1 + 2.0 * self.c2 + 3.0 * self.c3)
        return x * (self.c1 + x * (self.c2 + x * self.c3))
