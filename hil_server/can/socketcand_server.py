"""A socketcand (linux-can) protocol server on TCP, on an asyncio event loop.

Machines without kernel CAN (this one, CI) have no vcan; stock python-can clients in other
processes connect with ``can.Bus(interface="socketcand", host="127.0.0.1", port=PORT,
channel="vcan0")``. Bus semantics: a frame sent by one client reaches the emulator and every other
client (not itself, like SocketCAN without RECV_OWN_MSGS); frames the emulator sends reach every
client. Everything runs on one event loop (no thread per client): under ``hydrohil serve`` that is
uvicorn's, so CAN and REST never fight over the GIL.

The server binds loopback by default. CAN has no authentication: anyone who can reach the port can
move a valve, so a non-loopback bind is allowed but warned about (``warnings``, shown in the log
and ``/api/v1/health``).

Rawmode subset of the protocol, as the reference daemon (socketcand/src/state_raw.c) and
python-can's client speak it: ``< hi >`` on connect; ``< open BUS >`` -> ``< ok >``;
``< rawmode >`` -> ``< ok >``; client frames ``< send ID DLC b0 b1 ... >`` (unpadded hex bytes);
server frames ``< frame ID SEC.USEC DATA >`` (contiguous hex; 3 hex digits = 11-bit id, 8 = 29-bit).
python-can compares each handshake reply with one ``recv(256)``, so frames to a client are queued
and only sent after a short pause following its ``rawmode`` reply. python-can's client leaves Nagle
on; we ACK every read at once (TCP_QUICKACK) so its second small frame of a tick is not held for our
delayed ACK (40-200 ms). Unparseable input is counted and skipped; a client that cannot keep up has
frames dropped (counted) rather than growing memory; a client whose frames the bridge drops as flood
is read more slowly (TCP back-pressure), so a flood on one connection cannot starve the event loop.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import time

import can

log = logging.getLogger("hydrohil.socketcand")

HANDSHAKE_QUIET_S = 0.1
MAX_BUFFERED = 256 * 1024   # bytes queued in a client's transport before frames are dropped
FLOOD_PAUSE_S = 1.0 / 5000.0    # reading from a client pauses this long per frame the bridge dropped as flood
READ_BYTES = 4096           # per read (~100 frames): every client gets its turn every few hundred microseconds


def format_frame(msg: can.Message) -> bytes:
    cid = f"{msg.arbitration_id & 0x1FFFFFFF:08X}" if msg.is_extended_id else f"{msg.arbitration_id & 0x7FF:03X}"
    ts = msg.timestamp or time.time()
    return f"< frame {cid} {int(ts)}.{int((ts % 1) * 1e6):06d} {bytes(msg.data[:msg.dlc]).hex().upper()} >".encode("ascii")


def parse_send(body: str) -> can.Message:
    """'send ID DLC b0 b1 ...' -> Message (raises ValueError)."""
    parts = body.split()
    if len(parts) < 3 or parts[0] != "send":
        raise ValueError(body)
    cid_s, dlc = parts[1], int(parts[2], 16)
    data = bytes(int(b, 16) for b in parts[3:])
    if not 0 <= dlc <= 8 or len(data) != dlc:
        raise ValueError(f"dlc {dlc} with {len(data)} bytes")
    ext = len(cid_s) > 3
    cid = int(cid_s, 16)
    if cid > (0x1FFFFFFF if ext else 0x7FF):
        raise ValueError(f"id {cid_s} out of range")
    return can.Message(arbitration_id=cid, data=data, dlc=dlc, is_extended_id=ext, timestamp=time.time())


class _Client:
    def __init__(self, server: "SocketcandServer", reader: asyncio.StreamReader, writer: asyncio.StreamWriter):
        self.server = server
        self.reader = reader
        self.writer = writer
        self.raw = False
        self.pending: list[bytes] = []   # frames held during the handshake pause
        self.flushing = False
        self.flooded = 0                  # frames of the current read the bridge dropped as flood
        sock = writer.get_extra_info("socket")
        self._sock = sock
        self._quickack = getattr(socket, "TCP_QUICKACK", None)
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def write(self, data: bytes) -> None:
        if self.writer.is_closing():
            return
        if self.writer.transport.get_write_buffer_size() > MAX_BUFFERED:
            self.server.count("dropped_slow_client")
            return
        self.writer.write(data)

    def deliver(self, line: bytes) -> None:
        if not self.raw:
            return
        if self.flushing:
            self.pending.append(line)
        else:
            self.write(line)

    async def run(self) -> None:
        self.write(b"< hi >")
        buf = ""
        try:
            while True:
                data = await self.reader.read(READ_BYTES)
                if not data:
                    break
                if self._quickack is not None and self._sock is not None:
                    try:
                        self._sock.setsockopt(socket.IPPROTO_TCP, self._quickack, 1)
                    except OSError:
                        pass
                buf += data.decode("ascii", errors="replace")
                self.flooded = 0
                pos = 0
                while True:
                    start = buf.find("<", pos)
                    if start < 0:
                        pos = len(buf)
                        break
                    end = buf.find(">", start)
                    if end < 0:
                        if len(buf) - start > 1024:
                            self.server.count("malformed")
                            pos = len(buf)
                        else:
                            pos = start
                        break
                    self._handle(buf[start + 1:end].strip())
                    pos = end + 1
                buf = buf[pos:]
                if self.flooded:
                    # a flooding client is read no faster than its frames are admitted: TCP then holds
                    # the sender back, so the flood costs this loop (REST, the other clients) nothing
                    await asyncio.sleep(self.flooded * FLOOD_PAUSE_S)
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            self.server._drop(self)
            self.writer.close()

    def _handle(self, body: str) -> None:
        if not self.raw:
            if body.startswith("open "):
                name = body[5:].strip()
                self.write(b"< ok >" if name == self.server.channel else f"< error could not open bus '{name}' >".encode())
            elif body == "rawmode":
                self.write(b"< ok >")
                self.raw = True
                self.flushing = True
                asyncio.get_running_loop().call_later(HANDSHAKE_QUIET_S, self._flush)
            elif body == "echo":
                self.write(b"< echo >")
            else:
                self.server.count("malformed")
            return
        if body.startswith("send "):
            admit = self.server.admit
            if admit is not None:     # the flood budget first: a dropped frame is never decoded
                cid_s = body[5:].lstrip().partition(" ")[0]
                try:
                    cid = int(cid_s, 16)
                except ValueError:
                    self.server.count("malformed")
                    return
                if not admit(cid, len(cid_s) > 3):
                    self.flooded += 1
                    return
            try:
                msg = parse_send(body)
            except ValueError:
                self.server.count("malformed")
                return
            self.server._from_client(self, msg, admit is not None)
        elif body == "echo":
            self.write(b"< echo >")
        else:
            self.server.count("malformed")

    def _flush(self) -> None:
        self.flushing = False
        if self.pending:
            self.write(b"".join(self.pending))
            self.pending.clear()


class SocketcandServer:
    """Transport ``socketcand``: serves bus ``vcan0`` on ``host:port``."""

    def __init__(self, host: str = "127.0.0.1", port: int = 29536, channel: str = "vcan0"):
        from ..security import is_loopback

        self.host, self.port, self.channel = host, port, channel
        self.warnings = [] if is_loopback(host) else [
            f"socketcand CAN server exposed on {host}:{port}: CAN has no authentication, anyone who reaches "
            "this port can command the valves"]
        self.counters: dict[str, int] = {}
        self.clients: list[_Client] = []
        self.on_frame = None
        self.admit = None   # set by the bridge: admit(arbitration_id, extended) -> bool, before decoding
        self._server: asyncio.AbstractServer | None = None

    def count(self, key: str, n: int = 1) -> None:
        self.counters[key] = self.counters.get(key, 0) + n

    async def start(self, on_frame) -> None:
        self.on_frame = on_frame
        self._server = await asyncio.start_server(self._accept, self.host, self.port, reuse_address=True)
        self.port = self._server.sockets[0].getsockname()[1]

    async def _accept(self, reader, writer) -> None:
        c = _Client(self, reader, writer)
        self.clients.append(c)
        await c.run()

    def _drop(self, client: _Client) -> None:
        if client in self.clients:
            self.clients.remove(client)

    def _from_client(self, client: _Client, msg: can.Message, admitted: bool = False) -> None:
        ok = (self.on_frame(msg, True) if admitted else self.on_frame(msg)) is not False
        if not ok:                 # a frame dropped as flood is not forwarded either
            client.flooded += 1
            return
        if len(self.clients) > 1:
            line = format_frame(msg)
            for c in self.clients:
                if c is not client:
                    c.deliver(line)

    def send(self, msg: can.Message) -> None:
        self.send_many([msg])

    def send_many(self, msgs) -> None:
        data = b"".join(format_frame(m) for m in msgs)
        for c in list(self.clients):
            c.deliver(data)

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            for c in list(self.clients):
                c.writer.close()
            try:
                await asyncio.wait_for(self._server.wait_closed(), 2.0)
            except (asyncio.TimeoutError, Exception):  # noqa: BLE001
                pass

    def describe(self) -> dict:
        return {"port": self.port, "clients": len(self.clients), "bus": self.channel}
