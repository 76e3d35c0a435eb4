"""Forward selection refits the model's own parameters once an effect joins it: the next round's
candidates refit them too, so without that refit every candidate would be credited alike with what it
finds. Real fits on a HydroLek shoulder record with a hidden deadband, at a budget small enough that
the accepted candidate's fit stops before its optimum."""

import numpy as np

from sim_core.dataset import Dataset
from sim_core.excitation import multilevel_prbs
from sim_core.identification import output_error as oe
from sim_core.identification.candidates import bank
from sim_core.identification.metrics import noise_std
from sim_core.identification.record import record_from_dataset
from sim_core.identification.selection import Setting, model_with, select
from sim_core.identification.simulation import Runner, model_spec
from sim_core.model.spec import load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator

JOINT = "j2"
FLOW_KEY = f"joints.{JOINT}.valve.rated_flow"


def _record():
    truth = load_robot("hydrolek")
    truth.enable_effect("deadband", JOINT, width=1.2)
    truth.set(FLOW_KEY, 1.15 * truth.get(FLOW_KEY))
    t, U = multilevel_prbs(truth, JOINT, levels=5, amplitude=6, duration=16.0, rate=200, seed=4)
    cols = Simulator(Plant(truth).create_context(seed=1)).run(t, U).dataset_columns()
    cols = {k: v for k, v in cols.items() if not k.startswith("p_")}
    return record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), load_robot("hydrolek"),
                               source="rec")


def test_an_accepted_fit_stopped_by_its_budget_is_carried_on_before_the_next_round():
    rec = _record()
    m = model_spec(load_robot("hydrolek"))
    n = int(rec.n * 0.6)
    est, val = oe.Problem(rec, [JOINT], n=n), oe.Problem(rec, [JOINT], start=n)
    runner = Runner(rec)
    st = Setting(runner, est, runner, val, [FLOW_KEY], {JOINT: noise_std(rec.angles[JOINT])}, {}, max_sims=12,
                 fit_iterations=1)
    cands = bank(m, [JOINT], effects=["deadband"])
    sel = select(st, cands, m, workers=1, progress=False)
    assert [(e.candidate.effect, e.candidate.joint) for e in sel.accepted] == [("deadband", JOINT)]
    ev = sel.accepted[0]
    assert ev.sims >= st.max_sims            # the premise: its fit ran out of simulations

    def cost(model):
        return float(np.sum(est.residuals(runner.simulate(model, est.n)) ** 2))

    def score(model):
        return val.fits(runner.simulate(model, val.n))[JOINT]["score"]

    # the model the search ends with is the accepted fit carried further: a lower estimation cost and
    # a higher validation score than the accepted fit's own values give
    as_accepted = model_with(m, [], ev.candidate, ev.values)
    assert cost(sel.model) < 0.99 * cost(as_accepted), (cost(sel.model), cost(as_accepted))
    assert score(sel.model) > score(as_accepted)


def test_a_fit_with_many_free_parameters_gets_the_iterations_it_needs():
    """The candidates' budget: at least ``max_sims``, and beyond it room for ranking every start and
    ``fit_iterations`` forward-difference iterations (n + 1 simulations each) of all n free parameters
    (a rig's calibrated nuisances beside an effect's own parameters)."""
    st = Setting(None, None, None, None, [], {}, {}, max_sims=45)
    assert st.budget(1) == 45                                     # a one-parameter fit keeps the fixed budget
    for n, starts in ((5, 15), (8, 15), (12, 30)):
        b = st.budget(n, starts)
        assert b - (starts + 1) >= st.fit_iterations * (n + 1)
    assert Setting(None, None, None, None, [], {}, {}, max_sims=12, fit_iterations=1).budget(2, 4) == 12
