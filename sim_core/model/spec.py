"""Robot specifications: URDF (geometry, inertia) + TOML (hydraulics, sensors, effects), as data.

A :class:`RobotSpec` is the full parameter set of one robot. It is validated when loaded and every
change goes through :meth:`RobotSpec.set` / :meth:`RobotSpec.enable_effect`, so a bad value is
reported by its path and never reaches the kernel. Parameter paths::

    supply.pressure                       fluid.bulk_modulus            integrator.max_substep
    links.mass_scale                      joints.<joint>.<section>.<parameter>
    joints.<joint>.initial_position
    passive.<joint>.initial_position

Robot configurations are chosen by name, like python-can interfaces: the built-in ones live in
``sim_core/robots/<name>/robot.toml``; a directory holding a ``robot.toml`` (``hydrohil rig new``
writes one) or the path of a ``robot.toml`` works too (:func:`resolve_robot`, the one resolver every
``--robot`` goes through).

Parameters the user does not know exactly are listed in an optional ``[estimated]`` table, each path
with the range calibration may search, in the parameter's unit (or ``true``: a decade either way)::

    [estimated]
    "supply.pressure" = [9.8e6, 16.1e6]
    "joints.lift.valve.rated_flow" = [5e-5, 8e-4]
    "effects.payload.lift.mass" = [50.0, 205.0]

(nested tables, ``[estimated.joints.lift.valve] rated_flow = [...]``, read the same) and exposed as
``RobotSpec.estimated``. Errors are :class:`SpecError`s that name the file, the line, the key and
what was expected.
"""

from __future__ import annotations

import math
import pickle
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..components import (
    Amplifier, Cylinder, DirectionalValve, Fluid, Hose, LabviewAdaptation, LinkMasses, Potentiometer,
    ProportionalSolenoid, Pump, RotaryActuator, Spool,
)
from ..components.base import Component, Parameter, ParameterError
from ..effects import EFFECTS, EffectInstance, get_effect
from .toml_lines import TomlLines
from .urdf import KinematicTree, UrdfError, load_urdf

ROBOTS_DIR = Path(__file__).resolve().parent.parent / "robots"


class SpecError(ParameterError):
    """The robot specification or a parameter override is invalid.

    ``str(exc)`` reads ``<file>:<line>: <key>: <message>``, each part where known: the file and the
    line (from tomllib for syntax errors, from a scan of the text for the rest) and the parameter
    path or table the message is about.
    """

    def __init__(self, message: str, *, file: str | Path | None = None, line: int | None = None,
                 key: str | None = None):
        self.message, self.file, self.line, self.key = message, file, line, key
        super().__init__(self._format())

    def _format(self) -> str:
        head = ""
        if self.file is not None:
            head = _display_path(self.file) + (f":{self.line}" if self.line else "") + ": "
        if self.key and not self.message.startswith(f"{self.key}:"):
            head += f"{self.key}: "
        return head + self.message

    def __reduce__(self):  # pickles (process pools, Ray) as the formatted message
        return (SpecError, (str(self),))


def _display_path(path: str | Path) -> str:
    """A file path as a user would type it: relative to the working directory when inside it."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except (ValueError, OSError):
        return str(p)


class Integrator(Component):
    """Fixed-step integrator settings of the kernel (see ``sim_core.kernel.skeleton``)."""

    section = "integrator"
    citation = "HydroHIL research note 'performance-measurements' (SIP scheme, step-size study)"
    PARAMETERS = (
        Parameter("max_substep", "s", "largest integrator substep; output steps are split evenly", 1e-4, 1e-6, 1e-2),
        Parameter("rigid_body_refresh", "substeps", "refresh M(q) and the bias every k substeps; 0 = once per output step", 0.0, 0.0, 1000.0),
        Parameter("jacobian_tolerance", "-", "between refreshes, M + h dF/dqd is factored again only when a joint's implicit damping "
                  "term has moved by more than this fraction of its diagonal; 0 = whenever it changed at all (the exact "
                  "linearly implicit scheme)", 0.0, 0.0, 0.1),
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


# the robot-wide sections: one component each, paths <section>.<parameter> (listed in this order)
GLOBAL_SECTIONS = ("supply", "fluid", "integrator", "links")

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
    # parameters the user does not know exactly: path -> (lower, upper) in the parameter's unit (the
    # [estimated] table; calibration may move them within these bounds)
    estimated: dict[str, tuple[float, float]] = field(default_factory=dict)
    links: LinkMasses = field(default_factory=LinkMasses)     # [links]: a factor on the URDF's masses

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
        """A deep copy sharing the kinematic tree (its structure is never mutated). Made by a pickle
        round trip: the same result as copy.deepcopy at half the cost (a diagnosis copies a spec for
        every simulation it runs)."""
        tree = self.tree
        self.tree = None  # type: ignore[assignment]
        try:
            out = pickle.loads(pickle.dumps(self, protocol=pickle.HIGHEST_PROTOCOL))
        finally:
            self.tree = tree
        out.tree = tree
        return out

    # ---- parameter paths --------------------------------------------------------------------------
    def _resolve(self, path: str) -> tuple[Component, str]:
        parts = path.split(".")
        top = parts[0]
        if top in GLOBAL_SECTIONS and len(parts) == 2:
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
            f"unknown parameter path {path!r}; use supply.<p>, fluid.<p>, integrator.<p>, links.<p>, "
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
        for sec in GLOBAL_SECTIONS:
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
                    j.components["cylinder"].check_geometry(self.tree, i)
                except ParameterError as exc:
                    m = _LEADING_KEY.match(str(exc))
                    key, msg = (m.group(1), m.group(2)) if m else (f"joints.{j.name}.cylinder", str(exc))
                    raise SpecError(msg, key=key) from None


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


def resolve_robot(name_or_path: str | Path) -> Path:
    """The ``robot.toml`` that ``--robot`` names: a built-in robot's name, a directory holding a
    ``robot.toml``, or the path of a ``robot.toml`` (any ``.toml`` file). A path that exists wins over
    a built-in name."""
    text = str(name_or_path)
    p = Path(name_or_path).expanduser()
    if p.is_dir():
        if (p / "robot.toml").is_file():
            return (p / "robot.toml").resolve()
        if not (ROBOTS_DIR / text / "robot.toml").is_file():
            tomls = sorted(x.name for x in p.glob("*.toml"))
            hint = f" (it has {', '.join(tomls)}: give the file's path)" if tomls else \
                " ('hydrohil rig new TEMPLATE --out DIR' writes one)"
            raise SpecError(f"directory {text!r} holds no robot.toml{hint}")
    elif p.is_file() and not (p.suffix == "" and (ROBOTS_DIR / text / "robot.toml").is_file()):
        if p.suffix.lower() == ".toml":
            return p.resolve()
        if p.suffix.lower() == ".urdf":
            raise SpecError(f"{text!r} is a URDF; --robot takes the robot.toml beside it (hydraulics, sensors), "
                            f"a directory holding one, or a built-in name ({', '.join(available_robots())})")
        raise SpecError(f"{text!r} is not a robot.toml; --robot takes a built-in name "
                        f"({', '.join(available_robots())}), a directory holding robot.toml, or a robot.toml path")
    cand = ROBOTS_DIR / text / "robot.toml"
    if "/" not in text and "\\" not in text and cand.is_file():
        return cand
    if p.suffix.lower() == ".toml" or "/" in text or "\\" in text:
        raise SpecError(f"unknown robot {text!r}: no such file or directory")
    raise SpecError(f"unknown robot {text!r}; built-in robots: {', '.join(available_robots())} "
                    f"(or a directory holding robot.toml, or a robot.toml path)")


_robot_file = resolve_robot


_TOML_POS = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")


def _read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = _TOML_POS.search(msg)
        line = int(m.group(1)) if m else getattr(exc, "lineno", None)
        if m:
            msg = f"{msg[:m.start()]} (column {m.group(2)})"
        raise SpecError(f"invalid TOML: {msg}", file=path, line=line) from None
    except OSError as exc:
        raise SpecError(f"cannot read: {exc.strerror or exc}", file=path) from None


def _compose_arms(data: dict, where: Path) -> dict:
    """Expand ``[[arms]]`` (a robot made of prefixed copies of another spec) into plain tables."""
    out = {k: v for k, v in data.items() if k != "arms"}
    joints: dict = {}
    passive: dict = dict(out.get("passive", {}))
    effects: list = list(out.get("effects", []))
    for i, arm in enumerate(data["arms"]):
        if "spec" not in arm or "prefix" not in arm:
            raise SpecError(f"{where}: arms[{i}] needs spec and prefix")
        rel = where.parent / str(arm["spec"])          # a path relative to this file, else a name
        sub = _read_toml(resolve_robot(rel if rel.exists() else arm["spec"]))
        if "arms" in sub:
            sub = _compose_arms(sub, Path(arm["spec"]))
        prefix = arm["prefix"]
        modules = arm.get("cfp_modules", {})
        for sec in GLOBAL_SECTIONS:
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


TOP_LEVEL = ("robot", "integrator", "fluid", "supply", "links", "defaults", "joints", "passive", "effects", "estimated")
JOINT_KEYS = ("dof", "initial_position", "payload_frame")
_LEADING_KEY = re.compile(r"^([A-Za-z0-9_\-\[\]]+(?:\.[A-Za-z0-9_\-\[\]]+)*): (.*)$", re.S)
_UNKNOWN = re.compile(r"^unknown parameter\(s\) ([A-Za-z0-9_\-]+)")
_OUTSIDE = re.compile(r"^(-?[0-9.eE+\-]+|inf|-inf) \S+ is outside")

# values written in a common non-SI unit: (unit in the spec, other unit, factor to SI)
_UNIT_SLIPS = {
    "Pa": (("bar", 1e5), ("MPa", 1e6), ("kPa", 1e3), ("psi", 6894.757)),
    "m": (("mm", 1e-3), ("cm", 1e-2)),
    "m^3/s": (("L/min", 1.0 / 60000.0), ("L/s", 1e-3)),
    "m^3": (("cm^3", 1e-6), ("L", 1e-3)),
    "m^3/rad": (("cm^3/rev", 1e-6 / (2 * math.pi)),),
    "rad": (("deg", math.pi / 180.0),),
    "m^2/s": (("cSt (mm^2/s)", 1e-6),),
}


def _unit_hint(param: Parameter | None, value: Any) -> str:
    """' (looks like bar: 140 bar = 1.4e+07 Pa)' when a value out of range fits in another common unit."""
    if param is None or param.kind != "float" or isinstance(value, bool) or not isinstance(value, (int, float)):
        return ""
    for other, factor in _UNIT_SLIPS.get(param.unit, ()):
        si = float(value) * factor
        if param.lower <= si <= param.upper:
            return f" (looks like {other}: {value:g} {other} = {si:.4g} {param.unit})"
    return ""


def _declared(cls: type[Component], name: str) -> Parameter | None:
    for p in cls.PARAMETERS:
        if p.name == name:
            return p
    return None


class _Where:
    """Builds located :class:`SpecError`s for one robot.toml."""

    def __init__(self, path: Path):
        self.path = path
        self.lines = TomlLines.of_file(path)

    def error(self, key: str | None, message: str, *also: str | tuple) -> SpecError:
        line = self.lines.find(*(k for k in (key, *also) if k)) if key or also else None
        return SpecError(message, file=self.path, line=line, key=key)

    def component(self, exc: ParameterError, where: str, cls: type[Component], values: dict,
                  defaults_key: str | None = None) -> SpecError:
        """A component's validation error, its key recovered from the message it starts with."""
        msg = str(exc)
        m = _LEADING_KEY.match(msg)
        key, detail = (m.group(1), m.group(2)) if m else (where, msg)
        u = _UNKNOWN.match(detail)
        if u:
            key = f"{key}.{u.group(1)}"
        name = key[len(where) + 1:] if key.startswith(where + ".") else None
        if name and _OUTSIDE.match(detail):
            detail += _unit_hint(_declared(cls, name), values.get(name))
        also = [f"{defaults_key}.{name}"] if defaults_key and name else []
        return self.error(key, detail, *also, *( [defaults_key] if defaults_key else []))


def _urdf_actuated(urdf_path: Path) -> dict[str, tuple[float, int | None]]:
    """Moving URDF joints whose <limit effort> is above zero (a drive is expected): name -> (effort, line)."""
    import xml.etree.ElementTree as ET

    try:
        text = urdf_path.read_text(encoding="utf-8", errors="replace")
        root = ET.fromstring(text)
    except (OSError, ET.ParseError):
        return {}
    lines = text.splitlines()
    out = {}
    for el in root.iter("joint"):
        if el.get("type") not in ("revolute", "prismatic", "continuous"):
            continue
        lim = el.find("limit")
        try:
            effort = float(lim.get("effort", "0")) if lim is not None else 0.0
        except ValueError:
            effort = 0.0
        if effort > 0.0:
            name = el.get("name", "")
            line = next((i for i, ln in enumerate(lines, 1) if re.search(rf"<joint\b[^>]*name=[\"']{re.escape(name)}[\"']", ln)), None)
            out[name] = (effort, line)
    return out


def load_robot(name_or_path: str | Path) -> RobotSpec:
    """Load a robot: a built-in name, a directory holding ``robot.toml``, or a ``robot.toml`` path.

    Errors are :class:`SpecError`s naming the file, the line, the key and what was expected."""
    path = resolve_robot(name_or_path)
    data = _read_toml(path)
    at = _Where(path)
    if "arms" in data:
        data = _compose_arms(data, path)
        defaults: dict = {}
    else:
        defaults = data.get("defaults", {})
    unknown = sorted(set(data) - set(TOP_LEVEL))
    if unknown:
        raise at.error(unknown[0], f"unknown table(s) {', '.join(unknown)}; known: {', '.join(TOP_LEVEL)}")
    robot = data.get("robot", {})
    for key in ("name", "urdf"):
        if key not in robot:
            raise at.error(f"robot.{key}", f"[robot] needs {key}", "robot")
    urdf_path = (path.parent / robot["urdf"]).resolve()
    if not urdf_path.is_file():
        raise at.error("robot.urdf", f"no such file {_display_path(urdf_path)}")
    try:
        tree = load_urdf(urdf_path)
    except UrdfError as exc:
        raise SpecError(str(exc), file=urdf_path) from None

    def comp(cls, values, where, defaults_key=None):
        try:
            return cls(values, where)
        except ParameterError as exc:
            raise at.component(exc, where, cls, values, defaults_key) from None

    joints: list[JointSpec] = []
    moving = ", ".join(tree.dof_names)
    for jname, jt in data.get("joints", {}).items():
        where = f"joints.{jname}"
        if not isinstance(jt, dict):
            raise at.error(where, f"expected a table [joints.{jname}], got {jt!r}")
        merged = _merge(defaults, jt)
        dof = merged.pop("dof", jname)
        if dof not in tree.dof_names:
            raise at.error(f"{where}.dof" if "dof" in jt else where,
                           f"the URDF ({urdf_path.name}) has no moving joint {dof!r}; its moving joints: {moving}",
                           where)
        settings = {k: merged.pop(k) for k in list(merged) if k in ("initial_position", "payload_frame")}
        bad = sorted(k for k in merged if k not in SECTIONS)
        if bad:
            raise at.error(f"{where}.{bad[0]}", f"unknown key(s) {', '.join(bad)}; known: "
                           f"{', '.join(JOINT_KEYS)} and the sections {', '.join(SECTIONS)}")
        acts = [s for s in ACTUATOR_SECTIONS if s in merged]
        if len(acts) != 1:
            raise at.error(where, "needs exactly one of [cylinder] or [rotary]"
                           + (f" (has {' and '.join(acts)})" if acts else ""))
        missing = [s for s in REQUIRED_SECTIONS if s not in merged]
        if missing:
            raise at.error(where, f"missing section(s) {', '.join(missing)} (give them here or under [defaults])")
        comps = {sec: comp(SECTIONS[sec], vals, f"{where}.{sec}", f"defaults.{sec}") for sec, vals in merged.items()}
        js = JointSpec(jname, dof, comps, comp(JointSettings, settings, where))
        pf = js.settings["payload_frame"]
        if pf and pf not in tree.link_frames:
            raise at.error(f"{where}.payload_frame", f"no URDF link {pf!r}")
        joints.append(js)
    if not joints:
        raise at.error("joints", "no [joints]: a robot needs at least one actuated joint")
    driven = {j.dof for j in joints}
    if len(driven) != len(joints):
        dup = next(d for d in driven if sum(j.dof == d for j in joints) > 1)
        names = [j.name for j in joints if j.dof == dup]
        raise at.error(f"joints.{names[1]}", f"drives URDF joint {dup!r} as joints.{names[0]} does")
    passive_table = data.get("passive", {})
    extra = sorted(set(passive_table) - (set(tree.dof_names) - driven))
    if extra:
        raise at.error(f"passive.{extra[0]}", f"{', '.join(extra)}: not passive moving joints of the URDF "
                       f"(passive ones: {', '.join(d for d in tree.dof_names if d not in driven) or 'none'})")
    for name, (effort, line) in _urdf_actuated(urdf_path).items():
        if name in tree.dof_names and name not in driven and name not in passive_table:
            raise SpecError(f"has effort {effort:g} (a driven joint) but {path.name} has no [joints.{name}] "
                            f"(its actuator, valve, sensor); add one, or [passive.{name}] if nothing drives it "
                            f"(or set its effort to 0)", file=urdf_path, line=line, key=f"joint {name!r}")
    passive: dict[str, JointSettings] = {}
    for dof in tree.dof_names:
        if dof in driven:
            continue
        passive[dof] = comp(JointSettings, passive_table.get(dof, {}), f"passive.{dof}")
    spec = RobotSpec(
        name=robot["name"],
        description=robot.get("description", ""),
        reference=robot.get("reference", ""),
        urdf_path=urdf_path,
        tree=tree,
        integrator=comp(Integrator, data.get("integrator", {}), "integrator"),
        fluid=comp(Fluid, data.get("fluid", {}), "fluid"),
        supply=comp(Pump, data.get("supply", {}), "supply"),
        links=comp(LinkMasses, data.get("links", {}), "links"),
        joints=joints,
        passive=passive,
        source=path,
    )
    try:
        spec.validate_structure()
    except SpecError as exc:
        raise at.error(exc.key, exc.message) from None
    effects = data.get("effects", [])
    if not isinstance(effects, list):
        raise at.error("effects", "expected an array of tables [[effects]]")
    for i, e in enumerate(effects):
        e = dict(e)
        key = f"effects[{i}]"
        if "name" not in e:
            raise SpecError("needs a name", file=path, line=at.lines.find(("effects", str(i))), key=key)
        name = e.pop("name")
        joint = e.pop("joint", None)
        try:
            spec.enable_effect(name, joint, **e)
        except SpecError as exc:
            pkey = next((k for k in e if f".{k}:" in exc.message or f" {k}:" in exc.message), None)
            line = at.lines.find(("effects", str(i), pkey) if pkey else ("effects", str(i)))
            raise SpecError(exc.message, file=path, line=line, key=f"{key}.{pkey}" if pkey else key) from None
    spec.estimated = _estimated(spec, data.get("estimated", {}), at)
    return spec


def _estimated(spec: RobotSpec, table: Any, at: _Where) -> dict[str, tuple[float, float]]:
    """The ``[estimated]`` table: parameter path -> (lower, upper) in the parameter's unit."""
    if not isinstance(table, dict):
        raise at.error("estimated", 'expected a table of "path" = [lower, upper]')
    out: dict[str, tuple[float, float]] = {}
    for key, rng in _flatten(table).items():
        def fail(msg, key=key):
            line = at.lines.find(("estimated", key), ("estimated", *key.split(".")), "estimated")
            return SpecError(msg, file=at.path, line=line, key=f'estimated."{key}"' if "." in key else f"estimated.{key}")
        if rng is True:                   # estimated, no range given: a decade either way (or +-max(|v|, 1))
            try:
                param, value = estimable(spec, key)
            except SpecError as exc:
                raise fail(exc.message) from None
            if value > 0 and param.lower >= 0:
                rng = [max(param.lower, value / 10.0), min(param.upper, value * 10.0)]
            else:
                w = max(abs(value), 1.0)
                rng = [max(param.lower, value - w), min(param.upper, value + w)]
        if (not isinstance(rng, list) or len(rng) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in rng)):
            raise fail(f"expected [lower, upper] (two finite numbers) or true, got {rng!r}")
        lo, hi = float(rng[0]), float(rng[1])
        if not lo < hi:
            raise fail(f"lower {lo:g} must be below upper {hi:g}")
        try:
            param, value = estimable(spec, key)
        except SpecError as exc:
            raise fail(exc.message) from None
        unit = estimated_unit(spec, key)
        if lo < param.lower or hi > param.upper:
            raise fail(f"[{lo:g}, {hi:g}] {unit} leaves the parameter's bounds [{param.lower:g}, {param.upper:g}] {unit}")
        if not lo <= value <= hi:
            raise fail(f"the value {value:g} {unit} lies outside its estimated range [{lo:g}, {hi:g}] {unit}")
        out[key] = (lo, hi)
    return out


# units declared for a revolute joint that read differently on a prismatic one (referred to the joint)
_PRISMATIC = {"rad": "m", "rad/V": "m/V", "rad/s": "m/s", "N m": "N", "N m s/rad": "N s/m"}


def joint_unit(unit: str, prismatic: bool, joint_referred: bool = True) -> str:
    """A declared unit resolved to the joint's kind: 'N m or N' -> the first (revolute) or second
    (prismatic); a revolute unit of a joint-referred parameter (sensor, initial position) -> its linear one."""
    kinds = unit.split(" or ")
    if len(kinds) == 2:
        return kinds[1] if prismatic else kinds[0]
    return _PRISMATIC.get(unit, unit) if prismatic and joint_referred else unit


def estimated_unit(spec: RobotSpec, key: str) -> str:
    """The unit of an estimable parameter path as its joint reads it (m/V for a prismatic joint's sensor gain)."""
    param, _ = estimable(spec, key)
    parts = key.split(".")
    joint = parts[1] if parts[0] == "joints" else parts[2] if parts[0] == "effects" and len(parts) == 4 else None
    if joint is None or joint not in spec.joint_names:
        return param.unit
    prismatic = spec.tree.is_prismatic(spec.joint(joint).dof)
    referred = parts[0] == "effects" or parts[2] == "sensor" or len(parts) == 3
    return joint_unit(param.unit, prismatic, referred)


def estimable(spec: RobotSpec, key: str) -> tuple[Parameter, float]:
    """(declared parameter, current value) of a scalar parameter path: a spec path
    (``joints.lift.valve.rated_flow``) or an enabled effect's parameter
    (``effects.<effect>.<joint>.<parameter>``, ``effects.<effect>.<parameter>`` for a global one)."""
    parts = key.split(".")
    if parts[0] == "effects":
        if len(parts) not in (3, 4):
            raise SpecError("expected effects.<effect>.<joint>.<parameter> or effects.<effect>.<parameter>")
        joint = parts[2] if len(parts) == 4 else None
        inst = next((e for e in spec.effects if e.name == parts[1] and e.joint == joint), None)
        if inst is None:
            on = [f"effects.{e.name}.{e.joint}" if e.joint else f"effects.{e.name}" for e in spec.effects]
            raise SpecError(f"no such effect enabled in [[effects]] (enabled: {', '.join(on) or 'none'})")
        param = next((p for p in EFFECTS[parts[1]].PARAMETERS if p.name == parts[-1]), None)
        if param is None or parts[-1] not in inst.params:
            raise SpecError(f"{parts[1]} has no parameter {parts[-1]!r}; known: "
                            f"{', '.join(p.name for p in EFFECTS[parts[1]].PARAMETERS)}")
        value = inst.params[parts[-1]]
    else:
        comp, name = spec._resolve(key)
        param = _declared(type(comp), name)
        if param is None:
            raise SpecError(f"unknown parameter {name!r}; known: {', '.join(comp.values)}")
        value = comp.values[name]
    if param.kind != "float":
        raise SpecError(f"not a number parameter ({param.kind}): only numbers can be estimated")
    return param, float(value)


def effect_names() -> list[str]:
    return list(EFFECTS)
