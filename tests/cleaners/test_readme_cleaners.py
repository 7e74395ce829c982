"""The cleaner table of docs/configs.md (moved there from the README) says what the registry holds: every cleaner, its summary and
its parameters with their defaults (the table is written by hand; this keeps it true)."""
from __future__ import annotations

from mocapfix.cleaners import registry

from conftest import REPO

README = REPO / "docs" / "configs.md"


def test_every_cleaner_row_matches_the_registry():
    lines = README.read_text(encoding="utf-8").splitlines()
    wrong = []
    for name, cls in registry().items():
        row = f"| `{name}` | {cls.summary} | " + ", ".join(f"{p.name}={p.default}" for p in cls.params) + " |"
        if row not in lines:
            near = [line for line in lines if line.startswith(f"| `{name}` | {cls.summary}")]
            wrong.append(f"{name}: expected {row!r}, docs/configs.md has {near or 'no row'}")
    assert not wrong, "\n".join(wrong)
