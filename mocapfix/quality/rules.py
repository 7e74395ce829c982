"""Quality rules: validated YAML → warn/fail thresholds on measurements → a status.

One rule engine judges both what ``check`` measures on a capture as read
(:func:`mocapfix.quality.measure.measure_input`, stage ``input``) and what ``clean``'s report
measures after cleaning (:func:`mocapfix.quality.measure.measure_cleaning`, stage ``cleaned``).

Rules file::

    version: 1
    extends: [kinect]          # optional: preset names or paths whose rules come first
    formats: [kinect]          # optional: default format filter of the rules below
    exclude: ["*Angles"]       # optional: default include/exclude of the rules below
    unlabelled:                # optional: unlabelled trajectories (mocapfix.pipeline.unlabelled)
      judge: false             # true: judge them as markers (default: passed over)
      min_seen: 10 %           # seen on less of the take: unlabelled (0: off)
    rules:
      - metric: missing        # what to judge (see METRICS / `mocapfix configs --rules`)
        scope: joint           # joint (each joint/marker) or file (aggregated); default joint
        warn: 5 %              # WARN above this (FAIL for a metric judged from below)
        fail: 20 %
        formats: [c3d]         # optional: only for these formats
        include: ["L*"]        # optional: joint/marker name patterns (fnmatch)
        exclude: ["*:*"]
        name: markers-missing  # optional: the rule's name (default: the metric)

Thresholds carry units where the figure is physical: fractions as ``5 %`` (or a number
in [0, 1]), times as ``0.5 s`` / ``200 ms`` / ``10 frames``, lengths as ``20 mm``,
frequencies as ``60 Hz``, accelerations in m/s² (``15`` or ``15 m/s2``), counts as
integers. A bare number for a time, length or frequency is an error: there is no default
unit to guess. Unknown keys and metrics are errors naming the file and line.

Status words: ``OK``, ``WARN``, ``FAIL`` judge quality; ``ERROR`` (set by the callers)
means a file could not be read or processed at all.
"""
from __future__ import annotations

import fnmatch
import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from mocapfix.core.errors import ConfigError
from mocapfix.formats import FAMILIES, NAMES, matches
from mocapfix.core.presets import RULES_DIR, resolve_preset
from mocapfix.pipeline.unlabelled import Unlabelled
from mocapfix.core.yamlsafe import check_document, load_marked_yaml, read_bounded

STATUS_ORDER = {"OK": 0, "WARN": 1, "FAIL": 2}
RULES_VERSION = 1
_RULE_KEYS = {"metric", "scope", "warn", "fail", "formats", "include", "exclude", "name"}
_TOP_KEYS = {"version", "extends", "formats", "include", "exclude", "rules", "unlabelled"}


@dataclass(frozen=True)
class Metric:
    """A figure rules can judge. ``kind`` sets how thresholds are written and shown;
    ``below``: smaller is worse (frame rate); ``agg``: how joint figures make a file figure
    (``None``: a file-only figure)."""

    name: str
    stage: str          # "input" (check, info) or "cleaned" (clean's report)
    kind: str           # fraction | time | length | count | accel | frequency
    phrase: str         # "{v}" is the figure as shown
    help: str
    agg: str | None = "max"
    below: bool = False

    def joint_value(self, joint: dict, file: dict):
        return _GETTERS.get(self.name, lambda j, f: j.get(self.name))(joint, file)


def _get(*keys):
    def get(entry, file):
        for k in keys:
            if not isinstance(entry, dict):
                return None
            entry = entry.get(k)
        return entry
    return get


_GETTERS = {
    "never_seen": lambda j, f: int(bool(j.get("never_seen"))),
    "longest_gap": _get("longest_gap_s"),
    "correction": _get("correction_mm", "max"),
    "writeback": _get("writeback_residual_mm", "max"),
    "flagged": lambda j, f: (j["outliers_flagged"] / f["frames"]) if f.get("frames") else 0.0,
    "gaps_unfilled": lambda j, f: len(j["gaps"]["unfilled"]),
    "fill_bound": _get("fill_bound_mm"),
}

#: what a joint's entry says about why a metric's value is what it is, added to a finding
_DETAILS = {
    "correction": _get("correction_mm", "cause"),
}

METRICS = {m.name: m for m in (
    # what a capture is like as read
    Metric("missing", "input", "fraction", "{v} missing", "fraction of samples missing", "mean"),
    Metric("longest_gap", "input", "time", "longest gap {v}", "longest run of missing samples",
           "max"),
    Metric("gaps", "input", "count", "{v} gaps", "number of gaps (runs of missing samples)", "sum"),
    Metric("never_seen", "input", "count", "{v} never-seen markers/joints",
           "joints or markers with no sample at all", "sum"),
    Metric("outliers", "input", "fraction", "{v} outliers",
           "fraction of samples the spikes detector (defaults) flags", "mean"),
    Metric("jitter", "input", "accel", "jitter {v}", "RMS acceleration", "max"),
    Metric("bone_variation", "input", "fraction", "bone length varies by {v}",
           "std/mean of bone lengths (where bones are known)", "max"),
    Metric("dropped_frames", "input", "count", "{v} dropped frames",
           "frames missing between time stamps (Kinect time stamps)", None),
    Metric("timestamp_jumps", "input", "count", "{v} irregular time steps",
           "intervals longer than 1.5x the median, repeated or backward", None),
    Metric("held_frames", "input", "count", "{v} held frames",
           "frames that repeat the frame before them exactly (no new measurement)", None),
    Metric("cuts", "input", "count", "the take jumps as a whole at {v} frames",
           "frames where every point jumps at once (takes joined, a tracker that lost "
           "the subject)", None),
    Metric("swaps", "input", "count", "{v} suspected marker swaps",
           "label swaps the swaps cleaner finds (C3D)", None),
    Metric("fps", "input", "frequency", "frame rate {v}", "frame rate (judged from below)",
           None, below=True),
    # what a pipeline left (clean's report)
    Metric("missing_after", "cleaned", "fraction", "{v} still missing",
           "fraction of samples still missing after cleaning", "mean"),
    Metric("uncertain", "cleaned", "fraction", "{v} uncertain (missing in the input; a fill counts 1 − its confidence)",
           "fraction of frames not measured in the input (weighted by fill confidence)", "mean"),
    Metric("correction", "cleaned", "length", "a sample moved {v}",
           "largest move of a measured sample", "max"),
    Metric("flagged", "cleaned", "fraction", "{v} of samples flagged as outliers",
           "fraction of frames flagged by cleaners", "mean"),
    Metric("writeback", "cleaned", "length", "rotation write-back misses by up to {v}",
           "rotation write-back residual (BVH/AMC)", "max"),
    Metric("bone_variation_after", "cleaned", "fraction", "bone length varies by {v}",
           "bone length std/mean after cleaning", "max"),
    Metric("gaps_unfilled", "cleaned", "count", "{v} gaps left unfilled",
           "gaps no step filled completely", "sum"),
    Metric("fill_bound", "cleaned", "length", "a fill written may be off by {v} (90 % bound "
           "of its RMS error)", "largest calibrated 90 % error bound of a fill written", "max"),
    Metric("left_uncertain", "cleaned", "fraction", "{v} left unfilled as too uncertain to fill",
           "fraction of samples left missing because no fill could be trusted", "mean"),
)}

_FILE_ONLY_KEYS = {"dropped_frames": "dropped_frames", "timestamp_jumps": "timestamp_jumps",
                   "held_frames": "held_frames", "cuts": "cuts", "fps": "fps"}


def show(kind: str, value) -> str:
    if value is None:
        return "–"
    if kind == "fraction":
        return f"{100 * value:.1f} %"
    if kind == "time":
        return f"{value:.3g} s"
    if kind == "length":
        return f"{value:.1f} mm"
    if kind == "accel":
        return f"{value:.2f} m/s²"
    if kind == "frequency":
        return f"{value:g} Hz"
    return f"{value:g}" if isinstance(value, float) else str(value)


# -- thresholds --------------------------------------------------------------------------

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_WITH_UNIT = re.compile(rf"^\s*({_NUMBER})\s*([A-Za-z%/²2]*)\s*$")
_UNITS = {
    "time": {"s": 1.0, "ms": 0.001, "frames": None, "frame": None},
    "length": {"mm": 1.0, "cm": 10.0, "m": 1000.0},
    "frequency": {"hz": 1.0},
    "accel": {"m/s2": 1.0, "m/s²": 1.0, "": 1.0},
    "fraction": {"%": 0.01, "": 1.0},
    "count": {"": 1.0},
}


@dataclass(frozen=True)
class Threshold:
    value: float              # in the metric's unit (s, mm, Hz, m/s², fraction, count)
    frames: bool = False      # a time given in frames (converted with the file's fps)
    text: str = ""

    def resolve(self, fps) -> float:
        if self.frames:
            return self.value / fps if fps else math.inf
        return self.value


def parse_threshold(raw, metric: Metric, where: str) -> Threshold:
    kind = metric.kind
    if isinstance(raw, bool) or raw is None:
        raise ConfigError(f"{where}: expected a threshold, got {raw!r}")
    if isinstance(raw, (int, float)):
        number, unit = float(raw), ""
    elif isinstance(raw, str):
        m = _WITH_UNIT.match(raw)
        if not m:
            raise ConfigError(f"{where}: cannot read {raw!r} as a threshold for {metric.name}")
        number, unit = float(m.group(1)), m.group(2)
    else:
        raise ConfigError(f"{where}: expected a threshold, got {type(raw).__name__} {raw!r}")
    if not math.isfinite(number):
        raise ConfigError(f"{where}: {raw!r} is not a finite number")
    if number < 0:
        raise ConfigError(f"{where}: {raw!r} is negative")
    units = _UNITS[kind]
    key = unit.lower()
    if key not in units:
        if key == "" and kind in ("time", "length", "frequency"):
            raise ConfigError(f"{where}: {raw!r} needs a unit ({', '.join(u for u in units if u != 'frame')}) "
                              f"for {metric.name}")
        raise ConfigError(f"{where}: unit {unit!r} does not fit {metric.name} "
                          f"(use {', '.join(repr(u) for u in units if u)})" if any(units) else
                          f"{where}: {metric.name} is a plain count, got {raw!r}")
    factor = units[key]
    if kind == "fraction" and key == "" and number > 1:
        raise ConfigError(f"{where}: {raw!r} is a fraction above 1; write '{number:g} %' for a percentage")
    if factor is None:
        return Threshold(number, frames=True, text=f"{number:g} frames")
    value = number * factor
    if kind == "fraction" and value > 1:
        raise ConfigError(f"{where}: {raw!r} is above 100 % (a share cannot exceed it: the "
                          f"rule could never fire)")
    return Threshold(value, text=show(kind, value))


# -- rules -------------------------------------------------------------------------------

@dataclass
class Rule:
    name: str
    metric: Metric
    scope: str = "joint"
    warn: Threshold | None = None
    fail: Threshold | None = None
    formats: tuple | None = None
    include: tuple = ()
    exclude: tuple = ()
    where: str = ""

    def applies(self, fmt) -> bool:
        return self.formats is None or matches(fmt, self.formats)

    def selects(self, name: str) -> bool:
        if self.include and not any(fnmatch.fnmatchcase(name, p) for p in self.include):
            return False
        return not any(fnmatch.fnmatchcase(name, p) for p in self.exclude)

    def level(self, value, fps) -> tuple[str, Threshold | None]:
        if value is None or (isinstance(value, float) and not math.isfinite(value)):
            return "OK", None
        for level, th in (("FAIL", self.fail), ("WARN", self.warn)):
            if th is None:
                continue
            limit = th.resolve(fps)
            if (value < limit) if self.metric.below else (value > limit):
                return level, th
        return "OK", None

    def describe(self) -> dict:
        out = {"name": self.name, "metric": self.metric.name, "scope": self.scope}
        for key in ("warn", "fail"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key).text
        if self.formats:
            out["formats"] = list(self.formats)
        if self.include:
            out["include"] = list(self.include)
        if self.exclude:
            out["exclude"] = list(self.exclude)
        return out


@dataclass
class Finding:
    rule: str
    metric: str
    level: str
    value: float
    threshold: str
    message: str
    joint: str | None = None

    def as_dict(self) -> dict:
        out = {"rule": self.rule, "metric": self.metric, "level": self.level,
               "value": self.value, "threshold": self.threshold, "message": self.message}
        if self.joint is not None:
            out["joint"] = self.joint
        return out


@dataclass
class Judgement:
    status: str
    findings: list
    joint_status: dict = field(default_factory=dict)
    joint_reasons: dict = field(default_factory=dict)


def _line(raw) -> str:
    return f" (line {raw['__line__']})" if isinstance(raw, dict) and "__line__" in raw else ""


def _key_line(raw, key) -> str:
    lines = raw.get("__keylines__") if isinstance(raw, dict) else None
    if isinstance(lines, dict) and key in lines:
        return f" (line {lines[key]})"
    return _line(raw)


def _patterns(raw, key, where) -> tuple:
    value = raw.get(key)
    if value is None:
        return ()
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{where}: '{key}' must be a list of name patterns, got {value!r}")
    return tuple(value)


def _formats(value, where):
    if value is None:
        return None
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and (v in NAMES or v in FAMILIES)
                                                           for v in value):
        raise ConfigError(f"{where}: 'formats' must list some of {', '.join((*NAMES, *FAMILIES))}, "
                          f"got {value!r}")
    return tuple(value)


def _check_order(warn: Threshold | None, fail: Threshold | None, metric: Metric, where: str):
    """A WARN threshold beyond the FAIL one could never be reached (the FAIL is checked
    first): a config error rather than a rule that silently never warns. Thresholds in
    different units (frames and seconds) are left alone: their order depends on the file."""
    if warn is None or fail is None or warn.frames != fail.frames:
        return
    if (warn.value < fail.value) if metric.below else (warn.value > fail.value):
        side = "below" if metric.below else "above"
        raise ConfigError(f"{where}: warn {warn.text or warn.value} is beyond fail "
                          f"{fail.text or fail.value}; {metric.name} fails {side} its fail "
                          f"threshold first, so it could never warn")


def parse_rule(raw, where: str, stage: str | None = None, formats=None, include=(),
               exclude=()) -> Rule:
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: each rule is a mapping with 'metric' and 'warn'/'fail'")
    where = f"{where}{_line(raw)}"
    unknown = sorted(k for k in raw if k not in _RULE_KEYS and not str(k).startswith("__"))
    if unknown:
        first = unknown[0]
        raise ConfigError(f"{where.split(' (line')[0]}{_key_line(raw, first)}: unknown key(s) "
                          f"{', '.join(map(repr, unknown))} (known: {', '.join(sorted(_RULE_KEYS))})")
    name = raw.get("metric")
    if name not in METRICS:
        raise ConfigError(f"{where}: unknown metric {name!r} (known: {', '.join(METRICS)})")
    metric = METRICS[name]
    if stage is not None and metric.stage != stage:
        other = "`check` (a capture as read)" if metric.stage == "input" else "clean's report"
        raise ConfigError(f"{where}: metric {name!r} belongs to {other}, not here")
    scope = raw.get("scope", "joint" if metric.agg else "file")
    if scope not in ("joint", "file"):
        raise ConfigError(f"{where}: scope must be 'joint' or 'file', got {scope!r}")
    if scope == "joint" and metric.agg is None:
        raise ConfigError(f"{where}: metric {name!r} is measured per file only (scope: file)")
    if "warn" not in raw and "fail" not in raw:
        raise ConfigError(f"{where}: a rule needs 'warn' or 'fail' (or both)")
    warn = parse_threshold(raw["warn"], metric, f"{where}: warn") if "warn" in raw else None
    fail = parse_threshold(raw["fail"], metric, f"{where}: fail") if "fail" in raw else None
    _check_order(warn, fail, metric, where)
    rname = raw.get("name", name)
    if not isinstance(rname, str) or not rname:
        raise ConfigError(f"{where}: 'name' must be a non-empty string")
    return Rule(rname, metric, scope, warn, fail,
                _formats(raw["formats"], where) if "formats" in raw else formats,
                _patterns(raw, "include", where) if "include" in raw else tuple(include),
                _patterns(raw, "exclude", where) if "exclude" in raw else tuple(exclude), where)


@dataclass
class RuleSet:
    """Rules, and what ``check`` does with unlabelled trajectories (``unlabelled``: passed
    over unless its ``judge`` is set; a file's own ``unlabelled:`` wins over those of the
    files it extends)."""

    rules: list
    source: str = "<rules>"
    unlabelled: Unlabelled = field(default_factory=Unlabelled)

    def __len__(self):
        return len(self.rules)

    def describe(self) -> list[dict]:
        return [r.describe() for r in self.rules]

    def with_fail_on(self, overrides: list[str], stage: str = "input") -> "RuleSet":
        """Apply ``--fail-on RULE=VALUE``: set the fail threshold of every rule named RULE
        (or, if none, of the rules on metric RULE); add a rule if there is none."""
        rules = list(self.rules)
        for item in overrides:
            key, sep, value = item.partition("=")
            key = key.strip()
            if not sep or not key or not value.strip():
                raise ConfigError(f"--fail-on {item!r}: expected RULE=VALUE, e.g. missing=20%")
            hits = [n for n, r in enumerate(rules) if r.name == key] or \
                   [n for n, r in enumerate(rules) if r.metric.name == key]
            if hits:
                for n in hits:
                    rules[n] = replace(rules[n], fail=parse_threshold(
                        _number(value), rules[n].metric, f"--fail-on {item}"))
            else:
                rules.append(parse_rule({"metric": key, "fail": _number(value)},
                                        f"--fail-on {item}", stage))
        return replace(self, rules=rules)

    def judge(self, measured: dict) -> Judgement:
        """Judge ``{"file": {...}, "joints": [...]}`` (either stage). Joints marked
        ``"skipped"`` (model outputs, see :mod:`mocapfix.quality.measure`) are not judged."""
        file = measured["file"]
        joints = [j for j in measured["joints"] if not j.get("skipped")]
        fmt, fps = file.get("format"), file.get("fps")
        findings: list[Finding] = []
        joint_status = {j["name"]: "OK" for j in joints}
        joint_reasons: dict = {j["name"]: [] for j in joints}
        for rule in self.rules:
            if not rule.applies(fmt):
                continue
            m = rule.metric
            if rule.scope == "joint":
                for j in joints:
                    if not rule.selects(j["name"]):
                        continue
                    value = m.joint_value(j, file)
                    level, th = rule.level(value, fps)
                    if level != "OK":
                        detail = _DETAILS.get(m.name, lambda j, f: None)(j, file)
                        f = _finding(rule, level, value, th, j["name"], detail)
                        findings.append(f)
                        joint_reasons[j["name"]].append(f"{level}: {f.message}")
                        if STATUS_ORDER[level] > STATUS_ORDER[joint_status[j["name"]]]:
                            joint_status[j["name"]] = level
            else:
                value = _file_value(rule, file, joints)
                level, th = rule.level(value, fps)
                if level != "OK":
                    findings.append(_finding(rule, level, value, th, None))
        worst = max((STATUS_ORDER[f.level] for f in findings), default=0)
        status = next(k for k, v in STATUS_ORDER.items() if v == worst)
        return Judgement(status, findings, joint_status, joint_reasons)


def _number(text: str):
    text = text.strip()
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def _file_value(rule: Rule, file: dict, joints: list):
    m = rule.metric
    if m.agg is None:
        if m.name == "swaps":
            return len(file.get("swaps") or [])
        return file.get(_FILE_ONLY_KEYS.get(m.name, m.name))
    values = [m.joint_value(j, file) for j in joints if rule.selects(j["name"])]
    values = [v for v in values if v is not None and math.isfinite(v)]
    if not values:
        return None
    if m.agg == "sum":
        return sum(values)
    if m.agg == "mean":
        return sum(values) / len(values)
    return max(values)


def _finding(rule: Rule, level: str, value, th: Threshold, joint, detail=None) -> Finding:
    m = rule.metric
    shown = m.phrase.format(v=show(m.kind, value))
    if detail:
        shown = f"{shown} {detail}"
    where = f"{joint}: " if joint is not None else ""
    side = "below" if m.below else "above"
    message = f"{where}{shown} ({level.lower()} {side} {th.text}, rule {rule.name})"
    return Finding(rule.name, m.name, level, value, th.text, message, joint)


# -- loading -------------------------------------------------------------------------------

def preset_names() -> list[str]:
    return sorted(p.stem for p in RULES_DIR.glob("*.yaml"))


def resolve_rules_path(name_or_path) -> Path:
    """A rules file by path, or a shipped preset by name (``optical-gait``, or
    ``optical-gait.yaml`` as ``-c`` takes ``kinect.yaml``)."""
    return resolve_preset(name_or_path, RULES_DIR, "rules", preset_names())


def parse_rules(data, source: str = "<rules>", stage: str = "input", _chain: tuple = ()) -> RuleSet:
    """The rules of ``data`` (a parsed rules file) after those of the files it ``extends``;
    ``_chain``: the files being read that extend this one (a cycle is an error). An empty
    file is an error, as an empty config is (it judged every file OK with no rule: an
    unfinished or truncated file passed everything); ``rules: []`` judges nothing."""
    check_document(data, source, what="a rules file", body="rules", known=_TOP_KEYS,
                   kind="rules", version=RULES_VERSION, line_of=lambda key: _key_line(data, key))
    rules: list[Rule] = []
    unlabelled = Unlabelled()
    extends = data.get("extends") or []
    if isinstance(extends, str):
        extends = [extends]
    if not isinstance(extends, list):
        raise ConfigError(f"{source}: 'extends' must list preset names or paths")
    chain = (*_chain, source)
    if extends and len(chain) > 5:
        raise ConfigError(f"{source}: 'extends' nests too deep ({' -> '.join(chain)})")
    for parent in extends:
        base = Path(source).parent / str(parent) if source and not str(parent).isidentifier() else None
        path = base if base is not None and base.is_file() else resolve_rules_path(str(parent))
        seen = [c for c in chain if c and Path(c).exists() and Path(c).resolve() == Path(path).resolve()]
        if seen:
            raise ConfigError(f"{source}: 'extends' goes round in a circle: "
                              f"{' -> '.join((*chain[chain.index(seen[0]):], str(path)))}")
        parent = load_rules(path, stage, chain)
        rules += parent.rules
        if parent.unlabelled != Unlabelled():       # a parent that set it; the last one wins
            unlabelled = parent.unlabelled
    if "unlabelled" in data:
        unlabelled = Unlabelled.parse(data["unlabelled"], source, verb="judge")
    formats = _formats(data.get("formats"), source)
    include, exclude = _patterns(data, "include", source), _patterns(data, "exclude", source)
    items = data.get("rules") or []
    if not isinstance(items, list):
        raise ConfigError(f"{source}{_key_line(data, 'rules')}: 'rules' must be a list")
    for n, raw in enumerate(items, start=1):
        rules.append(parse_rule(raw, f"{source}: rule {n}", stage, formats, include, exclude))
    return RuleSet(rules, source, unlabelled)


def loads_rules(text: str, source: str = "<rules>", stage: str = "input") -> RuleSet:

    return parse_rules(load_marked_yaml(text, source), source, stage)


def load_rules(path, stage: str = "input", _chain: tuple = ()) -> RuleSet:

    path = Path(path)
    return parse_rules(load_marked_yaml(read_bounded(path, "rules"), str(path)), str(path), stage, _chain)


def default_rules(stage: str = "input") -> RuleSet:
    return load_rules(RULES_DIR / "default.yaml", stage)


# -- the clean report's thresholds (config ``report:`` section) ---------------------------

#: legacy threshold keys of the ``report:`` section → (metric, warn|fail)
REPORT_KEYS = {
    "warn_missing_after": ("missing_after", "warn"),
    "fail_missing_after": ("missing_after", "fail"),
    "warn_uncertain": ("uncertain", "warn"),
    "fail_uncertain": ("uncertain", "fail"),
    "warn_correction_mm": ("correction", "warn"),
    "fail_correction_mm": ("correction", "fail"),
    "warn_outlier_fraction": ("flagged", "warn"),
    "fail_outlier_fraction": ("flagged", "fail"),
    "warn_writeback_mm": ("writeback", "warn"),
    "fail_writeback_mm": ("writeback", "fail"),
    "warn_bone_variation": ("bone_variation_after", "warn"),
    "fail_bone_variation": ("bone_variation_after", "fail"),
    "warn_fill_bound_mm": ("fill_bound", "warn"),
    "fail_fill_bound_mm": ("fill_bound", "fail"),
    "warn_left_uncertain": ("left_uncertain", "warn"),
    "fail_left_uncertain": ("left_uncertain", "fail"),
}
#: (warn key, fail key) of each metric of the ``report:`` section
_REPORT_PAIRS = [(w, f) for w, (mw, lw) in REPORT_KEYS.items() if lw == "warn"
                 for f, (mf, lf) in REPORT_KEYS.items() if lf == "fail" and mf == mw]
DEFAULT_THRESHOLDS = {
    "warn_missing_after": 0.0,      # any sample still missing → WARN
    "fail_missing_after": 0.10,     # more than 10 % still missing → FAIL
    "warn_uncertain": 0.25,         # a quarter of a joint rebuilt, not measured → WARN
    "fail_uncertain": 0.75,         # three quarters rebuilt → FAIL
    "warn_correction_mm": 50.0,     # a measured sample moved more than this → WARN
    "warn_outlier_fraction": 0.05,  # more than 5 % of samples flagged → WARN
    "warn_writeback_mm": 1.0,       # rotation write-back residual above this → WARN
    "fail_writeback_mm": 20.0,
    "warn_bone_variation": 0.05,    # bone length std/mean after cleaning
    "warn_fill_bound_mm": 20.0,     # a fill written may be off by more (90 % bound) → WARN
                                    # (only with max_fill_error raised or null)
    "warn_left_uncertain": 0.0,     # any sample left as too uncertain to fill → WARN
}


#: defaults that differ by format (a config's ``report:`` keys still override them).
#: Kinect: the cleaning moves Tracked joints by ~1-2 cm and Inferred/occluded ones by up to
#: ~15 cm on good recordings (the 4 LabanotationSuite v2 files: largest move per joint
#: 48-147 mm; MSR Action3D 43-159 mm), while on recordings with glitches, leg confusion or
#: sparse rows many joints move by 20-70 cm (UTKinect: 5-17 joints > 200 mm;
#: KinectReader_joints, 32 % Inferred: 7 joints > 200 mm). 200 mm separates the two
#: groups; the 50 mm for optical markers flags every Kinect file. Outliers: the Kinect
#: step replaces glitching hands and wrists in place on good recordings too, up to 8.2 %
#: of a joint's frames on the 37-57-frame MSR files (2-4 samples; Laban 0-1.9 %), so a
#: joint warns above 10 % (5 % for optical markers).
FORMAT_THRESHOLDS = {"kinect": {"warn_correction_mm": 200.0, "warn_outlier_fraction": 0.10}}


def report_thresholds(section: dict | None = None, fmt: str | None = None) -> dict:
    """The clean report's thresholds for a file of format ``fmt``: the defaults, the
    format's own defaults, then the config's ``report:`` keys."""
    section = section or {}
    return {**DEFAULT_THRESHOLDS, **FORMAT_THRESHOLDS.get(fmt, {}),
            **{k: v for k, v in section.items() if k in REPORT_KEYS}}


def validate_report_section(data, source: str) -> dict:
    """Check a config's ``report:`` mapping: known threshold keys with finite, non-negative
    numbers, optionally ``rules:`` (a list of rules on cleaned-stage metrics) and ``viewer:`` (false: no 3D view in the HTML report). Returns
    the plain mapping (line marks stripped). Raises ConfigError naming the line."""
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: 'report' must be a mapping of thresholds")
    out: dict = {}
    for key, value in data.items():
        if str(key).startswith("__"):
            continue
        where = f"{source}: report{_key_line(data, key)}"
        if key == "rules":
            if not isinstance(value, list):
                raise ConfigError(f"{where}: 'rules' must be a list of rules")
            for n, raw in enumerate(value, start=1):
                parse_rule(raw, f"{source}: report rule {n}", "cleaned")
            out[key] = _strip(value)
            continue
        if key == "viewer":                 # the 3D view in the HTML report (default true)
            if not isinstance(value, bool):
                raise ConfigError(f"{where}: viewer must be true or false, got {value!r}")
            out[key] = value
            continue
        if key not in REPORT_KEYS:
            raise ConfigError(f"{where}: unknown key {key!r} (known: {', '.join(list(REPORT_KEYS) + ['rules', 'viewer'])})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise ConfigError(f"{where}: {key} must be a finite number >= 0, got {value!r}")
        if key.endswith(("_missing_after", "_uncertain", "_fraction", "_variation")) and value > 1:
            raise ConfigError(f"{where}: {key} is a fraction in [0, 1], got {value!r}")
        out[key] = float(value)
    merged = {**DEFAULT_THRESHOLDS, **out}
    for warn_key, fail_key in _REPORT_PAIRS:
        if warn_key in merged and fail_key in merged and merged[warn_key] > merged[fail_key]:
            given = [k for k in (warn_key, fail_key) if k in out]
            raise ConfigError(
                f"{source}: report{_key_line(data, given[0])}: {warn_key} {merged[warn_key]:g} is "
                f"above {fail_key} {merged[fail_key]:g}"
                + ("" if len(given) == 2 else f" (the default; set {fail_key} too)")
                + ": it could never warn")
    return out


def report_rules(section: dict | None = None, fmt: str | None = None) -> RuleSet:
    """The clean report's rules for a file of format ``fmt``: the thresholds of
    :func:`report_thresholds`, then the section's own ``rules:``."""
    section = section or {}
    th = report_thresholds(section, fmt)
    rules: list[Rule] = []
    by_metric: dict = {}
    for key, value in th.items():
        metric, level = REPORT_KEYS[key]
        by_metric.setdefault(metric, {})[level] = value
    for metric, levels in by_metric.items():
        m = METRICS[metric]
        kw = {lvl: Threshold(v, text=show(m.kind, v)) for lvl, v in levels.items()}
        rules.append(Rule(metric, m, "joint", kw.get("warn"), kw.get("fail"), where="report"))
    for n, raw in enumerate(section.get("rules") or [], start=1):
        rules.append(parse_rule(raw, f"report rule {n}", "cleaned"))
    return RuleSet(rules, "report")


def _strip(obj):
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if not str(k).startswith("__")}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj
