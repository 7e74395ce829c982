"""The README and the guide in docs/ stay true and whole: every relative link (README to
docs/, docs pages to each other and to repository files) names a file that is there, and
an anchor a heading that is there; the README's shell and Python examples run, and so does
every ```sh/```bash/```python block of docs/, in a temporary folder holding a copy of
sample_data/, so a command that breaks fails CI (the README's two set-up commands with
`pip install` are run by .ci/run itself). A docs block that cannot run in CI says so and why
on the line before it: ``<!-- not run: reason -->``."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

README = REPO / "README.md"
PAGES = sorted((REPO / "docs").rglob("*.md"))
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


def _without_code(text: str) -> str:
    return FENCE.sub("", text)


def _slug(heading: str) -> str:
    """A heading's anchor as GitHub (and mkdocs' toc) makes it."""
    text = heading.strip().lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    return {_slug(m.group(1)) for m in re.finditer(r"^#+ (.+)$", _without_code(
        page.read_text(encoding="utf-8")), re.M)}


def test_the_readme_is_short():
    assert README.stat().st_size <= 12 * 1024, "README.md over 12 KB: move the detail into docs/"


def test_the_guide_has_its_pages():
    names = {p.name for p in PAGES}
    for page in ("index.md", "install.md", "formats.md", "configs.md", "reports.md", "check.md",
                 "batches.md", "models.md", "python.md", "troubleshooting.md", "benchmarks.md"):
        assert page in names
    nav = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    missing = [p.relative_to(REPO / "docs").as_posix() for p in PAGES
               if p.relative_to(REPO / "docs").as_posix() not in nav]
    assert not missing, f"docs pages missing from mkdocs.yml's nav: {missing}"


@pytest.mark.parametrize("page", [README, *PAGES], ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_relative_link_resolves(page):
    broken = []
    for target in LINK.findall(_without_code(page.read_text(encoding="utf-8"))):
        if re.match(r"[a-z]+:", target):
            continue                                    # https:, mailto:
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(target)
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            broken.append(target)
    assert not broken, f"{page.name}: links to nothing: {broken}"


RUNNABLE = {"sh": "shell", "bash": "shell", "python": "python"}
NOT_RUN = re.compile(r"<!--\s*not run:\s*(.*?)\s*-->\s*$")


def _doc_blocks():
    """(page, line, language, body, reason or None) of every runnable fenced block of docs/;
    the reason is that of a ``<!-- not run: reason -->`` on the line just before the fence
    (a blank line between them allowed)."""
    out = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        lines = text.splitlines()
        for m in FENCE.finditer(text):
            if m.group(1) not in RUNNABLE:
                continue
            line = text.count("\n", 0, m.start())              # 0-based line of the fence
            before = [s for s in lines[max(0, line - 2):line] if s.strip()]
            mark = NOT_RUN.search(before[-1]) if before else None
            out.append((page, line + 1, m.group(1), m.group(2), mark.group(1) if mark else None))
    return out


def _block_id(block):
    page, line, lang, _, _ = block
    return f"{page.relative_to(REPO).as_posix()}:{line}"


def test_every_not_run_marker_gives_a_reason_and_stands_before_a_block():
    blocks = _doc_blocks()
    assert blocks, "no runnable examples found in docs/"
    assert all(reason for *_, reason in blocks if reason is not None), "a 'not run' marker without a reason"
    marked = {(b[0], b[1]) for b in blocks if b[4] is not None}
    stray = []
    for page in PAGES:
        lines = page.read_text(encoding="utf-8").splitlines()
        for i, s in enumerate(lines):
            if "<!-- not run" in s:
                nxt = next((j for j in range(i + 1, len(lines)) if lines[j].strip()), None)
                if nxt is None or (page, nxt + 1) not in marked:
                    stray.append(f"{page.relative_to(REPO).as_posix()}:{i + 1}")
    assert not stray, f"'not run' markers not right before a sh/bash/python block: {stray}"


@pytest.mark.slow                                       # ~10 s: every docs example
@pytest.mark.parametrize("block", [b for b in _doc_blocks() if b[4] is None], ids=_block_id)
def test_the_docs_examples_run(block, workdir):
    cwd, env = workdir
    page, line, lang, body, _ = block
    if RUNNABLE[lang] == "shell":
        cmd = ["bash", "-euo", "pipefail", "-c", body]
    else:
        cmd = [sys.executable, "-c", body]
    run = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, (f"{_block_id(block)}: example failed (mark it "
                                 f"'<!-- not run: reason -->' only if CI cannot run it):\n{body}\n"
                                 f"{run.stdout[-2000:]}{run.stderr[-2000:]}")


def _readme_blocks(lang):
    return [body for kind, body in FENCE.findall(README.read_text(encoding="utf-8")) if kind == lang]


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    shutil.copytree(REPO / "sample_data", tmp_path / "sample_data")
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"   # mocapfix
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return tmp_path, env


@pytest.mark.slow                                       # ~10 s: every README command
def test_the_readme_shell_examples_run(workdir):
    cwd, env = workdir
    blocks = [b for b in _readme_blocks("bash") if "pip install" not in b]
    assert sum("mocapfix " in b for b in blocks) >= 4
    for body in blocks:
        run = subprocess.run(["bash", "-euo", "pipefail", "-c", body], cwd=cwd, env=env,
                             capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, f"README example failed:\n{body}\n{run.stdout[-2000:]}{run.stderr[-2000:]}"


@pytest.mark.slow
def test_the_readme_python_example_runs(workdir):
    cwd, env = workdir
    for body in _readme_blocks("python"):
        run = subprocess.run([sys.executable, "-c", body], cwd=cwd, env=env,
                             capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, f"README example failed:\n{body}\n{run.stderr[-2000:]}"


def test_the_readme_setup_commands_are_what_ci_runs():
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8")
    setup = [b.strip() for b in _readme_blocks("bash") if "pip install" in b]
    assert "pip install . && mocapfix clean sample_data -o cleaned --report json,md,html" in setup
    assert "pip install -e '.[dev]' && python -m pytest -q" in setup
    assert "pip install -q -e '.[dev]' && python -m pytest -q" in ci
    assert "pip install -q . && " in ci
    assert "mocapfix clean sample_data -o cleaned --report json,md,html" in ci


def test_troubleshooting_names_every_public_error_class():
    """Every public exception class of mocapfix/core/errors.py has its row in
    docs/troubleshooting.md: what it means and what to do."""
    import inspect

    from mocapfix.core import errors

    classes = [name for name, obj in vars(errors).items()
               if inspect.isclass(obj) and issubclass(obj, BaseException) and not name.startswith("_")
               and obj.__module__ == errors.__name__]
    assert "MocapfixError" in classes and "ConfigError" in classes
    page = (REPO / "docs" / "troubleshooting.md").read_text(encoding="utf-8")
    rows = {m.group(1) for m in re.finditer(r"^\| `(\w+)`", page, re.M)}
    missing = [name for name in classes if name not in rows]
    assert not missing, f"docs/troubleshooting.md has no row for: {missing}"
