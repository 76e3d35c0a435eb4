"""Residual tests in the style of MATLAB's ``resid``: is anything wrong at all, and at what frequencies?

* whiteness: residual autocorrelation and the Ljung-Box Q on the decimated velocity residual (a
  global flag only: any band-limited residual fails it, so it never names a cause);
* independence: cross-correlation of the residual with u, |u|, sign(u) and sign(velocity), with the
  99 % band ``z sqrt(P / N)`` where P is the Bartlett sum of the two autocorrelations (coloured
  inputs widen the band); nonlinear features catch what the linear test misses (a deadband);
* spectrum of the residual and the empirical transfer estimate ``H = S_sim,meas / S_sim,sim`` of
  measured over simulated velocity with its coherence (pure phase: delay; roll-off: lag; peak: a
  resonance; flat but not 1: gain).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal
from scipy.stats import chi2

Z99 = 2.576


def autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    var = float(x @ x)
    if var <= 0.0 or n < 2:
        return np.zeros(max_lag + 1)
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[: max_lag + 1] / var
    return acf


def cross_correlation(e: np.ndarray, u: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised R_ue(k) = E[e(t+k) u(t)] for k in [-max_lag, max_lag] (positive k: e after u)."""
    e = np.asarray(e, dtype=float) - np.mean(e)
    u = np.asarray(u, dtype=float) - np.mean(u)
    n = e.size
    den = math.sqrt(float(e @ e) * float(u @ u))
    lags = np.arange(-max_lag, max_lag + 1)
    if den <= 0.0:
        return lags, np.zeros(lags.size)
    fe = np.fft.rfft(e, 2 * n)
    fu = np.fft.rfft(u, 2 * n)
    c = np.fft.irfft(fe * np.conj(fu))
    out = np.concatenate([c[-max_lag:], c[: max_lag + 1]]) if max_lag > 0 else c[:1]
    return lags, out / den


def correlation_band(e: np.ndarray, u: np.ndarray, max_lag: int, z: float = Z99) -> float:
    """99 % band of the normalised cross-correlation of two coloured signals (Bartlett)."""
    n = len(e)
    L = min(max_lag * 4, n // 4)
    re = autocorrelation(e, L)
    ru = autocorrelation(u, L)
    P = 1.0 + 2.0 * float(np.sum(re[1:] * ru[1:]))
    return z * math.sqrt(max(P, 1.0) / n)


def ljung_box(x: np.ndarray, lags: int = 20) -> tuple[float, float]:
    """(Q, p-value) of the Ljung-Box whiteness test; a series shorter than twice ``lags`` (a short
    record, decimated) is tested over half its length."""
    n = len(x)
    lags = min(lags, n // 2)
    if lags < 1:
        return 0.0, 1.0
    rho = autocorrelation(x, lags)[1:]
    q = float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, lags + 1))))
    return q, float(chi2.sf(q, lags))


def independence(e: np.ndarray, u: np.ndarray, speed: np.ndarray, rate: float, max_lag_s: float = 0.5) -> dict:
    """Cross-correlation of the residual with the input and nonlinear features of it, with 99 % bands."""
    max_lag = max(5, min(int(round(max_lag_s * rate)), len(e) // 4))
    feats = {"u": u, "|u|": np.abs(u), "sign(u)": np.sign(u), "sign(velocity)": np.sign(speed)}
    out = {}
    for name, f in feats.items():
        if np.ptp(f) == 0:
            continue
        lags, c = cross_correlation(e, f, max_lag)
        band = correlation_band(e, f, max_lag)
        k = int(np.argmax(np.abs(c)))
        out[name] = {"lags_s": (lags / rate).tolist(), "r": c.tolist(), "band": band,
                     "peak": float(c[k]), "peak_lag_s": float(lags[k] / rate), "exceeds": bool(abs(c[k]) > band)}
    return out


def spectrum(x: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    nper = int(min(len(x), max(64, 2 ** int(math.log2(max(64, rate * 10))))))
    f, p = signal.welch(signal.detrend(x), fs=rate, nperseg=nper)
    return f, p


def transfer_estimate(sim: np.ndarray, meas: np.ndarray, rate: float) -> dict:
    """ETFE of measured over simulated velocity, its coherence, and the slopes that name lag effects:
    phase slope (s) and magnitude slope (dB/Hz) over coherent bins in 0.3-8 Hz, and the peak."""
    nper = int(min(len(sim), max(64, 2 ** int(math.log2(max(64, rate * 5))))))
    f, Pss = signal.welch(sim, fs=rate, nperseg=nper)
    _, Psm = signal.csd(sim, meas, fs=rate, nperseg=nper)
    with np.errstate(divide="ignore", invalid="ignore"):
        _, coh = signal.coherence(sim, meas, fs=rate, nperseg=nper)
        H = Psm / Pss
    coh = np.nan_to_num(coh, nan=0.0)        # a channel that never moves (a model stuck in an end stop) has none
    band = (f >= 0.3) & (f <= min(8.0, 0.4 * rate)) & (coh > 0.6) & np.isfinite(H)
    res = {"f": f.tolist(), "mag_db": (20 * np.log10(np.abs(H) + 1e-300)).tolist(),
           "phase_deg": np.degrees(np.angle(H)).tolist(), "coherence": coh.tolist(),
           "phase_slope_s": 0.0, "mag_slope_db_per_hz": 0.0, "peak_db": 0.0, "peak_hz": None, "bins": int(band.sum())}
    if band.sum() >= 3:
        fb = f[band]
        ph = np.unwrap(np.angle(H[band]))
        mag = 20 * np.log10(np.abs(H[band]))
        res["phase_slope_s"] = float(-np.polyfit(2 * np.pi * fb, ph, 1)[0])
        res["mag_slope_db_per_hz"] = float(np.polyfit(fb, mag, 1)[0])
        k = int(np.argmax(mag))
        res["peak_db"] = float(mag[k] - np.median(mag))
        res["peak_hz"] = float(fb[k])
    return res


def residual_peak(r: np.ndarray, rate: float, fmin: float = 0.5, fmax: float = 20.0) -> tuple[float, float | None]:
    """Peak of the residual PSD above its median in [fmin, fmax] Hz: (dB, Hz)."""
    f, p = spectrum(r, rate)
    band = (f >= fmin) & (f <= min(fmax, 0.45 * rate)) & (p > 0)
    if band.sum() < 3:
        return 0.0, None
    db = 10 * np.log10(p[band])
    k = int(np.argmax(db))
    return float(db[k] - np.median(db)), float(f[band][k])
