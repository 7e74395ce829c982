"""One exception family for everything mocapfix refuses.

Every message names the file (and line or frame where known) and the cause, so the
CLI can print it as one line. The CLI maps ``UnreadableFileError`` and ``ConfigError``
to exit code 2.
"""
from __future__ import annotations

from pathlib import Path


def one_line(text) -> str:
    """``text`` (a path, a message naming one) with its line breaks shown as ``\\n``: a file
    named ``"a\\nb.bvh"`` must not split the line that names it in two."""
    return str(text).replace("\n", "\\n")


class MocapfixError(Exception):
    """Base class of every error mocapfix raises on purpose."""


class UnreadableFileError(MocapfixError):
    """A file cannot be read: missing, truncated, malformed or of an unknown format."""

    def __init__(self, path, reason: str, line: int | None = None):
        self.path = str(path) if path is not None else "<memory>"
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
