"""Rig templates: a user's hydraulic rig as editable data (``hydrohil rig new``).

A template is two text files in ``templates/<name>/`` (``robot.toml.in``, ``rig.urdf.in``) with
``${...}`` placeholders, plus shared fragments in ``templates/shared/``. The knobs of a template
(:mod:`.knobs`) fill them through :mod:`.derive`; ``--set PATH=VALUE`` then edits any key of the
written robot.toml in place (its comment kept), and the result is loaded (validated) before anything
is written. The [estimated] table lists the parameters a user rarely knows, with the range a
calibration may search, derived from their final values.
"""

from __future__ import annotations

import difflib
import json
import re
import string
import tempfile
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..model.spec import SpecError, estimable, load_robot
from ..model.toml_lines import TomlLines, split_key
from .derive import DERIVE, num, vec
from .knobs import TEMPLATE_KNOBS, Knob, RigError

TEMPLATES_DIR = Path(__file__).resolve().parent / "templates"
TEMPLATES = {
    "cylinder": "a load on a prismatic slide moved by one double-acting cylinder acting directly on it "
                "(vertical, horizontal or inclined)",
    "boom": "a revolute boom raised by a cylinder through its mounting pins (crane / excavator boom)",
    "rotary": "a rotary vane actuator or hydraulic motor turning an arm (an inertia)",
}

# (path with {joint}, rule value -> (lower, upper), what it is): parameters a user rarely knows
ESTIMATED = (
    ("supply.pressure", lambda v: (0.7 * v, 1.15 * v),
     "the pressure that reaches the valve is below the pump setting by line losses"),
    ("joints.{joint}.valve.rated_flow", lambda v: (v / 4.0, 4.0 * v),
     "catalogue flows are nominal; the valve's real gain differs"),
    ("joints.{joint}.sensor.A", lambda v: tuple(sorted((0.9 * v, 1.1 * v))), "sensor gain"),
    ("joints.{joint}.sensor.B", None, "sensor offset: within 10 % of the sensor's span"),
    ("joints.{joint}.{actuator}.viscous_friction", lambda v: (0.0, max(10.0 * v, 1.0)), "seal and bearing friction"),
    ("effects.payload.{joint}.mass", lambda v: (0.5 * v, 2.0 * v + 5.0), "the load"),
)


@dataclass
class Rig:
    """A rendered rig: file names and texts, and the knob values it was drawn from."""

    name: str
    template: str
    toml: str
    urdf_name: str
    urdf: str
    knobs: dict[str, Any]
    warnings: list[str]


def template_knobs(template: str) -> list[Knob]:
    if template not in TEMPLATES:
        raise RigError(f"unknown template {template!r}; templates: {', '.join(TEMPLATES)}")
    return TEMPLATE_KNOBS[template]


def default_name(out: str | Path) -> str:
    base = re.sub(r"[^A-Za-z0-9_]+", "_", Path(out).resolve().name).strip("_") or "rig"
    return base if base[0].isalpha() else f"rig_{base}"


def parse_value(text: str) -> Any:
    """A --set value: a number, a JSON list or bool, or plain text."""
    t = text.strip()
    try:
        return float(t)
    except ValueError:
        pass
    if t[:1] == "[" or t in ("true", "false"):
        try:
            return json.loads(t)
        except json.JSONDecodeError:
            raise RigError(f"cannot parse value {text!r} (a list is written [1.0, 2.0])") from None
    return t


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return num(value)
    if isinstance(value, (list, tuple)):
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            return vec(value)
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return json.dumps(str(value))


def _value_end(line: str, start: int) -> int:
    """Index where the value that starts at ``start`` ends (before its comment)."""
    quote, depth = "", 0
    for i in range(start, len(line)):
        ch = line[i]
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
        elif ch == "#" and depth == 0:
            return i
    return len(line)


def set_key(text: str, path: str, value: Any) -> str:
    """``text`` with ``path`` = ``value``: the value on its line replaced (comment kept), or a new line
    under its table (a new table at the end if there is none)."""
    lines = TomlLines(text)
    parts = split_key(path)
    rows = text.split("\n")
    new = _toml_value(value)
    n = lines.exact(parts)
    if n:
        row = rows[n - 1]
        eq = row.index("=")
        start = eq + 1 + (len(row[eq + 1:]) - len(row[eq + 1:].lstrip()))
        end = _value_end(row, start)
        old = row[start:end]
        pad = " " * max(1, len(old) - len(new)) if end < len(row) else ""
        rows[n - 1] = row[:start] + new + (pad + row[end:].lstrip() if end < len(row) else "")
        return "\n".join(rows)
    table = parts[:-1]
    h = lines.exact(table)
    entry = f"{parts[-1]} = {new}   # set by 'rig new --set'"
    if h:
        rows.insert(h, entry)
        return "\n".join(rows)
    return text.rstrip("\n") + f"\n\n[{'.'.join(table)}]\n{entry}\n"


_ASSIGN_LINE = re.compile(r"^([A-Za-z0-9_\"'.\-]+) = ")


def align_comments(text: str, column: int = 30) -> str:
    """Start every ``key = value  # comment`` line's comment at the same column (after a short value)."""
    rows = []
    for row in text.split("\n"):
        m = _ASSIGN_LINE.match(row)
        if m:
            end = _value_end(row, m.end())
            if end < len(row):
                head = row[:end].rstrip()
                row = head.ljust(column) + "  " + row[end:].lstrip()
        rows.append(row)
    return "\n".join(rows)


def _render_files(template: str, name: str, k: dict, out_hint: str) -> tuple[str, str]:
    tdir = TEMPLATES_DIR / template
    v = {kk: (num(vv) if isinstance(vv, float) else str(vv)) for kk, vv in k.items() if not kk.startswith("_")}
    v.update(DERIVE[template](k))
    urdf_name = f"{name}.urdf"
    v.update(name=name, template=template, urdf=urdf_name, out_hint=out_hint, joint=k["joint"],
             name_toml=json.dumps(name), description_toml=json.dumps(v["title"]))

    def fill(path: Path) -> str:
        try:
            return string.Template(path.read_text()).substitute(v)
        except KeyError as exc:  # a template placeholder without a value: a bug in the template
            raise AssertionError(f"{path}: no value for ${{{exc.args[0]}}}") from None

    v["head"] = fill(TEMPLATES_DIR / "shared" / "head.toml.in").rstrip("\n")
    v["valve_chain"] = fill(TEMPLATES_DIR / "shared" / "valve_chain.toml.in").rstrip("\n")
    return align_comments(fill(tdir / "robot.toml.in")), fill(tdir / "rig.urdf.in")


def _estimated_section(toml_text: str, urdf_text: str, urdf_name: str, joint: str) -> str:
    """The [estimated] table for the final values (ranges derived from them, inside declared bounds)."""
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "robot.toml").write_text(toml_text)
        (Path(tmp) / urdf_name).write_text(urdf_text)
        spec = load_robot(tmp)
    actuator = spec.joint(joint).kind
    rows = ["",
            "# ---- Parameters you probably do not know exactly. The values above are estimates; calibration",
            "# ('hydrohil fit', the baseline of 'hydrohil diagnose') may move each within [lower, upper] (same unit",
            "# as above). Narrow a range when you have measured the value, delete its line to hold it fixed.",
            "# Each line deleted is one number the record no longer has to explain: on a log without chamber",
            "# pressures a Coulomb friction shows only once the supply pressure and the load are measured.",
            "[estimated]"]
    for path, rule, what in ESTIMATED:
        path = path.format(joint=joint, actuator=actuator)
        try:
            param, value = estimable(spec, path)
        except SpecError:
            continue
        if rule is None:  # sensor offset: +-10 % of the span the sensor covers
            a = spec.get(f"joints.{joint}.sensor.A")
            lo_v, hi_v = spec.get(f"joints.{joint}.sensor.range")
            w = 0.1 * abs(a) * (hi_v - lo_v)
            lo, hi = value - w, value + w
        else:
            lo, hi = rule(value)
        lo, hi = max(lo, param.lower), min(hi, param.upper)
        if not lo < hi:
            continue
        unit = param.unit
        if path.startswith(f"joints.{joint}.sensor.") and spec.tree.is_prismatic(spec.joint(joint).dof):
            unit = unit.replace("rad", "m")
        key = json.dumps(path)
        rows.append(f"{key} = [{num(lo)}, {num(hi)}]".ljust(60) + f"  # {unit}; {what}")
    return "\n".join(rows) + "\n"


def render(template: str, out: str | Path, name: str | None = None, sets: list[str] | tuple = ()) -> Rig:
    """Render ``template`` with ``--set`` items ("PATH=VALUE"); raises :class:`RigError`."""
    knobs = template_knobs(template)
    by_name = {kn.name: kn for kn in knobs}
    name = default_name(out) if name is None else name
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name):
        raise RigError(f"--name {name!r}: expected letters, digits and _ (starting with a letter)")
    items: list[tuple[str, Any]] = []
    for item in sets:
        path, eq, val = item.partition("=")
        if not eq or not path.strip():
            raise RigError(f"--set {item!r}: expected PATH=VALUE")
        items.append((path.strip(), parse_value(val)))
    k: dict[str, Any] = {kn.name: kn.default for kn in knobs}
    for path, val in items:               # the joint's name first: key paths contain it
        if path == "joint":
            k["joint"] = by_name["joint"].parse(val)
    joint = k["joint"]
    aliases = {kn.path.format(joint=joint): kn for kn in knobs if kn.path}
    keyed: list[tuple[str, Any]] = []
    for path, val in items:
        kn = by_name.get(path) or aliases.get(path)
        if kn is None:
            keyed.append((path, val))
            continue
        try:
            k[kn.name] = kn.parse(val)
        except RigError as exc:
            raise RigError(f"--set {path}: {exc}") from None
        if kn.name == "incline_deg":
            k["_incline_given"] = True
            if any(p == "orientation" and v != "incline" for p, v in items):
                raise RigError("--set incline_deg and orientation=vertical|horizontal contradict; give one")
    toml_text, urdf_text = _render_files(template, name, k, str(out))
    if keyed:
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / "robot.toml").write_text(toml_text)
            (Path(tmp) / f"{name}.urdf").write_text(urdf_text)
            base = load_robot(tmp)
        valid = base.parameters()
        for path, val in keyed:
            if path not in valid:
                close = difflib.get_close_matches(path, list(valid) + list(by_name), n=1)
                raise RigError(
                    f"--set {path}: not a key of this rig{f' (did you mean {close[0]}?)' if close else ''}. "
                    f"Template knobs: {', '.join(by_name)}. "
                    f"robot.toml keys: {', '.join(valid)}")
            try:
                base.set(path, val)           # names the key, its unit and range on a bad value
            except SpecError as exc:
                raise RigError(f"--set {exc}") from None
            toml_text = set_key(toml_text, path, val)
    try:
        toml_text = toml_text.rstrip("\n") + "\n" + _estimated_section(toml_text, urdf_text, f"{name}.urdf", joint)
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / "robot.toml").write_text(toml_text)
            (Path(tmp) / f"{name}.urdf").write_text(urdf_text)
            spec = load_robot(tmp)
    except SpecError as exc:
        raise RigError(f"the rig would not load: {exc.key + ': ' if exc.key else ''}{exc.message}") from None
    tomllib.loads(toml_text)
    return Rig(name, template, toml_text, f"{name}.urdf", urdf_text,
               {kk: vv for kk, vv in k.items() if not kk.startswith("_")}, capacity_warnings(spec))


def capacity_warnings(spec) -> list[str]:
    """Where the actuator cannot hold the gravity load at full supply pressure somewhere in the joint's
    range (the rig would sag at zero command and cannot lift): one line per joint, naming the numbers."""
    import numpy as np

    from ..plant import Plant

    out = []
    ctx = Plant(spec).create_context(seed=0)
    rb = ctx.rigid_body()                     # masses with the payload on
    z = np.zeros(spec.tree.n)
    for j in spec.joints:
        i = spec.tree.index(j.dof)
        lo, hi = float(spec.tree.lower[i]), float(spec.tree.upper[i])
        qs = np.linspace(lo, hi, 21)
        q = np.array(ctx.q, dtype=float)
        tau = []
        for v in qs:
            q[i] = v
            tau.append(abs(float(rb.inverse_dynamics(q, z, z)[i])))
        tau = np.array(tau)
        supply = spec.get("supply.pressure") - spec.get("supply.tank_pressure")
        if j.kind == "cylinder":
            cyl = j.components["cylinder"]
            arm = np.abs(cyl.arms(spec.tree, i, qs))
            cap = cyl.area_a * supply * arm
            unit = "N" if spec.tree.is_prismatic(i) else "N m"
        else:
            rot = j.components["rotary"]
            cap = np.full_like(qs, rot["displacement"] * rot["gear_ratio"] * supply)
            unit = "N m"
        worst = int(np.argmax(tau / cap))
        need = f"joints.{j.name}: the load needs {tau[worst]:.4g} {unit} at q = {qs[worst]:.3g}"
        fix = "(a larger bore/displacement, a higher supply pressure or a lighter load)"
        if tau[worst] > cap[worst]:
            out.append(f"{need} but the actuator gives at most {cap[worst]:.4g} {unit} at the full supply pressure: "
                       f"it would sag and could not lift it {fix}")
        elif tau[worst] > 0.9 * cap[worst]:
            out.append(f"{need}, {100 * tau[worst] / cap[worst]:.0f} % of the {cap[worst]:.4g} {unit} the actuator gives "
                       f"at the full supply pressure: lifting would crawl {fix}")
    return out


def new_rig(template: str, out: str | Path, name: str | None = None, sets: list[str] | tuple = (),
            force: bool = False) -> tuple[Path, Path, list[str]]:
    """Write ``out/robot.toml`` and ``out/<name>.urdf``; refuses to overwrite unless ``force``.
    Returns both paths and the capacity warnings."""
    out = Path(out)
    rig = render(template, out, name, sets)
    toml_path, urdf_path = out / "robot.toml", out / rig.urdf_name
    if out.exists() and not out.is_dir():
        raise RigError(f"--out {out}: exists and is not a directory")
    existing = [p for p in (toml_path, urdf_path) if p.exists()]
    if existing and not force:
        raise RigError(f"{', '.join(str(p) for p in existing)} already exist(s); use --force to overwrite")
    out.mkdir(parents=True, exist_ok=True)
    toml_path.write_text(rig.toml)
    urdf_path.write_text(rig.urdf)
    return toml_path, urdf_path, rig.warnings


__all__ = ["RigError", "Rig", "TEMPLATES", "new_rig", "render", "template_knobs"]
