"""Open a page written by ``fixplan view`` in headless Chromium and report what it did.

Used by the browser test and by ``make gallery`` (``python -m fixplan.present.browser page.html shot.png``).
Playwright (the ``dev`` extra) drives Debian's ``chromium`` at :data:`CHROMIUM`; its own browser
download (``playwright install``) is never used. Every request that is not the page's own file
is blocked and recorded, so a page that tries to fetch anything is caught.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fixplan.errors import FixplanError

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)

# What the page shows once plotly has drawn it: frames loaded, SVG layers, WebGL scene.
_STATE_JS = """() => {
  const gd = document.querySelector('.js-plotly-plot');
  if (!gd || !gd._fullLayout) return null;
  const scene = gd._fullLayout.scene;
  return {
    frames: ((gd._transitionData || {})._frames || []).length,
    meta_frames: gd.layout.meta ? gd.layout.meta.frames : null,
    main_svg: document.querySelectorAll('.main-svg').length,
    canvases: document.querySelectorAll('canvas').length,
    webgl: !!(scene && scene._scene && scene._scene.glplot),
    is3d: !!scene,
    traces: gd.data.length,
    no_webgl_message: document.body.innerText.includes('WebGL is not supported'),
  };
}"""

# Jump to the last frame; then report whether the displayed workpiece is that frame's.
_LAST_FRAME_JS = """async () => {
  const gd = document.querySelector('.js-plotly-plot');
  const frames = (gd._transitionData || {})._frames || [];
  if (!frames.length) return null;
  const last = frames[frames.length - 1];
  await Plotly.animate(gd, [last.name], {frame: {duration: 0, redraw: true}, transition: {duration: 0},
                                        mode: 'immediate'});
  const k = last.traces[0];
  const shown = gd.data[k].x, want = last.data[0].x;
  return shown.length === want.length && shown.every((v, i) => v === want[i]);
}"""


@dataclass
class BrowserErrors:
    """What went wrong in a page: console errors, uncaught page errors, blocked fetches."""

    console_errors: list[str] = field(default_factory=list)
    page_errors: list[str] = field(default_factory=list)
    blocked_requests: list[str] = field(default_factory=list)

    @property
    def errors(self) -> list[str]:
        """Console errors, uncaught page errors and attempted fetches, one line each."""
        return (
            [f"console: {m}" for m in self.console_errors]
            + [f"page error: {m}" for m in self.page_errors]
            + [f"fetch attempted: {u}" for u in self.blocked_requests]
        )


@dataclass
class PageReport(BrowserErrors):
    """What happened when the page was opened."""

    state: dict[str, Any] = field(default_factory=dict)
    last_frame_shown: bool | None = None
    screenshot: Path | None = None


def browser_available() -> str | None:
    """None when the browser test can run, else why not (one line)."""
    if not CHROMIUM.exists():
        return f"{CHROMIUM} is absent (make install provides it: apt-get install chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright package is absent (pip install -e '.[dev]')"
    return None


@contextmanager
def headless_page(subject: str, *, width: int, height: int, software_gl: bool = False) -> Iterator[Any]:
    """A page of headless Chromium (Debian's, at :data:`CHROMIUM`) with a ``width`` × ``height`` viewport.

    The one place fixplan starts a browser: ``fixplan view``'s page check, the live haptic page
    and the haptic benchmark all open theirs here. ``software_gl``: WebGL through SwiftShader
    (headless Chromium has no GPU; viser's scene needs it). The browser is closed on leaving.

    Raises
    ------
    FixplanError
        No browser (``subject``: what was to be opened, for the message), or the browser failed.
    """
    why = browser_available()
    if why is not None:
        raise FixplanError(f"cannot open {subject}: {why}")
    from playwright.sync_api import Error as PlaywrightError
    from playwright.sync_api import sync_playwright

    args = (
        [*CHROMIUM_ARGS, "--use-gl=swiftshader", "--enable-unsafe-swiftshader"] if software_gl else list(CHROMIUM_ARGS)
    )
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=args, headless=True)
            try:
                yield browser.new_page(viewport={"width": width, "height": height})
            finally:
                browser.close()
    except PlaywrightError as exc:
        raise FixplanError(f"{subject}: the browser failed: {str(exc).splitlines()[0]}") from exc


def open_page(
    html: Path,
    screenshot: Path | None = None,
    *,
    width: int = 900,
    height: int = 600,
    last_frame: bool = True,
    timeout_s: float = 60.0,
) -> PageReport:
    """Open ``html`` in headless Chromium, wait for plotly to draw it, optionally jump to the last frame.

    Parameters
    ----------
    screenshot : Path, optional
        Write a PNG of the viewport (after the jump to the last frame when ``last_frame``).
    last_frame : bool
        Animate to the replay's last frame (checks the animation runs without errors).

    Raises
    ------
    FixplanError
        No browser, or the page never finished drawing within ``timeout_s``.
    """
    report = PageReport()
    url = Path(html).resolve().as_uri()
    timeout_ms = timeout_s * 1e3

    def on_console(msg: Any) -> None:
        if msg.type == "error":
            report.console_errors.append(msg.text)

    def route(r: Any) -> None:
        if r.request.url == url or r.request.url.startswith(("data:", "blob:")):
            r.continue_()
        else:
            report.blocked_requests.append(r.request.url)
            r.abort()

    with headless_page(str(html), width=width, height=height) as page:
        page.on("console", on_console)
        page.on("pageerror", lambda exc: report.page_errors.append(str(exc)))
        page.route("**/*", route)
        page.goto(url, wait_until="load", timeout=timeout_ms)
        page.wait_for_function(f"({_STATE_JS})() !== null", timeout=timeout_ms)
        page.wait_for_timeout(500)  # let the WebGL scene draw its first frame
        if last_frame:
            report.last_frame_shown = page.evaluate(_LAST_FRAME_JS)
            page.wait_for_timeout(300)
        report.state = page.evaluate(_STATE_JS)
        if screenshot is not None:
            Path(screenshot).parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(screenshot), full_page=False)
            report.screenshot = Path(screenshot)
    return report


def main(argv: list[str] | None = None) -> int:
    """``python -m fixplan.present.browser PAGE.html SHOT.png [--width W] [--height H]``: screenshot a page."""
    parser = argparse.ArgumentParser(prog="python -m fixplan.present.browser", description=main.__doc__)
    parser.add_argument("html", type=Path)
    parser.add_argument("png", type=Path)
    parser.add_argument("--width", type=int, default=900)
    parser.add_argument("--height", type=int, default=600)
    parser.add_argument("--first-frame", action="store_true", help="Screenshot the first frame, not the last.")
    args = parser.parse_args(argv)
    if not args.html.is_file():
        print(f"fixplan.present.browser: {args.html}: no such file", file=sys.stderr)
        return 2
    try:
        report = open_page(args.html, args.png, width=args.width, height=args.height, last_frame=not args.first_frame)
    except FixplanError as exc:
        print(f"fixplan.present.browser: {exc}", file=sys.stderr)
        return 2
    for line in report.errors:
        print(f"fixplan.present.browser: {line}", file=sys.stderr)
    print(f"wrote {args.png} ({args.png.stat().st_size / 1024:.0f} KB)")
    return 1 if report.errors else 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
