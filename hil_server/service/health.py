"""The health document (``/api/v1/health``): is the plant alive, how is the loop doing, and what is
wrong, in words. A dead, stalled or diverged plant is never reported as alive."""

from __future__ import annotations

import time

from ..engine import shared as S


class HealthReport:
    def __init__(self, svc):
        self.svc = svc               # health summarises every part of the service
        self.started = time.time()

    def document(self) -> dict:
        svc = self.svc
        sup = svc.supervisor
        st = svc.block.state
        running = sup.running and bool(st[S.S_ALIVE])
        diverged = svc.faults.diverged is not None
        if not running:
            status = "engine_down"
        elif diverged:
            status = "diverged"
        else:
            status = "ok"
        warnings = list(svc.cfg.warnings)
        if svc.bridge is not None and svc.bridge.transport is not None:
            warnings += list(getattr(svc.bridge.transport, "warnings", []))
        if not running:
            warnings.append(sup.down_message())
        if diverged:
            warnings.append("the plant diverged: valves are held neutral until POST /api/v1/reset")
        eng = sup.engine
        return {
            "status": status,
            "robot": svc.params.spec.name,
            "mode": S.MODES[int(st[S.S_MODE])],
            "rate_hz": svc.cfg.rate_hz,
            "tick": int(st[S.S_TICK]),
            "uptime_s": time.time() - self.started,
            "engine_alive": running and not diverged,
            "engine": sup.describe(),
            "diverged": svc.faults.diverged,
            "realtime_priority": bool(st[S.S_RTPRIO]),
            "realtime_note": eng.info.get("priority_note", "") if eng is not None else "",
            "estop": svc.commands.estopped,
            "can": svc.bridge.describe() if svc.bridge else None,
            "auth_required": bool(svc.cfg.token),
            "insecure": bool(svc.cfg.insecure),
            "warnings": warnings,
        }
