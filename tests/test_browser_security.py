"""The in-process viewer bound beyond loopback, in a real headless Chromium: its panel is read-only
until this browser enters the token, then the same slider commands the plant."""

import pytest

from web_helpers import (CHROMIUM, CHROMIUM_ARGS, LAUNCH_TIMEOUT_MS, InProcessServer, dismiss_notifications, open_page,
                         require_chromium, wait_for)

pytestmark = [pytest.mark.browser, pytest.mark.realtime]

TOKEN = "unlock-me"


def test_a_panel_beyond_loopback_is_read_only_until_the_browser_enters_the_token(tmp_path):
    require_chromium()
    from playwright.sync_api import sync_playwright

    srv = InProcessServer("hydrolek", tmp_path, token=TOKEN, viewer_host="0.0.0.0")
    try:
        svc = srv.svc
        with sync_playwright() as p:
            b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS,
                                  timeout=LAUNCH_TIMEOUT_MS)
            try:
                page = open_page(b, f"http://127.0.0.1:{srv.viewer.port}/")
                dismiss_notifications(page)
                page.wait_for_selector("text=read-only until this browser enters the token", timeout=30000)
                slider = page.locator('[role="slider"]').nth(1)            # j2
                slider.focus()
                for _ in range(10):
                    page.keyboard.press("ArrowRight")
                page.wait_for_selector("text=enter the token first", timeout=15000)
                page.wait_for_timeout(500)
                assert svc.documents.state()["joints"]["j2"]["requested_voltage"] == 0.0   # nothing reached the plant
                # a wrong token does not unlock
                # viser's label does not name its input (for= points elsewhere): find the input beside it
                field = page.locator("xpath=//label[text()='Token']/ancestor::div[contains(@class,'mantine-Flex-root')][1]"
                                     "//input")
                field.fill("wrong")
                field.press("Enter")
                page.wait_for_timeout(300)
                page.get_by_role("button", name="Unlock commands").click()
                page.wait_for_selector("text=wrong token", timeout=15000)
                field.fill(TOKEN)
                field.press("Enter")
                page.wait_for_timeout(300)
                page.get_by_role("button", name="Unlock commands").click()
                page.wait_for_selector("text=commands unlocked in this browser", timeout=15000)
                slider.focus()
                for _ in range(4):
                    page.keyboard.press("ArrowRight")
                wait_for(lambda: svc.documents.state()["joints"]["j2"]["requested_voltage"] > 0.0, 15,
                         "the unlocked slider's command")
                assert svc.documents.state()["joints"]["j2"]["source"] == "viewer"
            finally:
                b.close()
    finally:
        srv.close()
