"""Bounded YAML loading for configs and rule files.

A YAML document can ask for far more work than its size suggests: an alias "bomb"
(``a: &a [x, x]``, ``b: &b [*a, *a]``, … — the "billion laughs" of XML) is a few hundred
bytes that expand to billions of nodes when anything walks the loaded data; a deeply nested
``[[[[…]]]]`` makes PyYAML's composer and constructor, and any recursive walk of the result,
exceed Python's recursion limit; a byte that is not UTF-8 makes ``str.decode`` raise.

:func:`load_yaml` checks all of that on the parser's event stream (a flat sequence,
walked with an explicit stack: no recursion, one pass, O(size of the text)) *before*
anything is composed or constructed, and turns every failure into one
:class:`~mocapfix.core.errors.ConfigError` naming the source and, where known, the line:

* the text must be UTF-8 (a UTF-8 byte-order mark is allowed) and at most ``max_bytes``;
* nesting deeper than ``max_depth`` collections is refused;
* the nodes that aliases add when expanded (an alias counts the full size of what it
  names, aliases inside it included) must stay within ``alias_budget``; an alias to a
  collection that is still open (a recursive structure) or to an undefined anchor is
  refused;
* a key may appear only once in a mapping (YAML requires it; PyYAML would silently keep
  the last value, so ``max_gap: 0.5 s`` followed by ``max_gap: 5 s``, or a second
  ``pipeline:``, would change the run without a word); merge keys ``<<`` are exempt;
* only the safe tags are constructed (``yaml.SafeLoader`` or a subclass).
"""
from __future__ import annotations

import re

import yaml

from mocapfix.core.errors import ConfigError

#: defaults sized for pipeline configs (the shipped ones have < 200 nodes and depth < 6)
MAX_BYTES = 1 << 20
MAX_DEPTH = 64
ALIAS_BUDGET = 10_000

_OPEN = (yaml.SequenceStartEvent, yaml.MappingStartEvent)
_OPENERS = re.compile(r"[\[{](?:\s*[\[{]){64,}")
_CLOSE = (yaml.SequenceEndEvent, yaml.MappingEndEvent)


def read_bounded(path, what: str = "config", max_bytes: int = MAX_BYTES) -> bytes:
    """The bytes of a config or rules file, reading at most ``max_bytes`` + 1 of them: a
    larger file (or ``-c /dev/zero``) is refused without being read whole. A pipe
    (``-c <(…)``) reads like a file. Every failure is a ConfigError naming ``path``."""
    try:
        with open(path, "rb") as fh:
            data = fh.read(max_bytes + 1)
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a folder, not a {what} file") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        raise ConfigError(f"{path}: {what} file is more than the {max_bytes:,} bytes allowed")
    return data


def decode_text(data: bytes, source: str, max_bytes: int = MAX_BYTES) -> str:
    """UTF-8 text of a config file (BOM dropped), or a ConfigError naming the bad byte."""
    if len(data) > max_bytes:
        raise ConfigError(f"{source}: config is {len(data):,} bytes, more than the "
                          f"{max_bytes:,} a config may have")
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise ConfigError(f"{source}: config is UTF-16 text; save it as UTF-8")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise ConfigError(f"{source} (line {line}): not UTF-8 text (byte 0x{data[exc.start]:02x} "
                          f"at offset {exc.start}); save the config as UTF-8") from None
    return text[1:] if text.startswith("\ufeff") else text


def check_events(text: str, source: str, *, max_depth: int = MAX_DEPTH,
                 alias_budget: int = ALIAS_BUDGET) -> None:
    """Walk the YAML event stream of ``text`` once and refuse excessive nesting or alias
    expansion (see the module docstring). Raises ConfigError; returns None when fine."""
    # PyYAML's scanner keeps up to ~1,000 open flow collections as possible simple keys
    # and rescans them for every token (about 1.5 s for "[[[[..."): catch runs of openers
    # first; the event walk below bounds every other shape
    run = _OPENERS.search(text)
    if run is not None and run.group().count("[") + run.group().count("{") > max_depth:
        line = text.count("\n", 0, run.start()) + 1
        raise ConfigError(f"{source} (line {line}): nested deeper than {max_depth} levels "
                          "(a config is a few levels deep)")
    sizes: dict[str, int] = {}      # anchor -> expanded node count (None while still open)
    # open collections: [anchor, expanded node count, keys seen (mappings: key -> line;
    # sequences: None), whether the next node of a mapping is a key]
    stack: list[list] = []
    expanded_by_aliases = 0
    try:
        for event in yaml.parse(text, Loader=yaml.SafeLoader):
            if stack and stack[-1][2] is not None and isinstance(event, (*_OPEN, yaml.ScalarEvent,
                                                                          yaml.AliasEvent)):
                top = stack[-1]
                if top[3] and isinstance(event, yaml.ScalarEvent):
                    _check_key(event, top[2], source)
                top[3] = not top[3]
            if isinstance(event, _OPEN):
                if len(stack) >= max_depth:
                    raise ConfigError(f"{source}{_line(event)}: nested deeper than {max_depth} "
                                      "levels (a config is a few levels deep)")
                if event.anchor is not None:
                    sizes[event.anchor] = None
                mapping = isinstance(event, yaml.MappingStartEvent)
                stack.append([event.anchor, 1, {} if mapping else None, True])
                continue
            if isinstance(event, _CLOSE):
                anchor, size = stack.pop()[:2]
                if anchor is not None:
                    sizes[anchor] = size
                if stack:
                    stack[-1][1] += size
                continue
            if isinstance(event, yaml.ScalarEvent):
                if event.anchor is not None:
                    sizes[event.anchor] = 1
                if stack:
                    stack[-1][1] += 1
                continue
            if isinstance(event, yaml.AliasEvent):
                if event.anchor not in sizes:
                    raise ConfigError(f"{source}{_line(event)}: alias *{event.anchor} names no "
                                      "anchor defined before it")
                size = sizes[event.anchor]
                if size is None:
                    raise ConfigError(f"{source}{_line(event)}: alias *{event.anchor} refers to "
                                      "the collection it is inside (a recursive structure)")
                expanded_by_aliases += size
                if expanded_by_aliases > alias_budget:
                    raise ConfigError(
                        f"{source}{_line(event)}: aliases expand to more than {alias_budget:,} "
                        "nodes (an alias 'bomb'?); write the values out instead")
                if stack:
                    stack[-1][1] += size
    except yaml.YAMLError as exc:
        raise _yaml_error(exc, source) from None


_RESOLVER = yaml.resolver.Resolver()


def _check_key(event, seen: dict, source: str) -> None:
    """Refuse a scalar key already in this mapping (``seen``: key -> line). Keys are
    compared as YAML types them: ``1`` and ``"1"`` differ, ``a`` and ``"a"`` do not."""
    if event.value == "<<" and event.implicit[0]:
        return                                  # merge keys may repeat
    tag = event.tag or (_RESOLVER.resolve(yaml.ScalarNode, event.value, event.implicit)
                        if event.implicit[0] else "tag:yaml.org,2002:str")
    key = (tag, event.value)
    line = event.start_mark.line + 1
    if key in seen:
        raise ConfigError(f"{source} (line {line}): key {event.value!r} appears twice in one "
                          f"mapping (first on line {seen[key]}); YAML would keep only the last "
                          "value: remove one")
    seen[key] = line


def load_yaml(data, source: str = "<config>", *, loader: type = yaml.SafeLoader,
              max_bytes: int = MAX_BYTES, max_depth: int = MAX_DEPTH,
              alias_budget: int = ALIAS_BUDGET):
    """Load one YAML document from ``data`` (bytes or str) within the bounds above.

    ``loader`` must be ``yaml.SafeLoader`` or a subclass (e.g. one that records lines).
    Every failure is a :class:`ConfigError` naming ``source``.
    """
    if not (isinstance(loader, type) and issubclass(loader, yaml.SafeLoader)):
        raise TypeError("load_yaml needs yaml.SafeLoader or a subclass")
    if isinstance(data, (bytes, bytearray)):
        text = decode_text(bytes(data), source, max_bytes)
    else:
        text = str(data)
        if len(text) > max_bytes:
            raise ConfigError(f"{source}: config is {len(text):,} characters, more than the "
                              f"{max_bytes:,} a config may have")
    check_events(text, source, max_depth=max_depth, alias_budget=alias_budget)
    try:
        return yaml.load(text, Loader=loader)  # noqa: S506 — a SafeLoader subclass, checked above
    except yaml.YAMLError as exc:
        raise _yaml_error(exc, source) from None
    except RecursionError:  # cannot happen within max_depth; kept as a last guard
        raise ConfigError(f"{source}: nested too deeply to load") from None
    except ValueError as exc:  # e.g. an integer of more than 4,300 digits
        raise ConfigError(f"{source}: value cannot be read: {exc}") from None


def _line(event) -> str:
    mark = getattr(event, "start_mark", None)
    return f" (line {mark.line + 1})" if mark is not None else ""


def _yaml_error(exc: yaml.YAMLError, source: str) -> ConfigError:
    mark = getattr(exc, "problem_mark", None)
    where = f" (line {mark.line + 1})" if mark is not None else ""
    problem = str(getattr(exc, "problem", None) or exc).strip().splitlines()[0]
    if isinstance(exc, yaml.reader.ReaderError):  # a character YAML does not allow
        problem = f"character {exc.character!r} at offset {exc.position} is not allowed in YAML"
    return ConfigError(f"{source}{where}: not valid YAML: {problem}")


class LineLoader(yaml.SafeLoader):
    """Safe loader that remembers the line of every mapping (as key ``__line__``) and of
    every key (``__keylines__``), so errors can name them."""


def _construct_mapping(loader, node):
    mapping = loader.construct_mapping(node, deep=True)
    mapping["__line__"] = node.start_mark.line + 1
    mapping["__keylines__"] = {k.value: k.start_mark.line + 1 for k, _ in node.value
                               if isinstance(k, yaml.ScalarNode)}
    return mapping


LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def load_marked_yaml(text, source: str = "<config>"):
    """:func:`load_yaml` with line marks: every mapping carries ``__line__`` and
    ``__keylines__`` (:class:`LineLoader`)."""
    return load_yaml(text, source, loader=LineLoader)


#: the keys :class:`LineLoader` adds to every mapping
LINE_MARKS = ("__line__", "__keylines__")


def check_document(data, source: str, *, what: str, body: str, known, kind: str,
                   version: int, line_of=lambda key: "") -> None:
    """One ConfigError for a loaded config or rules file (``what``: "a config") that is
    not a mapping with ``body`` (its main key), holds a top-level key not in ``known``
    (the first one's line from ``line_of``), or declares a ``version`` other than
    ``version`` (``kind``: the word the message uses). A missing version is ``version``."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: {what} is a mapping with '{body}' (and 'version: 1', "
                          "which may be left out)")
    unknown = sorted((k for k in data if k not in known and k not in LINE_MARKS), key=repr)
    if unknown:
        raise ConfigError(f"{source}{line_of(unknown[0])}: unknown top-level key(s) "
                          f"{', '.join(map(repr, unknown))} (known: {', '.join(sorted(known))})")
    declared = data.get("version", version)
    if isinstance(declared, bool) or declared != version:    # (True == 1 in Python)
        raise ConfigError(f"{source}: unsupported {kind} version {declared!r} (this mocapfix "
                          f"reads {version})")

