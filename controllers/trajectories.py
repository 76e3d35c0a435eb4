"""Reference trajectories: joint sinusoid, operator Cartesian velocity commands, target sequences.

Each returns the desired value and its time derivative at time ``t`` (s), SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Sinusoid:
    """q_d(t) = q0 + A (1 - cos(2 pi t / T)): a sinusoidal angle command about q0 + A that starts at
    rest at q0 (no velocity step at t = 0). ``amplitude`` A (rad), ``period`` T (s)."""

    q0: float
    amplitude: float
    period: float

    def __call__(self, t: float) -> tuple[float, float]:
        w = 2.0 * math.pi / self.period
        return self.q0 + self.amplitude * (1.0 - math.cos(w * t)), self.amplitude * w * math.sin(w * t)


@dataclass
class VelocityStroke:
    """One joystick stroke of the operator: end-point velocity v(t) = d * (pi / 2T) sin(pi (t - t0) / T)
    for t0 <= t <= t0 + T, which moves the end point by ``displacement`` d (m) with a smooth start/stop."""

    t0: float                       # s
    duration: float                 # s
    displacement: tuple             # m (x, y, z)

    def velocity(self, t: float) -> np.ndarray:
        tau = (t - self.t0) / self.duration
        if not 0.0 <= tau <= 1.0:
            return np.zeros(3)
        return np.asarray(self.displacement, dtype=float) * (0.5 * math.pi / self.duration) * math.sin(math.pi * tau)


class OperatorCommand:
    """The operator's Cartesian velocity command, a sum of overlapping strokes (m/s). The controller
    integrates it to the commanded path, as the paper's joystick interface does (Sec. VI)."""

    def __init__(self, strokes: list[VelocityStroke]):
        self.strokes = list(strokes)
        self.duration = max(s.t0 + s.duration for s in self.strokes)

    def velocity(self, t: float) -> np.ndarray:
        v = np.zeros(3)
        for s in self.strokes:
            v += s.velocity(t)
        return v

    def path(self, p0, dt: float, t_end: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Integrated path (trapezoidal) on a grid of step ``dt``: times [N], positions [N, 3] (m)."""
        t_end = self.duration if t_end is None else t_end
        n = int(round(t_end / dt)) + 1
        ts = np.arange(n) * dt
        vs = np.array([self.velocity(t) for t in ts])
        ps = np.empty((n, 3))
        ps[0] = p0
        ps[1:] = np.asarray(p0, float) + np.cumsum(0.5 * (vs[1:] + vs[:-1]) * dt, axis=0)
        return ts, ps


def path_length(points: np.ndarray) -> float:
    """Arc length (m) of a polyline [N, 3]."""
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


@dataclass
class TargetSequence:
    """Point-to-point joint moves: from ``start`` to each target in turn with a quintic (minimum-jerk)
    transition of ``move_time`` s, then a hold of ``hold_time`` s. Arrays over joints (rad)."""

    start: np.ndarray
    targets: list                   # [n_targets][n_joints] rad
    move_time: float
    hold_time: float

    @property
    def duration(self) -> float:
        return len(self.targets) * (self.move_time + self.hold_time)

    def segment(self, t: float) -> int:
        return min(int(t // (self.move_time + self.hold_time)), len(self.targets) - 1)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        k = self.segment(t)
        a = np.asarray(self.start if k == 0 else self.targets[k - 1], float)
        b = np.asarray(self.targets[k], float)
        tau = (t - k * (self.move_time + self.hold_time)) / self.move_time
        if tau >= 1.0:
            return b.copy(), np.zeros_like(b)
        tau = max(tau, 0.0)
        s = tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
        ds = 30.0 * tau ** 2 * (1.0 - tau) ** 2 / self.move_time
        return a + (b - a) * s, (b - a) * ds
