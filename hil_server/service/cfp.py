"""The CompactFieldPoint view: the same I/O as the per-joint commands and state, addressed by
module/channel (two analog outputs per joint, amplifier A and B; one analog input per sensed joint,
its potentiometer)."""

from __future__ import annotations

import numpy as np

from ..channels import ChannelMap
from ..engine import shared as S
from .config import ServiceError


class CfpView:
    def __init__(self, channels: ChannelMap, commands, documents):
        self.channels = channels
        self.commands = commands
        self.documents = documents

    def channel(self, module: str, channel: str):
        try:
            return self.channels.get(module, channel)
        except KeyError as exc:
            raise ServiceError(str(exc.args[0]), 404) from None

    def value(self, ch, snap=None, cmd=None) -> float:
        if ch.role == "potentiometer":
            snap = self.documents.snapshot() if snap is None else snap
            a = self.commands.joint_index[ch.joint]
            return float(self.documents.actuators(snap)[a, S.A_SENS_V])
        u = (self.commands.voltages() if cmd is None else cmd)[ch.joint]
        return max(u, 0.0) if ch.role == "amplifier_a" else max(-u, 0.0)

    def describe(self, module: str, channel: str) -> dict:
        ch = self.channel(module, channel)
        return {"module": module, "channel": channel, "joint": ch.joint, "role": ch.role, "direction": ch.direction,
                "value": self.value(ch)}

    def modules(self) -> dict:
        snap = self.documents.snapshot()
        cmd = self.commands.voltages()
        return {m: [{"channel": c.channel, "name": c.name, "joint": c.joint, "role": c.role, "direction": c.direction,
                     "value": self.value(c, snap, cmd)} for c in chans]
                for m, chans in self.channels.modules().items()}

    def write(self, module: str, channel: str, value: float) -> dict:
        """Write an analog output as a LabVIEW VI would: AO A = v sets the joint's command to v - (AO B)."""
        ch = self.channel(module, channel)
        if ch.direction == "input":
            raise ServiceError(f"{ch.name} is an analog input (potentiometer of {ch.joint}); it cannot be written")
        lo, hi = self.commands.mirror.spec.joint(ch.joint).command_range
        top = hi if ch.role == "amplifier_a" else -lo
        if not (np.isfinite(value) and 0.0 <= value <= top):
            raise ServiceError(f"{ch.name}: {value} V is outside the amplifier input range [0, {top:g}] V")
        u = self.commands.voltages()[ch.joint]
        a_val, b_val = max(u, 0.0), max(-u, 0.0)
        if ch.role == "amplifier_a":
            a_val = value
        else:
            b_val = value
        self.commands.set({ch.joint: float(np.clip(a_val - b_val, lo, hi))})
        return {"module": module, "channel": channel, "joint": ch.joint, "value": value}
