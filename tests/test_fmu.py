"""hydrohil fmu: the FMI 2.0 co-simulation export, simulated by FMPy against `hydrohil simulate`.

Bound of the comparison: 1e-9 rad on the measured angles (and 1e-9 of full scale on pressures and
velocities). `hydrohil simulate` writes its CSV with 10 significant digits (5e-11 rad on an angle of
1 rad, 5e-4 Pa on 10 MPa), and FMPy's communication points k*h differ from the CSV's k/rate by an
ulp, so the step sizes do too (relative 1e-16); both sit far below the bound. The noise draws are the
same when the FMU's `seed` parameter equals `simulate --seed` and the communication step is the
input's sample period (one Simulator.step per row, as `simulate` does).
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

import fmpy  # the test extra installs fmpy and pythonfmu: a missing one fails here, never skips
import pythonfmu  # noqa: F401
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from sim_core.dataset import read_csv
from sim_core.export.fmi_names import FmiNameError, part, path_name
from sim_core.export.fmu_variables import interface, parameter_entries
from sim_core.export.robot_snapshot import write_snapshot
from sim_core.export.units import fmi_unit, for_joint_type
from sim_core.model.spec import available_robots, load_robot
from sim_core.rigs import TEMPLATES, new_rig

DATA = Path(__file__).resolve().parent / "data"

RATE = 200.0      # Hz: the input grid and the communication step
DURATION = 4.0    # s
EXCITED = {"hydrolek": "j2", "harvester": "boom"}


def _input_signal(csv: Path):
    ds = read_csv(csv)
    names = [c for c in ds.columns if c.startswith("u_")]
    sig = np.zeros(len(ds), dtype=[("time", float)] + [(n, float) for n in names])
    sig["time"] = ds.time
    for n in names:
        sig[n] = ds[n]
    return sig


def _simulate_fmu(fmu: Path, csv: Path, outputs, start_values=None, **kw):
    sig = _input_signal(csv)
    return simulate_fmu(str(fmu), start_time=0.0, stop_time=float(sig["time"][-1]), output_interval=1.0 / RATE,
                        input=sig, output=list(outputs), start_values=dict(start_values or {}), validate=True, **kw)


def _excite(cli, robot, tmp_path) -> Path:
    csv = tmp_path / "in.csv"
    cli("excite", "--robot", robot, "--joint", EXCITED[robot], "--duration", DURATION, "--rate", RATE, "--seed", 1,
        "--out", csv, check=True)
    return csv


def _assert_matches(res, sim_csv: Path, spec, tol_rad=1e-9, tol_rel=1e-9):
    ds = read_csv(sim_csv)
    assert len(res) == len(ds)
    assert np.max(np.abs(res["time"] - ds.time)) < 1e-9
    worst = 0.0
    for j in spec.sensed_joints:
        d = np.max(np.abs(res[f"q_{j}"] - ds[f"q_{j}"]))
        assert d <= tol_rad, f"q_{j}: FMU differs from hydrohil simulate by {d:.3g} rad"
        worst = max(worst, d)
    for j in spec.joint_names:
        for ch in "ab":
            p = ds[f"p_{j}_{ch}"]
            d = np.max(np.abs(res[f"p_{j}_{ch}"] - p))
            assert d <= tol_rel * np.max(np.abs(p)), f"p_{j}_{ch}: differs by {d:.3g} Pa"
    return worst


def _outputs(spec):
    return ([f"q_{j}" for j in spec.sensed_joints] + [f"p_{j}_{c}" for j in spec.joint_names for c in "ab"]
            + [f"qd_{j}" for j in spec.joint_names])


@pytest.mark.parametrize("robot", ["hydrolek", "harvester"])
def test_fmu_matches_simulate_on_prbs(robot, cli, tmp_path):
    """The exported FMU, simulated by FMPy on a PRBS input, gives `hydrohil simulate`'s angles and
    pressures within 1e-9 (noise included: same seed), and the modelDescription validates."""
    spec = load_robot(robot)
    csv = _excite(cli, robot, tmp_path)
    sim_csv = tmp_path / "sim.csv"
    cli("simulate", "--robot", robot, "--input", csv, "--out", sim_csv, "--seed", 7, check=True)
    fmu = tmp_path / "plant.fmu"
    out = cli("fmu", "--robot", robot, "--out", fmu, check=True)
    assert str(fmu) in out.stdout and "hydrohil installed" in out.stdout
    assert validate_fmu(str(fmu)) == []

    res = _simulate_fmu(fmu, csv, _outputs(spec), {"seed": 7})
    _assert_matches(res, sim_csv, spec)
    ds = read_csv(sim_csv)
    j = EXCITED[robot]
    assert np.ptp(ds[f"q_{j}"]) > 0.05, "the PRBS must move the excited joint for the comparison to mean something"

    # velocities against the Simulator on the same input (the dataset has no velocity column)
    from sim_core.plant import Plant
    from sim_core.simulator import Simulator

    U = np.column_stack([read_csv(csv)[f"u_{n}"] for n in spec.joint_names])
    traj = Simulator(Plant(spec).create_context(seed=7)).run(read_csv(csv).time, U)
    for a, n in enumerate(spec.joint_names):
        qd = traj.qd[:, spec.tree.index(spec.joint(n).dof)]
        assert np.max(np.abs(res[f"qd_{n}"] - qd)) <= 1e-9 * max(1.0, np.max(np.abs(qd)))
    assert np.ptp(res[f"qd_{j}"]) > 0.05

    # the seed parameter is applied: another seed draws other noise (sensor noise 5e-4 V rms ~ 0.3 mrad)
    other = _simulate_fmu(fmu, csv, [f"q_{j}"], {"seed": 8})
    assert np.max(np.abs(other[f"q_{j}"] - ds[f"q_{j}"])) > 1e-5


def test_fmu_with_params_file_travels_inside(cli, tmp_path):
    """--params changes (parameters and an effect) are inside the FMU: it matches `simulate --params`
    after the file is deleted, and its parameters start at the file's values."""
    robot = "hydrolek"
    spec = load_robot(robot)
    params = tmp_path / "fit.toml"
    params.write_text('robot = "hydrolek"\n[parameters]\n"joints.j2.valve.rated_flow" = 2.9e-5\n'
                      '"joints.j2.sensor.B" = -2.8\n"supply.pressure" = 12.5e6\n'
                      '[[effects]]\nname = "coulomb_friction"\njoint = "j2"\ntorque = 20.0\n')
    csv = _excite(cli, robot, tmp_path)
    sim_csv, nominal_csv = tmp_path / "sim.csv", tmp_path / "nominal.csv"
    cli("simulate", "--robot", robot, "--params", params, "--input", csv, "--out", sim_csv, "--seed", 3, check=True)
    cli("simulate", "--robot", robot, "--input", csv, "--out", nominal_csv, "--seed", 3, check=True)
    fmu = tmp_path / "out" / "fitted.fmu"
    cli("fmu", "--robot", robot, "--params", params, "--out", fmu, check=True)
    params.unlink()
    with zipfile.ZipFile(fmu) as z:
        names = set(z.namelist())
        assert {"resources/hydrohil/robot.toml", "resources/hydrohil/hydrolek.urdf",
                "resources/hydrohil/overrides.toml", "modelDescription.xml"} <= names
        assert "coulomb_friction" in z.read("resources/hydrohil/overrides.toml").decode()

    md = read_model_description(str(fmu))
    start = {v.name: v.start for v in md.modelVariables}
    assert float(start["joints.j2.valve.rated_flow"]) == 2.9e-5
    assert float(start["supply.pressure"]) == 12.5e6
    assert float(start["joints.j1.valve.rated_flow"]) == spec.get("joints.j1.valve.rated_flow")

    res = _simulate_fmu(fmu, csv, _outputs(spec), {"seed": 3})
    _assert_matches(res, sim_csv, spec)
    # the params matter: the nominal model is far from the fitted one
    assert np.max(np.abs(res["q_j2"] - read_csv(nominal_csv)["q_j2"])) > 1e-3


def test_parameters_set_by_the_importer_match_simulate_set(cli, tmp_path):
    """FMU parameters set by the importing tool act like `simulate --set`; a bad value is refused with
    its name."""
    robot = "harvester"
    spec = load_robot(robot)
    csv = _excite(cli, robot, tmp_path)
    changes = {"joints.boom.valve.rated_flow": 0.6 * spec.get("joints.boom.valve.rated_flow"),
               "fluid.bulk_modulus": 0.9e9, "joints.boom.initial_position": 0.2}
    sim_csv = tmp_path / "sim.csv"
    cli("simulate", "--robot", robot, "--input", csv, "--out", sim_csv, "--seed", 0,
        *[a for p, v in changes.items() for a in ("--set", f"{p}={v!r}")], check=True)
    fmu = tmp_path / "plant.fmu"
    cli("fmu", "--robot", robot, "--out", fmu, check=True)
    res = _simulate_fmu(fmu, csv, _outputs(spec), changes)
    _assert_matches(res, sim_csv, spec)
    assert abs(res["q_boom"][0] - 0.2) < 0.01  # the initial position took effect

    log = []
    with pytest.raises(Exception):
        _simulate_fmu(fmu, csv, ["q_boom"], {"joints.boom.valve.rated_flow": -1.0}, debug_logging=True,
                      logger=lambda env, inst, status, cat, msg: log.append(msg.decode()))
    assert any("joints.boom.valve.rated_flow" in m for m in log), log


def _instantiate(fmu: Path, md, log: list):
    """An FMPy FMU2Slave of ``fmu`` whose FMI log messages go to ``log``."""
    from fmpy import calloc, extract, free
    from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="test")
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(lambda env, inst, status, cat, msg: log.append(msg.decode()))
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    slave._test_callbacks = cb  # keep the ctypes callbacks alive as long as the instance
    slave.instantiate(callbacks=cb, loggingOn=True)
    return slave


def test_step_errors_end_the_instance_with_a_reason(tmp_path):
    """A NaN input, or a parameter set after initialization, is refused with the reason in the FMI log."""
    from sim_core.export.fmu_build import build_fmu

    fmu = build_fmu(load_robot("harvester"), tmp_path / "h.fmu")
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    cases = ((lambda s: s.setReal([vr["u_boom"]], [float("nan")]), "non-finite input(s) u_boom"),
             (lambda s: s.setReal([vr["supply.pressure"]], [1.0e7]), "supply.pressure is fixed"))
    for action, expect in cases:
        log: list[str] = []
        slave = _instantiate(fmu, md, log)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        slave.setReal([vr["u_boom"]], [5.0])
        slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.01)
        assert np.isfinite(slave.getReal([vr["q_boom"], vr["p_boom_a"]])).all()
        with pytest.raises(Exception):
            action(slave)
            slave.doStep(currentCommunicationPoint=0.01, communicationStepSize=0.01)
        assert any(expect in m for m in log), log


def test_fmu_without_hydrohil_says_what_is_missing(tmp_path):
    """On a Python without hydrohil the FMU fails at instantiation and says to install hydrohil."""
    from sim_core.export.fmu_build import build_fmu

    fmu = build_fmu(load_robot("harvester"), tmp_path / "h.fmu")
    site = sysconfig.get_paths()["purelib"]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = site  # fmpy and numpy, but -S skips the .pth files that install hydrohil (editable)
    code = ("import fmpy\n"
            "try:\n    import sim_core\nexcept ImportError:\n    pass\nelse:\n    raise SystemExit('sim_core importable')\n"
            f"fmpy.simulate_fmu({str(fmu)!r}, stop_time=0.01)\n")
    proc = subprocess.run([sys.executable, "-S", "-c", code], capture_output=True, text=True, cwd=tmp_path,
                          env=env, timeout=300)
    assert proc.returncode != 0
    assert "sim_core importable" not in proc.stderr
    assert "needs the hydrohil package" in proc.stderr and "pip install hydrohil" in proc.stderr
    assert "Failed to instantiate" in proc.stderr


def _libpython() -> Path | None:
    name = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY") or ""
    lib = Path(sysconfig.get_config_var("LIBDIR") or "") / name
    return lib if name.endswith(tuple(".so" + s for s in ("", ".1", ".1.0"))) and lib.is_file() else None


def test_fmu_runs_in_a_c_master_without_python(tmp_path):
    """A C program that drives the FMU through the FMI 2.0 C API, as Simulink and OMSimulator do,
    gets the Simulator's numbers; its process has no Python until the FMU brings libpython
    (LD_PRELOAD, as the README tells Linux users of such tools)."""
    import platform
    import shutil

    from sim_core.export.fmu_build import build_fmu
    from sim_core.plant import Plant
    from sim_core.simulator import Simulator

    cc = shutil.which("cc") or shutil.which("gcc")
    if sys.platform != "linux" or platform.machine() != "x86_64":
        pytest.skip("pythonfmu ships linux64 and win64 binaries; this test drives the linux64 one")
    if cc is None:
        pytest.skip("no C compiler (cc/gcc) to build the C master")
    lib = _libpython()
    if lib is None:
        pytest.skip(f"this Python has no shared libpython (Py_ENABLE_SHARED={sysconfig.get_config_var('Py_ENABLE_SHARED')})")
    headers = Path(fmpy.__file__).parent / "c-code"
    master = tmp_path / "fmu_c_master"
    subprocess.run([cc, "-O1", "-o", str(master), str(Path(__file__).parent / "fmu_c_master.c"), f"-I{headers}", "-ldl"],
                   check=True, capture_output=True, timeout=120)

    spec = load_robot("harvester")
    fmu = build_fmu(spec, tmp_path / "h.fmu")
    unzipped = tmp_path / "unzipped"
    zipfile.ZipFile(fmu).extractall(unzipped)
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = ["q_boom", "p_boom_a", "qd_boom", "q_stick"]
    steps, dt, u = 150, 0.01, 6.0
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["LD_PRELOAD"] = str(lib)
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).resolve().parent.parent), sysconfig.get_paths()["purelib"],
                                         sysconfig.get_paths()["platlib"]])
    proc = subprocess.run([str(master), str(unzipped), md.coSimulation.modelIdentifier, md.guid, str(steps), repr(dt),
                           f"{vr['u_boom']}={u}", ",".join(str(vr[n]) for n in outs)],
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = np.array([[float(x) for x in line.split(",")] for line in proc.stdout.split()])
    assert got.shape == (steps + 1, 1 + len(outs))

    U = np.zeros((steps + 1, len(spec.joint_names)))
    U[:, spec.joint_names.index("boom")] = u
    traj = Simulator(Plant(spec).create_context(seed=0)).run(np.arange(steps + 1) * dt, U)
    ref = {"q_boom": traj.angle("boom"), "p_boom_a": traj.pressure("boom", "a"), "q_stick": traj.angle("stick"),
           "qd_boom": traj.qd[:, spec.tree.index(spec.joint("boom").dof)]}
    for i, n in enumerate(outs):
        scale = max(1.0, float(np.max(np.abs(ref[n]))))
        assert np.max(np.abs(got[:, 1 + i] - ref[n])) <= 1e-9 * scale, n
    assert np.ptp(ref["q_boom"]) > 0.05


@pytest.mark.parametrize("robot", available_robots())
def test_model_description_is_the_robots_interface(robot, tmp_path):
    """Inputs, outputs and every float parameter of the spec, with units and exact start values."""
    from sim_core.export.fmu_build import build_fmu

    spec = load_robot(robot)
    fmu = build_fmu(spec, tmp_path / f"{robot}.fmu")
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert md.fmiVersion == "2.0" and md.coSimulation is not None
    assert md.coSimulation.canHandleVariableCommunicationStepSize
    by_name = {v.name: v for v in md.modelVariables}
    assert [v.name for v in md.modelVariables if v.causality == "input"] == [f"u_{j}" for j in spec.joint_names]
    assert all(by_name[f"u_{j}"].unit == "V" for j in spec.joint_names)
    outputs = {v.name for v in md.modelVariables if v.causality == "output"}
    assert outputs == ({f"q_{j}" for j in spec.sensed_joints}
                       | {f"qd_{j}" for j in spec.joint_names} | {f"qd_{d}" for d in spec.passive}
                       | {f"p_{j}_{c}" for j in spec.joint_names for c in "ab"})
    assert all(u.dependencies == [] for u in md.outputs)  # no direct feedthrough in a co-simulation step
    floats = {k: v for k, v in spec.parameters().items() if isinstance(v, float)}
    params = {v.name: v for v in md.modelVariables if v.causality == "parameter"}
    assert set(params) == {path_name(p) for p in floats} | {"seed"}
    for path, value in floats.items():
        assert float(params[path_name(path)].start) == value, path  # exact: written to round-trip
    units = {u.name: u for u in md.unitDefinitions}
    pa = units[by_name["supply.pressure"].unit].baseUnit
    assert (pa.kg, pa.m, pa.s) == (1, -1, -2)
    j = spec.joint_names[0]
    assert by_name[f"p_{j}_a"].unit == "Pa" and by_name[f"joints.{j}.valve.rated_flow"].unit == "m3/s"


def test_robot_snapshot_loads_back_to_the_same_spec(tmp_path):
    """The FMU's robot.toml is self-contained (arms expanded, defaults written, keyword defaults such as
    a direct cylinder's offset = 'auto', the [estimated] ranges) and loads back equal: built-in robots,
    a prismatic rig and every `rig new` template."""
    robots = [load_robot(r) for r in available_robots()] + [load_robot(DATA / "lift")]
    for template in TEMPLATES:
        toml_path, _, _ = new_rig(template, tmp_path / "rigs" / template)
        robots.append(load_robot(toml_path))
    for spec in robots:
        robot = spec.name
        assert spec.name != "lift" or spec.joints[0].components["cylinder"].values["offset"] == "auto"
        path = f"joints.{spec.joint_names[0]}.valve.rated_flow"
        spec.set(path, spec.parameters()[path] * 1.0123456789)
        spec.set("links.mass_scale", 1.1)
        back = load_robot(write_snapshot(spec, tmp_path / robot))
        assert back.parameters() == spec.parameters()
        assert [e.to_dict() for e in back.effects] == [e.to_dict() for e in spec.effects]
        assert back.tree.dof_names == spec.tree.dof_names
        tables = tomllib.loads((tmp_path / robot / "robot.toml").read_text())
        assert not {"arms", "defaults"} & set(tables)
        assert back.estimated == spec.estimated
    assert any(spec.estimated for spec in robots)


def test_every_parameter_has_a_declared_unit():
    for robot in available_robots():
        spec = load_robot(robot)
        entries = parameter_entries(spec)
        assert {p for p, _, _ in entries} == {k for k, v in spec.parameters().items() if isinstance(v, float)}
        names = [v.name for v in interface(spec)]
        assert len(names) == len(set(names))


def test_units_and_names():
    flow_per_pa = fmi_unit("m^3/(s Pa)")
    assert flow_per_pa == fmi_unit("m^3/s/Pa")
    assert dict(flow_per_pa.base) == {"kg": -1, "m": 4, "s": 1}      # m^3 s^-1 / (kg m^-1 s^-2)
    assert fmi_unit("N m s/rad").name == "N.m.s/rad"
    assert dict(fmi_unit("V").base) == {"kg": 1, "m": 2, "s": -3, "A": -1}
    assert fmi_unit("-") is None and fmi_unit("substeps") is None
    assert for_joint_type("rad/V", prismatic=True) == "m/V" and for_joint_type("rad/V", prismatic=False) == "rad/V"
    with pytest.raises(ValueError):
        fmi_unit("furlong")
    assert path_name("joints.j2.valve.rated_flow") == "joints.j2.valve.rated_flow"
    assert path_name("joints.boom-lift.sensor.A") == "joints.'boom-lift'.sensor.A"
    assert part("it's") == "'it\\'s'"
    with pytest.raises(FmiNameError):
        part("bras\u00e9")


@pytest.mark.parametrize("args, message", [
    (["--robot", "nosuch", "--out", "{tmp}/p.fmu"], "unknown robot 'nosuch'"),
    (["--robot", "harvester", "--out", "{tmp}/file.txt/p.fmu"], "file.txt is not a directory"),
    (["--robot", "harvester", "--out", "{tmp}/p.zip"], "must end in .fmu"),
    (["--robot", "harvester", "--out", "{tmp}"], "must end in .fmu"),
    (["--robot", "harvester", "--out", "/proc/hydrohil-test.fmu"], "cannot write there"),
    (["--robot", "harvester", "--params", "{tmp}/missing.toml", "--out", "{tmp}/p.fmu"], "missing.toml: no such file"),
    (["--robot", "harvester", "--params", "{tmp}/broken.toml", "--out", "{tmp}/p.fmu"], "broken.toml: invalid TOML"),
    (["--robot", "harvester", "--params", "{tmp}/wrong.toml", "--out", "{tmp}/p.fmu"], "written for robot 'hydrolek'"),
    (["--robot", "harvester", "--params", "{tmp}/range.toml", "--out", "{tmp}/p.fmu"], "supply.pressure"),
])
def test_bad_input_is_a_clear_error(cli, tmp_path, args, message):
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "broken.toml").write_text("[parameters\n")
    (tmp_path / "wrong.toml").write_text('robot = "hydrolek"\n')
    (tmp_path / "range.toml").write_text('[parameters]\n"supply.pressure" = -5.0\n')
    proc = cli("fmu", *[a.replace("{tmp}", str(tmp_path)) for a in args])
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("hydrohil fmu: error:") and message in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not list(tmp_path.rglob("*.fmu")), "no FMU, and no partial file, after an error"
