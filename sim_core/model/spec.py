"""Robot specifications: URDF (geometry, inertia) + TOML (hydraulics, sensors, effects), as data.

A :class:`RobotSpec` is the full parameter set of one robot. It is validated when loaded and every
change goes through :meth:`RobotSpec.set` / :meth:`RobotSpec.enable_effect`, so a bad value is
reported by its path and never reaches the kernel. Parameter paths::

    supply.pressure                       fluid.bulk_modulus            integrator.max_substep
    joints.<joint>.<section>.<parameter>  joints.<joint>.initial_position
    passive.<joint>.initial_position

Robot configurations are chosen by name, like python-can interfaces: the built-in ones live in
``sim_core/robots/<name>/robot.toml``; a path to another ``robot.toml`` works too.
"""

from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..components import (
    Amplifier, Cylinder, DirectionalValve, Fluid, Hose, LabviewAdaptation, Potentiometer,
    ProportionalSolenoid, Pump, RotaryActuator, Spool,
)
from ..components.base import Component, Parameter, ParameterError
from ..effects import EFFECTS, EffectInstance, get_effect
from .urdf import KinematicTree, load_urdf

ROBOTS_DIR = Path(__file__).resolve().parent.parent / "robots"


class SpecError(ParameterError):
    """The robot specification or a parameter override is invalid (the message names the path)."""


class Integrator(Component):
    """Fixed-step integrator settings of the kernel (see ``sim_core.kernel.skeleton``)."""

    section = "integrator"
    citation = "HydroHIL research note 'performance-measurements' (SIP scheme, step-size study)"
    PARAMETERS = (
        Parameter("max_substep", "s", "largest integrator substep; output steps are split evenly", 1e-4, 1e-6, 1e-2),
        Parameter("rigid_body_refresh", "substeps", "refresh M(q) and the bias every k substeps; 0 = once per output step", 0.0, 0.0, 1000.0),
        Parameter("end_stop_frequency", "Hz", "natural frequency of a link on its end stop (lower bound of the stiffness)", 50.0, 1.0, 500.0),
        Parameter("end_stop_penetration", "rad", "how far the actuator's full-pressure torque pushes a joint into its stop", 0.002, 1e-5, 0.1),
        Parameter("end_stop_damping_ratio", "-", "damping ratio of the end stops", 0.7, 0.0, 5.0),
    )


class JointSettings(Component):
    """Per-joint settings that are not a hydraulic component."""

    section = ""
    PARAMETERS = (
        Parameter("initial_position", "rad", "joint angle at reset", 0.0),
        Parameter("payload_frame", "-", "URDF link where the payload effect attaches ('' = end of the joint's link)", "", kind="str"),
    )


SECTIONS: dict[str, type[Component]] = {
    "cfp": LabviewAdaptation,
    "amplifier": Amplifier,
    "solenoid": ProportionalSolenoid,
    "spool": Spool,
    "valve": DirectionalValve,
    "hose": Hose,
    "sensor": Potentiometer,
    "cylinder": Cylinder,
    "rotary": RotaryActuator,
}
ACTUATOR_SECTIONS = ("cylinder", "rotary")
REQUIRED_SECTIONS = ("cfp", "amplifier", "solenoid", "spool", "valve", "hose")


@dataclass
class JointSpec:
    """One actuated joint: its URDF joint, its component chain and settings."""

    name: str
    dof: str
    components: dict[str, Component]
    settings: JointSettings

    @property
    def kind(self) -> str:
        return "cylinder" if "cylinder" in self.components else "rotary"

    @property
    def actuator_label(self) -> str:
        if self.kind == "cylinder":
            return "cylinder"
        return "hydraulic_motor" if self.components["rotary"]["type"] == "motor" else "rotary_actuator"

    @property
    def sensed(self) -> bool:
        return "sensor" in self.components

    @property
    def command_range(self) -> tuple[float, float]:
        lo, hi = self.components["cfp"]["command_range"]
        return float(lo), float(hi)


@dataclass
class RobotSpec:
    name: str
    description: str
    reference: str
    urdf_path: Path
    tree: KinematicTree
    integrator: Integrator
    fluid: Fluid
    supply: Pump
    joints: list[JointSpec]
    passive: dict[str, JointSettings]
    effects: list[EffectInstance] = field(default_factory=list)
    source: Path | None = None

    # ---- queries --------------------------------------------------------------------------------
    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def sensed_joints(self) -> list[str]:
        return [j.name for j in self.joints if j.sensed]

    def joint(self, name: str) -> JointSpec:
        for j in self.joints:
            if j.name == name:
                return j
        raise SpecError(f"unknown joint {name!r}; joints of {self.name}: {', '.join(self.joint_names)}")

    def copy(self) -> "RobotSpec":
        tree = self.tree
        self.tree = None  # type: ignore[assignment]  # the tree's structure is shared, never mutated
        try:
            out = copy.deepcopy(self)
        finally:
            self.tree = tree
        out.tree = tree
        return out

    # ---- parameter paths --------------------------------------------------------------------------
    def _resolve(self, path: str) -> tuple[Component, str]:
        parts = path.split(".")
        top = parts[0]
        if top in ("supply", "fluid", "integrator") and len(parts) == 2:
            return getattr(self, top), parts[1]
        if top == "joints" and len(parts) == 3:
            return self.joint(parts[1]).settings, parts[2]
        if top == "joints" and len(parts) == 4:
            j = self.joint(parts[1])
            if parts[2] not in j.components:
                raise SpecError(
                    f"{path}: joint {j.name!r} has no {parts[2]!r} section; sections: {', '.join(j.components)}"
                )
            return j.components[parts[2]], parts[3]
        if top == "passive" and len(parts) == 3:
            if parts[1] not in self.passive:
                raise SpecError(f"{path}: {parts[1]!r} is not a passive joint of {self.name} ({', '.join(self.passive) or 'none'})")
            return self.passive[parts[1]], parts[2]
        raise SpecError(
            f"unknown parameter path {path!r}; use supply.<p>, fluid.<p>, integrator.<p>, "
            f"joints.<joint>.<section>.<p>, joints.<joint>.initial_position or passive.<joint>.initial_position"
        )

    def get(self, path: str) -> Any:
        comp, name = self._resolve(path)
        if name not in comp.values:
            raise SpecError(f"{path}: unknown parameter {name!r}; known: {', '.join(comp.values)}")
        return comp.values[name]

    def set(self, path: str, value: Any) -> None:
        comp, name = self._resolve(path)
        try:
            comp.set(name, value)
        except ParameterError as exc:
            raise SpecError(f"{path}: {exc}") from None
        if comp is self.integrator or isinstance(comp, (Cylinder, DirectionalValve, LabviewAdaptation)):
            self.validate_structure()

    def parameters(self) -> dict[str, Any]:
        """Flat {path: value} of every parameter (read endpoints, reports)."""
        out: dict[str, Any] = {}
        for sec in ("supply", "fluid", "integrator"):
            for k, v in getattr(self, sec).values.items():
                out[f"{sec}.{k}"] = v
        for j in self.joints:
            for k, v in j.settings.values.items():
                out[f"joints.{j.name}.{k}"] = v
            for sec, comp in j.components.items():
                for k, v in comp.values.items():
                    out[f"joints.{j.name}.{sec}.{k}"] = v
        for d, s in self.passive.items():
            out[f"passive.{d}.initial_position"] = s["initial_position"]
        return out

    # ---- effects -----------------------------------------------------------------------------
    def enable_effect(self, name: str, joint: str | None = None, **params) -> EffectInstance:
        """Switch an effect on (replacing the same effect on the same joint)."""
        try:
            eff = get_effect(name)
        except KeyError as exc:
            raise SpecError(str(exc.args[0])) from None
        where = f"effect {name}" + (f" on {joint}" if joint else "")
        if eff.scope == "global":
            if joint is not None:
                raise SpecError(f"{where}: {name!r} is a global effect; do not give a joint")
        else:
            if joint is None:
                raise SpecError(f"effect {name}: needs joint=<name> (one of {', '.join(self.joint_names)})")
            js = self.joint(joint)
            if js.kind not in eff.actuators:
                raise SpecError(f"{where}: applies to {', '.join(eff.actuators)} joints; {joint!r} is a {js.kind}")
            if eff.requires_sensor and not js.sensed:
                raise SpecError(f"{where}: joint {joint!r} has no sensor")
        try:
            values = eff.validate(params, where)
        except ParameterError as exc:
            raise SpecError(str(exc)) from None
        inst = EffectInstance(name, joint, values)
        self.effects = [e for e in self.effects if not (e.name == name and e.joint == joint)] + [inst]
        return inst

    def disable_effect(self, name: str, joint: str | None = None) -> bool:
        before = len(self.effects)
        self.effects = [e for e in self.effects if not (e.name == name and e.joint == joint)]
        return len(self.effects) != before

    def apply_overrides(self, data: dict, where: str = "parameter file") -> None:
        """Apply a parameter/effect file: ``[parameters]`` paths and ``[[effects]]`` entries."""
        unknown = sorted(set(data) - {"robot", "parameters", "effects", "diagnosis"})
        if unknown:
            raise SpecError(f"{where}: unknown top-level key(s) {', '.join(unknown)} (robot, parameters, effects)")
        if "robot" in data and data["robot"] != self.name:
            raise SpecError(f"{where}: written for robot {data['robot']!r}, not {self.name!r}")
        params = data.get("parameters", {})
        if not isinstance(params, dict):
            raise SpecError(f"{where}: [parameters] must be a table of path = value")
        for path, value in _flatten(params).items():
            self.set(path, value)
        effects = data.get("effects", [])
        if not isinstance(effects, list):
            raise SpecError(f"{where}: effects must be an array of tables ([[effects]])")
        for i, e in enumerate(effects):
            if not isinstance(e, dict) or "name" not in e:
                raise SpecError(f"{where}: effects[{i}] needs a name")
            e = dict(e)
            name = e.pop("name")
            joint = e.pop("joint", None)
            enabled = e.pop("enabled", True)
            if enabled:
                self.enable_effect(name, joint, **e)
            elif not self.disable_effect(name, joint):
                raise SpecError(f"{where}: effects[{i}]: {name} on {joint} is not enabled, cannot disable it")

    def validate_structure(self) -> None:
        """Cross-component checks (linkage within limits, substep below the output step, ...)."""
        for j in self.joints:
            i = self.tree.index(j.dof)
            if j.kind == "cylinder":
                try:
                    j.components["cylinder"].linkage(self.tree.axis[i], self.tree.lower[i], self.tree.upper[i])
                except ParameterError as exc:
                    raise SpecError(f"joints.{j.name}: {exc}") from None


def _flatten(d: dict, prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, dict):
            out.update(_flatten(v, key))
        else:
            out[key] = v
    return out


def available_robots() -> list[str]:
    return sorted(p.name for p in ROBOTS_DIR.iterdir() if (p / "robot.toml").is_file())


def _robot_file(name_or_path: str | Path) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml" and p.is_file():
        return p.resolve()
    cand = ROBOTS_DIR / str(name_or_path) / "robot.toml"
    if cand.is_file():
        return cand
    raise SpecError(f"unknown robot {str(name_or_path)!r}; built-in robots: {', '.join(available_robots())}")


def _read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: invalid TOML: {exc}") from None


def _compose_arms(data: dict, where: Path) -> dict:
    """Expand ``[[arms]]`` (a robot made of prefixed copies of another spec) into plain tables."""
    out = {k: v for k, v in data.items() if k != "arms"}
    joints: dict = {}
    passive: dict = dict(out.get("passive", {}))
    effects: list = list(out.get("effects", []))
    for i, arm in enumerate(data["arms"]):
        if "spec" not in arm or "prefix" not in arm:
            raise SpecError(f"{where}: arms[{i}] needs spec and prefix")
        sub = _read_toml(_robot_file(arm["spec"]))
        if "arms" in sub:
            sub = _compose_arms(sub, Path(arm["spec"]))
        prefix = arm["prefix"]
        modules = arm.get("cfp_modules", {})
        for sec in ("integrator", "fluid", "supply"):
            out.setdefault(sec, sub.get(sec, {}))
        for jname, jt in sub.get("joints", {}).items():
            merged = _merge(sub.get("defaults", {}), jt)
            if "cfp" in merged:
                cfp = dict(merged["cfp"])
                for key in ("output_a", "output_b", "input"):
                    if cfp.get(key):
                        mod, _, ch = cfp[key].partition("/")
                        cfp[key] = f"{modules.get(mod, mod)}/{ch}"
                merged["cfp"] = cfp
            merged["dof"] = prefix + merged.get("dof", jname)
            if merged.get("payload_frame"):
                merged["payload_frame"] = prefix + merged["payload_frame"]
            joints[prefix + jname] = merged
        for pname, pt in sub.get("passive", {}).items():
            passive[prefix + pname] = pt
        for e in sub.get("effects", []):
            e = dict(e)
            if "joint" in e:
                e["joint"] = prefix + e["joint"]
            effects.append(e)
    out["joints"] = joints
    out["passive"] = passive
    out["effects"] = effects
    out.pop("defaults", None)
    return out


def _merge(defaults: dict, joint: dict) -> dict:
    """Joint table over the [defaults] tables; ``<section> = false`` drops a defaulted section."""
    out = {k: dict(v) for k, v in defaults.items()}
    for k, v in joint.items():
        if isinstance(v, dict):
            out.setdefault(k, {}).update(v)
        elif v is False and k in SECTIONS:
            out.pop(k, None)
        else:
            out[k] = v
    return out


def load_robot(name_or_path: str | Path) -> RobotSpec:
    """Load a built-in robot by name, or a ``robot.toml`` by path."""
    path = _robot_file(name_or_path)
    data = _read_toml(path)
    if "arms" in data:
        data = _compose_arms(data, path)
        defaults: dict = {}
    else:
        defaults = data.get("defaults", {})
    unknown = sorted(set(data) - {"robot", "integrator", "fluid", "supply", "defaults", "joints", "passive", "effects"})
    if unknown:
        raise SpecError(f"{path}: unknown table(s) {', '.join(unknown)}")
    robot = data.get("robot", {})
    for key in ("name", "urdf"):
        if key not in robot:
            raise SpecError(f"{path}: [robot] needs {key}")
    urdf_path = (path.parent / robot["urdf"]).resolve()
    tree = load_urdf(urdf_path)

    def comp(cls, values, where):
        try:
            return cls(values, where)
        except ParameterError as exc:
            raise SpecError(f"{path.name}: {exc}") from None

    joints: list[JointSpec] = []
    for jname, jt in data.get("joints", {}).items():
        merged = _merge(defaults, jt)
        dof = merged.pop("dof", jname)
        if dof not in tree.dof_names:
            raise SpecError(f"{path.name}: joints.{jname}: URDF has no moving joint {dof!r}")
        settings = {k: merged.pop(k) for k in list(merged) if k in ("initial_position", "payload_frame")}
        bad = sorted(set(merged) - set(SECTIONS))
        if bad:
            raise SpecError(f"{path.name}: joints.{jname}: unknown section(s) {', '.join(bad)}; sections: {', '.join(SECTIONS)}")
        acts = [s for s in ACTUATOR_SECTIONS if s in merged]
        if len(acts) != 1:
            raise SpecError(f"{path.name}: joints.{jname}: needs exactly one of [cylinder] or [rotary]")
        missing = [s for s in REQUIRED_SECTIONS if s not in merged]
        if missing:
            raise SpecError(f"{path.name}: joints.{jname}: missing section(s) {', '.join(missing)}")
        comps = {sec: comp(SECTIONS[sec], vals, f"joints.{jname}.{sec}") for sec, vals in merged.items()}
        js = JointSpec(jname, dof, comps, comp(JointSettings, settings, f"joints.{jname}"))
        pf = js.settings["payload_frame"]
        if pf and pf not in tree.link_frames:
            raise SpecError(f"{path.name}: joints.{jname}.payload_frame: no URDF link {pf!r}")
        joints.append(js)
    if not joints:
        raise SpecError(f"{path}: no [joints]")
    driven = {j.dof for j in joints}
    if len(driven) != len(joints):
        raise SpecError(f"{path.name}: two joints drive the same URDF joint")
    passive: dict[str, JointSettings] = {}
    for dof in tree.dof_names:
        if dof in driven:
            continue
        passive[dof] = comp(JointSettings, data.get("passive", {}).get(dof, {}), f"passive.{dof}")
    extra = sorted(set(data.get("passive", {})) - set(passive))
    if extra:
        raise SpecError(f"{path.name}: passive: {', '.join(extra)} are not passive URDF joints")
    spec = RobotSpec(
        name=robot["name"],
        description=robot.get("description", ""),
        reference=robot.get("reference", ""),
        urdf_path=urdf_path,
        tree=tree,
        integrator=comp(Integrator, data.get("integrator", {}), "integrator"),
        fluid=comp(Fluid, data.get("fluid", {}), "fluid"),
        supply=comp(Pump, data.get("supply", {}), "supply"),
        joints=joints,
        passive=passive,
        source=path,
    )
    spec.validate_structure()
    for i, e in enumerate(data.get("effects", [])):
        e = dict(e)
        if "name" not in e:
            raise SpecError(f"{path.name}: effects[{i}] needs a name")
        name = e.pop("name")
        joint = e.pop("joint", None)
        spec.enable_effect(name, joint, **e)
    return spec


def effect_names() -> list[str]:
    return list(EFFECTS)
