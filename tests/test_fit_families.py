"""Two families of starts. A rig's calibration can absorb part of an effect into its nuisances (a valve
offset partly taken up as a sensor offset), and each candidate then refits them from their calibrated
values and from their values before calibration. The starts are ranked on a shorter window than the
fit's, so the ranking can prefer a start whose basin the whole window holds worse; the best start of
each family is therefore fitted from and the lower cost kept (``output_error.fit``, ``second_family``).

The first test is the rule on a cost of two parameters with two basins (no simulation); the second
checks, with real simulations, that a candidate's evaluation fits from the nuisances' values before
calibration where the ranking puts the calibrated ones first."""

import dataclasses

import numpy as np
import pytest

from sim_core.dataset import Dataset
from sim_core.excitation import multilevel_prbs
from sim_core.identification import output_error as oe
from sim_core.identification.candidates import bank
from sim_core.identification.metrics import noise_std
from sim_core.identification.parameters import FreeParameter
from sim_core.identification.record import record_from_dataset
from sim_core.identification.selection import Setting, _Baseline, evaluate
from sim_core.identification.simulation import Runner, model_spec
from sim_core.model.spec import load_robot
from sim_core.plant import Plant
from sim_core.simulator import Simulator

# ---- the rule, on a cost with two basins -------------------------------------------------------------
EFFECT, NUISANCE = "effect.a", "nuisance.s"
TRUE_A = -0.3
SHALLOW = -0.27          # the nuisance's local minimum; the global one is at 0
CALIBRATED = -0.43       # where the calibration left the nuisance: in the shallow basin
FREE = [FreeParameter(EFFECT, -1.5, 1.5), FreeParameter(NUISANCE, -0.5, 0.5)]


class Values(dict):
    """A model spec of two numbers."""

    def copy(self):
        return Values(self)

    def get(self, key, default=None):
        return self[key]

    def set(self, key, value):
        self[key] = value


@dataclasses.dataclass
class Out:
    spec: Values
    ok: bool = True
    abandoned: bool = False     # a whole 'run' every time: the ranking's early stop is another test's


class EchoRunner:
    """'Simulates' a spec by handing its values on to the cost."""

    def simulate(self, spec, n=None, owned=False, **_):
        return Out(spec.copy())


class WholeWindow:
    """Residuals with zeros of the first at s = 0 and s = SHALLOW; the second makes s = 0 the better."""
    n = 100
    size = 3

    def residuals(self, out):
        a, s = out.spec[EFFECT], out.spec[NUISANCE]
        return np.array([10.0 * s * (s - SHALLOW), 0.1 * s, a - TRUE_A])


class GridWindow:
    """The ranking's shorter window, which prefers the calibrated nuisance."""
    n = 50

    def profiled_cost(self, out):
        a, s = out.spec[EFFECT], out.spec[NUISANCE]
        return (s - CALIBRATED) ** 2 + (a - TRUE_A) ** 2, {}


def _fit(second_family):
    grid = [[a, CALIBRATED] for a in (-0.5, 0.0, 0.5)] + [[a, 0.0] for a in (-0.5, 0.0, 0.5)]
    spec = Values({EFFECT: 0.0, NUISANCE: CALIBRATED})
    return oe.fit(EchoRunner(), WholeWindow(), spec, FREE, grid=grid, grid_problem=GridWindow(), max_sims=400,
                  uncertainty=False, tol=1e-8, second_family=second_family)


def test_each_family_s_best_start_is_fitted_from_and_the_lower_cost_kept():
    one = _fit(None)
    # the premise: from the start the ranking prefers, the fit ends in the shallow basin
    assert one.values[NUISANCE] == pytest.approx(SHALLOW, abs=0.01)
    both = _fit(3)
    assert both.values[NUISANCE] == pytest.approx(0.0, abs=1e-3)
    assert both.values[EFFECT] == pytest.approx(TRUE_A, abs=1e-3)
    assert both.cost < 0.01 * one.cost


def test_the_second_family_is_fitted_from_where_the_first_ranks_worse_too():
    """The order does not matter: with the ranking preferring the uncalibrated family, the calibrated
    one's best start is fitted from as well (here it is the better)."""
    grid = [[a, 0.0] for a in (-0.5, 0.5)] + [[a, CALIBRATED] for a in (-0.5, 0.5)]

    class Prefers0(GridWindow):
        def profiled_cost(self, out):
            return out.spec[NUISANCE] ** 2 + (out.spec[EFFECT] - TRUE_A) ** 2, {}

    class Deep(WholeWindow):          # now the basin of the calibrated value is the deeper one
        def residuals(self, out):
            a, s = out.spec[EFFECT], out.spec[NUISANCE]
            return np.array([10.0 * s * (s - SHALLOW), 0.1 * (s - SHALLOW), a - TRUE_A])

    spec = Values({EFFECT: 0.0, NUISANCE: 0.0})
    res = oe.fit(EchoRunner(), Deep(), spec, FREE, grid=grid, grid_problem=Prefers0(), max_sims=400,
                 uncertainty=False, tol=1e-8, second_family=2)
    assert res.values[NUISANCE] == pytest.approx(SHALLOW, abs=1e-3)


# ---- the wiring, with real simulations -----------------------------------------------------------------
JOINT = "j2"
FLOW_KEY = f"joints.{JOINT}.valve.rated_flow"
OFFSET_KEY = f"effects.sensor_offset.{JOINT}.offset"
CALIBRATED_OFFSET = 0.2      # rad: where a calibration left a rig's sensor offset (the truth has none)


class OffsetLog(Runner):
    """The real runner, keeping the sensor offset of every model it simulates."""

    def __init__(self, rec):
        super().__init__(rec)
        self.offsets = []

    def simulate(self, spec, n=None, rec=None, owned=False, **kw):
        self.offsets.append(float(FreeParameter(OFFSET_KEY, -0.5, 0.5).get(spec)))
        return super().simulate(spec, n, rec, owned, **kw)


def test_a_candidate_is_fitted_from_both_families_of_starts():
    """HydroLek's shoulder with a sensor offset treated as a rig's estimated nuisance, calibrated to
    0.2 rad, 0 before calibration (the truth). A candidate's evaluation ranks its grid at both values
    and fits from the best start of each: each value is simulated again after the ranking."""
    truth = load_robot("hydrolek")
    t, U = multilevel_prbs(truth, JOINT, levels=5, amplitude=6, duration=6.0, rate=200, seed=3)
    cols = Simulator(Plant(truth).create_context(seed=1)).run(t, U).dataset_columns()
    rec = record_from_dataset(Dataset(list(cols), np.column_stack(list(cols.values()))), truth, source="rec")
    model = model_spec(load_robot("hydrolek"))
    model.enable_effect("sensor_offset", JOINT, offset=CALIBRATED_OFFSET)
    est, val = oe.Problem(rec, [JOINT]), oe.Problem(rec, [JOINT], start=int(rec.n * 0.6))
    runner = OffsetLog(rec)
    st = Setting(runner, est, Runner(rec), val, [FLOW_KEY, OFFSET_KEY], {JOINT: noise_std(rec.angles[JOINT])}, {},
                 ranges={OFFSET_KEY: FreeParameter(OFFSET_KEY, -0.5, 0.5, null=0.0)},
                 uncalibrated={OFFSET_KEY: 0.0})
    base = _Baseline(st)
    base_out, base_cost = base.outputs(model), base.cost(model)
    cand = bank(model, [JOINT], effects=["deadband"])[0]
    assert cand.grid
    runner.offsets.clear()
    ev = evaluate(st, cand, model, [], base_out, base_cost)
    at = {v: sum(abs(o - v) < 1e-9 for o in runner.offsets) for v in (CALIBRATED_OFFSET, 0.0)}
    # ranking: every grid point at each value, and the current values (the calibrated family) once more
    ranked = {CALIBRATED_OFFSET: len(cand.grid) + 1, 0.0: len(cand.grid)}
    assert all(at[v] > ranked[v] for v in at), (at, ranked)
    assert abs(ev.values[OFFSET_KEY]) < 0.02
