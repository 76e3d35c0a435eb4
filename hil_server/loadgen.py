"""A lean HTTP/1.1 load generator (asyncio streams, keep-alive, paced), for the loop benchmark.

httpx costs about a millisecond of client CPU per request; on a 2-core machine the client would
then eat the CPU the server needs. Raw keep-alive requests cost ~20-30 us each.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time


async def _conn_worker(host, port, queue, lat, codes):
    reader, writer = await asyncio.open_connection(host, port)
    try:
        while True:
            item = await queue.get()
            if item is None:
                return
            t0, req = item
            writer.write(req)
            await writer.drain()
            head = await reader.readuntil(b"\r\n\r\n")
            status = int(head.split(b" ", 2)[1])
            length = 0
            for line in head.split(b"\r\n"):
                if line.lower().startswith(b"content-length:"):
                    length = int(line.split(b":", 1)[1])
            if length:
                await reader.readexactly(length)
            lat.append(time.perf_counter() - t0)
            codes.append(status)
    finally:
        writer.close()


async def run(host: str, port: int, rps: float, seconds: float, connections: int = 8) -> dict:
    get = (f"GET /api/v1/state HTTP/1.1\r\nHost: {host}\r\n\r\n").encode()
    bodies = [json.dumps({"voltages": {"j3": v}}).encode() for v in (1.0, -1.0)]
    puts = [(f"PUT /api/v1/commands HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\n"
             f"Content-Length: {len(b)}\r\n\r\n").encode() + b for b in bodies]
    queue: asyncio.Queue = asyncio.Queue()
    lat: list[float] = []
    codes: list[int] = []
    workers = [asyncio.create_task(_conn_worker(host, port, queue, lat, codes)) for _ in range(connections)]
    start = time.perf_counter()
    k = 0
    while time.perf_counter() - start < seconds:
        req = puts[(k // 5) % 2] if k % 5 == 0 else get
        queue.put_nowait((time.perf_counter(), req))
        k += 1
        await asyncio.sleep(max(0.0, start + k / rps - time.perf_counter()))
    for _ in workers:
        queue.put_nowait(None)
    await asyncio.gather(*workers)
    el = time.perf_counter() - start
    lat.sort()
    return {"requests": len(codes), "rps": len(codes) / el, "errors": sum(1 for c in codes if c >= 400),
            "p50_ms": lat[len(lat) // 2] * 1e3 if lat else None, "p99_ms": lat[int(len(lat) * 0.99)] * 1e3 if lat else None}


if __name__ == "__main__":
    host, port, rps, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
    print(json.dumps(asyncio.run(run(host, port, rps, seconds))))
