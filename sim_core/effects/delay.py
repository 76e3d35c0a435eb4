from numba import njit

from ..components.base import Parameter
from ..kernel.layout import AP, ERR_DELAY_OVERRUN, XG_ERROR, XG_HIST_COUNT, XS, col
from .base import CITE_CATALOG, Effect, clip_grid

DELAY = AP.declare("delay", col("DELAY", "s", "dead time of the command"))
CURSOR = XS.declare("delay", col("CURSOR", "-", "delay-line read cursor (event count, stored as float)"))


class Delay(Effect):
    """Transport delay of the valve command (bus, amplifier processing, pilot stage).

    u_d(t) = u(t - d). The whole response shifts later by d without changing its shape; the
    residual against an undelayed model is about -d times the joint velocity. The kernel averages
    the delayed command over each substep, which makes the delay fractional and smooth in d.
    """

    name = "delay"
    citation = CITE_CATALOG + " (§3.3)"
    PARAMETERS = (Parameter("delay", "s", "dead time between command and amplifier", 0.03, 0.0, 0.3),)
    HOOKS = {"command": "delay_command"}
    ORDER = 0
    CONFUSIONS = {
        "spool_lag": "a chirp to higher frequencies (a lag rolls the magnitude off, a delay does not)",
        "backlash": "slow reversals at several speeds (play costs the same angle at every speed, a delay costs angle in proportion to speed)",
    }

    @classmethod
    def lower(cls, params, lw, a):
        super().lower(params, lw, a)
        lw.AP[a, DELAY] = params["delay"]

    @classmethod
    def reset(cls, ctx, a, q_dof, tau, on):
        ctx.XS[a, CURSOR] = -1.0

    @classmethod
    def command_delay(cls, AP_, a):
        return float(AP_[a, DELAY])

    @classmethod
    def candidate(cls, spec, joint, scales, guess, current):
        grid = [0.005, 0.012, 0.025, 0.045, 0.07, 0.1, 0.15, 0.22, 0.3]
        if "delay" in guess:
            d = guess["delay"]
            grid += [d, 0.7 * d, 1.4 * d]
        null = current["delay"] if current else 0.0
        return {"free": [("delay", 0.0, 0.3, False, null, "s")], "grid": [[v] for v in clip_grid(grid, 0.0, 0.3)]}

    @classmethod
    def signature_guess(cls, sig, context):
        lag = sig.get("delay_lag_s")
        return {"delay": float(lag)} if lag is not None and lag > 0 else None


@njit
def delayed_command(a, t0, t1, HT, HU, XG, XS):
    """Mean of the command of actuator ``a`` over [t0, t1] from the event history (ZOH events)."""
    count = int(XG[XG_HIST_COUNT])
    cap = HT.shape[0]
    c = int(XS[a, CURSOR])
    # advance the cursor to the last event at or before t0
    while c + 1 < count and HT[(c + 1) % cap] <= t0:
        c += 1
    if c >= 0 and c < count - cap:
        XG[XG_ERROR] = ERR_DELAY_OVERRUN
        c = count - cap
    XS[a, CURSOR] = c
    acc = 0.0
    tau = t0
    j = c
    while tau < t1:
        val = HU[j % cap, a] if j >= 0 else 0.0
        nxt = HT[(j + 1) % cap] if j + 1 < count else 1e300
        end = nxt if nxt < t1 else t1
        if end > tau:
            acc += val * (end - tau)
            tau = end
        j += 1
    return acc / (t1 - t0)


@njit(inline="always")
def delay_command(u, a, t, h, AP, XS, XG, HT, HU):
    d = AP[a, DELAY]
    return delayed_command(a, t - d, t + h - d, HT, HU, XG, XS)
