"""Where a residual lives: which channel fits worst, when in the record, and in which frequency band.

The evidence an ``unexplained_discrepancy`` verdict carries, so a reader can look for the cause the
bank has no name for (a structural mode shows as a narrow band; a supply sag as spans under load).
"""

from __future__ import annotations

import math

import numpy as np

SPAN_FACTOR = 2.0       # a window whose residual energy exceeds this x the median window carries the misfit
WINDOW_S = 1.0          # window of the time localisation (s)


def octave_bands(f_max: float) -> list[tuple[float, float]]:
    """Octave bands centred on 2^k Hz (edges at 2^k / sqrt 2 and 2^k sqrt 2), from 0 up to ``f_max``."""
    edges = [0.0] + [2.0 ** k / math.sqrt(2.0) for k in range(-2, 12) if 2.0 ** k / math.sqrt(2.0) < f_max] + [f_max]
    return list(zip(edges[:-1], edges[1:]))


def dominant_band(f: np.ndarray, pxx: np.ndarray) -> dict:
    """The octave band holding most of a residual PSD's power, its share, and the PSD's peak."""
    f, pxx = np.asarray(f, dtype=float), np.asarray(pxx, dtype=float)
    if f.size < 2 or not np.any(pxx > 0):
        return {"band_hz": None, "band_share": None, "peak_hz": None}
    df = float(f[1] - f[0])
    total = float(np.sum(pxx) * df)
    best, share = None, -1.0
    for lo, hi in octave_bands(float(f[-1]) + df):
        sel = (f >= lo) & (f < hi)
        s = float(np.sum(pxx[sel]) * df) / total if total > 0 else 0.0
        if s > share:
            best, share = (lo, hi), s
    k = int(np.argmax(pxx[1:])) + 1          # the peak, DC left out
    return {"band_hz": [round(best[0], 3), round(best[1], 3)], "band_share": round(share, 3),
            "peak_hz": round(float(f[k]), 3)}


def locate(t: np.ndarray, r: np.ndarray, window_s: float = WINDOW_S) -> dict:
    """When the residual ``r`` (sampled at ``t``) carries its energy: the windows above SPAN_FACTOR x
    the median window energy, merged into spans (s), the share of the energy in them, and the
    strongest window. No span: the misfit is spread over the record."""
    t, r = np.asarray(t, dtype=float), np.asarray(r, dtype=float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    w = max(1, min(int(round(window_s / dt)), t.size // 4 or 1))
    n = (r.size // w) * w
    if n == 0:
        return {"spans_s": [], "span_share": 0.0, "strongest_s": None}
    e = np.sum((r[:n] - np.mean(r[:n])).reshape(-1, w) ** 2, axis=1)
    total = float(e.sum())
    hot = e > SPAN_FACTOR * float(np.median(e))
    spans = []
    for i in np.flatnonzero(hot):
        a, b = float(t[i * w]), float(t[min((i + 1) * w, t.size - 1)])
        if spans and abs(spans[-1][1] - a) <= 1.5 * dt:
            spans[-1][1] = b
        else:
            spans.append([a, b])
    k = int(np.argmax(e))
    return {"spans_s": [[round(a, 3), round(b, 3)] for a, b in spans],
            "span_share": round(float(e[hot].sum()) / total, 3) if total > 0 else 0.0,
            "strongest_s": [round(float(t[k * w]), 3), round(float(t[min((k + 1) * w, t.size - 1)]), 3)]}


def worst_channel(fits: dict, ceilings: dict | None = None) -> tuple[str | None, float | None]:
    """The channel (angle, velocity, pressure) with the lowest NRMSE fit or, given the channels' noise
    ceilings, the one furthest below its own ceiling (a noisy velocity fits worst and may still be
    at its ceiling while the angle misses by points)."""
    chans = {c: v for c, v in fits.items() if c in ("angle", "velocity", "pressure") and v is not None}
    if not chans:
        return None, None
    ceilings = ceilings or {}
    key = lambda k: (chans[k] - ceilings.get(k, 0.0)) if math.isfinite(chans[k]) else -math.inf
    c = min(chans, key=key)
    return c, float(chans[c])


def joint_evidence(t: np.ndarray, velocity_residual: np.ndarray, spectrum: tuple, fits: dict,
                   ceilings: dict | None = None) -> dict:
    """The evidence for one joint: worst channel and its fit, the time spans, the dominant band."""
    ch, fit = worst_channel(fits, ceilings)
    return {"channel": ch, "channel_fit": None if fit is None or not math.isfinite(fit) else round(fit, 2),
            "where": locate(t, velocity_residual), "frequency": dominant_band(*spectrum)}


def residual_fails(test: dict, p_min: float = 0.01) -> bool:
    """A joint's residual tests (diagnosis.residual_tests) fail: not white, or correlated with the input."""
    if not test:
        return False
    if test.get("ljung_box_p", 1.0) < p_min:
        return True
    return any(v.get("exceeds") for v in test.get("independence", {}).values())


def evidence(rec, prob, out, start: int, tests: dict, fits: dict, ceilings: dict | None = None) -> dict:
    """Per diagnosed joint of ``prob``: :func:`joint_evidence` of the validation residual of ``out``
    (``tests``: residual_tests' answer for ``out``, whose velocity residual and spectrum are reused;
    ``ceilings``: the channels' noise ceilings per joint, when known)."""
    res = {}
    if not out.ok:
        return res
    for j in prob.joints:
        tj = tests.get(j)
        if not tj:
            continue
        res[j] = joint_evidence(rec.time[start:prob.n], tj["_velocity_residual"], tj["_spectrum"], fits.get(j, {}),
                                (ceilings or {}).get(j)) | {"tests_fail": residual_fails(tj)}
    return res
