"""One exception family for everything mocapfix refuses.

Every message names the file (and line or frame where known) and the cause, so the
CLI can print it as one line. The exit codes each command gives for them are in
docs/commands.md ("Exit codes"): a ``ConfigError`` is a usage error (2); a file that
cannot be read fails that file (``clean``: 1, the others go on; ``check``, ``info``: 3).
"""
from __future__ import annotations

import re
from pathlib import Path


def one_line(text) -> str:
    """``text`` (a path, a message naming one) with its line breaks shown as ``\\n``: a file
    named ``"a\\nb.bvh"`` must not split the line that names it in two."""
    return str(text).replace("\n", "\\n")


_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def printable(text: str) -> str:
    """``text`` with control characters shown as ``\\xNN``: a file named with an escape
    sequence (``"\\x1b[31m.bvh"``) must not recolour or rewrite the user's terminal, nor a
    name with a carriage return hide the line before it (tab and line break are kept)."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


#: the longest field (a number, a name) a text reader accepts: longer is a malformed file
MAX_FIELD = 1000
#: the longest reason an UnreadableFileError keeps (a reader quoting a file's garbage)
MAX_REASON = 1000


def excerpt(text, length: int = 40) -> str:
    """``text`` quoted (``repr``), cut to its first ``length`` characters with its full
    length said when longer: an error message quotes a file's garbage, never all of it."""
    text = str(text)
    if len(text) <= length:
        return repr(text)
    return f"{text[:length]!r}… ({len(text):,} characters)"


class MocapfixError(Exception):
    """Base class of every error mocapfix raises on purpose."""


class UnreadableFileError(MocapfixError):
    """A file cannot be read: missing, truncated, malformed or of an unknown format."""

    def __init__(self, path, reason: str, line: int | None = None):
        self.path = str(path) if path is not None else "<memory>"
        if len(reason) > MAX_REASON:
            reason = f"{reason[:MAX_REASON - 100]}… (cut: {len(reason):,} characters in all)"
        self.reason = reason
        self.line = line
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {reason}")


class UnsupportedFeatureError(UnreadableFileError):
    """A well-formed file uses a feature mocapfix does not support."""


class WriteError(MocapfixError):
    """A motion cannot be written to the requested file."""

    def __init__(self, path, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


class ConfigError(MocapfixError):
    """A pipeline configuration or cleaner parameter is invalid."""


def name_the_file(path, message) -> str:
    """``message`` as a per-file error, ``<path>: <cause>``: every ``ERROR`` line starts
    with the file it is about. A message that starts with the path is kept; one that only
    mentions it further on (a cleaner's ``step 1 (...): ... (PATH: ...)``) gets it in front
    as well, since a path in the middle of a line is easy to miss."""
    message = str(message)
    return message if message.startswith(str(path)) else f"{path}: {message}"


def display_path(path) -> str:
    return str(Path(path))
