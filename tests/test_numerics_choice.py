"""The diagnosis's fast integrator step is checked on every channel it scores: a step that keeps the
angles but not the chamber pressures (end-stop contact at a coarse step) is not chosen, a step that
diverges is reported as such, a calibrated model that diverges at it gets a finer one, and its
rigid-body refresh every 20 ms is checked with it."""

import math

import numpy as np
import pytest

from sim_core.dataset import Dataset
from sim_core.excitation import multilevel_prbs
from sim_core.identification import diagnosis
from sim_core.identification.output_error import Problem
from sim_core.identification.record import record_from_dataset
from sim_core.identification.simulation import (ANGLE_TOLERANCE, FAST_REFRESH_S, PRESSURE_TOLERANCE, Outputs, Runner,
                                                choose_numerics, close_enough, compare_outputs, model_spec,
                                                refresh_substeps)
from sim_core.model.spec import load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator


def _record(spec, pressures=True):
    """HydroLek shoulder and elbow driven together by unguarded +-4 V PRBS (the elbow often at its
    end stops), 60 s at 200 Hz."""
    t, U = multilevel_prbs(spec, "j2", levels=5, amplitude=4, duration=60.0, rate=200, seed=1, guard=False)
    _, U3 = multilevel_prbs(spec, "j3", levels=5, amplitude=4, duration=60.0, rate=200, seed=2, guard=False)
    U += U3
    cols = Simulator(Plant(spec).create_context(seed=1)).run(t, U).dataset_columns()
    if not pressures:
        cols = {k: v for k, v in cols.items() if not k.startswith("p_")}
    return record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), spec, source="endstops")


def test_pressures_decide_when_the_record_has_them():
    spec = load_robot("hydrolek")
    rec = _record(spec)
    ref = Outputs({j: rec.angles[j] for j in rec.targets}, {j: rec.pressures[j] for j in rec.targets})
    t = rec.time
    # same angles, pressures off by a 2 Hz ripple of 20 % of their spread: angles pass, pressures fail
    bent = {j: tuple(p + 0.2 * np.std(p) * np.sin(2 * np.pi * 2 * t) for p in ps) for j, ps in ref.pressures.items()}
    entry = compare_outputs(ref, Outputs(ref.angles, bent), rec)
    assert entry["angle_fit"] == 100.0 and entry["velocity_fit"] == 100.0
    assert entry["pressure_fit"] < 100.0 - PRESSURE_TOLERANCE and not close_enough(entry)
    # a ripple well inside the tolerance passes
    slight = {j: tuple(p + 0.002 * np.std(p) * np.sin(2 * np.pi * 2 * t) for p in ps) for j, ps in ref.pressures.items()}
    assert close_enough(compare_outputs(ref, Outputs(ref.angles, slight), rec))
    # an angle off by more than its tolerance fails whatever the pressures
    off = {j: a + 0.05 * np.std(a) for j, a in ref.angles.items()}
    entry = compare_outputs(ref, Outputs(off, ref.pressures), rec)
    assert entry["angle_fit"] < 100.0 - ANGLE_TOLERANCE and not close_enough(entry)


def test_a_step_that_fails_a_channel_on_the_record_is_not_chosen():
    """On the end-stop record the 2 ms step diverges or mangles a channel over the whole record;
    the step chosen passes every channel; without pressure columns only angles and velocities count."""
    spec = load_robot("hydrolek")
    m = model_spec(spec)
    _, report = choose_numerics(m, _record(spec))
    coarse = report["candidates"]["0.002"]
    assert coarse.get("diverged") or not close_enough(coarse)
    assert report["substep"] < 0.002
    chosen = report["candidates"].get(f"{report['substep']:g}")
    assert chosen is None or (close_enough(chosen) and "pressure_fit" in chosen)
    _, no_p = choose_numerics(m, _record(spec, pressures=False))
    assert all("pressure_fit" not in c for c in no_p["candidates"].values())


def test_a_calibrated_model_that_diverges_at_the_nominal_models_step_gets_a_finer_one():
    """The fast step is chosen on the nominal model before the calibration. A calibrated model that
    diverges at that step over the validation part gets the step chosen again on itself, and says
    so. Here the 'calibrated' model has links at a fifth of their mass: the wrist's hydraulic mode
    then rings faster than the semi-implicit coupling of pressures and mechanics holds at the 2 ms
    step (omega h > 2), and the 1 ms step holds it."""
    spec = load_robot("hydrolek")
    t, U = multilevel_prbs(spec, "j2", levels=5, amplitude=6, duration=8.0, rate=200, seed=5)
    cols = Simulator(Plant(spec).create_context(seed=1)).run(t, U).dataset_columns()
    rec = record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), spec, source="rec")
    m0 = model_spec(spec)
    n = int(rec.n * 0.6)
    vprob = Problem(rec, rec.targets, start=n)
    fast, vfast, numerics = diagnosis._numerics(m0, rec, None, rec)
    assert fast.substep == 2e-3
    light = m0.copy()
    light.set("links.mass_scale", 0.2)
    assert not vfast.simulate(light, vprob.n).ok          # the trigger is real: this model diverges there
    same = dict(numerics)
    assert diagnosis._numerics_again(m0, fast, vfast, vprob, rec, None, rec, same) == (fast, vfast) and same == numerics
    fast2, vfast2 = diagnosis._numerics_again(light, fast, vfast, vprob, rec, None, rec, numerics)
    again = numerics["calibrated_model"]
    assert fast2.substep == vfast2.substep == again["substep"] == numerics["substep"] < 2e-3
    assert again["nominal_model_substep"] == 2e-3 and "step of 0.002 s" in again["because"]
    assert vfast2.simulate(light, vprob.n).ok


@pytest.mark.parametrize("dt, substep, every", [(0.005, 2e-3, 12), (0.01, 2e-3, 10), (0.001, 2e-3, 20),
                                                (0.02, 2e-3, 0), (0.05, 2e-3, 0), (0.005, 5e-4, 40)])
def test_the_fast_step_refreshes_the_rigid_body_about_every_20_ms(dt, substep, every):
    """The fast variant refreshes M(q) and the bias every FAST_REFRESH_S (whole substeps of the output
    step the kernel takes), and at each output step where that is as long already (a 50 Hz record)."""
    assert refresh_substeps(dt, substep) == every
    if every:
        h = dt / math.ceil(dt / substep - 1e-9)
        assert abs(every * h - FAST_REFRESH_S) <= 0.5 * h


def test_the_fast_refresh_costs_far_less_than_the_fast_step_and_is_checked_with_it():
    """On a 200 Hz HydroLek record (a 20 kg payload on the shoulder: gravity is what the refresh holds)
    the fast variant with its 20 ms refresh stays within the numerics tolerance of the default, and the
    refresh alone moves the angle fit by a small part of that tolerance (achieved: 0.024 points, the
    coarse step 0.14)."""
    spec = load_robot("hydrolek")
    truth = spec.copy()
    truth.enable_effect("payload", "j2", mass=20.0)
    t, U = multilevel_prbs(truth, "j2", levels=5, amplitude=6, duration=20.0, rate=200, seed=7)
    cols = Simulator(Plant(truth).create_context(seed=1)).run(t, U).dataset_columns()
    rec = record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), spec, source="payload")
    m = model_spec(truth)
    runner, report = choose_numerics(m, rec)
    assert runner.substep == 2e-3 and runner.refresh == 12 and report["rigid_body_refresh_substeps"] == 12
    ref = Runner(rec).simulate(m)
    fast = runner.simulate(m)
    every_step = m.copy()
    every_step.set("integrator.rigid_body_refresh", 3.0)     # the 2 ms step refreshing at each 5 ms output step
    coarse = runner.simulate(every_step)
    step_cost = 100.0 - compare_outputs(ref, coarse, rec)["angle_fit"]
    refresh_cost = 100.0 - compare_outputs(coarse, fast, rec)["angle_fit"]
    assert close_enough(compare_outputs(ref, fast, rec))
    assert 0.0 < refresh_cost < 0.5 * ANGLE_TOLERANCE and step_cost > 0.0, (refresh_cost, step_cost)
