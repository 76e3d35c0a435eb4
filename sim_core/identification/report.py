"""The diagnosis report: ``diagnosis.json`` (the contract), ``report.html`` (plots and reasoning) and
``extended.toml`` (the improved model as a parameter/effect file).

Plots per diagnosed joint: measured vs baseline vs extended angle; the residuals with the segments
that carry the named effect's evidence highlighted; residual autocorrelation and the input
cross-correlations with their 99 % bands; the residual spectrum and the transfer estimate.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path

import numpy as np

from .. import background_import
from ..dataset import column_unit
from ..effects import EFFECTS
from . import beyond_range, command_hold, conditional, detectability
from .closed_loop import RESTART_TAUS
from .diagnosis import Diagnosis
from ..params_file import overrides, write_params
from .record import start_position
from .residual_tests import autocorrelation
from .side_by_side import SideBySide, held

# where each effect typically shows (the legend of the highlighted evidence)
EVIDENCE = {
    "deadband": "small commands", "hysteresis": "holds after motion", "leakage": "holds",
    "delay": "steps and reversals", "spool_lag": "steps and reversals", "backlash": "reversals",
    "coulomb_friction": "reversals", "joint_compliance": "after steps", "line_dynamics": "after steps",
    "bulk_modulus": "after steps", "valve_asymmetry": "negative commands", "area_ratio": "negative commands",
    "payload": "raising and lowering", "flow_saturation": "large commands", "sensor_offset": "everywhere",
    "sensor_gain": "large angles", "pump_limit": "large commands",
}


def evidence_mask(y_base: np.ndarray, y_ext: np.ndarray, rate: float, share: float = 0.4) -> np.ndarray:
    """Samples where the extension changes the prediction most (angle or velocity): where the record
    carries the named effect's evidence. Smoothed over 0.25 s; above ``share`` of the largest change."""
    from scipy.ndimage import uniform_filter1d

    from .metrics import velocity

    w = max(1, int(round(0.25 * rate)))
    mask = np.zeros(y_base.size, dtype=bool)
    for a, b in ((y_base, y_ext), (velocity(y_base, 1.0 / rate), velocity(y_ext, 1.0 / rate))):
        dlt = uniform_filter1d(np.abs(a - b), w)
        top = float(dlt.max())
        if top > 0:
            mask |= dlt >= share * top
    return mask


def _spans(mask: np.ndarray, t: np.ndarray):
    if not mask.any():
        return []
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return [(t[a], t[min(b, t.size - 1)]) for a, b in zip(starts, stops)]


# fixed margins (inches) on every figure: laid out once, instead of measured by a second drawing pass
# (``bbox_inches="tight"`` costs each figure about as much again as drawing it). They hold tick labels
# of up to six characters: linear axes switch to an offset exponent outside 0.01-10^4 (``SCI_LIMITS``)
# instead of writing -0.0025 in full.
MARGINS_IN = {"left": 0.9, "right": 0.12, "bottom": 0.5, "top": 0.3, "between": 0.9}
SCI_LIMITS = (-2, 4)


def _png(fig) -> str:
    layout(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def layout(fig) -> None:
    """Place a figure of one row of panels by ``MARGINS_IN`` (no drawing needed)."""
    from matplotlib.ticker import ScalarFormatter

    for ax in fig.axes:
        if isinstance(ax.yaxis.get_major_formatter(), ScalarFormatter):
            ax.ticklabel_format(axis="y", style="sci", scilimits=SCI_LIMITS)
    w, h = fig.get_size_inches()
    m = MARGINS_IN
    cols = max(1, len(fig.axes))         # every figure here is one row of panels
    panel = (w - m["left"] - m["right"] - (cols - 1) * m["between"]) / cols
    fig.subplots_adjust(left=m["left"] / w, right=1 - m["right"] / w, bottom=m["bottom"] / h, top=1 - m["top"] / h,
                        wspace=m["between"] / panel)


# drawn in this order, the slowest first (the spectrum's log axis lays out the most text), so that
# the last figure to start is a short one; the page shows them in its own order
FIGURES = ("spectrum", "correlation", "residuals", "angles")


def all_plots(d: Diagnosis, joints: list[str], workers: int = 0) -> dict[str, dict[str, str]]:
    """Every figure of every joint, drawn side by side in forked processes (Agg drawing is single-threaded
    and a report's figures are independent: about half the time on two cores); ``workers`` 0: the CPU
    count, 1: here."""
    jobs = [(j, name) for name in FIGURES for j in joints]
    _pyplot()                      # imported once, before any fork: the children inherit it
    with SideBySide(workers) as side:
        pngs = side.map(_forked_figure, jobs, hold=d)   # the children hold the diagnosis from their fork
    out: dict[str, dict[str, str]] = {j: {} for j in joints}
    for (j, name), png in zip(jobs, pngs):
        out[j][name] = png
    return out


def _forked_figure(job) -> str:
    return _figure(held(), *job)


def preload() -> None:
    """Start importing the plotting library in the background (:mod:`sim_core.background_import`):
    a caller that will draw a report calls this before the diagnosis, whose first second leaves a
    core free."""
    background_import.start(_load_pyplot)


def _pyplot():
    background_import.wait()       # not while a preload may still be setting the backend
    return _load_pyplot()


def _load_pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _figure(d: Diagnosis, joint: str, name: str) -> str:
    return _DRAW[name](_pyplot(), d, joint)


def _traces(d: Diagnosis, joint: str):
    """The validation record and the joint's measured, baseline and extended angles (None where absent)."""
    rec = d.validation
    return rec, rec.angles[joint], d.baseline_out.angles.get(joint), d.extended_out.angles.get(joint)


def _position(d: Diagnosis, joint: str) -> tuple[str, str]:
    """What the joint's position is called and its unit: ('position', 'm') on a prismatic joint,
    ('angle', 'rad') on a revolute one."""
    unit = column_unit(f"q_{joint}", d.baseline_spec)
    return ("position", unit) if unit == "m" else ("angle", unit)


def _fig_angles(plt, d: Diagnosis, joint: str) -> str:
    """Measured vs baseline vs extended angle, the validation part shaded."""
    rec, y, yb, ye = _traces(d, joint)
    t = rec.time
    t_val = t[d.split]
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(t, y, "k", lw=0.8, label="measured")
    if yb is not None:
        ax.plot(t, yb, color="tab:red", lw=0.8, label=f"baseline ({d.baseline_fits[joint]['angle']:.1f} %)")
    if ye is not None and d.selected:
        ax.plot(t, ye, color="tab:blue", lw=0.8, ls="--", label=f"extended ({d.extended_fits[joint]['angle']:.1f} %)")
    ax.axvspan(t_val, t[-1], color="0.92", zorder=0, label="validation")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("{} {} ({})".format(joint, *_position(d, joint)))
    ax.legend(loc="upper right", fontsize=8, ncol=4)
    return _png(fig)


def _fig_residuals(plt, d: Diagnosis, joint: str) -> str:
    """Angle residuals with the evidence of the named effect highlighted."""
    rec, y, yb, ye = _traces(d, joint)
    t = rec.time
    t_val = t[d.split]
    fig, ax = plt.subplots(figsize=(10, 3.0))
    if yb is not None:
        ax.plot(t, y - yb, color="tab:red", lw=0.7, label="measured - baseline")
    if ye is not None and d.selected:
        ax.plot(t, y - ye, color="tab:blue", lw=0.7, label="measured - extended")
    sel = [s for s in d.selected if s["joint"] in (joint, None)] or d.selected
    if sel and yb is not None and ye is not None:
        s = sel[0]
        mask = evidence_mask(yb, ye, rec.rate)
        for a, b in _spans(mask, t)[:400]:
            ax.axvspan(a, b, color="gold", alpha=0.3, lw=0)
        ax.plot([], [], color="gold", alpha=0.5, lw=6,
                label=f"evidence: where {s['effect']} changes the prediction most ({EVIDENCE.get(s['effect'], '')})")
    ax.axvline(t_val, color="0.5", lw=0.8, ls=":")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("{} residual ({})".format(*_position(d, joint)))
    ax.legend(loc="upper right", fontsize=8)
    return _png(fig)


def _fig_correlation(plt, d: Diagnosis, joint: str) -> str:
    """Velocity residual autocorrelation and the cross-correlations with the input, with their bands."""
    from .metrics import velocity

    rec, y, yb, ye = _traces(d, joint)
    tests = d.tests
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.0))
    for state, color in (("baseline", "tab:red"), ("extended", "tab:blue")):
        tj = tests.get(state, {}).get(joint)
        if not tj or (state == "extended" and not d.selected):
            continue
        w = velocity(y, rec.dt)[d.split:]
        sim = yb if state == "baseline" else ye
        r = w - velocity(sim, rec.dt)[d.split:]
        dec = max(1, int(round(0.075 * rec.rate)))
        acf = autocorrelation(r[::dec], 25)
        axes[0].stem(np.arange(26) * dec / rec.rate, acf, linefmt=color, markerfmt=" ", basefmt=" ", label=state)
        ind = tj["_independence"].get("u")
        if ind:
            axes[1].plot(ind["lags_s"], ind["r"], color=color, lw=0.9, label=f"{state}: R(r, u)")
            axes[1].axhline(ind["band"], color=color, ls=":", lw=0.8)
            axes[1].axhline(-ind["band"], color=color, ls=":", lw=0.8)
        ind = tj["_independence"].get("|u|")
        if ind:
            axes[1].plot(ind["lags_s"], ind["r"], color=color, lw=0.7, ls="--", label=f"{state}: R(r, |u|)")
    n_dec = max(1, (rec.n - d.split) // max(1, int(round(0.075 * rec.rate))))
    b = 2.576 / math.sqrt(n_dec)
    axes[0].axhspan(-b, b, color="0.9", zorder=0)
    axes[0].set_title("velocity residual autocorrelation (99 % band)", fontsize=9)
    axes[0].set_xlabel("lag (s)")
    axes[1].set_title("cross-correlation with the input (99 % bands)", fontsize=9)
    axes[1].set_xlabel("lag (s)")
    for a in axes:
        a.legend(fontsize=7)
    return _png(fig)


def _fig_spectrum(plt, d: Diagnosis, joint: str) -> str:
    """Velocity residual spectrum and the transfer estimate."""
    rec = d.validation
    tests = d.tests
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.0))
    for state, color in (("baseline", "tab:red"), ("extended", "tab:blue")):
        tj = tests.get(state, {}).get(joint)
        if not tj or (state == "extended" and not d.selected):
            continue
        f, p = tj["_spectrum"]
        axes[0].semilogy(f, p, color=color, lw=0.8, label=state)
        H = tj.get("_etfe")
        if H:
            ff = np.array(H["f"])
            keep = (ff > 0) & (ff <= min(20.0, 0.45 * rec.rate))
            axes[1].plot(ff[keep], np.array(H["mag_db"])[keep], color=color, lw=0.8, label=f"{state} |H| (dB)")
    axes[0].set_title("velocity residual spectrum", fontsize=9)
    axes[0].set_xlabel("Hz")
    axes[1].set_title("measured / simulated velocity (transfer estimate)", fontsize=9)
    axes[1].set_xlabel("Hz")
    for a in axes:
        a.legend(fontsize=7)
    return _png(fig)


_DRAW = {"angles": _fig_angles, "residuals": _fig_residuals, "correlation": _fig_correlation,
         "spectrum": _fig_spectrum}


def _fmt(v, digits=4):
    if v is None:
        return "-"
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.{digits}g}"
    return html.escape(str(v))


def _detectable_html(det: dict, e) -> str:
    """What the record could have shown of each effect not named (detectability.shown)."""
    rows = det.get("effects") or []
    if not rows:
        return ""
    out = [f"<h2>What this record can show</h2><p>Each effect not named, put into the final model and the calibration "
           f"refitted beside it to first order: the smallest magnitude whose expected gain reaches "
           f"{det.get('threshold_points', 2):g} points (a named effect: the same on the model without it). An "
           f"estimate; a magnitude under it would not have been named on this record.</p><table><tr><th>effect</th>"
           f"<th>joint</th><th>shows from</th><th>far end of the range</th></tr>"]
    for r in rows:
        unit = f" {r['unit']}" if r["unit"] else ""
        top = ("not within the range" if r["shows_from"] is None
               else f"{r['parameter']} = {_fmt(r['shows_from'])}{unit}{detectability.from_spec(r)}")
        out.append(f"<tr><td>{e(r['effect'] + (' (named)' if r.get('named') else ''))}</td><td>{e(str(r['joint'] or '-'))}</td>"
                   f"<td class='{'bad' if r['shows_from'] is None else ''}'>{e(top)}</td>"
                   f"<td>{e(_fmt(r['range_end']) + unit)}</td></tr>")
    out.append("</table>")
    return "".join(out)


def html_report(d: Diagnosis, data: dict, workers: int = 0) -> str:
    e = html.escape
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>HydroHIL diagnosis: {e(d.robot)}</title>",
             "<style>body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:2px 6px;font-size:90%}th{background:#f4f4f4}.ok{color:#070}"
             ".bad{color:#a00}img{max-width:100%}</style></head><body>"]
    parts.append(f"<h1>Diagnosis of {e(d.record.source)} on {e(d.robot)}</h1>")
    verdict = data["verdict"]
    parts.append(f"<p><b>Verdict: {e(verdict)}</b> ({e(d.stopped)}).</p>")
    if data.get("unexplained"):
        parts.append(_unexplained_html(data))
    elif not d.selected:
        parts.append("<p>No candidate extension improved the validation score by the threshold with identified "
                     "parameters: the model explains the data to within what the data can show.</p>")
    parts.append(f"<p>Validation: {e(d.validation.source)} from {d.validation.time[d.split]:.2f} s "
                 f"({d.validation.n - d.split} samples). Gain = rise of the joint's score, the mean NRMSE fit of angle, "
                 f"velocity and recorded pressures; accepted from max({data['decision']['threshold_points']:g} points, "
                 f"{data['decision']['noise_factor']:g} x noise spread) with BIC improving and identified parameters."
                 + (f" The record is closed loop: the score also takes the angle fit restarted from the recorded position "
                    f"every {d.restart_s:.2f} s ({RESTART_TAUS:g} time constants of the loop, which corrects a drift within "
                    f"them, where the model replayed open loop carries it to the end)." if d.restart_s else "") + "</p>")
    # cause and gain
    for s in d.selected:
        eff = EFFECTS[s["effect"]]
        where = f" on joint {s['joint']}" if s["joint"] else ""
        parts.append(f"<h2>Cause: {e(s['effect'])}{e(where)}</h2><p>{e(eff.summary())}</p>")
        parts.append(f"<p><i>{e(' '.join((eff.__doc__ or '').split()[len(eff.summary().split()):]))}</i></p>")
        rows = "".join(f"<tr><td>{e(k)}</td><td>{_fmt(v)}</td><td>[{_fmt(s['ci95'][k][0])}, {_fmt(s['ci95'][k][1])}]</td>"
                       f"<td>{_fmt(s['significance'].get(k))}</td></tr>" for k, v in s["params"].items())
        parts.append("<table><tr><th>parameter</th><th>estimate</th><th>95 % interval</th><th>|est - none| / sigma</th></tr>"
                     f"{rows}</table>")
        for k, h in s.get("held_at_default", {}).items():
            parts.append(f"<p><b>Held</b>: {e(k)} = {_fmt(h['value'])}, {e(h['because'])}.</p>")
        for line in conditional.describe(s) + command_hold.describe(s):
            parts.append(f"<p><b>Conditional</b>: {e(line)}.</p>")
        gc = ", ".join(f"{k} {v:+.2f}" for k, v in s["gain_channels"].items())
        parts.append(f"<p>Gain <b>{s['gain']:+.2f} points</b>{_share(s)} ({e(gc)}); noise spread {s['noise_spread']:.3f}; "
                     f"BIC change {_fmt(s['bic_delta'])}." + (" Refit of an effect the nominal model already has." if s["refit_of_nominal"] else "") + "</p>")
        if s.get("explains_record"):
            parts.append(f"<p><b>Below the floor</b>: {e(s['explains_record'])}.</p>")
        if "named_together_with" in s:
            o, alone = s["named_together_with"], s.get("alone", {})
            parts.append(f"<p><b>Named together with {e(o['effect'])}{' on ' + e(o['joint']) if o['joint'] else ''}</b>: "
                         f"neither passes alone (alone: {alone.get('gain', float('nan')):+.2f} points; "
                         f"{e('; '.join(alone.get('rejected_because', [])) or 'not accepted')}); each alone is absorbed "
                         "by the calibration or masked by the other. The gain is the pair's.</p>")
        if "runner_up" in s:
            ru = s["runner_up"]
            parts.append(f"<p>Runner-up: {e(ru['effect'])}{' on ' + e(ru['joint']) if ru['joint'] else ''} "
                         f"({ru['gain']:+.2f} points{_share(ru)}).")
            if s.get("ambiguous"):
                parts.append(f" <b class='bad'>Ambiguous</b>: the margin is under 20 %. What would decide: {e(s['decided_by'])}.")
                for r in s.get("rivals", [])[1:]:
                    parts.append(f" As close: {e(r['effect'])}{' on ' + e(r['joint']) if r['joint'] else ''} "
                                 f"({r['gain']:+.2f} points); what would decide: {e(r['decided_by'])}.")
            parts.append("</p>")
        parts += [f"<p><b class='bad'>Beyond a declared range</b>: {e(line)}.</p>" for line in beyond_range.describe(s)]
    parts.append(_calibration_html(data))
    # fits
    parts.append("<h2>Fit on validation data (NRMSE %, angle)</h2><table><tr><th>joint</th><th>baseline</th>"
                 "<th>extended</th><th>baseline score</th><th>extended score</th></tr>")
    for j, f in d.baseline_fits.items():
        fe = d.extended_fits[j]
        parts.append(f"<tr><td>{e(j)}{'' if f.get('excited', True) else ' (not commanded)'}</td><td>{_fmt(f['angle'])}</td>"
                     f"<td>{_fmt(fe['angle'])}</td><td>{_fmt(f.get('score'))}</td><td>{_fmt(fe.get('score'))}</td></tr>")
    parts.append("</table>")
    # plots
    drawn = all_plots(d, [j for j in d.record.targets if j in d.validation.angles], workers)
    for j, p in drawn.items():
        parts.append(f"<h2>Joint {e(j)}: where the model is wrong</h2>")
        for key, cap in (("angles", "measured, baseline and extended model (validation shaded)"),
                         ("residuals", "angle residuals, with the effect's evidence highlighted"),
                         ("correlation", "whiteness and independence tests"),
                         ("spectrum", "residual spectrum and transfer estimate")):
            parts.append(f"<figure><img src='data:image/png;base64,{p[key]}'><figcaption>{e(cap)}</figcaption></figure>")
        tb = d.tests.get("baseline", {}).get(j)
        te = d.tests.get("extended", {}).get(j)
        if tb:
            parts.append(f"<p>Ljung-Box Q (velocity residual, 20 lags): baseline {tb['ljung_box_Q']:.0f}"
                         + (f", extended {te['ljung_box_Q']:.0f}" if te and d.selected else "") + ".</p>")
        sig = data["signatures"].get(j, {})
        rows = "".join(f"<tr><td>{e(k)}</td><td>{_fmt(v)}</td></tr>" for k, v in sig.items() if not isinstance(v, dict))
        parts.append(f"<details><summary>signature statistics (screening)</summary><table>{rows}</table></details>")
    # candidates
    parts.append("<h2>All candidates</h2><table><tr><th>round</th><th>effect</th><th>joint</th><th>gain</th><th>BIC change</th>"
                 "<th>parameters</th><th>verdict</th></tr>")
    for c in data["candidates"]:
        params = ", ".join(f"{k}={_fmt(v)}" for k, v in c["params"].items())
        why = "accepted" if c["accepted"] else "; ".join(c["rejected_because"])
        parts.append(f"<tr><td>{e(_round(c))}</td><td>{e(c['effect'])}</td><td>{e(str(c['joint'] or '-'))}</td>"
                     f"<td>{c['gain']:+.2f}{_share(c)}</td><td>{_fmt(c['bic_delta'])}</td><td>{e(params)}</td>"
                     f"<td class='{'ok' if c['accepted'] else ''}'>{e(why)}</td></tr>")
    parts.append("</table>")
    parts.append(_detectable_html(data.get("detectable") or {}, e))
    # data checks
    parts.append("<h2>Data checks</h2><ul>")
    chk = data["data"]
    parts.append(f"<li>{chk['rate_hz']:.1f} Hz, {chk['duration_s']:.1f} s, diagnosed joints: {e(', '.join(chk['targets']))}, "
                 f"pressures {'recorded' if chk['pressures'] else 'not recorded'}</li>")
    for j, s in chk["noise_rad"].items():
        word, unit = _position(d, j)
        parts.append(f"<li>{e(j)}: {word} noise {s * 1e3:.3f} m{unit}, fit ceiling {chk['fit_ceiling'][j]:.1f} %, "
                     f"end-stop contact {100 * chk['end_stop_share'][j]:.1f} %, start pose from {chk['initial_pose_source'][j]}</li>")
    for n in chk["notes"]:
        parts.append(f"<li>{e(n)}</li>")
    cal = data["calibration"]
    for k, v in cal["values"].items():
        ci = cal["ci95"].get(k)
        parts.append(f"<li>calibrated {e(k)} = {_fmt(v)}" + (f" [{_fmt(ci[0])}, {_fmt(ci[1])}]" if ci else "") + "</li>")
    parts.append(f"<li>fast integrator substep for the candidate fits: {_fmt(d.numerics.get('substep'))} s "
                 f"(checked on this record: {e(json.dumps(d.numerics.get('candidates', {})))})</li></ul>")
    parts.append("</body></html>")
    return "".join(parts)


def _round(c: dict) -> str:
    """A candidate's round; for the exchange pass's fits, the effect it was fitted in place of."""
    x = c.get("in_place_of")
    return f"{c['round']} (in place of {x['effect']}@{x['joint'] or '-'})" if x else str(c["round"])


def _share(item: dict) -> str:
    """A gain's share of the baseline residual, beside its points."""
    v = item.get("residual_explained_pct")
    return "" if v is None else f", {v:.0f} % of the baseline residual"


def _evidence_rows(evidence: dict) -> str:
    e = html.escape
    rows = []
    for j, ev in evidence.items():
        w, f = ev["where"], ev["frequency"]
        spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in w["spans_s"][:6]) or "spread over the record"
        if len(w["spans_s"]) > 6:
            spans += f" (+{len(w['spans_s']) - 6} more)"
        band = f"{f['band_hz'][0]:.2g}-{f['band_hz'][1]:.2g} Hz ({100 * f['band_share']:.0f} %)" if f["band_hz"] else "-"
        rows.append(f"<tr><td>{e(j)}</td><td>{e(str(ev['channel']))} ({_fmt(ev['channel_fit'])} %)</td>"
                    f"<td>{e(spans)}" + (f" ({100 * w['span_share']:.0f} % of the residual)" if w["spans_s"] else "")
                    + f"</td><td>{band}</td><td>{_fmt(f['peak_hz'])}</td>"
                    f"<td>{'fail' if ev.get('tests_fail') else 'pass'}</td></tr>")
    return "".join(rows)


def _unexplained_html(data: dict) -> str:
    """Why no named cause explains the record, the closest candidates, and where the residual is."""
    e = html.escape
    u = data["unexplained"]
    parts = ["<h2 class='bad'>Unexplained discrepancy</h2><p>Neither the calibration nor any effect of the bank "
             "explains the record: " + e("; ".join(u["because"])) + ". The model is not extended; the cause is "
             "outside the bank (a supply or oil property, a structural mode, a different flow law, ...)"
             + (", or in the record" if u.get("record_causes") else "") + ".</p>"]
    for cause in u.get("record_causes", []):
        parts.append(f"<p>In the record: {e(cause)}.</p>")
    if u.get("closest"):
        rows = "".join(f"<tr><td>{e(c['effect'])}</td><td>{e(str(c['joint'] or '-'))}</td><td>{c['gain']:+.2f}</td>"
                       f"<td>{_fmt(c.get('residual_explained_pct'))}</td></tr>" for c in u["closest"])
        parts.append("<p>Closest candidates (they passed the acceptance rules but leave the record unexplained):</p>"
                     "<table><tr><th>effect</th><th>joint</th><th>gain (points)</th><th>baseline residual explained (%)"
                     f"</th></tr>{rows}</table>")
    parts.append("<p>Where the remaining residual is (velocity residual of the closest model on the validation data):</p><table><tr>"
                 "<th>joint</th><th>worst channel (fit)</th><th>when</th><th>dominant band (share of power)</th>"
                 f"<th>peak (Hz)</th><th>residual tests</th></tr>{_evidence_rows(u.get('evidence', {}))}</table>")
    return "".join(parts)


def _refitted_cell(r: dict | None) -> str:
    """A calibrated parameter as the extended model has it, with what it hangs on."""
    if r is None:
        return "-"
    return _fmt(r["value"]) + (f" ({html.escape(conditional.given(r))})" if r.get("conditional_on") else "")


def _calibration_html(data: dict) -> str:
    """What the baseline calibration changed (and could not identify), and the closed-loop finding."""
    e = html.escape
    cal = data["calibration"]
    parts = ["<h2>Baseline calibration</h2><p>Freed before any effect was tried; a parameter the record does not "
             "identify (|value/sigma| &lt; 3, or tied to another by their correlation) is kept at its nominal value. "
             "Once effects are named, what the calibration identifies with them in the model is refitted beside them: "
             "the extended model (and extended.toml) has those values.</p>",
             "<table><tr><th>parameter</th><th>nominal</th><th>fitted</th><th>sigma</th><th>identified</th><th>used</th>"
             "<th>refitted with the named effects</th><th>why freed</th></tr>"]
    refitted = cal.get("refitted_with_effects", {})
    for c in cal.get("changes", []):
        ident = (("yes" + (f" ({c['note']})" if c.get("note") else "")) if c["identified"]
                 else f"no: {c.get('not_identified_because', '')}")
        parts.append(f"<tr><td>{e(c['parameter'])}</td><td>{_fmt(c['nominal'])}</td><td>{_fmt(c['fitted'])}</td>"
                     f"<td>{_fmt(c['sigma'])}</td><td class='{'ok' if c['identified'] else 'bad'}'>{e(ident)}</td>"
                     f"<td>{_fmt(c['value'])} {e(c.get('unit', ''))}"
                     + (f" ({e(conditional.given(c))})" if c.get("conditional_on") else "")
                     + f"</td><td>{_refitted_cell(refitted.get(c['parameter']))}</td>"
                     + f"<td>{e(c.get('why', ''))}</td></tr>")
    parts.append("</table>")
    parts += [f"<p><b class='bad'>Calibrated beyond a declared range</b>: {e(line)}.</p>"
              for line in beyond_range.found(cal)]
    if cal.get("held"):
        parts.append("<details><summary>nominal parameters not freed</summary><ul>"
                     + "".join(f"<li>{e(k)}: {e(v)}</li>" for k, v in cal["held"].items()) + "</ul></details>")
    loop = data.get("closed_loop_evidence") or {}
    if data.get("closed_loop"):
        parts.append(f"<h2>Closed-loop record</h2><p>{e(loop.get('note', ''))}.</p>")
    hold = loop.get("command_hold")
    if hold:
        fits = hold["velocity_fit"]
        parts.append(f"<p><b>Command between samples</b>: replayed {e(hold['replay'].replace('_', ' '))} on "
                     f"{e(', '.join(hold['joints']))} (velocity fit of the calibrated baseline held {fits['held']:.2f} %, "
                     f"period mean {fits['period_mean']:.2f} %; {e(hold['rule'])}).</p>")
        if "revisited" in hold:
            parts.append(f"<p><b>Replay revisited</b>: {e(command_hold.said(hold))}.</p>")
    if loop.get("joints"):
        rows = "".join(f"<tr><td>{e(j)}</td><td>{_fmt(v['correlation'])}</td><td>{_fmt(v['gain'])}</td>"
                       f"<td>{_fmt(v['explained'])}</td><td>{'yes' if v['closed_loop'] else 'no'}</td></tr>"
                       for j, v in loop["joints"].items())
        parts.append(f"<details><summary>closed-loop test ({e(loop.get('rule', ''))})</summary><table><tr><th>joint</th>"
                     f"<th>correlation</th><th>K</th><th>share explained</th><th>closed loop</th></tr>{rows}</table></details>")
    return "".join(parts)


def extended_params(d: Diagnosis, configured_spec) -> dict:
    """The extended model as a parameter/effect file relative to the robot's built-in spec."""
    spec = configured_spec.copy()
    refitted = d.calibration.get("refitted_with_effects", {})
    for k in d.calibration["values"]:
        if k not in d.calibration.get("identified", d.calibration["values"]) and k not in refitted:
            continue
        if k.startswith("effects."):
            name, joint = k.split(".")[1], (k.split(".")[2] if k.count(".") == 3 else None)
            inst = next(e for e in d.extended_spec.effects if e.name == name and e.joint == joint)
            spec.enable_effect(name, joint, **inst.params)
        else:
            spec.set(k, d.extended_spec.get(k))
    for s in d.selected:
        inst = next(e for e in d.extended_spec.effects if e.name == s["effect"] and e.joint == s["joint"])
        params = dict(inst.params)
        params.update(s["params"])
        spec.enable_effect(s["effect"], s["joint"], **params)
    for j, src in d.check.initial_pose_source.items():
        if src == "data":
            spec.set(f"joints.{j}.initial_position", start_position(d.extended_spec, d.record, j))
    data = overrides(spec)
    data["diagnosis"] = {
        "generated_by": "hydrohil diagnose", "source": d.record.source, "validation": d.validation.source,
        "verdict": d.verdict,
        "effects": [f"{s['effect']}" + (f"@{s['joint']}" if s["joint"] else "") for s in d.selected],
        "baseline_fit": {j: f["angle"] for j, f in d.baseline_fits.items() if f.get("excited", True)},
        "extended_fit": {j: f["angle"] for j, f in d.extended_fits.items() if f.get("excited", True)},
    }
    return data


def write(d: Diagnosis, out_dir: str | Path, configured_spec, fmt: str = "html", workers: int = 0) -> dict[str, Path]:
    """``workers``: processes drawing the HTML report's figures (0: the CPU count)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    data = d.to_json()
    paths = {"json": out_dir / "diagnosis.json", "toml": out_dir / "extended.toml"}
    paths["json"].write_text(json.dumps(_json_safe(data), indent=2))
    write_params(paths["toml"], extended_params(d, configured_spec),
                 header=f"Extended model from 'hydrohil diagnose' on {d.record.source}: {d.verdict}.\n"
                        f"Use with: hydrohil simulate --robot {d.robot} --params extended.toml ...")
    if fmt == "html":
        paths["report"] = out_dir / "report.html"
        paths["report"].write_text(html_report(d, data, workers))
    else:
        paths["report"] = out_dir / "report.md"
        paths["report"].write_text(markdown_report(d, data))
    return paths


def markdown_report(d: Diagnosis, data: dict) -> str:
    lines = [f"# Diagnosis of {d.record.source} on {d.robot}", "", f"**Verdict: {data['verdict']}** ({d.stopped})", ""]
    u = data.get("unexplained")
    if u:
        lines += ["Unexplained: " + "; ".join(u["because"]) + ".", ""]
        if u.get("record_causes"):
            lines += [f"In the record: {cause}." for cause in u["record_causes"]] + [""]
        for c in u.get("closest", []):
            lines.append(f"- closest: {c['effect']}" + (f" on {c['joint']}" if c["joint"] else "")
                         + f", gain {c['gain']:+.2f} points{_share(c)}")
        for j, ev in u.get("evidence", {}).items():
            f, w = ev["frequency"], ev["where"]
            lines.append(f"- {j}: worst channel {ev['channel']} ({_fmt(ev['channel_fit'])} %); "
                         + (f"band {f['band_hz'][0]:.2g}-{f['band_hz'][1]:.2g} Hz, peak {_fmt(f['peak_hz'])} Hz; " if f["band_hz"] else "")
                         + ("at " + ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in w["spans_s"][:6]) if w["spans_s"]
                            else "spread over the record"))
        lines.append("")
    for s in d.selected:
        lines.append(f"## {s['effect']}" + (f" on {s['joint']}" if s["joint"] else ""))
        for k, v in s["params"].items():
            lo, hi = s["ci95"][k]
            lines.append(f"- {k} = {_fmt(v)} (95 %: {_fmt(lo)} .. {_fmt(hi)})")
        lines += [f"- {k} {h['because']}" for k, h in s.get("held_at_default", {}).items()]
        lines += [f"- {line}" for line in conditional.describe(s) + command_hold.describe(s)]
        lines.append(f"- gain {s['gain']:+.2f} points{_share(s)}")
        if s.get("explains_record"):
            lines.append(f"- {s['explains_record']}")
        if "named_together_with" in s:
            o = s["named_together_with"]
            lines.append(f"- named together with {o['effect']}" + (f" on {o['joint']}" if o["joint"] else "")
                         + f": neither passes alone (alone {s.get('alone', {}).get('gain', float('nan')):+.2f} points)")
        lines += [f"- {line}" for line in beyond_range.describe(s)]
        if s.get("ambiguous"):
            lines.append(f"- ambiguous with {s['runner_up']['effect']}; decided by {s['decided_by']}")
            lines += [f"- as close: {r['effect']}" + (f" on {r['joint']}" if r["joint"] else "")
                      + f" ({r['gain']:+.2f} points); decided by {r['decided_by']}" for r in s.get("rivals", [])[1:]]
        lines.append("")
    if data.get("closed_loop"):
        lines += [f"Closed-loop record: {data['closed_loop_evidence'].get('note', '')}.", ""]
    refitted = data["calibration"].get("refitted_with_effects", {})
    lines += ["| calibrated | nominal | fitted | sigma | identified | with the named effects |", "|---|---|---|---|---|---|"]
    for c in data["calibration"].get("changes", []):
        lines.append(f"| {c['parameter']} | {_fmt(c['nominal'])} | {_fmt(c['fitted'])} | {_fmt(c['sigma'])} | "
                     f"{('yes' + (f', {conditional.given(c)}' if c.get('conditional_on') else '')) if c['identified'] else 'no (kept nominal)'} | "
                     f"{_fmt(refitted[c['parameter']]['value']) if c['parameter'] in refitted else '-'} |")
    lines.append("")
    found = beyond_range.found(data["calibration"])
    lines += [f"Calibrated beyond a declared range: {line}." for line in found] + ([""] if found else [])
    lines.append("| joint | baseline fit | extended fit |")
    lines.append("|---|---|---|")
    for j, f in d.baseline_fits.items():
        lines.append(f"| {j} | {_fmt(f['angle'])} | {_fmt(d.extended_fits[j]['angle'])} |")
    lines.append("")
    lines.append("| round | effect | joint | gain | BIC change | verdict |")
    lines.append("|---|---|---|---|---|---|")
    for c in data["candidates"]:
        why = "accepted" if c["accepted"] else "; ".join(c["rejected_because"])
        lines.append(f"| {_round(c)} | {c['effect']} | {c['joint'] or '-'} | {c['gain']:+.2f} | {_fmt(c['bic_delta'])} | {why} |")
    return "\n".join(lines) + "\n"


def _json_safe(v):
    if isinstance(v, dict):
        return {str(k): _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v
