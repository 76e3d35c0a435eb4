"""Where a candidate's fit starts. A new effect enters the model at its null (the model without it),
and some effects' slopes vanish there: a leak coefficient's on its log scale, a deadband's at zero
width. A least-squares fit started at the null can stay there. Beside accepted effects (fitted
without the candidate, they absorb what they can of it) the null ranks above the grid's starts even
where the effect is in the record, so there the best grid point is fitted from too. Real fits on a
HydroLek shoulder record with a hidden leak and a grid whose only start is 25 times too large."""

import dataclasses

import numpy as np
import pytest

from sim_core.dataset import Dataset
from sim_core.excitation import multilevel_prbs
from sim_core.identification import output_error as oe
from sim_core.identification.candidates import bank
from sim_core.identification.metrics import noise_std
from sim_core.identification.parameters import find_effect
from sim_core.identification.record import record_from_dataset
from sim_core.identification.selection import Setting, _Baseline, evaluate, free_list, model_with
from sim_core.identification.simulation import Runner, model_spec
from sim_core.model.spec import load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator

JOINT = "j2"
FLOW_KEY = f"joints.{JOINT}.valve.rated_flow"
LEAK = 2e-12              # m^3/(s Pa), the hidden cross-port leak
# m^3/(s Pa): the grid's only start, 25 times too large, inside the range. From the range's top (3e-10)
# the profiled flow gain starts on its own lower bound too, and the fit out of that corner ended within
# its budget on one CPU and needed more than the 80 of its budget on another (AMD EPYC), beside an
# accepted effect too; from here 47 on that one
START = 5e-11
NULL = 1e-30              # m^3/(s Pa): 1e-23 m^3/s at 10 MPa, far below a chamber pressure's rounding


@pytest.fixture(scope="module")
def record():
    truth = load_robot("hydrolek")
    truth.enable_effect("leakage", JOINT, internal=LEAK, external=0.0)
    t, U = multilevel_prbs(truth, JOINT, levels=5, amplitude=6, duration=8.0, rate=200, seed=3)
    cols = Simulator(Plant(truth).create_context(seed=1)).run(t, U).dataset_columns()
    return record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), load_robot("hydrolek"),
                               source="rec")


def _leak_candidate(model, null: float | None = None, start: float = START):
    """The bank's leak candidate, its grid's only start at ``start``. ``null``: its null and its
    range's bottom moved there (NULL: a leak that changes no state by as much as its rounding, so the
    slope vanishes on every machine; at the bank's own 1e-15 it is faint, not nil, and whether a
    finite difference resolves it depends on the CPU's rounding)."""
    cand = bank(model, [JOINT], effects=["leakage"])[0]
    assert not cand.existing
    if null is None:
        return dataclasses.replace(cand, grid=[[start, 1e-16]])
    free = [dataclasses.replace(fp, lower=null) for fp in cand.free]
    return dataclasses.replace(cand, free=free, fixed={fp.key.split(".")[-1]: null for fp in free},
                               grid=[[start, null]])


def test_where_the_null_ranks_first_the_grid_is_fitted_from_too(record):
    model = model_spec(load_robot("hydrolek"))
    cand = _leak_candidate(model, null=NULL)
    s0 = model_with(model, [], cand, {})
    free = free_list(s0, cand, [], [FLOW_KEY])
    grid = [p + [fp.get(s0) for fp in free[len(cand.free):]] for p in cand.grid]
    prob, runner = oe.Problem(record, [JOINT]), Runner(record)
    key = f"effects.leakage.{JOINT}.internal"

    def fitted(grid_start_too):
        return oe.fit(runner, prob, s0, free, grid=grid, max_sims=80, uncertainty=False, tol=1e-3,
                      grid_start_too=grid_start_too).values[key]

    # the premise: the null ranks above the overshooting start, and a fit from there does not move
    assert fitted(False) < 0.01 * LEAK
    assert fitted(True) == pytest.approx(LEAK, rel=0.05)


class LeakLog(Runner):
    """The real runner, keeping the leak coefficient of every model it simulates."""

    def __init__(self, rec):
        super().__init__(rec)
        self.leaks = []

    def simulate(self, spec, n=None, rec=None, owned=False, **kw):
        inst = find_effect(spec, "leakage", JOINT)
        self.leaks.append(inst.params["internal"] if inst is not None else 0.0)
        return super().simulate(spec, n, rec, owned, **kw)


def test_beside_accepted_effects_a_candidate_starts_from_its_grid(record):
    """``selection.evaluate`` in a later round: with an effect already accepted (a deadband of zero
    width, which changes nothing) the new leak candidate, whose null ranks first, is fitted from its
    grid point too (simulated there once to rank it and again to start from it), and found."""
    model = model_spec(load_robot("hydrolek"))
    accepted = bank(model, [JOINT], effects=["deadband"])[0]
    before = model_with(model, [], accepted, {f"effects.deadband.{JOINT}.width": 0.0})
    est, val = oe.Problem(record, [JOINT]), oe.Problem(record, [JOINT], start=int(record.n * 0.6))
    runner = LeakLog(record)
    st = Setting(runner, est, Runner(record), val, [FLOW_KEY], {JOINT: noise_std(record.angles[JOINT])}, {})
    base = _Baseline(st)
    base_out, base_cost = base.outputs(before), base.cost(before)
    runner.leaks.clear()
    ev = evaluate(st, _leak_candidate(model), before, [(accepted, {})], base_out, base_cost, round_=2)
    assert sum(v == pytest.approx(START, rel=1e-6) for v in runner.leaks) >= 2
    assert ev.values[f"effects.leakage.{JOINT}.internal"] == pytest.approx(LEAK, rel=0.05)
    assert ev.gain > 2.0
