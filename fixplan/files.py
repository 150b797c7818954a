"""Users' files: reading input text safely, and checking output paths before anything is written.

Inputs: only regular files are opened (a named pipe would block forever, a device never ends),
at most :data:`~fixplan.limits.MAX_FILE_BYTES`, and decoded as UTF-8 with a message that names
what the file seems to be (HDF5, UTF-16, binary) instead of a ``UnicodeDecodeError``.

Outputs: a path is writable when nothing is there, or a regular file is there and the user said
``--force``. A path that is a directory, a device (``/dev/full``), a pipe or a dangling symbolic
link is refused (the link would create a file outside the folder the user named), and several
outputs of one command must be distinct files (compared by inode, so a hard link to an input is
refused too). An output is written to a temporary file beside it and renamed onto it, never
through a link onto another file. Write errors name the path and the reason.
"""

from __future__ import annotations

import codecs
import errno
import hashlib
import os
import secrets
import stat
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, TypeVar

from fixplan.errors import InputError
from fixplan.limits import MAX_FILE_BYTES

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

T = TypeVar("T")


class UnreadableFile(InputError):
    """An input file cannot be read as text; ``reason`` says why in words for a message."""

    def __init__(self, path: Path, reason: str):
        self.path = path
        self.reason = reason
        super().__init__(f"{path}: cannot read: {reason}")


def read_user_text(path: Path, *, expected: str, max_bytes: int = MAX_FILE_BYTES) -> str:
    """The text of a user's input file, or :class:`UnreadableFile` with a one-line reason.

    Parameters
    ----------
    expected : str
        What the file should be, for messages: ``"a .toml fixture file"``.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise UnreadableFile(path, "no such file") from None
    except OSError as exc:
        raise UnreadableFile(path, exc.strerror or str(exc)) from None
    if stat.S_ISDIR(info.st_mode):
        raise UnreadableFile(path, f"is a directory (expected {expected})")
    if not stat.S_ISREG(info.st_mode):
        raise UnreadableFile(path, f"is not a regular file but {_file_kind(info.st_mode)} (expected {expected})")
    if info.st_size > max_bytes:
        raise UnreadableFile(
            path, f"is {info.st_size} bytes, larger than the limit of {max_bytes} bytes (expected {expected})"
        )
    try:
        # O_NONBLOCK: should the file have been swapped for a pipe since stat, open does not block
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
                raise UnreadableFile(path, f"is not a regular file (expected {expected})")
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise UnreadableFile(path, exc.strerror or str(exc)) from None
    if len(data) > max_bytes:
        raise UnreadableFile(path, f"is larger than the limit of {max_bytes} bytes (expected {expected})")
    return decode_text(path, data, expected=expected)


def open_user_file(path: Path, *, expected: str, max_bytes: int) -> BinaryIO:
    """A user's input file opened for binary reading, checked as :func:`read_user_text` checks it.

    Only a regular file of at most ``max_bytes`` bytes (a directory, pipe or device is refused
    with a one-line :class:`UnreadableFile`), opened without blocking. The caller reads it (a
    mesh reads its header first) and closes it.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise UnreadableFile(path, "no such file") from None
    except OSError as exc:
        raise UnreadableFile(path, exc.strerror or str(exc)) from None
    if stat.S_ISDIR(info.st_mode):
        raise UnreadableFile(path, f"is a directory (expected {expected})")
    if not stat.S_ISREG(info.st_mode):
        raise UnreadableFile(path, f"is not a regular file but {_file_kind(info.st_mode)} (expected {expected})")
    if info.st_size > max_bytes:
        raise UnreadableFile(
            path, f"is {info.st_size} bytes, larger than the limit of {max_bytes} bytes (expected {expected})"
        )
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        fh = os.fdopen(fd, "rb")
    except OSError as exc:
        raise UnreadableFile(path, exc.strerror or str(exc)) from None
    if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
        fh.close()
        raise UnreadableFile(path, f"is not a regular file (expected {expected})")
    return fh


def file_sha256(path: Path, *, max_bytes: int = MAX_FILE_BYTES) -> str:
    """The SHA-256 (hex) of a user's file bytes, as read (at most ``max_bytes``); :class:`UnreadableFile` if it cannot be read."""
    try:
        with open(path, "rb") as fh:
            return hashlib.sha256(fh.read(max_bytes + 1)).hexdigest()
    except OSError as exc:
        raise UnreadableFile(path, exc.strerror or str(exc)) from None


def decode_text(path: Path, data: bytes, *, expected: str) -> str:
    """``data`` decoded as UTF-8 (a UTF-8 byte-order mark is dropped), or :class:`UnreadableFile`."""
    if data.startswith(b"\x89HDF\r\n\x1a\n"):
        raise UnreadableFile(path, f"is an HDF5 file (expected {expected}; FCLib problems are read by 'fixplan fclib')")
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)) or (
        len(data) >= 4 and (data[1::2][:2] == b"\0\0" or data[0::2][:2] == b"\0\0")
    ):
        raise UnreadableFile(path, f"is UTF-16 text (expected {expected} in UTF-8: save it as UTF-8)")
    if b"\0" in data:
        raise UnreadableFile(path, f"is a binary file (expected {expected})")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise UnreadableFile(
            path, f"is not UTF-8 text: byte 0x{data[exc.start]:02x} on line {line} (expected {expected} in UTF-8)"
        ) from None
    return text.removeprefix("\ufeff")


def _file_kind(mode: int) -> str:
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a special file"


def check_output(path: Path, force: bool, *, option: str = "--out") -> Path:
    """Refuse an output path that would lose a user's file or write where they did not ask.

    Returns ``path``; creates its missing parent folders. Nothing is written here.
    """
    if path.is_symlink() and not path.exists():
        raise InputError(
            f"{option} {path} is a dangling symbolic link to {os.readlink(path)} "
            "(writing would create a file elsewhere; remove the link or choose another path)"
        )
    if path.exists():
        info = os.stat(path)
        if stat.S_ISDIR(info.st_mode):
            raise InputError(f"{option} {path} is a directory (expected a file path)")
        if not stat.S_ISREG(info.st_mode):
            raise InputError(
                f"{option} {path} is {_file_kind(info.st_mode)}, not a regular file (expected a file path)"
            )
        if not force:
            raise InputError(f"{path} exists (use --force to overwrite it)")
    parent = path.parent
    if parent.is_symlink() and not parent.exists():
        raise InputError(f"{option} {path}: the folder {parent} is a dangling symbolic link")
    if parent.exists() and not parent.is_dir():
        raise InputError(f"{option} {path}: {parent} is not a directory")
    if not parent.exists():
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{option} {path}: cannot create the folder {parent}: {exc.strerror or exc}") from None
    return path


def check_distinct(outputs: Sequence[tuple[str, Path | None]]) -> None:
    """Refuse two paths of one command that are the same file: an output would replace an input or another output.

    ``outputs`` lists ``(option, path)`` pairs, inputs first; ``None`` paths are skipped.
    """
    seen: dict[object, str] = {}
    for option, path in outputs:
        if path is None:
            continue
        key: object = Path(os.path.abspath(path))
        try:
            key = Path(os.path.abspath(path)).resolve()
            info = os.stat(key)
            key = (info.st_dev, info.st_ino)  # an existing file: by inode, so a hard link is the same file
        except OSError:  # not there yet (or a loop of links): by its resolved path
            pass
        if key in seen:
            raise InputError(
                f"{option} {path} is the same file as {seen[key]} (an output must not replace an input or another output)"
            )
        seen[key] = f"{option} {path}"


def write_output(path: Path, write: Callable[[Path], T]) -> T:
    """Run ``write`` on a temporary file beside ``path``, then rename it onto ``path``.

    The rename replaces the directory entry, so an output that is a link (hard or symbolic) to
    an input never writes through it onto the input, and a failed write leaves no half file. The
    temporary name keeps the suffix (writers pick their format by it). A failure (disk full,
    permission) is one line naming the path.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{path.suffix}")
    try:
        result = write(tmp)
        os.replace(tmp, path)
        return result
    except OSError as exc:
        reason = exc.strerror or str(exc)
        if exc.errno == errno.ENOSPC:
            reason = "no space left on the device"
        raise InputError(f"cannot write {path}: {reason}") from None
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` as UTF-8 (see :func:`write_output`)."""
    write_output(path, lambda p: p.write_text(text, encoding="utf-8"))


def read_plan_json(path: Path, *, expected: str) -> object:
    """The parsed JSON document of a plan file.

    Raises :class:`InputError` with a one-line reason when it is unreadable, not JSON or nested
    too deeply; ``expected`` says what the file should be.
    """
    import json

    text = read_user_text(Path(path), expected=expected)
    try:
        return json.loads(text)
    except RecursionError:
        raise InputError(f"{path}: not a fixplan plan (JSON nested too deeply)") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None


def read_wrench_csv(path: Path, n: int) -> NDArray[np.float64]:
    """Wrenches from a CSV file, one per line; every bad line is reported (FILE: line K: ...)."""
    import numpy as np

    from fixplan import limits
    from fixplan.errors import InputFileError, Issue

    text = read_user_text(path, expected=f"a CSV file of wrenches, {n} numbers per line")
    rows = []
    issues: list[Issue] = []
    ranges = limits.wrench_ranges(n)
    seen_data = False
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            rows.append(limits.parse_numbers(line, "wrench", n, ranges))
        except InputError as exc:
            # a header line is allowed as the first non-empty line
            if not seen_data and not any(ch.isdigit() for ch in line.replace("Fx", "")):
                seen_data = True
                continue
            issues.append(Issue(f"line {lineno}", str(exc)))
        seen_data = True
        if len(issues) >= 100:
            issues.append(Issue("...", "more bad lines not shown (stopped after 100)"))
            break
    if issues:
        raise InputFileError(str(path), issues)
    if not rows:
        raise InputError(f"{path}: no wrenches (expected one wrench of {n} numbers per line)")
    return np.array(rows)
