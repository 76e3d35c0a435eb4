"""The CompactFieldPoint channel map: which module/channel carries which joint signal.

From the robot spec's ``[joints.<j>.cfp]`` tables. A joint has two analog outputs (amplifier A and
B: the LabVIEW adaptation puts a positive command on A and a negative one on B, unipolar 0..10 V)
and, when sensed, one analog input (its potentiometer voltage). The per-joint view and the
per-channel view are two readings of the same commands: writing AO A = v sets the joint's command
to v - (AO B), as the net solenoid current does.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Channel:
    module: str
    channel: str
    joint: str
    role: str          # amplifier_a | amplifier_b | potentiometer

    @property
    def direction(self) -> str:
        return "input" if self.role == "potentiometer" else "output"

    @property
    def name(self) -> str:
        return f"{self.module}/{self.channel}"


class ChannelMap:
    def __init__(self, spec):
        self.channels: dict[tuple[str, str], Channel] = {}
        for j in spec.joints:
            cfp = j.components["cfp"]
            for key, role in (("output_a", "amplifier_a"), ("output_b", "amplifier_b"), ("input", "potentiometer")):
                name = cfp[key]
                if not name:
                    continue
                module, _, channel = name.partition("/")
                if not channel:
                    raise ValueError(f"joints.{j.name}.cfp.{key}: {name!r} is not 'module/channel'")
                if (module, channel) in self.channels:
                    raise ValueError(f"cFP channel {name} is used twice")
                self.channels[(module, channel)] = Channel(module, channel, j.name, role)

    def get(self, module: str, channel: str) -> Channel:
        try:
            return self.channels[(module, channel)]
        except KeyError:
            raise KeyError(f"no cFP channel {module}/{channel}") from None

    def modules(self) -> dict[str, list[Channel]]:
        out: dict[str, list[Channel]] = {}
        for ch in sorted(self.channels.values(), key=lambda c: (c.module, c.channel)):
            out.setdefault(ch.module, []).append(ch)
        return out
