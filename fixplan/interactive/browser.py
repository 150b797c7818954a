"""Open the ``fixplan haptic`` page in headless Chromium (the browser test, the gallery, the benchmark).

Like :mod:`fixplan.present.browser` for ``fixplan view``: Playwright drives Debian's ``chromium``; any
request to a host other than the page's own (127.0.0.1) is blocked and recorded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from fixplan.present.browser import BrowserErrors, headless_page


@dataclass
class LivePageReport(BrowserErrors):
    """What the page did while it was open."""

    requests: list[str] = field(default_factory=list)
    canvases: int = 0
    text: str = ""
    screenshot: Path | None = None


def open_live_page(
    url: str,
    screenshot: Path | None = None,
    *,
    width: int = 1100,
    height: int = 700,
    wait_text: str | None = "felt force",
    hold_s: float = 2.0,
    timeout_s: float = 60.0,
) -> LivePageReport:
    """Open ``url``, wait for the viser canvas (and ``wait_text`` in the panel), keep it open ``hold_s``."""
    report = LivePageReport()
    own = urlsplit(url).hostname

    def route(r: Any) -> None:
        u = r.request.url
        report.requests.append(u)
        host = urlsplit(u).hostname
        if u.startswith(("data:", "blob:")) or host == own:
            r.continue_()
        else:
            report.blocked_requests.append(u)
            r.abort()

    def on_console(msg: Any) -> None:
        if msg.type == "error":
            report.console_errors.append(msg.text)

    with headless_page(url, width=width, height=height, software_gl=True) as page:
        page.on("console", on_console)
        page.on("pageerror", lambda exc: report.page_errors.append(str(exc)))
        page.route("**/*", route)
        page.goto(url, wait_until="load", timeout=timeout_s * 1e3)
        page.wait_for_selector("canvas", timeout=timeout_s * 1e3)
        if wait_text:
            page.wait_for_function(f"document.body.innerText.includes({wait_text!r})", timeout=timeout_s * 1e3)
        end = time.perf_counter() + hold_s
        while time.perf_counter() < end:
            page.wait_for_timeout(100)
        report.canvases = int(page.evaluate("document.querySelectorAll('canvas').length"))
        report.text = str(page.evaluate("document.body.innerText"))
        if screenshot is not None:
            from playwright.sync_api import Error as PlaywrightError

            # viser's "software WebGL" notice (headless Chromium has no GPU) would cover the scene
            for button in page.locator("[class*=Notification] button").all():
                try:
                    button.click(timeout=1000)
                except PlaywrightError:
                    pass
            page.wait_for_timeout(500)
            Path(screenshot).parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(screenshot), full_page=False)
            report.screenshot = Path(screenshot)
    return report
