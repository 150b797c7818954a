"""The ``fixplan haptic`` web app: the session drawn live with viser, and its controls.

The scene: the workpiece, the locators (grey; red while pressed; green: the planner's next
target), the goal pose ghosted, contact normals at the locator tips, contact forces as orange
arrows, the device proxy (a green ghost of the part at the device's pose) joined to the part by
the virtual coupling drawn as a spring, and the suggested non-jamming push as a green arrow at
the centre of mass. With a ``[robot]``, the arm holding the part (a stick figure through its
joints, red while the part is where it does not reach), its joints solved per frame by
warm-started inverse kinematics at the display rate (:class:`fixplan.robot.follow.ArmFollower`),
never in the loop. With ``--device mouse`` the transform gizmo on the proxy is the device
handle. The panel: contact state with forces, felt force and moment, the verdict of the current
push (``classify``, with margin; a red JAMMED warning), the guidance, loop statistics, an
*auto* switch (the planner's executor drives), *reset*, and the mouse's stiffness slider
(bounded by the coupling's passivity).

A display thread redraws at :data:`DISPLAY_HZ` from the session's latest :class:`Snapshot`; it
only reads, so it never blocks the loop. viser serves its client from the installed package
(one self-contained page), so the page fetches nothing from elsewhere. With a token (``--host``
other than 127.0.0.1), viser listens on a private Unix socket and :mod:`.gate` is the only listener.
"""

from __future__ import annotations

import contextlib
import io
import sys
import threading
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError
from fixplan.haptics.coordinates import coordinates_from_pose
from fixplan.interactive.handles import GizmoHandle
from fixplan.interactive.session import HapticSession, Snapshot, real_time_priority
from fixplan.spatial import Pose, quaternion_wxyz_from_matrix

FloatArray = NDArray[np.float64]

DISPLAY_HZ = 30.0
PART = (74, 127, 181)
GOAL = (154, 165, 177)
PROXY = (44, 160, 44)
LOCATOR = (127, 127, 127)
PRESSED = (214, 39, 40)
TARGET = (44, 160, 44)
NORMAL = (51, 51, 51)
FORCE = (255, 127, 14)
SPRING = (120, 120, 120)
PUSH = (44, 160, 44)
ARM = (90, 90, 90)


def _mesh(fixture: Any) -> tuple[FloatArray, NDArray[np.int64]]:
    """Body-frame mesh of the workpiece (2D shapes extruded to a thin slab)."""
    from fixplan.present.meshes import part_mesh, shape_outline

    shape = fixture.workpiece.shape
    if fixture.dimension == 3:
        V, F = part_mesh(fixture)  # the shape with its holes' walls
        return np.asarray(V, dtype=float), np.asarray(F, dtype=np.int64)
    P = shape_outline(shape)
    n = len(P)
    h = 0.1 * shape.bounding_radius
    V = np.vstack([np.column_stack([P, np.full(n, -h)]), np.column_stack([P, np.full(n, h)])])
    tris = [(0, k + 1, k) for k in range(1, n - 1)] + [(n, n + k, n + k + 1) for k in range(1, n - 1)]
    for k in range(n):
        j = (k + 1) % n
        tris += [(k, j, n + j), (k, n + j, n + k)]
    return V, np.asarray(tris, dtype=np.int64)


def _xyz(p: FloatArray) -> FloatArray:
    p = np.asarray(p, dtype=float).reshape(-1)
    return p if p.shape[0] == 3 else np.array([p[0], p[1], 0.0])


def _R3(pose: Pose) -> FloatArray:
    R = pose.R_world_body
    if R.shape == (3, 3):
        return R
    out = np.eye(3)
    out[:2, :2] = R
    return out


def _wxyz(pose: Pose) -> FloatArray:
    return quaternion_wxyz_from_matrix(_R3(pose))


def spring_points(a: FloatArray, b: FloatArray, *, coils: int = 8, radius: float) -> FloatArray:
    """Line segments (N, 2, 3) of a helix from ``a`` to ``b`` (the coupling drawn as a spring)."""
    a, b = _xyz(a), _xyz(b)
    axis = b - a
    L = float(np.linalg.norm(axis))
    if L < 1e-9:
        return np.array([[a, b]])
    u = axis / L
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(u, ref)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    s = np.linspace(0.0, 1.0, coils * 12 + 1)
    r = radius * np.minimum(1.0, np.minimum(s, 1 - s) * 10)  # straight ends
    pts = (
        a
        + np.outer(s, axis)
        + np.outer(r * np.cos(2 * np.pi * coils * s), e1)
        + np.outer(r * np.sin(2 * np.pi * coils * s), e2)
    )
    return np.stack([pts[:-1], pts[1:]], axis=1)


def arrow_points(start: FloatArray, vec: FloatArray) -> FloatArray:
    """Segments of an arrow: the shaft and two head strokes."""
    s, v = _xyz(start), _xyz(vec)
    L = float(np.linalg.norm(v))
    if L < 1e-9:
        return np.array([[s, s]])
    u = v / L
    ref = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    side = np.cross(u, ref)
    side /= np.linalg.norm(side)
    tip = s + v
    h = 0.25 * L
    return np.array([[s, tip], [tip, tip - h * u + 0.5 * h * side], [tip, tip - h * u - 0.5 * h * side]])


class HapticApp:
    """The viser server, the scene, the panel and the display thread for one session."""

    def __init__(self, session: HapticSession, *, host: str = "127.0.0.1", port: int = 8080, token: str | None = None):
        self.session = session
        self.host = host
        self.port = port
        self.token = token
        self.server: Any = None
        self.gate: Any = None
        self._socket: Any = None  # the private folder of viser's Unix socket (with a token)
        self.gizmo: Any = None
        self.frames = 0
        self.skipped = 0
        self.always_draw = False  # draw even without a browser connected (tests that read the scene)
        self.display_s: list[float] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last: Snapshot | None = None
        self.arm: Any = None  # the fixture's arm following the part (fixplan.robot.follow.ArmFollower)
        self.arm_lines: Any = None

    # -- set-up ----------------------------------------------------------------------------------
    def start(self) -> str:
        """Start viser (behind the token gate when there is a token), draw the scene; the page's URL."""
        try:
            import viser
        except ImportError:  # pragma: no cover - viser is a dependency
            raise InputError("fixplan haptic needs viser: pip install viser") from None
        # viser's banner names where viser listens: fixplan prints the page's URL itself (the gate's,
        # with a token), so the banner is dropped, not moved to stderr
        if self.token is None:
            with contextlib.redirect_stdout(io.StringIO()):
                self.server = viser.ViserServer(host=self.host, port=self.port, label="fixplan haptic", verbose=False)
            bound = int(self.server.get_port())
            if self.port not in (0, bound):
                with contextlib.redirect_stdout(sys.stderr):
                    self.server.stop()
                raise InputError(f"HapticApp.port {self.port} is in use (choose another, or 0 for any free port)")
            url_port = bound
        else:
            from fixplan.interactive.gate import PrivateSocket, TokenGate, viser_on_unix_socket

            # viser on a socket only this user can reach, the gate the only listener (no TCP port without the token)
            self._socket = PrivateSocket()
            with contextlib.redirect_stdout(io.StringIO()), viser_on_unix_socket(self._socket.path):
                self.server = viser.ViserServer(host="127.0.0.1", port=0, label="fixplan haptic", verbose=False)
            self.gate = TokenGate(self.host, self.port, self._socket.path, self.token)
            url_port = self.gate.start()
        self._build_scene()
        self._build_panel()
        if self.session.realtime:

            @self.server.on_client_connect
            async def _(_client: Any) -> None:
                real_time_priority(20)  # viser's event-loop thread: the same reason as the display thread

        self._thread = threading.Thread(target=self._display_loop, name="fixplan-display", daemon=True)
        self._thread.start()
        host = "127.0.0.1" if self.host in ("0.0.0.0", "") else self.host  # noqa: S104 - shown URL only
        url = f"http://{host}:{url_port}/"
        return url + (f"?token={self.token}" if self.token else "")

    @property
    def url_port(self) -> int:
        return int(self.gate.port if self.gate is not None else self.server.get_port())

    def _build_scene(self) -> None:
        s = self.session
        fx = s.fixture
        sc = self.server.scene
        sc.set_up_direction("+z" if fx.dimension == 3 else "+y")
        V, F = _mesh(fx)
        self.bound = float(fx.workpiece.shape.bounding_radius)
        start = fx.start
        self.part = sc.add_mesh_simple(
            "/part", V, F, color=PART, opacity=0.85, position=_xyz(start.p_world), wxyz=_wxyz(start)
        )
        from fixplan.locating import located_pose

        goal = located_pose(fx)  # the file's, or a shaft's seated in its bore
        sc.add_mesh_simple("/goal", V, F, color=GOAL, opacity=0.25, position=_xyz(goal.p_world), wxyz=_wxyz(goal))
        self.proxy = sc.add_mesh_simple(
            "/proxy", V, F, color=PROXY, opacity=0.25, position=_xyz(start.p_world), wxyz=_wxyz(start)
        )
        self.locators = {}
        for loc in fx.locators:
            self.locators[loc.name] = sc.add_icosphere(
                f"/locators/{loc.name}", radius=float(loc.radius_m), color=LOCATOR, position=_xyz(loc.p_world)
            )
            sc.add_label(
                f"/labels/{loc.name}", loc.name, position=_xyz(loc.p_world) + np.array([0, 0, 2.5 * loc.radius_m])
            )
        from fixplan.present.meshes import fixture_meshes

        # pins and bores (world frame), coloured like the locators: red while pressing, green as the target
        for name, (V_pin, F_pin) in fixture_meshes(fx).items():
            self.locators[name] = sc.add_mesh_simple(f"/pins/{name}", V_pin, F_pin, color=LOCATOR, opacity=0.9)
            sc.add_label(f"/labels/{name}", name, position=V_pin.max(axis=0))
        self._colors = dict.fromkeys(self.locators, LOCATOR)
        z = np.zeros((1, 2, 3))
        t = 0.004 * self.bound
        self.normals = sc.add_line_segments("/normals", z, NORMAL, thickness=t)
        self.forces = sc.add_line_segments("/forces", z, FORCE, thickness=2 * t)
        self.spring = sc.add_line_segments("/spring", z, SPRING, thickness=t)
        self.push = sc.add_line_segments("/push", z, PUSH, thickness=3 * t)
        self._build_arm(2 * t)
        if isinstance(s.handle, GizmoHandle):
            self.gizmo = sc.add_transform_controls(
                "/handle", scale=1.2 * self.bound, position=_xyz(start.p_world), wxyz=_wxyz(start), depth_test=False
            )
            self._gizmo_seen = (self.gizmo.position.copy(), self.gizmo.wxyz.copy())

            @self.gizmo.on_update
            def _(_event: Any) -> None:
                self._gizmo_to_handle()

        # the camera looks at the fixture from the front, above
        anchors = [loc.p_world for loc in fx.locators] + [p.p_world for p in fx.pins] + [b.p_world for b in fx.bores]
        c = np.mean([_xyz(a) for a in anchors], axis=0)
        self.server.initial_camera.look_at = c
        if fx.dimension == 3:
            self.server.initial_camera.position = c + np.array([1.3, -2.0, 1.4]) * self.bound * 1.05
        else:  # the plane of motion, seen from the front (+z), y up
            self.server.initial_camera.position = c + np.array([0.0, -0.6, 3.0]) * self.bound * 1.4

    def _build_arm(self, thickness: float) -> None:
        """The arm's stick figure, at the start (nothing without a [robot] or where it cannot be loaded)."""
        fx = self.session.fixture
        if fx.robot is None or fx.dimension != 3:
            return
        from fixplan.robot.follow import ArmFollower
        from fixplan.robot_file import RobotError

        try:
            self.arm = ArmFollower(fx)
        except RobotError:
            return
        P = self.arm.skeleton_world()
        pts = np.zeros((1, 2, 3)) if P is None else np.stack([P[:-1], P[1:]], axis=1)
        self.arm_lines = self.server.scene.add_line_segments("/arm", pts, ARM, thickness=thickness)
        self._arm_color = ARM

    def _draw_arm(self, pose: Pose) -> None:
        """The arm at ``pose`` (warm-started IK from the last frame); red where it does not reach."""
        if self.arm is None:
            return
        self.arm.follow(pose)
        P = self.arm.skeleton_world()
        if P is not None:
            self.arm_lines.points = np.stack([P[:-1], P[1:]], axis=1)
        color = ARM if self.arm.reached else PRESSED
        if color != self._arm_color:
            self.arm_lines.colors = np.array(color, dtype=np.uint8)
            self._arm_color = color

    def _build_panel(self) -> None:
        s = self.session
        gui = self.server.gui
        with gui.add_folder("Session"):
            self.auto = gui.add_checkbox("auto (planner drives)", initial_value=s.auto, disabled=s.handle is None)
            self.reset = gui.add_button("reset to start")
            self.stiffness: Any = None
            if isinstance(s.handle, GizmoHandle):
                slider = gui.add_slider(
                    "stiffness ×", min=0.1, max=round(s.stiffness_scale_max, 2), step=0.05, initial_value=1.0
                )
                self.stiffness = slider

                @slider.on_update
                def _(_e: Any) -> None:
                    s.set_stiffness_scale(min(float(slider.value), s.stiffness_scale_max))

        @self.auto.on_update
        def _(_e: Any) -> None:
            s.set_auto(bool(self.auto.value))

        @self.reset.on_click
        def _(_e: Any) -> None:
            s.request_reset()
            if self.gizmo is not None:
                start = s.fixture.start
                self.gizmo.position = _xyz(start.p_world)
                self.gizmo.wxyz = _wxyz(start)
                self._gizmo_to_handle()

        self.verdict_md = gui.add_markdown("**verdict**: –")
        self.guidance_md = gui.add_markdown("**guidance**: planning…")
        self.contacts_md = gui.add_markdown("")
        self.felt_md = gui.add_markdown("")
        self.stats_md = gui.add_markdown("")

    # -- the gizmo is the handle -----------------------------------------------------------------
    def _gizmo_to_handle(self) -> None:
        s = self.session
        h = s.handle
        if not isinstance(h, GizmoHandle) or self.gizmo is None or s.auto:
            return
        p = np.asarray(self.gizmo.position, dtype=float)
        q = np.asarray(self.gizmo.wxyz, dtype=float)
        from fixplan.spatial import matrix_from_quaternion_wxyz

        R = matrix_from_quaternion_wxyz(q)
        pose = Pose(R, p) if s.dimension == 3 else Pose(R[:2, :2], p[:2])
        h.set_pose(coordinates_from_pose(pose, s.R0))
        self._gizmo_seen = (p.copy(), q.copy())

    # -- drawing ---------------------------------------------------------------------------------
    def _display_loop(self) -> None:
        # below the loop's priority, above other processes: a display thread preempted while it holds
        # the GIL would hold the loop up until the scheduler came back to it (priority inversion)
        if self.session.realtime:
            real_time_priority(20)
        period = 1.0 / DISPLAY_HZ
        next_t = time.perf_counter()
        while not self._stop.is_set():
            next_t += period
            t0 = time.perf_counter()
            try:
                self.draw()
            except Exception:  # noqa: BLE001 - a closing browser connection must not end the session
                if self._stop.is_set():
                    return
            self.display_s.append(time.perf_counter() - t0)
            delay = next_t - time.perf_counter()
            if delay > 0:
                self._stop.wait(delay)
            else:
                next_t = time.perf_counter()

    def draw(self) -> None:
        """Redraw from the session's latest snapshot (called by the display thread)."""
        s = self.session
        snap = s.snapshot
        if snap is None:
            return
        if not self.server.get_clients() and not self.always_draw:
            self.skipped += 1  # nobody is looking: no work that competes with the loop for the GIL
            return
        if self.gizmo is not None:
            if s.auto:  # the gizmo follows the simulated device, so that switching auto off does not jump
                self.gizmo.position = _xyz(snap.device_pose.p_world)
                self.gizmo.wxyz = _wxyz(snap.device_pose)
            else:
                p, q = np.asarray(self.gizmo.position), np.asarray(self.gizmo.wxyz)
                seen_p, seen_q = self._gizmo_seen
                if not (np.array_equal(p, seen_p) and np.array_equal(q, seen_q)):
                    self._gizmo_to_handle()  # moved through the Python API (a script)
        if snap is self._last:
            return
        self._last = snap
        fx = s.fixture
        from fixplan.present.meshes import contact_anchors

        pose = snap.pose
        with self.server.atomic():
            self.part.position = _xyz(pose.p_world)
            self.part.wxyz = _wxyz(pose)
            self.proxy.position = _xyz(snap.device_pose.p_world)
            self.proxy.wxyz = _wxyz(snap.device_pose)
            tips, normals = contact_anchors(fx, pose)  # per name: locators, then pins and bores
            tips3 = np.array([_xyz(t) for t in tips])
            n3 = np.array([_xyz(n) for n in normals])
            self.normals.points = np.stack([tips3, tips3 + 0.25 * self.bound * n3], axis=1)
            F = np.array([_xyz(f) for f in snap.forces_world_N])
            fmax = max(float(np.max(np.linalg.norm(F, axis=1), initial=0.0)), s.weight_N)
            scale = 0.8 * self.bound / fmax
            if np.any(np.linalg.norm(F, axis=1) > 1e-6):
                self.forces.points = np.stack([tips3, tips3 + scale * F], axis=1)
            else:
                self.forces.points = np.zeros((1, 2, 3))
            self.spring.points = spring_points(pose.p_world, snap.device_pose.p_world, radius=0.06 * self.bound)
            self._draw_arm(pose)
            g = snap.guidance
            com = _xyz(pose.point_world_from_body(fx.workpiece.com_body))
            if g.push is not None and snap.at_goal is False:
                self.push.points = arrow_points(com, scale * _xyz(g.push[: fx.dimension]))
            else:
                self.push.points = np.zeros((1, 2, 3))
            for name, handle in self.locators.items():
                color = PRESSED if name in snap.pressed else (TARGET if name == g.target else LOCATOR)
                if self._colors[name] != color:
                    handle.color = color
                    self._colors[name] = color
            self._panel(snap)
        self.frames += 1

    def _panel(self, snap: Snapshot) -> None:
        s = self.session
        d = s.dimension
        g = snap.guidance
        if s.clamp_phase:  # --clamp: the stage after the goal
            hand = "the hand holds the part" if s.clamp_phase.endswith("ramps") else "the hand has let go"
            verdict = f"<span style='color:#1f77b4'>**CLAMPING**</span>: {s.clamp_phase} ({hand})"
        elif snap.at_goal:
            verdict = f"<span style='color:#2ca02c'>**GOAL**</span>: {s.goal_words()}, at rest"
        elif snap.jammed:
            verdict = "<span style='color:#d62728'>**JAMMED**</span>: friction holds the part against this push — push another way"
        elif g.verdict is None:
            verdict = "**verdict**: –"
        else:
            margin = "" if g.margin is None else f", margin {g.margin:.3g}"
            if snap.speed_mps >= s.rest_speed_mps:  # classify judges a part at rest: say so while it moves
                verdict = f"verdict of the current push if the part stopped here: **{g.verdict}**{margin} (moving)"
            else:
                word = "<span style='color:#d62728'>**jammed**</span>" if g.verdict == "jammed" else f"**{g.verdict}**"
                verdict = f"verdict of the current push: {word}{margin}"
        self.verdict_md.content = verdict
        if g.target is not None:
            push = "" if g.push is None else " · push " + ", ".join(f"{x:.2f}" for x in g.push)
            guidance = f"**next**: press **{g.target}** ({g.motion}, transition {g.transition}){push}"
        else:
            guidance = f"**guidance**: {g.motion}" + (f" — {g.note}" if g.note else "")
        self.guidance_md.content = guidance + (" · **auto**" if snap.auto else "")
        rows = ["| locator | pressed | normal force [N] |", "|---|---|---:|"]
        for i, name in enumerate(s.names):
            rows.append(f"| {name} | {'●' if name in snap.pressed else '○'} | {snap.normal_forces_N[i]:.2f} |")
        self.contacts_md.content = "\n".join(rows)
        f = snap.felt_wrench
        self.felt_md.content = (
            f"**felt force** [N]: {', '.join(f'{x:.2f}' for x in f[:d])} (‖F‖ {np.linalg.norm(f[:d]):.2f})  \n"
            f"**felt moment** [N·m]: {', '.join(f'{x:.3f}' for x in f[d:])}"
        )
        st = snap.stats
        bridge = ""
        if snap.bridge:
            b = snap.bridge
            bridge = f"  \nbridge: {b['accepted']} poses, {b['malformed']} malformed, {b['out_of_order']} out of order"
        loop = (
            f"loop {st.ticks} ticks, mean {st.tick_mean_us:.0f} µs, p99 {st.tick_p99_us:.0f} µs, "
            f"{st.deadline_misses} deadline misses ({s.scheduling})"
            if st.ticks
            else "loop stepped by a script (no wall clock)"
        )
        rates = s.guidance_rates()
        loop += f"; guidance {rates['guidance_hz']:.0f} Hz, verdict {rates['verdict_hz']:.0f} Hz"
        self.stats_md.content = f"t = {snap.time_s:.2f} s · {loop}" + bridge

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self.gate is not None:
            self.gate.stop()
        if self.server is not None:
            with contextlib.redirect_stdout(sys.stderr):
                self.server.stop()
        if self._socket is not None:
            self._socket.close()
            self._socket = None
