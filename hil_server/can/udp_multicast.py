"""Transport ``udp_multicast[:GROUP][@PORT][,hop_limit=N]``: python-can's UDP multicast bus, a virtual
CAN bus between processes that needs neither kernel CAN nor a server of ours. A stock python-can
program joins it with ``can.Bus(interface="udp_multicast", channel=GROUP, port=PORT)``.

Two things python-can's bus does not do, done here:

* Its own frames come back to a sender (multicast loopback). Frames this bridge sends carry a
  per-process marker in the message's ``channel`` field and are dropped when they come back.
* It listens on every interface. By default (``hop_limit=0``) the emulator's bus is this host's
  only: its frames are sent with TTL 0 and datagrams from other hosts are dropped (counted), since
  CAN has no authentication. ``hop_limit=N`` (N >= 1) opens it to the network, with a warning.
"""

from __future__ import annotations

import ipaddress
import os
import socket

import can
from can.interfaces.udp_multicast import UdpMulticastBus

DEFAULT_GROUP = UdpMulticastBus.DEFAULT_GROUP_IPv4
DEFAULT_PORT = 43113


def parse_arg(arg: str) -> tuple[str, int, int]:
    """``GROUP[@PORT][,hop_limit=N]`` -> (group, port, hop_limit); ValueError naming what is wrong."""
    arg, _, opts = arg.partition(",")
    group, _, port_s = arg.partition("@")
    group = group.strip("[]") or DEFAULT_GROUP
    try:
        if not ipaddress.ip_address(group).is_multicast:
            raise ValueError
    except ValueError:
        raise ValueError(f"udp_multicast: {group!r} is not a multicast address (224.0.0.0/4 or ff00::/8)") from None
    if port_s and not (port_s.isdigit() and 0 < int(port_s) < 65536):
        raise ValueError(f"udp_multicast: port must be a number 1-65535, got {port_s!r}")
    hop_limit = 0
    if opts:
        key, _, value = opts.partition("=")
        if key != "hop_limit" or not value.isdigit() or not 0 <= int(value) <= 255:
            raise ValueError(f"udp_multicast: unknown option {opts!r} (hop_limit=0..255)")
        hop_limit = int(value)
    return group, int(port_s) if port_s else DEFAULT_PORT, hop_limit


class HostAwareUdpMulticastBus(UdpMulticastBus):
    """python-can's UDP multicast bus that drops its own frames coming back and, with hop limit 0,
    datagrams from other hosts."""

    def __init__(self, channel: str, port: int, hop_limit: int = 0, **kw):
        super().__init__(channel=channel, port=port, hop_limit=hop_limit, **kw)
        self.host_only = hop_limit == 0
        self.marker = f"hydrohil-{os.getpid()}-{id(self):x}"
        self.counters = {"own_echo": 0, "foreign_host": 0}
        self._local: dict[str, bool] = {}

    def _is_local(self, sender) -> bool:
        addr = sender[0]
        known = self._local.get(addr)
        if known is None:
            family = socket.AF_INET6 if ":" in addr else socket.AF_INET
            try:
                with socket.socket(family, socket.SOCK_DGRAM) as s:
                    s.bind((addr, 0) if family == socket.AF_INET else (addr, 0, 0, sender[3] if len(sender) > 3 else 0))
                known = True
            except OSError:
                known = False
            self._local[addr] = known
        return known

    def _recv_internal(self, timeout):
        result = self._multicast.recv(timeout)
        if not result:
            return None, False
        data, sender, timestamp = result
        if self.host_only and not self._is_local(sender):
            self.counters["foreign_host"] += 1
            return None, False
        from can.interfaces.udp_multicast.utils import unpack_message

        try:
            msg = unpack_message(data, replace={"timestamp": timestamp}, check=True)
        except Exception as exc:  # noqa: BLE001 - garbage on the port
            raise can.CanOperationError("could not unpack received message") from exc
        if msg.channel == self.marker:
            self.counters["own_echo"] += 1
            return None, False
        return msg, False

    def send(self, msg: can.Message, timeout=None) -> None:
        msg.channel = self.marker
        super().send(msg, timeout)


def open_bus(arg: str) -> HostAwareUdpMulticastBus:
    group, port, hop_limit = parse_arg(arg)
    return HostAwareUdpMulticastBus(group, port, hop_limit)
