"""A measured record prepared for identification: columns checked against the robot, the split into
estimation and validation data, the initial pose, and the data checks every later step relies on
(sample rate, noise floor, end-stop contact, which joints are excited and measured).

The start pose comes from the record (policy 'auto' or 'data'): a real arm starts wherever it was
left, and a model started elsewhere carries the difference through the whole record as if the
sensor were offset. What the record gives is the first *reading*; the simulation starts at the joint
position the model's sensor (with its gain and offset effects) reads as that value
(:func:`start_position`), so a sensor offset is still a property of the sensor, identified from what
depends on the true pose (gravity load, lever arms, end stops), not from where the record starts.
'spec' (``--initial-pose spec``) starts every joint at the robot's ``initial_position`` instead.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..dataset import Dataset, DatasetError, column_unit, input_matrix
from ..ingest import joint_range, pressure_band
from ..ingest.timegrid import SLOW_RATE_HZ, short_hint, unit_hint
from . import held_at_extreme
from .metrics import fit_ceiling, noise_std

ESTIMATION_SHARE = 0.6      # single record: first 60 % estimation, last 40 % validation
MIN_SAMPLES = 50
MIN_DURATION = 2.0          # s
START_WINDOWS = (0.02, 0.05, 0.1, 0.2, 0.5)   # s: spans the start reading is fitted over (first_reading)
END_STOP_MARGIN = 0.01      # rad (m on a prismatic joint): closer to a joint limit counts as end-stop contact
STILL_SPAN = 10.0           # noise sigmas: a commanded joint whose reading spans less does not move


@dataclass
class Record:
    """One measured record on the robot's joints (time from 0)."""

    source: str
    time: np.ndarray                      # [N] s, starting at 0
    U: np.ndarray                         # [N, n_act] commands (V), every actuated joint
    angles: dict[str, np.ndarray]         # measured angle per sensed joint with a q_ column
    pressures: dict[str, tuple[np.ndarray, np.ndarray]]  # (p_a, p_b) per joint with both columns
    joint_names: list[str]
    excited: list[str]                    # actuated joints whose command moves
    initial_pose: dict[str, float]        # joint -> start angle: a reading (pose_kind 'reading') or the pose
    notes: list[str] = field(default_factory=list)
    pose_kind: str = "reading"            # 'reading': initial_pose holds first readings; 'true': joint positions
    _digest: bytes | None = field(default=None, init=False, repr=False, compare=False)
    _dt: float | None = field(default=None, init=False, repr=False, compare=False)

    def digest(self) -> bytes:
        """A digest of the time grid and the commands: what a simulation on this record reads."""
        if self._digest is None:
            h = hashlib.blake2b(digest_size=16)
            for a in (self.time, self.U):
                h.update(str(a.shape).encode())
                h.update(np.ascontiguousarray(a, dtype=float).tobytes())
            self._digest = h.digest()
        return self._digest

    @property
    def n(self) -> int:
        return self.time.size

    @property
    def rate(self) -> float:
        return 1.0 / self.dt

    @property
    def dt(self) -> float:
        """The median sample interval (s), computed once: every fit's velocity channel asks for it."""
        if self._dt is None:
            self._dt = float(np.median(np.diff(self.time)))
        return self._dt

    @property
    def targets(self) -> list[str]:
        """Joints that are both excited and measured: the ones a discrepancy can be named on."""
        return [j for j in self.excited if j in self.angles]

    @property
    def has_pressures(self) -> bool:
        return any(j in self.pressures for j in self.targets)

    def u(self, joint: str) -> np.ndarray:
        return self.U[:, self.joint_names.index(joint)]

    def head(self, n: int) -> "Record":
        """The first ``n`` samples (estimation part of a single record)."""
        return Record(self.source, self.time[:n], self.U[:n], {k: v[:n] for k, v in self.angles.items()},
                      {k: (a[:n], b[:n]) for k, (a, b) in self.pressures.items()}, self.joint_names,
                      self.excited, self.initial_pose, self.notes, self.pose_kind)

    def tail(self, start: int) -> "Record":
        """The samples from ``start`` on as a record of their own: time from 0 again, the start pose
        each measured joint's reading there (:func:`first_reading`)."""
        t = self.time[start:] - self.time[start]
        angles = {k: v[start:] for k, v in self.angles.items()}
        pose = dict(self.initial_pose)
        pose.update({k: first_reading(t, v)[0] for k, v in angles.items()})
        return Record(self.source, t, self.U[start:], angles,
                      {k: (a[start:], b[start:]) for k, (a, b) in self.pressures.items()}, self.joint_names,
                      self.excited, pose, self.notes, "reading")


@dataclass
class DataCheck:
    """What the checks found, per measured joint (for the report and the decision thresholds)."""

    rate: float
    duration: float
    irregular_sampling: float                  # max/median sample interval
    noise: dict[str, float]                    # rad, white-noise estimate per measured joint
    end_stop_share: dict[str, float]           # share of samples within END_STOP_MARGIN of a limit
    command_saturation_share: dict[str, float]  # share of samples at the command range limits
    initial_pose_source: dict[str, str]        # 'spec' or 'data'
    fit_ceiling: dict[str, float]              # best angle fit a perfect model reaches (noise floor)
    held_at_extreme: dict[str, dict] = field(default_factory=dict)  # held_at_extreme.find per joint
    outside_range: dict[str, float] = field(default_factory=dict)  # share of samples outside the joint's range
    implausible_pressures: dict[str, str] = field(default_factory=dict)  # column -> why no chamber holds it

    def to_dict(self) -> dict:
        return {
            "rate_hz": self.rate, "duration_s": self.duration, "irregular_sampling": self.irregular_sampling,
            "noise_rad": self.noise, "end_stop_share": self.end_stop_share,
            "command_saturation_share": self.command_saturation_share,
            "initial_pose_source": self.initial_pose_source, "fit_ceiling": self.fit_ceiling,
            "held_at_extreme": self.held_at_extreme, "outside_range_share": self.outside_range,
            "implausible_pressures": self.implausible_pressures,
        }


def load_record(path: str | Path, spec, *, initial_pose: str = "auto", label: str | None = None,
                options=None) -> Record:
    """Read a record and check it against ``spec``; errors name the column (and row). ``options``
    (:class:`sim_core.ingest.ReadOptions`) read a log file that is not a dataset (CSV or Parquet) as it
    is; what the reading found (units, time grid, saturation) opens the record's notes."""
    from ..ingest import read_input

    imp = read_input(path, spec, options)
    rec = record_from_dataset(imp.dataset, spec, source=label or str(path), initial_pose=initial_pose)
    rec.notes[:0] = imp.notes
    return rec


def record_from_dataset(ds: Dataset, spec, *, source: str, initial_pose: str = "auto") -> Record:
    where = f"{source}: "
    U = input_matrix(ds, spec, where=where)   # checks time, u_ columns, ranges and unknown columns
    if len(ds) < MIN_SAMPLES:
        raise DatasetError(f"{where}{len(ds)} rows; identification needs at least {MIN_SAMPLES}")
    t = ds.time - ds.time[0]
    period = float(np.median(np.diff(t)))
    if period * SLOW_RATE_HZ > 1.0:
        # before the duration: such a record usually lasts hours, and each simulation of it would too
        raise DatasetError(f"{where}column 'time': a sample every {period:.4g} s ({1.0 / period:.3g} Hz); identification "
                           f"needs at least {SLOW_RATE_HZ:g} Hz (the command is replayed held between samples, and "
                           f"what the model's effects do happens within 0.01-0.1 s); {unit_hint(period)}")
    if t[-1] < MIN_DURATION:
        raise DatasetError(f"{where}column 'time': the record lasts {t[-1]:g} s; identification needs at least {MIN_DURATION:g} s"
                           + short_hint(period, float(t[-1]), MIN_DURATION))
    notes: list[str] = []
    angles: dict[str, np.ndarray] = {}
    for j in spec.joint_names:
        col = f"q_{j}"
        if col not in ds:
            continue
        if not spec.joint(j).sensed:
            notes.append(f"column {col!r} ignored: joint {j} has no sensor in the {spec.name} model")
            continue
        angles[j] = ds[col].copy()
    pressures: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for j in spec.joint_names:
        a, b = f"p_{j}_a", f"p_{j}_b"
        if a in ds and b in ds:
            pressures[j] = (ds[a].copy(), ds[b].copy())
        elif a in ds or b in ds:
            notes.append(f"pressure of joint {j} ignored: needs both {a!r} and {b!r}")
    if not angles:
        sensed = [f"q_{j}" for j in spec.sensed_joints]
        raise DatasetError(f"{where}no measured angle column; expected one of {', '.join(sensed)}")
    excited = [j for a, j in enumerate(spec.joint_names) if np.ptp(U[:, a]) > 1e-6 or np.abs(U[:, a]).max() > 1e-6]
    if not any(j in angles for j in excited):
        if not excited:
            raise DatasetError(f"{where}no joint is commanded: every u_<joint> column is zero or absent")
        raise DatasetError(
            f"{where}the commanded joint(s) {', '.join(excited)} have no measured angle column "
            f"({', '.join('q_' + j for j in excited)})"
        )
    _check_motion(spec, angles, U, excited, where, notes)
    pose = _initial_pose(spec, angles, t, initial_pose, notes)
    return Record(source, t, U, angles, pressures, list(spec.joint_names), excited, pose, notes,
                  "true" if initial_pose == "spec" else "reading")


def reading_span(q: np.ndarray) -> float:
    """How far a reading ranges: its 1st to 99th percentile (a few glitches do not widen it)."""
    return float(np.percentile(q, 99) - np.percentile(q, 1))


def holds_still(q: np.ndarray) -> bool:
    """Whether a reading spans no more than ``STILL_SPAN`` noise sigmas: it never leaves its noise."""
    span = reading_span(q)
    return span == 0.0 or span <= STILL_SPAN * noise_std(q)


def _check_motion(spec, angles, U, excited, where: str, notes: list[str]) -> None:
    """A commanded joint whose reading never leaves its noise (the pump off, the valve unplugged, the
    wrong column mapped) says nothing about the model: noted, and refused when no commanded joint moves."""
    still: dict[str, str] = {}
    for j in excited:
        if j not in angles:
            continue
        q = angles[j]
        if holds_still(q):
            span, sigma = reading_span(q), noise_std(q)
            u = U[:, spec.joint_names.index(j)]
            unit = "m" if spec.tree.is_prismatic(spec.joint(j).dof) else "rad"
            still[j] = (f"q_{j} spans {span:.3g} {unit} (1st to 99th percentile), "
                        f"{span / sigma if sigma > 0 else 0.0:.3g} x its noise, while u_{j} spans {u.min():.4g} .. "
                        f"{u.max():.4g} V")
    if not still:
        return
    what = "; ".join(still.values())
    if all(j in still for j in excited if j in angles):
        raise DatasetError(f"{where}no commanded joint moves ({what}): nothing to identify. Was the pump on and the "
                           f"valve connected, and does the position column hold the joint's position?")
    notes.append(f"commanded but not moving: {what}; the pump, the valve or the column mapping may be at fault")


def _initial_pose(spec, angles, t, policy: str, notes: list[str]) -> dict[str, float]:
    """Where the simulation starts. 'auto' and 'data': the record's first reading of each measured
    joint (:func:`first_reading`; joints without a sensor start at the spec's position); 'spec': the
    robot's initial positions."""
    if policy not in ("auto", "spec", "data"):
        raise ValueError(f"--initial-pose {policy!r}: expected auto, spec or data")
    pose: dict[str, float] = {}
    tree = spec.tree
    for j in spec.joint_names:
        q_spec = float(spec.joint(j).settings["initial_position"])
        pose[j] = q_spec
        if j not in angles or policy == "spec":
            continue
        q_meas, se = first_reading(t, angles[j])
        i = tree.index(spec.joint(j).dof)
        lo, hi = float(tree.lower[i]), float(tree.upper[i])
        # a rig at rest on its end stop starts there (the stop itself, not a margin inside it: on a slide a
        # centimetre is a motion of its own); a reading beyond the stop is clamped to it, and said when it
        # lies further beyond than a stop's contact and the noise explain
        inside = min(max(q_meas, lo), hi) if lo < hi else q_meas
        unit = column_unit(f"q_{j}", spec)
        if abs(inside - q_meas) > END_STOP_MARGIN:
            notes.append(f"{j}: the record starts at {q_meas:.3f} {unit}, outside the joint's range [{lo:.3f}, {hi:.3f}] "
                         f"{unit} (check the units, {unit}, and the sensor calibration); the simulation starts at "
                         f"{inside:.3f}")
        q_meas = inside
        pose[j] = q_meas
        if abs(q_meas - q_spec) > 1e-3:
            notes.append(f"{j}: the record starts at {q_meas:.4f} {unit} (+-{se:.1e} from its first readings), "
                         f"{q_meas - q_spec:+.3f} {unit} from the model's initial position; the simulation starts there")
    return pose


def first_reading(t: np.ndarray, y: np.ndarray, noise: float | None = None) -> tuple[float, float]:
    """The reading at t = 0 and its standard error. Over ever longer START_WINDOWS the lowest-degree
    polynomial (0-2) whose residual is consistent with the sensor noise (chi-square, 3 sigma) is
    fitted; the window grows while its value at t = 0 agrees with the shorter window's (within two
    of its standard errors): a joint at rest averages its noise over up to 0.5 s, a joint that
    starts moving at once keeps the short fit (a long one is biased by the start transient)."""
    y = np.asarray(y, dtype=float)
    s = noise_std(y) if noise is None else noise
    if y.size < 3 or not s > 1e-12 * max(1.0, float(np.max(np.abs(y[:10])))):
        return float(y[0]), 0.0
    tt = t - t[0]
    best: tuple[float, float] | None = None
    for w in START_WINDOWS:
        n = min(y.size, int(np.searchsorted(tt, w, side="right")))
        est = None
        for deg in (0, 1, 2):
            dof = n - deg - 1
            if dof < 2:
                continue
            A = np.vander(tt[:n] / max(tt[n - 1], 1e-12), deg + 1, increasing=True)
            coef, *_ = np.linalg.lstsq(A, y[:n], rcond=None)
            r = y[:n] - A @ coef
            if float(r @ r) / s ** 2 <= dof + 3.0 * math.sqrt(2.0 * dof):
                est = (float(coef[0]), s * math.sqrt(float(np.linalg.inv(A.T @ A)[0, 0])))
                break
        if est is None or (best is not None and abs(est[0] - best[0]) > 2.0 * best[1]):
            break
        if best is None or est[1] < best[1]:
            best = est
        if n >= y.size:
            break
    return best if best is not None else (float(y[0]), s)


def start_position(spec, rec: "Record", joint: str) -> float:
    """The joint position a simulation of ``spec`` starts from on ``rec``: the position its sensor
    reads as the record's first reading (sensor gain and offset effects inverted, y = g q + c), or
    the recorded start pose itself when it is one (pose_kind 'true')."""
    q0 = rec.initial_pose.get(joint)
    if q0 is None:
        return float(spec.joint(joint).settings["initial_position"])
    if rec.pose_kind != "reading" or joint not in rec.angles:
        return float(q0)
    g, c = 1.0, 0.0
    for e in spec.effects:
        if e.joint == joint and e.name == "sensor_gain":
            g = float(e.params["gain"])
        elif e.joint == joint and e.name == "sensor_offset":
            c = float(e.params["offset"])
    return (float(q0) - c) / g


def check_record(rec: Record, spec) -> DataCheck:
    """The checks before anything else (research note §4.0)."""
    d = np.diff(rec.time)
    tree = spec.tree
    noise, stops, sat, src, ceiling, outside = {}, {}, {}, {}, {}, {}
    for j, y in rec.angles.items():
        noise[j] = noise_std(y)
        i = tree.index(spec.joint(j).dof)
        lo, hi = tree.lower[i], tree.upper[i]
        near = np.zeros(y.size, dtype=bool)
        if math.isfinite(lo):
            near |= y < lo + END_STOP_MARGIN
        if math.isfinite(hi):
            near |= y > hi - END_STOP_MARGIN
        stops[j] = float(near.mean())
        outside[j] = joint_range.share(y, lo, hi)
        if outside[j] > 0.0:
            unit = column_unit(f"q_{j}", spec)
            rec.notes.append(f"q_{j}: {100 * outside[j]:.0f} % of the samples lie more than {joint_range.MARGIN:g} {unit} "
                             f"outside the joint's range [{lo:.3f}, {hi:.3f}] {unit}: check the units ({unit}) and the "
                             f"sensor calibration")
        src[j] = "spec" if rec.pose_kind == "true" else "data"
        ceiling[j] = fit_ceiling(y, noise[j])
    held = {}
    for j in rec.excited:
        lo, hi = spec.joint(j).command_range
        u = rec.u(j)
        sat[j] = float(np.mean((u <= lo + 1e-9) | (u >= hi - 1e-9)))
        if j in rec.angles:
            i = tree.index(spec.joint(j).dof)
            found = held_at_extreme.find(rec.time, rec.angles[j], u, noise[j], (lo, hi),
                                         (float(tree.lower[i]), float(tree.upper[i])), END_STOP_MARGIN)
            if found is not None:
                held[j] = found
                rec.notes.append(held_at_extreme.note(j, found, column_unit(f"q_{j}", spec)))
    implausible = {}
    for j, pair in rec.pressures.items():
        for side, p in zip("ab", pair):
            why = pressure_band.implausible(p, spec, pressure_band.alternatives(p, spec, "Pa"))
            if why is not None:
                implausible[f"p_{j}_{side}"] = why
    return DataCheck(rec.rate, float(rec.time[-1]), float(d.max() / np.median(d)), noise, stops, sat, src, ceiling,
                     held, outside, implausible)
