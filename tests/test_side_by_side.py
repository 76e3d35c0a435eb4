"""Simulations and report figures run side by side in forked processes give what running them one
after the other gives: the final refit's Jacobian columns, its uncertainty and the report's figures."""

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from sim_core.dataset import Dataset
from sim_core.excitation import multilevel_prbs
from sim_core.identification import diagnosis, report
from sim_core.identification import output_error as oe
from sim_core.identification.parameters import free_parameter
from sim_core.identification.record import record_from_dataset
from sim_core.identification.side_by_side import SideBySide
from sim_core.identification.simulation import Runner, model_spec
from sim_core.model.spec import load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator


@pytest.fixture(scope="module")
def record():
    """8 s of PRBS on the HydroLek shoulder, supply 10 % low and a 0.6 V deadband, pressures recorded."""
    truth = load_robot("hydrolek")
    truth.set("supply.pressure", 12.6e6)
    truth.enable_effect("deadband", "j2", width=0.6)
    t, U = multilevel_prbs(truth, "j2", levels=5, amplitude=6, duration=8.0, rate=200, seed=5)
    cols = Simulator(Plant(truth).create_context(seed=1)).run(t, U).dataset_columns()
    return record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), load_robot("hydrolek"),
                               source="rec")


@pytest.mark.parametrize("x", [[0.3, 0.7], [0.0, 0.5], [1.0, 0.9996], [0.9995, 1e-12], [0.25, 1.0]])
def test_forward_steps_are_scipys(x):
    """The steps least_squares' '2-point' differences take (relative 1e-3, turned inward at a bound):
    the side-by-side Jacobian must use the same ones for the fit to stay the same."""
    x = np.array(x)
    seen = []
    approx_derivative(lambda z: seen.append(z.copy()) or np.array([z.sum()]), x, method="2-point", rel_step=1e-3,
                      f0=np.array([x.sum()]), bounds=(0.0, 1.0))
    scipy_steps = np.array([z[i] - x[i] for i, z in enumerate(seen)])
    ours = oe.forward_steps(x, 1e-3)
    np.testing.assert_array_equal((x + ours) - x, scipy_steps)


def test_a_fit_with_its_jacobian_side_by_side_is_the_serial_fit(record):
    spec = model_spec(load_robot("hydrolek"))
    free = [free_parameter(spec, "joints.j2.valve.rated_flow", span=3.0), free_parameter(spec, "supply.pressure", span=1.5)]
    prob = oe.Problem(record, ["j2"], n=int(record.n * 0.6))
    runner = Runner(record, 1e-3)
    serial = oe.fit(runner, prob, spec, free, max_sims=30, tol=1e-3)
    with SideBySide(2) as side:
        parallel = oe.fit(runner, prob, spec, free, max_sims=30, tol=1e-3, side=side)
    assert serial.sims == parallel.sims > 3 * (len(free) + 1)     # several iterations, not only the start
    assert parallel.values == serial.values and parallel.cost == serial.cost
    assert parallel.sigma == pytest.approx(serial.sigma, rel=1e-12)
    # the supply really moved: the comparison is of a fit that did something
    assert parallel.values["supply.pressure"] == pytest.approx(12.6e6, rel=0.05)


def test_side_by_side_simulations_are_the_serial_ones_in_order(record):
    spec = model_spec(load_robot("hydrolek"))
    specs = []
    for flow in (3e-5, 4.3e-5, 6e-5):
        s = spec.copy()
        s.set("joints.j2.valve.rated_flow", flow)
        specs.append(s)
    runner = Runner(record, 1e-3)
    with SideBySide(2) as side:
        outs = side.simulate(runner, specs, record.n)
    for s, o in zip(specs, outs):
        np.testing.assert_array_equal(o.angles["j2"], runner.simulate(s).angles["j2"])
    assert np.ptp(outs[0].angles["j2"]) != np.ptp(outs[2].angles["j2"])


def test_report_figures_drawn_side_by_side_are_those_drawn_here(record):
    d = diagnosis.run(load_robot("hydrolek"), record, workers=2, progress=False, effects=["deadband", "delay"])
    assert [s["effect"] for s in d.selected] == ["deadband"]
    here = report.all_plots(d, ["j2"], workers=1)
    forked = report.all_plots(d, ["j2"], workers=2)
    assert set(here["j2"]) == set(report.FIGURES)
    assert forked == here


def test_a_calibration_side_by_side_is_the_serial_calibration(record):
    """The flow-gain scan, the fits and the refits after each parameter the record cannot identify
    is reset (elimination.py) give the same calibration in forked processes as here."""
    from sim_core.identification.calibration import calibrate

    spec = model_spec(load_robot("hydrolek"))
    keys = ["joints.j2.valve.rated_flow", "supply.pressure", "joints.j2.sensor.B"]
    prob = oe.Problem(record, ["j2"], n=int(record.n * 0.6))
    runner = Runner(record, 1e-3)
    serial = calibrate(spec, runner, prob, keys)
    with SideBySide(2) as side:
        parallel = calibrate(spec, runner, prob, keys, side=side)
        assert side._pool is not None            # the simulations did run in the forked processes
    assert parallel.changes == serial.changes
    assert parallel.result.values == serial.result.values and parallel.result.cost == serial.result.cost
    rows = {c["parameter"]: c for c in serial.changes}
    # a calibration that did something: the supply moved towards the truth's 12.6 MPa, and the sensor
    # offset the record cannot tell from the start pose was reset (a refit after a drop ran)
    assert abs(rows["supply.pressure"]["value"] - 12.6e6) < abs(rows["supply.pressure"]["nominal"] - 12.6e6)
    assert not rows["joints.j2.sensor.B"]["identified"]
