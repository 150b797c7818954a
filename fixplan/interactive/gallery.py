"""Screenshots of ``fixplan haptic`` for the docs: ``python -m fixplan.interactive.gallery OUTDIR``.

Two scripted sessions on the default box, drawn by the app and photographed in headless Chromium:

- ``haptic.png``: the gizmo (the mouse device) moved through viser's Python API where the spring
  transmits the planner's suggested push, stopped while the part slides toward E1 (contact forces,
  normals, the proxy and the spring, the suggested push, the panel);
- ``haptic-jammed.png``: a hand that insists on pushing down and sideways: the part stays on its
  base, ``classify`` calls the push jammed, the panel says JAMMED.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import fixplan
from fixplan.haptics.coordinates import coordinates_from_pose, pose_from_coordinates
from fixplan.interactive.app import HapticApp, _wxyz, _xyz
from fixplan.interactive.browser import open_live_page
from fixplan.interactive.device_sim import LockstepHandle
from fixplan.interactive.handles import GizmoHandle
from fixplan.interactive.session import HapticSession


def _app(session: HapticSession) -> HapticApp:
    app = HapticApp(session, port=0)
    app.start()
    app._stop.set()  # drawn by the script between ticks
    if app._thread is not None:
        app._thread.join()
    app.always_draw = True
    return app


def sliding_shot(path: Path, until_s: float = 0.32) -> None:
    """The gizmo session, photographed at ``until_s`` of simulated time."""
    fx = fixplan.load(fixplan.default_fixture_path())
    handle = GizmoHandle(coordinates_from_pose(fx.start, fx.start.R_world_body))
    s = HapticSession(fx, handle, realtime=False, synchronous=True, duration_s=10.0)
    app = _app(s)
    try:
        s._warm_up()
        s._run_guide(s.snapshot)  # type: ignore[arg-type]
        while s.status is None and s.sim.time_s < until_s:
            g = s.guidance
            if g.push is not None and app.gizmo is not None:
                x_w, _ = s.coordinates()
                pose = pose_from_coordinates(x_w + g.push / s.K, s.R0, 3)
                app.gizmo.position, app.gizmo.wxyz = _xyz(pose.p_world), _wxyz(pose)
            app.draw()
            for _ in range(10):
                s.tick(0.0)
        app.draw()
        url = f"http://127.0.0.1:{app.url_port}/"
        open_live_page(url, path, hold_s=2.0)
    finally:
        app.stop()


def jammed_shot(path: Path) -> None:
    """A constant push into the base and sideways (friction holds the part): the JAMMED warning."""
    fx = fixplan.load(fixplan.default_fixture_path())
    s = HapticSession(fx, None, realtime=False, synchronous=True, until_goal=False, duration_s=5.0)
    s.handle = LockstepHandle(s.bridge_config(), push=np.array([0.0, -3.0, -30.0, 0, 0, 0]), noise=0.0, delay_s=0.0)
    s._auto = False
    app = _app(s)
    try:
        s._warm_up()
        s._run_guide(s.snapshot)  # type: ignore[arg-type]
        while not s._jammed_flag() and s.sim.time_s < 2.0:
            s.tick(0.0)
        for _ in range(20):
            s.tick(0.0)
        app.draw()
        url = f"http://127.0.0.1:{app.url_port}/"
        open_live_page(url, path, hold_s=2.0, wait_text="JAMMED")
    finally:
        app.stop()


def main(argv: list[str] | None = None) -> int:
    """Write both screenshots into OUTDIR."""
    parser = argparse.ArgumentParser(prog="python -m fixplan.interactive.gallery", description=__doc__)
    parser.add_argument("outdir", type=Path)
    args = parser.parse_args(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    sliding_shot(args.outdir / "haptic.png")
    jammed_shot(args.outdir / "haptic-jammed.png")
    print(f"wrote {args.outdir / 'haptic.png'}, {args.outdir / 'haptic-jammed.png'}", file=sys.stderr)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
