"""A fixed-size history of every joint's command and angle, for the panel's live plots."""

from __future__ import annotations

import numpy as np

CHANNELS = ("requested_voltage", "command_voltage", "angle", "true_angle")


class History:
    """Ring buffer of plant time and, per joint, the :data:`CHANNELS`; ``add`` one state document."""

    def __init__(self, joints: list[str], dofs: list[str], capacity: int):
        self.joints = list(joints)
        self.dofs = list(dofs)
        self.capacity = int(capacity)
        self.t = np.zeros(self.capacity)
        self.data = np.zeros((len(self.joints), len(CHANNELS), self.capacity))
        self.n = 0          # samples written in total
        self._last_t = None

    def add(self, state: dict) -> bool:
        """Append a sample if plant time moved on (a reset, where it goes back, starts afresh)."""
        t = float(state.get("time", 0.0))
        if self._last_t is not None:
            if t == self._last_t:
                return False
            if t < self._last_t:
                self.n = 0
        self._last_t = t
        k = self.n % self.capacity
        self.t[k] = t
        joints, pose = state.get("joints", {}), state.get("pose", {})
        for a, (j, dof) in enumerate(zip(self.joints, self.dofs)):
            js = joints.get(j, {})
            self.data[a, 0, k] = js.get("requested_voltage", np.nan)
            self.data[a, 1, k] = js.get("command_voltage", np.nan)
            self.data[a, 2, k] = js.get("angle", np.nan)
            self.data[a, 3, k] = pose.get(dof, np.nan)
        self.n += 1
        return True

    def series(self, joint: str) -> tuple[np.ndarray, np.ndarray]:
        """(time [m], values [channels, m]) of one joint, oldest first."""
        a = self.joints.index(joint)
        m = min(self.n, self.capacity)
        if self.n <= self.capacity:
            idx = np.arange(m)
        else:
            idx = (np.arange(m) + self.n) % self.capacity
        return self.t[idx].copy(), self.data[a][:, idx].copy()
