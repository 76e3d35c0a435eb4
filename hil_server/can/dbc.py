"""The CAN database. The shipped ``dbc/<robot>.dbc`` files are the single source of truth for
frames: the bridge encodes and decodes with them (cantools), and so do controllers. They were
written by :func:`generate_dbc`; a test keeps the files and the robots' joint lists in step.

Conventions borrowed from hydraulic valve electronics:
* CiA 301/408: SYNC (0x080) advances the plant in lockstep mode; EMCY (0x080 + node) reports faults
  (error codes in :data:`EMCY_CODES`, 0x0000 error reset); heartbeat 0x700 + node with the NMT state
  (0 boot-up once after an engine restart, 4 stopped while the engine is down, 5 operational, 127
  pre-operational while paused).
* J1939: a command that stops arriving puts the valve in its safe (neutral) state; the command's
  ``counter`` is an alive (message) counter that must step by one per frame; faults carry a
  DM1-style SPN (proprietary range 520192 + joint index) and FMI (9 abnormal update rate, 2 erratic,
  3 above range, 12 bad device, 19 received network data in error, 31 condition exists) with an
  occurrence count.
"""

from __future__ import annotations

from pathlib import Path

DBC_DIR = Path(__file__).resolve().parent / "dbc"

NODE_ID = 0x10
ID_SYNC = 0x080
ID_EMCY = 0x080 + NODE_ID
ID_STATUS = 0x101
ID_ENGINE = 0x102
ID_HEARTBEAT = 0x700 + NODE_ID
BASE_COMMAND = 0x200
BASE_FEEDBACK = 0x180
BASE_PRESSURE = 0x280
MAX_JOINTS = 32

EMCY_RESET = 0x0000
EMCY_TIMEOUT = 0x8250
EMCY_LENGTH = 0x8210
EMCY_HARDWARE = 0x5000
EMCY_RANGE = 0xFF01
EMCY_ENGINE_DIED = 0x6100
EMCY_ENGINE_STALLED = 0x6101
EMCY_DIVERGED = 0xFF02
EMCY_CAN_OVERRUN = 0x8110
EMCY_ALIVE_COUNTER = 0x8200
SPN_BASE = 520192
FMI_TIMEOUT, FMI_ERRATIC, FMI_ABOVE, FMI_BAD_DEVICE, FMI_NETWORK_DATA, FMI_CONDITION = 9, 2, 3, 12, 19, 31

# every EMCY error code this node sends, with its FMI and meaning (README, DBC comment)
EMCY_CODES = {
    EMCY_TIMEOUT: (FMI_TIMEOUT, "command timeout: no ValveCommand within --watchdog-ms, valve neutral (joint)"),
    EMCY_LENGTH: (FMI_ERRATIC, "ValveCommand with a wrong DLC, ignored (joint)"),
    EMCY_RANGE: (FMI_ABOVE, "ValveCommand outside the joint's command range, ignored (joint)"),
    EMCY_ALIVE_COUNTER: (FMI_NETWORK_DATA, "ValveCommand alive counter stuck or jumping past the limit: "
                                           "frames treated as lost until the counter steps again (joint)"),
    EMCY_CAN_OVERRUN: (FMI_CONDITION, "frames on one CAN id beyond its budget dropped (flood; joint 0xFF)"),
    EMCY_HARDWARE: (FMI_BAD_DEVICE, "injected fault active (joint, or 0xFF for the supply)"),
    EMCY_DIVERGED: (FMI_ERRATIC, "plant diverged: valves held neutral until reset (joint 0xFF)"),
    EMCY_ENGINE_DIED: (FMI_BAD_DEVICE, "engine process died: feedback stopped, NMT stopped (joint 0xFF)"),
    EMCY_ENGINE_STALLED: (FMI_TIMEOUT, "engine loop stalled and was killed: feedback stopped, NMT stopped "
                                       "(joint 0xFF)"),
}

STATUS_WATCHDOG, STATUS_FAULT, STATUS_ESTOP, STATUS_NOT_SENSED = 1, 2, 4, 8
HIL_OK, HIL_WATCHDOG, HIL_FAULT, HIL_ESTOP, HIL_ENGINE_DOWN, HIL_DIVERGED = range(6)
ENGINE_RUNNING, ENGINE_RESTARTING, ENGINE_DOWN, ENGINE_STOPPED = range(4)
NMT_BOOT_UP, NMT_STOPPED, NMT_OPERATIONAL, NMT_PRE_OPERATIONAL = 0, 4, 5, 127


def dbc_path(robot: str) -> Path:
    p = DBC_DIR / f"{robot}.dbc"
    if not p.is_file():
        known = ", ".join(sorted(x.stem for x in DBC_DIR.glob("*.dbc")))
        raise FileNotFoundError(f"no CAN database for robot {robot!r}; databases: {known}")
    return p


def load_database(robot: str):
    import cantools

    return cantools.database.load_file(str(dbc_path(robot)))


def database_text(spec) -> str:
    """The CAN database of a loaded robot spec: the shipped file of a built-in robot, generated from
    the spec's joints for any other (a user's rig from 'hydrohil rig new')."""
    from sim_core.model.spec import ROBOTS_DIR

    shipped = DBC_DIR / f"{spec.name}.dbc"
    builtin = spec.source is not None and Path(spec.source).parent.parent == ROBOTS_DIR
    if builtin and shipped.is_file():
        return shipped.read_text()
    jtype = spec.tree.jtype
    prismatic = [jtype is not None and int(jtype[spec.tree.index(j.dof)]) == 1 for j in spec.joints]
    return generate_dbc(spec.name, spec.joint_names, [j.sensed for j in spec.joints],
                        [j.command_range for j in spec.joints], prismatic)


def load_database_for(spec):
    import cantools

    return cantools.database.load_string(database_text(spec), database_format="dbc")


def generate_dbc(robot: str, joints: list[str], sensed: list[bool], ranges: list[tuple[float, float]],
                 prismatic: list[bool] | None = None) -> str:
    """DBC text for a robot with these actuated joints (used to write the shipped files). A prismatic
    joint's ``angle`` and ``velocity`` signals carry m and m/s (same names, scaling and ranges)."""
    if len(joints) > MAX_JOINTS:
        raise ValueError(f"at most {MAX_JOINTS} joints")
    out = [
        'VERSION "HydroHIL 1"',
        "",
        "NS_ :",
        "    CM_",
        "    BA_DEF_",
        "    BA_",
        "    VAL_",
        "",
        "BS_:",
        "",
        "BU_: HIL CONTROLLER",
        "",
        f"BO_ {ID_SYNC} Sync: 1 CONTROLLER",
        ' SG_ counter : 0|8@1+ (1,0) [0|255] "" HIL',
        "",
        f"BO_ {ID_EMCY} Emergency: 8 HIL",
        ' SG_ error_code : 0|16@1+ (1,0) [0|65535] "" CONTROLLER',
        ' SG_ error_register : 16|8@1+ (1,0) [0|255] "" CONTROLLER',
        ' SG_ joint : 24|8@1+ (1,0) [0|255] "" CONTROLLER',
        ' SG_ spn : 32|19@1+ (1,0) [0|524287] "" CONTROLLER',
        ' SG_ fmi : 51|5@1+ (1,0) [0|31] "" CONTROLLER',
        ' SG_ occurrence : 56|8@1+ (1,0) [0|255] "" CONTROLLER',
        "",
        f"BO_ {ID_STATUS} HilStatus: 8 HIL",
        ' SG_ mode : 0|8@1+ (1,0) [0|3] "" CONTROLLER',
        ' SG_ state : 8|8@1+ (1,0) [0|5] "" CONTROLLER',
        ' SG_ watchdog_mask : 16|32@1+ (1,0) [0|4294967295] "" CONTROLLER',
        ' SG_ tick : 48|16@1+ (1,0) [0|65535] "" CONTROLLER',
        "",
        f"BO_ {ID_ENGINE} EngineStatus: 8 HIL",
        ' SG_ engine_state : 0|8@1+ (1,0) [0|3] "" CONTROLLER',
        ' SG_ restarts : 8|16@1+ (1,0) [0|65535] "" CONTROLLER',
        ' SG_ error_code : 24|16@1+ (1,0) [0|65535] "" CONTROLLER',
        ' SG_ diverged : 40|8@1+ (1,0) [0|1] "" CONTROLLER',
        "",
        f"BO_ {ID_HEARTBEAT} Heartbeat: 1 HIL",
        ' SG_ nmt_state : 0|8@1+ (1,0) [0|127] "" CONTROLLER',
        "",
    ]
    for a, j in enumerate(joints):
        lo, hi = ranges[a]
        pos_unit, vel_unit = ("m", "m/s") if prismatic and prismatic[a] else ("rad", "rad/s")
        out += [
            f"BO_ {BASE_COMMAND + a} ValveCommand_{j}: 4 CONTROLLER",
            f' SG_ voltage : 0|16@1- (0.001,0) [{lo:g}|{hi:g}] "V" HIL',
            ' SG_ counter : 16|8@1+ (1,0) [0|255] "" HIL',
            "",
            f"BO_ {BASE_FEEDBACK + a} JointFeedback_{j}: 8 HIL",
            f' SG_ angle : 0|16@1- (0.0001,0) [-3.2767|3.2767] "{pos_unit}" CONTROLLER',
            ' SG_ sensor_voltage : 16|16@1+ (0.0002,0) [0|13.107] "V" CONTROLLER',
            f' SG_ velocity : 32|16@1- (0.001,0) [-32.767|32.767] "{vel_unit}" CONTROLLER',
            ' SG_ status : 48|8@1+ (1,0) [0|255] "" CONTROLLER',
            ' SG_ counter : 56|8@1+ (1,0) [0|255] "" CONTROLLER',
            "",
            f"BO_ {BASE_PRESSURE + a} JointPressure_{j}: 8 HIL",
            ' SG_ pressure_a : 0|16@1+ (1000,0) [0|65535000] "Pa" CONTROLLER',
            ' SG_ pressure_b : 16|16@1+ (1000,0) [0|65535000] "Pa" CONTROLLER',
            f' SG_ command_voltage : 32|16@1- (0.001,0) [{lo:g}|{hi:g}] "V" CONTROLLER',
            ' SG_ spool : 48|8@1- (0.01,0) [-1.28|1.27] "" CONTROLLER',
            ' SG_ counter : 56|8@1+ (1,0) [0|255] "" CONTROLLER',
            "",
        ]
    codes = "; ".join(f"0x{c:04X} {text} (FMI {fmi})" for c, (fmi, text) in EMCY_CODES.items())
    out += [
        f'CM_ "HydroHIL CAN database for robot {robot}. Node id 0x{NODE_ID:02X}. SYNC advances the plant in lockstep mode. '
        'Angles for joints without a sensor and sensor_voltage are sent as not available (0x7FFF / 0xFFFF) with status '
        'bit 8. While the engine is down no JointFeedback/JointPressure is sent, the heartbeat says stopped and '
        'HilStatus.state says engine_down.";',
        f'CM_ BO_ {ID_SYNC} "CiA 301 SYNC: in lockstep mode each SYNC advances the plant by one tick and triggers feedback.";',
        f'CM_ BO_ {ID_EMCY} "CiA 301 EMCY with a J1939 DM1-style SPN/FMI; sent when a fault starts and with error_code 0 '
        f'when it clears. Error codes: {codes}; 0x0000 reset.";',
        f'CM_ BO_ {ID_HEARTBEAT} "CiA 301 heartbeat, 1 Hz: 0 boot-up (once, after an engine restart), 4 stopped (engine '
        'down), 5 operational, 127 pre-operational (paused).";',
        f'CM_ BO_ {ID_ENGINE} "Engine supervision, 10 Hz: state (0 running, 1 restarting, 2 down, 3 stopped), restarts so '
        'far, EMCY code of the last engine failure, diverged flag.";',
        f'CM_ SG_ {ID_STATUS} watchdog_mask "Bit a set: joint a (actuated joint order) is held neutral by the command watchdog.";',
    ]
    for a, j in enumerate(joints):
        out.append(f'CM_ BO_ {BASE_COMMAND + a} "Command voltage of joint {j} (LabVIEW Lab_out). Without a new command within the '
                   'watchdog timeout the valve goes neutral; the next command recovers it. DLC must be 4.";')
        out.append(f'CM_ SG_ {BASE_COMMAND + a} counter "Alive counter (J1939/CiA): add 1 (mod 256) with every frame of '
                   'this joint. A repeated (stuck) or jumping counter is counted; past --alive-counter-limit errors in a '
                   'row (default 3) frames are treated as lost (no watchdog refresh: the valve goes neutral, EMCY '
                   '0x8200) until the counter steps by one again.";')
        out.append(f'CM_ BO_ {BASE_FEEDBACK + a} "Measured angle (A*raw+B) and potentiometer voltage of joint {j}{"" if sensed[a] else " (no sensor: not available)"}.";')
    out += [
        f"VAL_ {ID_STATUS} mode 0 \"realtime\" 1 \"paused\" 2 \"lockstep\" 3 \"fast\" ;",
        f"VAL_ {ID_STATUS} state 0 \"ok\" 1 \"watchdog\" 2 \"fault\" 3 \"estop\" 4 \"engine_down\" 5 \"diverged\" ;",
        f"VAL_ {ID_ENGINE} engine_state 0 \"running\" 1 \"restarting\" 2 \"down\" 3 \"stopped\" ;",
        f"VAL_ {ID_HEARTBEAT} nmt_state 0 \"boot_up\" 4 \"stopped\" 5 \"operational\" 127 \"pre_operational\" ;",
        "",
    ]
    return "\n".join(out)
