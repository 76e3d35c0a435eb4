"""Soak benchmark of the HIL service (issue 11): ``hydrohil serve`` at 1 kHz for a long time under
500 REST requests/s and 1 kHz of CAN each way (socketcand, separate client processes) with a
recording on. Targets: resident memory growth <= 5 MB (service and engine processes, from the end of
the warm-up to the end), 0 lost or duplicated recording rows, 0 lost CAN commands, and overruns per
10 000 ticks against a bare loop (same deadlines, same priority, no work) measured before and after
in the same run.

    .venv/bin/python benchmarks/bench_soak.py [--duration 1800] [--robot hydrolek] [--rps 500]
                                              [--format parquet|csv] [--bare S] [--json]

A benchmark, not a test: the issue's 30 minutes are the default; ``--duration 60`` checks that it
works.
"""

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from hil_server.bench_loop import bare_loop, feedback_rate_for, finish_load, start_load
from hil_server.launcher import ServerProcess


def rss_mib(pid: int) -> float:
    with open(f"/proc/{pid}/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmRSS for pid {pid}")


def recording_times(path: Path, fmt: str) -> np.ndarray:
    if fmt == "parquet":
        import pyarrow.parquet as pq

        return pq.read_table(path, columns=["time"]).column("time").to_numpy()
    import pyarrow.csv as pcsv

    return pcsv.read_csv(path, convert_options=pcsv.ConvertOptions(include_columns=["time"])).column("time").to_numpy()


def soak(duration: float, robot: str, rps: float, fmt: str, bare_s: float, workdir: Path) -> dict:
    bare1 = bare_loop(bare_s)
    warm_s = min(60.0, max(20.0, 0.1 * duration))   # allocator pools and TCP buffers settle in ~15 s
    samples = []
    with ServerProcess("--feedback-rate", f"{feedback_rate_for(robot):g}", "--log-level", "warning", robot=robot,
                       can="socketcand", workdir=workdir) as srv:
        time.sleep(2.0)
        engine_pid = srv.rest.health()["engine"]["pid"]
        rec = srv.rest.request("POST", "/api/v1/recordings", {"name": "soak", "format": fmt})
        before_loop = srv.rest.state()["loop"]
        before_frames = srv.rest.health()["can"]["frames"]
        rest, canp = start_load(srv, duration, rps)
        t0 = time.monotonic()
        while rest.poll() is None or canp.poll() is None:
            samples.append((time.monotonic() - t0, rss_mib(srv.proc.pid), rss_mib(engine_pid)))
            time.sleep(min(5.0, max(1.0, duration / 100)))
        samples.append((time.monotonic() - t0, rss_mib(srv.proc.pid), rss_mib(engine_pid)))
        rest_res, can_res = finish_load(rest, canp, 120)
        after_loop = srv.rest.state()["loop"]
        after_frames = srv.rest.health()["can"]["frames"]
        done = srv.rest.request("POST", "/api/v1/recordings/stop")
        health = srv.rest.health()
        assert health["engine"]["restarts"] == 0 and health["status"] == "ok", health
        path = srv.recordings / done["file"]
    bare2 = bare_loop(bare_s)

    t = recording_times(path, fmt)
    dt = np.diff(t)
    ideal = 1.0 / after_loop["rate_hz"]
    rows_expected = int(round((t[-1] - t[0]) / ideal)) + 1
    s = np.array(samples)
    base = s[s[:, 0] >= warm_s][0] if np.any(s[:, 0] >= warm_s) else s[0]
    ticks = after_loop["ticks"] - before_loop["ticks"]
    overruns = after_loop["overruns"] - before_loop["overruns"]
    bare_over = (bare1["overruns"] + bare2["overruns"]) / 2.0
    bare_ticks = (bare1["ticks"] + bare2["ticks"]) / 2.0
    commands = after_frames.get("rx.command", 0) - before_frames.get("rx.command", 0)
    return {
        "robot": robot, "duration_s": duration, "warm_up_s": warm_s, "recording_format": fmt, "recording_id": rec["id"],
        "rss_mib": {"service": {"after_warm_up": base[1], "end": s[-1, 1], "growth": s[-1, 1] - base[1],
                                "max_growth": float(s[s[:, 0] >= base[0], 1].max() - base[1])},
                    "engine": {"after_warm_up": base[2], "end": s[-1, 2], "growth": s[-1, 2] - base[2],
                               "max_growth": float(s[s[:, 0] >= base[0], 2].max() - base[2])}},
        "recording": {"rows": int(len(t)), "rows_reported": done["rows"], "complete": done["complete"],
                      "lost": max(0, rows_expected - len(t)),
                      "duplicated": int(np.count_nonzero(dt < 0.5 * ideal)),
                      "gaps": int(np.count_nonzero(dt > 1.5 * ideal))},
        "loop": {"ticks": ticks, "overruns": overruns, "overruns_per_10k_ticks": 1e4 * overruns / max(ticks, 1),
                 "bare_loop_overruns_per_10k_ticks": 1e4 * bare_over / max(bare_ticks, 1),
                 "overrun_ratio_to_bare_loop": (overruns + 1) / (bare_over * ticks / max(bare_ticks, 1) + 1),
                 "lateness_us": after_loop["lateness_us"], "realtime_priority": after_loop["realtime_priority"],
                 "bare_loop": [bare1, bare2]},
        "rest_load": rest_res,
        "can_load": {**can_res, "commands_applied": commands, "commands_lost": can_res["sent"] - commands},
        "targets": {"rss_growth_mib": 5.0, "lost_or_duplicated_rows": 0},
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=1800.0, help="loaded seconds (default 1800 = 30 min)")
    ap.add_argument("--robot", default="hydrolek")
    ap.add_argument("--rps", type=float, default=500.0, help="REST requests per second")
    ap.add_argument("--format", choices=["parquet", "csv"], default="parquet", help="recording format")
    ap.add_argument("--bare", type=float, default=None, help="seconds of each bare-loop phase (default 5 %% of "
                                                                "--duration, 10-60 s)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    bare_s = args.bare or min(60.0, max(10.0, 0.05 * args.duration))
    with tempfile.TemporaryDirectory(prefix="hydrohil-soak-") as tmp:
        res = soak(args.duration, args.robot, args.rps, args.format, bare_s, Path(tmp))
    if args.json:
        print(json.dumps(res, indent=2, default=float))
        return
    r, lp, rec, rl, cl = res["rss_mib"], res["loop"], res["recording"], res["rest_load"], res["can_load"]
    lat = lp["lateness_us"]
    print(f"soak: {args.robot} at 1 kHz for {args.duration:.0f} s under {rl['rps']:.0f} REST req/s and "
          f"{cl['tx_fps']:.0f}/{cl['rx_fps']:.0f} CAN frames/s in/out, recording {args.format}")
    print(f"  RSS growth after {res['warm_up_s']:.0f} s warm-up: service {r['service']['growth']:+.2f} MiB "
          f"(max {r['service']['max_growth']:+.2f}), engine {r['engine']['growth']:+.2f} MiB "
          f"(max {r['engine']['max_growth']:+.2f}); target <= 5")
    print(f"  recording: {rec['rows']} rows, {rec['lost']} lost, {rec['duplicated']} duplicated, {rec['gaps']} gaps, "
          f"complete={rec['complete']}")
    print(f"  CAN commands: {cl['sent']} sent, {cl['commands_applied']} applied ({cl['commands_lost']} lost)")
    print(f"  loop: {lp['ticks']} ticks, {lp['overruns']} overruns = {lp['overruns_per_10k_ticks']:.2f} per 10k; "
          f"bare loop {lp['bare_loop_overruns_per_10k_ticks']:.2f} per 10k; ratio {lp['overrun_ratio_to_bare_loop']:.2f}; "
          f"lateness p50 {lat['p50']:.1f} us, p99 {lat['p99']:.1f} us, max {lat['max']:.0f} us")
    print(f"  REST: {rl['requests']} requests, {rl['errors']} errors, p50 {rl['p50_ms']:.1f} ms, p99 {rl['p99_ms']:.1f} ms")


if __name__ == "__main__":
    main()
