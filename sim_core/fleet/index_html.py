"""index.html: the fleet at a glance. A table of the records (verdict, named effects with parameters
and intervals, fit before and after, time, error, a link to each record's report), then one section
per effect: the records that name it and each parameter across the records, plotted over time when
the records are dated (in record order otherwise), so a growing deadband or leakage stands out.
"""

from __future__ import annotations

import base64
import html
import io
import math

from .rows import days

e = html.escape


def _fmt(v, digits=4) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}g}" if math.isfinite(v) else str(v)
    return e(str(v))


def _unit(u: str | None, paren: bool = False) -> str:
    """' V' (or ' (V)'), escaped; nothing for a dimensionless or unknown unit."""
    if not u or u == "-":
        return ""
    return f" ({e(u)})" if paren else f" {e(u)}"


def _png(fig) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def parameter_plot(view: dict, param: str, order: list[str]) -> str:
    """The parameter on every record that has it: filled with its 95 % interval where the record names
    the effect, hollow where it was only fitted as a candidate; against the date when all are dated."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.pyplot as plt

    pts = view["params"][param]
    u = view["units"].get(param)
    unit = f" {u}" if u and u != "-" else ""
    dated = all(p["date"] for p in pts)
    fig, ax = plt.subplots(figsize=(9, 3.0))
    if dated:
        from datetime import datetime

        x = [datetime.fromisoformat(p["date"]) for p in pts]
    else:
        x = [order.index(p["record"]) for p in pts]
    for named, style in ((True, dict(fmt="o", color="tab:blue", label="named (95 % interval)")),
                         (False, dict(fmt="o", mfc="none", color="0.5", label="fitted, not named"))):
        idx = [i for i, p in enumerate(pts) if p["named"] == named]
        if not idx:
            continue
        y = [pts[i]["value"] for i in idx]
        err = None
        if named:
            lo = [pts[i]["value"] - (pts[i]["ci95"] or [pts[i]["value"]] * 2)[0] for i in idx]
            hi = [(pts[i]["ci95"] or [pts[i]["value"]] * 2)[1] - pts[i]["value"] for i in idx]
            err = [lo, hi]
        ax.errorbar([x[i] for i in idx], y, yerr=err, capsize=3, lw=0.8, **style)
    tr = view["trend"].get(param)
    if tr and dated:
        from datetime import datetime

        named = [(days(p["date"]), p["value"]) for p in pts if p["named"] and p["date"]]
        t0 = min(t for t, _ in named)
        t1 = max(t for t, _ in named)
        mean_t = sum(t for t, _ in named) / len(named)
        mean_y = sum(y for _, y in named) / len(named)
        ends = [t0, t1]
        ax.plot([datetime.fromtimestamp(t * 86400.0) for t in ends],
                [mean_y + tr["per_day"] * (t - mean_t) for t in ends], "--", color="tab:red", lw=1.0,
                label=f"trend {tr['per_day']:+.3g}{unit} per day")
    if dated:
        ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(ax.xaxis.get_major_locator()))
        ax.set_xlabel("record date")
    else:
        ax.set_xticks(range(len(order)))
        ax.set_xticklabels(order, rotation=45, ha="right", fontsize=7)
        ax.set_xlabel("record")
    ax.set_ylabel(f"{view['label']} {param}" + (f" ({u})" if unit else ""))
    ax.legend(fontsize=8, loc="best")
    return _png(fig)


def index_html(data: dict) -> str:
    rows = data["records"]
    t = data["totals"]
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>HydroHIL fleet diagnosis: {e(data['robot'])}</title>",
             "<style>body{font-family:sans-serif;max-width:1200px;margin:auto;padding:1em}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:2px 6px;font-size:90%;vertical-align:top}th{background:#f4f4f4}"
             ".failed{color:#a00}.discrepancy{color:#a50}.ok{color:#070}img{max-width:100%}</style></head><body>"]
    parts.append(f"<h1>Fleet diagnosis: {t['records']} records on {e(data['robot'])}</h1>")
    verdicts = ", ".join(f"{n} {e(v)}" for v, n in sorted(t["verdicts"].items()))
    parts.append(f"<p>{t['diagnosed']} diagnosed, {t['unchanged']} unchanged since the last run (not re-diagnosed), "
                 f"<span class='failed'>{t['failed']} failed</span>. Verdicts: {verdicts or 'none'}. "
                 f"Generated {e(data['generated'])}" + (f" on {e(data['backend'])}" if data["backend"] else "") + ".</p>")
    joints: list[str] = []
    for r in rows:
        for j in r["fit_before"]:
            if j not in joints:
                joints.append(j)
    parts.append("<h2>Records</h2><table><tr><th>record</th><th>date</th><th>status</th><th>verdict</th>"
                 "<th>named effects (95 % interval)</th>"
                 + "".join(f"<th>fit {e(j)} before &rarr; after (%)</th>" for j in joints)
                 + "<th>time (s)</th></tr>")
    for r in rows:
        name = f"<a href='{e(r['report'])}'>{e(r['record'])}</a>" if r["report"] else e(r["record"])
        if r["status"] == "failed":
            parts.append(f"<tr><td>{name}</td><td>{_fmt(r['date'])}</td><td class='failed'>failed</td>"
                         f"<td colspan='{2 + len(joints)}' class='failed'>{e(r['error'] or '')}</td>"
                         f"<td>{_fmt(r['seconds'])}</td></tr>")
            continue
        eff = "<br>".join(
            f"<b>{e(x['label'])}</b>: " + ", ".join(f"{e(k)}={_fmt(v)} [{_fmt(x['ci95'][k][0])}, {_fmt(x['ci95'][k][1])}]"
                                                    + _unit(x.get("units", {}).get(k)) for k, v in x["params"].items())
            + (" <i>(ambiguous)</i>" if x["ambiguous"] else "")
            + "".join(f" <i>(as well: {e(p)} beyond its declared range)</i>" for p in x.get("as_well_beyond_range", []))
            for x in r["effects"]) or "-"
        fits = "".join(f"<td>{_fmt(r['fit_before'].get(j), 3)} &rarr; {_fmt(r['fit_after'].get(j), 3)}</td>" for j in joints)
        cls = "discrepancy" if r["verdict"] == "discrepancy" else "ok"
        parts.append(f"<tr><td>{name}</td><td>{_fmt(r['date'])}</td><td>{e(r['status'])}</td>"
                     f"<td class='{cls}'>{e(r['verdict'] or '')}</td><td>{eff}</td>{fits}<td>{_fmt(r['seconds'])}</td></tr>")
    parts.append("</table>")
    order = [r["record"] for r in rows]
    parts.append("<h2>Effects across the fleet</h2>")
    if not data["effects"]:
        parts.append("<p>No record names an effect.</p>")
    n_ok = t["records"] - t["failed"]
    for view in data["effects"]:
        parts.append(f"<h3>{e(view['label'])}: named in {len(view['records'])} of {n_ok} records</h3>"
                     f"<p>{e(', '.join(view['records']))}</p>")
        for k, pts in view["params"].items():
            tr = view["trend"].get(k)
            if tr:
                word = "rises" if tr["rising"] else "falls" if tr["falling"] else "shows no significant trend"
                parts.append(f"<p>{e(k)} {word}: {tr['per_day']:+.4g}{_unit(view['units'].get(k))} per day (95 %: {_fmt(tr['ci95'][0])} .. "
                             f"{_fmt(tr['ci95'][1])}) over {tr['records']} dated records that name it.</p>")
            parts.append(f"<figure><img src='data:image/png;base64,{parameter_plot(view, k, order)}'>"
                         f"<figcaption>{e(view['label'])} {e(k)}{_unit(view['units'].get(k), paren=True)} across the "
                         f"records</figcaption></figure>")
            parts.append("<details><summary>values</summary><table><tr><th>record</th><th>date</th>"
                         f"<th>{e(k)}{_unit(view['units'].get(k), paren=True)}</th>"
                         "<th>95 % interval</th><th>gain (points)</th><th>named</th></tr>"
                         + "".join(f"<tr><td>{e(p['record'])}</td><td>{_fmt(p['date'])}</td><td>{_fmt(p['value'])}</td>"
                                   f"<td>{'[' + _fmt(p['ci95'][0]) + ', ' + _fmt(p['ci95'][1]) + ']' if p['ci95'] else '-'}</td>"
                                   f"<td>{_fmt(p['gain'])}</td><td>{'yes' if p['named'] else 'no'}</td></tr>" for p in pts)
                         + "</table></details>")
    parts.append("</body></html>")
    return "".join(parts)
