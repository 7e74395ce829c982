"""The package's layers: every import — at the top of a module or inside a function —
goes down the layers or stays within one, and no modules import each other in a circle.

Layers, bottom to top (a module may import its own layer and the ones below):

==  ===========================================================================
0   ``mocapfix.core`` — Motion, kinematics, units, errors, files, YAML, threads
1   ``mocapfix.solvers`` — numerical kernels, arrays in and out
2   ``mocapfix.formats`` — readers and writers
3   ``mocapfix.cleaners`` — the cleaner classes over the kernels, and their registry
4   ``mocapfix.pipeline`` — steps run on a Motion, which points they clean
5   ``mocapfix.quality`` — measurements, rules, reports
6   ``mocapfix.config``, ``mocapfix.cleaning`` — YAML to a pipeline; clean one file
7   ``mocapfix.batch`` — discovery, planning, executors, the clean and check batches
8   ``mocapfix.bench``, ``mocapfix.train`` — benchmarks, model training
9   ``mocapfix.cli``, ``mocapfix.cli_options``, ``mocapfix.bench.cli`` — the commands;
    ``mocapfix`` (the public face)
==  ===========================================================================
"""
from __future__ import annotations

import ast
from pathlib import Path

from conftest import REPO

PACKAGE = REPO / "mocapfix"

LAYERS = [
    ("mocapfix.core",),
    ("mocapfix.solvers",),
    ("mocapfix.formats",),
    ("mocapfix.cleaners",),
    ("mocapfix.pipeline",),
    ("mocapfix.quality",),
    ("mocapfix.config", "mocapfix.cleaning"),
    ("mocapfix.batch",),
    ("mocapfix.bench", "mocapfix.train"),
    ("mocapfix.cli", "mocapfix.cli_options", "mocapfix.bench.cli", "mocapfix"),
]


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {module_name(p): p for p in PACKAGE.rglob("*.py")}


def layer_of(module: str) -> int:
    best, found = -1, None
    for n, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best:
                best, found = len(prefix), n
    assert found is not None, f"{module} is in no layer"
    return found


def imports_of(module: str) -> set[str]:
    """The mocapfix modules ``module`` imports anywhere in its code (a ``from X import y``
    that names a submodule counts as importing it)."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("mocapfix")}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[:len(package.split(".")) - node.level + 1]
                                + ([node.module] if node.module else []))
            if not base.startswith("mocapfix"):
                continue
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                out.add(sub if sub in MODULES else base)
    return {m for m in out if m in MODULES and m != module}


GRAPH = {m: imports_of(m) for m in MODULES}


def test_every_module_is_in_a_layer():
    for module in MODULES:
        layer_of(module)


def test_no_import_runs_up_the_layers():
    upward = sorted(f"{m} (layer {layer_of(m)}) imports {t} (layer {layer_of(t)})"
                    for m, targets in GRAPH.items() for t in targets
                    if layer_of(t) > layer_of(m) and m != "mocapfix")
    assert not upward, "\n".join(upward)


def _faces() -> set[str]:
    """Packages whose ``__init__`` only hands names on from their own modules: importing
    a submodule runs the face first, so its imports of the submodules are not edges."""
    return {m for m, p in MODULES.items() if p.name == "__init__.py"}


def test_no_modules_import_each_other_in_a_circle():
    faces = _faces()
    graph = {m: {t for t in targets if not (m in faces and t.startswith(m + "."))}
             for m, targets in GRAPH.items()}
    circles, state = [], {}

    def visit(m, stack):
        state[m] = "open"
        stack.append(m)
        for t in sorted(graph[m]):
            if state.get(t) == "open":
                circles.append(" -> ".join(stack[stack.index(t):] + [t]))
            elif t not in state:
                visit(t, stack)
        stack.pop()
        state[m] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m, [])
    assert not circles, "\n".join(circles)


def test_the_layer_table_knows_real_edges():
    """The test above can fail: the graph holds the imports it should (a known edge in
    each direction of concern)."""
    assert "mocapfix.core.motion" in GRAPH["mocapfix.pipeline.steps"]
    assert "mocapfix.quality.rules" in GRAPH["mocapfix.config"]
    assert layer_of("mocapfix.quality.rules") > layer_of("mocapfix.pipeline.steps")
