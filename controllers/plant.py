"""The plant-client interface shared by the CAN client and the in-process simulator client.

A controller sees the plant only through :class:`PlantClient`: ``start()`` gives the first
observation, then every ``exchange(u)`` applies the command voltages for one control period and
returns the observation at its end. The same controller code therefore runs over CAN against
``hydrohil serve`` ("emulated") and in-process against ``sim_core`` ("simulated").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# JointFeedback.status bits (see hil_server/can/dbc.py; duplicated here so that a controller needs
# nothing but the DBC file)
STATUS_WATCHDOG, STATUS_FAULT, STATUS_ESTOP, STATUS_NOT_SENSED = 1, 2, 4, 8


@dataclass
class Observation:
    """What a controller reads back after one control period (arrays over the actuated joints)."""

    t: float                 # s: plant time (lockstep, in-process) or wall time since start (realtime)
    angle: np.ndarray        # rad: calibrated sensor angle A*raw+B (noise, 16-bit quantisation); NaN if not sensed
    velocity: np.ndarray     # rad/s: the emulator's true joint velocity (for plots only; controllers differentiate angle)
    p_a: np.ndarray          # Pa: chamber A (cap side / motor port A) pressure
    p_b: np.ndarray          # Pa: chamber B pressure
    u_applied: np.ndarray    # V: command the plant applied (0 when the watchdog or e-stop holds the valve)
    spool: np.ndarray        # -: spool position, fraction of the metering stroke
    status: np.ndarray       # int: JointFeedback status bits (1 watchdog, 2 fault, 4 e-stop, 8 not sensed)


class PlantClient:
    """Interface; see :class:`controllers.plant_can.CanPlant` and :class:`controllers.plant_local.LocalPlant`."""

    joints: list[str]
    dt: float                # s: nominal control period

    def start(self) -> Observation:
        raise NotImplementedError

    def exchange(self, u) -> Observation:
        """Apply ``u`` (V per actuated joint) for one control period; return the observation at its end."""
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
