"""The candidate round's progress bar shows fits done and the best candidate so far."""

import io
import math
from types import SimpleNamespace

from sim_core.identification.progress import RoundProgress


def ev(label: str, gain: float):
    return SimpleNamespace(candidate=SimpleNamespace(label=label), gain=gain)


def last_frame(text: str) -> str:
    return [f for f in text.replace("\n", "\r").split("\r") if f.strip()][-1]


def test_the_bar_counts_every_fit_and_shows_the_highest_gain_so_far():
    out = io.StringIO()
    bar = RoundProgress(5, "round 1: fitting 5 candidates", True, file=out, mininterval=0)
    bar.done(ev("friction@j1", 1.0))
    assert "best friction@j1 +1.0" in last_frame(out.getvalue())
    for e in (ev("deadband@j2", 7.5), ev("leakage@j2", 3.0), ev("payload", math.nan), ev("backlash@j3", -math.inf)):
        bar.done(e)
    frame = last_frame(out.getvalue())
    assert "5/5" in frame and "best deadband@j2 +7.5" in frame        # a lower or failed fit later does not replace it
    assert bar.best.candidate.label == "deadband@j2"
    bar.close()


def test_a_failed_first_fit_is_not_the_best():
    bar = RoundProgress(2, "round 1", False)
    bar.done(ev("payload", math.nan))
    assert bar.best is None
    bar.done(ev("friction@j1", -0.4))         # a negative gain is still a fit, and the best so far
    assert bar.best.candidate.label == "friction@j1"
    bar.close()


def test_a_disabled_bar_draws_nothing():
    out = io.StringIO()
    bar = RoundProgress(1, "round 1", False, file=out, mininterval=0)
    bar.done(ev("friction@j1", 2.0))
    bar.close()
    assert out.getvalue() == ""
