"""The layout of benchmarks/ (benchmarks/README.md): every script is documented, one-off
studies sit in benchmarks/studies/, and generated tables live in files their generator owns
under benchmarks/results/ — no script writes benchmarks/RESULTS.md, the hand-kept record."""
from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").exists())
BENCH = REPO / "benchmarks"
STUDIES = BENCH / "studies"
RESULTS_DIR = BENCH / "results"
README = BENCH / "README.md"

#: generator → its output option; the default must be a file of benchmarks/results/
GENERATORS = {"run_suite.py": "--out", "harm.py": "--markdown", "tsmc_tables.py": "--out",
              "kinect_tables.py": "--out", "feng2015_calibration.py": "--markdown"}

_ROW = re.compile(r"^\|\s*`([^`/]+\.(?:py|md))`")


def _readme_rows() -> dict[str, set[str]]:
    """{"## heading": names in the first cell of that section's table rows}."""
    sections: dict[str, set[str]] = {}
    heading = ""
    for line in README.read_text(encoding="utf-8").splitlines():
        if line.startswith("## "):
            heading = line[3:].strip()
        m = _ROW.match(line)
        if m:
            sections.setdefault(heading, set()).add(m.group(1))
    return sections


def _studies_heading(sections) -> str:
    found = [h for h in sections if h.lower().startswith("studies")]
    assert len(found) == 1, f"benchmarks/README.md needs one '## Studies …' section, has {found}"
    return found[0]


def test_every_benchmark_script_has_a_row_in_the_readme():
    sections = _readme_rows()
    studies = _studies_heading(sections)
    listed = set().union(*(names for h, names in sections.items() if h != studies))
    scripts = {p.name for p in BENCH.glob("*.py")}
    assert scripts, "no scripts found in benchmarks/"
    missing = sorted(scripts - listed)
    assert not missing, f"benchmarks/README.md has no row for {missing} (outside '## {studies}')"


def test_every_study_has_a_row_in_the_studies_section():
    sections = _readme_rows()
    studies = _studies_heading(sections)
    scripts = {p.name for p in STUDIES.glob("*.py")}
    assert scripts, "no scripts found in benchmarks/studies/"
    missing = sorted(scripts - sections[studies])
    assert not missing, f"benchmarks/README.md, '## {studies}', has no row for {missing}"


def test_every_readme_row_names_a_file_that_exists():
    sections = _readme_rows()
    studies = _studies_heading(sections)
    stale = []
    for heading, names in sections.items():
        for name in names:
            if name.endswith(".md"):
                continue
            folder = STUDIES if heading == studies else BENCH
            if not (folder / name).is_file():
                stale.append(f"{heading}: {name}")
    assert not stale, f"benchmarks/README.md lists scripts that are not there: {stale}"


def test_every_generated_file_has_an_owner_in_the_readme():
    text = README.read_text(encoding="utf-8")
    files = sorted(p.name for p in RESULTS_DIR.glob("*.md"))
    assert files, "no generated files in benchmarks/results/"
    for name in files:
        row = [line for line in text.splitlines() if line.startswith(f"| `results/{name}`")]
        assert row, f"benchmarks/README.md does not name the owner of results/{name}"
        owner = re.findall(r"`([\w/]+\.py)`", row[0])
        assert owner and (BENCH / owner[0]).is_file(), f"results/{name}: owner {owner} not found"


def _string_constants(path: Path):
    """Every string literal of the module's code (docstrings left out)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docstrings = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                docstrings.add(id(body[0].value))
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            yield node.value


def test_no_script_names_results_md_in_its_code():
    """RESULTS.md is hand-kept: a script may cite it in a docstring, never build its path."""
    offenders = [str(p.relative_to(REPO)) for p in sorted(BENCH.rglob("*.py"))
                 if any("RESULTS.md" in s or s == "RESULTS" for s in _string_constants(p))]
    assert not offenders, f"these scripts name RESULTS.md in code: {offenders}"


def _help(script: Path) -> str:
    env = dict(os.environ, COLUMNS="1000", OMP_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, str(script), "--help"], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"{script.name} --help failed:\n{proc.stderr[-2000:]}"
    return proc.stdout


@pytest.mark.parametrize("script,option", sorted(GENERATORS.items()))
def test_generators_write_their_own_file_under_results(script, option):
    out = _help(BENCH / script)
    m = re.search(re.escape(option) + r"\s+\S+\s+.*?\(default: ([^;)\s]+)", out)
    assert m, f"{script} --help does not show the default of {option}:\n{out}"
    default = Path(m.group(1)).resolve()
    assert default.parent == RESULTS_DIR.resolve(), f"{script} writes {default} by default"
    assert default.name != "RESULTS.md"


@pytest.mark.parametrize("script", sorted(p.name for p in STUDIES.glob("*.py")))
def test_studies_still_start(script):
    assert "usage:" in _help(STUDIES / script)
