"""Free-run simulation of a model on a measured record's input (what output-error fitting compares).

The model output is noise-free and unquantised (the record has the noise). Every joint is
simulated, commanded or not: holding the others rigid (``Context.lock``) saves little here and
changes the response measurably (the harvester's boom and stick ring together through the hoses).
The fast variant used for the many candidate fits takes a coarser integrator substep, checked
against the default on the record itself before it is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..plant import Plant
from ..simulator import SimulationError, Simulator, SimulatorState
from .metrics import nrmse_fit, velocity
from .record import Record, start_position

FAST_SUBSTEPS = (2e-3, 1e-3, 5e-4)   # s, tried coarsest first (the built-in robots use 0.25 ms)
ANGLE_TOLERANCE = 0.25       # fit points of angle the fast substep may cost against the default
VELOCITY_TOLERANCE = 1.0     # fit points of velocity (far below the 2-point decision threshold)
PRESSURE_TOLERANCE = 1.0     # fit points of a chamber pressure, when the record has pressures (end-stop
                             # contact makes pressures far more sensitive to the step than angles)


@dataclass(frozen=True)
class End:
    """Where a simulation on a record ended, to continue it (``Runner.simulate(resume=)``): a fit's
    estimation window is the first part of the record its validation window is scored on, so the
    validation run of the fitted model goes on from there instead of simulating it again."""

    key: bytes              # the model and initial state as the kernel saw them, the record, the step
    index: int              # the sample the state is at (the last one simulated)
    state: SimulatorState
    row: np.ndarray         # the outputs row of that sample


@dataclass
class Outputs:
    """Simulated channels on the record's time grid (None where the simulation failed)."""

    angles: dict[str, np.ndarray]
    pressures: dict[str, tuple[np.ndarray, np.ndarray]]
    ok: bool = True
    end: End | None = None  # with ``Runner.simulate(keep_end=True)``


def model_spec(spec):
    """A copy of ``spec`` with noise-free, unquantised sensors (the record has the noise)."""
    s = spec.copy()
    for j in s.joints:
        if j.sensed:
            j.components["sensor"].set("noise", 0.0)
            j.components["sensor"].set("bits", 0.0)
    return s


class Runner:
    """Simulates model specs on one record's input with a fixed integrator substep (None: the spec's)."""

    def __init__(self, rec: Record, substep: float | None = None):
        self.rec = rec
        self.substep = substep
        self.calls = 0

    def simulate(self, spec, n: int | None = None, rec: Record | None = None, owned: bool = False,
                 keep_end: bool = False, resume: Outputs | None = None) -> Outputs:
        """Run ``spec`` (already a model spec) over the first ``n`` samples of the record; ``owned``:
        the caller's private copy, which may be changed (saves a copy per simulation). ``keep_end``:
        the outputs carry where the run ended (:class:`End`). ``resume``: the outputs of an earlier
        run of the same model on the same record with that end; when model, record and step match,
        this run takes its samples and simulates only the rest (the same bits as simulating them
        all), otherwise it simulates them all."""
        rec = rec or self.rec
        n = rec.n if n is None else n
        s = spec if owned else spec.copy()
        for j in s.joints:   # start where this record starts
            j.settings.set("initial_position", start_position(s, rec, j.name))
        if self.substep is not None and spec.integrator["max_substep"] < self.substep:
            s.set("integrator.max_substep", self.substep)
        self.calls += 1
        try:
            ctx = Plant(s).create_context(s, seed=0, owned=True)     # s is this call's own copy
            sim = Simulator(ctx)
            key = _key(sim, rec) if keep_end or resume is not None else b""
            end = resume.end if resume is not None and resume.ok and resume.end is not None else None
            if end is not None and end.key == key and end.index >= n - 1:      # the run had these samples
                return Outputs({j: y[:n] for j, y in resume.angles.items()},
                               {j: (pa[:n], pb[:n]) for j, (pa, pb) in resume.pressures.items()},
                               end=end if keep_end and end.index == n - 1 else None)
            if end is not None and end.key == key:
                sim.restore(end.state)
                m = end.index
                traj = sim.run(rec.time[m:n], rec.U[m:n], first_row=end.row)
                angles = {j: np.concatenate((resume.angles[j][:m], traj.angle(j))) for j in rec.angles}
                pressures = {j: (np.concatenate((resume.pressures[j][0][:m], traj.pressure(j, "a"))),
                                 np.concatenate((resume.pressures[j][1][:m], traj.pressure(j, "b"))))
                             for j in rec.pressures}
            else:
                traj = sim.run(rec.time[:n], rec.U[:n])
                angles = {j: traj.angle(j) for j in rec.angles}
                pressures = {j: (traj.pressure(j, "a"), traj.pressure(j, "b")) for j in rec.pressures}
        except (SimulationError, ValueError, ArithmeticError):
            return Outputs({}, {}, ok=False)
        for y in angles.values():
            if not np.all(np.isfinite(y)):
                return Outputs({}, {}, ok=False)
        if keep_end:
            return Outputs(angles, pressures, end=End(key, n - 1, sim.save(), traj.act[-1].copy()))
        return Outputs(angles, pressures)


def _key(sim: Simulator, rec: Record) -> bytes:
    """What must match for a run to continue another: the model and initial state (the simulator's
    fingerprint, the step included) and the record's time grid and commands."""
    return sim.fingerprint() + rec.digest()


def compare_outputs(ref: Outputs, out: Outputs, rec: Record) -> dict:
    """Worst fit (points) of ``out`` against ``ref`` over the record's targets, per channel: angle,
    velocity and, when the record has pressures, every chamber pressure of a target."""
    worst_a, worst_v, worst_p = 100.0, 100.0, 100.0
    for j in rec.targets:
        worst_a = min(worst_a, nrmse_fit(ref.angles[j], out.angles[j]))
        worst_v = min(worst_v, nrmse_fit(velocity(ref.angles[j], rec.dt), velocity(out.angles[j], rec.dt)))
        if j in ref.pressures and j in out.pressures:
            for side in (0, 1):
                worst_p = min(worst_p, nrmse_fit(ref.pressures[j][side], out.pressures[j][side]))
    entry = {"angle_fit": round(worst_a, 3), "velocity_fit": round(worst_v, 3)}
    if any(j in ref.pressures for j in rec.targets):
        entry["pressure_fit"] = round(worst_p, 3)
    return entry


def close_enough(entry: dict) -> bool:
    """A faster step may stand for the default when every channel stays within its tolerance."""
    return (entry["angle_fit"] >= 100.0 - ANGLE_TOLERANCE and entry["velocity_fit"] >= 100.0 - VELOCITY_TOLERANCE
            and entry.get("pressure_fit", 100.0) >= 100.0 - PRESSURE_TOLERANCE)


def choose_numerics(spec, rec: Record, n: int | None = None) -> tuple[Runner, dict]:
    """The coarsest substep whose output on this record matches the default (checked, not assumed).

    Every channel the diagnosis scores is compared: angles, velocities and, where the record has
    them, chamber pressures (a step that keeps angles but not pressures makes the pressure part of
    every cost noisy in the parameters, and the fits stall). Returns the runner and what was
    compared (worst fit of fast vs default per channel)."""
    ref = Runner(rec).simulate(spec, n)
    report: dict = {"candidates": {}}
    chosen = Runner(rec)
    if ref.ok:
        for sub in FAST_SUBSTEPS:
            if sub <= spec.integrator["max_substep"]:
                break
            cand = Runner(rec, sub)
            out = cand.simulate(spec, n)
            if not out.ok:
                report["candidates"][f"{sub:g}"] = {"diverged": True}
                continue
            entry = compare_outputs(ref, out, rec)
            report["candidates"][f"{sub:g}"] = entry
            if close_enough(entry):
                chosen = cand
                break
    report["substep"] = chosen.substep or spec.integrator["max_substep"]
    return chosen, report
