"""The scene figure: workpiece, locators, contact normals, force arrows, and the replay's frames.

:func:`scene_figure` draws a :class:`~fixplan.present.replay.Replay` (a plan's timeline, or the
start pose at rest) with plotly (3D: Mesh3d workpiece and locator tips; 2D: filled polygons);
:func:`~fixplan.present.page.write_scene` writes it as a page that fetches nothing.

Drawing conventions (one place):

- a locator's *tip* is the point of its sphere nearest the workpiece, ``p + ρ n``, with ``n`` the
  contact normal at that pose (from the locator into the workpiece); at contact it is the
  contact point;
- a contact-force arrow starts at the tip and is the force on the workpiece times
  :attr:`SceneInfo.force_scale_m_per_N` (one scale for the whole replay, so that the largest
  force is drawn :data:`FORCE_ARROW_FRACTION` of the workpiece's bounding radius long); the
  workpiece is drawn translucent, so arrows pointing into it stay visible;
- contact normals are drawn at every locator tip with a fixed length; locators pressed at a
  sample are highlighted.

plotly is imported inside the functions that need it, so ``import fixplan`` stays light.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.present.meshes import (
    fixture_meshes,
    locator_tips,
    part_mesh,
    points_world,
    shape_outline,
    sphere_mesh,
)

if TYPE_CHECKING:
    from fixplan.model import Fixture, RobotSpec
    from fixplan.present.replay import Replay
    from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

MAX_FRAMES = 150  # frames in the page's replay (a longer trace is subsampled evenly)
FORCE_ARROW_FRACTION = 0.8  # the largest force arrow, as a fraction of the workpiece's bounding radius
NORMAL_FRACTION = 0.25  # contact-normal length, as a fraction of the workpiece's bounding radius
COORD_DECIMALS = 7  # coordinates written to the page are rounded to 0.1 µm (keeps the page small)
FRAME_MS = 60  # display time per frame of the replay [ms]

# Colours
WORKPIECE = "#4a7fb5"
GOAL = "#9aa5b1"
LOCATOR = "#7f7f7f"
PRESSED = "#d62728"
NORMAL = "#333333"
FORCE = "#ff7f0e"
PUSH = "#2ca02c"
ARM = "#6b4c9a"  # the robot arm's stick figure
PATH = "#17becf"
CLAMP = "#9467bd"
CLAMP_ARROW_MAX_NORMALS = (
    6.0  # the longest clamp arrow, in contact-normal lengths (a big clamp force stays on the page)
)


def frame_indices(n_samples: int, max_frames: int = MAX_FRAMES) -> IntArray:
    """At most ``max_frames`` evenly spread sample indices, always the first and the last."""
    if n_samples <= 0:
        return np.zeros(0, dtype=np.int64)
    if n_samples <= max_frames:
        return np.arange(n_samples, dtype=np.int64)
    if max_frames < 2:
        return np.array([n_samples - 1], dtype=np.int64)
    return np.unique(np.round(np.linspace(0, n_samples - 1, max_frames)).astype(np.int64))


def force_scale(fixture: Fixture, replay: Replay) -> float:
    """Arrow length per newton [m/N]: the largest force (contact or push) spans a fixed part of the part's size."""
    biggest = 0.0
    if replay.forces_world_N is not None and replay.forces_world_N.size:
        biggest = float(np.linalg.norm(replay.forces_world_N, axis=-1).max())
    for _, f in replay.extra_forces:
        biggest = max(biggest, float(np.linalg.norm(f)))
    if replay.push_wrench is not None and replay.push_wrench.size:
        biggest = max(biggest, float(np.linalg.norm(replay.push_wrench[:, : fixture.dimension], axis=1).max()))
    if biggest <= 0.0:
        return 0.0
    return FORCE_ARROW_FRACTION * fixture.workpiece.shape.bounding_radius / biggest


def segments_xyz(starts: FloatArray, ends: FloatArray) -> list[list[float | None]]:
    """Coordinate lists (x, y[, z]) for plotly lines: one segment per row, separated by None."""
    starts = np.asarray(starts, dtype=float)
    ends = np.asarray(ends, dtype=float)
    d = starts.shape[1] if starts.ndim == 2 else 0
    out: list[list[float | None]] = [[] for _ in range(max(d, 0))]
    for a, b in zip(starts, ends, strict=True):
        for k in range(d):
            out[k] += [_r(a[k]), _r(b[k]), None]
    return out


def _r(x: float) -> float:
    return float(round(float(x), COORD_DECIMALS))


def _mesh3d(go: Any, V: FloatArray, F: IntArray, **style: Any) -> Any:
    """A plotly Mesh3d of vertices ``V`` (world, rounded) and triangles ``F``, with ``style``."""
    return go.Mesh3d(
        x=_rounded(V[:, 0]),
        y=_rounded(V[:, 1]),
        z=_rounded(V[:, 2]),
        i=F[:, 0].tolist(),
        j=F[:, 1].tolist(),
        k=F[:, 2].tolist(),
        **style,
    )


def _rounded(a: FloatArray) -> list[float]:
    return [float(x) for x in np.round(np.asarray(a, dtype=float), COORD_DECIMALS)]


# -- the figure ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class SceneInfo:
    """Facts about a built scene, also stored in the figure's ``layout.meta``."""

    source: str
    frames: int  # frames in the replay (0: a still scene)
    samples: int  # samples in the replay before subsampling
    force_scale_m_per_N: float
    traces: dict[str, int]  # trace name → index in fig.data


def scene_figure(
    fixture: Fixture,
    replay: Replay,
    *,
    max_frames: int = MAX_FRAMES,
    clamp_forces_N: dict[str, float] | None = None,
) -> Any:
    """The plotly figure of ``replay``: a still scene for one sample, else an animation.

    A fixture's ``[[clamp]]`` entries are drawn at the located pose (they act after loading):
    each tip and an arrow along its direction ending on the part, as long as its force at the
    contact forces' scale when ``clamp_forces_N`` gives it (``fixplan clamp``'s least forces),
    else of the normals' length; the labels name the clamps and their forces.

    Frames update only the traces that move (workpiece, pressed highlight, normals, forces,
    push); the axes are fixed over the whole replay. ``fig.layout.meta`` holds the
    :class:`SceneInfo` as a dictionary.
    """
    import plotly.graph_objects as go

    d = fixture.dimension
    shape = fixture.workpiece.shape
    scale = force_scale(fixture, replay)
    idx = frame_indices(len(replay), max_frames)
    animated = len(idx) > 1
    R = shape.bounding_radius
    normal_len = NORMAL_FRACTION * R
    names = [loc.name for loc in fixture.locators]
    centres = np.array([loc.p_world for loc in fixture.locators]).reshape(-1, d)

    if d == 3:
        V_body, F = part_mesh(fixture)  # the shape with its holes' walls
    else:
        outline = shape_outline(shape)

    def workpiece_trace(pose: Pose, *, ghost: bool = False) -> Any:
        if d == 3:
            V = points_world(pose, V_body)
            return _mesh3d(
                go,
                V,
                F,
                color=GOAL if ghost else WORKPIECE,
                opacity=0.15 if ghost else 0.35,
                flatshading=True,
                name="goal pose" if ghost else "workpiece",
                showlegend=True,
                hoverinfo="name",
            )
        P = points_world(pose, outline)
        P = np.vstack([P, P[:1]])
        return go.Scatter(
            x=_rounded(P[:, 0]),
            y=_rounded(P[:, 1]),
            mode="lines",
            fill="toself",
            fillcolor="rgba(154,165,177,0.15)" if ghost else "rgba(74,127,181,0.45)",
            line={"color": GOAL if ghost else WORKPIECE, "dash": "dash" if ghost else "solid"},
            name="goal pose" if ghost else "workpiece",
            hoverinfo="name",
        )

    def lines(starts: FloatArray, ends: FloatArray, name: str, color: str, width: float) -> Any:
        xyz = segments_xyz(starts, ends) if len(starts) else [[] for _ in range(d)]
        if d == 3:
            return go.Scatter3d(
                x=xyz[0], y=xyz[1], z=xyz[2], mode="lines", line={"color": color, "width": width}, name=name
            )
        return go.Scatter(x=xyz[0], y=xyz[1], mode="lines", line={"color": color, "width": width}, name=name)

    def arrows(starts: FloatArray, vectors: FloatArray, name: str, color: str) -> Any:
        """Shafts as lines; heads as markers at the ends (2D: arrow markers pointing along the shaft)."""
        starts = np.asarray(starts, dtype=float).reshape(-1, d)
        vectors = np.asarray(vectors, dtype=float).reshape(-1, d)
        keep = np.linalg.norm(vectors, axis=1) * scale > 1e-4 * R  # drop zero-length arrows
        starts, ends = starts[keep], starts[keep] + scale * vectors[keep]
        xyz = segments_xyz(starts, ends) if len(starts) else [[] for _ in range(d)]
        n = len(starts)
        if d == 3:
            size = [0, 4, 0] * n
            return go.Scatter3d(
                x=xyz[0],
                y=xyz[1],
                z=xyz[2],
                mode="lines+markers",
                line={"color": color, "width": 6},
                marker={"size": size, "color": color, "symbol": "diamond"},
                name=name,
            )
        return go.Scatter(
            x=xyz[0],
            y=xyz[1],
            mode="lines+markers",
            line={"color": color, "width": 3},
            marker={"size": [0, 12, 0] * n, "color": color, "symbol": "arrow", "angleref": "previous"},
            name=name,
        )

    if d == 3:
        loc_mesh, loc_owner = _locator_mesh(fixture, go)
    arm_points = _arm_skeletons(fixture, fixture.robot, replay, idx) if d == 3 and fixture.robot is not None else None

    def dynamic(k: int, *, full: bool = False) -> dict[str, Any]:
        """The traces that change from sample to sample, by name (``full``: complete traces, for fig.data)."""
        pose = replay.poses[k]
        tips, normals = locator_tips(fixture, pose)
        pressed = set(replay.pressed[k]) if replay.pressed else set()
        flags = [1 if n in pressed else 0 for n in names]
        if d == 3:
            # the locator spheres themselves turn red; a frame carries only the per-vertex intensity
            intensity = [flags[i] for i in loc_owner]
            highlight = loc_mesh.update(intensity=intensity) if full else go.Mesh3d(intensity=intensity)
        else:
            highlight = go.Scatter(
                x=_rounded(centres[:, 0]),
                y=_rounded(centres[:, 1]),
                mode="markers",
                marker={
                    "size": 9,
                    "color": [PRESSED if f else LOCATOR for f in flags],
                    "line": {"color": "black", "width": 1},
                },
                name="pressed (red)",
                hoverinfo="skip",
            )
        out = {
            "workpiece": workpiece_trace(pose),
            "locators": highlight,
            "normals": lines(tips, tips + normal_len * normals, "contact normals", NORMAL, 2),
        }
        if replay.forces_world_N is not None or replay.extra_forces:
            starts = [tips] if replay.forces_world_N is not None else []
            vecs = [replay.forces_world_N[k]] if replay.forces_world_N is not None else []
            for p, f in replay.extra_forces:
                starts.append(np.asarray(p, dtype=float).reshape(1, d))
                vecs.append(np.asarray(f, dtype=float).reshape(1, d))
            out["forces"] = arrows(np.vstack(starts), np.vstack(vecs), "contact forces", FORCE)
        if replay.push_wrench is not None:
            out["push"] = arrows(pose.p_world[None, :], replay.push_wrench[k, :d][None, :], "hand push (force)", PUSH)
        if arm_points is not None and k in arm_points:
            P = arm_points[k]
            out["arm"] = go.Scatter3d(
                x=_rounded(P[:, 0]), y=_rounded(P[:, 1]), z=_rounded(P[:, 2]), mode="lines+markers",
                line={"color": ARM, "width": 8}, marker={"size": 3, "color": ARM}, name="robot (joints)",
            )  # fmt: skip
        return out

    static: dict[str, Any] = {}
    if fixture.is_full:
        static["goal"] = workpiece_trace(fixture.goal, ghost=True)
    if d == 2:
        static["locator tips"] = _locator_bodies(fixture, go)
    static["locator names"] = _locator_labels(fixture, go)
    for name, (V_pin, F_pin) in fixture_meshes(fixture).items():  # pins and bores (world frame)
        static[f"pin {name}"] = _mesh3d(
            go, V_pin, F_pin, color=LOCATOR, opacity=0.9, flatshading=True, name=name, showlegend=True, hoverinfo="name"
        )
    if fixture.clamps:
        static.update(_clamp_traces(fixture, go, arrows, clamp_forces_N, scale, normal_len))
    if fixture.contacts:
        pts = np.array([c.point_world for c in fixture.contacts]).reshape(-1, d)
        nrm = np.array([c.normal_world for c in fixture.contacts]).reshape(-1, d)
        static["explicit contacts"] = lines(pts, pts + normal_len * nrm, "explicit contacts (normals)", NORMAL, 4)
    if animated:
        path = np.array([replay.poses[k].p_world for k in idx])
        if d == 3:
            static["path"] = go.Scatter3d(
                x=_rounded(path[:, 0]),
                y=_rounded(path[:, 1]),
                z=_rounded(path[:, 2]),
                mode="lines",
                line={"color": PATH, "width": 3, "dash": "dot"},
                name="body-origin path",
            )
        else:
            static["path"] = go.Scatter(
                x=_rounded(path[:, 0]),
                y=_rounded(path[:, 1]),
                mode="lines",
                line={"color": PATH, "width": 2, "dash": "dot"},
                name="body-origin path",
            )

    first = dynamic(int(idx[0]), full=True)
    order = list(static) + list(first)
    traces = {name: i for i, name in enumerate(order)}
    fig = go.Figure(data=[*static.values(), *first.values()])

    frames = []
    if animated:
        moving = [traces[name] for name in first]
        for k in idx:
            dyn = dynamic(int(k))
            frames.append(
                go.Frame(
                    name=f"{replay.time_s[k]:.3f}",
                    data=[dyn[name] for name in first],
                    traces=moving,
                )
            )
        fig.frames = frames

    info = SceneInfo(replay.source, len(frames), len(replay), scale, traces)
    title = f"{fixture.name}: {replay.note}"
    if scale > 0:
        kinds = [
            k
            for k, on in (
                ("orange: contact forces on the part", "forces" in first),
                ("green: the hand's push", "push" in first),
            )
            if on
        ]
        title += f"<br><sup>arrows: 1 N = {scale * 1e3:.3g} mm ({', '.join(kinds)})</sup>"
    if replay.policy:
        # the policy beside the scene: what the executor does in every contact state
        fig.add_annotation(
            text="<br>".join(replay.policy),
            xref="paper", yref="paper", x=0.0, y=0.0, xanchor="left", yanchor="bottom",
            align="left", showarrow=False, font={"size": 9}, bgcolor="rgba(255,255,255,0.7)",
        )  # fmt: skip
    fig.update_layout(
        title={"text": title, "x": 0.02, "xanchor": "left"},
        meta={
            "source": info.source,
            "frames": info.frames,
            "samples": info.samples,
            "force_scale_m_per_N": info.force_scale_m_per_N,
            "traces": info.traces,
        },
        legend={
            "x": 1.0,
            "xanchor": "right",
            "y": 0.98,
            "yanchor": "top",
            "bgcolor": "rgba(255,255,255,0.7)",
            "font": {"size": 11},
        },
        margin={"l": 10, "r": 10, "t": 60, "b": 10 + (90 if animated else 0)},
        paper_bgcolor="white",
    )
    lo, hi = _bounds(fixture, replay, idx, fig)
    if d == 3:
        span = hi - lo
        ratio = span / span.max()
        fig.update_layout(
            scene={
                "xaxis": {"title": {"text": "x [m]"}, "range": [lo[0], hi[0]]},
                "yaxis": {"title": {"text": "y [m]"}, "range": [lo[1], hi[1]]},
                "zaxis": {"title": {"text": "z [m]"}, "range": [lo[2], hi[2]]},
                "aspectmode": "manual",
                "aspectratio": {"x": ratio[0], "y": ratio[1], "z": ratio[2]},
                "camera": {"eye": {"x": -0.75, "y": -1.0, "z": 0.62}},
            }
        )
    else:
        fig.update_layout(
            xaxis={"title": {"text": "x [m]"}, "range": [lo[0], hi[0]], "constrain": "domain"},
            yaxis={"title": {"text": "y [m]"}, "range": [lo[1], hi[1]], "scaleanchor": "x", "scaleratio": 1},
            plot_bgcolor="white",
        )
    if animated:
        _add_controls(fig, [f.name for f in frames], [float(replay.time_s[k]) for k in idx], redraw=d == 3)
    return fig


def scene_info(fig: Any) -> SceneInfo:
    """The :class:`SceneInfo` stored in a figure built by :func:`scene_figure`."""
    meta = fig.layout.meta
    return SceneInfo(
        meta["source"], int(meta["frames"]), int(meta["samples"]), float(meta["force_scale_m_per_N"]), meta["traces"]
    )


def _locator_mesh(fixture: Fixture, go: Any) -> tuple[Any, list[int]]:
    """The locators' spheres as one Mesh3d, and the locator index of each vertex.

    A point locator is drawn small. The spheres are coloured by a 0/1 intensity (grey: open,
    red: pressed) that the frames update.
    """
    R = fixture.workpiece.shape.bounding_radius
    Vs, Fs, owner, base = [], [], [], 0
    for i, loc in enumerate(fixture.locators):
        V, F = sphere_mesh(loc.radius_m if loc.radius_m > 0 else 0.02 * R, rings=6, segments=10)
        Vs.append(V + loc.p_world)
        Fs.append(F + base)
        owner += [i] * len(V)
        base += len(V)
    V = np.vstack(Vs) if Vs else np.zeros((0, 3))
    F = np.vstack(Fs) if Fs else np.zeros((0, 3), dtype=np.int64)
    mesh = _mesh3d(
        go,
        V,
        F,
        intensity=[0] * len(V),
        intensitymode="vertex",
        colorscale=[[0.0, LOCATOR], [1.0, PRESSED]],
        cmin=0,
        cmax=1,
        showscale=False,
        flatshading=True,
        name="locators (red: pressed)",
        showlegend=True,
        hoverinfo="skip",
    )
    return mesh, owner


def _clamp_traces(
    fixture: Fixture,
    go: Any,
    arrows: Any,
    forces_N: dict[str, float] | None,
    scale_m_per_N: float,
    normal_len_m: float,
) -> dict[str, Any]:
    """The clamps: their tips (labelled with name and force) and arrows along their directions, ending on the part."""
    d = fixture.dimension
    tips = np.array([k.p_world for k in fixture.clamps]).reshape(-1, d)
    dirs = np.array([k.direction_world for k in fixture.clamps]).reshape(-1, d)
    ends = tips + np.array([k.radius_m for k in fixture.clamps])[:, None] * dirs  # where the tip meets the part
    if forces_N is not None and scale_m_per_N > 0.0:
        lengths = np.array([forces_N.get(k.name, 0.0) * scale_m_per_N for k in fixture.clamps])
    else:
        lengths = np.full(len(fixture.clamps), normal_len_m)
    lengths = np.clip(lengths, 0.25 * normal_len_m, CLAMP_ARROW_MAX_NORMALS * normal_len_m)  # 0 N still shows
    vectors = dirs * lengths[:, None]
    labels = [
        f"{k.name} {forces_N[k.name]:.3g} N" if forces_N is not None and k.name in forces_N else k.name
        for k in fixture.clamps
    ]
    text = {"text": labels, "mode": "markers+text", "textposition": "top center", "name": "clamps", "hoverinfo": "text"}
    marker = {"size": 6, "color": CLAMP, "symbol": "square"}
    if d == 3:
        tip_trace = go.Scatter3d(
            x=_rounded(tips[:, 0]), y=_rounded(tips[:, 1]), z=_rounded(tips[:, 2]), marker=marker, **text
        )
    else:
        tip_trace = go.Scatter(x=_rounded(tips[:, 0]), y=_rounded(tips[:, 1]), marker=marker | {"size": 9}, **text)
    # arrows() scales by the contact forces' scale; hand it vectors already in metres
    unit = scale_m_per_N if scale_m_per_N > 0.0 else 1.0
    return {"clamps": tip_trace, "clamp forces": arrows(ends - vectors, vectors / unit, "clamp pushes", CLAMP)}


def _locator_labels(fixture: Fixture, go: Any) -> Any:
    """The locators' names beside them."""
    d = fixture.dimension
    P = np.array([loc.p_world for loc in fixture.locators]).reshape(-1, d)
    common = {
        "mode": "text",
        "text": [loc.name for loc in fixture.locators],
        "textposition": "top center",
        "name": "locator names",
        "showlegend": False,
        "hoverinfo": "skip",
    }
    if d == 3:
        return go.Scatter3d(x=_rounded(P[:, 0]), y=_rounded(P[:, 1]), z=_rounded(P[:, 2]), **common)
    return go.Scatter(x=_rounded(P[:, 0]), y=_rounded(P[:, 1]), **common)


def _locator_bodies(fixture: Fixture, go: Any) -> Any:
    """The locators' circles (2D), a point locator drawn small."""
    R = fixture.workpiece.shape.bounding_radius
    xs: list[float | None] = []
    ys: list[float | None] = []
    a = np.linspace(0.0, 2.0 * np.pi, 33)
    for loc in fixture.locators:
        r = loc.radius_m if loc.radius_m > 0 else 0.02 * R
        xs += [*_rounded(loc.p_world[0] + r * np.cos(a)), None]
        ys += [*_rounded(loc.p_world[1] + r * np.sin(a)), None]
    return go.Scatter(
        x=xs,
        y=ys,
        mode="lines",
        fill="toself",
        fillcolor="rgba(127,127,127,0.6)",
        line={"color": LOCATOR},
        name="locator tips",
        hoverinfo="skip",
    )


def _arm_skeletons(fixture: Fixture, robot: RobotSpec, replay: Replay, idx: IntArray) -> dict[int, FloatArray] | None:
    """The arm's stick figure at each frame's part pose (inverse kinematics, each frame from the one before).

    None when the arm cannot be loaded or does not reach the first frame; a frame it does not
    reach keeps the last reached figure (the plan check names such a knot).
    """
    from fixplan.robot import Arm
    from fixplan.robot.check import first_configuration
    from fixplan.robot_file import RobotError

    try:
        arm = Arm(robot, fixture.gravity)
    except RobotError:
        return None
    out: dict[int, FloatArray] = {}
    q = None
    for k in idx:
        pose = replay.poses[int(k)]
        if q is None:
            q, err = first_configuration(arm, fixture, pose)
            if err > arm.settings.reach_tol_m:
                return None
        else:
            q_new, err = arm.ik(*arm.tool_target(pose), q)
            if err <= arm.settings.reach_tol_m:
                q = q_new
        out[int(k)] = arm.skeleton_world(q)
    return out


def _bounds(fixture: Fixture, replay: Replay, idx: IntArray, fig: Any) -> tuple[FloatArray, FloatArray]:
    """Axis ranges holding every trace of every frame, padded, so the view does not jump."""
    d = fixture.dimension
    pts = []
    for trace in [*fig.data, *(t for f in fig.frames for t in f.data)]:
        cols: list[Any] = [getattr(trace, c, None) for c in "xyz"[:d]]
        if any(c is None for c in cols):
            continue
        arr = np.array([[np.nan if v is None else float(v) for v in c] for c in cols], dtype=float).T
        if arr.size:
            pts.append(arr)
    P = np.vstack(pts)
    lo, hi = np.nanmin(P, axis=0), np.nanmax(P, axis=0)
    pad = 0.1 * float(np.max(hi - lo)) + 1e-3
    return np.round(lo - pad, 4), np.round(hi + pad, 4)


def _add_controls(fig: Any, names: list[str], times: list[float], *, redraw: bool) -> None:
    """Play/pause buttons and a time slider over the frames."""
    play = {
        "frame": {"duration": FRAME_MS, "redraw": redraw},
        "transition": {"duration": 0},
        "fromcurrent": True,
        "mode": "immediate",
    }
    pause = {"frame": {"duration": 0, "redraw": redraw}, "transition": {"duration": 0}, "mode": "immediate"}
    fig.update_layout(
        updatemenus=[
            {
                "type": "buttons",
                "direction": "left",
                "x": 0.0,
                "y": 0.0,
                "xanchor": "left",
                "yanchor": "top",
                "pad": {"t": 50, "r": 4},
                "showactive": False,
                "buttons": [
                    {"label": "▶ play", "method": "animate", "args": [None, play]},
                    {"label": "❚❚ pause", "method": "animate", "args": [[None], pause]},
                ],
            }
        ],
        sliders=[
            {
                "active": 0,
                "x": 0.22,
                "len": 0.78,
                "y": 0.0,
                "yanchor": "top",
                "pad": {"t": 30},
                "currentvalue": {"prefix": "t = ", "suffix": " s"},
                "steps": [
                    {"label": f"{t:.2f}", "method": "animate", "args": [[name], pause]}
                    for name, t in zip(names, times, strict=True)
                ],
            }
        ],
    )
