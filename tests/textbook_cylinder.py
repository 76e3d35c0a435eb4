"""A rig HydroHIL's simulator did not make: a cylinder on a slide or raising a boom, from the textbook.

The equations are Merritt's (Hydraulic Control Systems, 1967, ch. 3 and 5) for a single-rod cylinder
fed by a 4/3 proportional valve, acting directly on a slide or through its two pins on a boom (the
law of cosines, by hand), written here from the meaning of the rig templates' parameters (their
comments in robot.toml and the URDF), with none of sim_core's code: its own state, its own orifice regularisation,
hose volumes lumped into the chambers, a tanh Coulomb friction, an ideal supply or a fixed pump behind
a relief valve (its own supply-line state), SciPy's LSODA between samples. A
logger and a P controller run on the jittered sample grid, as on a test bench, and the log is what
such a bench writes: `time (s), position (sensor volts, quantised), valve command (V)`.

A difference between this rig and the template that the diagnosis names is a finding about the rig;
a difference between the two codes that it names is a false alarm (or a bug in one of them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

G = 9.80665  # m/s^2


@dataclass(frozen=True)
class Boom:
    """A boom on a pivot raised by the cylinder through its pins (the `boom` template's geometry).
    Angles in rad, positive raises the boom; lengths in m from the pivot, [x, z] with x forward (the
    boom at q = 0) and z up."""
    mass: float = 60.0                  # kg, without the load
    com: float = 1.0                    # m along the boom
    inertia: float = 20.0               # kg m^2 about its centre of mass, across the pivot axis
    tip: float = 2.0                    # m, where the load hangs
    base_mount: tuple = (0.15, -1.0)    # m, the cylinder's base pin, fixed
    rod_mount: tuple = (1.0, 0.0)       # m, the rod's pin, in the boom's frame
    lower: float = -0.2                 # rad, the boom angle at full retraction
    upper: float = 0.9                  # rad, at full extension

    def length(self, q: float) -> tuple[float, float]:
        """(pin-to-pin length L (m), dL/dq (m/rad))."""
        rx, rz = self.rod_mount
        c, s = math.cos(q), math.sin(q)
        px, pz = rx * c - rz * s, rx * s + rz * c          # the rod pin, rotated with the boom
        dx, dz = px - self.base_mount[0], pz - self.base_mount[1]
        length = math.hypot(dx, dz)
        return length, (dx * -pz + dz * px) / length        # dP/dq = (-pz, px)


@dataclass(frozen=True)
class Rig:
    """The physical rig (SI). Defaults: the `cylinder` template's values."""
    slide_mass: float = 15.0            # kg
    load_mass: float = 100.0            # kg
    gravity_along: float = 1.0          # -; component of gravity along +q (1: hanging, extending lowers
                                        # the load; -1: vertical lift; 0: horizontal)
    bore: float = 0.05                  # m
    rod: float = 0.028                  # m
    stroke: float = 0.5                 # m; piston at 0 at q = 0
    dead_a: float = 3.92699e-5          # m^3
    dead_b: float = 2.69549e-5          # m^3
    hose_volume: float = math.pi / 4 * 8e-3 ** 2 * 1.5   # m^3 per side
    hose_bulk: float = 1.0e9            # Pa
    oil_bulk: float = 1.4e9             # Pa
    viscous: float = 2000.0             # N s/m
    coulomb: float = 0.0                # N
    supply: float = 1.4e7               # Pa gauge
    tank: float = 2.0e5                 # Pa gauge
    rated_flow: float = 2.0e-4          # m^3/s per edge at rated_drop
    rated_drop: float = 3.5e6           # Pa
    overlap: float = 0.0                # spool stroke fraction: no flow below it (geometric: the
                                        # opening is |x| - overlap, a full stroke opens 1 - overlap)
    negative_flow_ratio: float = 1.0    # -; flow of the negative-travel edges over the positive ones
    null_bias: float = 0.0              # spool stroke fraction the spool sits off its centre at zero
                                        # current (a valve's null shift: it opens as if commanded)
    piston_leakage: float = 0.0         # m^3/(s Pa); laminar leakage across the piston, A to B
    command_delay: float = 0.0          # s; dead time between the controller's output and the amplifier
    pump_flow: float = 0.0              # m^3/s; 0: an ideal pressure source at `supply`; else a fixed pump
                                        # of this flow whose relief valve holds `supply` (it passes the
                                        # whole flow there, none 2 bar below): the supply line's pressure
                                        # falls while the valve asks for more
    supply_volume: float = 1.0e-3       # m^3; oil between the pump and the valve (with a pump_flow)
    laminar_below: float = 1.0e5        # Pa
    stop_stiffness: float = 2.0e7       # N/m; the piston's end stops at 0 and the full stroke (a full
                                        # bore force pushes about 1.4 mm in), damped at 0.7 of critical
    amp_gain: float = 0.08              # A/V
    max_current: float = 0.8            # A
    coil_tau: float = 0.008             # s
    spool_hz: float = 15.0              # Hz
    spool_zeta: float = 0.8             # -
    spool_gain: float = 1.25            # 1/A
    sensor_a: float = 0.05              # m/V (position = a * volts + b)
    sensor_b: float = 0.0               # m
    sensor_noise: float = 1e-3          # V
    sensor_bits: int = 12               # over 0..10 V
    boom: Boom | None = None            # the cylinder raises this boom (q in rad; load_mass at its tip,
                                        # slide_mass, gravity_along and stroke unused), else a slide


def _edge(k: float, opening: float, dp: float, dp_lam: float) -> float:
    """Orifice flow (m^3/s): turbulent sqrt law, linear below dp_lam with matching flow at dp_lam."""
    if opening <= 0.0:
        return 0.0
    if abs(dp) >= dp_lam:
        return k * opening * math.copysign(math.sqrt(abs(dp)), dp)
    return k * opening * dp / math.sqrt(dp_lam)


def mechanics(rig: Rig):
    """(piston(q) -> (x (m), dx/dq), inertia (kg or kg m^2), gravity(q) -> generalised force along +q)."""
    b = rig.boom
    if b is None:
        m = rig.slide_mass + rig.load_mass
        return (lambda q: (q, 1.0)), m, (lambda q: m * G * rig.gravity_along)
    l0 = b.length(b.lower)[0]
    inertia = b.inertia + b.mass * b.com ** 2 + rig.load_mass * b.tip ** 2
    moment = (b.mass * b.com + rig.load_mass * b.tip) * G

    def piston(q):
        length, arm = b.length(q)
        return length - l0, arm
    return piston, inertia, (lambda q: -moment * math.cos(q))


def stroke(rig: Rig) -> float:
    b = rig.boom
    return rig.stroke if b is None else b.length(b.upper)[0] - b.length(b.lower)[0]


def rhs(rig: Rig, u: float):
    aa = math.pi / 4 * rig.bore ** 2
    ab = aa - math.pi / 4 * rig.rod ** 2
    piston, inertia, gravity = mechanics(rig)
    full = stroke(rig)
    k = rig.rated_flow / math.sqrt(rig.rated_drop)
    i_ref = max(-rig.max_current, min(rig.max_current, rig.amp_gain * u))
    w = 2 * math.pi * rig.spool_hz

    def f(_t, y):
        q, v, pa, pb, i, x, xd = y[:7]
        ps = y[7] if rig.pump_flow > 0.0 else rig.supply
        xp, arm = piston(q)
        vp = arm * v                                      # rod speed, m/s
        xs = x + rig.null_bias
        op_pos = max(xs - rig.overlap, 0.0)
        op_neg = max(-xs - rig.overlap, 0.0)
        kn = k * rig.negative_flow_ratio
        leak = rig.piston_leakage * (pa - pb)
        qpa, qpb = _edge(k, op_pos, ps - pa, rig.laminar_below), _edge(kn, op_neg, ps - pb, rig.laminar_below)
        qa = qpa - _edge(kn, op_neg, pa - rig.tank, rig.laminar_below) - leak
        qb = qpb - _edge(k, op_pos, pb - rig.tank, rig.laminar_below) + leak
        ca = (rig.dead_a + aa * xp) / rig.oil_bulk + rig.hose_volume / rig.hose_bulk
        cb = (rig.dead_b + ab * (full - xp)) / rig.oil_bulk + rig.hose_volume / rig.hose_bulk
        force = pa * aa - pb * ab - rig.viscous * vp - rig.coulomb * math.tanh(vp / 1e-3)
        if xp < 0.0 or xp > full:         # in an end stop: a unilateral spring-damper, pushing out only
            depth, speed = (-xp, -vp) if xp < 0.0 else (xp - full, vp)
            damping = 1.4 * math.sqrt(rig.stop_stiffness * inertia / arm ** 2)
            push = max(rig.stop_stiffness * depth + damping * speed, 0.0)
            force += push if xp < 0.0 else -push
        dy = [v, (force * arm + gravity(q)) / inertia, (qa - aa * vp) / ca, (qb + ab * vp) / cb,
              (i_ref - i) / rig.coil_tau, xd, w * w * (rig.spool_gain * i - x) - 2 * rig.spool_zeta * w * xd]
        if rig.pump_flow > 0.0:     # the relief opens over the 2 bar below the supply setting
            relief = rig.pump_flow * max(ps - rig.supply + 2e5, 0.0) / 2e5
            dy.append((rig.pump_flow - relief - qpa - qpb) * rig.oil_bulk / rig.supply_volume)
        return dy
    return f


def reference_profile(kind: str, rng, duration: float, references=(0.12, 0.38)):
    """The set-point (m or rad) as a function of time (s), within ``references``: ``steps`` held 1.5-4 s,
    ``ramps`` (an operator's moves: to a new target at 0.2-1 x the range per second, then held 0.5-3 s),
    or ``sine`` (two sines of 0.05-0.4 Hz about the range's middle, a tracking test)."""
    lo, hi = references
    if kind == "steps":
        starts, values, t = [], [], 0.0
        while t < duration:
            starts.append(t)
            values.append(rng.uniform(lo, hi))
            t += rng.uniform(1.5, 4.0)
        return lambda t: values[int(np.searchsorted(starts, t, side="right")) - 1]
    if kind == "sine":
        f = rng.uniform(0.05, 0.4, 2)
        ph = rng.uniform(0.0, 2 * math.pi, 2)
        mid, amp = 0.5 * (lo + hi), 0.25 * (hi - lo)
        return lambda t: mid + amp * (math.sin(2 * math.pi * f[0] * t + ph[0]) + math.sin(2 * math.pi * f[1] * t + ph[1]))
    if kind != "ramps":
        raise ValueError(f"reference {kind!r}: steps, ramps or sine")
    knots_t, knots_r, t = [0.0], [rng.uniform(lo, hi)], 0.0
    while t < duration:
        t += rng.uniform(0.5, 3.0)                              # the hold
        knots_t.append(t)
        knots_r.append(knots_r[-1])
        r = rng.uniform(lo, hi)
        t += abs(r - knots_r[-1]) / (rng.uniform(0.2, 1.0) * (hi - lo))
        knots_t.append(t)
        knots_r.append(r)
    return lambda t: float(np.interp(t, knots_t, knots_r))


def closed_loop_log(rig: Rig, *, seed: int, duration: float = 60.0, rate: float = 50.0, q0: float = 0.23,
                    kp: float = 100.0, ki: float = 0.0, jitter: float = 0.1, references=(0.12, 0.38),
                    reference: str = "steps", control_every: int = 1) -> np.ndarray:
    """A P or PI controller (kp in V/m or V/rad, ki in V/(m s) or V/(rad s); command clipped to +-10 V, the
    integral held while the command saturates in its direction) tracking a ``reference`` profile within
    ``references`` (m or rad; `reference_profile`), run at ``control_every`` x ``rate``; returns the logged
    rows (time s, sensor V, command V), every ``control_every``-th of the controller's (a logger slower
    than the loop)."""
    rng = np.random.default_rng(seed)
    setpoint = reference_profile(reference, rng, duration, references)
    integral = 0.0
    aa = math.pi / 4 * rig.bore ** 2
    ab = aa - math.pi / 4 * rig.rod ** 2
    piston, _, gravity = mechanics(rig)
    pa0 = 0.5 * rig.supply                                   # at rest, holding the load: (pa aa - pb ab) arm = -gravity
    pb0 = (pa0 * aa + gravity(q0) / piston(q0)[1]) / ab
    y = np.array([q0, 0.0, pa0, pb0, 0.0, 0.0, 0.0] + ([rig.supply] if rig.pump_flow > 0.0 else []))
    atol = [1e-9, 1e-8, 1.0, 1.0, 1e-7, 1e-7, 1e-5] + ([1.0] if rig.pump_flow > 0.0 else [])
    lsb = 10.0 / 2 ** rig.sensor_bits
    rows, t = [], 0.0
    while t < duration:
        volts = (y[0] - rig.sensor_b) / rig.sensor_a + rng.normal(0.0, rig.sensor_noise)
        volts = float(np.clip(np.round(volts / lsb) * lsb, 0.0, 10.0))
        error = setpoint(t) - (rig.sensor_a * volts + rig.sensor_b)
        raw = kp * error + ki * integral
        u = float(np.clip(raw, -10.0, 10.0))
        rows.append((t, volts, round(u, 3)))
        dt = (1.0 + rng.uniform(-jitter, jitter)) / (rate * control_every)
        if raw == u or (raw > u) != (error > 0):               # anti-windup: no integrating into the clip
            integral += error * dt
        # the valve sees each command from its time + command_delay on: split the interval where one
        # delayed command gives way to the next
        recent = rows[-64 * control_every:]
        seen_t = np.array([r[0] for r in recent]) + rig.command_delay
        seen_u = [r[2] for r in recent]
        cuts = [t] + [c for c in seen_t if t < c < t + dt] + [t + dt]
        for a, b in zip(cuts[:-1], cuts[1:]):
            n = int(np.searchsorted(seen_t, a, side="right")) - 1
            u_valve = seen_u[n] if n >= 0 else 0.0
            sol = solve_ivp(rhs(rig, u_valve), (a, b), y, method="LSODA", rtol=1e-7, atol=atol)
            if not sol.success:
                raise RuntimeError(f"textbook cylinder: {sol.message} at t = {a:.3f} s")
            y = sol.y[:, -1]
        t += dt
    return np.array(rows)[::control_every]


SPOOL_GAIN_PER_VOLT = 0.08 * 1.25        # templates: amplifier A/V x spool 1/A: stroke fraction per volt


@dataclass(frozen=True)
class Bench:
    """A template rig as the textbook describes it: the template and its --set, the joint, the
    template's nominal rig in this module's terms, a truth's values off it, and how its P loop runs."""
    template: str
    rig_set: tuple
    joint: str
    nominal: dict
    off: dict
    loop: dict
    tolerance: float                      # m or rad: the replay's RMS limit
    moved: float                          # m or rad: the replay's motion (std) at least


BOOM = dict(boom=Boom(), load_mass=40.0, rod=0.03, dead_b=2.51327e-5, rated_flow=3.3e-4, viscous=5000.0,
            sensor_a=0.5236, sensor_b=-2.618)
BENCHES = {
    "hanging": Bench("cylinder", ("incline_deg=-90",), "lift", dict(gravity_along=1.0),
                     dict(rated_flow=2.4e-4, supply=1.26e7, load_mass=120.0, viscous=2600.0), dict(q0=0.23), 1e-3, 0.03),
    "vertical": Bench("cylinder", ("orientation=vertical",), "lift", dict(gravity_along=-1.0),
                      dict(rated_flow=2.4e-4, supply=1.26e7, load_mass=120.0, viscous=2600.0), dict(q0=0.23), 1e-3, 0.03),
    "boom": Bench("boom", (), "boom", BOOM, dict(rated_flow=3.96e-4, supply=1.26e7, load_mass=50.0, viscous=6500.0),
                  dict(q0=0.25, kp=45.0, references=(0.02, 0.68)), 1e-3, 0.08),
}
