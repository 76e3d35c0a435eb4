"""A simulation continued from where an earlier one ended gives the bits of one run over both spans:
the simulator's saved state (Simulator.save/restore), a runner's resumed validation run
(Runner.simulate(resume=)), and the fits that hand their optimum's end to it. A model or record that
differs from the saved one is simulated whole, never continued."""

import numpy as np
import pytest

from sim_core.dataset import Dataset
from sim_core.excitation import multilevel_prbs
from sim_core.kernel.layout import XG_FACTORS, YA_SENS_V
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
    """6 s of PRBS on the HydroLek shoulder with a hidden delay and deadband, pressures recorded."""
    truth = load_robot("hydrolek")
    truth.enable_effect("deadband", "j2", width=0.5)
    truth.enable_effect("delay", "j2", delay=0.03)
    t, U = multilevel_prbs(truth, "j2", levels=5, amplitude=6, duration=6.0, rate=200, seed=3)
    cols = Simulator(Plant(truth).create_context(seed=1)).run(t, U).dataset_columns()
    return record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), load_robot("hydrolek"),
                               source="rec")


def _spec(**settings):
    """A HydroLek model with the effects whose states the continuation must carry (the delay's command
    history, the backlash's contact side, the hysteresis' last turn), a noisy sensor and ``settings``."""
    s = load_robot("hydrolek")
    s.enable_effect("delay", "j2", delay=0.04)
    s.enable_effect("backlash", "j2", width=0.01)
    s.enable_effect("hysteresis", "j2")
    for k, v in settings.items():
        s.set(k, v)
    return s


@pytest.mark.parametrize("settings", [{}, {"integrator.max_substep": 2e-3},
                                      {"integrator.rigid_body_refresh": 7.0, "integrator.jacobian_tolerance": 1e-3}],
                         ids=["default", "coarse_substep", "refresh_every_7_substeps_factor_kept"])
def test_a_restored_simulator_continues_with_the_bits_of_one_run(record, settings):
    spec = _spec(**settings)
    n, m = record.n, record.n // 2 + 37
    whole_ctx = Plant(spec).create_context(seed=4)
    whole = Simulator(whole_ctx).run(record.time, record.U)
    first = Simulator(Plant(spec).create_context(seed=4))
    head = first.run(record.time[:m], record.U[:m])
    later = Simulator(Plant(spec).create_context(seed=4))     # a fresh simulator of the same model
    later.restore(first.save())
    tail = later.run(record.time[m - 1:n], record.U[m - 1:n], first_row=head.act[-1])
    assert np.array_equal(np.concatenate((head.act[:-1], tail.act)), whole.act, equal_nan=True)
    assert np.array_equal(np.concatenate((head.q[:-1], tail.q)), whole.q)
    # the factor of M + h dF/dqd was renewed as often: a call that continues another keeps it
    assert later.context.XG[XG_FACTORS] == whole_ctx.XG[XG_FACTORS]
    # the sensors are noisy (the robot's wiper noise): the same numbers were drawn, none twice
    assert np.ptp(whole.act[:, 0, YA_SENS_V]) > 0


def test_without_the_saved_state_the_continuation_differs(record):
    """The check above can fail: a fresh simulator started from the state alone (not the cached
    command-chain discretisation, not the workspace) gives other bits."""
    spec = _spec()
    n, m = record.n, record.n // 2 + 37
    whole = Simulator(Plant(spec).create_context(seed=4)).run(record.time, record.U)
    first = Simulator(Plant(spec).create_context(seed=4))
    head = first.run(record.time[:m], record.U[:m])
    later = Simulator(Plant(spec).create_context(seed=4))
    for k in ("XQ", "XS", "XG", "HT", "HU", "rng"):
        getattr(later.context, k)[...] = getattr(first.context, k)
    tail = later.run(record.time[m - 1:n], record.U[m - 1:n], first_row=head.act[-1])
    assert not np.array_equal(np.concatenate((head.q[:-1], tail.q)), whole.q)


def test_a_resumed_runner_gives_the_whole_simulation_and_only_for_the_same_model(record):
    spec = model_spec(_spec())
    runner = Runner(record, 2e-3)
    m = int(record.n * 0.6)
    head = runner.simulate(spec, m, keep_end=True)
    assert head.end is not None and head.end.index == m - 1
    whole = runner.simulate(spec)
    resumed = runner.simulate(spec, resume=head)
    for j in record.angles:
        assert np.array_equal(resumed.angles[j], whole.angles[j])
    for j in record.pressures:
        assert all(np.array_equal(a, b) for a, b in zip(resumed.pressures[j], whole.pressures[j]))
    # it did continue from the saved state: moved, the state moves what follows it
    moved = head.end.state.context[0].copy()
    moved[0] += 1e-3
    bent = type(head)(head.angles, head.pressures, end=type(head.end)(
        head.end.key, head.end.index, type(head.end.state)((moved,) + head.end.state.context[1:], head.end.state.workspace),
        head.end.row))
    assert not np.array_equal(runner.simulate(spec, resume=bent).angles["j2"], whole.angles["j2"])
    # another model (a slightly wider backlash), another step or another record: simulated whole
    other = spec.copy()
    other.enable_effect("backlash", "j2", width=0.011)
    own = runner.simulate(other)
    assert np.array_equal(runner.simulate(other, resume=head).angles["j2"], own.angles["j2"])
    assert not np.array_equal(own.angles["j2"], whole.angles["j2"])
    fine = Runner(record, 1e-3)
    assert np.array_equal(fine.simulate(spec, resume=head).angles["j2"], fine.simulate(spec).angles["j2"])
    shifted = record_from_dataset(Dataset(["time"] + [f"u_{j}" for j in record.joint_names] + [f"q_{j}" for j in record.angles],
                                          np.column_stack([record.time, record.U * 0.9] + list(record.angles.values()))),
                                  load_robot("hydrolek"), source="shifted")
    assert np.array_equal(runner.simulate(spec, rec=shifted, resume=head).angles["j2"],
                          runner.simulate(spec, rec=shifted).angles["j2"])


def test_a_fit_hands_its_optimum_on_and_side_by_side_resumes_it(record):
    spec = model_spec(load_robot("hydrolek"))
    free = [free_parameter(spec, "joints.j2.valve.rated_flow", span=3.0)]
    prob = oe.Problem(record, ["j2"], n=int(record.n * 0.6))
    runner = Runner(record, 2e-3)
    res = oe.fit(runner, prob, spec, free, max_sims=20, tol=1e-3, uncertainty=False)
    assert res.outputs is not None and res.outputs.end is not None
    assert np.array_equal(res.outputs.angles["j2"], runner.simulate(res.spec, prob.n).angles["j2"])
    whole = runner.simulate(res.spec)
    with SideBySide(2) as side:
        outs = side.simulate(runner, [res.spec, res.spec], resume=[res.outputs, None])
    for out in outs:
        assert np.array_equal(out.angles["j2"], whole.angles["j2"])
