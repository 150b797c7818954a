"""Users' files: reading input text safely, writing outputs without losing a byte of theirs, and standard output.

Inputs: only regular files are opened (a named pipe would block forever, a device never ends),
at most :data:`~fixplan.limits.MAX_FILE_BYTES`, and decoded as UTF-8 with a message that names
what the file seems to be (HDF5, UTF-16, binary) instead of a ``UnicodeDecodeError``. Within a
command (:class:`CommandStreams`) every input read is remembered by device and inode.

Outputs: a path is writable when nothing is there, or a regular file is there and the user said
``--force``. A path that is a directory, a device (``/dev/full``), a pipe or a dangling symbolic
link is refused (the link would create a file outside the folder the user named), and several
outputs of one command must be distinct files (compared by inode, so a hard link to an input is
refused too). Every output goes through :func:`write_output`: written to a temporary file beside
it, flushed to the disk, and renamed onto it, so it never writes through a link onto another file
and a full disk leaves nothing half-written under the user's name. A target that is the same file
as an input of the command is refused, whatever option named it. Write errors name the path and
the reason.

Standard output: :class:`CommandStreams` turns a failed write (``/dev/full``, a closed pipe) into
one :class:`StdoutError` line instead of a traceback, and while a ``--json`` document owns
standard output it sends everything else printed (libraries, their threads and child processes)
to standard error; the document goes to :func:`document_stream`.
"""

from __future__ import annotations

import codecs
import contextlib
import errno
import hashlib
import io
import math
import os
import secrets
import select
import stat
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, TextIO, TypeVar

from fixplan.errors import FixplanError, InputError, shorten
from fixplan.limits import MAX_FILE_BYTES

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

T = TypeVar("T")


# the inputs read by the running command: (device, inode) -> its path as given; None outside a command
_inputs: dict[tuple[int, int], str] | None = None


def note_input(path: Path | str, info: os.stat_result | None = None) -> None:
    """Remember ``path`` as an input of the running command, so that no output replaces it.

    ``info``: its ``os.fstat`` when the caller holds it open (else the path is stat'ed). Readers of
    users' files call this (:func:`read_user_text` does); outside a command nothing is kept.
    """
    if _inputs is None:
        return
    try:
        info = os.stat(path) if info is None else info
    except OSError:
        return
    _inputs.setdefault((info.st_dev, info.st_ino), str(path))


def input_named(path: Path) -> str | None:
    """The input of the running command that ``path`` is (the same device and inode), else None."""
    if not _inputs:
        return None
    try:
        info = os.stat(path)
    except OSError:
        return None
    return _inputs.get((info.st_dev, info.st_ino))


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
    with open_user_file(path, expected=expected, max_bytes=max_bytes) as fh:
        try:
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
        # O_NONBLOCK: should the file have been swapped for a pipe since stat, open does not block
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        fh = os.fdopen(fd, "rb")
    except OSError as exc:
        raise UnreadableFile(path, exc.strerror or str(exc)) from None
    opened = os.fstat(fh.fileno())
    if not stat.S_ISREG(opened.st_mode):
        fh.close()
        raise UnreadableFile(path, f"is not a regular file (expected {expected})")
    note_input(path, opened)  # an output of this command never replaces it
    return fh


def file_sha256(path: Path, *, max_bytes: int = MAX_FILE_BYTES) -> str:
    """The SHA-256 (hex) of a user's file bytes, as read (at most ``max_bytes``); :class:`UnreadableFile` if it cannot be read."""
    try:
        with open(path, "rb") as fh:
            note_input(path, os.fstat(fh.fileno()))
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


def check_output(path: Path, force: bool, *, option: str = "check_output.path") -> Path:
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
        if (source := input_named(path)) is not None:
            raise InputError(
                f"{option} {path} is the same file as the input {source} (an output must not replace an input)"
            )
        if not force:
            raise InputError(f"{path} exists (use check_output.force to overwrite it)")
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
    """Run ``write`` on a temporary file beside ``path``, flush it to the disk, then rename it onto ``path``.

    The rename replaces the directory entry, so an output that is a link (hard or symbolic) to
    an input never writes through it onto the input, and a failed write (a full disk, reported
    by the write, the close or the flush to the disk) removes the temporary file and leaves
    ``path`` as it was: nothing half-written under the user's name. A ``path`` that is the same
    file as an input of the running command is refused, checked again just before the rename.
    The temporary name keeps the suffix (writers pick their format by it); a file replaced keeps
    its permissions. A failure is one line naming the path (:class:`InputError`).
    """
    path = Path(path)
    _refuse_input(path)
    tmp = temporary_path(path)
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        mode = None  # a new file: the writer's mode under the umask
    try:
        result = write(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:  # a full disk that only shows when the data reaches it fails here, before the rename
            os.fsync(fd)
        finally:
            os.close(fd)
        if mode is not None:
            os.chmod(tmp, mode)
        _refuse_input(path)
        os.replace(tmp, path)
        return result
    except OSError as exc:
        reason = exc.strerror or str(exc)
        if exc.errno == errno.ENOSPC:
            reason = "no space left on the device"
        raise InputError(f"cannot write {path}: {reason}") from None
    finally:
        if os.path.lexists(tmp):
            tmp.unlink()


def temporary_path(path: Path) -> Path:
    """A fresh hidden name beside ``path`` with its suffix, within the 255-byte limit of a file name."""
    mark = f".{os.getpid()}-{secrets.token_hex(4)}.tmp{path.suffix}"
    room = 255 - 1 - len(os.fsencode(mark))
    stem = os.fsencode(path.name)[: max(room, 0)].decode("utf-8", "ignore")
    return path.with_name(f".{stem}{mark}")


def _refuse_input(path: Path) -> None:
    if (source := input_named(path)) is not None:
        raise InputError(f"{path} is the same file as the input {source} (an output must not replace an input)")


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` as UTF-8 (see :func:`write_output`)."""
    write_output(path, lambda p: p.write_text(text, encoding="utf-8"))


# -- standard output ---------------------------------------------------------------------------
class StdoutError(FixplanError):
    """Standard output cannot be written (a full device, a closed pipe): what the command printed is lost."""


def _stdout_error(exc: OSError) -> StdoutError:
    reason = {errno.EPIPE: "the reader closed the pipe", errno.ENOSPC: "no space left on the device"}.get(
        exc.errno or 0, exc.strerror or str(exc)
    )
    return StdoutError(f"cannot write to standard output: {reason}")


class _GuardedFd(io.RawIOBase):
    """Writes to a file descriptor; the first failure raises :class:`StdoutError`, later writes are dropped.

    Dropping after the failure is what lets the interpreter's last flush pass quietly: whatever
    was still buffered can no longer reach the reader, and the failure was reported once.
    """

    def __init__(self, fd: int, *, owned: bool):
        super().__init__()
        self._fd, self._owned = fd, owned
        self.broken = False

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._fd

    def isatty(self) -> bool:
        try:
            return os.isatty(self._fd)
        except OSError:
            return False

    def write(self, data: Any) -> int:
        size = len(memoryview(data).cast("B"))
        if self.broken:
            return size
        while True:
            try:
                return os.write(self._fd, data)
            except BlockingIOError:  # a descriptor left non-blocking by whoever shares it: wait until it takes more
                select.select([], [self._fd], [])
            except OSError as exc:
                self.broken = True
                raise _stdout_error(exc) from None

    def close(self) -> None:
        if not self.closed and self._owned:
            os.close(self._fd)
        super().close()


def _text_stream(fd: int, like: TextIO | None, *, owned: bool) -> io.TextIOWrapper:
    encoding = getattr(like, "encoding", None) or "utf-8"
    errors = getattr(like, "errors", None) or "strict"
    line_buffering = bool(getattr(like, "line_buffering", False))
    return io.TextIOWrapper(
        io.BufferedWriter(_GuardedFd(fd, owned=owned)), encoding=encoding, errors=errors, line_buffering=line_buffering
    )


_document: TextIO | None = None


def document_stream() -> TextIO:
    """Where a command's ``--json`` document goes: standard output, also while library output goes to stderr."""
    return _document if _document is not None else sys.stdout


class CommandStreams:
    """Standard output and the inputs' record for one command (``with CommandStreams(document=...)``).

    On the process's own standard output, the command writes through a guard on a duplicate of
    file descriptor 1: a failure is one :class:`StdoutError` (exit 2) instead of ``OSError`` from
    deep in a library. With ``document=True`` (``--json``) file descriptor 1 points at standard
    error for the duration, so that whatever else prints (viser's messages from its thread,
    numba, Dask's worker processes) cannot break the JSON; the document is written with
    :func:`document_stream` to the real standard output. When standard output is not the
    process's (a test's capture), only ``sys.stdout`` is swapped. Call :meth:`flush` at the end
    of the command to learn whether the output arrived. Once standard output failed, file
    descriptor 1 points at /dev/null, so that what a library still buffers for it cannot fail
    again when the interpreter exits.
    """

    def __init__(self, *, document: bool):
        self.document = document
        self._saved: tuple[Any, TextIO | None, dict[tuple[int, int], str] | None] | None = None
        self._own: io.TextIOWrapper | None = None  # the guarded stream the command's output goes to
        self._fd1: int | None = None  # a duplicate of the real standard output, the guard's
        self._redirected = False  # file descriptor 1 points at standard error (--json)
        self._pending: StdoutError | None = None  # standard output had failed before the command

    def __enter__(self) -> CommandStreams:
        global _document, _inputs
        original = sys.stdout
        self._saved = (original, _document, _inputs)
        _inputs = {}
        if not (original is None or (original is sys.__stdout__ and _fileno(original) == 1)):
            if self.document:  # a capture (pytest, CliRunner): swap the Python objects only
                _document = original
                sys.stdout = sys.stderr
            return self
        try:
            self._fd1 = os.dup(1)
        except OSError:  # no standard output at all: the guard on 1 reports it on writing
            self._fd1 = None
        if original is not None:
            try:
                original.flush()
            except OSError as exc:
                self._pending = _stdout_error(exc)
                _silence_fd1()
        fd, owned = (1, False) if self._fd1 is None else (self._fd1, True)
        self._own = _text_stream(fd, original, owned=owned)
        if self.document:
            if self._fd1 is not None and self._pending is None:
                with contextlib.suppress(OSError):
                    os.dup2(2, 1)
                    self._redirected = True
            _document = self._own
        else:
            sys.stdout = self._own
        return self

    def flush(self) -> None:
        """Send what is buffered; :class:`StdoutError` when standard output did not take it."""
        if self._pending is not None:
            pending, self._pending = self._pending, None
            if not (self._own is not None and self._own.buffer.raw.broken):  # type: ignore[attr-defined]
                raise pending  # else the command's own write failed and said so
        if self._own is not None:
            self._own.flush()  # the guard turns a failure into StdoutError
        if self._saved is None:
            return
        for stream in (sys.stdout, self._saved[0]):
            if stream is None or stream is self._own or stream is sys.stderr:
                continue
            try:  # a library's own reference to the interpreter's stream, which the guard does not cover
                stream.flush()
            except OSError as exc:
                if self._redirected:
                    continue  # file descriptor 1 is standard error now: not the output's failure
                _silence_fd1()
                raise _stdout_error(exc) from None

    def __exit__(self, *exc: object) -> None:
        global _document, _inputs
        with contextlib.suppress(StdoutError):
            self.flush()  # a failure was reported by the caller's own flush, or is lost with the error it is part of
        if self._redirected and self._fd1 is not None:
            with contextlib.suppress(OSError):
                os.dup2(self._fd1, 1)
        if self._own is not None:
            with contextlib.suppress(OSError, StdoutError):
                self._own.close()
        if self._saved is not None:
            sys.stdout, _document, _inputs = self._saved


def _fileno(stream: Any) -> int | None:
    try:
        return stream.fileno()
    except (OSError, ValueError, AttributeError):
        return None


def _silence_fd1() -> None:
    """Point file descriptor 1 at /dev/null: what a library still buffers for it then goes nowhere, quietly."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.close(devnull)
    except OSError:
        pass


def read_plan_json(path: Path, *, expected: str) -> object:
    """The parsed JSON document of a plan file (strict JSON, see :func:`parse_strict_json`).

    Raises :class:`InputError` with a one-line reason when it is unreadable (not a regular file,
    over the size limit, not UTF-8) or not strict JSON; ``expected`` says what the file should be.
    """
    text = read_user_text(Path(path), expected=expected)
    return parse_strict_json(text, str(path))


class _Refused(ValueError):
    """A token strict JSON refuses, raised from inside the parser's hooks."""


def _json_depth(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in a JSON text, outside strings (linear time)."""
    import re

    import numpy as np

    # strings (with their escapes) removed first: a bracket inside one does not nest
    bare = re.sub(r'"(?:[^"\\]|\\.)*"', '""', text)
    data = np.frombuffer(bare.encode("utf-8", "replace"), dtype=np.uint8)
    step = np.zeros(len(data), dtype=np.int64)
    step[(data == ord("[")) | (data == ord("{"))] = 1
    step[(data == ord("]")) | (data == ord("}"))] = -1
    return int(np.cumsum(step).max()) if len(step) else 0


def _where(text: str, token: str) -> str:
    at = text.find(token)
    if at < 0:
        return ""
    line = text.count("\n", 0, at) + 1
    return f"line {line}, column {at - (text.rfind(chr(10), 0, at) + 1) + 1}: "


def parse_strict_json(text: str, source: str) -> object:
    """``text`` parsed as strict JSON, or :class:`InputError` with one line saying why not.

    Refused before or while parsing: nesting deeper than :data:`~fixplan.limits.MAX_JSON_DEPTH`,
    a number longer than :data:`~fixplan.limits.MAX_NUMBER_DIGITS` characters (Python's integer
    parser refuses 4,301 digits with an exception of its own), a number too large for a float,
    ``NaN`` / ``Infinity`` (not JSON; fixplan writes an unknown number as ``null``) and a key
    given twice in one object (which one would count?).
    """
    import json

    from fixplan.limits import MAX_JSON_DEPTH, MAX_NUMBER_DIGITS

    depth = _json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise InputError(f"{source}: JSON nested {depth} deep (expected at most {MAX_JSON_DEPTH}: not a fixplan plan)")

    def number(token: str) -> float | int:
        if len(token) > MAX_NUMBER_DIGITS:
            raise _Refused(f"a number of {len(token)} characters (expected at most {MAX_NUMBER_DIGITS})")
        value = float(token) if any(c in token for c in ".eE") else int(token)
        if isinstance(value, float) and not math.isfinite(value):
            raise _Refused(
                f"{_where(text, token)}the number {token} is too large for a float (expected a finite number)"
            )
        return value

    def constant(token: str) -> float:
        raise _Refused(f"{_where(text, token)}{token} is not JSON (expected a finite number; null for an unknown one)")

    def unique(pairs: list[tuple[str, object]]) -> dict[str, object]:
        out: dict[str, object] = {}
        for key, value in pairs:
            if key in out:
                raise _Refused(f"the key {shorten(key)} appears twice in one object (expected each key once)")
            out[key] = value
        return out

    try:
        return json.loads(text, parse_int=number, parse_float=number, parse_constant=constant, object_pairs_hook=unique)
    except _Refused as exc:
        raise InputError(f"{source}: not strict JSON: {exc}") from None
    except RecursionError:
        raise InputError(f"{source}: not a fixplan plan (JSON nested too deeply)") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{source}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None


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
