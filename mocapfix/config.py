"""A YAML config → a validated :class:`~mocapfix.pipeline.steps.Pipeline`.

Config shape (safe-loaded, bounded: :mod:`mocapfix.core.yamlsafe`)::

    version: 1
    pipeline:
      - cleaner: spikes
      - cleaner: fill_pca
        max_gap: 1.0 s
      - cleaner: butterworth
        cutoff: 6 Hz
        formats: [c3d, kinect]      # optional: run this step only on these formats
        exclude: ["Probe*"]         # optional: markers this step leaves alone
    markers: ["*"]                   # optional: markers the whole pipeline cleans
    exclude: [RASI]                  # optional: markers the whole pipeline leaves alone
    max_fill_error: 20 mm            # optional: a fill is written only when its calibrated
                                     # 90 % error bound is at most this (null: every fill)
    memory_budget: 1 GB              # optional: a longer take is cleaned in overlapping
                                     # windows (mocapfix.pipeline.windows; null: whole)
    unlabelled:                      # optional: unlabelled trajectories (mocapfix.pipeline.unlabelled)
      clean: false                   # true: clean them as markers (default false)
      min_seen: 10 %                 # seen on less of the take: unlabelled (0: off)
    report:                          # optional thresholds of the quality report
      warn_missing_after: 0.0        # keys: mocapfix.quality.rules.REPORT_KEYS
      ...

Errors name the file, the line and the key; a bare number for a physical parameter is
read in its default unit and noted in :data:`UNIT_WARNINGS`.
"""
from __future__ import annotations

from pathlib import Path

from mocapfix.cleaners import build
from mocapfix.cleaners.base import FittedCleaner
from mocapfix.core.errors import ConfigError
from mocapfix.core.presets import CONFIG_DIR
from mocapfix.core.yamlsafe import check_document, load_marked_yaml, read_bounded
from mocapfix.formats import FAMILIES, NAMES
from mocapfix.pipeline.selection import Selection
from mocapfix.pipeline.steps import (CONFIG_VERSION, DEFAULT_MAX_FILL_ERROR, Pipeline, Step,
                                     parse_max_fill_error)
from mocapfix.pipeline.unlabelled import Unlabelled
from mocapfix.pipeline.windows import DEFAULT_MEMORY_BUDGET, parse_memory_budget
from mocapfix.quality.rules import validate_report_section

_STEP_KEYS = {"cleaner", "formats", "name", "markers", "exclude"}
_TOP_KEYS = {"version", "pipeline", "report", "markers", "exclude", "unlabelled",
             "max_fill_error", "memory_budget"}


def _line_of(obj) -> str:
    return f" (line {obj['__line__']})" if isinstance(obj, dict) and "__line__" in obj else ""


def _strip_lines(obj):
    if isinstance(obj, dict):
        return {k: _strip_lines(v) for k, v in obj.items() if k not in ("__line__", "__keylines__")}
    if isinstance(obj, list):
        return [_strip_lines(v) for v in obj]
    return obj


def _config_folder(source: str) -> Path | None:
    """The folder model paths in a config are relative to (None for an in-memory config)."""
    path = Path(source)
    return path.parent if path.is_file() else None


def parse_config(data, source: str = "<config>") -> Pipeline:
    """Validate a loaded config (dict, possibly carrying ``__line__`` marks)."""
    check_document(data, source, what="a config", body="pipeline", known=_TOP_KEYS,
                   kind="config", version=CONFIG_VERSION)
    steps_data = data.get("pipeline")
    if not isinstance(steps_data, list):
        raise ConfigError(f"{source}: 'pipeline' must be a list of steps ([] for a report-only run)")
    steps = []
    for n, raw in enumerate(steps_data, start=1):
        where = f"{source}: step {n}{_line_of(raw)}"
        if not isinstance(raw, dict) or "cleaner" not in raw:
            raise ConfigError(f"{where}: each step is a mapping with a 'cleaner' key")
        odd = [k for k in raw if not isinstance(k, str)]
        if odd:
            raise ConfigError(f"{where}: parameter names must be words, got {odd[0]!r}")
        params = {k: _strip_lines(v) for k, v in raw.items()
                  if k not in _STEP_KEYS and k not in ("__line__", "__keylines__")}
        name = raw["cleaner"]
        if not isinstance(name, str):
            raise ConfigError(f"{where}: 'cleaner' must be a name, got {name!r}")
        _check_step_params(name, raw, params, f"{source}: step {n} ({raw.get('name') or name})")
        formats = raw.get("formats")
        if formats is not None:
            if isinstance(formats, str):
                formats = [formats]
            if not isinstance(formats, list) or not all(isinstance(f, str) and (f in NAMES or f in FAMILIES)
                                                        for f in formats):
                raise ConfigError(f"{where}: 'formats' must list some of "
                                  f"{', '.join((*sorted(NAMES), *FAMILIES))} (a family: its formats), "
                                  f"got {_strip_lines(formats)!r}")
            formats = tuple(formats)
        label = f"step {n} ({raw.get('name') or name}){_line_of(raw)}"
        cleaner = build(name, step=f"{source}: {label}", **params)
        if isinstance(cleaner, FittedCleaner):
            cleaner.resolve_models(_config_folder(source))
        cleaner.step = label.split(" (line")[0]
        steps.append(Step(cleaner, formats, raw.get("__line__"), Selection.parse(raw, where)))
    report = validate_report_section(data.get("report"), source)
    line = (data.get("__keylines__") or {}).get("max_fill_error")
    where = f"{source}{f' (line {line})' if line else ''}: max_fill_error"
    raw = data.get("max_fill_error", DEFAULT_MAX_FILL_ERROR)
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        UNIT_WARNINGS.append(f"{where}: {raw} has no unit; read as '{raw} mm' — write the "
                             "unit to say so")
    line = (data.get("__keylines__") or {}).get("memory_budget")
    budget = parse_memory_budget(_strip_lines(data.get("memory_budget", DEFAULT_MEMORY_BUDGET)),
                                 f"{source}{f' (line {line})' if line else ''}: memory_budget")
    return Pipeline(steps, report, source, Selection.parse(data, source),
                    Unlabelled.parse(data.get("unlabelled"), source),
                    parse_max_fill_error(_strip_lines(raw), where), budget)


def _check_step_params(name: str, raw: dict, params: dict, where: str) -> None:
    """An unknown parameter is named with its own line; a bare number for a physical
    parameter is read in the parameter's default unit and noted in ``UNIT_WARNINGS``."""
    from mocapfix.cleaners import lookup

    cls = lookup(name)
    if cls is None:
        return
    known = {p.name: p for p in cls.params}
    lines = raw.get("__keylines__") or {}
    for key in params:
        line = f" (line {lines[key]})" if key in lines else _line_of(raw)
        if key not in known:
            raise ConfigError(f"{where}{line}: unknown parameter {key!r} for cleaner '{name}' "
                              f"(known: {', '.join(known) or 'none'})")
        note = known[key].bare_number_note(params[key])
        if note:
            UNIT_WARNINGS.append(f"{where}{line}: {note}")


#: warnings of the last configs parsed (bare numbers for physical parameters); the CLI
#: prints and clears them
UNIT_WARNINGS: list[str] = []


def load_config(path) -> Pipeline:
    path = Path(path)
    return loads_config(read_bounded(path, "config"), str(path))


def loads_config(text: str | bytes, source: str = "<config>") -> Pipeline:
    """Parse a config's text (or its bytes, checked to be UTF-8) with bounded nesting and
    alias expansion (:func:`mocapfix.core.yamlsafe.load_marked_yaml`)."""
    return parse_config(load_marked_yaml(text, source), source)


def default_config_path() -> Path:
    return CONFIG_DIR / "default.yaml"
