"""Faults: the ones an operator injects (sensor stuck/noisy/offset, spool stuck, leak, hose burst,
supply sag) and the one the plant raises itself, ``diverged``.

``diverged`` is latched by the engine after several rollbacks in a row (the simulator rejected the
state as non-finite): valves neutral, the plant held at its last finite state. It is listed with the
other faults, it cannot be cleared by DELETE (only ``POST /api/v1/reset`` clears it, after the
offending parameters were fixed), and it is logged with those parameters and the state."""

from __future__ import annotations

import json
import logging
import threading

from ..engine import shared as S
from .config import ServiceError
from .engine_calls import engine_call

log = logging.getLogger("hydrohil.faults")

DIVERGED = "diverged"


class FaultTable:
    def __init__(self, mirror, engine, block: S.SharedBlock):
        self.mirror = mirror
        self.engine = engine
        self.block = block
        self.active: dict[str, dict] = {}       # injected faults by id
        self.diverged: dict | None = None       # the latched diverged fault, or None
        self._lock = threading.Lock()

    def listing(self) -> list[dict]:
        out = list(self.active.values())
        if self.diverged is not None:
            out.append(self.diverged)
        return out

    def inject(self, kind: str, joint: str | None, params: dict) -> dict:
        spec = self.mirror.spec
        key = f"{kind}:{joint or 'supply'}"
        if kind != "supply_sag":
            if joint not in spec.joint_names:
                raise ServiceError(f"fault {kind}: unknown joint {joint!r}; joints: {', '.join(spec.joint_names)}")
            if kind.startswith("sensor_") and not spec.joint(joint).sensed:
                raise ServiceError(f"fault {kind}: joint {joint} has no sensor")
        elif joint is not None:
            raise ServiceError("supply_sag acts on the whole supply; do not give a joint")
        engine_call(self.engine, "set_fault", joint, kind, params)
        fault = {"id": key, "kind": kind, "joint": joint, "params": params, "since": float(self.block.state[S.S_TIME])}
        with self._lock:
            self.active[key] = fault
        return fault

    def clear(self, fid: str) -> dict:
        if fid == DIVERGED and self.diverged is not None:
            raise ServiceError("the diverged fault is cleared by POST /api/v1/reset (fix the parameters first)", 409)
        fault = self.active.get(fid)
        if fault is None:
            raise ServiceError(f"no active fault {fid!r}", 404)
        engine_call(self.engine, "clear_fault", fault["joint"], fault["kind"])
        with self._lock:
            self.active.pop(fid, None)
        return fault

    def clear_all(self) -> None:
        engine_call(self.engine, "clear_faults")
        with self._lock:
            self.active.clear()

    # ---- events ---------------------------------------------------------------------------------
    def forget_injected(self) -> None:
        """A restarted engine has none of the injected faults."""
        with self._lock:
            self.active.clear()
            self.diverged = None

    def latch_diverged(self, info: dict) -> dict:
        changed = self.mirror.changed_from_defaults()
        fault = {"id": DIVERGED, "kind": DIVERGED, "joint": None, "since": info.get("time"),
                 "params": {"reason": info.get("reason", ""), "rollbacks": info.get("rollbacks")},
                 "parameters_changed": changed}
        with self._lock:
            self.diverged = fault
        log.error("plant diverged at t = %.6f s (tick %s) after %s rollbacks in a row: %s; valves held neutral "
                  "until POST /api/v1/reset. Parameters that differ from the built-in %s: %s. Last finite state: "
                  "q = %s, qd = %s, p_a = %s, p_b = %s, commands = %s",
                  info.get("time", float("nan")), info.get("tick"), info.get("rollbacks"), info.get("reason"),
                  self.mirror.spec.name, json.dumps(changed, default=str), json.dumps(info.get("q")),
                  json.dumps(info.get("qd")), json.dumps(info.get("pressure_a")), json.dumps(info.get("pressure_b")),
                  json.dumps(info.get("command")))
        return fault

    def clear_diverged(self) -> None:
        with self._lock:
            self.diverged = None
