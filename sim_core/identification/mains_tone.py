"""Mains interference on the measured position, seen as a steady line where mains aliases.

A potentiometer's wiring picks up the mains (50 or 60 Hz, with a rectifier's ripple at twice that and
a third harmonic from saturating transformers);
a logger without an anti-alias filter folds it to ``|k F - m f_s|``: 60 Hz logged at 50 Hz is a 10 Hz
line, its third harmonic a 20 Hz one; at 200 Hz both are logged as they are. No motion of the joint
makes it (the command does not drive the joint there, and the model replays the command), so the
residual carries it whole; the velocity channel then sits far below its noise ceiling and the
residual tests fail (a line is coloured), but nothing in the bank names it. Left unsaid, the record
reads as a misfit of the motion the bank cannot name.

What tells it from a misfit of the motion at the same frequency (a structural mode the model lacks,
rung by each step of the command) is that it is steady: the same size in every stretch of the record,
holds included. So a joint's residual carries mains when, in the band a mains line occupies after
aliasing by this logger (:func:`bands`), its velocity residual has

* a line: the band's strongest bin LINE_CONTRAST times the median of the spectrum outside it;
* most of the misfit: at least SHARE_MIN of the residual's power;
* the same size throughout: the band's energy over windows of the record varies by at most
  STEADY_CV (coefficient of variation). A mode rung by steps varies by more than 1 (measured on
  8 and 10 Hz modes in the rig templates' closed-loop records: 1.24, 1.25; 60 Hz hum on the same
  records, with a steady or a 10 %-jittered clock, read by the controller or not: 0.04-0.16);
* no motion of the model there: the model's own velocity (the logged command replayed) has at most
  MOTION_RATIO of the residual's energy in the band. A joint driven at that frequency (a sine
  excitation) whose gain the model misses leaves a steady line too, beside a larger one of its own.
  Hum the controller reads back (the same sensor wired to both) is logged in the command as well;
  the model driven by that command moves at the alias as the joint did, by a fraction of the line
  (a loop that crosses over at a few hertz), and the residual keeps the hum.

A line that aliases to within a few hertz of zero (50 Hz mains on a 50 Hz or 10 Hz log) is a slow
wave that a record of a minute cannot tell from a drift; it is not judged here.
"""

from __future__ import annotations

import math

import numpy as np

from ..ingest.timegrid import regular_deviations

MAINS_HZ = (50.0, 60.0)
HARMONICS = (1, 2, 3)        # the fundamental and the two harmonics picked up beside it
MAINS_TOLERANCE = 0.01       # the mains' frequency, +- this share (a grid holds 0.4 %; a generator set less well)
LINE_CONTRAST = 10.0         # the band's strongest bin over the median of the spectrum outside the band
SHARE_MIN = 0.5              # share of the velocity residual's power in the band
STEADY_CV = 0.6              # largest coefficient of variation of the band's energy over the record's windows
MOTION_RATIO = 0.5           # the model's velocity energy in the band, at most this share of the residual's there
MIN_WINDOWS = 6              # windows the steadiness is judged over, at the least
MIN_WINDOW_S = 1.0           # shortest window (s); a window also holds 5 periods of the line and the band-pass's response


def bands(rate_hz: float, jitter_s: float, resolution_hz: float) -> list[dict]:
    """Where mains lines fall in a record logged at ``rate_hz`` with rms timing jitter ``jitter_s``,
    seen in a spectrum of resolution ``resolution_hz``: one row per mains frequency and harmonic
    whose alias can be judged, {'mains_hz', 'harmonic', 'alias_hz', 'band_hz': (lo, hi)}.

    The half-width is the mains' tolerance aliased, the line's broadening by a logger whose sample
    instants wander (a phase random walk of (2 pi f jitter)^2 per sample: a Lorentzian of that times
    rate / 4 pi half-width; twice that is taken) and two bins of the spectrum. A band wider than its
    line's own frequency (a line near 0 Hz, or one the jitter smears over the spectrum) is left out."""
    nyquist = 0.5 * rate_hz
    out = []
    for mains in MAINS_HZ:
        for k in HARMONICS:
            f = k * mains
            alias = abs(f - round(f / rate_hz) * rate_hz)
            diffusion = (2.0 * math.pi * f * jitter_s) ** 2
            half = k * mains * MAINS_TOLERANCE + 2.0 * diffusion * rate_hz / (4.0 * math.pi) + 2.0 * resolution_hz
            if 2.0 * half > alias:
                continue
            out.append({"mains_hz": mains, "harmonic": k, "alias_hz": round(alias, 3),
                        "band_hz": (round(alias - half, 3), round(min(alias + half, nyquist), 3))})
    return out


def _band_passed(x: np.ndarray, rate_hz: float, lo: float, hi: float) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    spec = np.fft.rfft(x - x.mean())
    ff = np.fft.rfftfreq(x.size, 1.0 / rate_hz)
    spec[(ff < lo) | (ff > hi)] = 0.0
    return np.fft.irfft(spec, x.size)


def line(residual: np.ndarray, simulated: np.ndarray, rate_hz: float, spectrum: tuple[np.ndarray, np.ndarray],
         band: tuple[float, float]) -> dict:
    """The figures of one band of a velocity residual (``simulated``: the model's velocity on the
    same samples): its strongest bin's frequency, the contrast, the share of the power, the
    coefficient of variation of its energy over the record's windows (None when the record is too
    short for MIN_WINDOWS of them) and the model's energy in the band over the residual's."""
    f, pxx = (np.asarray(a, dtype=float) for a in spectrum)
    lo, hi = band
    inside = (f >= lo) & (f <= hi)
    if not inside.any() or inside.all() or not np.any(pxx > 0):
        return {}
    k = np.flatnonzero(inside)[int(np.argmax(pxx[inside]))]
    floor = float(np.median(pxx[~inside]))
    share = float(pxx[inside].sum() / pxx.sum())
    passed = _band_passed(residual, rate_hz, lo, hi)
    energy = float(np.mean(passed ** 2))
    moved = _band_passed(simulated, rate_hz, lo, hi)
    w = int(round(rate_hz * max(MIN_WINDOW_S, 5.0 / lo, 1.0 / (hi - lo))))
    m = passed.size // max(w, 1)
    cv = None
    if m >= MIN_WINDOWS and energy > 0:
        e = np.mean(passed[: m * w].reshape(m, w) ** 2, axis=1)
        cv = float(np.std(e) / np.mean(e))
    return {"peak_hz": round(float(f[k]), 3), "contrast": float(pxx[k] / floor) if floor > 0 else math.inf,
            "share": share, "steadiness_cv": cv,
            "model_motion_ratio": float(np.mean(moved ** 2)) / energy if energy > 0 else math.inf}


def found(tests: dict[str, dict], time: np.ndarray, rate_hz: float) -> dict[str, dict]:
    """Per joint whose velocity residual (``tests``: diagnosis.residual_tests of the final model, with
    its ``_velocity_residual``, ``_velocity_simulated`` and ``_spectrum``; ``time``: the record's
    sample times over the same samples, s) carries a
    steady mains line: the band's row of :func:`bands` and its figures of :func:`line`. Of several
    bands that hold one, the one with the most power."""
    period = np.diff(np.asarray(time, dtype=float))
    dev = regular_deviations(period)[2] if period.size else period
    jitter = float(np.sqrt(np.mean(dev ** 2))) if dev.size else 0.0
    out: dict[str, dict] = {}
    for j, test in tests.items():
        spectrum, residual, simulated = (test.get(k) for k in
                                         ("_spectrum", "_velocity_residual", "_velocity_simulated"))
        if spectrum is None or residual is None or simulated is None or len(spectrum[0]) < 2:
            continue
        resolution = float(spectrum[0][1] - spectrum[0][0])
        best = None
        for b in bands(rate_hz, jitter, resolution):
            fig = line(residual, simulated, rate_hz, spectrum, b["band_hz"])
            if (fig and fig["contrast"] >= LINE_CONTRAST and fig["share"] >= SHARE_MIN
                    and fig["steadiness_cv"] is not None and fig["steadiness_cv"] <= STEADY_CV
                    and fig["model_motion_ratio"] <= MOTION_RATIO
                    and (best is None or fig["share"] > best["share"])):
                best = b | fig
        if best is not None:
            out[j] = best
    return out


def cause(joint: str, finding: dict) -> str:
    """The record cause for one joint of :func:`found`."""
    k = finding["harmonic"]
    source = f"{finding['mains_hz']:g} Hz mains"
    if k != 1:
        source += f" (its harmonic {k}, {k * finding['mains_hz']:g} Hz)"
    lo, hi = finding["band_hz"]
    return (f"the position of {joint} carries a steady line at {finding['peak_hz']:.2f} Hz "
            f"({100 * finding['share']:.0f} % of the velocity misfit, in {lo:.2f}-{hi:.2f} Hz, the same size "
            f"throughout the record): where {source} "
            f"falls at this log's rate ({finding['alias_hz']:.2f} Hz). Mains picked up by the sensor's wiring and "
            "sampled without an anti-alias filter does this; a misfit of the joint's motion, rung by the command, "
            "would come and go with it. Shield the sensor's cable or filter it before the logger (below half the "
            "log's rate) and record again; a vibration source on the rig at that frequency (a pump's ripple) is "
            "the other reading. The effects tried on this record are the closest, not its cause")
