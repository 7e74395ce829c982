"""Model files: the learned state of a fitted cleaner, versioned, never pickled.

A model is one ``.npz`` archive (``numpy.savez``) holding the learned arrays plus one
member ``__header__``: a UTF-8 JSON document stored as a uint8 array, so the whole file
loads with ``allow_pickle=False``. The header records:

- ``schema`` (:data:`SCHEMA`), ``cleaner`` and its ``parameters``, ``mocapfix`` version;
- ``units`` of the learned lengths (always ``"m"``);
- whatever the cleaner needs to interpret the arrays (joint names, partlets, window,
  normalisation, sample rate), under ``state``;
- ``training``: the files (path, sha256, frames), total frames and seconds taken.

Files are written atomically (:mod:`mocapfix.core.fileio`). A config names a model by path
(relative to the config file) or by the name of a model shipped in
``mocapfix/data/models``; :func:`resolve` finds it and :func:`load` checks it, so a wrong,
corrupt or incompatible model is a :class:`~mocapfix.core.errors.ConfigError` when the config is
loaded, not halfway through a batch. :func:`load` caches per process (keyed on path, size
and modification time): a worker reads each model once.
"""
from __future__ import annotations

import io
import json
import zipfile
from functools import lru_cache
from pathlib import Path

import numpy as np

from mocapfix.core.errors import ConfigError
from mocapfix.core.fileio import atomic_write_bytes, file_sha256
from mocapfix.core.presets import MODELS_DIR

SCHEMA = "mocapfix.model/1"
HEADER_KEY = "__header__"
SHIPPED_DIR = MODELS_DIR


def shipped() -> dict[str, Path]:
    """Shipped models by name (file stem)."""
    if not SHIPPED_DIR.is_dir():
        return {}
    return {p.stem: p for p in sorted(SHIPPED_DIR.glob("*.npz"))}


def save(path, header: dict, arrays: dict) -> Path:
    """Write a model atomically. ``header`` must hold ``cleaner``; schema, version and
    units are added. Arrays are stored as float64/float32/int/bool, never objects."""
    from mocapfix.core.version import __version__

    full = {"schema": SCHEMA, "mocapfix": __version__, "units": "m", **header}
    if HEADER_KEY in arrays:
        raise ValueError(f"{HEADER_KEY!r} is reserved")
    for name, a in arrays.items():
        if np.asarray(a).dtype == object:
            raise ValueError(f"model array {name!r} has dtype object")
    buf = io.BytesIO()
    payload = np.frombuffer(json.dumps(full, indent=1, sort_keys=True).encode("utf-8"), dtype=np.uint8)
    np.savez_compressed(buf, **{HEADER_KEY: payload}, **{k: np.asarray(v) for k, v in arrays.items()})
    return atomic_write_bytes(path, buf.getvalue())


#: the most a model archive may hold uncompressed, in all and in its JSON header, and its
#: most members (the zip directory's sizes, checked before anything is decompressed: a
#: 1 MB zip bomb named as ``model:`` took 4 GB and 37 s to be refused)
MAX_MODEL_BYTES = 1 << 30
MAX_HEADER_BYTES = 16 << 20
MAX_MEMBERS = 1000


def _check_archive(zf: zipfile.ZipFile) -> None:
    """A ValueError when the zip directory of a model declares more than the caps above."""
    infos = zf.infolist()
    if len(infos) > MAX_MEMBERS:
        raise ValueError(f"{len(infos):,} members (at most {MAX_MEMBERS:,})")
    total = sum(i.file_size for i in infos)
    if total > MAX_MODEL_BYTES:
        raise ValueError(f"{total:,} bytes uncompressed (at most {MAX_MODEL_BYTES:,}); "
                         "a zip bomb, or a model far larger than any mocapfix trains")
    header = next((i for i in infos if i.filename == HEADER_KEY + ".npy"), None)
    if header is not None and header.file_size > MAX_HEADER_BYTES:
        raise ValueError(f"a header of {header.file_size:,} bytes (at most {MAX_HEADER_BYTES:,})")


def read_header(path) -> dict:
    """The JSON header of a model file, without loading its arrays. The archive's declared
    sizes are checked first (:data:`MAX_MODEL_BYTES`): nothing is decompressed from one
    over the caps."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as zf:
            _check_archive(zf)
            raw = zf.read(HEADER_KEY + ".npy")
        header = json.loads(np.load(io.BytesIO(raw), allow_pickle=False).tobytes().decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such model file") from None
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, UnicodeDecodeError,
            RecursionError, MemoryError) as exc:      # (a header nested 100,000 deep)
        raise ConfigError(f"{path}: not a mocapfix model file ({type(exc).__name__}: {exc})") from None
    if not isinstance(header, dict) or header.get("schema") != SCHEMA:
        raise ConfigError(f"{path}: unsupported model schema {header.get('schema') if isinstance(header, dict) else None!r} "
                          f"(this mocapfix reads {SCHEMA}); retrain it with `mocapfix train-dictionary`")
    return header


def _check_declared_sizes(path: str) -> None:
    """Each array's header declares its shape; one that declares more bytes than its
    archive member holds is corrupt, and loading it would first allocate what it
    declares (a few bytes can ask for hundreds of GiB: MemoryError)."""
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with zf.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                        else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read(fh)
            declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
            if declared > info.file_size:
                raise ValueError(f"array {info.filename[:-4]!r} declares {declared:,} bytes, "
                                 f"its member holds {info.file_size:,}")


@lru_cache(maxsize=16)
def _load_cached(path: str, size: int, mtime_ns: int) -> tuple[dict, dict]:
    header = read_header(path)
    try:
        _check_declared_sizes(path)
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k != HEADER_KEY}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, MemoryError) as exc:
        raise ConfigError(f"{path}: corrupt model file ({type(exc).__name__}: {exc})") from None
    try:
        _check_arrays(arrays)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{path}: corrupt model file ({exc})") from None
    for a in arrays.values():
        a.setflags(write=False)
    return header, arrays


# -- what a model's arrays and state must hold ------------------------------------------------
# A hand-edited or damaged model (a joint index past the joint list, a sample rate of 0,
# NaN in a dictionary, an array of another rank) loaded as a config's model and failed
# only on each file, as "internal error IndexError / ZeroDivisionError / LinAlgError", or
# cleaned silently with NaN. The arrays are checked here; each fitted cleaner's
# ``check_state`` checks its state with the validators below, when the model is loaded.

def _check_arrays(arrays: dict) -> None:
    """Every learned array holds finite real numbers (what :func:`save` writes)."""
    for name, a in arrays.items():
        if a.dtype.kind not in "biuf":
            raise ValueError(f"array {name!r} has dtype {a.dtype}, not real numbers")
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise ValueError(f"array {name!r} holds NaN or infinite values")


def is_int(v) -> bool:
    """A whole number of a model's JSON state (not a bool)."""
    return isinstance(v, int) and not isinstance(v, bool)


def positive(st: dict, key: str, what: str = "state") -> None:
    """A ValueError unless ``st[key]`` is a finite number above 0."""
    v = st.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
        raise ValueError(f"{what} {key!r} is {v!r}, not a positive number")


def window(st: dict, what: str = "state") -> None:
    """A ValueError unless ``st["window"]`` is a whole number of at least 1."""
    v = st.get("window")
    if not is_int(v) or v < 1:
        raise ValueError(f"{what} 'window' is {v!r}, not a whole number >= 1")


def matrix(arrays: dict, name: str) -> None:
    """A ValueError unless ``arrays[name]`` is a matrix with at least one column."""
    a = arrays.get(name)
    if a is None:
        raise ValueError(f"no array {name!r}")
    if a.ndim != 2 or a.shape[1] < 1:
        raise ValueError(f"array {name!r} has shape {a.shape}, not rows × (1 or more) columns")


def load(path, cleaner: str | None = None, where: str = "",
         check=None) -> tuple[dict, dict]:
    """(header, arrays) of a model file, checked; cached per process. ``cleaner``: the
    cleaner that will use it (a model for another cleaner is refused); ``check(state,
    arrays)``: its check of the state (a ValueError or TypeError makes the file corrupt)."""
    path = Path(path)
    prefix = f"{where}: " if where else ""
    try:
        st = path.stat()
    except OSError:
        raise ConfigError(f"{prefix}{path}: no such model file") from None
    try:
        header, arrays = _load_cached(str(path), st.st_size, st.st_mtime_ns)
    except ConfigError as exc:
        raise ConfigError(f"{prefix}{exc}") from None
    if cleaner is not None and header.get("cleaner") != cleaner:
        raise ConfigError(f"{prefix}{path} is a model for cleaner {header.get('cleaner')!r}, "
                          f"not {cleaner!r}")
    if check is not None:
        try:
            check(header.get("state"), arrays)
        except (ValueError, TypeError) as exc:
            raise ConfigError(f"{prefix}{path}: corrupt model file ({exc})") from None
    return header, arrays


def resolve(ref: str, base_dir=None, where: str = "") -> Path:
    """A model reference from a config: a path (absolute, or relative to ``base_dir``, the
    config file's folder) or the name of a shipped model."""
    prefix = f"{where}: " if where else ""
    candidates = []
    p = Path(ref).expanduser()
    if p.is_absolute():
        candidates.append(p)
    else:
        if base_dir is not None:
            candidates.append(Path(base_dir) / p)
        candidates.append(Path.cwd() / p)
    for c in candidates:
        if c.is_file():
            return c.resolve()
    ships = shipped()
    if ref in ships:
        return ships[ref]
    known = ", ".join(ships) or "none"
    raise ConfigError(f"{prefix}model {ref!r} is neither a file (looked in "
                      f"{', '.join(str(c) for c in candidates)}) nor a shipped model (shipped: {known})")


def provenance(paths, frames, seconds: float) -> dict:
    """The ``training`` block of a header: files with their sha256 and frame counts."""
    files = [{"path": str(p), "sha256": file_sha256(p), "frames": int(n)} for p, n in zip(paths, frames)]
    return {"files": files, "frames": int(sum(frames)), "seconds": round(float(seconds), 3)}
