"""The plant as a pythonfmu co-simulation slave: what runs inside an exported FMU.

The FMU's resources hold the robot (:mod:`.robot_snapshot`), the parameter overrides and a small
script that imports :class:`PlantSlave` from the installed hydrohil package; pythonfmu's binary
loads that script into a Python interpreter of the importing process. So the FMU needs a Python with
hydrohil on the importing side; the script says so when the import fails.

Semantics (FMI 2.0 co-simulation):

* Parameters (``fixed``) go through :meth:`Context.set_parameter`, which validates each one; a
  value refused only because of another parameter not yet set (a cross-component check) is retried
  after the others when the plant starts, and an error then names every refused value.
* The plant starts (a fresh Context with the ``seed`` parameter, like ``hydrohil simulate``) when
  initialization ends or an output is read during initialization; the outputs then are the first
  sample of the sensors, as row 0 of ``hydrohil simulate``'s output.
* ``fmi2DoStep(t, h)`` holds the inputs for ``h`` seconds (zero-order hold) and advances one
  :meth:`Simulator.step`; a communication step equal to the input grid of ``hydrohil simulate``
  gives the same numbers (same noise draws too).
* A non-finite input, a non-positive step or a diverged state raises: pythonfmu then reports the
  message through the FMI logger and the instance is finished (never a plant that looks alive).
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import re
from pathlib import Path
from urllib.parse import unquote, urlparse
from xml.etree.ElementTree import Element, SubElement

import numpy as np
from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

from ..kernel import layout as L
from ..model.spec import SpecError, load_robot
from ..params_file import apply_params_file
from ..plant import Plant
from ..simulator import Simulator
from .fmu_build import DATA_DIR, MANIFEST
from .fmu_variables import SEED, interface
from .units import fmi_unit

DEFAULT_STEP = 1e-3            # s; the HIL engine's tick, a natural communication step


def resource_dir(resources: str) -> Path:
    """The resources folder, given as a path or as a file URI (FMI passes a URI)."""
    if resources.startswith("file:"):
        return Path(unquote(urlparse(resources).path))
    return Path(resources)


def model_identifier(robot: str) -> str:
    """A C identifier naming the FMU's binary (``hydrohil_<robot>``)."""
    return "hydrohil_" + re.sub(r"\W", "_", robot, flags=re.ASCII)


_NAMESPACES: list[dict] = []


def hold_namespace(namespace: dict) -> None:
    """Keep one more reference to the FMU script's module namespace.

    pythonfmu's binary (0.7 and earlier) executes the script once more at every instantiation and
    then drops a reference to the module's namespace that it never took (PythonFMU issue #228): the
    second instance in one process (a second simulation in FMPy, a second run in Simulink) then
    finds the module freed. The script calls this at every execution, which balances that release.
    """
    _NAMESPACES.append(namespace)


class _UnitReal(Real):
    """pythonfmu's Real with a unit attribute (FMI's ``<Real unit=...>``) and a start value written
    to round-trip exactly (shortest repr, not 16 digits)."""

    def __init__(self, name, unit=None, **kwargs):
        super().__init__(name, **kwargs)
        self.unit = unit

    def to_xml(self) -> Element:
        node = super().to_xml()
        real = node.find("Real")
        if self.start is not None:
            real.set("start", repr(float(self.start)))
        if self.unit:
            real.set("unit", self.unit)
        return node


class PlantSlave(Fmi2Slave):
    author = "HydroHIL"
    license = "Apache-2.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        folder = resource_dir(self.resources or "") / DATA_DIR
        try:
            manifest = json.loads((folder / MANIFEST).read_text())
        except (OSError, ValueError) as exc:
            raise RuntimeError(f"HydroHIL FMU: cannot read {folder / MANIFEST}: {exc}") from None
        spec = load_robot(folder / manifest["robot_file"])
        if manifest.get("overrides"):
            apply_params_file(spec, folder / manifest["overrides"])
        self._cfg = Plant(spec).create_context()  # holds and validates the parameters until the plant starts
        spec = self._cfg.spec
        self.modelName = model_identifier(spec.name)
        self.description = f"HydroHIL plant '{spec.name}': {spec.description}"
        self.version = manifest.get("hydrohil", "")
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=10.0, step_size=DEFAULT_STEP)
        try:
            here = importlib.metadata.version("hydrohil")
        except importlib.metadata.PackageNotFoundError:
            here = "unknown"
        if manifest.get("hydrohil") and here != manifest["hydrohil"]:
            self.log(f"exported by hydrohil {manifest['hydrohil']}, running on hydrohil {here}: the plant's equations "
                     f"are those of the installed version", Fmi2Status.warning)

        self._vars = interface(spec)
        n = len(self._vars)
        self._real = np.full(n, math.nan)            # value of every Real variable, by value reference
        self._n_in = sum(v.causality == "input" for v in self._vars)
        assert all(v.causality == "input" for v in self._vars[:self._n_in]), "interface() lists the inputs first"
        self._u = np.zeros(self._n_in)               # inputs are value references 0 .. n_in-1
        self._seed = 0
        self._pending: dict[str, tuple[float, Exception]] = {}
        self._sim: Simulator | None = None
        self._stepping = False
        idx = {k: [(vr, v.index) for vr, v in enumerate(self._vars) if v.kind == k]
               for k in ("angle", "velocity", "p_a", "p_b")}
        self._out = {k: (np.array([a for a, _ in pairs], dtype=np.intp), np.array([b for _, b in pairs], dtype=np.intp))
                     for k, pairs in idx.items()}
        self._outputs = np.array([vr for vr, v in enumerate(self._vars) if v.causality == "output"], dtype=np.intp)
        for vr, v in enumerate(self._vars):
            self._register(vr, v)

    # ---- variables -----------------------------------------------------------------------------
    def _register(self, vr: int, v) -> None:
        unit = fmi_unit(v.unit)
        common = dict(description=v.description, causality=getattr(Fmi2Causality, v.causality))
        if v.kind == "seed":
            self.register_variable(Integer(v.name, variability=Fmi2Variability.fixed, getter=lambda: self._seed,
                                           setter=self._set_seed, **common))
            return
        if v.causality == "parameter":
            self._real[vr] = self._cfg.get_parameter(v.path)
            common["variability"] = Fmi2Variability.fixed
            setter = lambda x, vr=vr: self._set_real_one(vr, x)  # noqa: E731
        elif v.causality == "input":
            self._real[vr] = 0.0
            common["variability"] = Fmi2Variability.continuous
            setter = lambda x, vr=vr: self._set_real_one(vr, x)  # noqa: E731
        else:
            common["variability"] = Fmi2Variability.continuous
            setter = None
        self.register_variable(_UnitReal(v.name, unit=unit.name if unit else None,
                                         getter=lambda vr=vr: self.get_real([vr])[0], setter=setter, **common))

    def get_real(self, vrs):
        if self._sim is None and np.isin(vrs, self._outputs).any():
            self._start()
        return self._real[np.asarray(vrs, dtype=np.intp)].tolist()

    def set_real(self, vrs, values):
        vrs_a = np.asarray(vrs, dtype=np.intp)
        if vrs_a.size and vrs_a.max() < self._n_in:     # the per-step call: inputs only, no Python loop
            vals = np.asarray(values, dtype=float)
            self._real[vrs_a] = vals
            self._u[vrs_a] = vals
            return
        for vr, x in zip(vrs, values):
            self._set_real_one(int(vr), float(x))

    def _set_real_one(self, vr: int, x: float) -> None:
        v = self._vars[vr]
        if v.causality == "input":
            self._real[vr] = self._u[vr] = x
            return
        if v.causality != "parameter":
            raise ValueError(f"{v.name} is an output; it cannot be set")
        if self._stepping:
            raise ValueError(f"parameter {v.name} is fixed: set it before the end of initialization")
        self._real[vr] = x
        if x == self._cfg.get_parameter(v.path) and v.path not in self._pending:
            return
        self._sim = None                                  # the plant starts again from the new values
        try:
            self._cfg.set_parameter(v.path, x)
            self._pending.pop(v.path, None)
        except SpecError as exc:
            # maybe valid once another parameter is set (cross-component checks): retried at start
            self._pending[v.path] = (x, exc)
            self.log(f"{exc}; retried when the plant starts, after the other parameters", Fmi2Status.warning)

    def _set_seed(self, x) -> None:
        if self._stepping:
            raise ValueError(f"parameter {SEED} is fixed: set it before the end of initialization")
        if int(x) != self._seed:
            self._seed = int(x)
            self._sim = None

    # ---- life cycle ----------------------------------------------------------------------------
    def _apply_pending(self) -> None:
        progress = True
        while self._pending and progress:
            progress = False
            for path, (x, _) in list(self._pending.items()):
                try:
                    self._cfg.set_parameter(path, x)
                except SpecError as exc:
                    self._pending[path] = (x, exc)
                else:
                    del self._pending[path]
                    progress = True
        if self._pending:
            raise ValueError("invalid parameter value(s): " + "; ".join(str(e) for _, e in self._pending.values()))

    def _check_inputs(self) -> None:
        if not np.isfinite(self._u).all():
            bad = [self._vars[i].name for i in np.flatnonzero(~np.isfinite(self._u))]
            raise ValueError(f"non-finite input(s) {', '.join(bad)}: the plant needs a number of volts")

    def _start(self) -> None:
        """A fresh plant from the current parameters and seed, and its first sensor sample."""
        self._apply_pending()
        self._check_inputs()
        ctx = Plant(self._cfg.spec).create_context(seed=self._seed)
        self._sim = Simulator(ctx)
        self._publish(self._sim.sample(self._u))

    def _publish(self, row) -> None:
        r = self._real
        vr, a = self._out["angle"]
        r[vr] = row[a, L.YA_ANGLE]
        vr, a = self._out["p_a"]
        r[vr] = row[a, L.YA_P_A]
        vr, a = self._out["p_b"]
        r[vr] = row[a, L.YA_P_B]
        vr, d = self._out["velocity"]
        r[vr] = self._sim.context.qd[d]

    def enter_initialization_mode(self):
        self._stepping = False

    def exit_initialization_mode(self):
        if self._sim is None:
            self._start()
        self._stepping = True

    def do_step(self, current_time: float, step_size: float) -> bool:
        if not self._stepping:
            raise RuntimeError("fmi2DoStep before the end of initialization")
        if not (step_size > 0.0 and math.isfinite(step_size)):
            raise ValueError(f"communication step {step_size!r} s: must be a positive number of seconds")
        self._check_inputs()
        self._publish(self._sim.step(self._u, step_size))  # SimulationError (diverged) propagates: the instance ends
        return True

    # ---- modelDescription.xml --------------------------------------------------------------------
    def to_xml(self, model_options=dict()) -> Element:  # noqa: B006 (pythonfmu's signature)
        """pythonfmu's description plus what it does not write: unit definitions, and the model
        structure (outputs do not depend on the inputs of the same instant; initial unknowns)."""
        root = super().to_xml(model_options)
        units = {}
        for v in self._vars:
            u = fmi_unit(v.unit)
            if u:
                units[u.name] = u
        defs = Element("UnitDefinitions")
        for u in units.values():
            SubElement(SubElement(defs, "Unit", name=u.name), "BaseUnit", {b: str(e) for b, e in u.base})
        at = list(root).index(root.find("CoSimulation")) + 1
        root.insert(at, defs)
        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        outs = [i + 1 for i, v in enumerate(self._vars) if v.causality == "output"]
        if outs:
            node = SubElement(structure, "Outputs")
            for i in outs:
                SubElement(node, "Unknown", index=str(i), dependencies="")
            node = SubElement(structure, "InitialUnknowns")
            for i in outs:
                SubElement(node, "Unknown", index=str(i))
        return root
