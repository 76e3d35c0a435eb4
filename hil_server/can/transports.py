"""CAN transports chosen by configuration, like python-can interfaces.

``--can`` takes ``KIND[:ARG]``:

* ``virtual[:channel]``  python-can's in-process virtual bus (tests; default channel 'hydrohil')
* ``socketcan[:iface]``  kernel SocketCAN, e.g. a vcan on Linux hosts that have the module
* ``socketcand[:port][@host]``  our socketcand-protocol TCP server, bus name 'vcan0', for stock
  python-can clients in other processes where there is no kernel CAN (default 127.0.0.1:29536)
* ``udp_multicast[:group][@port][,hop_limit=N]``  python-can's UDP multicast bus (no kernel CAN, no
  server: every process on the group is a node); this host only unless ``hop_limit`` >= 1

A transport delivers received frames to ``on_frame`` on the bridge's event loop and sends frames
from it. python-can buses are wrapped with a :class:`can.Notifier` bound to that loop. More kinds
can be added with the ``hydrohil.can_transports`` entry-point group (a callable taking the argument
string and returning a transport, or a :class:`can.BusABC`).
"""

from __future__ import annotations

import asyncio
from importlib.metadata import entry_points

import can


class PythonCanTransport:
    """Any python-can bus as a transport."""

    def __init__(self, bus: can.BusABC):
        self.bus = bus
        self._notifier: can.Notifier | None = None

    async def start(self, on_frame) -> None:
        loop = asyncio.get_running_loop()

        class _Listener(can.Listener):
            def on_message_received(self, msg):
                on_frame(msg)

        self._notifier = can.Notifier(self.bus, [_Listener()], timeout=0.1, loop=loop)

    @property
    def counters(self) -> dict:
        return dict(getattr(self.bus, "counters", {}))

    @property
    def warnings(self) -> list[str]:
        return list(getattr(self.bus, "warnings", []))

    def send(self, msg: can.Message) -> None:
        self.bus.send(msg)

    def send_many(self, msgs) -> None:
        for m in msgs:
            self.bus.send(m)

    async def close(self) -> None:
        if self._notifier is not None:
            self._notifier.stop()
        self.bus.shutdown()

    def describe(self) -> dict:
        return {"bus": getattr(self.bus, "channel_info", str(self.bus))}


def _udp_multicast(arg: str):
    from .udp_multicast import open_bus

    try:
        bus = open_bus(arg)
    except can.CanError as exc:
        raise OSError(str(exc)) from exc
    if not bus.host_only:
        bus.warnings = [f"udp_multicast CAN bus open to the network (hop_limit {bus._multicast.hop_limit}): CAN has "
                        "no authentication, any host on the segment can command the valves"]
    return PythonCanTransport(bus)


def _virtual(arg: str):
    return PythonCanTransport(can.Bus(interface="virtual", channel=arg or "hydrohil", receive_own_messages=False))


def _socketcan(arg: str):
    return PythonCanTransport(can.Bus(interface="socketcan", channel=arg or "vcan0"))


def _socketcand(arg: str):
    from .socketcand_server import SocketcandServer

    port_s, _, host = arg.partition("@")
    try:
        port = int(port_s) if port_s else 29536
    except ValueError:
        raise ValueError(f"socketcand: port must be a number, got {port_s!r}") from None
    return SocketcandServer(host=host or "127.0.0.1", port=port)


TRANSPORTS = {"virtual": _virtual, "socketcan": _socketcan, "socketcand": _socketcand,
              "udp_multicast": _udp_multicast}


def _factories() -> dict:
    factories = dict(TRANSPORTS)
    for ep in entry_points(group="hydrohil.can_transports"):
        factories[ep.name] = ep.load()
    return factories


def check_spec(spec: str) -> None:
    """Raise ValueError naming the problem if ``spec`` names no known transport (checked at start-up)."""
    kind, _, arg = spec.partition(":")
    factories = _factories()
    if kind not in factories:
        raise ValueError(f"unknown CAN transport {kind!r}; transports: {', '.join(sorted(factories))}")
    if kind == "socketcand":
        port_s = arg.partition("@")[0]
        if port_s and not (port_s.isdigit() and 0 <= int(port_s) < 65536):
            raise ValueError(f"socketcand: port must be a number 0-65535, got {port_s!r}")
    if kind == "udp_multicast":
        from .udp_multicast import parse_arg

        parse_arg(arg)


def open_transport(spec: str):
    check_spec(spec)
    kind, _, arg = spec.partition(":")
    factories = _factories()
    try:
        t = factories[kind](arg)
    except (OSError, can.CanError) as exc:
        raise OSError(f"CAN transport {spec!r} could not be opened: {exc}") from exc
    return PythonCanTransport(t) if isinstance(t, can.BusABC) else t


def probe_transport(spec: str) -> None:
    """Open, start and close the transport once on a throw-away event loop.

    Raises OSError or ValueError naming the transport when the host cannot give it (no kernel CAN,
    a socketcand port already taken): a clear start-up error before the plant starts, not a
    traceback from inside the server's event loop."""

    async def once() -> None:
        t = open_transport(spec)
        try:
            await t.start(lambda _msg: None)
        except OSError as exc:
            raise OSError(f"CAN transport {spec!r} could not be started: {exc}") from exc
        finally:
            await t.close()

    asyncio.run(once())

