"""A rig HydroHIL's simulator did not make: a cylinder on a slide, written from the textbook.

The equations are Merritt's (Hydraulic Control Systems, 1967, ch. 3 and 5) for a single-rod cylinder
fed by a 4/3 proportional valve, written here from the meaning of the rig template's parameters (their
comments in robot.toml), with none of sim_core's code: its own state, its own orifice regularisation,
hose volumes lumped into the chambers, a tanh Coulomb friction, SciPy's LSODA between samples. A
logger and a P controller run on the jittered sample grid, as on a test bench, and the log is what
such a bench writes: `time (s), position (sensor volts, quantised), valve command (V)`.

A difference between this rig and the template that the diagnosis names is a finding about the rig;
a difference between the two codes that it names is a false alarm (or a bug in one of them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.integrate import solve_ivp

G = 9.80665  # m/s^2


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
    piston_leakage: float = 0.0         # m^3/(s Pa); laminar leakage across the piston, A to B
    command_delay: float = 0.0          # s; dead time between the controller's output and the amplifier
    laminar_below: float = 1.0e5        # Pa
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

    def with_(self, **kw) -> "Rig":
        return replace(self, **kw)


def _edge(k: float, opening: float, dp: float, dp_lam: float) -> float:
    """Orifice flow (m^3/s): turbulent sqrt law, linear below dp_lam with matching flow at dp_lam."""
    if opening <= 0.0:
        return 0.0
    if abs(dp) >= dp_lam:
        return k * opening * math.copysign(math.sqrt(abs(dp)), dp)
    return k * opening * dp / math.sqrt(dp_lam)


def rhs(rig: Rig, u: float):
    aa = math.pi / 4 * rig.bore ** 2
    ab = aa - math.pi / 4 * rig.rod ** 2
    m = rig.slide_mass + rig.load_mass
    k = rig.rated_flow / math.sqrt(rig.rated_drop)
    i_ref = max(-rig.max_current, min(rig.max_current, rig.amp_gain * u))
    w = 2 * math.pi * rig.spool_hz

    def f(_t, y):
        q, v, pa, pb, i, x, xd = y
        op_pos = max(x - rig.overlap, 0.0)
        op_neg = max(-x - rig.overlap, 0.0)
        kn = k * rig.negative_flow_ratio
        leak = rig.piston_leakage * (pa - pb)
        qa = _edge(k, op_pos, rig.supply - pa, rig.laminar_below) - _edge(kn, op_neg, pa - rig.tank, rig.laminar_below) - leak
        qb = _edge(kn, op_neg, rig.supply - pb, rig.laminar_below) - _edge(k, op_pos, pb - rig.tank, rig.laminar_below) + leak
        va = rig.dead_a + aa * q
        vb = rig.dead_b + ab * (rig.stroke - q)
        ca = va / rig.oil_bulk + rig.hose_volume / rig.hose_bulk
        cb = vb / rig.oil_bulk + rig.hose_volume / rig.hose_bulk
        force = pa * aa - pb * ab - rig.viscous * v - rig.coulomb * math.tanh(v / 1e-3) + m * G * rig.gravity_along
        return [v, force / m, (qa - aa * v) / ca, (qb + ab * v) / cb,
                (i_ref - i) / rig.coil_tau, xd, w * w * (rig.spool_gain * i - x) - 2 * rig.spool_zeta * w * xd]
    return f


def closed_loop_log(rig: Rig, *, seed: int, duration: float = 60.0, rate: float = 50.0, q0: float = 0.23,
                    kp: float = 100.0, jitter: float = 0.1, references=(0.12, 0.38), control_every: int = 1) -> np.ndarray:
    """A P controller (kp in V/m, command clipped to +-10 V) tracking set-point steps held 1.5-4 s within
    ``references`` (m), run at ``control_every`` x ``rate``; returns the logged rows (time s, sensor V,
    command V), every ``control_every``-th of the controller's (a logger slower than the loop)."""
    rng = np.random.default_rng(seed)
    steps_t, steps_r, t = [], [], 0.0
    while t < duration:
        steps_t.append(t)
        steps_r.append(rng.uniform(*references))
        t += rng.uniform(1.5, 4.0)
    aa = math.pi / 4 * rig.bore ** 2
    ab = aa - math.pi / 4 * rig.rod ** 2
    m = rig.slide_mass + rig.load_mass
    pa0 = 0.5 * rig.supply                                   # at rest, holding the load: pa aa - pb ab = -m g along
    pb0 = (pa0 * aa + m * G * rig.gravity_along) / ab
    y = np.array([q0, 0.0, pa0, pb0, 0.0, 0.0, 0.0])
    lsb = 10.0 / 2 ** rig.sensor_bits
    rows, t = [], 0.0
    while t < duration:
        volts = (y[0] - rig.sensor_b) / rig.sensor_a + rng.normal(0.0, rig.sensor_noise)
        volts = float(np.clip(np.round(volts / lsb) * lsb, 0.0, 10.0))
        ref = steps_r[int(np.searchsorted(steps_t, t, side="right")) - 1]
        u = float(np.clip(kp * (ref - (rig.sensor_a * volts + rig.sensor_b)), -10.0, 10.0))
        rows.append((t, volts, round(u, 3)))
        dt = (1.0 + rng.uniform(-jitter, jitter)) / (rate * control_every)
        # the valve sees each command from its time + command_delay on: split the interval where one
        # delayed command gives way to the next
        recent = rows[-64 * control_every:]
        seen_t = np.array([r[0] for r in recent]) + rig.command_delay
        seen_u = [r[2] for r in recent]
        cuts = [t] + [c for c in seen_t if t < c < t + dt] + [t + dt]
        for a, b in zip(cuts[:-1], cuts[1:]):
            n = int(np.searchsorted(seen_t, a, side="right")) - 1
            u_valve = seen_u[n] if n >= 0 else 0.0
            sol = solve_ivp(rhs(rig, u_valve), (a, b), y, method="LSODA", rtol=1e-7,
                            atol=[1e-9, 1e-8, 1.0, 1.0, 1e-7, 1e-7, 1e-5])
            if not sol.success:
                raise RuntimeError(f"textbook cylinder: {sol.message} at t = {a:.3f} s")
            y = sol.y[:, -1]
        t += dt
    return np.array(rows)[::control_every]
