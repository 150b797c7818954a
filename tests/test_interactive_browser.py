"""fixplan haptic's web app: the page in headless Chromium, the gizmo as the device, the token gate.

The browser tests (marked ``browser``) need Debian's chromium (``make install``) and skip without it.
"""

import json
import urllib.error
import urllib.request

import numpy as np
import pytest

import fixplan
from fixplan.haptics.coordinates import coordinates_from_pose, pose_from_coordinates
from fixplan.interactive.app import HapticApp, _wxyz, _xyz
from fixplan.interactive.gate import COOKIE, token_ok
from fixplan.interactive.handles import GizmoHandle
from fixplan.interactive.record import plan_json, verify_recording
from fixplan.interactive.session import HapticSession
from fixplan.present.browser import browser_available

browser = pytest.mark.skipif(browser_available() is not None, reason=str(browser_available()))


@pytest.fixture(scope="module")
def box():
    return fixplan.load(fixplan.default_fixture_path())


def gizmo_session(box, **options):
    handle = GizmoHandle(coordinates_from_pose(box.start, box.start.R_world_body))
    return handle, HapticSession(box, handle, **options)


def test_gizmo_moved_through_viser_is_the_device_and_loads_the_part(box):
    """A script moves the transform gizmo through viser's Python API, following the guidance."""
    handle, s = gizmo_session(box, realtime=False, synchronous=True, duration_s=10.0)
    app = HapticApp(s, port=0)
    app.start()
    app._stop.set()  # the test draws (and so reads the gizmo) itself, between ticks
    app._thread.join()
    app.always_draw = True
    try:
        s._warm_up()
        # the gizmo 2 mm beside the part: after one tick the part feels K·dx (the handle is still)
        dx = np.array([-2e-3, 0.0, 0.0])
        app.gizmo.position = _xyz(box.start.p_world) + dx
        app.draw()
        np.testing.assert_allclose(handle.pose[:3], box.start.p_world + dx, atol=1e-12)
        s._run_guide(s.snapshot)
        for _ in range(10):
            s.tick(0.0)
        assert s.trace.coupling_wrench[-1][0] < 0  # pulled toward the gizmo
        assert s.trace.felt_wrench[-1][0] == pytest.approx(-s.trace.coupling_wrench[-1][0])
        moves = 0
        last = None
        while s.status is None:
            g = s.guidance
            if g.push is not None:  # where the spring transmits the suggested push
                x_w, _ = s.coordinates()
                pose = pose_from_coordinates(x_w + g.push / s.K, s.R0, 3)
                app.gizmo.position, app.gizmo.wxyz = _xyz(pose.p_world), _wxyz(pose)
                # set where the gizmo already was, as it stores it (the part at rest under the same
                # push, within the gizmo's float32), it did not move
                now = (tuple(np.asarray(app.gizmo.position)), tuple(np.asarray(app.gizmo.wxyz)))
                moves += now != last
                last = now
            app.draw()
            for _ in range(10):
                s.tick(0.0)
                if s.status is not None:
                    break
        res = s.result()
    finally:
        app.stop()
    assert res.status == "reached", res.reason
    assert res.device == "mouse" and moves > 10 and handle.moves >= moves
    data = json.loads(json.dumps(plan_json(res, box)))
    v = verify_recording(box, data)
    assert v.passed, v.reason


def test_token_check():
    assert token_ok("/?token=s3cret-token", None, "s3cret-token") == (True, True)
    assert token_ok("/", f"{COOKIE}=s3cret-token; other=1", "s3cret-token") == (True, False)
    for path, cookie in (("/", None), ("/?token=wrong", None), ("/", f"{COOKIE}=wrong"), ("/", "garbage;;=")):
        assert token_ok(path, cookie, "s3cret-token")[0] is False


def test_token_gate_refuses_requests_and_websockets_without_the_token(box):
    import viser
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    _, s = gizmo_session(box, realtime=False, guidance=False)
    token = "tok-0123456789"
    app = HapticApp(s, host="127.0.0.2", port=0, token=token)  # any loopback address other than 127.0.0.1
    url = app.start()
    try:
        assert url.startswith("http://127.0.0.2:") and url.endswith(f"?token={token}")
        base = url.split("?")[0]
        with pytest.raises(urllib.error.HTTPError) as exc:
            urllib.request.urlopen(base, timeout=10)  # noqa: S310 - a local test server
        assert exc.value.code == 403
        with urllib.request.urlopen(url, timeout=10) as r:  # noqa: S310
            assert r.status == 200 and b"<html" in r.read(2000).lower()
            assert f"{COOKIE}={token}" in r.headers["Set-Cookie"]
        ws_url = base.replace("http://", "ws://")
        with pytest.raises(InvalidStatus):
            connect(ws_url, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10).close()
        with connect(ws_url, subprotocols=[f"viser-v{viser.__version__}"], additional_headers={"Cookie": f"{COOKIE}={token}"},
                     open_timeout=10) as ws:  # fmt: skip
            assert ws.recv(timeout=10)  # the scene arrives through the gate
        assert app.gate.refused == 2
        # viser itself listens on 127.0.0.1 only
        assert app.server.get_host() == "127.0.0.1"
    finally:
        app.stop()


@browser
@pytest.mark.browser
def test_page_renders_the_live_scene_and_fetches_nothing_from_outside(box, tmp_path):
    from PIL import Image

    from fixplan.interactive.browser import open_live_page

    # until_goal=False: the auto drive may reach the goal before Chromium has loaded the page (it
    # did on a busy machine: one frame drawn); the session keeps publishing while the page is open
    _, s = gizmo_session(box, duration_s=120.0, auto=True, until_goal=False)
    app = HapticApp(s, port=0)
    url = app.start()
    s.start()
    try:
        report = open_live_page(url, tmp_path / "haptic.png", hold_s=3.0)
    finally:
        s.stop()
        app.stop()
    assert report.errors == []
    assert report.requests and all(
        r.startswith(url.rstrip("/")) or r.startswith(("data:", "blob:")) for r in report.requests
    )
    assert report.canvases >= 1
    for word in ("fixplan haptic", "felt force", "normal force", "B1", "E1", "deadline misses", "auto"):
        assert word in report.text
    img = np.asarray(Image.open(report.screenshot).convert("RGB"), dtype=float)
    assert img.std() > 10.0  # not a flat page
    # the 3D view (left of the panel) has the part's blue and more than a few colours
    view = img[:, : int(img.shape[1] * 0.6)]
    assert len(np.unique(view.reshape(-1, 3), axis=0)) > 100
    assert app.frames > 10  # the display thread redrew while the page was open
