"""The operator panel (viser GUI): per-joint command sliders with a neutral button, E-STOP, readouts
with units, live plots of command and angle history, fault/watchdog indicators, loop health and the
connection state.

Threads: GUI callbacks run in viser's threads and only call the link (microseconds in-process; a
queued, coalesced HTTP request for a remote server). :meth:`OperatorPanel.update` runs in the viewer's
render thread at a few Hz and only assigns GUI values (viser sends just what changed).

Who may command: a browser the Origin guard accepted (:mod:`.origin_guard`), through a link that can
command (a remote server's token), and, when the viewer is bound beyond loopback, only after that
browser entered the token (a field of its own, never shown to other browsers). Everyone else sees a
read-only panel; E-STOP can be engaged from any accepted browser (stopping is always allowed),
released only by one that may command.

Safety rules:
* E-STOP engages the service's latched stop (every valve at 0 V until released), zeroes and disables
  the sliders; a slider cannot command while the stop is engaged.
* Dead man: when the last browser disconnects, every joint this panel set to a non-zero command is
  put back to neutral (0 V), so a closed tab or a lost network does not leave a valve open.
* A slider follows the plant's command when another source (REST, CAN) changes it, except for a
  second after the operator moved it.
"""

from __future__ import annotations

import html
import logging
import secrets
import threading
import time

import numpy as np

from .colors import legend_html
from .history import History
from .links import LinkError

log = logging.getLogger("hydrohil.web")

STEP_V = 0.05          # slider resolution (V)
HOLD_OFF_S = 1.0       # a slider the operator touched is not re-synchronised from the plant for this long
PLOT_WINDOW_S = 10.0


def _badge(text: str, colour: str) -> str:
    return (f"<span style='background:{colour};color:white;border-radius:4px;padding:0 5px;"
            f"font-weight:600'>{html.escape(text)}</span>")


def _fmt(v, spec: str, none: str = "—") -> str:
    return none if v is None else format(v, spec)


class OperatorPanel:
    def __init__(self, server, link, *, scene=None, render_rate_hz: float = 40.0, guard=None, needs_token: bool = False):
        self.server = server
        self.scene = scene
        self.link = link
        self.guard = guard
        self.needs_token = needs_token
        self._unlocked: set = set()            # client ids that entered the token
        spec = link.spec
        self.joints = list(spec.joint_names)
        self.ranges = {j: spec.joint(j).command_range for j in self.joints}
        self.kinds = {j: spec.joint(j).kind for j in self.joints}
        self.sensed = {j: spec.joint(j).sensed for j in self.joints}
        self.p_supply = float(spec.supply["pressure"])
        self.history = History(self.joints, [spec.joint(j).dof for j in self.joints],
                               int(PLOT_WINDOW_S * render_rate_hz) + 1)
        self._lock = threading.Lock()
        self._command_lock = threading.Lock()   # slider read + send, one at a time
        self._touched: dict[str, float] = {}
        self._known: dict[str, float] = {}    # each slider's value (V) as the panel last set, sent or saw it
        self._held: dict[str, float] = {}     # joints this panel commands away from neutral
        self._estop = False
        self._last_plot = 0.0
        self.updates = 0
        self.notifications: list[str] = []     # what the panel told the operator (tests read it)
        gui = server.gui
        gui.configure_theme(control_width="large", show_share_button=False, brand_color=(230, 160, 20))

        self.status = gui.add_html("<i>connecting…</i>")
        self.estop_button = gui.add_button("E-STOP", color="red", icon="alert-octagon",
                                           hint="every valve to 0 V (latched until released)")
        self.release_button = gui.add_button("Release E-STOP", color="gray", icon="lock-open", disabled=True)
        self.neutral_all = gui.add_button("All neutral", icon="player-stop", hint="every joint to 0 V")
        if not link.can_command:
            gui.add_html("<div style='color:#b00;font-size:0.85em;padding:0 0.5em'>Read-only: the server needs a "
                         "token for commands (hydrohil view --token T).</div>")
        elif needs_token:
            gui.add_html("<div style='color:#b00;font-size:0.85em;padding:0 0.5em'>This monitor is reachable beyond "
                         "loopback: it is read-only until this browser enters the token (below).</div>")
        self.warnings = gui.add_html("")
        tabs = gui.add_tab_group()
        self.sliders, self.neutral_buttons, self.readouts = {}, {}, {}
        with tabs.add_tab("Joints", icon="adjustments"):
            many = len(self.joints) > 8
            for k, j in enumerate(self.joints):
                lo, hi = self.ranges[j]
                label = f"{j} · {self.kinds[j]}" + ("" if self.sensed[j] else " · unsensed")
                with gui.add_folder(label, expand_by_default=not many or k < len(self.joints) // 2):
                    s = gui.add_slider("command (V)", min=lo, max=hi, step=STEP_V, initial_value=0.0,
                                       marks=((lo, f"{lo:g}"), (0.0, "0"), (hi, f"{hi:g}")),
                                       disabled=not link.can_command, hint=f"valve command of {j}, {lo:g}..{hi:g} V")
                    b = gui.add_button(f"Neutral {j}", icon="player-pause", disabled=not link.can_command,
                                       hint="this valve to 0 V")
                    r = gui.add_html("")
                self.sliders[j], self.neutral_buttons[j], self.readouts[j] = s, b, r
                s.on_update(self._slider_cb(j))
                b.on_click(self._neutral_cb(j))
        with tabs.add_tab("Plots", icon="chart-line"):
            self.plot_joint = gui.add_dropdown("joint", options=self.joints, initial_value=self.joints[0])
            # A strip chart: x is plant time relative to the newest sample, on a fixed [-10 s, 0] axis.
            # (With an auto x axis viser keeps the window relative to the data, and a plot that is
            # updated while its tab is hidden can end up looking at an old window.)
            empty = (np.zeros(0), np.zeros(0), np.zeros(0))
            v_lo = min(r[0] for r in self.ranges.values())
            v_hi = max(r[1] for r in self.ranges.values())
            self.plot_command = gui.add_uplot(
                empty, series=({"label": "t − now (s)"},
                               {"label": "requested (V)", "stroke": "#1f77b4", "width": 1.5, "scale": "V"},
                               {"label": "applied (V)", "stroke": "#d62728", "width": 1.5, "scale": "V"}),
                title="command (V)",
                scales={"x": {"time": False, "range": [-PLOT_WINDOW_S, 0.0]},
                        "V": {"auto": False, "range": [v_lo, v_hi]}},
                axes=({}, {"scale": "V", "size": 50}), aspect=2.0)
            self.plot_angle = gui.add_uplot(
                empty, series=({"label": "t − now (s)"},
                               {"label": "measured (°)", "stroke": "#2ca02c", "width": 1.5, "scale": "deg"},
                               {"label": "true (°)", "stroke": "#555555", "width": 1.0, "scale": "deg"}),
                title="angle (°)",
                scales={"x": {"time": False, "range": [-PLOT_WINDOW_S, 0.0]}, "deg": {"auto": True}},
                axes=({}, {"scale": "deg", "size": 50}), aspect=2.0)
            self.plot_joint.on_update(lambda _ev: self._update_plots(force=True))
        with tabs.add_tab("Health", icon="heart-rate-monitor"):
            self.health = gui.add_html("")
            self.faults = gui.add_html("")
        gui.add_html(legend_html(self.p_supply))
        with gui.add_folder("Display", expand_by_default=False):
            self.show_links = gui.add_checkbox("links", initial_value=True)
            self.show_actuators = gui.add_checkbox("cylinders and motors", initial_value=True)
        if scene is not None:
            self.show_links.on_update(lambda _ev: scene.set_visible(links=self.show_links.value))
            self.show_actuators.on_update(lambda _ev: scene.set_visible(actuators=self.show_actuators.value))
        self.estop_button.on_click(self._on_estop)
        self.release_button.on_click(self._on_release)
        self.neutral_all.on_click(self._on_neutral_all)
        self.link.errors.append(self.notify)
        server.on_client_disconnect(self._on_disconnect)
        if needs_token and link.can_command:
            server.on_client_connect(self._offer_token)

    # ---- who may command ---------------------------------------------------------------------------
    def _accepted(self, client) -> bool:
        return client is None or self.guard is None or self.guard.allowed(client.client_id)

    def may_command(self, client) -> bool:
        if not (self.link.can_command and self._accepted(client)):
            return False
        return not self.needs_token or client is None or client.client_id in self._unlocked

    def _refuse(self, client) -> bool:
        """True (and the operator told why) when ``client`` may not command."""
        if self.may_command(client):
            return False
        if not self._accepted(client):
            return True   # a foreign page: no word back
        why = ("read-only: enter the token first (this monitor is reachable beyond loopback)" if self.link.can_command
               else "read-only: the server needs a token for commands (hydrohil view --token T)")
        self.notify(why, client=client)
        return True

    def _offer_token(self, client) -> None:
        """A token field and an unlock button for this browser only."""
        field = client.gui.add_text("Token", initial_value="", hint="the server's token: unlocks commands here")
        button = client.gui.add_button("Unlock commands", icon="lock-open")

        def unlock(_ev):
            given = str(field.value or "")
            token = self.link.token or ""
            if token and given and secrets.compare_digest(given.encode(), token.encode()):
                self._unlocked.add(client.client_id)
                field.value = ""
                self.notify("commands unlocked in this browser", client=client, colour="green")
            else:
                self.notify("wrong token", client=client)

        button.on_click(unlock)

    # ---- operator actions ----------------------------------------------------------------------------
    def notify(self, body: str, title: str = "HydroHIL", client=None, colour: str = "red") -> None:
        self.notifications = self.notifications[-49:] + [body]
        targets = [client] if client is not None else list(self.server.get_clients().values())
        for c in targets:
            try:
                c.add_notification(title=title, body=body, auto_close_seconds=6.0, color=colour)
            except Exception:  # noqa: BLE001 - a client that just left
                pass

    def _slider_cb(self, j: str):
        def cb(ev):
            if ev.client is None:  # the panel itself set the value (sync, E-STOP): not an operator command
                return
            if self._refuse(ev.client):
                self._known[j] = float(self.sliders[j].value)   # seen: the sync puts it back
                return
            with self._lock:   # before the command goes out: a state read earlier must not undo it
                self._touched[j] = time.monotonic()
            # callbacks run on a thread pool: reading the slider and sending its value happen under one
            # lock, so the last command sent is the slider's last value (an earlier callback that read
            # an older value cannot overtake it)
            with self._command_lock:
                v = float(self.sliders[j].value)
                self._known[j] = v
                if self._estop:
                    self._set_slider(j, 0.0)
                    self.notify("E-STOP is engaged: release it before commanding.", client=ev.client)
                    return
                try:
                    self.link.set_voltages({j: v})
                except (LinkError, ValueError) as exc:
                    self.notify(str(exc), client=ev.client)
                    return
            with self._lock:   # and again once it went out: a state read while it was on its way predates it
                self._touched[j] = time.monotonic()
                if v != 0.0:
                    self._held[j] = v
                else:
                    self._held.pop(j, None)
        return cb

    def _neutral_cb(self, j: str):
        def cb(ev):
            if self._refuse(ev.client):
                return
            try:
                self.link.neutral([j])
            except (LinkError, ValueError) as exc:
                self.notify(str(exc), client=ev.client)
                return
            with self._lock:
                self._touched[j] = time.monotonic()
                self._held.pop(j, None)
            self._set_slider(j, 0.0)
        return cb

    def _on_estop(self, ev) -> None:
        if not self._accepted(ev.client):
            return
        try:
            self.link.set_estop(True)
        except LinkError as exc:
            self.notify(f"E-STOP NOT ENGAGED: {exc}", client=ev.client)
            return
        self._apply_estop(True)
        log.warning("viewer: E-STOP engaged from the browser")

    def _on_release(self, ev) -> None:
        if self._refuse(ev.client):
            return
        try:
            self.link.set_estop(False)
        except LinkError as exc:
            self.notify(str(exc), client=ev.client)
            return
        self._apply_estop(False)

    def _on_neutral_all(self, ev) -> None:
        if self._refuse(ev.client):
            return
        try:
            self.link.neutral(None)
        except (LinkError, ValueError) as exc:
            self.notify(str(exc), client=ev.client)
            return
        with self._lock:
            self._held.clear()
            now = time.monotonic()
            self._touched = {j: now for j in self.joints}
        for j in self.joints:
            self._set_slider(j, 0.0)

    def _on_disconnect(self, client) -> None:
        self._unlocked.discard(getattr(client, "client_id", None))
        if self.server.get_clients():
            return
        with self._lock:
            held, self._held = list(self._held), {}
        if held and self.link.can_command:
            try:
                self.link.neutral(held)
                log.warning("viewer: last browser left; neutral on %s (dead man)", ", ".join(held))
            except (LinkError, ValueError) as exc:
                log.error("viewer: dead-man neutral failed: %s", exc)
            for j in held:
                self._set_slider(j, 0.0)

    def _set_slider(self, j: str, v: float) -> None:
        lo, hi = self.ranges[j]
        self._known[j] = float(np.clip(round(v / STEP_V) * STEP_V, lo, hi))
        self.sliders[j].value = self._known[j]

    def _apply_estop(self, on: bool) -> None:
        if on == self._estop:
            return
        self._estop = on
        if on:
            with self._lock:
                self._held.clear()
            for j in self.joints:
                self._set_slider(j, 0.0)
        can = self.link.can_command
        for j in self.joints:
            self.sliders[j].disabled = on or not can
        self.release_button.disabled = not on
        self.release_button.color = "green" if on else "gray"

    # ---- periodic refresh (viewer thread) --------------------------------------------------------------
    def record(self, state: dict) -> None:
        """Every rendered state goes into the plot history (cheap; called at the render rate)."""
        self.history.add(state)

    def update(self, state: dict | None, link_status: dict, viewer_stats: dict,
               fetched_at: float | None = None) -> None:
        """``fetched_at``: time.monotonic() when ``state`` was read (default: now)."""
        with self.server.atomic():
            self._update(state, link_status, viewer_stats, time.monotonic() if fetched_at is None else fetched_at)

    def _update(self, state: dict | None, link_status: dict, viewer_stats: dict, fetched_at: float) -> None:
        self.updates += 1
        if state is not None:
            self._apply_estop(bool(state.get("estop")))
            self._sync_sliders(state, fetched_at)
            for j in self.joints:
                self.readouts[j].content = self._readout(j, state["joints"].get(j, {}))
            self.faults.content = self._faults_html(state)
            self.health.content = self._health_html(state, link_status, viewer_stats)
        self.status.content = self._status_html(state, link_status)
        self.warnings.content = self._warnings_html(link_status)
        self._update_plots()

    def _sync_sliders(self, state: dict, fetched_at: float) -> None:
        """Follow the plant's command, unless the operator touched the slider less than HOLD_OFF_S
        before the state was read (or after: a state read before a touch predates its command). A
        slider holding a value the panel neither set nor sent is such a touch: viser stores the
        browser's new value before the slider callback runs on its thread pool, and putting the slider
        back in between would make that callback send the old command (a callback that never comes
        leaves the slider to the plant's command once the hold-off is over)."""
        for j in self.joints:
            js = state["joints"].get(j)
            if not js or js.get("source") == "viewer" and self.link.kind == "local":
                continue
            value = self.sliders[j].value
            with self._lock:
                if abs(value - self._known.get(j, 0.0)) > STEP_V / 2:
                    self._known[j] = value
                    self._touched[j] = time.monotonic()
                if fetched_at - self._touched.get(j, -1e9) < HOLD_OFF_S:
                    continue
            req = float(js.get("requested_voltage", 0.0))
            if abs(value - req) > STEP_V / 2:
                self._set_slider(j, req)

    def _update_plots(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last_plot < 0.25:
            return
        self._last_plot = now
        t, v = self.history.series(self.plot_joint.value)
        if t.size:
            t = t - t[-1]
        self.plot_command.data = (t, v[0], v[1])
        self.plot_angle.data = (t, np.degrees(v[2]), np.degrees(v[3]))

    # ---- HTML ---------------------------------------------------------------------------------------
    def _readout(self, j: str, js: dict) -> str:
        ang = js.get("angle")
        sv = js.get("sensor_voltage")
        pa, pb = js.get("pressure_a"), js.get("pressure_b")
        src = js.get("source", "none")
        wd = _badge("WATCHDOG", "#c0392b") if js.get("watchdog") else ""
        sensor = f"{sv:.3f} V" if sv is not None else "unsensed"
        return (
            "<div style='font-size:0.82em;line-height:1.35;padding:0 0.5em;font-variant-numeric:tabular-nums'>"
            f"angle <b>{_fmt(None if ang is None else np.degrees(ang), '+.2f')}°</b> "
            f"({_fmt(ang, '+.4f')} rad) · sensor <b>{sensor}</b><br>"
            f"p<sub>A</sub> <b>{_fmt(None if pa is None else pa / 1e5, '.1f')} bar</b> · "
            f"p<sub>B</sub> <b>{_fmt(None if pb is None else pb / 1e5, '.1f')} bar</b> · "
            f"valve <b>{_fmt(js.get('command_voltage'), '+.2f')} V</b> "
            f"(asked {_fmt(js.get('requested_voltage'), '+.2f')} V, {html.escape(str(src))}) {wd}</div>"
        )

    def _warnings_html(self, ls: dict) -> str:
        items = list(ls.get("warnings") or [])
        if not items:
            return ""
        body = "".join(f"<li>{html.escape(str(w))}</li>" for w in items)
        return ("<div style='background:#fdecea;color:#b00;border:2px solid #c0392b;border-radius:4px;"
                f"font-size:0.85em;padding:0.3em 0.5em'><b>WARNING</b><ul style='margin:0;padding-left:1.2em'>{body}"
                "</ul></div>")

    def _status_html(self, state: dict | None, ls: dict) -> str:
        engine = ls.get("engine") or {}
        if engine.get("state") not in (None, "running"):
            conn = _badge(f"ENGINE {str(engine.get('state')).upper()}", "#c0392b")
        elif ls.get("connected"):
            conn = _badge("connected", "#2e7d32")
        else:
            conn = _badge("DISCONNECTED", "#c0392b")
        where = html.escape(str(ls.get("where", "")))
        age = ls.get("age_s")
        lines = [f"<b>{html.escape(self.link.spec.name)}</b> · {conn} {where}"
                 + (f" · {age * 1e3:.0f} ms old" if ls.get("kind") == "remote" and age is not None else "")]
        if not ls.get("connected"):
            lines.append(f"<span style='color:#b00'>{html.escape(str(ls.get('detail', '')))}</span>")
        if state is not None:
            loop = state.get("loop", {})
            late = loop.get("lateness_us", {}) or {}
            n_f = len(state.get("faults", []))
            wd = [j for j, js in state["joints"].items() if js.get("watchdog")]
            estop = _badge("E-STOP ENGAGED", "#c0392b") if state.get("estop") else _badge("E-STOP released", "#2e7d32")
            faults = _badge(f"{n_f} fault{'s' if n_f != 1 else ''}", "#c0392b" if n_f else "#2e7d32")
            wdb = _badge("watchdog: " + ", ".join(wd), "#c0392b") if wd else _badge("watchdog ok", "#2e7d32")
            div = _badge("DIVERGED: reset needed", "#c0392b") + " " if state.get("diverged") else ""
            lines.append(f"{div}{estop} {faults} {wdb}")
            lines.append(f"t = {state.get('time', 0.0):.2f} s · {html.escape(str(state.get('mode', '')))} · "
                         f"loop {loop.get('rate_hz', 0.0):.0f} Hz · overruns {loop.get('overruns', 0)} · "
                         f"late p99 {_fmt(late.get('p99'), '.0f')} µs")
        return "<div style='font-size:0.85em;line-height:1.6;padding:0 0.5em'>" + "<br>".join(lines) + "</div>"

    def _faults_html(self, state: dict) -> str:
        rows = []
        for f in state.get("faults", []):
            params = ", ".join(f"{k}={v}" for k, v in (f.get("params") or {}).items())
            rows.append(f"<li>{_badge(f.get('kind', '?'), '#c0392b')} {html.escape(str(f.get('joint') or 'supply'))}"
                        f" {html.escape(params)}</li>")
        wd = [j for j, js in state["joints"].items() if js.get("watchdog")]
        body = "<ul style='margin:0;padding-left:1.2em'>" + "".join(rows) + "</ul>" if rows else "no active faults"
        wds = "watchdog tripped on " + ", ".join(wd) if wd else "no watchdog trips active"
        return (f"<div style='font-size:0.85em;padding:0 0.5em'><b>Faults</b><br>{body}<br>"
                f"<b>Watchdog</b><br>{wds}</div>")

    def _health_html(self, state: dict, ls: dict, vs: dict) -> str:
        loop = state.get("loop", {})
        late = loop.get("lateness_us", {}) or {}
        rows = [
            ("plant rate", f"{loop.get('rate_hz', 0.0):.1f} Hz"),
            ("ticks", f"{loop.get('ticks', 0)}"),
            ("overruns", f"{loop.get('overruns', 0)}"),
            ("resyncs", f"{loop.get('resyncs', 0)}"),
            ("watchdog trips", f"{loop.get('watchdog_trips', 0)}"),
            ("lateness p50/p99/max", f"{_fmt(late.get('p50'), '.1f')} / {_fmt(late.get('p99'), '.1f')} / "
                                     f"{_fmt(late.get('max'), '.0f')} µs"),
            ("real-time priority", "yes" if loop.get("realtime_priority") else "no"),
            ("supply pressure", f"{state.get('supply_pressure', 0.0) / 1e5:.1f} bar"),
            ("link", f"{ls.get('kind')} · {html.escape(str(ls.get('detail', '')))} · "
                     f"reconnects {ls.get('reconnects', 0)}"),
            ("viewer", f"{vs.get('rate_hz', 0.0):.1f} Hz · {vs.get('frame_cpu_ms', 0.0):.2f} ms CPU/frame · "
                       f"{vs.get('clients', 0)} browser(s)"),
        ]
        body = "".join(f"<tr><td style='padding-right:1em'>{k}</td><td><b>{v}</b></td></tr>" for k, v in rows)
        return f"<div style='font-size:0.85em;padding:0 0.5em'><b>Loop health</b><table>{body}</table></div>"
