"""One record's diagnosis as a backend task: the worker side of a fleet.

The driver reads the record (so that a bad column fails there, naming the file) and sends it with
the configured robot; the worker runs the same diagnosis as ``hydrohil diagnose`` (its candidate fits
one after another: the fleet's parallelism is across records), writes the report into a scratch
directory and sends the files' bytes back, so that workers need not share a file system with the
driver. Any error is this record's alone: it comes back as the record's error, and the fleet goes on.
"""

from __future__ import annotations

import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path


@dataclass
class RecordJob:
    name: str
    record: object        # identification.record.Record


@dataclass
class Shared:
    spec: object          # the configured robot spec (--params, --set, --effect applied)
    effects: list[str] | None
    fmt: str              # report format: html or md
    command_hold: str = "auto"   # diagnose --command-hold


EXPECTED = (ValueError, ArithmeticError)   # bad data, a diverging model: the message says it all
_WARM: list[bool] = []


def warm_up(spec) -> float:
    """A worker's start-up, once per process (s): the diagnosis modules imported and the compiled
    kernel loaded (from the kernel cache, or compiled into it) by one short simulation. Timed apart so
    that a fleet can tell a worker's start from a record's own cost."""
    if _WARM:
        return 0.0
    t0 = time.perf_counter()
    import numpy as np

    from ..identification import diagnosis, report  # noqa: F401
    from ..plant import Plant
    from ..simulator import Simulator

    ctx = Plant(spec).create_context(seed=0)
    t = np.arange(0.0, 0.1, 0.01)
    Simulator(ctx).run(t, np.zeros((t.size, len(spec.joint_names))))
    _WARM.append(True)
    return time.perf_counter() - t0


def diagnose_record(shared: Shared, job: RecordJob) -> dict:
    from ..identification import diagnosis, report

    warm = warm_up(shared.spec)
    t0 = time.perf_counter()
    try:
        d = diagnosis.run(shared.spec, job.record, None, workers=1, progress=False, effects=shared.effects,
                           command_hold=shared.command_hold)
        with tempfile.TemporaryDirectory(prefix="hydrohil-fleet-") as tmp:
            paths = report.write(d, tmp, shared.spec, fmt=shared.fmt)
            files = {Path(p).name: Path(p).read_bytes() for p in paths.values()}
    except EXPECTED as exc:
        return {"ok": False, "error": str(exc), "seconds": time.perf_counter() - t0, "warmup_s": warm}
    except Exception as exc:     # a defect, not bad data: keep where it happened
        return {"ok": False, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc(),
                "seconds": time.perf_counter() - t0, "warmup_s": warm}
    return {"ok": True, "files": files, "seconds": time.perf_counter() - t0, "warmup_s": warm}
