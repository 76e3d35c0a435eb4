"""Free-run simulation of a model on a measured record's input (what output-error fitting compares).

The model output is noise-free and unquantised (the record has the noise). Every joint is
simulated, commanded or not: holding the others rigid (``Context.lock``) saves little here and
changes the response measurably (the harvester's boom and stick ring together through the hoses).
The fast variant used for the many candidate fits takes a coarser integrator substep and refreshes
the rigid body (M(q) and the Coriolis/gravity bias) every ``FAST_REFRESH_S``, as the default does at
every output step of a 50 Hz record; both are checked against the default on the record itself
before it is used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..plant import Plant
from ..simulator import SimulationError, Simulator, SimulatorState
from .metrics import nrmse_fit, velocity
from .record import Record, start_position

FAST_SUBSTEPS = (2e-3, 1e-3, 5e-4)   # s, tried coarsest first (the built-in robots use 0.25 ms)
FAST_REFRESH_S = 0.02        # s between the fast variant's rigid-body refreshes, where output steps are shorter
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
    abandoned: bool = False  # stopped early by ``Runner.simulate(abandon=)`` (not ok, not failed)


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
        # substeps between rigid-body refreshes of the fast variant (0: each output step, the spec's)
        self.refresh = 0 if substep is None else refresh_substeps(rec.dt, substep)

    def simulate(self, spec, n: int | None = None, rec: Record | None = None, owned: bool = False,
                 keep_end: bool = False, resume: Outputs | None = None, abandon=None) -> Outputs:
        """Run ``spec`` (already a model spec) over the first ``n`` samples of the record; ``owned``:
        the caller's private copy, which may be changed (saves a copy per simulation). ``keep_end``:
        the outputs carry where the run ended (:class:`End`). ``resume``: the outputs of an earlier
        run of the same model on the same record with that end; when model, record and step match,
        this run takes its samples and simulates only the rest (the same bits as simulating them
        all), otherwise it simulates them all. ``abandon(outputs so far)``: asked after each of
        ``PIECES`` pieces of the run; True stops it (``Outputs.abandoned``; the pieces give the bits
        of one run)."""
        rec = rec or self.rec
        n = rec.n if n is None else n
        s = spec if owned else spec.copy()
        for j in s.joints:   # start where this record starts
            j.settings.set("initial_position", start_position(s, rec, j.name))
        if self.substep is not None and spec.integrator["max_substep"] < self.substep:
            s.set("integrator.max_substep", self.substep)
            if self.refresh and s.integrator["rigid_body_refresh"] == 0:
                s.set("integrator.rigid_body_refresh", float(self.refresh))
        self.calls += 1
        try:
            ctx = Plant(s).create_context(s, seed=0, owned=True)     # s is this call's own copy
            sim = Simulator(ctx)
            end = resume.end if resume is not None and resume.ok else None
            key = _key(sim, rec) if keep_end or end is not None else b""
            if end is None or end.key != key:
                end = None
            elif end.index >= n - 1:        # the earlier run had these samples
                return Outputs({j: y[:n] for j, y in resume.angles.items()},
                               {j: (pa[:n], pb[:n]) for j, (pa, pb) in resume.pressures.items()},
                               end=end if keep_end and end.index == n - 1 else None)
            run = _Run(sim, rec)
            if end is not None:
                run.resume(resume, end)
            stops = [n] if abandon is None else \
                sorted({run.have + (n - run.have) * k // PIECES for k in range(1, PIECES + 1)} - {run.have})
            for stop in stops:
                run.to(stop)
                if stop < n and abandon(run.outputs()):
                    return Outputs({}, {}, ok=False, abandoned=True)
        except (SimulationError, ValueError, ArithmeticError):
            return Outputs({}, {}, ok=False)
        out = run.outputs()
        for y in out.angles.values():
            if not np.all(np.isfinite(y)):
                return Outputs({}, {}, ok=False)
        if keep_end:
            out.end = End(key, n - 1, sim.save(), run.row.copy())
        return out


PIECES = 4     # a run that may be abandoned is asked after each quarter


class _Run:
    """One simulation on a record, advanced in pieces: the outputs so far, and the last row."""

    def __init__(self, sim: Simulator, rec: Record):
        self.sim, self.rec = sim, rec
        self.have = 0                # samples [0, have) simulated
        self.row = None              # the outputs row of sample have - 1
        self.angles = {j: [] for j in rec.angles}
        self.pressures = {j: ([], []) for j in rec.pressures}

    def resume(self, out: Outputs, end: End) -> None:
        """Continue from ``end``, the end of ``out``'s run."""
        self.sim.restore(end.state)
        self.have, self.row = end.index + 1, end.row
        for j, parts in self.angles.items():
            parts.append(out.angles[j][: self.have])
        for j, (pa, pb) in self.pressures.items():
            pa.append(out.pressures[j][0][: self.have])
            pb.append(out.pressures[j][1][: self.have])

    def to(self, stop: int) -> None:
        """Simulate samples [have, stop)."""
        first = max(self.have - 1, 0)            # the run goes on from the last sample it has
        traj = self.sim.run(self.rec.time[first:stop], self.rec.U[first:stop], first_row=self.row)
        new = slice(1 if self.have else 0, None)
        for j, parts in self.angles.items():
            parts.append(traj.angle(j)[new])
        for j, (pa, pb) in self.pressures.items():
            pa.append(traj.pressure(j, "a")[new])
            pb.append(traj.pressure(j, "b")[new])
        self.have, self.row = stop, traj.act[-1]

    def outputs(self) -> Outputs:
        return Outputs({j: _joined(p) for j, p in self.angles.items()},
                       {j: (_joined(pa), _joined(pb)) for j, (pa, pb) in self.pressures.items()})


def _joined(parts: list[np.ndarray]) -> np.ndarray:
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def refresh_substeps(dt: float, substep: float) -> int:
    """Substeps of an output step ``dt`` (s) cut to at most ``substep`` (s) that make about
    ``FAST_REFRESH_S``; 0 (each output step) where an output step is as long already."""
    nsub = max(1, math.ceil(dt / substep - 1e-9))
    k = max(1, round(FAST_REFRESH_S / (dt / nsub)))
    return 0 if k <= nsub else k


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
    if chosen.refresh:
        report["rigid_body_refresh_substeps"] = chosen.refresh
    return chosen, report
