"""The command table: valve voltages per joint from REST, CAN and the viewer, and the E-STOP latch.

Commands are validated against the mirror's command ranges, then written into the shared command
table under its seqlock (one writer at a time in this process); the engine applies them every tick.
While the engine is down or the plant has diverged, commands are refused: nothing may pretend a
valve moved."""

from __future__ import annotations

import threading
import time

import numpy as np

from ..engine import shared as S
from .config import ServiceError


class CommandTable:
    def __init__(self, block: S.SharedBlock, mirror, supervisor):
        self.block = block
        self.mirror = mirror
        self.supervisor = supervisor
        self._lock = threading.Lock()
        self._row = np.zeros(S.C_N)

    @property
    def joint_index(self) -> dict[str, int]:
        return {j: a for a, j in enumerate(self.mirror.spec.joint_names)}

    def accepting(self) -> None:
        """Raise unless commands can act now: 503 while the engine is down, 409 while diverged."""
        if not self.supervisor.running:
            raise ServiceError(f"commands refused: {self.supervisor.down_message()}", 503)
        if self.block.state[S.S_DIVERGED]:
            raise ServiceError("commands refused: the plant diverged (fault 'diverged'); valves are held neutral "
                               "until POST /api/v1/reset", 409)

    def validate(self, voltages: dict[str, float]) -> dict[int, float]:
        spec = self.mirror.spec
        index = self.joint_index
        out = {}
        for j, v in voltages.items():
            if j not in index:
                raise ServiceError(f"unknown joint {j!r}; joints: {', '.join(spec.joint_names)}")
            if not np.isfinite(v):
                raise ServiceError(f"joint {j}: voltage must be a finite number")
            lo, hi = spec.joint(j).command_range
            if not lo <= v <= hi:
                raise ServiceError(f"joint {j}: {v:g} V is outside the command range [{lo:g}, {hi:g}] V")
            out[index[j]] = float(v)
        return out

    def set(self, voltages: dict[str, float], source: float = S.SRC_REST) -> dict[str, float]:
        """Validate and apply; returns what was applied by joint name."""
        checked = self.validate(voltages)
        self.accepting()
        self.write(checked, source)
        names = self.mirror.spec.joint_names
        return {names[a]: v for a, v in checked.items()}

    def write(self, by_index: dict[int, float], source: float) -> None:
        """Write already validated commands (the CAN bridge calls this directly)."""
        if not by_index:
            return
        now = time.monotonic()
        t_sim = float(self.block.state[S.S_TIME])
        idx = np.fromiter(by_index.keys(), dtype=np.int64, count=len(by_index))
        rows = np.empty((len(by_index), S.C_N))
        rows[:, S.C_VOLT] = np.fromiter(by_index.values(), dtype=float, count=len(by_index))
        rows[:, S.C_SOURCE] = source
        rows[:, S.C_T_WALL] = now
        rows[:, S.C_T_SIM] = t_sim
        with self._lock:
            self.block.write_commands(idx, rows)

    def zero_all(self, source: float = S.SRC_NONE) -> None:
        self.write({a: 0.0 for a in range(self.block.layout.n_act)}, source)

    def voltages(self) -> dict[str, float]:
        cmd = self.block.commands()
        return {j: float(cmd[a, S.C_VOLT]) for a, j in enumerate(self.mirror.spec.joint_names)}

    def neutral(self, joints=None, source: float = S.SRC_REST) -> None:
        names = self.mirror.spec.joint_names if joints is None else joints
        self.set({j: 0.0 for j in names}, source)

    def set_estop(self, on: bool) -> None:
        """E-STOP: every valve neutral until released; the commands are also zeroed. Always accepted
        (also while the engine is down: the latch holds for when it comes back)."""
        self.block.estop[0] = 1.0 if on else 0.0
        if on:
            self.zero_all(S.SRC_REST)

    @property
    def estopped(self) -> bool:
        return bool(self.block.estop[0])
