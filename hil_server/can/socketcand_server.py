"""A socketcand (linux-can) protocol server on TCP, as a python-can bus.

Machines without kernel CAN (this one, CI) have no vcan; stock python-can clients in other
processes connect with ``can.Bus(interface="socketcand", host="127.0.0.1", port=PORT,
channel="vcan0")``. The server side is a :class:`can.BusABC`, so the bridge uses it like any other
bus. Bus semantics: a frame sent by one client reaches the emulator and every other client (not
itself, like SocketCAN without RECV_OWN_MSGS); frames the emulator sends reach every client.

Rawmode subset of the protocol, as the reference daemon (socketcand/src/state_raw.c) and
python-can's client speak it: ``< hi >`` on connect; ``< open BUS >`` -> ``< ok >``;
``< rawmode >`` -> ``< ok >``; client frames ``< send ID DLC b0 b1 ... >`` (unpadded hex bytes);
server frames ``< frame ID SEC.USEC DATA >`` (contiguous hex; 3 hex digits = 11-bit id, 8 = 29-bit).
python-can compares each handshake reply with one ``recv(256)``, so frames to a client are queued
and only sent after a short pause following its ``rawmode`` reply. Unparseable input is counted and skipped.
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time

import can

log = logging.getLogger("hydrohil.socketcand")

HANDSHAKE_QUIET_S = 0.1
CLIENT_QUEUE = 20000


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
    def __init__(self, server: "SocketcandServerBus", sock: socket.socket, addr):
        self.server = server
        self.sock = sock
        self.addr = addr
        self.raw = False
        self.raw_since = 0.0
        self.out: queue.Queue = queue.Queue(CLIENT_QUEUE)
        self.alive = True
        self.dropped = 0
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._quickack = getattr(socket, "TCP_QUICKACK", None)
        threading.Thread(target=self._reader, name=f"socketcand-rx-{addr}", daemon=True).start()
        threading.Thread(target=self._writer, name=f"socketcand-tx-{addr}", daemon=True).start()

    def control(self, text: str) -> None:
        self.sock.sendall(text.encode("ascii"))

    def enqueue(self, line: bytes) -> None:
        if not self.raw:
            return
        try:
            self.out.put_nowait(line)
        except queue.Full:
            self.dropped += 1
            self.server.count("dropped_slow_client")

    def _writer(self) -> None:
        while self.alive and (not self.raw or time.monotonic() - self.raw_since < HANDSHAKE_QUIET_S):
            time.sleep(0.01)  # frames queue up; sent once the handshake reply stands alone
        while self.alive:
            try:
                line = self.out.get(timeout=0.2)
            except queue.Empty:
                continue
            batch = [line]
            while len(batch) < 256:
                try:
                    batch.append(self.out.get_nowait())
                except queue.Empty:
                    break
            try:
                self.sock.sendall(b"".join(batch))
            except OSError:
                self.close()

    def _reader(self) -> None:
        buf = ""
        try:
            self.control("< hi >")
            while self.alive:
                try:
                    data = self.sock.recv(65536)
                    if self._quickack is not None:
                        # ACK at once: python-can's client leaves Nagle on, so its second small frame
                        # of a tick would otherwise wait for our delayed ACK (40-200 ms per tick)
                        self.sock.setsockopt(socket.IPPROTO_TCP, self._quickack, 1)
                except OSError:
                    break
                if not data:
                    break
                buf += data.decode("ascii", errors="replace")
                while True:
                    start = buf.find("<")
                    if start < 0:
                        buf = ""
                        break
                    end = buf.find(">", start)
                    if end < 0:
                        if len(buf) - start > 1024:  # garbage without a closing bracket
                            self.server.count("malformed")
                            buf = ""
                        else:
                            buf = buf[start:]
                        break
                    self._handle(buf[start + 1:end].strip())
                    buf = buf[end + 1:]
        finally:
            self.close()

    def _handle(self, body: str) -> None:
        if not self.raw:
            if body.startswith("open "):
                name = body[5:].strip()
                if name == self.server.channel:
                    self.control("< ok >")
                else:
                    self.control(f"< error could not open bus '{name}' >")
            elif body == "rawmode":
                self.control("< ok >")
                self.raw_since = time.monotonic()
                self.raw = True
            elif body == "echo":
                self.control("< echo >")
            else:
                self.server.count("malformed")
            return
        if body.startswith("send "):
            try:
                msg = parse_send(body)
            except ValueError:
                self.server.count("malformed")
                return
            self.server._from_client(self, msg)
        elif body == "echo":
            self.control("< echo >")
        else:
            self.server.count("malformed")

    def close(self) -> None:
        if not self.alive:
            return
        self.alive = False
        try:
            self.sock.close()
        except OSError:
            pass
        self.server._drop(self)


class SocketcandServerBus(can.BusABC):
    """Server side of the socketcand protocol as a python-can bus (``interface`` 'socketcand-server')."""

    def __init__(self, channel: str = "vcan0", host: str = "127.0.0.1", port: int = 29536, **kwargs):
        self.channel = channel
        self.channel_info = f"socketcand server {host}:{port} bus {channel}"
        self.host, self.port = host, port
        self._rx: queue.Queue = queue.Queue(100000)
        self._clients: list[_Client] = []
        self._lock = threading.Lock()
        self.counters: dict[str, int] = {}
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind((host, port))
        self._listener.listen(16)
        self.port = self._listener.getsockname()[1]
        self._open = True
        threading.Thread(target=self._accept, name="socketcand-accept", daemon=True).start()
        super().__init__(channel=channel, **kwargs)

    def count(self, key: str, n: int = 1) -> None:
        self.counters[key] = self.counters.get(key, 0) + n

    @property
    def clients(self) -> int:
        return len(self._clients)

    def _accept(self) -> None:
        while self._open:
            try:
                sock, addr = self._listener.accept()
            except OSError:
                break
            c = _Client(self, sock, addr)
            with self._lock:
                self._clients.append(c)

    def _drop(self, client: _Client) -> None:
        with self._lock:
            if client in self._clients:
                self._clients.remove(client)

    def _from_client(self, client: _Client, msg: can.Message) -> None:
        try:
            self._rx.put_nowait(msg)
        except queue.Full:
            self.count("dropped_rx_full")
        line = format_frame(msg)
        with self._lock:
            others = [c for c in self._clients if c is not client]
        for c in others:
            c.enqueue(line)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        line = format_frame(msg)
        with self._lock:
            clients = list(self._clients)
        for c in clients:
            c.enqueue(line)

    def _recv_internal(self, timeout):
        try:
            if timeout is None:
                return self._rx.get(), False
            if timeout <= 0:
                return self._rx.get_nowait(), False
            return self._rx.get(timeout=timeout), False
        except queue.Empty:
            return None, False

    def shutdown(self) -> None:
        self._open = False
        try:
            self._listener.close()
        except OSError:
            pass
        with self._lock:
            clients = list(self._clients)
        for c in clients:
            c.close()
        super().shutdown()
