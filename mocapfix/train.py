"""``mocapfix train-dictionary``: discover training files, read them (joint positions by
forward kinematics for BVH/AMC), fit a cleaner's model and write it as a model file
(:mod:`mocapfix.core.models`) with its training provenance.

A file that cannot be read does not stop the training: it is named, left out, listed in
the model's provenance (``training.unread``) and makes the command exit 1, as ``clean`` does
for a file it could not clean — one damaged take in a corpus of hundreds costs that take,
not the run.

A training method names a fitted cleaner and the parameters that select its training
algorithm (:data:`METHODS`); other options are that cleaner's parameters.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from mocapfix import formats
from mocapfix.core import models
from mocapfix.cleaners import build
from mocapfix.cleaners.base import FittedCleaner
from mocapfix.core.errors import MocapfixError, UnreadableFileError, name_the_file

#: --method → (cleaner, parameters that choose its training algorithm)
METHODS: dict[str, tuple[str, dict]] = {
    "partlet": ("partlet_dictionary", {"method": "partlet"}),
    "ksvd": ("partlet_dictionary", {"method": "ksvd"}),
    "mssa": ("mssa", {}),
}


def discover_training(inputs, skipped: list | None = None) -> list[Path]:
    """Motion files among ``inputs`` (files, or folders searched recursively), found as
    ``clean`` and ``check`` find them (:func:`mocapfix.batch.discovery.discover_inputs`): in folders,
    text files that are not motion data (notes, exports), special files and symlink loops
    are passed over, each with its reason appended to ``skipped``."""
    from mocapfix.batch.discovery import discover_inputs

    found = discover_inputs(inputs, once_per_file=True)     # (a file found twice was trained on twice)
    if skipped is not None:
        skipped.extend(found.skipped)
    files = [f.path for f in found.files]
    if not files:
        raise MocapfixError("no training files found in " + ", ".join(map(str, inputs)))
    return files


@dataclass(frozen=True)
class ReadTask:
    """Read one training file (picklable, for a process pool or Dask); a failure is an
    ERROR result naming the file."""

    fps: float | None = None

    def __call__(self, path):
        try:
            return formats.read(path, **({"default_fps": self.fps} if self.fps else {}))
        except MocapfixError as exc:
            # the cause without the file name, for a message that names the file itself
            cause = (f"line {exc.line}: " if getattr(exc, "line", None) is not None else "") + \
                getattr(exc, "reason", str(exc))
            return {"input": str(path), "status": "ERROR", "error": str(exc), "cause": cause}


def read_all(paths, jobs: int = 1, fps: float | None = None, progress=None, spec=None,
             unread: list | None = None):
    """Read every training file (in ``jobs`` local processes, or on the executor ``spec``
    names: :class:`mocapfix.batch.executors.ExecutorSpec`). A file that cannot be read is an error
    naming it; with an ``unread`` list it is appended there instead, as ``{"path", "error",
    "cause"}`` (the message, and its cause without the file name), and left out of the
    result (``None`` in its place)."""
    from mocapfix.batch.tasks import run_tasks

    out: list = [None] * len(paths)
    for done, (n, motion) in enumerate(run_tasks(ReadTask(fps), list(paths), jobs, spec=spec), 1):
        if isinstance(motion, dict):
            message = name_the_file(paths[n], motion["error"])
            if unread is None:
                raise MocapfixError(message)
            unread.append({"path": str(paths[n]), "error": message,
                           "cause": motion.get("cause", message)})
        else:
            out[n] = motion
        if progress:
            progress(done, len(paths))
    return out


def train(inputs, output, method: str = "partlet", params: dict | None = None, jobs: int = 1,
          fps: float | None = None, progress=None, spec=None) -> dict:
    """Train a model and write it; returns a summary (the model's header)."""
    if method not in METHODS:
        raise MocapfixError(f"unknown training method {method!r} (known: {', '.join(METHODS)})")
    started = time.perf_counter()
    cleaner_name, fixed = METHODS[method]
    cleaner = build(cleaner_name, step=f"train-dictionary --method {method}",
                    **{k: v for k, v in (params or {}).items() if v is not None}, **fixed)
    if not isinstance(cleaner, FittedCleaner):
        raise MocapfixError(f"{cleaner_name} is not a trained cleaner")
    skipped: list = []
    paths = discover_training(inputs, skipped)
    unread: list = []
    motions = read_all(paths, jobs, fps, progress=(lambda n, t: progress("read", n, t)) if progress else None,
                       spec=spec, unread=unread)
    if unread:
        paths = [p for p, m in zip(paths, motions) if m is not None]
        motions = [m for m in motions if m is not None]
        if not motions:
            raise UnreadableFileError(unread[0]["path"], f"none of the {len(unread)} training "
                                                         f"files could be read; this one: "
                                                         f"{unread[0]['cause']}")
    cleaner.fit(motions, progress=(lambda n, t: progress("fit", n, t)) if progress else None)
    header, arrays = cleaner.state()
    header.update(cleaner.model_header_fields())
    header["training"] = models.provenance(paths, [m.n_frames for m in motions],
                                           time.perf_counter() - started)
    if unread:
        header["training"]["unread"] = [{"path": u["path"], "error": u["error"]} for u in unread]
    models.save(output, header, arrays)
    return {"output": str(output), "skipped": skipped, "unread": unread, **header}
