"""Declared column layout of the flat arrays the compiled kernel works on.

The plant is lowered (like Drake's Context) into a few dense float64 arrays so that one numba call
advances everything without Python in the loop:

* ``AP[n_act, AP_N]``  actuator parameters (command chain, valve, actuator, hose, sensor, effects,
  faults); effect switches are stored as 0.0/1.0.
* ``DP[n_dof, DP_N]``  per-joint mechanical parameters (limits, end stops, damping).
* ``GP[GP_N]``         global parameters (supply, fluid, integrator settings).
* ``XS[n_act, XS_N]``  actuator state;  ``XQ[2, n_dof]`` joint positions and velocities;
  ``XG[XG_N]`` global state (time, supply node, energy ledger).
* ``YA[.., n_act, YA_N]`` per-actuator outputs of each output step.

Nobody numbers columns by hand: each component and effect declares the columns it owns, with a
unit and a description, when its module is imported (``AP.declare("deadband", col("DB_WIDTH", "V",
...))``); the declaration hands back the indices, which the owner binds to module-level names so
numba freezes them into the compiled code. The names are also published here as ``AP_DB_WIDTH``
etc. for code outside the owner (tests, the HIL engine). :func:`check` verifies that every table's
columns are unique and contiguous; :func:`fingerprint` changes whenever any column moves, and is
part of the compiled kernel's cache key (see ``kernel.compose``).
"""

from __future__ import annotations

import hashlib
import importlib
import sys
from dataclasses import dataclass


@dataclass(frozen=True)
class Column:
    """One named column (or a block of ``size`` columns) of a kernel array."""

    table: str
    owner: str          # the component or effect that declared it
    symbol: str         # constant name without the table prefix, e.g. 'P_A'
    unit: str
    doc: str
    index: int
    size: int = 1
    ode: bool = False   # a continuous state the reference solver integrates
    atol: float = 0.0   # its absolute tolerance there

    @property
    def name(self) -> str:
        return f"{self.table}_{self.symbol}"


@dataclass(frozen=True)
class ColumnSpec:
    symbol: str
    unit: str
    doc: str
    size: int = 1
    ode: bool = False
    atol: float = 0.0


def col(symbol: str, unit: str, doc: str, size: int = 1, *, ode: bool = False, atol: float = 0.0) -> ColumnSpec:
    """A column to declare: ``symbol`` becomes ``<TABLE>_<symbol>`` in this module."""
    return ColumnSpec(symbol, unit, doc, size, ode, atol)


class LayoutError(RuntimeError):
    """Two owners declared the same column, or a table has holes."""


class Table:
    """The columns of one kernel array, in declaration order."""

    def __init__(self, key: str, rows: str, doc: str):
        self.key = key
        self.rows = rows
        self.doc = doc
        self.columns: list[Column] = []
        self._size = 0

    @property
    def N(self) -> int:
        return self._size

    def declare(self, owner: str, *specs: ColumnSpec) -> tuple[int, ...] | int:
        """Append ``specs`` as ``owner``'s columns; returns their first indices (one int for one spec)."""
        out = []
        module = sys.modules[__name__]
        for s in specs:
            name = f"{self.key}_{s.symbol}"
            if any(c.symbol == s.symbol for c in self.columns):
                prev = next(c for c in self.columns if c.symbol == s.symbol)
                raise LayoutError(f"{name}: declared by {prev.owner!r} and again by {owner!r}")
            c = Column(self.key, owner, s.symbol, s.unit, s.doc, self._size, s.size, s.ode, s.atol)
            self.columns.append(c)
            self._size += s.size
            setattr(module, name, c.index)
            setattr(module, f"{self.key}_N", self._size)
            out.append(c.index)
        return out[0] if len(out) == 1 else tuple(out)

    def column(self, symbol: str) -> Column:
        for c in self.columns:
            if c.symbol == symbol:
                return c
        raise KeyError(f"{self.key} has no column {symbol!r}")

    def owned_by(self, owner: str) -> list[Column]:
        return [c for c in self.columns if c.owner == owner]


_FINGERPRINT: list = [None, ""]  # (the tables and their column counts when hashed, the hash)

AP = Table("AP", "actuator", "actuator parameters (command chain, valve, actuator, hose, sensor, effects, faults)")
DP = Table("DP", "joint", "per-joint mechanical parameters")
GP = Table("GP", "global", "global parameters (supply, fluid, integrator)")
XS = Table("XS", "actuator", "actuator state")
XG = Table("XG", "global", "global state (time, supply node, energy ledger)")
YA = Table("YA", "actuator", "per-actuator outputs of one output step")
TABLES = (AP, DP, GP, XS, XG, YA)
AP_N = DP_N = GP_N = XS_N = XG_N = YA_N = 0

# kernel-wide error codes in XG[XG_ERROR]
ERR_NAN = 1
ERR_DELAY_OVERRUN = 2

# --- columns owned by the kernel itself (time, bookkeeping, integrator settings, outputs) ---------
XG.declare(
    "kernel",
    col("TIME", "s", "simulated time"),
    col("ERROR", "-", "kernel error code (0 ok): 1 NaN, 2 delay line overrun"),
    col("STEPS", "-", "substeps taken"),
    col("HIST_COUNT", "-", "command events written to the delay line"),
    col("FACTORS", "-", "factorisations of M + h dF/dqd (at refreshes, and where the implicit damping moved)"),
)
GP.declare(
    "kernel",
    col("ENERGY", "-", "1.0: keep the energy ledger (costs ~10 %)"),
    col("H_MAX", "s", "largest integrator substep"),
    col("RB_EVERY", "-", "refresh M(q) and bias every k substeps (0: once per output step)"),
    col("JAC_TOL", "-", "refactor M + h dF/dqd between refreshes when a diagonal damping term moves by this fraction"),
)
AP.declare(
    "kernel",
    col("KIND", "-", "actuator kind id (registered actuator components)"),
    col("DOF", "-", "index of the driven joint in the kinematic tree"),
    col("U_MIN", "V", "command range"),
    col("U_MAX", "V", "command range"),
)
XS.declare(
    "kernel",
    col("U_EFF", "V", "effective command after delay/hysteresis/deadband, last substep"),
)
XG.declare(
    "energy",
    col("E_SUPPLY", "J", "energy ledger: hydraulic energy delivered by the pump"),
    col("E_TANK", "J", "hydraulic energy returned to tank (p_T Q)"),
    col("E_VALVE", "J", "dissipated in metering edges"),
    col("E_HOSE", "J", "dissipated in hose resistance"),
    col("E_LEAK", "J", "dissipated by leakage, reliefs and fault leaks"),
    col("E_MECH", "J", "dissipated by damping, friction and end-stop damping"),
    col("E_RELIEF_PUMP", "J", "pump-side relief and compensator spill"),
    col("E_ACT", "J", "work done by the actuators on the links (hydraulic -> mechanical)"),
    col("E_COMPRESS", "J", "second-order term of the constant-beta continuity equation, int p^2/(2 beta) dV"),
)
YA.declare(
    "kernel",
    col("U", "V", "commanded voltage"),
    col("SENS_V", "V", "sensor voltage"),
    col("ANGLE", "rad or m", "measured (calibrated) joint position"),
    col("P_A", "Pa", "chamber A pressure"),
    col("P_B", "Pa", "chamber B pressure"),
    col("SPOOL", "-", "spool position (stroke fraction)"),
    col("Q_A", "m^3/s", "valve flow into line A"),
)


def _load_owners() -> None:
    """Import every component and effect, so that all columns are declared."""
    importlib.import_module("sim_core.components")
    importlib.import_module("sim_core.effects")


def __getattr__(name: str):
    # a column constant asked for before its owner was imported: import the owners, then look again
    if name.split("_", 1)[0] in {t.key for t in TABLES}:
        _load_owners()
        mod = sys.modules[__name__]
        if name in mod.__dict__:
            return mod.__dict__[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def check() -> None:
    """Every table: symbols unique, columns contiguous from 0 without overlap."""
    _load_owners()
    for t in TABLES:
        seen = set()
        pos = 0
        for c in t.columns:
            if c.symbol in seen:
                raise LayoutError(f"{t.key}: {c.symbol} declared twice")
            seen.add(c.symbol)
            if c.index != pos:
                raise LayoutError(f"{t.key}_{c.symbol}: index {c.index}, expected {pos} (hole or overlap)")
            pos += c.size
        if pos != t.N:
            raise LayoutError(f"{t.key}: {t.N} columns counted, {pos} declared")


def fingerprint() -> str:
    """Changes whenever any column of any table is added, moved or resized. Columns are only ever
    appended (frozen, never removed), so the hash is kept until the next declaration (or another set
    of tables): every simulation asks for it (``kernel.compose.kernel``), and hashing every column
    anew cost about 0.15 ms, 1-2 % of a simulation of a 60 s, 50 Hz record."""
    _load_owners()
    state = (TABLES, tuple(len(t.columns) for t in TABLES))
    if _FINGERPRINT[0] == state:
        return _FINGERPRINT[1]
    h = hashlib.sha256()
    for t in TABLES:
        for c in t.columns:
            h.update(f"{c.name}:{c.index}:{c.size}:{int(c.ode)};".encode())
    _FINGERPRINT[:] = [state, h.hexdigest()[:16]]
    return _FINGERPRINT[1]


def describe() -> list[dict]:
    """Every column with its owner, unit and meaning (documentation, ``hydrohil`` introspection)."""
    _load_owners()
    return [{"table": c.table, "name": c.name, "index": c.index, "size": c.size, "unit": c.unit,
             "owner": c.owner, "doc": c.doc} for t in TABLES for c in t.columns]
