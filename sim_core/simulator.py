"""Simulator: advances a Context with zero-order-hold commands, one compiled call per batch."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from .dynamics.compiled_arg import compiled_arg
from .kernel import layout as L
from .kernel.compose import kernel
from .kernel.workspace import STALE, make_workspace, tree_arrays


class SimulationError(RuntimeError):
    """The state would have become non-finite, or the delay line overflowed; the state is unchanged."""


@dataclass
class Trajectory:
    """Outputs on the input time grid. Row 0 is the initial state; ``u[k]`` acts on [t_k, t_k+1)."""

    time: np.ndarray            # [N] s
    u: np.ndarray               # [N, n_act] commanded voltage (V)
    q: np.ndarray               # [N, n_dof] true joint angles (rad)
    qd: np.ndarray              # [N, n_dof] true joint velocities (rad/s)
    act: np.ndarray             # [N, n_act, YA_N] per-actuator outputs (see kernel.layout YA_*)
    joint_names: list[str]
    dof_names: list[str]
    sensed: list[bool]

    def column(self, joint: str, field: int) -> np.ndarray:
        return self.act[:, self.joint_names.index(joint), field]

    def angle(self, joint: str) -> np.ndarray:
        """Measured angle of a sensed joint (rad), through the sensor model."""
        return self.column(joint, L.YA_ANGLE)

    def true_angle(self, joint: str, spec) -> np.ndarray:
        return self.q[:, spec.tree.index(spec.joint(joint).dof)]

    def pressure(self, joint: str, chamber: str) -> np.ndarray:
        return self.column(joint, L.YA_P_A if chamber == "a" else L.YA_P_B)

    def dataset_columns(self) -> dict[str, np.ndarray]:
        """The dataset CSV columns: time, u_<joint>, q_<joint> (sensed), p_<joint>_a/_b."""
        cols: dict[str, np.ndarray] = {"time": self.time}
        for a, j in enumerate(self.joint_names):
            cols[f"u_{j}"] = self.u[:, a]
        for a, j in enumerate(self.joint_names):
            if self.sensed[a]:
                cols[f"q_{j}"] = self.act[:, a, L.YA_ANGLE]
        for a, j in enumerate(self.joint_names):
            cols[f"p_{j}_a"] = self.act[:, a, L.YA_P_A]
            cols[f"p_{j}_b"] = self.act[:, a, L.YA_P_B]
        return cols


@dataclass(frozen=True)
class SimulatorState:
    """What a later call of the kernel reads that an earlier one wrote: the context's state (XQ, XS,
    XG, the command history HT/HU, the noise generator), its actuator parameters (AP: the command
    chain's discretisation is cached there per substep) and the workspace (the mass matrix, bias and
    factor kept between substeps). Restored into a simulator of the same model, the next call gives
    the same bits as one call over both spans."""

    context: tuple[np.ndarray, ...]
    workspace: tuple[np.ndarray, ...]


_STATE = ("XQ", "XS", "XG", "HT", "HU", "rng", "AP")


class Simulator:
    def __init__(self, context):
        self.context = context
        ctx = context
        n, na = ctx.spec.tree.n, len(ctx.spec.joints)
        self._kernel = kernel()
        self._ws = make_workspace(n, na)
        self._factored_for = ctx.lowered        # the parameters the workspace's factor was made for
        self._tree_made = None
        # one-step buffers for the real-time loop (no allocation per tick)
        self._dt1 = np.zeros(1)
        self._u1 = np.zeros((1, na))
        self._yt1 = np.zeros(1)
        self._yq1 = np.zeros((1, n))
        self._yqd1 = np.zeros((1, n))
        self._ya1 = np.zeros((1, na, L.YA_N))

    def _tree(self):
        """The tree's arrays for the kernel, rebuilt when the context's tree or lowering is replaced
        (a parameter set), not on every call."""
        c = self.context
        made = self._tree_made
        if made is None or made[0] is not c.spec.tree or made[1] is not c.lowered:
            self._tree_made = made = (c.spec.tree, c.lowered, tree_arrays(c.spec.tree, c.lowered))
        return made[2]

    def _call(self, dts, U, Yt, Yq, Yqd, Ya) -> int:
        c = self.context
        if self._factored_for is not c.lowered:
            # new parameters (a lock, a fault cleared) since the last call: the factor is renewed
            self._ws.Dfac[:] = STALE
            self._factored_for = c.lowered
        k = self._kernel.advance(dts, U, self._tree(), c.DP, c.AP, c.GP, c.XQ, c.XS, c.XG, c.HT, c.HU, c.rng,
                                 self._ws, Yt, Yq, Yqd, Ya)
        err = int(c.XG[L.XG_ERROR])
        if err:
            c.XG[L.XG_ERROR] = 0.0
            what = {L.ERR_NAN: "the state became non-finite (NaN/inf); the step was rejected",
                    L.ERR_DELAY_OVERRUN: "the delay line overflowed (command rate too high for the delay)"}.get(err, str(err))
            raise SimulationError(f"t = {c.time:.6f} s: {what}")
        return k

    def save(self) -> SimulatorState:
        """A copy of everything the next call continues from (:class:`SimulatorState`)."""
        c = self.context
        return SimulatorState(tuple(getattr(c, k).copy() for k in _STATE), tuple(a.copy() for a in self._ws))

    def restore(self, state: SimulatorState) -> None:
        """Continue from ``state`` (saved from a simulator of the same model: see :meth:`fingerprint`)."""
        c = self.context
        for k, a in zip(_STATE, state.context):
            getattr(c, k)[...] = a
        for dst, a in zip(self._ws, state.workspace):
            dst[...] = a
        self._factored_for = c.lowered

    def fingerprint(self) -> bytes:
        """A digest of the model as the kernel sees it (the lowered parameters and tree) and of the
        current state: two simulators with the same fingerprint run the same bits on the same input."""
        c = self.context
        h = hashlib.blake2b(digest_size=16)
        for a in (c.DP, c.AP, c.GP, *(getattr(c, k) for k in _STATE[:-1]), *(a for a in self._tree() if a is not None)):
            h.update(str(a.shape).encode())
            h.update(np.ascontiguousarray(a).tobytes())
        return h.digest()

    def step(self, u, dt: float) -> np.ndarray:
        """Advance one output step with command ``u`` (V per actuated joint) held for ``dt`` s.
        Returns the per-actuator output row (YA_* columns), a view reused on the next call."""
        self._dt1[0] = dt
        self._u1[0, :] = u
        self._call(self._dt1, self._u1, self._yt1, self._yq1, self._yqd1, self._ya1)
        return self._ya1[0]

    def sample(self, u=None) -> np.ndarray:
        """Sensor/output row for the current state without advancing (draws sensor noise)."""
        c = self.context
        na = len(c.spec.joints)
        row = np.zeros((na, L.YA_N))
        self._kernel.sample_sensors(c.AP, c.XQ[0], c.XS, c.rng, row, np.zeros(na) if u is None else compiled_arg(u, float))
        return row

    def run(self, times, U, first_row: np.ndarray | None = None) -> Trajectory:
        """Simulate on the time grid ``times`` [N] with commands ``U`` [N, n_act] (ZOH). ``first_row``:
        row 0's outputs where the state continues a run that already sampled them (a restored
        :class:`SimulatorState`): no sensor noise is drawn for them again."""
        c = self.context
        times = np.asarray(times, dtype=float)
        U = compiled_arg(U, dtype=float)
        N = times.shape[0]
        n, na = c.spec.tree.n, len(c.spec.joints)
        if U.shape != (N, na):
            raise ValueError(f"U must be [{N}, {na}], got {list(U.shape)}")
        dts = np.ascontiguousarray(np.diff(times))
        if np.any(dts <= 0):
            raise ValueError("time must increase strictly")
        q = np.zeros((N, n))
        qd = np.zeros((N, n))
        act = np.zeros((N, na, L.YA_N))
        yt = np.zeros(N)
        yt[0] = c.time
        q[0], qd[0] = c.XQ[0], c.XQ[1]
        act[0] = self.sample(U[0]) if first_row is None else first_row
        if N > 1:
            self._call(dts, U[:-1], yt[1:], q[1:], qd[1:], act[1:])
        act[:, :, L.YA_U] = U
        return Trajectory(times.copy(), U.copy(), q, qd, act, list(c.spec.joint_names),
                          list(c.spec.tree.dof_names), [j.sensed for j in c.spec.joints])
