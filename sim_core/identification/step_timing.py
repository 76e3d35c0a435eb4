"""How well a perfect model can fit a record whose command is replayed as its period means.

A controller faster than its logger steps its set point anywhere within a log period; the period-mean
replay (command_hold.py) puts each step's share of the period at one half, the expected value, while
the real one was anywhere from 0 to 1. An open-loop replay integrates that error into the angle for
the rest of the record, which the real loop pulled back: on the rotary rig logged at 50 Hz from a 1
kHz loop, the truth model itself fits the whole-record angle to 79-88 %. That misfit belongs to the
log, not to the model, so it joins the noise in the ceiling each channel is judged against (the
forward selection's stop, below-the-floor naming, the unexplained verdict); otherwise a record whose
every cause was named still read as unexplained.

The misfit is estimated on the calibrated baseline: at each period in which the set point steps,
the command's mean is drawn as ``u_k + phi (u_k+1 - u_k)`` with ``phi`` uniform in [0, 1] (the
step anywhere in the period), the model is simulated on ``DRAWS`` such replays, and each channel's
sum of squared differences from the period-mean replay is kept at its 90th percentile over the
draws: the angle's is a random walk of a few dozen steps, whose misfit on one record ranged over two
decades on the rotary rig's log (0.15 to 18 rad^2 over eight draws), so a perfect model is judged
against what it reaches on nine records in ten, not on the average one. A period steps where the
set point the P law implies, ``r = y + u / K`` (``K``: the loop gain closed_loop.py found), moves by
more than ``STEP_MADS`` robust spreads of its sample-to-sample changes: under the law those changes
are the log's rounding only, and a smooth set point (a sine) has no steps. A period saturated at both
ends carries no uncertainty (its command is the limit throughout).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .closed_loop import unsaturated
from .command_hold import period_mean
from .record import Record

DRAWS = 12         # replays drawn
QUANTILE = 0.9     # of the draws' misfits: what a perfect model stays within on nine records in ten
STEP_MADS = 10.0   # a set-point change this many robust spreads (1.4826 MAD) above its median: a step
SEED = 0


def step_periods(u: np.ndarray, y: np.ndarray, gain: float, command_range=None) -> np.ndarray:
    """Indices k of the periods [t_k, t_k+1) in which the set point ``y + u / gain`` steps."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    if gain <= 0 or u.size < 3:
        return np.zeros(0, dtype=int)
    dr = np.abs(np.diff(y + u / gain))
    inside = unsaturated(u, command_range)
    moving = (inside[1:] | inside[:-1]) & (np.diff(u) != 0.0)
    if not moving.any():
        return np.zeros(0, dtype=int)
    med = float(np.median(dr[moving]))
    mad = 1.4826 * float(np.median(np.abs(dr[moving] - med)))
    return np.flatnonzero(moving & (dr > med + STEP_MADS * max(mad, 1e-12)))


def steps(logged: Record, loop: dict, joints: list[str], spec) -> dict[int, np.ndarray]:
    """Command column -> its step periods, per closed-loop joint of ``joints`` (``logged``: the record
    as logged, held samples; ``loop``: closed_loop.detect's answer)."""
    found = {}
    for j in joints:
        c = logged.joint_names.index(j)
        ks = step_periods(logged.U[:, c], logged.angles[j], loop["joints"][j]["gain"], spec.joint(j).command_range)
        if ks.size:
            found[c] = ks
    return found


def drawn_commands(U: np.ndarray, steps: dict[int, np.ndarray], rng) -> np.ndarray:
    """The period-mean replay of the logged ``U`` with each step period's mean drawn instead
    (``steps``: column -> its step periods)."""
    out = period_mean(U, list(steps))
    for c, ks in steps.items():
        phi = rng.uniform(0.0, 1.0, ks.size)
        out[ks, c] = U[ks, c] + phi * (U[ks + 1, c] - U[ks, c])
    return out


def misfit(model, logged: Record, replayed: Record, stepped: dict[int, np.ndarray], prob, runner) -> dict:
    """Per (joint, channel) of ``prob`` (the validation problem, on ``replayed``), the sum of squares of
    what the unknown step instants alone change in the model's output (its ``QUANTILE`` over the
    draws); {} when no period steps. ``logged``: the record as logged (held samples); ``stepped``: its
    step periods (:func:`steps`)."""
    if not stepped:
        return {}
    ref = runner.simulate(model, prob.n)
    if not ref.ok:
        return {}
    base = prob.simulated(ref)
    rng = np.random.default_rng(SEED)
    sums: dict[tuple[str, str], list[float]] = {}
    for _ in range(DRAWS):
        rec = replace(replayed, U=drawn_commands(logged.U, stepped, rng))
        out = runner.simulate(model, prob.n, rec=rec)
        if not out.ok:
            continue
        sim = prob.simulated(out)
        for j in prob.joints:
            for ch in ("angle", "velocity"):
                d = sim[(j, ch)] - base[(j, ch)]
                sums.setdefault((j, ch), []).append(float(d @ d))
            if prob.restart:
                d = prob.restarted(j, sim[(j, "angle")]) - prob.restarted(j, base[(j, "angle")])
                sums.setdefault((j, "restarted"), []).append(float(d @ d))
    return {k: float(np.quantile(v, QUANTILE)) for k, v in sums.items()}


def ceiling(noise_ceiling: float, meas: np.ndarray, sum_of_squares: float) -> float:
    """A channel's ceiling (fit, %) once the replay's misfit joins the noise's: the two are
    independent, so their squared norms add."""
    den = float(np.linalg.norm(meas - meas.mean())) or 1.0
    noise = (1.0 - noise_ceiling / 100.0) * den
    return 100.0 * (1.0 - math.sqrt(noise * noise + sum_of_squares) / den)
