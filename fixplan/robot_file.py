"""A fixture's robot (``[robot]``): the URDF it names, read into a pinocchio model, checked at load.

``urdf`` is either a path relative to the fixture file's folder (and inside it, as a mesh file
must be: :func:`fixplan.mesh_file.mesh_path`'s rule, for the same reasons), or the name of a
robot of example-robot-data (``panda``, ``ur5``, ...), which the optional extra
``fixplan[robots]`` installs. The file is read as every input is (a regular file, at most
:data:`~fixplan.limits.MAX_FILE_BYTES`), then parsed by pinocchio; its collision geometry
(primitives, or meshes beside the URDF) is read for the clearance check when it loads, and
left out with a note when it does not (a mesh the URDF names that is not there).

:func:`load_robot` caches by file (path, size, modification time) and tool frame: ``validate``,
``solve`` and a batch read one URDF once per process. The loaded model is not part of the
:class:`~fixplan.model.Fixture` (which stays a plain, picklable value): commands ask for it.
"""

from __future__ import annotations

import functools
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fixplan.errors import InputError
from fixplan.files import UnreadableFile, read_user_text
from fixplan.model import RobotSpec

ROBOT_NAME = re.compile(r"^[a-z][a-z0-9_]*$")  # a robot of example-robot-data, not a path
EXTRA = "pip install fixplan[robots]"


class RobotError(InputError):
    """A ``[robot]`` that cannot be used: its URDF is missing, unreadable or names no such frame."""


@dataclass(frozen=True)
class LoadedRobot:
    """A robot read from its URDF: pinocchio's model, its collision geometry, the tool frame.

    Attributes
    ----------
    model : pinocchio.Model
        Kinematics, inertias and limits (``effortLimit``, ``velocityLimit``, position limits).
    collision : pinocchio.GeometryModel or None
        The URDF's collision geometry; None when it could not be read (``collision_note`` says why).
    tool_frame : str
        The frame that holds the part.
    tool_frame_id : int
    source : str
        The URDF's path, or ``example-robot-data:<name>``.
    """

    model: Any
    collision: Any
    tool_frame: str
    tool_frame_id: int
    source: str
    collision_note: str = ""


def urdf_path(urdf: str, base_dir: Path) -> Path | None:
    """The file ``urdf`` names (relative to ``base_dir``, inside it), or None for a robot name."""
    if ROBOT_NAME.match(urdf) and not urdf.endswith(".urdf"):
        return None
    if Path(urdf).is_absolute():
        raise RobotError(f"{urdf!r} is an absolute path (expected a path relative to the fixture file's folder)")
    path = base_dir / urdf
    root, real = os.path.realpath(base_dir), os.path.realpath(path)
    if os.path.commonpath([root, real]) != root:
        raise RobotError(
            f"{urdf!r} is outside the fixture file's folder (it resolves to {real}; expected a file in that folder "
            "or below it, so that a fixture reads only what travels with it)"
        )
    return path


def robot_data_installed() -> bool:
    """Whether example-robot-data's loaders (the optional extra ``fixplan[robots]``) can be imported."""
    import importlib.util

    return importlib.util.find_spec("example_robot_data") is not None


def names_robot_data(path: Path) -> str | None:
    """The robot of example-robot-data a fixture file's ``[robot] urdf`` names (``"panda"``), else None.

    Read from the TOML alone (None where it does not parse): for a caller that must know, before
    loading the file, that it needs the extra.
    """
    import tomllib

    try:
        with open(path, "rb") as fh:
            robot = tomllib.load(fh).get("robot")
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return None
    urdf = robot.get("urdf") if isinstance(robot, dict) else None
    if isinstance(urdf, str) and ROBOT_NAME.match(urdf) and not urdf.endswith(".urdf"):
        return urdf
    return None


def load_robot(spec: RobotSpec) -> LoadedRobot:
    """The robot ``spec`` names, loaded (cached per file and tool frame); :class:`RobotError` when it cannot be."""
    if spec.urdf_path is None:
        return _named(spec.urdf, spec.tool_frame)
    try:
        stat = os.stat(spec.urdf_path)
        stamp = (stat.st_size, stat.st_mtime_ns)
    except OSError:
        stamp = (-1, -1)
    return _from_file(str(spec.urdf_path), stamp, spec.tool_frame)


@functools.lru_cache(maxsize=8)
def _from_file(path: str, stamp: tuple[int, int], tool_frame: str | None) -> LoadedRobot:
    import pinocchio as pin

    try:
        text = read_user_text(Path(path), expected="a URDF file")
    except UnreadableFile as exc:
        raise RobotError(f"{path}: cannot read: {exc.reason}") from None
    try:
        model = pin.buildModelFromXML(text)
    except (RuntimeError, ValueError) as exc:
        raise RobotError(f"{path}: not a URDF pinocchio can read ({_first_line(exc)})") from None
    collision, note = None, ""
    try:
        collision = pin.buildGeomFromUrdfString(
            model, text, pin.GeometryType.COLLISION, package_dirs=[str(Path(path).parent)]
        )
    except (RuntimeError, ValueError, OSError) as exc:
        note = f"its collision geometry was not read ({_first_line(exc)}); clearance is not checked"
    return _finish(model, collision, tool_frame, path, note)


@functools.lru_cache(maxsize=8)
def _named(name: str, tool_frame: str | None) -> LoadedRobot:
    try:
        import example_robot_data
    except ImportError:
        raise RobotError(
            f"{name!r} names a robot of example-robot-data, which is not installed ({EXTRA}); "
            "or give a URDF file relative to the fixture file"
        ) from None
    try:
        wrapper = example_robot_data.load(name)
    except (ValueError, KeyError, AttributeError, RuntimeError, ImportError, OSError) as exc:
        raise RobotError(f"{name!r} is not a robot of example-robot-data ({_first_line(exc)})") from None
    return _finish(wrapper.model, wrapper.collision_model, tool_frame, f"example-robot-data:{name}", "")


def _finish(model: Any, collision: Any, tool_frame: str | None, source: str, note: str) -> LoadedRobot:
    if model.nq == 0:
        raise RobotError(f"{source}: the robot has no joint (expected an arm with at least one)")
    if model.nq != model.nv:
        raise RobotError(
            f"{source}: a joint whose configuration is not its velocity (a free-flyer or a continuous joint: nq "
            f"{model.nq}, nv {model.nv}); expected revolute and prismatic joints"
        )
    names = [f.name for f in model.frames]
    frame = tool_frame if tool_frame is not None else names[-1]
    if not model.existFrame(frame):
        shown = ", ".join(names[-6:])
        raise RobotError(f"tool_frame {frame!r} is not a frame of {source} (its last frames: {shown})")
    return LoadedRobot(model, collision, frame, int(model.getFrameId(frame)), source, note)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else type(exc).__name__


__all__ = ["EXTRA", "LoadedRobot", "RobotError", "load_robot", "urdf_path"]
