"""CAN transports chosen by configuration, like python-can interfaces.

``--can`` takes ``KIND[:ARG]``:

* ``virtual[:channel]``  python-can's in-process virtual bus (tests; default channel 'hydrohil')
* ``socketcan[:iface]``  kernel SocketCAN, e.g. a vcan on Linux hosts that have the module
* ``socketcand[:port][@host]``  our socketcand-protocol TCP server, bus name 'vcan0', for stock
  python-can clients in other processes where there is no kernel CAN (default 127.0.0.1:29536)

More kinds can be added with the ``hydrohil.can_transports`` entry-point group (a callable taking
the argument string and returning a :class:`can.BusABC`).
"""

from __future__ import annotations

from importlib.metadata import entry_points

import can


def _virtual(arg: str) -> can.BusABC:
    return can.Bus(interface="virtual", channel=arg or "hydrohil", receive_own_messages=False)


def _socketcan(arg: str) -> can.BusABC:
    return can.Bus(interface="socketcan", channel=arg or "vcan0")


def _socketcand(arg: str) -> can.BusABC:
    from .socketcand_server import SocketcandServerBus

    port_s, _, host = arg.partition("@")
    try:
        port = int(port_s) if port_s else 29536
    except ValueError:
        raise ValueError(f"socketcand: port must be a number, got {port_s!r}") from None
    return SocketcandServerBus(channel="vcan0", host=host or "127.0.0.1", port=port)


TRANSPORTS = {"virtual": _virtual, "socketcan": _socketcan, "socketcand": _socketcand}


def open_bus(spec: str) -> can.BusABC:
    kind, _, arg = spec.partition(":")
    factories = dict(TRANSPORTS)
    for ep in entry_points(group="hydrohil.can_transports"):
        factories[ep.name] = ep.load()
    if kind not in factories:
        raise ValueError(f"unknown CAN transport {kind!r}; transports: {', '.join(sorted(factories))}")
    try:
        return factories[kind](arg)
    except OSError as exc:
        raise OSError(f"CAN transport {spec!r} could not be opened: {exc}") from exc
