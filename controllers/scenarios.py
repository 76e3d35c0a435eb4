"""The closed-loop experiments of issue 6: controllers (what runs in the controller process) and the
metrics computed from their traces.

* ``stick``     Figs. 11-12 and 14 of Papadopoulos et al. (2003): the stick tracks a sinusoidal angle
                command under the joint PID alone (swing and boom held); simulated and emulated
                tracking errors are compared, and the valve-model feedforward computed off-line from
                the recorded run is compared with the PID's voltage command.
* ``cartesian`` Fig. 15: the operator's Cartesian velocity command for a ~5 m path is integrated,
                resolved into joint motions by inverse kinematics and tracked by PID + feedforward.
* ``mars_nd``   MARS-ND: joint-space PID moving every sensed HydroLek joint of both arms through a set
                of targets with an estimated 8 % valve overlap (deadband) switched on, settling
                without limit cycles; the plain PID with the same gains on the same plant shows what
                the deadband does without the measures (it parks off target while its integral
                crawls through the deadband).

Every scenario's controller runs unchanged on a :class:`~.plant_can.CanPlant` (emulated) or a
:class:`~.plant_local.LocalPlant` (simulated).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_core.model.spec import RobotSpec

from .feedforward import JointFeedforward
from .kinematics import HarvesterKinematics
from .pid import PidGains
from .tracking import Controller, JointTracker
from .trajectories import OperatorCommand, Sinusoid, TargetSequence, VelocityStroke, path_length

PLANT_RATE_HZ = 1000.0      # emulator tick (the default --rate)
CONTROL_RATE_HZ = 200.0     # controller period: the paper's 200 Hz data/control rate (Sec. IV-B)


@dataclass
class Scenario:
    name: str
    title: str
    robot: str
    duration: float                          # s: full run (the reproduce command)
    params: dict | None = None               # parameter/effect file contents (--params), or None
    seed: int = 1                            # sensor-noise seed (POST /api/v1/reset)
    plant_rate_hz: float = PLANT_RATE_HZ
    control_rate_hz: float = CONTROL_RATE_HZ
    local_runs: tuple = ("simulated",)       # in-process runs besides the emulated one

    @property
    def ticks(self) -> int:
        """Emulator ticks per control period."""
        return int(round(self.plant_rate_hz / self.control_rate_hz))


# ==== stick: Figs. 11-12, 14 ===========================================================================
STICK_AMPLITUDE = 0.25       # rad: q_d = q0 + A (1 - cos(2 pi t / T)), a 0.5 rad peak-to-peak swing
STICK_PERIOD = 10.0          # s: reversals at 5, 10, 15 s (the paper's hose oscillations near 6 and 16 s)
# Gains tuned in simulation for the nominal pose (as the paper did: "computed for an average
# configuration ... further tuned by simulations"). The stick loop's integral carries the deadband and
# the speed-dependent valve voltage (no feedforward in this experiment); swing and boom only hold.
STICK_GAINS = {"stick": PidGains(kp=70.0, ki=600.0, kd=3.0, tau_d=0.02),
               "swing": PidGains(kp=60.0, ki=30.0, kd=0.0),
               "boom": PidGains(kp=60.0, ki=30.0, kd=0.0)}


class StickController(Controller):
    def __init__(self, spec: RobotSpec, amplitude: float = STICK_AMPLITUDE, period: float = STICK_PERIOD):
        self.spec = spec
        self.tracker = JointTracker(spec, STICK_GAINS, kappa=0.0)   # PID only, "without the feedforward part"
        self.amplitude, self.period = amplitude, period
        self.j = spec.joint_names.index("stick")

    def start(self, obs) -> None:
        self.q0 = obs.angle.copy()
        self.traj = Sinusoid(float(self.q0[self.j]), self.amplitude, self.period)
        self.tracker.start(obs, 0.0)

    def step(self, t, obs) -> dict:
        q_d = self.q0.copy()
        qd_d = np.zeros_like(q_d)
        q_d[self.j], qd_d[self.j] = self.traj(t)
        out = self.tracker.command(t, obs, q_d, qd_d)
        out["q_d"], out["qd_d"] = q_d, qd_d
        return out


def feedforward_prediction(spec: RobotSpec, trace: dict, joint: str) -> np.ndarray:
    """Fig. 14, off-line as in the paper: the feedforward voltage (kappa = 1) of eqs. (19)-(21) from the
    recorded desired speed, desired angle and measured pressures of a run (V per sample)."""
    a = list(trace["joints"]).index(joint)
    ff = JointFeedforward(spec, joint)
    return np.array([ff.voltage(q, qd, pa, pb) for q, qd, pa, pb in
                     zip(trace["q_d"][:, a], trace["qd_d"][:, a], trace["p_a"][:, a], trace["p_b"][:, a])])


def reversal_mask(t: np.ndarray, qd_d: np.ndarray, before: float = 0.5, after: float = 1.0) -> np.ndarray:
    """Samples within [-before, +after] s of a spool reversal: a polarity change of the desired speed,
    or the start of motion from rest (both times the valve command must cross the deadband; the PID
    lags, so the window extends further after)."""
    s = np.sign(qd_d)
    idx = list(np.flatnonzero(s[1:] * s[:-1] < 0) + 1)
    nz = np.flatnonzero(s != 0)
    if len(nz) and (nz[0] > 0 or qd_d[0] == 0.0):
        idx.insert(0, int(nz[0]))       # motion starts from rest
    mask = np.zeros(len(t), dtype=bool)
    for i in idx:
        mask |= (t >= t[i] - before) & (t <= t[i] + after)
    return mask


def analyse_stick(spec: RobotSpec, runs: dict[str, dict]) -> dict:
    a = list(runs["emulated"]["joints"]).index("stick")
    out: dict = {"amplitude_rad": STICK_AMPLITUDE, "period_s": STICK_PERIOD}
    err = {}
    for name, tr in runs.items():
        e = tr["q_d"][:, a] - tr["angle"][:, a]
        err[name] = e
        out[name] = {"rms_error_rad": float(np.sqrt(np.mean(e ** 2))), "max_error_rad": float(np.max(np.abs(e))),
                     "duration_s": float(tr["t"][-1] + (tr["t"][1] - tr["t"][0]))}
    # on the emulated run's time grid (lockstep: the same grid; realtime: the controller's own clock)
    t_em = runs["emulated"]["t"]
    em = err["emulated"]
    si = np.interp(t_em, runs["simulated"]["t"], err["simulated"])
    d = em - si
    out["emulated_vs_simulated"] = {"rms_difference_rad": float(np.sqrt(np.mean(d ** 2))),
                                    "max_difference_rad": float(np.max(np.abs(d))),
                                    "relative_rms": float(np.sqrt(np.mean(d ** 2)) / np.sqrt(np.mean(em ** 2)))}
    if "simulated_quantized" in err:
        dq = em - np.interp(t_em, runs["simulated_quantized"]["t"], err["simulated_quantized"])
        out["emulated_vs_simulated_quantized"] = {"max_difference_rad": float(np.max(np.abs(dq)))}
    # Fig. 14: feedforward alone vs the PID's command on the emulated run
    tr = runs["emulated"]
    u_ff = feedforward_prediction(spec, tr, "stick")
    u = tr["u"][:, a]
    rev = reversal_mask(tr["t"], tr["qd_d"][:, a])
    away = ~rev
    diff = u_ff - u
    out["feedforward"] = {
        "rms_command_v": float(np.sqrt(np.mean(u[away] ** 2))),
        "rms_difference_away_from_reversals_v": float(np.sqrt(np.mean(diff[away] ** 2))),
        "relative_difference_away_from_reversals": float(np.sqrt(np.mean(diff[away] ** 2)) / np.sqrt(np.mean(u[away] ** 2))),
        "rms_difference_at_reversals_v": float(np.sqrt(np.mean(diff[rev] ** 2))) if rev.any() else float("nan"),
        "max_difference_at_reversals_v": float(np.max(np.abs(diff[rev]))) if rev.any() else float("nan"),
        "reversal_windows": int(np.count_nonzero(np.diff(rev.astype(int)) == 1) + int(rev[0])),
    }
    return out


# ==== cartesian: Fig. 15 ===============================================================================
# The operator's joystick strokes (m): pull the head in and up, swing it sideways, then lower it a little
# out to the side - a 3-D path of about 5 m (the paper's path length; its start point was lost).
CARTESIAN_STROKES = (VelocityStroke(0.5, 6.0, (-1.8, 0.0, 1.1)),
                     VelocityStroke(3.5, 7.0, (0.0, 2.4, 0.0)),
                     VelocityStroke(9.0, 5.0, (0.5, 0.3, -0.8)))
CARTESIAN_SETTLE = 1.0       # s after the last stroke (the end point comes to rest)
CARTESIAN_KAPPA = 0.9        # feedforward weight: "less but close to one" (Sec. VI)
CARTESIAN_GAINS = {"swing": PidGains(kp=60.0, ki=100.0, kd=0.0, tau_d=0.02),
                   "boom": PidGains(kp=60.0, ki=100.0, kd=0.0, tau_d=0.02),
                   "stick": PidGains(kp=60.0, ki=100.0, kd=0.0, tau_d=0.02)}


class CartesianController(Controller):
    """Operator velocity -> integrated path -> inverse kinematics -> joint PID + feedforward."""

    def __init__(self, spec: RobotSpec, strokes=CARTESIAN_STROKES, kappa: float = CARTESIAN_KAPPA,
                 gains: dict | None = None):
        self.spec = spec
        self.kin = HarvesterKinematics(spec)
        self.operator = OperatorCommand(list(strokes))
        self.tracker = JointTracker(spec, gains or CARTESIAN_GAINS, kappa=kappa)
        self.idx = [spec.joint_names.index(j) for j in self.kin.dofs]

    def start(self, obs) -> None:
        q = obs.angle[self.idx]
        self.p_d = self.kin.forward(q)           # the path starts where the end point is
        self.v_prev = np.zeros(3)
        self.t_prev = 0.0
        self.tracker.start(obs, 0.0)

    def step(self, t, obs) -> dict:
        v = self.operator.velocity(t)
        self.p_d = self.p_d + 0.5 * (v + self.v_prev) * (t - self.t_prev)   # integrate the velocity command
        self.v_prev, self.t_prev = v, t
        qj = self.kin.inverse(self.p_d)
        qdj = self.kin.joint_rates(qj, v)
        na = len(self.spec.joint_names)
        q_d = np.zeros(na)
        qd_d = np.zeros(na)
        q_d[self.idx], qd_d[self.idx] = qj, qdj
        out = self.tracker.command(t, obs, q_d, qd_d)
        out.update(q_d=q_d, qd_d=qd_d, p_d=self.p_d.copy(), v_cmd=v, p_m=self.kin.forward(obs.angle[self.idx]))
        return out


def analyse_cartesian(spec: RobotSpec, runs: dict[str, dict]) -> dict:
    out: dict = {}
    for name, tr in runs.items():
        e = tr["p_d"] - tr["p_m"]
        length = path_length(tr["p_d"])
        rms = float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))
        joints = list(tr["joints"])
        ej = {j: float(np.sqrt(np.mean((tr["q_d"][:, joints.index(j)] - tr["angle"][:, joints.index(j)]) ** 2)))
              for j in ("swing", "boom", "stick")}
        out[name] = {"path_length_m": length, "rms_error_m": rms,
                     "rms_error_xyz_m": [float(x) for x in np.sqrt(np.mean(e ** 2, axis=0))],
                     "max_error_m": float(np.max(np.linalg.norm(e, axis=1))),
                     "relative_error": rms / length, "rms_joint_error_rad": ej,
                     "start_m": [float(x) for x in tr["p_d"][0]], "end_m": [float(x) for x in tr["p_d"][-1]]}
    return out


# ==== mars_nd: joint-space PID through targets with the valve deadband ================================
MARS_DEADBAND_V = 0.8        # V: estimated spool overlap, 8 % of the 10 V command range (HydroLek valves
                             # are not characterised in the source paper; 5-20 % overlap is typical)
MARS_ARM_JOINTS = ("j1", "j2", "j3", "j4", "j5")                    # sensed (potentiometers)
MARS_OFFSETS = ((0.25, 0.20, -0.25, 0.30, 0.35),                    # rad from the start pose, per target (left
                                                                    # arm; the right arm moves mirrored, -offset)
                (-0.20, 0.35, 0.15, -0.25, -0.30),
                (0.0, 0.0, 0.0, 0.0, 0.0))
MARS_MOVE_TIME = 2.0         # s: quintic transition to each target
MARS_HOLD_TIME = 3.0         # s: hold; the last second of each hold is checked for settling
MARS_SETTLED_RAD = 0.005     # rad: a hold counts as settled when the mean error of its last second is below
                             # this (5 mm at the arm's ~1 m reach), the valve stays closed throughout and
MARS_STILL_RAD = 0.003       # rad: the measured angle's peak-to-peak stays within the sensor noise band
                             # (10 x the 0.3 mrad rms potentiometer noise); a limit cycle must open the
                             # valve and move the joint, so it fails both
# The PID for a valve with overlap (see .pid): deadband compensation w_c = the identified width, ramped
# over 0.2 V, so a correction of 0.16 V / Kp = 1.6 mrad or more opens the valve; the integral runs only
# within 10 mrad of the reference (it trims the last millimetres instead of winding up during a move);
# a settle band of 3 mrad (10x the 0.3 mrad rms sensor noise, about twice the residual dead zone)
# closes the valve once a stationary target is reached, re-engaging beyond 10 mrad. The closed-centre,
# zero-leakage valve then holds the joint: no integrator/deadband limit cycle ("hunting") can start.
MARS_GAINS = PidGains(kp=100.0, ki=50.0, kd=1.0, tau_d=0.02, i_limit=2.0, i_band=0.010,
                      deadband_comp=MARS_DEADBAND_V, comp_ramp=0.2, settle_band=0.003, release_band=0.010)
MARS_PLAIN_GAINS = PidGains(kp=100.0, ki=50.0, kd=1.0, tau_d=0.02)   # the same PID without those measures


def mars_params() -> dict:
    """Parameter/effect file contents for ``hydrohil serve --params``: the overlap deadband on both arms."""
    return {"robot": "mars_nd", "effects": [{"name": "deadband", "joint": f"{arm}_{j}", "width": MARS_DEADBAND_V}
                                            for arm in ("left", "right") for j in MARS_ARM_JOINTS]}


class MarsController(Controller):
    def __init__(self, spec: RobotSpec, gains: PidGains = MARS_GAINS):
        self.spec = spec
        self.arm_joints = [j for j in spec.joint_names if j.split("_", 1)[-1] in MARS_ARM_JOINTS and spec.joint(j).sensed]
        self.tracker = JointTracker(spec, {j: gains for j in self.arm_joints}, kappa=0.0)
        self.idx = [spec.joint_names.index(j) for j in self.arm_joints]

    def start(self, obs) -> None:
        q0 = obs.angle[self.idx]
        sign = np.array([-1.0 if j.startswith("right_") else 1.0 for j in self.arm_joints])
        offs = [sign * np.array([o[MARS_ARM_JOINTS.index(j.split("_", 1)[-1])] for j in self.arm_joints]) for o in MARS_OFFSETS]
        self.seq = TargetSequence(q0, [q0 + o for o in offs], MARS_MOVE_TIME, MARS_HOLD_TIME)
        self.tracker.start(obs, 0.0)

    def step(self, t, obs) -> dict:
        na = len(self.spec.joint_names)
        q_d = np.where(np.isfinite(obs.angle), obs.angle, 0.0)
        qd_d = np.zeros(na)
        qs, qds = self.seq(t)
        q_d[self.idx], qd_d[self.idx] = qs, qds
        out = self.tracker.command(t, obs, q_d, qd_d)
        out["q_d"], out["qd_d"] = q_d, qd_d
        return out


def analyse_mars(spec: RobotSpec, runs: dict[str, dict], check_window: float = 1.0) -> dict:
    """Per hold: final error, peak-to-peak angle and valve openings in the last ``check_window`` s."""
    out: dict = {"deadband_v": MARS_DEADBAND_V}
    joints = list(runs["emulated"]["joints"])
    arm = [j for j in joints if j.split("_", 1)[-1] in MARS_ARM_JOINTS]
    for name, tr in runs.items():
        t = tr["t"]
        holds = []
        for k in range(len(MARS_OFFSETS)):
            t_end = (k + 1) * (MARS_MOVE_TIME + MARS_HOLD_TIME)
            w = (t >= t_end - check_window) & (t < t_end)
            if not w.any():
                continue
            for j in arm:
                a = joints.index(j)
                e = tr["q_d"][w, a] - tr["angle"][w, a]
                u = tr["u_applied"][w, a]
                opens = int(np.count_nonzero(np.diff((np.abs(u) > MARS_DEADBAND_V).astype(int)) == 1))
                holds.append({"target": k, "joint": j, "final_error_rad": float(abs(np.mean(e))),
                              "peak_to_peak_rad": float(np.ptp(tr["angle"][w, a])),
                              "rms_velocity_rad_s": float(np.sqrt(np.mean(tr["velocity"][w, a] ** 2))),
                              "valve_openings": opens, "open_fraction": float(np.mean(np.abs(u) > MARS_DEADBAND_V))})
        out[name] = {"holds": holds,
                     "max_final_error_rad": max(h["final_error_rad"] for h in holds),
                     "max_peak_to_peak_rad": max(h["peak_to_peak_rad"] for h in holds),
                     "max_rms_velocity_rad_s": max(h["rms_velocity_rad_s"] for h in holds),
                     "settled_holds": sum(1 for h in holds if h["final_error_rad"] < MARS_SETTLED_RAD and h["open_fraction"] == 0.0
                                          and h["peak_to_peak_rad"] < MARS_STILL_RAD),
                     "holds_with_valve_activity": sum(1 for h in holds if h["valve_openings"] > 0 or h["open_fraction"] > 0),
                     "n_holds": len(holds)}
    return out


# ==== registry ========================================================================================
SCENARIOS = {
    "stick": Scenario("stick", "Stick sinusoid under joint PID (Figs. 11-12) and feedforward prediction (Fig. 14)",
                      "harvester", duration=20.0, local_runs=("simulated", "simulated_quantized")),
    "cartesian": Scenario("cartesian", "Cartesian end-point motion over a ~5 m path (Fig. 15)", "harvester",
                          duration=max(s.t0 + s.duration for s in CARTESIAN_STROKES) + CARTESIAN_SETTLE,
                          local_runs=("simulated", "pid_only")),
    "mars_nd": Scenario("mars_nd", "MARS-ND joint PID through targets with an 8 % valve deadband", "mars_nd",
                        duration=len(MARS_OFFSETS) * (MARS_MOVE_TIME + MARS_HOLD_TIME), params=mars_params(),
                        local_runs=("simulated", "plain_pid")),
}


def make_controller(scenario: str, spec: RobotSpec, variant: str = "") -> Controller:
    """The scenario's controller; ``variant`` picks a comparison controller of a local run
    (``pid_only``: Cartesian control without the feedforward; ``plain_pid``: MARS-ND PID without the
    deadband measures); any other variant is the scenario's reference controller."""
    if scenario == "stick":
        return StickController(spec)
    if scenario == "cartesian":
        return CartesianController(spec, kappa=0.0 if variant == "pid_only" else CARTESIAN_KAPPA)
    if scenario == "mars_nd":
        return MarsController(spec, MARS_PLAIN_GAINS if variant == "plain_pid" else MARS_GAINS)
    raise KeyError(f"unknown scenario {scenario!r}; scenarios: {', '.join(SCENARIOS)}")


ANALYSE = {"stick": analyse_stick, "cartesian": analyse_cartesian, "mars_nd": analyse_mars}
