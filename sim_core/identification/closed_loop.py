"""Is the record closed loop? A controller that computed the command from the measured position.

Under feedback ``u = K (r - y)`` from the position reading ``y``, every change of the reading (the
sensor's noise included) reaches the command at once: sample to sample, ``du = -K dy`` wherever the
reference holds or moves smoothly. In open loop the command is exogenous: a PRBS or a joystick does
not follow the sensor's noise, and a signal and its own derivative are uncorrelated. The test
therefore correlates the command's increments with the reading's, at lags 0 to ``MAX_LAG`` samples
(a controller that logs the reading one sample before it acts), leaving out the largest command
jumps (reference steps, PRBS switches) and samples at the command limits (saturation cuts the loop).
A reference that moves all the time (a sine to track, a ramp) puts its own increments into both,
``du = K (dr - dy)`` with ``dy`` mostly the joint following ``dr``: the noise's share of ``dy`` is then
small and the correlation weak; a PI controller's integral adds ``K_i e dt`` to ``du``, which grows with
the error while the joint moves to close it, so it biases ``K`` low. So the same test also runs on what
is left of each signal after its local quadratic in time over ``LOCAL_SAMPLES`` samples (fitted at each
sample's own time, so uneven steps are allowed): a smooth reference, the motion that follows it and an
integral's smooth action vanish there, a sensor's noise and the command's answer to it do not, and in
open loop the command's and the reading's residuals stay as uncorrelated as their increments. It
takes only windows over which the command changes at every step: a controller acting on a noisy
reading does, a controller that parks the valve once its joint settles does not act there, and a
held open-loop command (a PRBS) is left with its switches, where the plant's step response, not
feedback, ties the two. The evidence is the test with the stronger correlation: the larger share of
the command's changes that ``-K dy`` explains, the less of anything else is left to bias the gain.
Evidence reported per joint: that correlation, the gain ``K`` it implies (V per rad or m), the lag,
the share of the command's changes ``-K dy`` explains, and which test showed it (``test``:
``increments`` or ``local_residuals``).

What it means for the diagnosis: the recorded command is what the valve saw, so it stays the model's
input and output-error fits are valid; but the loop shapes what the record shows. A delay appears
as phase (a lag between command and motion, a loop that rings), not as a dead time after steps; a
deadband appears as limit cycles or a standing error around the reference, not as a stall at small
commands; and the excitation is as narrow as the loop's bandwidth, so their intervals are wider.
Between two logged samples the command is replayed held, which is what the valve saw only when the
controller ran at the log's rate, or as the mean of the two, where the record says the controller
ran faster (command_hold.py); a faster controller's reference steps fall anywhere between samples,
an error an open-loop replay carries to the end of the record (step_timing.py).

The same replay carries any flow bias the calibration left (a supply or load it could not identify)
to the end of the record, while the real loop pulled that error back within a few of its time
constants; so on such a record the validation score also takes the angle fit restarted from the
recorded position every ``RESTART_TAUS`` loop time constants: what the model predicts over the loop's
own horizon. The whole-record angle stays in the score: a leak's evidence on a position-only record
is that very drift. The time constant is ``1 / (K G)``, with ``K`` the loop gain above and ``G`` the
joint's speed per volt of command (regressed from the record).
"""

from __future__ import annotations

import math

import numpy as np

from .metrics import velocity
from .record import Record

MAX_LAG = 2               # samples between the reading and the command it causes
JUMP_QUANTILE = 0.95      # command increments above this quantile of |du| are left out (steps, switches)
CORRELATION_LIMIT = -0.5  # correlation of du and dy at or below this: feedback
LOCAL_SAMPLES = 7         # samples of the local quadratic whose residual the second test correlates
RESTART_TAUS = 4.0        # loop time constants per validation window (an error decays to 2 % in 4)

NOTE = ("the record was taken in closed loop ({joints}): the command follows -K (q - r) with a smooth reference r. "
        "The recorded command is what the valve saw and stays the model's input; but a delay shows as phase (a lag "
        "between command and motion, a ringing loop) rather than as dead time after steps, and a deadband as limit "
        "cycles or a standing error around the reference rather than a stall at small commands; the loop's narrow "
        "excitation widens their intervals. Between samples the model holds each logged command, or replays the "
        "mean of each two where the record fits better that way (a controller faster than its log; see the command "
        "between samples): log at the controller's own rate (a controller faster than its log steps between "
        "samples, and no replay knows where)")

# Said beside an unexplained verdict on a closed-loop record: a cause in the record, not in the model
HELD_REPLAY = ("the record is closed loop and its command is replayed held from one logged sample to the next, which "
               "is what the valve saw only if the controller ran at the log's rate: a faster controller's reference "
               "steps fall between samples, the replay starts each move up to one period late, and an open-loop "
               "replay carries that to the end of the record. Check the controller's rate; log the command at it")


def unsaturated(u: np.ndarray, command_range: tuple[float, float] | None) -> np.ndarray:
    """Samples whose command is strictly inside its range (at a limit the loop is cut)."""
    if command_range is None:
        return np.ones(u.size, dtype=bool)
    lo, hi = command_range
    span = 1e-6 * max(hi - lo, 1.0)
    return (u > lo + span) & (u < hi - span)


def _evidence(test: str, rho: float = 0.0, gain: float = 0.0, lag: int = 0) -> dict:
    """One test's evidence: correlation ``rho`` at ``lag`` samples, the gain ``K`` it implies."""
    return {"correlation": round(rho, 4), "gain": gain, "lag_samples": lag, "explained": round(rho * rho, 4),
            "closed_loop": rho <= CORRELATION_LIMIT, "test": test}


def _correlated(du: np.ndarray, dy: np.ndarray, keep: np.ndarray, test: str) -> dict:
    """The most negative correlation of ``du`` with ``dy`` over lags 0..MAX_LAG (``du`` that many
    samples later), over ``keep``'s samples without the largest command changes."""
    best = _evidence(test)
    big = np.abs(du)
    if keep.any():
        keep = keep & (big <= np.quantile(big[keep], JUMP_QUANTILE))
    for lag in range(MAX_LAG + 1):
        a = du[lag:][keep[lag:]]
        b = dy[: dy.size - lag][keep[lag:]]
        if a.size < 10:
            continue
        a, b = a - a.mean(), b - b.mean()
        sa, sb = float(np.sqrt(a @ a)), float(np.sqrt(b @ b))
        if sa <= 0 or sb <= 0 or not (math.isfinite(sa) and math.isfinite(sb)):
            continue
        rho = float(a @ b) / (sa * sb)
        if rho < best["correlation"]:
            best = _evidence(test, rho, -float(a @ b) / float(b @ b), lag)
    return best


def local_residuals(t: np.ndarray, f: np.ndarray, samples: int = LOCAL_SAMPLES) -> np.ndarray:
    """``f`` less its least-squares quadratic in time ``t`` over the ``samples`` (odd) samples centred on
    each one, at that sample's time; the first and last ``samples // 2`` have none. Zero for anything
    quadratic in time, however uneven the steps."""
    half = samples // 2
    centre = np.arange(half, f.size - half)
    window = centre[:, None] + np.arange(-half, half + 1)[None, :]
    x = t[window] - t[centre][:, None]
    x = x / np.abs(x).max(axis=1, keepdims=True)
    x2 = x * x
    s0, s1, s2, s3, s4 = float(samples), x.sum(1), x2.sum(1), (x2 * x).sum(1), (x2 * x2).sum(1)
    fw = f[window]
    r0, r1, r2 = fw.sum(1), (x * fw).sum(1), (x2 * fw).sum(1)
    # the fit's constant term by Cramer's rule on the 3 x 3 normal equations (one per sample)
    det = s0 * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s3 * s2) + s2 * (s1 * s3 - s2 * s2)
    c0 = r0 * (s2 * s4 - s3 * s3) - s1 * (r1 * s4 - s3 * r2) + s2 * (r1 * s3 - s2 * r2)
    return f[centre] - c0 / det


def increments_evidence(u: np.ndarray, y: np.ndarray, command_range: tuple[float, float] | None = None) -> dict:
    """Correlation of the command's and the reading's increments (most negative over lags 0..MAX_LAG),
    the gain ``K`` of ``du ~ -K dy`` at that lag and the share of ``du``'s variance it explains."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    inside = unsaturated(u, command_range)
    return _correlated(np.diff(u), np.diff(y), inside[1:] & inside[:-1], "increments")


def local_residual_evidence(u: np.ndarray, y: np.ndarray, command_range: tuple[float, float] | None = None,
                            t: np.ndarray | None = None) -> dict:
    """The same of what is left of each after its local quadratic in time ``t`` (s; evenly spaced
    samples where None), over windows whose every sample is inside the command's range and whose
    command changes at every step: a controller acting on a noisy reading does, one that parks the
    valve within a settle band does not act on the reading there (the reading's noise would only
    dilute the correlation), and a held open-loop command (a PRBS, a doublet) leaves only its
    switches, whose windows correlate as the plant's step response does, not as feedback; no
    feedback where the record is too short or its clock does not increase."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    t = np.arange(u.size, dtype=float) if t is None else np.asarray(t, float)
    if u.size < 10 + LOCAL_SAMPLES or not np.all(np.diff(t) > 0):
        return _evidence("local_residuals")
    inside = unsaturated(u, command_range)
    n = u.size - LOCAL_SAMPLES + 1
    changes = np.diff(u) != 0.0
    keep = np.ones(n, dtype=bool)
    for k in range(LOCAL_SAMPLES):
        keep &= inside[k:k + n]
    for k in range(LOCAL_SAMPLES - 1):
        keep &= changes[k:k + n]
    return _correlated(local_residuals(t, u), local_residuals(t, y), keep, "local_residuals")


def joint_evidence(u: np.ndarray, y: np.ndarray, command_range: tuple[float, float] | None = None,
                   t: np.ndarray | None = None) -> dict:
    """:func:`increments_evidence` or :func:`local_residual_evidence`, whichever correlation is the more
    negative (a smooth reference or an integral's action masks the increments, not the local
    residuals); the increments' on a tie."""
    first = increments_evidence(u, y, command_range)
    second = local_residual_evidence(u, y, command_range, t)
    return second if second["correlation"] < first["correlation"] else first


def direction(u: np.ndarray, y: np.ndarray, dt: float, command_range: tuple[float, float] | None = None) -> dict:
    """Which way ``y`` moves per volt of command ``u``: the least-squares slope of its smoothed velocity
    on the command (an offset allowed; m/s or rad/s per V) and their correlation, over samples whose
    command is inside its range (at a limit the joint may sit in an end stop). Zeros where either is
    constant or fewer than 10 samples are left."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    keep = unsaturated(u, command_range) & np.isfinite(y) & np.isfinite(u)
    none = {"speed_per_volt": 0.0, "correlation": 0.0}
    if keep.sum() < 10:
        return none
    v = velocity(np.where(np.isfinite(y), y, 0.0), dt)[keep]
    uc = u[keep] - u[keep].mean()
    vc = v - v.mean()
    su, sv = float(uc @ uc), float(vc @ vc)
    if su <= 0.0 or sv <= 0.0 or not math.isfinite(sv):
        return none
    return {"speed_per_volt": float(uc @ v) / su, "correlation": float(uc @ vc) / math.sqrt(su * sv)}


def time_constant(u: np.ndarray, y: np.ndarray, dt: float, gain: float,
                  command_range: tuple[float, float] | None = None) -> float | None:
    """Time constant (s) of the position loop ``u = K (r - y)`` around a joint whose speed is about
    ``G u``: ``1 / (K G)``, ``G`` the record's speed per volt (:func:`direction`). None where that is
    not positive."""
    if gain <= 0:
        return None
    g = direction(u, y, dt, command_range)["speed_per_volt"]
    return 1.0 / (gain * g) if g > 0 else None


def validation_window(evidence: dict) -> float | None:
    """Seconds between the validation angle's restarts from the record: ``RESTART_TAUS`` time constants
    of the slowest closed loop (None: no closed loop, or none whose time constant the record gives)."""
    taus = [e["time_constant_s"] for e in evidence.get("joints", {}).values()
            if e.get("closed_loop") and e.get("time_constant_s")]
    return RESTART_TAUS * max(taus) if taus else None


def _unit(spec, joint: str) -> str:
    if spec is None:
        return "V per rad (or m)"
    try:
        return "V/m" if spec.tree.is_prismatic(spec.joint(joint).dof) else "V/rad"
    except AttributeError:
        return "V/rad"


def detect(rec: Record, spec=None) -> dict:
    """Per commanded, measured joint: the evidence; ``closed_loop`` when any joint shows feedback,
    with the note for the report."""
    ranges = {j: (spec.joint(j).command_range if spec is not None else None) for j in rec.targets}
    joints = {j: joint_evidence(rec.u(j), rec.angles[j], ranges[j], rec.time) for j in rec.targets}
    for j, e in joints.items():
        if e["closed_loop"]:
            e["time_constant_s"] = time_constant(rec.u(j), rec.angles[j], rec.dt, e["gain"], ranges[j])
    closed = [j for j, e in joints.items() if e["closed_loop"]]
    out = {"closed_loop": bool(closed), "joints": joints,
           "rule": f"correlation of the command's and the position reading's sample-to-sample changes (lags 0-{MAX_LAG}, "
                   f"without the largest {1 - JUMP_QUANTILE:.0%} of command jumps and saturated samples) <= {CORRELATION_LIMIT:g}, "
                   f"or of what is left of each after its local quadratic in time over {LOCAL_SAMPLES} samples (a reference that moves all the time, "
                   f"a PI controller's integral; windows whose command changes at every step), whichever is the more negative"}
    if closed:
        out["note"] = NOTE.format(joints=", ".join(
            f"{j}: correlation {joints[j]['correlation']:+.2f}"
            + (" after each signal's local quadratic, which a moving set point, a controller's integral or a "
               "parked valve does not mask"
               if joints[j]["test"] == "local_residuals" else "")
            + f", K = {joints[j]['gain']:.3g} {_unit(spec, j)}" for j in closed))
    return out
