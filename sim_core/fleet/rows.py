"""The fleet summary's content: one row per record, and one view per effect across the records.

A row carries the verdict, the named effects with their parameters and 95 % intervals, the angle
fit (NRMSE %, validation part) of every diagnosed joint before and after the extension, the time
the diagnosis took, or the record's error. It also keeps every candidate's first-round fit, so the
view of an effect can show its fitted parameter on the records where it was not (yet) accepted: a
deadband that grows shows up as a rising line that crosses into "named" at some date.
"""

from __future__ import annotations

import math
from datetime import datetime

STATUSES = ("diagnosed", "unchanged", "failed")


def label(effect: str, joint: str | None) -> str:
    return f"{effect}@{joint}" if joint else effect


def record_row(name: str, source: str, date: str | None, status: str, diag: dict | None, *, seconds: float | None,
               report: str | None = None, error: str | None = None, reason: list[str] | None = None,
               notes: list[str] | None = None) -> dict:
    row = {"record": name, "source": source, "date": date, "status": status, "verdict": None, "effects": [],
           "fit_before": {}, "fit_after": {}, "seconds": None if seconds is None else round(float(seconds), 2),
           "report": report, "error": error, "rerun_because": reason or [], "notes": notes or [],
           "candidate_fits": {}}
    if diag is None:
        return row
    targets = diag.get("data", {}).get("targets") or list(diag["baseline"]["fit"])
    row["verdict"] = diag["verdict"]
    row["effects"] = [{"effect": s["effect"], "joint": s["joint"], "label": label(s["effect"], s["joint"]),
                       "params": s["params"], "ci95": s["ci95"], "gain": s["gain"],
                       "ambiguous": bool(s.get("ambiguous", False)),
                       # a rig's estimated parameters that explain the record as well beyond their declared ranges
                       "as_well_beyond_range": [r["parameter"] for r in s.get("as_well_beyond_range", [])]}
                      for s in diag["selected"]]
    row["fit_before"] = {j: diag["baseline"]["fit"][j] for j in targets if j in diag["baseline"]["fit"]}
    row["fit_after"] = {j: diag["extended"]["fit"][j] for j in targets if j in diag["extended"]["fit"]}
    row["candidate_fits"] = {label(c["effect"], c["joint"]): {"params": c["params"], "gain": c["gain"]}
                             for c in diag["candidates"] if c["round"] == 1}
    return row


def effect_views(rows: list[dict], prismatic: frozenset[str] = frozenset()) -> list[dict]:
    """Per effect (and joint) named in at least one record: which records show it, and each
    parameter across the records (named there, or only fitted as a candidate) with its unit (on the
    joint's kind: ``prismatic`` names the prismatic joints), and its trend over time where the
    records are dated."""
    ok = [r for r in rows if r["status"] != "failed"]
    named: dict[str, tuple[str, str | None]] = {}
    for r in ok:
        for e in r["effects"]:
            named.setdefault(e["label"], (e["effect"], e["joint"]))
    views = []
    for lab, (effect, joint) in sorted(named.items()):
        showing = [r["record"] for r in ok if any(e["label"] == lab for e in r["effects"])]
        params: dict[str, list[dict]] = {}
        for r in ok:
            e = next((e for e in r["effects"] if e["label"] == lab), None)
            if e is not None:
                for k, v in e["params"].items():
                    params.setdefault(k, []).append({"record": r["record"], "date": r["date"], "value": v,
                                                     "ci95": e["ci95"].get(k), "gain": e["gain"], "named": True})
                continue
            c = r["candidate_fits"].get(lab)
            if c is not None:
                for k, v in c["params"].items():
                    if v is not None:
                        params.setdefault(k, []).append({"record": r["record"], "date": r["date"], "value": v,
                                                         "ci95": None, "gain": c["gain"], "named": False})
        views.append({"effect": effect, "joint": joint, "label": lab, "records": showing,
                      "share": len(showing) / len(ok) if ok else 0.0, "params": params,
                      "units": {k: unit(effect, k, joint in prismatic) for k in params},
                      "trend": {k: trend(pts) for k, pts in params.items() if trend(pts) is not None}})
    return views


def unit(effect: str, param: str, prismatic: bool = False) -> str:
    """The parameter's SI unit as the effect declares it; a unit declared for both joint kinds
    ('N m or N') resolved to the joint's: the first for a revolute joint, the second for a prismatic one."""
    from ..effects import EFFECTS

    eff = EFFECTS.get(effect)
    u = next((p.unit for p in getattr(eff, "PARAMETERS", ()) if p.name == param), "")
    kinds = u.split(" or ")
    return kinds[1] if prismatic and len(kinds) == 2 else kinds[0] if len(kinds) == 2 else u


def with_units(rows: list[dict], prismatic: frozenset[str] = frozenset()) -> list[dict]:
    """The rows with each named effect's parameter units (``units``: param -> unit) added."""
    return [{**r, "effects": [{**e, "units": {k: unit(e["effect"], k, e["joint"] in prismatic) for k in e["params"]}}
                              for e in r["effects"]]} for r in rows]


def days(date: str) -> float:
    return datetime.fromisoformat(date).timestamp() / 86400.0


def trend(points: list[dict]) -> dict | None:
    """Least-squares slope of a parameter over time on the records that name the effect (at least 3,
    on 2 or more dates): per day, with its 95 % interval."""
    pts = [(days(p["date"]), p["value"]) for p in points if p["named"] and p["date"]]
    if len(pts) < 3 or len({t for t, _ in pts}) < 2:
        return None
    from scipy import stats

    t = [a for a, _ in pts]
    y = [b for _, b in pts]
    fit = stats.linregress(t, y)
    n = len(pts)
    half = float(stats.t.ppf(0.975, n - 2) * fit.stderr) if n > 2 and math.isfinite(fit.stderr) else math.inf
    return {"per_day": float(fit.slope), "ci95": [float(fit.slope - half), float(fit.slope + half)],
            "records": n, "rising": bool(fit.slope - half > 0), "falling": bool(fit.slope + half < 0)}
