"""A fit's Jacobian between forward differences: Broyden's secant update of the step least_squares
just took, used only while the last Jacobian predicted that step well. Each column of a difference
is a simulation of the whole estimation window; a secant update costs none. The fit must end where
a fit of differences at every step ends, within its own tolerance, on fewer simulations."""

import numpy as np
import pytest

from sim_core.dataset import Dataset
from sim_core.excitation import multilevel_prbs
from sim_core.identification import output_error as oe
from sim_core.identification.parameters import free_parameter
from sim_core.identification.record import record_from_dataset
from sim_core.identification.simulation import Runner, model_spec
from sim_core.model.spec import load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator

TRUE_SUPPLY = 12.6e6      # Pa, 10 % under the spec's
TRUE_FLOW = 1.15          # x the spec's rated flow


def test_the_update_maps_the_step_onto_its_change_and_leaves_the_rest():
    rng = np.random.default_rng(3)
    for _ in range(20):
        m, k = int(rng.integers(5, 40)), int(rng.integers(1, 5))
        J, step, df = rng.normal(size=(m, k)), rng.normal(size=k), rng.normal(size=m)
        new = oe.broyden_update(J, step, df)
        np.testing.assert_allclose(new @ step, df, rtol=1e-10, atol=1e-12)        # the secant condition
        # the least change: directions orthogonal to the step map as before
        other = rng.normal(size=k)
        other -= (other @ step) / (step @ step) * step
        np.testing.assert_allclose(new @ other, J @ other, rtol=1e-10, atol=1e-12)
    # a null step changes nothing
    J = rng.normal(size=(6, 2))
    assert np.array_equal(oe.broyden_update(J, np.zeros(2), rng.normal(size=6)), J)


def test_a_step_the_jacobian_mispredicted_is_differenced_again():
    J = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
    x0, f0 = np.array([0.2, 0.3]), np.zeros(3)
    step = np.array([0.01, -0.02])
    linear = f0 + J @ step
    acc = {"x": x0, "f": f0, "J": J}
    assert oe._predicted_well(acc, x0 + step, linear)
    assert oe._predicted_well(acc, x0 + step, linear * 1.2)             # 20 % off: within the trust
    assert not oe._predicted_well(acc, x0 + step, linear * 2.0)         # twice the prediction
    assert not oe._predicted_well(acc, x0 + step, -linear)              # the wrong way


@pytest.fixture(scope="module")
def record():
    """8 s of PRBS on the HydroLek shoulder, the supply 10 % low and the valve 15 % stronger."""
    truth = load_robot("hydrolek")
    truth.set("supply.pressure", TRUE_SUPPLY)
    truth.set("joints.j2.valve.rated_flow", truth.get("joints.j2.valve.rated_flow") * TRUE_FLOW)
    t, U = multilevel_prbs(truth, "j2", levels=5, amplitude=6, duration=8.0, rate=200, seed=5)
    cols = Simulator(Plant(truth).create_context(seed=1)).run(t, U).dataset_columns()
    return record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), load_robot("hydrolek"),
                               source="rec")


def test_a_fit_with_secant_updates_ends_where_differences_end_on_fewer_simulations(record, monkeypatch):
    spec = model_spec(load_robot("hydrolek"))
    flow0 = spec.get("joints.j2.valve.rated_flow")
    free = [free_parameter(spec, "joints.j2.valve.rated_flow", span=3.0), free_parameter(spec, "supply.pressure", span=1.5)]
    prob = oe.Problem(record, ["j2"], n=int(record.n * 0.6))
    runner = Runner(record, 1e-3)

    def fitted(updates):
        monkeypatch.setattr(oe, "BROYDEN_UPDATES", updates)
        return oe.fit(runner, prob, spec, free, max_sims=60, tol=1e-4, uncertainty=False)

    plain, secant = fitted(0), fitted(2)
    # both found the truth (the record is noise-free: the optimum is the truth)
    for res in (plain, secant):
        assert res.values["supply.pressure"] == pytest.approx(TRUE_SUPPLY, rel=0.02)
        assert res.values["joints.j2.valve.rated_flow"] == pytest.approx(flow0 * TRUE_FLOW, rel=0.02)
    # the same optimum: within a thousandth of the distance the fit started from it (tol 1e-4 in the fit
    # coordinates; both end within 1e-6 of each other), at the same cost
    for fp in free:
        start, truth = fp.to_x(fp.get(spec)), fp.to_x(plain.values[fp.key])
        assert abs(fp.to_x(secant.values[fp.key]) - truth) < 1e-3 * abs(start - truth)
    assert secant.cost == pytest.approx(plain.cost, rel=1e-3)
    # and the secant steps cost no simulation
    assert secant.sims < plain.sims
