"""The same plant-client interface on the in-process simulator (``sim_core``), no CAN: "simulated".

The emulator's engine runs exactly this plant (``Plant(spec).create_context(seed)`` and
``Simulator.step(u, 1/rate)`` once per tick), so a controller run here and over CAN in lockstep
differs only by what the CAN frames do to the numbers: 1 mV command resolution, 1e-4 rad angles,
1 kPa pressures, 0.01 spool. With ``quantize=True`` this client passes every command and reading
through the same DBC encoding (and the bridge's clipping) as the CAN path, and the two runs become
identical; that is how the tests show quantisation is the only difference.
"""

from __future__ import annotations

from pathlib import Path

import cantools
import numpy as np

from sim_core.kernel import layout as KL
from sim_core.model.spec import RobotSpec, load_robot
from sim_core.params_file import apply_params_file
from sim_core.plant import Plant
from sim_core.simulator import Simulator

from .plant import STATUS_NOT_SENSED, Observation, PlantClient


def configured_spec(robot: str, params: str | Path | None = None) -> RobotSpec:
    """The robot's spec with a parameter/effect file applied, as ``hydrohil serve --params`` does."""
    spec = load_robot(robot)
    if params:
        apply_params_file(spec, params)
    return spec


class LocalPlant(PlantClient):
    """In-process plant. ``tick_s``: simulator output step (s); ``ticks``: steps per control period."""

    def __init__(self, robot: str, *, params: str | Path | None = None, spec: RobotSpec | None = None, seed: int = 1,
                 tick_s: float = 1e-3, ticks: int = 1, quantize: bool = False, dbc: str | Path | None = None):
        self.spec = spec or configured_spec(robot, params)
        self.plant = Plant(self.spec)
        self.ctx = self.plant.create_context(seed=seed)
        self.sim = Simulator(self.ctx)
        self.joints = list(self.spec.joint_names)
        self.tick_s = float(tick_s)
        self.ticks = int(ticks)
        self.dt = self.tick_s * self.ticks
        na = len(self.joints)
        self._range = np.array([self.spec.joint(j).command_range for j in self.joints])
        self._sensed = np.array([self.spec.joint(j).sensed for j in self.joints])
        self._dof = np.array([self.spec.tree.index(self.spec.joint(j).dof) for j in self.joints])
        self._u = np.zeros(na)
        self.quantize = quantize
        if quantize:
            from .plant_can import default_dbc

            db = cantools.database.load_file(str(dbc or default_dbc(self.spec.name)))
            self._qcmd = [db.get_message_by_name(f"ValveCommand_{j}") for j in self.joints]
            self._qfb = [db.get_message_by_name(f"JointFeedback_{j}") for j in self.joints]
            self._qpr = [db.get_message_by_name(f"JointPressure_{j}") for j in self.joints]

    def _roundtrip(self, m, values: dict) -> dict:
        return m.decode(m.encode(values, scaling=True, strict=False), decode_choices=False)

    def _observe(self) -> Observation:
        XS = self.ctx.XS
        angle = np.where(self._sensed, XS[:, KL.XS_SENS_ANGLE], np.nan)
        vel = self.ctx.XQ[1, self._dof].copy()
        pa = XS[:, KL.XS_P_A].copy()
        pb = XS[:, KL.XS_P_B].copy()
        sp = XS[:, KL.XS_SPOOL_X].copy()
        ua = self._u.copy()
        status = np.where(self._sensed, 0, STATUS_NOT_SENSED).astype(int)
        if self.quantize:   # exactly what the bridge sends and cantools decodes (hil_server/can/bridge.py)
            for a in range(len(self.joints)):
                lo, hi = self._range[a]
                v = float(np.clip(vel[a], -32.7, 32.7))
                if self._sensed[a]:
                    fb = self._roundtrip(self._qfb[a], {"angle": float(np.clip(angle[a], -3.2767, 3.2767)),
                                                        "sensor_voltage": float(np.clip(XS[a, KL.XS_SENS_V], 0.0, 13.1)),
                                                        "velocity": v, "status": 0, "counter": 0})
                    angle[a] = fb["angle"]
                else:
                    fb = self._roundtrip(self._qfb[a], {"angle": 0.0, "sensor_voltage": 0.0, "velocity": v,
                                                        "status": 0, "counter": 0})
                vel[a] = fb["velocity"]
                pr = self._roundtrip(self._qpr[a], {"pressure_a": float(np.clip(pa[a], 0.0, 65.5e6)),
                                                    "pressure_b": float(np.clip(pb[a], 0.0, 65.5e6)),
                                                    "command_voltage": float(np.clip(ua[a], lo, hi)),
                                                    "spool": float(np.clip(sp[a], -1.28, 1.27)), "counter": 0})
                pa[a], pb[a], ua[a], sp[a] = pr["pressure_a"], pr["pressure_b"], pr["command_voltage"], pr["spool"]
        return Observation(self.ctx.time, angle, vel, pa, pb, ua, sp, status)

    def _set_command(self, u) -> None:
        u = np.asarray(u, dtype=float)
        if u.shape != self._u.shape:
            raise ValueError(f"command must have {len(self.joints)} voltages ({', '.join(self.joints)}), got shape {u.shape}")
        u = np.where(np.isfinite(u), np.clip(u, self._range[:, 0], self._range[:, 1]), 0.0)
        if self.quantize:
            u = np.array([self._roundtrip(m, {"voltage": float(v), "counter": 0})["voltage"] for m, v in zip(self._qcmd, u)])
        self._u[:] = u

    def start(self) -> Observation:
        """First observation after one tick with every valve neutral (as the first SYNC after a reset)."""
        self._set_command(np.zeros(len(self.joints)))
        self.sim.step(self._u, self.tick_s)
        return self._observe()

    def exchange(self, u) -> Observation:
        self._set_command(u)
        for _ in range(self.ticks):
            self.sim.step(self._u, self.tick_s)
        return self._observe()
