"""Signature statistics of the baseline residual: cheap, explainable evidence per effect, and the
initial guesses that keep the output-error fits of non-smooth parameters out of flat regions.

They order and explain; they never decide (the research note's screening step was right first only
10-13 times in 15; the validation gain of a fitted extension decides). Statistics, per joint:

* velocity-ratio map over constant-command segments, rho = measured / simulated steady speed:
  deadband (``rho |u| = s |u| - u0``: intercept u0 and its t-value), direction asymmetry (median rho
  for u < 0 over u > 0), saturation (slope of rho against |u| at large |u|);
* holds (u = 0): drift not in the model (chi^2 per hold against the noise), and its correlation with
  the sign of the previous command (hysteresis creeps the previous way; leakage does not care);
* lag of the velocity cross-correlation (delay), the transfer estimate's magnitude slope (a lag rolls
  off, a delay does not) and the residual spectrum's peak (compliance, hose, air);
* the residual regressed on the play state of the simulated motion (backlash) and on [1, angle]
  (sensor offset and gain: nothing dynamic is linear in the angle).
"""

from __future__ import annotations

import math

import numpy as np

from ..effects import EFFECTS
from .metrics import velocity
from .residual_tests import ljung_box, residual_peak, transfer_estimate

MIN_SEGMENT = 0.25   # s: shorter constant-command segments carry no steady speed


def segments(u: np.ndarray, rate: float, min_len: float = MIN_SEGMENT) -> list[tuple[int, int, float]]:
    """Runs of constant command: (start, stop, value), at least ``min_len`` long."""
    change = np.flatnonzero(np.abs(np.diff(u)) > 1e-9) + 1
    edges = np.concatenate([[0], change, [u.size]])
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        if (b - a) / rate >= min_len and b - a >= 8:
            out.append((int(a), int(b), float(u[a])))
    return out


def _slope(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares slope and the centred time spread sqrt(sum (t - mean)^2)."""
    tc = t - t.mean()
    s = float(np.sqrt(tc @ tc))
    if s == 0:
        return 0.0, 0.0
    return float(tc @ (y - y.mean())) / (s * s), s


def _ols(X: np.ndarray, z: np.ndarray):
    beta, *_ = np.linalg.lstsq(X, z, rcond=None)
    r = z - X @ beta
    dof = max(len(z) - X.shape[1], 1)
    s2 = float(r @ r) / dof
    try:
        cov = np.linalg.inv(X.T @ X) * s2
    except np.linalg.LinAlgError:
        cov = np.full((X.shape[1], X.shape[1]), np.inf)
    return beta, np.sqrt(np.abs(np.diag(cov))), r


def velocity_ratio_map(t, y, yhat, u, sigma, rate) -> list[dict]:
    """Steady speeds on the last 60 % of every constant-command segment (measured and simulated)."""
    rows = []
    for a, b, val in segments(u, rate):
        k = a + int(0.4 * (b - a))
        tt = t[k:b]
        wm, spread = _slope(tt, y[k:b])
        ws, _ = _slope(tt, yhat[k:b])
        se = sigma / spread if spread > 0 else math.inf
        rows.append({"start": a, "stop": b, "u": val, "w_meas": wm, "w_sim": ws, "se": se})
    return rows


def joint_signatures(t, y, yhat, u, sigma: float, rate: float, *, model_deadband: float = 0.0) -> dict:
    """All statistics for one joint; ``model_deadband`` is the deadband already in the model (V)."""
    dt = 1.0 / rate
    r = y - yhat
    wm_all = velocity(y, dt)
    ws_all = velocity(yhat, dt)
    rw = wm_all - ws_all
    out: dict = {}

    rows = velocity_ratio_map(t, y, yhat, u, sigma, rate)
    moving = [rw_ for rw_ in rows if rw_["u"] != 0.0 and abs(rw_["w_sim"]) > max(3 * rw_["se"], 1e-3)]
    for rw_ in moving:
        rw_["rho"] = rw_["w_meas"] / rw_["w_sim"]
    # deadband: rho |u| = s |u| - u0 over the segments the model moves in
    if len(moving) >= 3 and len({abs(m["u"]) for m in moving}) >= 2:
        x = np.array([abs(m["u"]) for m in moving])
        z = np.array([m["rho"] * abs(m["u"]) for m in moving])
        beta, se, _ = _ols(np.column_stack([x, np.ones_like(x)]), z)
        u0 = -beta[1]
        out["deadband_u0"] = float(u0)
        out["deadband_t"] = float(u0 / se[1]) if se[1] > 0 else 0.0
    # all segments the model says should move: does the joint stand still?
    stalled = [m for m in rows if m["u"] != 0.0 and abs(m["w_sim"]) > max(3 * m["se"], 1e-3)
               and abs(m["w_meas"]) < 3 * m["se"]]
    out["stalled_segments"] = len(stalled)
    pos = [m["rho"] for m in moving if m["u"] > 0]
    neg = [m["rho"] for m in moving if m["u"] < 0]
    if pos and neg and np.median(pos) > 0:
        out["asymmetry_ratio"] = float(np.median(neg) / np.median(pos))
    big = [m for m in moving if abs(m["u"]) >= 0.4 * max(abs(m2["u"]) for m2 in moving)] if moving else []
    if len(big) >= 3 and len({abs(m["u"]) for m in big}) >= 2:
        xs = np.array([abs(m["u"]) for m in big])
        out["saturation_slope"] = float(np.polyfit(xs, [m["rho"] for m in big], 1)[0])

    # holds: drift the model does not have, and whether it follows the previous command's sign
    holds = []
    segs = segments(u, rate, min_len=0.6)
    for a, b, val in segs:
        if val != 0.0:
            continue
        k = a + int(round(0.3 * rate))
        if b - k < 8:
            continue
        prev = u[:a][np.abs(u[:a]) > 1e-9]
        if prev.size == 0:
            continue
        wm, spread = _slope(t[k:b], y[k:b])
        ws, _ = _slope(t[k:b], yhat[k:b])
        se = sigma / spread if spread > 0 else math.inf
        holds.append((wm - ws, se, float(np.sign(prev[-1]))))
    out["holds"] = len(holds)
    if holds:
        d = np.array([h[0] for h in holds])
        se = np.array([h[1] for h in holds])
        sg = np.array([h[2] for h in holds])
        out["hold_drift_chi2"] = float(np.mean((d / np.maximum(se, 1e-12)) ** 2))
        out["hold_drift_rate"] = float(np.median(np.abs(d)))
        if len(holds) >= 3 and np.ptp(sg) > 0 and np.ptp(d) > 0:
            out["hold_drift_prev_sign_corr"] = float(np.corrcoef(d, sg)[0, 1])

    # delay: lag of the velocity cross-correlation (positive: measured later)
    max_lag = int(min(0.5 * rate, len(y) // 4))
    if np.ptp(ws_all) > 0 and max_lag > 2:
        a = wm_all - wm_all.mean()
        b = ws_all - ws_all.mean()
        n = a.size
        c = np.fft.irfft(np.fft.rfft(a, 2 * n) * np.conj(np.fft.rfft(b, 2 * n)))
        c = np.concatenate([c[-max_lag:], c[: max_lag + 1]])
        k = int(np.argmax(c))
        lag = float(k - max_lag)
        if 0 < k < c.size - 1:
            den = c[k - 1] - 2 * c[k] + c[k + 1]
            if den < 0:
                lag += 0.5 * (c[k - 1] - c[k + 1]) / den
        out["delay_lag_s"] = lag / rate
    if np.ptp(ws_all) > 0:
        H = transfer_estimate(ws_all, wm_all, rate)
        out["etfe_phase_slope_s"] = H["phase_slope_s"]
        out["etfe_mag_slope_db_per_hz"] = H["mag_slope_db_per_hz"]
        out["etfe_peak_db"] = H["peak_db"]
        out["etfe_peak_hz"] = H["peak_hz"]
        out["_etfe"] = H
    pk_db, pk_f = residual_peak(rw, rate)
    out["residual_peak_db"] = pk_db
    out["residual_peak_hz"] = pk_f

    # backlash: the residual against the play state of the simulated motion (with nuisance terms)
    thr = max(5 * sigma * rate / 10.0, 0.02 * float(np.max(np.abs(ws_all)) or 1.0))
    state = np.zeros_like(ws_all)
    cur = 0.0
    for i, w in enumerate(ws_all):
        if w > thr:
            cur = 1.0
        elif w < -thr:
            cur = -1.0
        state[i] = cur
    if np.ptp(state) > 0:
        knots = max(2, int(t[-1] / 3.0) + 1)
        centres = np.linspace(t[0], t[-1], knots)
        width = centres[1] - centres[0]
        hats = np.clip(1.0 - np.abs(t[:, None] - centres[None, :]) / width, 0.0, None)
        X = np.column_stack([state, ws_all, hats])
        beta, se, res = _ols(X, r)
        X0 = np.column_stack([ws_all, hats])
        _, _, res0 = _ols(X0, r)
        rss1, rss0 = float(res @ res), float(res0 @ res0)
        dof = max(len(r) - X.shape[1], 1)
        out["backlash_F"] = float((rss0 - rss1) / max(rss1 / dof, 1e-30))
        out["backlash_half_width"] = float(-beta[0])
    # sensor: nothing dynamic is linear in the angle
    if np.ptp(yhat) > 0:
        X = np.column_stack([np.ones_like(yhat), yhat])
        beta, se, res = _ols(X, r)
        out["sensor_R2"] = float(1.0 - float(res @ res) / max(float(r @ r), 1e-30))
        out["sensor_offset"] = float(np.mean(r))
        gslope = float((yhat @ r) / (yhat @ yhat)) if float(yhat @ yhat) > 0 else 0.0
        out["sensor_gain"] = 1.0 + gslope
    # global flag: Ljung-Box on the decimated velocity residual
    dec = max(1, int(round(0.075 * rate)))
    q, p = ljung_box(rw[::dec], lags=20)
    out["ljung_box_Q"] = q
    out["ljung_box_p"] = p
    # each effect reads its starting values off these statistics (its own ``signature_guess``)
    out["guesses"] = {}
    for eff in EFFECTS.values():
        guess = eff.signature_guess(out, {"model_deadband": model_deadband})
        if guess:
            out["guesses"][eff.name] = guess
    return out


def public(sig: dict) -> dict:
    """The statistics without bulky arrays (for diagnosis.json)."""
    return {k: v for k, v in sig.items() if not k.startswith("_")}
