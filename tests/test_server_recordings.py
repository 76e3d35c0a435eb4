"""Recordings as Parquet: the dataset's columns (the CSV's names) as float64 with units and robot in
the schema metadata, one row per tick after a clean stop, and closed readable with the reason when
the engine dies."""

import io
import json
import os
import signal
import time

import numpy as np
import pyarrow.parquet as pq
import pytest

from sim_core.dataset import read_csv

from server_helpers import ServerProcess

pytestmark = pytest.mark.realtime

UNIT = {"time": "s", "u": "V", "q": "rad", "p": "Pa"}


def wait_closed(c, rid, timeout=2.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        d = c.get(f"/api/v1/recordings/{rid}").json()
        if not d["active"]:
            return d
        time.sleep(0.01)
    raise AssertionError(f"recording {rid} still active")


def test_parquet_recordings_after_a_clean_stop_and_after_engine_death(tmp_path):
    srv = ServerProcess(robot="hydrolek", tmp_path=tmp_path)
    try:
        with srv.client() as c:
            csv = c.post("/api/v1/recordings", json={"name": "ref"}).json()
            time.sleep(0.3)
            c.post("/api/v1/recordings/stop").raise_for_status()
            assert c.post("/api/v1/recordings", json={"format": "feather"}).status_code == 422
            rec = c.post("/api/v1/recordings", json={"name": "clean", "format": "parquet"}).json()
            assert rec["format"] == "parquet" and rec["file"] == "clean.parquet"
            for k in range(12):
                c.put("/api/v1/commands", json={"voltages": {"j2": 3.0 if k % 2 else -3.0}}).raise_for_status()
                time.sleep(0.1)
            done = c.post("/api/v1/recordings/stop").json()
            assert done["complete"] and not done["active"] and done["stop_reason"] == "stopped"
            body = c.get(f"/api/v1/recordings/{rec['id']}/data")
            assert body.status_code == 200 and body.headers["content-type"] == "application/vnd.apache.parquet"
            table = pq.read_table(io.BytesIO(body.content))
            # same columns as the CSV recording, in the same order, each float64
            header = read_csv(srv.recordings / f"{csv['id']}.csv").columns
            assert table.column_names == header
            assert all(str(t) == "double" for t in table.schema.types)
            meta = table.schema.metadata
            assert meta[b"hydrohil.robot"] == b"hydrolek"
            units = json.loads(meta[b"hydrohil.units"])
            assert units == {c: UNIT[c.split("_")[0]] for c in header}
            t = table.column("time").to_numpy()
            assert table.num_rows == done["rows"] > 1000
            np.testing.assert_allclose(np.diff(t), 1e-3, atol=1e-9)          # every tick once
            u = table.column("u_j2").to_numpy()
            assert set(np.unique(u)) <= {3.0, -3.0, 0.0} and (u == 3.0).any() and (u == -3.0).any()
            assert pq.read_metadata(srv.recordings / "clean.parquet").metadata[b"hydrohil.stop_reason"] == b"stopped"
            # the engine dies while recording: the file is closed at once, readable, with the reason
            rec = c.post("/api/v1/recordings", json={"name": "dies", "format": "parquet"}).json()
            time.sleep(0.4)
            os.kill(c.get("/api/v1/health").json()["engine"]["pid"], signal.SIGKILL)
            d = wait_closed(c, rec["id"])
            assert d["complete"] and "engine died" in d["stop_reason"]
            path = srv.recordings / "dies.parquet"
            table = pq.read_table(path)
            assert table.num_rows == d["rows"] > 200
            np.testing.assert_allclose(np.diff(table.column("time").to_numpy()), 1e-3, atol=1e-9)
            assert b"engine died" in pq.read_metadata(path).metadata[b"hydrohil.stop_reason"]
    finally:
        srv.stop()

