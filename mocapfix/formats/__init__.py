"""Format registry: picks a reader by suffix and content, a writer by suffix.

A format is one module of this package that declares, at its top level and as literals,
``NAME = "..."``, ``SUFFIXES = (".ext", ...)``, ``FAMILY = "..."`` (what its points are:
``markers`` for optical marker files, ``rotations`` for joint-rotation files, ``skeletons``
for depth-sensor skeletons; a config's ``formats:`` may name a family) and optionally
``SNIFF_ORDER = n`` (where its sniffer runs when a file's suffix does not settle the
format; lower first), and defines
``sniff(head: bytes) -> bool``, ``read(path, **options) -> Motion`` and
``write(motion, path, **options) -> list[Path]`` (writers use
:mod:`mocapfix.core.fileio` so outputs appear atomically); one whose reader reads other
files besides the one named also defines ``companion_files(path) -> list[Path]``, one whose
files cannot hold every value ``storable(motion) -> Motion``. The table :data:`FORMATS` is
read off those declarations (the module's text, not its import), so a new module is found
with nothing else edited, and modules are imported on first use so that ``mocapfix
--help`` stays fast.

Several formats may claim one suffix (``.csv``: Vicon Nexus, OptiTrack Motive and Kinect
text; ``.tsv``: Qualisys QTM and Kinect text). :func:`detect` then runs the claiming
formats' sniffers in sniffing order (the vendor sniffers are strict and run first), then
the others'; a ``.csv``/``.txt``/``.tsv`` file that none accepts is refused with "not a
known layout (first line: '...')". :func:`write` without a format writes the motion's own
format when it claims the suffix, else the last (most general) claiming format -- see
:func:`write_format`.
"""
from __future__ import annotations

import ast
import importlib
import pkgutil
import re
from pathlib import Path

import numpy as np

from mocapfix.core.errors import MocapfixError, UnreadableFileError, WriteError
from mocapfix.core.motion import Motion

#: a module-level declaration of a format module (module docstring)
_DECLARATION = re.compile(r"^(NAME|SUFFIXES|SNIFF_ORDER|FAMILY) = (.+)$", re.MULTILINE)


def _declared_formats(paths) -> dict:
    """name -> (module, suffixes) of the format modules found in ``paths`` (a package's
    ``__path__``), in sniffing order, from the literals they declare."""
    found = []
    for info in pkgutil.iter_modules(paths):
        source = Path(info.module_finder.path) / f"{info.name}.py"
        if info.ispkg or not source.is_file():
            continue
        decl = {k: ast.literal_eval(v) for k, v in _DECLARATION.findall(source.read_text(encoding="utf-8"))}
        if "NAME" in decl and "SUFFIXES" in decl:
            found.append((decl.get("SNIFF_ORDER", 10), decl["NAME"], f"{__name__}.{info.name}",
                          tuple(s.lower() for s in decl["SUFFIXES"])))
            _FAMILY[decl["NAME"]] = decl.get("FAMILY", decl["NAME"])
    return {name: (mod, suffixes) for _, name, mod, suffixes in sorted(found)}


#: format name -> its family (filled by :func:`_declared_formats`)
_FAMILY: dict[str, str] = {}


#: The one format table: name -> (module, suffixes), sniffing order. Configs, rule files and
#: folder discovery use it too.
FORMATS = _declared_formats(__path__)
#: format names, as configs and rule files spell them in ``formats:``
NAMES = tuple(FORMATS)
#: family -> its format names (``markers``: c3d, trc and the vendors' exports)
FAMILIES = {family: tuple(n for n in NAMES if _FAMILY[n] == family)
            for family in dict.fromkeys(_FAMILY[n] for n in NAMES)}
#: the formats whose points are optical markers
MARKER_FORMATS = FAMILIES["markers"]


def matches(name: str, listed) -> bool:
    """Format ``name`` is among ``listed`` (format or family names: a config's or a rule
    file's ``formats:``)."""
    return name in listed or _FAMILY.get(name) in listed


#: suffix -> the formats that claim it, in sniffing order (``.csv``: the strict vendor
#: layouts first, Kinect's general text layouts last)
_SUFFIXES = {}
for _name, (_, _suffixes) in FORMATS.items():
    for _suffix in _suffixes:
        _SUFFIXES[_suffix] = (*_SUFFIXES.get(_suffix, ()), _name)
#: suffixes of files that hold motions (``.asf`` alone is a skeleton, read as a rest pose)
MOTION_SUFFIXES = tuple(suffix for suffix in _SUFFIXES if suffix != ".asf")
#: suffixes of text tables: a file of these no sniffer accepts is "not a known layout"
TEXT_SUFFIXES = (".csv", ".txt", ".tsv")


def claiming(suffix: str) -> tuple[str, ...]:
    """The formats that claim ``suffix`` (any case), in sniffing order."""
    names = _SUFFIXES.get(suffix.lower(), ())
    return (names,) if isinstance(names, str) else tuple(names)


def suffixes(name: str) -> tuple[str, ...]:
    """The file suffixes of format ``name``."""
    return FORMATS[name][1]


def module(name: str):
    try:
        return importlib.import_module(FORMATS[name][0])
    except KeyError:
        raise MocapfixError(
            f"unknown format {name!r}; known: {', '.join(sorted(FORMATS))}") from None


def detect(path) -> str:
    """Format name of ``path``: the sniffers of the formats that claim its suffix, in
    sniffing order, then the others'. A text table (``.csv``, ``.txt``, ``.tsv``) that no
    sniffer accepts is refused here as "not a known layout (first line: '...')"; for other
    suffixes the claiming format's reader explains what is wrong."""
    path = Path(path)
    claim = claiming(path.suffix)
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError as exc:
        raise UnreadableFileError(path, f"cannot open: {exc.strerror or exc}") from None
    if not head:
        raise UnreadableFileError(path, "file is empty")
    for name in (*claim, *(n for n in FORMATS if n not in claim)):
        if module(name).sniff(head):
            return name
    if path.suffix.lower() in TEXT_SUFFIXES and claim:
        from mocapfix.formats.texttable import not_text, unknown_layout
        if not head.strip():
            raise UnreadableFileError(path, "file is empty")
        raise UnreadableFileError(path, not_text(head) or unknown_layout(head))
    if claim:
        return claim[0]  # let the reader explain what is wrong
    known = ", ".join(f"{name} ({'/'.join(suffixes(name))})" for name in NAMES)
    raise UnreadableFileError(path, f"unknown file format (expected one of: {known})")


def read(path, format: str | None = None, *, default_fps: float | None = None,
         share_values: bool = False, **options) -> Motion:
    """Read any supported file into a :class:`Motion`.

    ``fps`` (an option of every reader) overrides the file's rate; ``default_fps`` (the
    command line's ``--fps``) is the rate of a file that stores none — AMC, Kinect text
    without time stamps, a QTM TSV whose FREQUENCY is EXT without Frame and Time
    columns — and leaves a stored rate alone (a note says it was not
    used where it differs: a batch of AMC and C3D files given ``--fps 60`` for the AMC
    files rewrote the C3D files' rate).

    ``share_values``: for a caller that never changes the motion it reads in place
    (``clean``): what the source keeps for its writer is the motion's own arrays, made
    read-only (:func:`share_values_read`); the BVH and AMC readers then never make their
    copy of the channels (a whole-take array at the read's peak).

    Any failure is a :class:`UnreadableFileError` naming the file and the cause.
    """
    path = Path(path)
    if not path.exists():
        raise UnreadableFileError(path, "no such file")
    if path.is_dir():
        raise UnreadableFileError(path, "is a directory, not a file")
    name = format or detect(path)
    if share_values and name in ("bvh", "asfamc"):
        options = {**options, "share_values": True}
    motion = _read_at_rate(path, name, default_fps, options)
    if share_values:
        share_values_read(motion)
    return motion


def _read_at_rate(path: Path, name: str, default_fps: float | None, options: dict) -> Motion:
    """:func:`read` of a file of format ``name``, ``default_fps`` applied as it says."""
    if default_fps is None or options.get("fps") is not None:
        return _read_as(path, name, options)
    if name == "asfamc":                           # AMC files never store a rate
        return _read_as(path, name, {**options, "fps": default_fps})
    if name in ("kinect", "qtm_tsv"):             # the reader knows which files store none
        motion = _read_as(path, name, {**options, "default_fps": default_fps})
        if motion.source is not None and motion.source.extra.get("rate_assumed"):
            return motion
    else:
        motion = _read_as(path, name, options)
    if abs(float(default_fps) - motion.fps) > 1e-6 * motion.fps:
        motion.notes.append(f"--fps {float(default_fps):g} not used: the file stores its "
                            f"rate ({motion.fps:g} Hz)")
    return motion


def companion_files(path) -> list[Path]:
    """The files besides ``path`` that :func:`read` reads for it (an AMC's ASF skeleton);
    an UnreadableFileError when ``path`` cannot be opened."""
    find = getattr(module(detect(path)), "companion_files", None)
    return find(Path(path)) if find is not None else []


def _read_as(path: Path, name: str, options: dict) -> Motion:
    """The format module's reader, its failures made :class:`UnreadableFileError`."""
    mod = module(name)
    try:
        motion = mod.read(path, **options)
    except MocapfixError:
        raise
    except MemoryError:
        raise UnreadableFileError(path, "file declares more data than can be held in memory") from None
    except (ValueError, IndexError, KeyError, TypeError, OverflowError, EOFError,
            UnicodeDecodeError, OSError, AssertionError, ArithmeticError) as exc:
        # a reader bug or a malformation it did not anticipate: still one clear line
        raise UnreadableFileError(path, f"malformed {name} file ({type(exc).__name__}: {exc})") from exc
    motion.path = str(path)
    motion.format = name
    return motion


def share_values_read(motion: Motion) -> None:
    """For a caller that never changes the motion it read in place (``clean``): the
    channel values a BVH or AMC source keeps to tell the writer which lines changed (a
    copy of ``motion.channels`` as read, so that an edit of the motion's own array in
    place is written) become ``motion.channels`` itself, made read-only: one whole-take
    array fewer (20 bytes a sample for a CMU BVH); a Kinect source's coordinates, the
    same with ``motion.positions``, and a TRC source's values as read
    (:func:`_share_coordinates_read`). Any other motion,
    or one whose arrays are no longer the values read, is left as it is."""
    _share_coordinates_read(motion)
    values = getattr(motion.source, "values", None)
    channels = motion.channels
    if (not isinstance(values, np.ndarray) or channels is None or values is channels
            or values.shape != channels.shape or values.dtype != channels.dtype
            or not np.array_equal(values, channels)):
        return
    values.flags.writeable = False
    motion.channels = values


#: where a source keeps the values a writer compares the motion with (a BVH's or AMC's
#: channels, a Kinect or TRC file's coordinates), shared by :func:`share_values_read`
SHARED_VALUES = ("values", "original")


def replace_shared_values(source, array, replacement) -> None:
    """Where ``source`` keeps ``array`` itself as the values its writer compares with
    (:func:`share_values_read`), keep ``replacement`` instead (the same values, kept
    elsewhere: :class:`mocapfix.core.diskarray.FramesOnDisk`)."""
    for name in SHARED_VALUES:
        if getattr(source, name, None) is array:
            setattr(source, name, replacement)


def _share_coordinates_read(motion: Motion) -> None:
    """A Kinect or TRC source's coordinates as written (``original``: the writer compares
    the samples seen in the file with them, to rewrite only those that moved) become the
    motion's positions, made read-only, when the two agree on every sample seen (they
    differ only where the reader made a sample missing, where the writer does not look):
    one whole-take array fewer (24 bytes a sample). :func:`share_values_read`'s rule."""
    source, positions = motion.source, motion.positions
    original = getattr(source, "original", None)
    if (motion.format not in ("kinect", "trc") or not isinstance(original, np.ndarray)
            or original is positions or original.shape != positions.shape
            or original.dtype != positions.dtype
            or source.missing.shape != positions.shape[:2]):
        return
    for a in range(0, len(positions), SHARE_CHUNK):     # no whole-take temporaries
        rows = slice(a, a + SHARE_CHUNK)
        seen = ~source.missing[rows]
        if not np.array_equal(original[rows][seen], positions[rows][seen]):
            return
    positions.flags.writeable = False
    source.original = positions


#: frames compared at a time by :func:`_share_coordinates_read`
SHARE_CHUNK = 16384


def storable(motion: Motion, name: str | None = None) -> Motion:
    """``motion`` as the writer of format ``name`` (None: its own) will store it (a format
    module's ``storable``, where a file cannot hold every value: an int16 C3D), so that
    what is measured and reported is what is written."""
    name = name or motion.format
    if name not in FORMATS:
        return motion
    fix = getattr(module(name), "storable", None)
    return motion if fix is None else fix(motion)


def losses(motion: Motion, name: str) -> list[str]:
    """What a file of format ``name`` cannot carry from ``motion`` (read in another
    format), one note each: what only the motion's own format keeps (its module's
    ``kept_only_here(motion)``: a C3D's analog channels and events, a Kinect file's tracking
    states) and what the target cannot hold (its module's ``losses(motion)``), and the
    rotations of a rig written as joint positions."""
    if name == motion.format:
        return []
    notes = []
    if motion.format in FORMATS:
        notes += getattr(module(motion.format), "kept_only_here", lambda m: [])(motion)
    notes += [n for n in getattr(module(name), "losses", lambda m: [])(motion) if n not in notes]
    if motion.channels is not None and name not in ("bvh", "asfamc"):
        notes.append(f"the joint rotations ({motion.channels.shape[1]} channels) are not "
                     f"carried: {name} stores the joint positions (forward kinematics)")
    return notes


def write_format(motion: Motion, path) -> str | None:
    """The format :func:`write` uses for ``path`` when none is given: the motion's own
    format if it claims the suffix; else, for a suffix several formats claim, the most
    general of them -- the LAST in sniffing order (``.csv``/``.txt``/``.tsv``: Kinect's
    headed wide CSV, which holds any motion; the vendor layouts are written only for
    motions read from them or when named); else the suffix's one format; else the
    motion's own format (None if none)."""
    claim = claiming(Path(path).suffix)
    if motion.format in claim:
        return motion.format
    if claim:
        return claim[-1]
    return motion.format if motion.format in FORMATS else None


def write(motion: Motion, path, format: str | None = None, **options) -> list[Path]:
    """Write ``motion`` to ``path`` (format: ``format``, else :func:`write_format`). Returns
    the files written (ASF/AMC writes the skeleton beside the motion)."""
    path = Path(path)
    name = format or write_format(motion, path)
    if name not in FORMATS:
        raise WriteError(path, f"cannot tell the output format from suffix {path.suffix!r}")
    return module(name).write(motion, path, **options)
