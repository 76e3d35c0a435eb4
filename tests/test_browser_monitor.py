"""The browser monitor in a real headless Chromium (software WebGL), against a real in-process
HydroHIL server (engine process, uvicorn, the viewer plugin loaded through its entry point).

From screenshots: the arm is drawn where forward kinematics and the browser's own camera put it
(pixels differ from the empty scene there and hardly anywhere else), and it moves when a joint is
commanded. From the page: a slider moved with the keyboard changes the command the plant receives,
E-STOP neutralises every valve, closing the last page puts the panel's joints back to neutral.
Screenshots go to artifacts/browser/. Serial and short: headless rendering takes about one core."""

import time

import httpx
import numpy as np
import pytest
from viser import GuiEvent
from web_helpers import (CHROMIUM, CHROMIUM_ARGS, LAUNCH_TIMEOUT_MS, InProcessServer, artifacts_dir, changed,
                         dismiss_notifications, open_page, project, region_mask, require_chromium, screenshot,
                         settled_screenshot, solid, wait_changed, wait_for)

from web.panel import HOLD_OFF_S

pytestmark = [pytest.mark.browser, pytest.mark.realtime]

MARGIN_PX = 12


@pytest.fixture(scope="module")
def browser():
    require_chromium()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS,
                              timeout=LAUNCH_TIMEOUT_MS)
        yield b
        b.close()


class Monitor:
    """One server and one page showing it, with the geometry the screenshots are judged by."""

    def __init__(self, robot, browser, tmp):
        self.robot = robot
        self.server = InProcessServer(robot, tmp)
        self.viewer = self.server.viewer
        self.scene = self.viewer.scene
        self.panel = self.viewer.panel
        self.dir = artifacts_dir()
        try:
            self.page = open_page(browser, self.viewer.url)
            dismiss_notifications(self.page)
            wait_for(lambda: self.viewer.server.get_clients(), 20, "the page to connect")
            self.page.wait_for_timeout(1000)
            # the control panel floats on the right: the 3D canvas is judged left of it
            panel_x = self.page.get_by_role("button", name="E-STOP", exact=True).bounding_box()["x"]
            self.canvas = np.zeros((800, 1280), dtype=bool)
            self.canvas[:, : int(panel_x) - 20] = True
        except BaseException:
            self.server.close()
            raise

    @property
    def camera(self):
        return next(iter(self.viewer.server.get_clients().values())).camera

    def arm_region(self) -> np.ndarray:
        """Where the arm must appear: the projected bounding box of its geometry and cylinder pins."""
        lo, hi = self.scene.geometry_bounds(self.scene.last_q)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        pts = np.concatenate([corners, self.scene.points_of_interest()])
        return region_mask((800, 1280), project(pts, self.camera), MARGIN_PX)

    def shot(self, name: str) -> np.ndarray:
        return settled_screenshot(self.page, self.dir / f"{self.robot}_{name}.png", self.canvas)

    def show(self, on: bool) -> None:
        self.panel.show_links.value = on      # the panel's own "Display" checkboxes
        self.panel.show_actuators.value = on

    def toggled_shot(self, name: str, on: bool, before: np.ndarray, wait_s: float) -> np.ndarray:
        """Show or hide the arm, then a settled screenshot once the page drew it: the page's own checkbox
        took the value (the scene's change comes in the same message stream) and the canvas differs from
        ``before`` (or ``wait_s`` passed: nothing there to change). Without the wait, a page still drawing
        the old frame looks "settled" and both pictures show the same scene."""
        self.show(on)
        for h in (self.panel.show_links, self.panel.show_actuators):
            box = self.page.locator(f'[id="{h._impl.uuid}"]')  # viser gives an input its element's id
            wait_for(lambda: box.is_checked() == on, 15, f"the page's checkbox to read {on}")
        wait_changed(self.page, self.dir / f"{self.robot}_{name}.png", before, self.canvas, wait_s)
        return self.shot(name)

    def close(self):
        try:
            self.page.close()
        finally:
            self.server.close()


@pytest.fixture(scope="module")
def hydrolek(browser, tmp_path_factory):
    m = Monitor("hydrolek", browser, tmp_path_factory.mktemp("browser_hydrolek"))
    yield m
    m.close()


def assert_arm_drawn(m: Monitor) -> None:
    # hidden first: an arm whose meshes are still loading looks like a hidden one, so the arm is judged
    # by what appears when it is shown (given up to 60 s: software WebGL parses meshes slowly)
    try:
        empty = m.toggled_shot("empty_scene", False, screenshot(m.page, m.dir / f"{m.robot}_initial.png"), 5.0)
        full = m.toggled_shot("arm", True, empty, 60.0)
        region = m.arm_region() & m.canvas
        hidden = m.toggled_shot("hidden_again", False, full, 30.0)
        again = m.toggled_shot("arm_again", True, hidden, 30.0)
    finally:
        m.show(True)        # the module's later tests share the page: never leave the arm hidden
    d = changed(full, empty)
    inside = d[region].mean()
    # what the arm's showing drew outside its region, not lines that re-rasterised a pixel over
    outside = solid(d)[m.canvas & ~region].mean()
    assert inside > 0.05, (f"{m.robot}: only {inside:.1%} of the arm's region differs from the empty scene "
                           f"({outside:.2%} outside it)")
    assert outside < 0.005, f"{m.robot}: {outside:.2%} of the canvas outside the arm's region changed"
    # shown again: the arm is back where it was. Not pixel-identical: the plant runs in real time (the
    # harvester's boom settles ~0.3 mrad over these seconds) and edges re-rasterise, so the test is
    # that the second picture is nearer the first than the empty scene (the CI run that failed the old
    # pixel-identity check: 1.2 % of the canvas, edges only, 3.5 % of the boom region against ~19 %)
    back = changed(again, empty)[region].mean()
    assert back > 0.5 * inside, f"{m.robot}: the arm did not come back ({back:.1%} vs {inside:.1%})"
    assert changed(full, again)[region].mean() < 0.5 * inside


def assert_arm_moves(m: Monitor, joint: str, volts: float, seconds: float) -> float:
    dof = m.scene.spec.joint(joint).dof
    before = m.shot("before_command")
    region = m.arm_region()
    q0 = m.server.svc.documents.state()["pose"][dof]
    with httpx.Client(base_url=m.server.url, timeout=10) as c:
        c.put("/api/v1/commands", json={"voltages": {joint: volts}}).raise_for_status()
        time.sleep(seconds)
        c.put("/api/v1/commands", json={"voltages": {joint: 0.0}}).raise_for_status()
    wait_for(lambda: abs(m.server.svc.documents.state()["joints"][joint]["velocity"]) < 0.01, 10, f"{joint} to stop")
    q1 = m.server.svc.documents.state()["pose"][dof]
    region = (region | m.arm_region()) & m.canvas
    # the plant stopped; the page may still be drawing an older pose (software WebGL): wait for it
    wait_changed(m.page, m.dir / f"{m.robot}_after_command.png", before, region, 15.0)
    after = m.shot("after_command")
    moved = changed(before, after)[region].mean()
    assert abs(q1 - q0) > 0.15, f"{joint} moved only {q1 - q0:.3f} rad"
    assert moved > 0.03, f"{m.robot}: commanding {joint} changed only {moved:.1%} of the arm's region"
    return moved


def test_arm_is_drawn(hydrolek):
    assert_arm_drawn(hydrolek)


def test_arm_moves_when_a_joint_is_commanded(hydrolek):
    assert_arm_moves(hydrolek, "j2", 6.0, 1.2)


def slider_of(m: Monitor, joint: str):
    """The page's slider of a joint (the panel lists joints in spec order, all folders open)."""
    k = m.scene.spec.joint_names.index(joint)
    s = m.page.locator('[role="slider"]').nth(k)
    lo, hi = m.scene.spec.joint(joint).command_range
    assert float(s.get_attribute("aria-valuemin")) == lo and float(s.get_attribute("aria-valuemax")) == hi
    return s


def test_slider_in_the_page_commands_the_plant(hydrolek):
    m, svc = hydrolek, hydrolek.server.svc
    s = slider_of(m, "j2")
    s.focus()
    for _ in range(20):  # 20 steps of 0.05 V
        m.page.keyboard.press("ArrowRight")
    wait_for(lambda: svc.documents.state()["joints"]["j2"]["requested_voltage"] == pytest.approx(1.0), 15,
             "the plant to receive the slider's command")
    js = svc.documents.state()["joints"]["j2"]
    assert js["source"] == "viewer" and js["command_voltage"] == pytest.approx(1.0)
    assert float(s.get_attribute("aria-valuenow")) == pytest.approx(1.0)
    m.page.get_by_role("button", name="Neutral j2", exact=True).click()
    wait_for(lambda: svc.documents.state()["joints"]["j2"]["requested_voltage"] == 0.0, 15, "neutral on j2")
    wait_for(lambda: float(s.get_attribute("aria-valuenow")) == 0.0, 15, "the slider back at 0 V")


def test_a_state_read_before_the_operator_moved_the_slider_does_not_move_it_back(hydrolek):
    """The render thread may apply a state it read before the operator's command (a loaded machine):
    the slider keeps the operator's value; a state read after the hold-off is followed again."""
    m, svc = hydrolek, hydrolek.server.svc
    s = slider_of(m, "j3")
    before = time.monotonic()
    s.focus()
    for _ in range(10):
        m.page.keyboard.press("ArrowRight")
    wait_for(lambda: svc.documents.state()["joints"]["j3"]["requested_voltage"] == pytest.approx(0.5), 15,
             "the plant to receive the slider's command")
    stale = svc.documents.state()
    stale["joints"]["j3"].update(source="rest", requested_voltage=0.0)   # as it was before the command
    time.sleep(HOLD_OFF_S + 0.2)          # the render thread stalled past the hold-off, then applies it
    m.panel._sync_sliders(stale, before)
    assert m.panel.sliders["j3"].value == pytest.approx(0.5)
    m.panel._sync_sliders(stale, time.monotonic() + HOLD_OFF_S)
    assert m.panel.sliders["j3"].value == 0.0
    m.page.get_by_role("button", name="Neutral j3", exact=True).click()
    wait_for(lambda: svc.documents.state()["joints"]["j3"]["requested_voltage"] == 0.0, 15, "neutral on j3")


def test_a_slider_move_whose_callback_has_not_run_yet_is_not_put_back(hydrolek):
    """viser stores the browser's new slider value, then runs the panel's callback on a thread pool: a
    render in between keeps that value (putting it back would make the callback send the old command);
    a value whose callback never comes gives way to the plant's command after the hold-off."""
    m, svc = hydrolek, hydrolek.server.svc
    panel, slider = m.panel, m.panel.sliders["j5"]
    with httpx.Client(base_url=m.server.url, timeout=10) as c:     # another source holds j5 at 0.5 V
        c.put("/api/v1/commands", json={"voltages": {"j5": 0.5}}).raise_for_status()
    wait_for(lambda: slider.value == pytest.approx(0.5), 15, "the slider to follow the REST command")
    client = next(iter(panel.server.get_clients().values()))

    slider._impl.value = 0.75           # what viser's message handler does before submitting the callback
    panel._sync_sliders(svc.documents.state(), time.monotonic())
    assert slider.value == pytest.approx(0.75)
    panel._slider_cb("j5")(GuiEvent(client, client.client_id, slider))    # the callback, late
    wait_for(lambda: svc.documents.state()["joints"]["j5"]["requested_voltage"] == pytest.approx(0.75), 15,
             "the plant to receive the operator's value")

    with httpx.Client(base_url=m.server.url, timeout=10) as c:
        c.put("/api/v1/commands", json={"voltages": {"j5": 0.5}}).raise_for_status()
    wait_for(lambda: slider.value == pytest.approx(0.5), 15, "the slider to follow the REST command again")
    slider._impl.value = -0.25          # a browser value whose callback never comes
    wait_for(lambda: slider.value == pytest.approx(0.5), 3 * HOLD_OFF_S + 5, "the plant's command to win")
    assert svc.documents.state()["joints"]["j5"]["requested_voltage"] == pytest.approx(0.5)
    m.page.get_by_role("button", name="Neutral j5", exact=True).click()
    wait_for(lambda: svc.documents.state()["joints"]["j5"]["requested_voltage"] == 0.0, 15, "neutral on j5")


def test_estop_in_the_page_neutralises_every_valve(hydrolek):
    m, svc = hydrolek, hydrolek.server.svc
    names = svc.spec.joint_names
    with httpx.Client(base_url=m.server.url, timeout=10) as c:
        c.put("/api/v1/commands", json={"voltages": {j: (-1.0) ** k * 0.5 for k, j in enumerate(names) if j != "j4"}}
              ).raise_for_status()
    s = slider_of(m, "j4")
    s.focus()
    for _ in range(8):
        m.page.keyboard.press("ArrowLeft")
    wait_for(lambda: svc.documents.state()["joints"]["j4"]["requested_voltage"] == pytest.approx(-0.4), 15,
             "the j4 slider command")
    assert all(js["command_voltage"] != 0.0 for js in svc.documents.state()["joints"].values())
    m.page.get_by_role("button", name="E-STOP", exact=True).click()
    wait_for(lambda: svc.commands.estopped, 15, "the E-STOP to engage")
    try:
        wait_for(lambda: svc.documents.state()["estop"], 5, "the engine to apply the E-STOP")
        wait_for(lambda: all(js["command_voltage"] == 0.0 and js["requested_voltage"] == 0.0
                             for js in svc.documents.state()["joints"].values()), 5, "every valve at 0 V")
        wait_for(lambda: all(abs(js["spool"]) < 1e-3 for js in svc.documents.state()["joints"].values()), 5,
                 "every spool centred")
        m.page.wait_for_selector("text=E-STOP ENGAGED", timeout=15000)
        wait_for(lambda: s.get_attribute("aria-disabled") == "true", 15, "the sliders to lock")
        m.page.screenshot(path=str(m.dir / "hydrolek_estop.png"))
        # a locked slider does not command
        s.focus()
        m.page.keyboard.press("ArrowRight")
        m.page.wait_for_timeout(1000)
        assert svc.documents.state()["joints"]["j4"]["requested_voltage"] == 0.0
    finally:
        m.page.get_by_role("button", name="Release E-STOP", exact=True).click()
        wait_for(lambda: not svc.commands.estopped, 15, "the E-STOP release")
    wait_for(lambda: s.get_attribute("aria-disabled") == "false", 15, "the sliders to unlock")


PLOT_STATE_JS = """() => Object.values((window.__viserTestpoints || {}).uplots || {}).map(p => ({
    title: p.chart.root.querySelector('.u-title').textContent,
    x: Array.from(p.chart.data[0]), y: Array.from(p.chart.data[1]),
    xmin: p.chart.scales.x.min, xmax: p.chart.scales.x.max}))"""


def test_plots_and_health_in_the_page(hydrolek):
    m = hydrolek
    with httpx.Client(base_url=m.server.url, timeout=10) as c:
        c.put("/api/v1/commands", json={"voltages": {"j1": 1.0}}).raise_for_status()
        m.page.get_by_role("tab", name="Plots").click()
        m.page.wait_for_selector(".uplot canvas:visible", timeout=15000)  # a collapsed plot keeps a 0-px canvas
        m.page.wait_for_timeout(3000)
        c.put("/api/v1/commands", json={"voltages": {"j1": 0.0}}).raise_for_status()

    def plots():
        got = {p["title"]: p for p in m.page.evaluate(PLOT_STATE_JS)}
        return got if {"command (V)", "angle (°)"} <= set(got) else None

    wait_for(plots, 15, "both plots in the page (viser's uPlot test point)")

    def shows_the_command():
        p = plots()["command (V)"]
        return len(p["x"]) > 40 and any(v == pytest.approx(1.0) for v in p["y"]) and p["x"][-1] == 0.0

    wait_for(shows_the_command, 15, "the command plot to show the last seconds with the 1 V step")
    got = plots()
    assert got["command (V)"]["xmin"] == -10 and got["command (V)"]["xmax"] == 0  # a live 10 s window
    angle = got["angle (°)"]["y"]
    assert max(angle) - min(angle) > 5.0  # j1 moved while commanded (degrees)
    m.page.screenshot(path=str(m.dir / "hydrolek_plots.png"))
    m.page.get_by_role("tab", name="Health").click()
    for text in ("Loop health", "overruns", "lateness", "Faults", "Watchdog"):
        m.page.wait_for_selector(f"text={text}", timeout=15000)
    m.page.screenshot(path=str(m.dir / "hydrolek_health.png"))
    m.page.get_by_role("tab", name="Joints").click()
    m.page.wait_for_selector('[role="slider"]', timeout=15000)


def test_closing_the_last_page_puts_its_joints_to_neutral(hydrolek):
    m, svc = hydrolek, hydrolek.server.svc
    s = slider_of(m, "j5")
    s.focus()
    for _ in range(10):
        m.page.keyboard.press("ArrowRight")
    wait_for(lambda: svc.documents.state()["joints"]["j5"]["requested_voltage"] == pytest.approx(0.5), 15, "the j5 command")
    m.page.close()
    wait_for(lambda: svc.documents.state()["joints"]["j5"]["requested_voltage"] == 0.0, 15, "the dead-man neutral on j5")


@pytest.mark.parametrize("robot, joint, volts, seconds", [("mars_nd", "left_j2", 6.0, 1.2),
                                                          ("harvester", "boom", 8.0, 1.5)])
def test_other_robots_are_drawn_and_move(browser, tmp_path_factory, robot, joint, volts, seconds):
    m = Monitor(robot, browser, tmp_path_factory.mktemp(f"browser_{robot}"))
    try:
        assert_arm_drawn(m)
        assert_arm_moves(m, joint, volts, seconds)
        m.page.get_by_role("tab", name="Plots").click()
        m.page.wait_for_selector(".uplot canvas:visible", timeout=15000)  # a collapsed plot keeps a 0-px canvas
        m.page.wait_for_timeout(2000)
        m.page.screenshot(path=str(m.dir / f"{robot}_plots.png"))
    finally:
        m.close()
