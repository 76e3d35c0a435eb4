"""Service lifecycle on real processes: auth, SIGTERM with an open recording, fuzzing, bad options."""

import signal
import socket
import subprocess
import sys
import threading
import time

import httpx
import numpy as np
import pytest

from sim_core.dataset import read_csv

from server_helpers import ROOT, ServerProcess

pytestmark = pytest.mark.realtime


def test_mutating_endpoints_need_the_bearer_token(tmp_path):
    s = ServerProcess(robot="harvester", token="s3cret", tmp_path=tmp_path)
    try:
        with httpx.Client(base_url=s.url, timeout=30) as anon:
            assert anon.get("/api/v1/state").status_code == 200
            r = anon.put("/api/v1/commands", json={"voltages": {"boom": 2.0}})
            assert r.status_code == 401 and r.headers.get("www-authenticate") == "Bearer"
            bad = anon.put("/api/v1/commands", json={"voltages": {"boom": 2.0}}, headers={"Authorization": "Bearer nope"})
            assert bad.status_code == 403
            for method, path, body in (("put", "/api/v1/mode", {"mode": "paused"}), ("post", "/api/v1/reset", {}),
                                       ("patch", "/api/v1/parameters", {"values": {"supply.pressure": 1e7}}),
                                       ("post", "/api/v1/faults", {"kind": "supply_sag", "factor": 0.5}),
                                       ("post", "/api/v1/recordings", {}), ("put", "/api/v1/estop", {"engaged": True})):
                assert getattr(anon, method)(path, json=body).status_code == 401, path
            assert anon.get("/api/v1/health").json()["auth_required"] is True
        with s.client() as c:
            assert c.put("/api/v1/commands", json={"voltages": {"boom": 2.0}}).status_code == 200
            assert c.get("/api/v1/commands").json()["voltages"]["boom"] == 2.0
    finally:
        s.stop()


def test_sigterm_flushes_an_open_recording_complete(tmp_path):
    s = ServerProcess(robot="mars_nd", tmp_path=tmp_path)
    with s.client() as c:
        c.post("/api/v1/recordings", json={"name": "until_sigterm"})
        stop = threading.Event()

        def load():
            with s.client() as c2:
                k = 0
                while not stop.is_set():
                    try:
                        c2.put("/api/v1/commands", json={"voltages": {"left_j2": 2.0 if k % 2 else -2.0}})
                        c2.get("/api/v1/state")
                    except httpx.HTTPError:
                        return
                    k += 1

        th = threading.Thread(target=load)
        th.start()
        time.sleep(2.5)
        stop.set()
        th.join()
    assert s.terminate() == 0   # graceful shutdown, clean exit status
    ds = read_csv(s.recordings / "until_sigterm.csv")
    assert len(ds) > 2000
    np.testing.assert_allclose(np.diff(ds.time), 1e-3, atol=1e-9)     # every tick, once, to the end
    assert ds.columns[1] == "u_left_j1" and ds.columns[-1] == "p_right_j7_b"
    text = (s.recordings / "until_sigterm.csv").read_text()
    assert text.endswith("\n") and len(text.splitlines()) == len(ds) + 1


@pytest.mark.slow
def test_schemathesis_finds_no_server_errors(tmp_path):
    s = ServerProcess(robot="hydrolek", tmp_path=tmp_path)
    try:
        proc = subprocess.run(
            [str(ROOT / ".venv" / "bin" / "schemathesis") if (ROOT / ".venv" / "bin" / "schemathesis").exists() else "schemathesis",
             "run", f"{s.url}/openapi.json", "--checks", "not_a_server_error", "--max-time", "45", "--workers", "1",
             "--phases", "examples,coverage,fuzzing", "--suppress-health-check", "all"],
            capture_output=True, text=True, timeout=600, cwd=tmp_path)
        assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
        with s.client() as c:
            h = c.get("/api/v1/health").json()
            assert h["engine_alive"], (h, s.log_text()[-3000:])   # still alive after the fuzzing
            assert h["engine"]["restarts"] == 0, h["engine"]           # and never killed during it
    finally:
        s.stop()


def test_without_realtime_priority_it_runs_and_says_so(tmp_path):
    s = ServerProcess("--no-rt", robot="hydrolek", tmp_path=tmp_path)
    try:
        with s.client() as c:
            h = c.get("/api/v1/health").json()
            assert h["realtime_priority"] is False and "disabled" in h["realtime_note"]
            t0 = c.get("/api/v1/state").json()["time"]
            time.sleep(0.5)
            assert c.get("/api/v1/state").json()["time"] > t0 + 0.3          # the plant runs anyway
    finally:
        s.stop()
    assert "without real-time priority" in (s.recordings.parent / f"serve-{s.port}.log").read_text()


@pytest.mark.parametrize("args,message", [
    (["--robot", "nope"], "unknown robot 'nope'"),
    (["--rate", "0"], "--rate 0"),
    (["--can", "carrier-pigeon:1"], "unknown CAN transport 'carrier-pigeon'"),
    (["--params", "/nonexistent.toml"], "no such file"),
])
def test_serve_rejects_bad_options(cli, args, message):
    proc = cli("serve", "--viewer-port", "0", "--port", "0", *args, timeout=120)
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr


def test_a_can_transport_the_host_cannot_give_is_a_clear_error(cli):
    """No such CAN interface (this machine has no kernel CAN at all) and a socketcand port already
    taken: exit 2 with the transport named, no traceback."""
    proc = cli("serve", "--viewer-port", "0", "--port", "0", "--can", "socketcan:nosuchcan0", timeout=120)
    assert proc.returncode == 2 and "CAN transport 'socketcan:nosuchcan0'" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc = cli("serve", "--viewer-port", "0", "--port", "0", "--can", f"socketcand:{port}", timeout=120)
    assert proc.returncode == 2 and f"CAN transport 'socketcand:{port}'" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


def test_the_engine_dies_with_its_service(tmp_path):
    """A SCHED_FIFO engine must not outlive a service that was killed outright (SIGKILL)."""
    import os

    s = ServerProcess(robot="hydrolek", tmp_path=tmp_path)
    engine_pids = [int(p) for p in subprocess.run(["pgrep", "-P", str(s.proc.pid)], capture_output=True,
                                                  text=True).stdout.split()]
    assert engine_pids
    s.proc.kill()
    s.proc.wait(10)
    deadline = time.time() + 10
    alive = engine_pids
    while alive and time.time() < deadline:
        alive = []
        for pid in engine_pids:
            try:
                with open(f"/proc/{pid}/stat") as fh:
                    if fh.read().split()[2] != "Z":   # zombies (exited, not yet reaped) count as gone
                        alive.append(pid)
            except FileNotFoundError:
                pass
        time.sleep(0.2)
    assert not alive, f"orphaned engine processes: {alive}"


def test_a_closed_log_pipe_does_not_kill_the_server():
    """A supervisor that stops reading the server's output (closed pipe) must not kill the plant:
    the next log line would raise SIGPIPE if the CLI had set it to its default action."""
    import socket

    from server_helpers import free_port

    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "sim_core.cli", "serve", "--robot", "hydrolek", "--port", str(port),
                             "--can", "none", "--viewer-port", "0", "--recordings", "/tmp/hydrohil-pipe-test"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        url = f"http://127.0.0.1:{port}"
        for _ in range(600):
            try:
                if httpx.get(url + "/api/v1/health", timeout=1).json()["engine_alive"]:
                    break
            except (httpx.HTTPError, ValueError):
                time.sleep(0.2)
        proc.stdout.close()                        # nobody reads the log any more
        for _ in range(5):                         # uvicorn logs a warning for each invalid request
            with socket.create_connection(("127.0.0.1", port), timeout=2.0) as sock:
                sock.sendall(b"THIS IS NOT HTTP\r\n\r\n")
                try:
                    sock.recv(100)
                except TimeoutError:
                    pass
        time.sleep(1.0)
        assert proc.poll() is None, f"server died (exit {proc.returncode})"
        assert httpx.get(url + "/api/v1/health", timeout=5).json()["engine_alive"]
    finally:
        proc.terminate()
        proc.wait(30)
