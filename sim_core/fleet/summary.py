"""fleet.json (everything, the contract) and fleet.csv (one line per record, for a spreadsheet).

fleet.csv columns: record, source, date, status, verdict, effects (';'-separated effect@joint), seconds,
error, then fit_before_<joint> and fit_after_<joint> (angle NRMSE %, validation part) per diagnosed
joint, then per named effect parameter ``<effect>@<joint>.<param>`` with ``..._ci95_lo`` and
``..._ci95_hi`` (empty where the record does not name the effect).
"""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

from .rows import STATUSES, effect_views, with_units

CSV_FIXED = ("record", "source", "date", "status", "verdict", "effects", "seconds", "error")


def fleet_data(rows: list[dict], *, robot: str, backend: str | None, generated: str, wall_s: float | None,
               prismatic: frozenset[str] = frozenset()) -> dict:
    """The fleet.json content; ``prismatic``: the robot's prismatic joints (their parameters are in m, N)."""
    rows = with_units(rows, prismatic)
    totals = {s: sum(r["status"] == s for r in rows) for s in STATUSES}
    verdicts = {}
    for r in rows:
        if r["verdict"]:
            verdicts[r["verdict"]] = verdicts.get(r["verdict"], 0) + 1
    return {"robot": robot, "generated": generated, "backend": backend, "records": rows,
            "effects": effect_views(rows, prismatic),
            "totals": {"records": len(rows), **totals, "verdicts": verdicts,
                       "wall_s": None if wall_s is None else round(wall_s, 2)}}


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _num(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if not math.isfinite(v) else f"{v:.8g}"
    return str(v)


def _finite(v):
    """JSON has no inf or nan: null."""
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def csv_text(data: dict) -> str:
    rows = data["records"]
    joints: list[str] = []
    for r in rows:
        for j in list(r["fit_before"]) + list(r["fit_after"]):
            if j not in joints:
                joints.append(j)
    params: list[tuple[str, str]] = []
    for view in data["effects"]:
        for k in view["params"]:
            params.append((view["label"], k))
    header = list(CSV_FIXED)
    for j in joints:
        header += [f"fit_before_{j}", f"fit_after_{j}"]
    for lab, k in params:
        header += [f"{lab}.{k}", f"{lab}.{k}_ci95_lo", f"{lab}.{k}_ci95_hi"]
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        line = [r["record"], r["source"], r["date"] or "", r["status"], r["verdict"] or "",
                ";".join(e["label"] for e in r["effects"]), _num(r["seconds"]), (r["error"] or "").replace("\n", " ")]
        for j in joints:
            line += [_num(r["fit_before"].get(j)), _num(r["fit_after"].get(j))]
        named = {e["label"]: e for e in r["effects"]}
        for lab, k in params:
            e = named.get(lab)
            if e is None or k not in e["params"]:
                line += ["", "", ""]
            else:
                lo, hi = e["ci95"].get(k, [None, None])
                line += [_num(e["params"][k]), _num(lo), _num(hi)]
        w.writerow(line)
    return buf.getvalue()


def write_summary(out_dir: Path, data: dict) -> dict[str, Path]:
    """fleet.json and fleet.csv (each replaced whole, so a reader never sees half a file)."""
    paths = {"json": out_dir / "fleet.json", "csv": out_dir / "fleet.csv"}
    _write_atomic(paths["json"], json.dumps(_finite(data), indent=2, allow_nan=False))
    _write_atomic(paths["csv"], csv_text(data))
    return paths
