"""Hidden-effect cases for the diagnose tests: 'measured' records made with the real commands.

Each case hides one or two effects in a truth model: the magnitude is drawn from a seeded range,
the nominal parameters are perturbed a few percent (valve flow gain, spool bandwidth, seal friction)
so the baseline is not exact, and the angle noise is drawn from a realistic range. Only the CSV
reaches ``diagnose``. (Not the oil bulk modulus: on the harvester, whose boom rides on its hose and
oil stiffness, 3 % of it moves the angle fit by several points, a discrepancy the tool reports as
line dynamics; see the README.)
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np

from sim_core.identification.candidates import confusions
from sim_core.model.spec import load_robot

DURATION = 30.0      # s per record (the benchmark uses 60 s); 200 Hz, the excite defaults otherwise


def confusable_with(*effects: str) -> list[str]:
    """``effects`` and every effect the catalog (each effect's CONFUSIONS) lists as confusable with one
    of them, sorted."""
    out = set(effects)
    for pair in confusions():
        if pair & set(effects):
            out |= pair
    return sorted(out)


@dataclass
class Case:
    name: str
    robot: str
    joint: str                                    # the excited joint
    hidden: list[tuple[str, str | None, dict]]    # (effect, joint, {param: (lo, hi)})
    sign: dict = field(default_factory=dict)      # param -> True: random sign
    # diagnose options for what the user knows about the record; a sensor offset or gain is told from
    # where the arm started only when the start pose is known (homed: --initial-pose spec): from the
    # record's own first reading, a gain error only scales the motion, as a flow gain error does
    options: list = field(default_factory=list)


CASES = [
    Case("valve_asymmetry", "hydrolek", "j2", [("valve_asymmetry", "j2", {"ratio": (0.75, 0.88)})]),
    Case("spool_lag", "hydrolek", "j2", [("spool_lag", "j2", {"time_constant": (0.04, 0.1)})]),
    Case("delay", "hydrolek", "j2", [("delay", "j2", {"delay": (0.03, 0.08)})]),
    Case("coulomb_friction", "hydrolek", "j2", [("coulomb_friction", "j2", {"torque": (50.0, 90.0)})]),
    Case("backlash", "hydrolek", "j2", [("backlash", "j2", {"width": (0.015, 0.03)})]),
    Case("area_ratio", "hydrolek", "j2", [("area_ratio", "j2", {"ratio": (0.55, 0.66)})]),
    Case("flow_saturation", "hydrolek", "j2", [("flow_saturation", "j2", {"max_flow": (2.0e-5, 2.8e-5)})]),
    Case("pump_limit", "hydrolek", "j2", [("pump_limit", None, {"max_flow": (2.0e-5, 3.5e-5)})]),
    Case("sensor_offset", "hydrolek", "j2", [("sensor_offset", "j2", {"offset": (0.015, 0.035)})], sign={"offset": True},
         options=["--initial-pose", "spec"]),
    Case("hysteresis", "hydrolek", "j2", [("hysteresis", "j2", {"width": (0.4, 0.8)})]),
    Case("valve_offset", "hydrolek", "j2", [("valve_offset", "j2", {"offset": (0.1, 0.4)})], sign={"offset": True}),
    Case("bulk_modulus", "hydrolek", "j2", [("bulk_modulus", None, {"scale": (0.3, 0.5)})]),
    Case("joint_compliance", "hydrolek", "j2", [("joint_compliance", "j2", {"frequency": (3.0, 6.0)})]),
    Case("sensor_gain", "hydrolek", "j3", [("sensor_gain", "j3", {"gain": (1.03, 1.06)})],
         options=["--initial-pose", "spec"]),
    # harvester: deadband, swing leakage and hose lines are part of its nominal model, so the hidden
    # effect is a changed parameter of them
    Case("deadband", "harvester", "boom", [("deadband", "boom", {"width": (1.6, 2.0)})]),
    Case("leakage", "harvester", "swing", [("leakage", "swing", {"internal": (6e-12, 1.2e-11)})]),
    Case("line_dynamics", "harvester", "stick", [("line_dynamics", "stick", {"bulk_modulus_scale": (0.3, 0.5)})]),
    Case("payload", "harvester", "boom", [("payload", "boom", {"mass": (200.0, 400.0)})]),
]
CLEAN = [Case("clean_hydrolek", "hydrolek", "j2", []), Case("clean_harvester", "harvester", "boom", [])]
TWO = [Case("deadband+sensor_offset", "hydrolek", "j2",
            [("deadband", "j2", {"width": (0.6, 1.0)}), ("sensor_offset", "j2", {"offset": (0.015, 0.03)})],
            sign={"offset": True}, options=["--initial-pose", "spec"]),
       # a negative null offset beside a hysteresis: round 1 takes a valve asymmetry for the offset, and
       # only beside the hysteresis named in round 2 does the offset explain more (the exchange pass)
       Case("hysteresis+valve_offset", "hydrolek", "j2",
            [("hysteresis", "j2", {"width": (0.6, 0.72)}), ("valve_offset", "j2", {"offset": (-0.13, -0.09)})]),
       # a leak beside a valve offset: the offset alone wins round 1, fits the angle near its ceiling
       # and leaves more than 15 % of the chamber pressures' misfit (unexplained); from the leak the
       # offset follows, and the leak, worth little of the score beside it, is kept because without
       # it the record is left unexplained. The bank is narrowed to the two and what the effects'
       # catalog lists as confusable with either (the search among them is what is tested; the whole
       # bank on such records is the scored matrix's pair row), which keeps the test to a third.
       Case("leakage+valve_offset", "hydrolek", "j2",
            [("leakage", "j2", {"internal": (3e-13, 4e-13)}), ("valve_offset", "j2", {"offset": (0.08, 0.12)})],
            options=["--effects", *confusable_with("leakage", "valve_offset")])]


def draw(case: Case):
    """(truth effects with drawn values, perturbations {path: value}, noise, seed) for a case."""
    seed = zlib.crc32(case.name.encode())
    rng = np.random.default_rng(seed)
    spec = load_robot(case.robot)
    truth = []
    for name, joint, ranges in case.hidden:
        nominal = [e for e in spec.effects if e.name == name and e.joint == joint]
        vals = dict(nominal[0].params) if nominal else {}   # a changed nominal effect keeps its other values
        for p, (lo, hi) in ranges.items():
            v = float(rng.uniform(lo, hi))
            if case.sign.get(p) and rng.random() < 0.5:
                v = -v
            vals[p] = v
        truth.append((name, joint, vals))
    js = spec.joint(case.joint)
    act = "cylinder" if js.kind == "cylinder" else "rotary"
    pert = {}
    for path, rel in ((f"joints.{case.joint}.valve.rated_flow", 0.05), (f"joints.{case.joint}.spool.natural_frequency", 0.05),
                      (f"joints.{case.joint}.{act}.viscous_friction", 0.1)):
        v = spec.get(path)
        if v:
            pert[path] = float(v * (1.0 + rng.uniform(-rel, rel)))
    noise = float(rng.uniform(2e-4, 6e-4))
    return truth, pert, noise, seed % 1000


def generate(cli, case: Case, where, extra: list[tuple[str, str | None, dict]] = ()):
    """Write the input and the 'measured' CSV with the real commands; returns (csv path, truth).
    ``extra``: effects (name, joint, values) hidden beside the case's, on the same draw of everything else."""
    truth, pert, noise, seed = draw(case)
    truth = truth + list(extra)
    inp = where / "in.csv"
    meas = where / "measured.csv"
    cli("excite", "--robot", case.robot, "--joint", case.joint, "--duration", DURATION, "--seed", seed,
        "--out", inp, check=True)
    args = ["simulate", "--robot", case.robot, "--input", inp, "--out", meas, "--noise-angle", noise, "--seed", seed]
    for path, v in pert.items():
        args += ["--set", f"{path}={v!r}"]
    for name, joint, vals in truth:
        spec = ",".join([f"joint={joint}"] * (joint is not None) + [f"{k}={v!r}" for k, v in vals.items()])
        args += ["--effect", f"{name}:{spec}" if spec else name]
    cli(*args, check=True)
    return meas, truth


def elbow_hysteresis_record(cli, where, duration: float):
    """HydroLek's shoulder and elbow driven together for ``duration`` s (each its own unguarded +-4 V
    PRBS, the elbow often in its end stops), a 0.6 V hysteresis hidden on the elbow, written with
    the real commands (excite, simulate); returns the measured CSV's path."""
    from sim_core.dataset import read_csv, write_csv

    cols = {}
    for joint, seed in (("j2", 1), ("j3", 2)):
        cli("excite", "--robot", "hydrolek", "--joint", joint, "--duration", duration, "--amplitude", 4, "--seed", seed,
            "--no-guard", "--out", where / f"{joint}.csv", check=True)
        ds = read_csv(where / f"{joint}.csv")
        cols["time"] = ds["time"]
        cols[f"u_{joint}"] = ds[f"u_{joint}"]
    write_csv(where / "in.csv", cols)
    cli("simulate", "--robot", "hydrolek", "--input", where / "in.csv", "--out", where / "measured.csv",
        "--effect", "hysteresis:joint=j3,width=0.6", "--noise-angle", 3e-4, "--seed", 5, check=True)
    return where / "measured.csv"
