"""Goodness of fit and signal helpers shared by calibration, residual tests and selection.

The fit is MATLAB's ``compare`` NRMSE fit, ``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` in percent
per channel: 100 is perfect, 0 is no better than the mean, and it can be negative.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy.signal import savgol_coeffs


def nrmse_fit(y: np.ndarray, yhat: np.ndarray) -> float:
    """MATLAB's NRMSE fit in percent (``goodnessOfFit(yhat, y, 'NRMSE')`` is ``1 - fit/100``)."""
    y = np.asarray(y, dtype=float)
    yhat = np.asarray(yhat, dtype=float)
    den = float(np.linalg.norm(y - y.mean()))
    num = float(np.linalg.norm(y - yhat))
    if den <= 0.0:
        return 100.0 if num == 0.0 else -math.inf
    return 100.0 * (1.0 - num / den)


def savgol_window(rate: float, seconds: float = 0.075, minimum: int = 5) -> int:
    """Odd Savitzky-Golay window of about ``seconds`` at ``rate`` Hz."""
    n = max(minimum, int(round(seconds * rate)))
    return n if n % 2 else n + 1


def velocity(y: np.ndarray, dt: float, window: int | None = None) -> np.ndarray:
    """Smoothed derivative (Savitzky-Golay, order 2): raw differences amplify sensor noise.

    The same numbers as ``scipy.signal.savgol_filter(y, w, 2, deriv=1, delta=dt)`` (mode 'interp':
    the first and last w/2 samples from the polynomial fitted to the end windows), with the end fits
    as fixed linear maps: the fits call this thousands of times, and scipy solves both end fits anew
    on every call."""
    y = np.asarray(y, dtype=float)
    w = window or savgol_window(1.0 / dt)
    if y.size < w:
        return np.gradient(y, dt)
    conv, left, right = _savgol_derivative(w, float(dt))
    half = w // 2
    out = np.convolve(y, conv, mode="same")
    out[:half] = left @ y[:w]
    out[-half:] = right @ y[-w:]
    return out


def smoothed(y: np.ndarray, dt: float, window: int | None = None) -> np.ndarray:
    """The signal through the same Savitzky-Golay filter (order 2) as :func:`velocity`, not differentiated."""
    from scipy.signal import savgol_filter

    y = np.asarray(y, dtype=float)
    w = window or savgol_window(1.0 / dt)
    return y.copy() if y.size < w else savgol_filter(y, w, 2)


@lru_cache(maxsize=64)
def _savgol_derivative(w: int, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Convolution taps of the order-2 Savitzky-Golay first derivative and the matrices mapping the
    first and last ``w`` samples to the derivative of their least-squares parabola at the first and
    last ``w // 2`` of them."""
    half = w // 2
    x = np.arange(w, dtype=float)
    fit = np.linalg.pinv(np.vander(x, 3))             # samples -> (a, b, c) of a x^2 + b x + c
    slope = lambda at: np.stack([2.0 * at, np.ones_like(at), np.zeros_like(at)], axis=1) @ fit / dt  # noqa: E731
    conv = savgol_coeffs(w, 2, deriv=1, delta=dt)
    return conv, slope(x[:half]), slope(x[w - half:])


def noise_std(y: np.ndarray) -> float:
    """Robust estimate of white measurement noise from second differences.

    For a smooth motion sampled fast, the second difference is dominated by noise (variance 6
    sigma^2); the median absolute deviation ignores the steps and reversals. A quantised reading's
    second differences sit on the quantum's lattice, where a plain median moves in whole quanta
    (5 where the noise gives 5.4 is 7 % low); the grouped median interpolates within its quantum.
    """
    y = np.asarray(y, dtype=float)
    if y.size < 5:
        return 0.0
    d2 = np.diff(y, 2)
    a = np.abs(d2 - np.median(d2))
    mad = float(np.median(a))
    # readings written with ten significant digits tie to about 1e-9 of their size, not exactly
    tol = 1e-7 * float(np.max(np.abs(y)))
    if mad > tol:       # at zero (the noise under one quantum) the quantum itself is the estimate, below
        mad = grouped_median(a, floor=0.0, tol=tol)
    sigma = 1.4826 * mad / math.sqrt(6.0)
    if sigma == 0.0:
        # quantised and mostly still: use the quantisation step seen in the data
        steps = np.abs(np.diff(y))
        steps = steps[steps > 0]
        if steps.size:
            sigma = float(np.min(steps)) / math.sqrt(12.0)
    return sigma


#: share of the samples tied at the median above which the values are taken as a lattice's
LATTICE_TIES = 0.01


def grouped_median(a: np.ndarray, floor: float | None = None, tol: float | None = None) -> float:
    """Median of ``a``, interpolated within its lattice step where ``a`` takes few distinct values.

    The grouped-data median: the median value ``m`` stands for the bin ``m +- h/2`` (``h`` the gap to
    the nearest distinct value), and the median is placed in it by the share of the samples below
    and at it. Where no more than ``LATTICE_TIES`` of the samples tie at the median (a continuous
    signal) this is the plain median. ``floor`` bounds the bin below (0 for absolute values); values
    within ``tol`` of each other tie (default: 1e-9 of the largest).
    """
    a = np.asarray(a, dtype=float).ravel()
    m = float(np.median(a))
    if a.size < 3:
        return m
    if tol is None:
        tol = 1e-9 * float(np.max(np.abs(a)))
    at = np.abs(a - m) <= tol
    n_at = int(np.count_nonzero(at))
    if n_at <= max(2, LATTICE_TIES * a.size):
        return m
    below, above = a[a < m - tol], a[a > m + tol]
    gaps = [m - float(below.max())] if below.size else []
    gaps += [float(above.min()) - m] if above.size else []
    if not gaps:
        return m
    h = min(gaps)
    lo = m - 0.5 * h if floor is None else max(floor, m - 0.5 * h)
    hi = m + 0.5 * h
    return lo + (0.5 * a.size - below.size) / n_at * (hi - lo)


def fit_ceiling(y: np.ndarray, sigma: float) -> float:
    """Best fit a perfect model can reach on ``y`` with white noise of ``sigma`` (the noise floor)."""
    y = np.asarray(y, dtype=float)
    den = float(np.linalg.norm(y - y.mean()))
    if den <= 0.0:
        return 100.0
    return 100.0 * (1.0 - sigma * math.sqrt(y.size) / den)


def effective_samples(r: np.ndarray, max_lag: int | None = None) -> float:
    """N_eff = N / (1 + 2 sum rho_k) of a coloured residual (sum until rho first drops below 0.05)."""
    r = np.asarray(r, dtype=float)
    n = r.size
    if n < 4:
        return float(n)
    r = r - r.mean()
    var = float(r @ r)
    if var <= 0.0:
        return float(n)
    max_lag = max_lag or min(n // 4, 2000)
    spec = np.fft.rfft(r, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec))[: max_lag + 1] / var
    s = 0.0
    for k in range(1, max_lag + 1):
        if acf[k] < 0.05:
            break
        s += acf[k]
    return max(1.0, n / (1.0 + 2.0 * s))
