"""Synthetic 'real' records of a user's rig, as a test bench logs them: closed loop, 50 Hz, headerless.

A P controller (run by the 'rig', not by the code under test) tracks operator-like steps with holds;
the truth model is the rig's spec with its nominal parameters off by 10-30 % and one hidden effect;
the logger writes `time (s), position (sensor volts), valve command (V)` with jittered timestamps and
a start pose off the template's. Only the CSV reaches `hydrohil import` and `diagnose`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sim_core.kernel import layout as L
from sim_core.plant import Plant
from sim_core.simulator import Simulator


def reference_steps(lo: float, hi: float, duration: float, rng) -> callable:
    """Piecewise-constant set points within [lo, hi] (joint units), held 1.5-4 s each."""
    t, times, levels = 0.0, [], []
    while t < duration:
        times.append(t)
        levels.append(rng.uniform(lo, hi))
        t += rng.uniform(1.5, 4.0)
    times, levels = np.array(times), np.array(levels)
    return lambda tt: levels[np.searchsorted(times, tt, side="right") - 1]


def sine_reference(lo: float, hi: float, duration: float, rng) -> callable:
    """A raised-cosine set point sweeping [lo, hi] at 0.1-0.3 Hz: the tracking test of a bench."""
    f = rng.uniform(0.1, 0.3)
    return lambda tt: lo + (hi - lo) * 0.5 * (1.0 - np.cos(2.0 * np.pi * f * tt))


def closed_loop_record(rig_dir, *, hidden: tuple[str, dict] | None, off: dict[str, float], seed: int,
                       duration: float = 60.0, rate: float = 50.0, kp: float | None = None,
                       start_offset: float = 0.0, jitter: float = 0.1, log_every: int = 1,
                       extra: tuple[tuple[str, dict], ...] = (), ti: float | None = None,
                       reference_range: tuple[float, float] | None = None, reference=reference_steps,
                       interference=None, during=None):
    """Simulate the rig under P control; returns (rows [N, 3]: time, sensor V, command V, truth spec).

    ``off``: {parameter path: factor} applied to the truth model (the nominal spec stays as written);
    ``hidden``: (effect, params) switched on at the rig's one actuated joint; ``kp``: V per joint unit
    (default: full command for 20 % of the range of motion); ``log_every``: the controller runs at
    ``log_every`` x ``rate`` and every ``log_every``-th sample is logged (a logger slower than the loop);
    ``extra``: more (effect, params) of the truth at the joint, physics the diagnosis is not asked to
    name (a Stribeck friction: real seals); ``ti``: integral time (s) of a PI controller (integral
    gain kp / ti), its integral frozen while the command saturates (anti-windup); None: P only.
    ``reference_range``: (low, high) of the set points (default: the middle 60 % of the range);
    ``reference``: how the set point moves in it (``reference_steps`` or ``sine_reference``);
    ``interference``: volts the sensor's wiring adds at time t (s) (mains hum), read by the controller
    and logged alike; ``during(context, t)``: called before each step with the truth's context (a
    parameter that drifts, a load picked up mid-record)."""
    rng = np.random.default_rng(seed)
    plant = Plant.from_robot(rig_dir)
    spec = plant.spec.copy()
    joint = spec.joint_names[0]
    for path, factor in off.items():
        spec.set(path, spec.get(path) * factor)
    for name, params in ((hidden,) if hidden is not None else ()) + tuple(extra):
        spec.enable_effect(name, joint, **params)
    i = spec.tree.index(spec.joint(joint).dof)
    lo_q, hi_q = float(spec.tree.lower[i]), float(spec.tree.upper[i])
    span = hi_q - lo_q
    q0 = float(spec.joint(joint).settings["initial_position"]) + start_offset
    spec.set(f"joints.{joint}.initial_position", q0)
    ctx = plant.create_context(spec, seed=seed)
    sim = Simulator(ctx)
    u_lo, u_hi = spec.joint(joint).command_range
    kp = kp if kp is not None else u_hi / (0.2 * span)
    ki = 0.0 if ti is None else kp / ti
    ref = reference(*(reference_range or (lo_q + 0.2 * span, hi_q - 0.2 * span)), duration, rng)
    A = float(spec.get(f"joints.{joint}.sensor.A"))
    B = float(spec.get(f"joints.{joint}.sensor.B"))
    rows = []
    t, integral = 0.0, 0.0
    y = sim.sample()[0]
    while t < duration:
        if during is not None:
            during(ctx, t)
        volts = float(y[L.YA_SENS_V]) + (interference(t) if interference is not None else 0.0)
        pos = A * volts + B                      # the rig's controller reads its own sensor
        e = ref(t) - pos
        raw = kp * e + ki * integral
        u = float(np.clip(raw, u_lo, u_hi))
        rows.append((t, volts, round(u, 3)))
        dt = (1.0 + rng.uniform(-jitter, jitter)) / (rate * log_every)
        if raw == u:
            integral += e * dt
        y = sim.step(np.array([u]), dt)[0]
        t += dt
    return np.array(rows)[::log_every], spec


def stroke(spec, joint: str) -> float:
    """The joint's range between its limits (rad or m): start offsets are shares of it."""
    i = spec.tree.index(spec.joint(joint).dof)
    return float(spec.tree.upper[i] - spec.tree.lower[i])


def as_record(spec, rows: np.ndarray, source: str = "log"):
    """The logged rows as the diagnosis reads them: the position from the sensor volts by the rig's
    own sensor model (A raw + B), without the CSV round trip of ``hydrohil import``."""
    from sim_core.dataset import Dataset
    from sim_core.identification.record import record_from_dataset

    j = spec.joint_names[0]
    A, B = spec.get(f"joints.{j}.sensor.A"), spec.get(f"joints.{j}.sensor.B")
    ds = Dataset(["time", f"q_{j}", f"u_{j}"], np.column_stack([rows[:, 0], A * rows[:, 1] + B, rows[:, 2]]))
    return record_from_dataset(ds, spec, source=source)


def logged_like_a_daq(rows: np.ndarray, rng, bits: int = 0, dropouts: int = 0, span_v: float = 10.0) -> np.ndarray:
    """The rows as a plainer acquisition logs them: the sensor volts quantised by a ``bits``-bit
    converter over ``span_v`` volts, and ``dropouts`` samples where the wiper lifts (0 V)."""
    out = np.array(rows, float)
    if bits:
        q = span_v / 2 ** bits
        out[:, 1] = np.round(out[:, 1] / q) * q
    if dropouts:
        out[rng.choice(np.arange(5, len(out) - 5), dropouts, replace=False), 1] = 0.0
    return out


def write_headerless(rows: np.ndarray, path) -> None:
    np.savetxt(path, rows, delimiter=",", fmt=["%.4f", "%.4f", "%.3f"])


def measured(rig_dir, keys: dict[str, float]) -> None:
    """What a user does after measuring some of the rig's parameters: each key of ``keys`` (a
    robot.toml path, e.g. ``supply.pressure``) is written with its measured value and its line leaves
    the [estimated] table, so calibration holds it (README: "delete its line to hold it fixed")."""
    import re

    from sim_core.model.spec import estimable, load_robot

    path = Path(rig_dir) / "robot.toml"
    text = path.read_text()
    for key, value in keys.items():
        text = "\n".join(line for line in text.splitlines() if not line.startswith(f'"{key}"')) + "\n"
        table, name = key.rsplit(".", 1)
        if table.startswith("effects."):                       # [[effects]] name = "payload", joint = "lift"
            _, effect, joint = table.split(".")
            block = re.compile(rf'(\[\[effects\]\]\s*\nname = "{effect}"\s*\njoint = "{joint}"\s*\n(?:(?!\[).*\n)*?)'
                               rf'{name} = [^#\n]*')
        else:
            block = re.compile(rf'(\[{re.escape(table)}\]\s*\n(?:(?!\[).*\n)*?){name} = [^#\n]*')
        text, n = block.subn(lambda m: f"{m.group(1)}{name} = {float(value)!r}  ", text, count=1)
        if n != 1:
            raise KeyError(f"{key}: not written in {path}")
    path.write_text(text)
    spec = load_robot(rig_dir)
    for key, value in keys.items():
        assert estimable(spec, key)[1] == float(value) and key not in spec.estimated, key


def diagnose_log(cli, root, name: str, joint: str, command_unit: str = "",
                 position_unit: str = ":sensor_volts") -> tuple[dict, str]:
    """``diagnose`` of ``root/log.csv`` (headerless: time, position, command) on the rig in ``root/rig``
    as a user reads it, the command in ``command_unit`` (e.g. ':*2-10'), the position in
    ``position_unit`` ('' for SI); the report in ``root/name``. Returns diagnosis.json and what was printed."""
    proc = cli("diagnose", "--robot", root / "rig", root / "log.csv", "--no-header", "--column", "time=0",
               "--column", f"q_{joint}=1{position_unit}", "--column", f"u_{joint}=2{command_unit}", "--report",
               root / name, "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert "RuntimeWarning" not in proc.stderr
    return json.loads((root / name / "diagnosis.json").read_text()), proc.stdout


def rig_log(cli, root, template: str, logged, *, off: dict[str, float], start_offset: float, seed: int = 5,
            **loop):
    """A clean rig of ``template`` in ``root/rig`` under its P controller (``loop``: more of
    ``closed_loop_record``'s settings, e.g. ``ti`` for PI), written to ``root/log.csv`` as a headerless
    log whose command column is ``logged(u)``: the command as a logger got it wrong."""
    cli("rig", "new", template, "--out", root / "rig", check=True)
    rows, _ = closed_loop_record(root / "rig", hidden=None, seed=seed, start_offset=start_offset, off=off, **loop)
    rows = np.asarray(rows, float)
    rows[:, 2] = logged(rows[:, 2])
    write_headerless(rows, root / "log.csv")
    return root
