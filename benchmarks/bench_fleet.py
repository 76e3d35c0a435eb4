"""Throughput of ``hydrohil diagnose-fleet`` through the local pool and through Ray, at 1 and 2 workers.

A fleet of N records (default 20 of 60 s at 200 Hz, the issue's setting) is made with the real
commands (``excite`` once, then ``simulate`` per record with a hidden deadband on the HydroLek
shoulder whose width grows with the record's date, and its own noise seed). Each configuration
diagnoses the whole fleet into a fresh directory, in this process as the command does; Ray is a
fresh local instance of as many CPUs as workers. Printed per configuration:

* records per hour over the fleet's wall time, without and with the backend's start-up;
* per-record overhead: the time the driver waited for a record beyond what the worker spent on it
  (transport, scheduling, (de)serialisation), and, against the local pool at the same worker
  count, (wall_ray - wall_local) x workers / records;
* each worker process's start: importing the diagnosis and loading the compiled kernel, timed in
  the worker before its first record (``--cold-cache``: compiling it into an empty cache instead).
  A local pool's workers are forked from this process and inherit what it has loaded.

The reference measured in the same run is the local pool at the same worker count (ratio ray/local),
and 1 worker (scaling 2/1). ``--repeat N`` runs every configuration N times, interleaved, and keeps
the fastest (other work on a shared machine only ever slows a run down). Every diagnosis through Ray
is compared with the local one (identical apart from the timings). The load average is printed.

    .venv/bin/python benchmarks/bench_fleet.py [--records 20] [--duration 60] [--rate 200] [--repeat 1]
                                               [--workers 1,2] [--backends local,ray] [--cold-cache] [--json FILE]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import date, timedelta
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# the code this benchmark sits in, in this process and in every Ray worker it starts (they inherit the
# environment), whatever hydrohil the interpreter has installed
sys.path.insert(0, str(ROOT))
os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))


def cli(*args):
    subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)


def make_records(where: Path, n: int, duration: float, rate: float) -> list[Path]:
    cli("excite", "--robot", "hydrolek", "--joint", "j2", "--duration", duration, "--rate", rate, "--seed", 7,
        "--out", where / "in.csv")
    paths = []
    for i in range(n):
        day = date(2024, 1, 1) + timedelta(days=7 * i)
        width = 0.4 + 0.8 * i / max(1, n - 1)           # a deadband growing over the weeks (V)
        out = where / f"crane_{day.isoformat()}.csv"
        cli("simulate", "--robot", "hydrolek", "--input", where / "in.csv", "--out", out, "--noise-angle", 3e-4,
            "--seed", 100 + i, "--effect", f"deadband:joint=j2,width={width:.4f}")
        paths.append(out)
    return paths


def run_config(backend_name: str, workers: int, paths, out: Path) -> dict:
    from sim_core.backends import open_backend
    from sim_core.fleet import FleetOptions, run_fleet
    from sim_core.ingest import ReadOptions
    from sim_core.model.spec import load_robot

    t0 = time.perf_counter()
    backend = open_backend(backend_name, workers=workers)
    startup = time.perf_counter() - t0
    opts = FleetOptions(load_robot("hydrolek"), ReadOptions())
    res = run_fleet(paths, opts, out, backend_factory=lambda: backend)
    n = sum(r["status"] == "diagnosed" for r in res.rows)
    if not n:
        raise SystemExit(f"{backend_name} x{workers}: no record was diagnosed; first error: {res.failed[0]['error']}")
    done = [o for o in res.outcomes if o.task and o.value and o.value.get("ok")]
    tasks = [o.value["seconds"] for o in done]
    waits = [o.seconds - o.task["seconds"] for o in done]
    warm = [o.value["warmup_s"] for o in done if o.task.get("first")]
    errors = [r["error"] for r in res.failed]
    return {"errors": errors, "backend": backend_name, "workers": workers, "records": len(paths), "diagnosed": n,
            "failed": len(res.failed), "startup_s": startup, "wall_s": res.wall_s,
            "records_per_hour": n / res.wall_s * 3600, "records_per_hour_with_startup": n / (res.wall_s + startup) * 3600,
            "task_s_mean": statistics.mean(tasks), "overhead_s_mean": statistics.mean(waits),
            "overhead_s_max": max(waits), "worker_start_s": warm,
            "workers_seen": len({o.task["worker"] for o in done}),
            "per_record_task_s": {o.item: o.value["seconds"] for o in done}}


def same_diagnoses(a: Path, b: Path, names) -> bool:
    for n in names:
        da = json.loads((a / n / "diagnosis.json").read_text())
        db = json.loads((b / n / "diagnosis.json").read_text())
        da.pop("timings_s")
        db.pop("timings_s")
        if da != db:
            return False
    return True


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--records", type=int, default=20)
    ap.add_argument("--duration", type=float, default=60.0, help="s per record")
    ap.add_argument("--rate", type=float, default=200.0, help="Hz")
    ap.add_argument("--workers", default="1,2", help="worker counts to measure (comma-separated)")
    ap.add_argument("--backends", default="local,ray")
    ap.add_argument("--repeat", type=int, default=1, help="runs per configuration, interleaved; the fastest counts")
    ap.add_argument("--cold-cache", action="store_true", help="compile the kernel into an empty cache in every configuration")
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    args = ap.parse_args()
    workers = [int(w) for w in args.workers.split(",")]
    backends = args.backends.split(",")

    tmp = Path(tempfile.mkdtemp(prefix="bench_fleet_"))
    t0 = time.perf_counter()
    (tmp / "records").mkdir()
    paths = make_records(tmp / "records", args.records, args.duration, args.rate)
    print(f"{args.records} records of {args.duration:g} s at {args.rate:g} Hz made in {time.perf_counter() - t0:.0f} s; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at start", flush=True)
    results = []
    for rep in range(args.repeat):
        for w in workers:
            for b in backends:
                if args.cold_cache:
                    os.environ["HYDROHIL_KERNEL_CACHE"] = tempfile.mkdtemp(prefix="kernels_", dir=tmp)
                out = tmp / f"{b}-{w}-{rep}"
                r = run_config(b, w, paths, out)
                r.update(load_average=os.getloadavg()[0], repeat=rep, dir=str(out))
                results.append(r)
                print(f"{b:>5} x{w}: {r['records_per_hour']:7.1f} records/h ({r['records_per_hour_with_startup']:.1f} with "
                      f"{r['startup_s']:.1f} s start-up), {r['wall_s']:.0f} s wall, task {r['task_s_mean']:.1f} s mean, "
                      f"driver waited {r['overhead_s_mean'] * 1e3:.0f} ms more per record (max {r['overhead_s_max'] * 1e3:.0f}), "
                      f"worker start (imports, kernel load) {', '.join(f'{x:.1f}' for x in r['worker_start_s']) or '-'} s, "
                      f"load {r['load_average']:.2f}" + (f"; {r['failed']} FAILED: {r['errors'][0]}" if r["failed"] else ""),
                      flush=True)
    names = [p.stem for p in paths]
    by = {}
    for r in results:               # the fastest run of each configuration
        k = (r["backend"], r["workers"])
        if k not in by or r["wall_s"] < by[k]["wall_s"]:
            by[k] = r
    print(f"\nsummary (fastest of {args.repeat} run(s) each; reference: the local pool at the same worker count, "
          f"measured in this run)")
    for w in workers:
        lo, ry = by.get(("local", w)), by.get(("ray", w))
        if lo and ry:
            per_record = (ry["wall_s"] - lo["wall_s"]) * w / lo["diagnosed"]
            ry["overhead_vs_local_s"] = per_record
            ry["identical_to_local"] = same_diagnoses(Path(lo["dir"]), Path(ry["dir"]), names)
            print(f"  {w} worker(s): ray/local throughput {ry['records_per_hour'] / lo['records_per_hour']:.3f}; Ray costs "
                  f"{per_record:+.2f} s per record from the wall times, {ry['overhead_s_mean'] - lo['overhead_s_mean']:+.3f} s "
                  f"from the driver's waits; diagnoses identical: {'yes' if ry['identical_to_local'] else 'NO'}")
    for b in backends:
        one, two = by.get((b, 1)), by.get((b, 2))
        if one and two:
            print(f"  {b}: 2 workers / 1 worker throughput {two['records_per_hour'] / one['records_per_hour']:.2f}")
    print(f"  machine load average now {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)")
    if args.json:
        Path(args.json).write_text(json.dumps({"args": vars(args), "results": results,
                                               "best": {f"{b}-{w}": r for (b, w), r in by.items()}}, indent=2))


if __name__ == "__main__":
    main()
