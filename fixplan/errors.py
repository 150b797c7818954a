"""Exceptions owned by fixplan.

Every failure a caller can act on is a :class:`FixplanError`. Third-party failures are
re-raised as one of these with ``raise ... from exc`` so callers never see a backend's
exception types.
"""

from __future__ import annotations

from dataclasses import dataclass


class FixplanError(Exception):
    """Base class of every error fixplan raises on purpose."""


def one_line(text: str) -> str:
    r"""``text`` with every non-printable character escaped (``\n``, ``\x1b``): one line, no terminal codes.

    File names, TOML keys and values come from users; a newline or an ANSI escape in them must
    not break the one-line ``FILE: key: message`` form or colour a terminal.
    """
    if text.isprintable():
        return text
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)


@dataclass(frozen=True)
class Issue:
    """One problem found in a fixture file.

    Attributes
    ----------
    key : str
        Dotted key path, e.g. ``locator.P1.position``.
    message : str
        What is wrong and what was expected.
    """

    key: str
    message: str

    def format(self, source: str) -> str:
        """The one-line form ``FILE: key: message`` used by every command."""
        return one_line(f"{source}: {self.key}: {self.message}")


class FixtureError(FixplanError):
    """A fixture file is malformed or physically impossible.

    Carries every :class:`Issue` found, not only the first, so that ``fixplan validate``
    can list them all.
    """

    def __init__(self, source: str, issues: list[Issue]):
        self.source = source
        self.issues = list(issues)
        super().__init__("\n".join(issue.format(source) for issue in self.issues))


class InputError(FixplanError):
    """A command-line or API argument is malformed (a wrench, a contact name, a range)."""


class InputFileError(InputError):
    """An input file other than a fixture (a wrench CSV) has problems; carries every one.

    Issues are keyed by place (``line 3``) and print as ``FILE: line 3: message``.
    """

    def __init__(self, source: str, issues: list[Issue]):
        self.source = source
        self.issues = list(issues)
        super().__init__("\n".join(issue.format(source) for issue in self.issues))


class InfeasibleError(FixplanError):
    """The question has no answer: no goal pose, no non-jamming wrench, no plan."""


class SolverError(FixplanError):
    """A numerical solver failed in a way the caller should know about."""

    def __init__(self, message: str, *, extras: dict | None = None):
        super().__init__(message)
        self.extras = dict(extras or {})


SHOWN_CHARS = 40  # a value quoted in a message is cut to this many characters


def shorten(text: str) -> str:
    """``repr(text)`` (escapes keep a message on one line), cut to a readable length."""
    shown = repr(text)
    return shown if len(shown) <= SHOWN_CHARS else shown[: SHOWN_CHARS - 1] + "…"


def quote_number(value: object) -> str:
    """A number as the user gave it, for "got ..." in a range message: never rounded to the limit.

    A float is shown with six significant digits when those read back as the same float and are
    no longer (``200``, ``1e+12``), else as ``repr`` — the shortest text that does — so ``mass = 10000.0001`` shows
    ``10000.0001`` where ``:g`` printed ``10000``, the limit itself. An integer
    shows its digits, text (a number as typed on the command line) is quoted as typed; either
    is cut to a readable length.
    """
    if isinstance(value, bool):
        return repr(value)
    if isinstance(value, int):
        shown = repr(value)
    elif isinstance(value, float):
        x = float(value)  # numpy's float64 too (its repr is np.float64(...))
        short, exact = f"{x:g}", repr(x)
        shown = short if float(short) == x and len(short) <= len(exact) else exact
    else:
        text = str(value).strip()
        return text if len(text) <= SHOWN_CHARS and text.isprintable() else shorten(text)
    return shown if len(shown) <= SHOWN_CHARS else shown[: SHOWN_CHARS - 1] + "…"
