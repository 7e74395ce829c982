"""The manifest of an output folder: what each input became, so a batch can resume.

``OUTDIR/mocapfix-manifest.jsonl`` is a journal, one JSON record per line, appended as each
file finishes (one ``write`` of one line, then ``fsync``: a record is either whole or,
after a crash mid-write, an unparsable last line that is ignored). The last record of an
input and output wins (one file found through two given paths, ``clean in in/sub/x.bvh``,
has two outputs and two records: keyed by the input alone, the second replaced the first
and the re-run of the same command stopped on "output(s) exist already"). Fields: ``input``
(absolute path), ``input_sha256``, ``companions_sha256`` (``{path: sha256}`` of the other
files read with the input: an AMC's ASF), ``output`` and ``files`` (relative to the output
folder), ``status`` (``done``, ``failed``, or ``started`` — written for every file of a run
before it begins), ``quality`` (OK/WARN/FAIL), ``config_sha256`` (of the effective config
text), ``models_sha256`` (``{path: sha256}`` of the model files the pipeline may read),
``reports``, ``read_options``, ``version`` (mocapfix), ``time``; ``error`` for a failed
file; ``summary`` (frames, missing, filled, flagged, worst joints: what the batch index shows)
for a cleaned one.

A file is *finished* when its last record is ``done`` with this run's config and model
hashes, report kinds, read options and mocapfix version, the sha256 of its input and of the
files read with it are unchanged and its output files all exist (a record written before a
field existed lacks it, so its file is not finished). A re-run skips finished files; an
output whose last record is ``started`` under the same run key was written by an
interrupted run of this same config (killed between writing and recording) and may be
replaced without ``--overwrite``. At the end of a run the journal is rewritten (atomically)
with one record per input and output.

The journal is never written through a link (one at its name is refused); a write the disk
refuses is a :class:`~mocapfix.core.errors.WriteError`, with no torn line left. One run at a
time writes into a folder: :func:`lock_output_folder`.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import stat
import time
from pathlib import Path

from mocapfix.core.version import __version__
from mocapfix.core.fileio import atomic_write_text, file_sha256

MANIFEST_NAME = "mocapfix-manifest.jsonl"
#: the run lock of an output folder (:func:`lock_output_folder`)
LOCK_NAME = ".mocapfix.lock"
_KEY_FIELDS = ("config_sha256", "models_sha256", "reports", "read_options", "version")
_INPUT_FIELDS = ("input_sha256", "companions_sha256")
#: what the batch index (:mod:`mocapfix.quality.index`) shows of a file, kept in its record
SUMMARY_FIELDS = ("frames", "joints", "missing_before", "missing_after", "samples_filled",
                  "samples_flagged", "worst")


def run_key(config_text: str, reports, read_options: dict | None, model_files=(),
            to: str | None = None) -> dict:
    """What determines a run's outputs besides the input: config, the content of the model
    files it reads (``model_files``, hashed here once per run: a model retrained at the
    same path leaves the config text as it was), report kinds, read options, the output
    format asked for (``to``), mocapfix version."""
    body = "\n".join(line for line in config_text.splitlines() if not line.startswith("#"))
    try:
        models = {str(p): file_sha256(p) for p in model_files}
    except OSError as exc:
        from mocapfix.core.errors import ConfigError

        raise ConfigError(f"{exc.filename}: cannot read the model file: {exc.strerror or exc}") from None
    return {"config_sha256": hashlib.sha256(body.encode("utf-8")).hexdigest(),
            "models_sha256": models, "reports": sorted(reports),
            "read_options": dict(sorted((read_options or {}).items())), "version": __version__,
            **({"to": to} if to else {})}


def input_identity(source) -> dict:
    """The sha256 of ``source`` (``input_sha256``) and of every other file its reader reads
    with it (``companions_sha256``: an AMC's ASF skeleton, which decides the output as much
    as the AMC does). An OSError when one cannot be read."""
    from mocapfix import formats
    from mocapfix.core.errors import MocapfixError

    try:
        companions = formats.companion_files(source)
    except MocapfixError:
        companions = []                 # reading the input names the cause
    return {"input_sha256": file_sha256(source),
            "companions_sha256": {str(p): file_sha256(p) for p in companions}}


class Manifest:
    """The journal of one output folder (see the module docstring)."""

    def __init__(self, outdir, key: dict):
        self.outdir = Path(os.path.abspath(outdir))
        self.path = self.outdir / MANIFEST_NAME
        self.key = key
        self.records: dict[tuple, dict] = {}       # (input, output) -> last record
        self._fd: int | None = None
        self._size_before: int | None = None     # the file's size before this run wrote
        _refuse_link(self.path)
        if self.path.exists():
            try:
                text = self.path.read_text(encoding="utf-8", errors="replace")
            except OSError as exc:
                from mocapfix.core.errors import ConfigError

                raise ConfigError(f"{self.path}: cannot read the output folder's manifest: "
                                  f"{exc.strerror or exc}") from None
            for line in text.splitlines():
                try:
                    rec = json.loads(line)
                except ValueError:
                    continue                      # a torn last line after a crash
                if _well_formed(rec):
                    self.records[_key(rec)] = rec

    def _same_run(self, rec: dict) -> bool:
        return all(rec.get(f) == self.key[f] for f in _KEY_FIELDS)

    def finished(self, job) -> bool:
        """``job`` was cleaned by an earlier run of this config and nothing changed since."""
        rec = self.records.get((str(job.source), self._rel(job.output)))
        if not rec or rec.get("status") != "done" or not self._same_run(rec):
            return False
        files = rec.get("files", [])
        if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
            return False                          # a damaged record: redo the file
        if not all((self.outdir / f).is_file() for f in files):
            return False
        try:
            identity = input_identity(job.source)
        except OSError:
            return False
        return all(rec.get(f) == identity[f] for f in _INPUT_FIELDS)

    def made_with_other_models(self, job) -> bool:
        """``job``'s output was recorded as made with this config but other model files
        (retrained at the same path): an output ``--skip-existing`` must not keep as this
        config's. A record without model hashes tells nothing."""
        rec = self.records.get((str(job.source), self._rel(job.output)))
        return (bool(rec) and rec.get("config_sha256") == self.key["config_sha256"]
                and "models_sha256" in rec and rec["models_sha256"] != self.key["models_sha256"])

    def interrupted(self, job) -> bool:
        """``job`` was started by a run of this same config that did not record its end."""
        rec = self.records.get((str(job.source), self._rel(job.output)))
        return bool(rec) and rec.get("status") == "started" and self._same_run(rec)

    def knows(self, source) -> bool:
        """Some record names ``source`` as its input."""
        return any(key[0] == str(source) for key in self.records)

    def _rel(self, path) -> str:
        p = Path(path)
        try:
            return p.relative_to(self.outdir).as_posix()
        except ValueError:
            return str(p)

    # -- writing ----------------------------------------------------------------------

    def _append(self, records: list[dict]) -> None:
        if not records:
            return
        for r in records:
            self.records[_key(r)] = r
        data = "".join(json.dumps(r, sort_keys=True) + "\n" for r in records).encode("utf-8")
        try:
            if self._fd is None:
                self.outdir.mkdir(parents=True, exist_ok=True)
                self._size_before = self.path.stat().st_size if self.path.exists() else None
                # never through a link (it appended to the file a planted link named)
                self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT
                                   | getattr(os, "O_NOFOLLOW", 0), 0o666)
            end = os.fstat(self._fd).st_size
            try:
                while data:
                    data = data[os.write(self._fd, data):]
                os.fsync(self._fd)
            except OSError:
                os.ftruncate(self._fd, end)     # no torn line for the next record to join
                raise
        except OSError as exc:
            from mocapfix.core.errors import WriteError

            why = "is a link; not written through" if exc.errno == errno.ELOOP else \
                exc.strerror or str(exc)
            raise WriteError(self.path, f"cannot write the manifest: {why}") from None

    def start(self, jobs) -> None:
        """Record that these jobs are about to run (one write for all)."""
        now = _now()
        self._append([{"input": str(j.source), "output": self._rel(j.output), "status": "started",
                       "time": now, **self.key} for j in jobs])

    def abandon(self) -> None:
        """Take back what this run wrote (nothing ran: the Dask scheduler could not be
        reached): the file as it was before, or no file if this run made it."""
        if self._fd is None:
            return
        os.close(self._fd)
        self._fd = None
        if self._size_before is None:
            self.path.unlink(missing_ok=True)
        else:
            os.truncate(self.path, self._size_before)

    def record(self, result: dict) -> None:
        """Record one finished file from its batch result (call as each finishes)."""
        rec = {"input": result["input"], "output": self._rel(result.get("output", "")),
               "time": _now(), **self.key}
        if result["status"] == "ERROR":
            rec.update(status="failed", error=result.get("error", ""))
        else:
            files = [*result.get("written", []), *result.get("reports", [])]
            rec.update(status="done", quality=result["status"], files=[self._rel(f) for f in files],
                       summary={k: result[k] for k in SUMMARY_FIELDS if k in result},
                       **{f: result.get(f) for f in _INPUT_FIELDS})
        self._append([rec])

    def close(self, compact: bool = True) -> None:
        """Close the journal; with ``compact`` rewrite it with one record per input."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if compact and self.records:
            from mocapfix.core.errors import WriteError

            try:
                atomic_write_text(self.path, "".join(json.dumps(r, sort_keys=True) + "\n"
                                                     for r in self.records.values()))
            except WriteError as exc:   # said as the appends say it (one line for both)
                raise WriteError(self.path, "cannot write the manifest: "
                                 + exc.reason.removeprefix("cannot write: ")) from None


def lock_output_folder(outdir, soft: bool = False) -> int | None:
    """Take the run lock of ``outdir``: an exclusive ``flock`` on ``OUTDIR/.mocapfix.lock``
    (never through a link), which the kernel releases when this process ends however it
    ends. Returns its descriptor for :func:`unlock_output_folder` (None where there is no
    ``flock``: no lock). A run that finds it held is refused, a ConfigError naming the
    process that holds it: two runs in one folder removed each other's temporaries and
    kept only their own manifest records. ``soft``: None, not an error, when the lock file
    cannot be made (a folder that takes no files: its own check says so)."""
    try:
        import fcntl
    except ImportError:                 # (Windows)
        return None
    path = Path(outdir) / LOCK_NAME
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o666)
        except OSError as exc:
            if soft:
                return None
            from mocapfix.core.errors import ConfigError

            why = "is a link" if exc.errno == errno.ELOOP else exc.strerror or str(exc)
            raise ConfigError(f"{path}: cannot take the output folder's run lock: {why}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 32).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            from mocapfix.core.errors import ConfigError

            raise ConfigError(f"{outdir}: another mocapfix run (process {holder}) is writing "
                              "into this output folder; wait for it to end, or choose another "
                              "output folder") from None
        try:                            # the holder before us may have removed the file
            if os.fstat(fd).st_ino == os.lstat(path).st_ino:
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    with contextlib.suppress(OSError):  # who holds it, for the message above (a full disk: none)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode("ascii"))
    _HELD.add(fd)
    return fd


#: the descriptors of the run locks this process holds
_HELD: set[int] = set()


def drop_inherited_locks() -> None:
    """In a forked worker: close the run locks' descriptors copied from its parent, so that
    only the run holds its lock (a worker still dying after a ``kill -9`` of the run kept
    the folder locked for the run that came next)."""
    for fd in _HELD:
        with contextlib.suppress(OSError):
            os.close(fd)
    _HELD.clear()


def unlock_output_folder(outdir, fd: int | None) -> None:
    """Release and remove the lock :func:`lock_output_folder` took (the lock is released
    for the worker processes that share the descriptor too)."""
    if fd is None:
        return
    import fcntl

    with contextlib.suppress(OSError):
        os.unlink(Path(outdir) / LOCK_NAME)
    with contextlib.suppress(OSError):
        fcntl.flock(fd, fcntl.LOCK_UN)
    _HELD.discard(fd)
    os.close(fd)


def _refuse_link(path: Path) -> None:
    """A ConfigError when ``path`` is a symbolic link or not a regular file: the journal is
    appended to in place, and a link planted there made a run write into its target."""
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        return
    if not stat.S_ISREG(mode):
        from mocapfix.core.errors import ConfigError

        what = "a symbolic link" if stat.S_ISLNK(mode) else "not a regular file"
        raise ConfigError(f"{path}: the output folder's manifest is {what}; mocapfix does not "
                          "write through it (remove it, or choose another output folder)")


def _well_formed(rec) -> bool:
    """A record of the shape :class:`Manifest` writes. The journal is a text file anyone
    (or another version) may have changed: a record with a summary, quality, error or file
    list of another type crashed the run at its end, when ``--report html`` listed every
    record in the batch index (after the file was cleaned, before the config record). A
    record that is not is dropped, as a torn line is: its file is not finished."""
    if not (isinstance(rec, dict) and isinstance(rec.get("input"), str)
            and isinstance(rec.get("output"), str)
            and rec.get("status") in ("done", "failed", "started")):
        return False
    files, summary = rec.get("files", []), rec.get("summary", {})
    if not (isinstance(files, list) and all(isinstance(f, str) for f in files)
            and isinstance(rec.get("error", ""), str) and isinstance(summary, dict)):
        return False
    worst = summary.get("worst", [])
    if not (isinstance(worst, list) and all(isinstance(w, list) and len(w) == 2
                                            and all(isinstance(x, str) for x in w)
                                            for w in worst)):
        return False
    return rec["status"] != "done" or rec.get("quality") in ("OK", "WARN", "FAIL")


def _key(rec: dict) -> tuple:
    output = rec.get("output")
    return rec["input"], output if isinstance(output, str) else None


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
