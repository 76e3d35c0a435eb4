"""Starting points ranked with runs abandoned early (output_error._rank): a run whose early samples
already cost more than the best start of its group cannot be chosen, so it stops there. The choice
must be the one the whole runs give; the bound that stops a run must be a lower bound."""

import math

import numpy as np
import pytest

from sim_core.dataset import Dataset
from sim_core.excitation import multilevel_prbs
from sim_core.identification import output_error as oe
from sim_core.identification.record import record_from_dataset
from sim_core.identification.simulation import PIECES, Runner, model_spec
from sim_core.model.spec import load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator


@pytest.fixture(scope="module")
def record():
    """8 s of PRBS on the HydroLek shoulder with a 0.6 V deadband, pressures recorded."""
    truth = load_robot("hydrolek")
    truth.enable_effect("deadband", "j2", width=0.6)
    t, U = multilevel_prbs(truth, "j2", levels=5, amplitude=6, duration=8.0, rate=200, seed=5)
    cols = Simulator(Plant(truth).create_context(seed=1)).run(t, U).dataset_columns()
    return record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), load_robot("hydrolek"),
                               source="rec")


def _widths(widths):
    base = model_spec(load_robot("hydrolek"))
    out = []
    for w in widths:
        s = base.copy()
        s.enable_effect("deadband", "j2", width=w)
        out.append(s)
    return out


WIDTHS = (0.05, 0.3, 0.6, 0.9, 1.4, 2.0, 3.0)


def test_a_run_in_pieces_gives_the_bits_of_one_run_and_asks_after_each(record):
    runner = Runner(record, 2e-3)
    spec = _widths([0.6])[0]
    seen = []
    pieces = runner.simulate(spec, 1200, abandon=lambda out: seen.append(out.angles["j2"].size) or False)
    whole = runner.simulate(spec, 1200)
    assert np.array_equal(pieces.angles["j2"], whole.angles["j2"])
    assert all(np.array_equal(a, b) for a, b in zip(pieces.pressures["j2"], whole.pressures["j2"]))
    assert len(seen) == PIECES - 1 and seen == sorted(seen) and seen[-1] < 1200
    stopped = runner.simulate(spec, 1200, abandon=lambda out: True)
    assert stopped.abandoned and not stopped.ok


def test_the_early_cost_is_a_lower_bound_of_the_whole_cost(record):
    runner = Runner(record, 2e-3)
    prob = oe.Problem(record, ["j2"], n=800)
    bounds, costs = [], []
    for spec in _widths(WIDTHS):
        parts = []
        out = runner.simulate(spec, prob.n, abandon=lambda o: parts.append(prob.profiled_bound(o)) or False)
        cost, _ = prob.profiled_cost(out)
        assert all(b <= cost * (1 + 1e-12) for b in parts), (parts, cost)
        assert parts == sorted(parts)          # more samples, more cost
        bounds.append(parts[-1])
        costs.append(cost)
    # not a vacuous bound: the far starts' early cost already exceeds the best whole cost
    assert sum(b > min(costs) for b in bounds) >= 2


@pytest.mark.parametrize("groups", [[0] * 8, [0, 0, 0, 0, 1, 1, 1, 2]], ids=["one_group", "two_families_and_current"])
def test_abandoning_changes_no_group_best_and_saves_simulation(record, groups):
    runner = Runner(record, 2e-3)
    prob = oe.Problem(record, ["j2"], n=800)
    specs = _widths(WIDTHS + (0.55,))
    full = [prob.profiled_cost(runner.simulate(s, prob.n))[0] for s in specs]
    sims = [0]
    costs, profiles = oe._rank(runner, prob, specs, groups, sims, max_sims=100)
    assert sims[0] == len(specs)
    for g in set(groups):
        members = [k for k in range(len(specs)) if groups[k] == g]
        best = min(members, key=lambda k: full[k])
        assert costs[best] == full[best] and min(members, key=lambda k: costs[k]) == best
    abandoned = [k for k in range(len(specs)) if math.isinf(costs[k])]
    assert abandoned                               # the test saw runs stop early
    for k in abandoned:                            # each exceeded the best of its group
        assert full[k] > min(full[m] for m in range(len(specs)) if groups[m] == groups[k])
    kept = [k for k in range(len(specs)) if k not in abandoned]
    assert all(costs[k] == full[k] and profiles[k] for k in kept)


def test_a_ranking_the_budget_cuts_short_runs_whole_and_in_order(record):
    runner = Runner(record, 2e-3)
    prob = oe.Problem(record, ["j2"], n=400)
    specs = _widths(WIDTHS)
    sims = [0]
    with pytest.raises(oe._Budget):
        oe._rank(runner, prob, specs, [0] * len(specs), sims, max_sims=4)
    assert sims[0] == 4


@pytest.mark.parametrize("n", [1, 2, 3, 5, 9])
def test_a_run_shorter_than_its_pieces_is_still_the_whole_run(record, n):
    runner = Runner(record, 2e-3)
    spec = _widths([0.6])[0]
    assert np.array_equal(runner.simulate(spec, n, abandon=lambda out: False).angles["j2"],
                          runner.simulate(spec, n).angles["j2"])
