"""``mocapfix bench`` as tasks over a batch executor (issue 13): one task per (seed, setting,
file) block, run by :func:`mocapfix.batch.tasks.run_tasks` in this process, in local worker
processes (``-j``) or on Dask (``--dask-workers``, ``--scheduler``).

A task carries the clean Motion (without ``source``, the raw file only the writers read)
and the block's seed and setting; the worker corrupts it
(:func:`mocapfix.bench.corrupt.apply_protocol`, seeded, so every method and every executor sees
the same corruption), runs every active method on it and scores each output. Methods
travel as their configs (:meth:`mocapfix.bench.Method.__reduce__`) and are parsed once per
worker process (:func:`method_in_worker`), so models load once per worker.

Results are put back in the order of the sequential run (seed → setting → file → method),
so tables and JSON do not depend on the executor except the timing fields. With a method
budget (``method_budget_s``) the blocks of one (seed, setting) run in parallel and the
budgets are updated when all of them are back: the same blocks run as in one process.
"""
from __future__ import annotations

import copy
import json
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from mocapfix.bench import harm as bench_harm, corrupt
from mocapfix.core.errors import MocapfixError


@dataclass(frozen=True)
class Block:
    """One corrupted motion: ``motion`` (the clean truth) under ``setting`` and ``seed``;
    ``active``: indices of the methods still within their budget."""

    label: str
    motion: object
    setting: str
    seed: int
    active: tuple

    @property
    def path(self) -> str:          # what batch.tasks.error_result names
        return self.label


@dataclass
class BlockTask:
    """Run the active methods on one :class:`Block`; returns ``{"runs": [record, …]}`` in
    method order, or ``{"corrupt_error": message}`` if the protocol cannot corrupt it."""

    protocol: str
    methods: list

    def __call__(self, block: Block) -> dict:
        from mocapfix.bench.scoring import cleaner_input, evaluate

        motion, protocol = block.motion, self.protocol
        try:
            corrupted, mask = corrupt.apply_protocol(motion, protocol, block.setting, block.seed)
        except ValueError as exc:
            return {"corrupt_error": f"{block.label}: {protocol}/{block.setting}: {exc}"}
        base = {"file": block.label, "setting": block.setting, "seed": block.seed,
                "corrupted_pct": 100.0 * float(mask.mean())}
        runs = []
        for i in block.active:
            method = self.methods[i]
            if method.kind == "oracle":
                # its own copy: it keeps its last choice, and a Dask worker's threads
                # may share this task object
                method = copy.copy(method)
            # rotations: the methods get the corrupted channels (bench_rotations); harm:
            # the file as read, whole (bench_harm)
            inp = (corrupted.copy() if protocol in ("rotations", "harm")
                   else cleaner_input(motion, corrupted))
            started, cpu_started = time.perf_counter(), time.process_time()
            try:
                # only the oracle-tuned baselines (bench_oracle) see the truth
                if protocol == "harm":
                    out, noop = bench_harm.clean(method, inp), None
                else:
                    out, noop = (method.run(inp, truth=motion) if method.kind == "oracle"
                                 else method.run(inp))
            except Exception as exc:  # noqa: BLE001 — a failing method is a result
                runs.append({**base, "method": method.name,
                             "seconds": time.perf_counter() - started,
                             "cpu_seconds": time.process_time() - cpu_started,
                             "error": f"{type(exc).__name__}: {exc}"})
                continue
            seconds = time.perf_counter() - started
            cpu = time.process_time() - cpu_started
            found = None
            if protocol == "rotations":
                from mocapfix.bench import rotations as bench_rotations

                scores = bench_rotations.evaluate(motion, out)
            elif protocol == "harm":
                scores, found = bench_harm.evaluate(out)
            else:
                scores = evaluate(protocol, motion, out.positions, mask)
            rec = {**base, "method": method.name, "seconds": seconds, "cpu_seconds": cpu,
                   "metrics": _finite(scores)}
            if found is not None:
                rec["cases"] = found
            if noop:
                rec["skipped"] = noop
            if getattr(method, "last_choice", None):
                rec["tuned"] = method.last_choice
            runs.append(rec)
        return {"runs": runs}


def _finite(d: dict) -> dict:
    return {k: (v if math.isfinite(v) else None) for k, v in d.items()}


_METHODS: dict = {}
_METHODS_LOCK = threading.Lock()


def method_in_worker(cls, name: str, kind: str, config: dict | None, source: str | None):
    """``cls(name, kind, pipeline)`` with the pipeline parsed from ``config`` once per
    process (what a pickled :class:`mocapfix.bench.Method` becomes in a worker)."""
    from mocapfix.config import parse_config

    key = (cls.__module__, cls.__qualname__, name, kind,
           json.dumps(config, sort_keys=True, default=str), source)
    with _METHODS_LOCK:
        if key not in _METHODS:
            _METHODS[key] = cls(name, kind, None if config is None else parse_config(config, source))
        return _METHODS[key]


def _failed_block(block: Block, methods: list, message: str) -> list[dict]:
    """Error records for a block whose task did not come back (e.g. a killed worker)."""
    base = {"file": block.label, "setting": block.setting, "seed": block.seed}
    return [{**base, "method": methods[i].name, "seconds": 0.0, "cpu_seconds": 0.0,
             "error": message} for i in block.active]


def run_blocks(protocol: str, motions: list, methods: list, seeds: list, settings: list,
               method_budget_s: float | None = None, progress=None, spec=None):
    """The run records of every (seed, setting, file, method), in that order, and
    ``stopped``: per method, how many corrupted motions its budget kept it from.

    ``settings`` in the order they run; ``spec``: where
    (:class:`mocapfix.batch.executors.ExecutorSpec`; default: this process)."""
    from mocapfix.batch.tasks import run_tasks
    from mocapfix.batch.executors import ExecutorSpec, open_executor

    task = BlockTask(protocol, list(methods))
    used = {m.name: 0.0 for m in methods}
    stopped: dict[str, int] = {}
    records: list[dict] = []
    every = [(seed, setting) for seed in seeds for setting in settings]
    # without a budget nothing waits for a block: every corrupted motion is one batch
    rounds = [every] if method_budget_s is None else [[b] for b in every]
    width = len(motions) * len(rounds[0])
    # what a task carries: the raw file kept for writing back (``source``) stays behind
    light = [(label, m if m.source is None else m.replace(source=None)) for label, m in motions]
    with open_executor(spec or ExecutorSpec(), width) as running:
        for blocks in rounds:
            # the budget is checked per block (one seed and setting, every file), so that
            # every cell a method has averages the same files as the other methods'
            active = tuple(i for i, m in enumerate(methods)
                           if method_budget_s is None or used[m.name] < method_budget_s)
            for i, m in enumerate(methods):
                if i not in active:
                    stopped[m.name] = stopped.get(m.name, 0) + len(motions) * len(blocks)
            items = [Block(label, motion, setting, seed, active)
                     for seed, setting in blocks for label, motion in light]
            done: list = [None] * len(items)
            for n, result in run_tasks(task, items, running.slots, executor=running.executor):
                block = items[n]
                if "corrupt_error" in result:
                    raise MocapfixError(result["corrupt_error"])
                done[n] = (result["runs"] if "runs" in result
                           else _failed_block(block, methods, result.get("error", "task failed")))
                if progress:
                    progress(f"{Path(block.label).name} {protocol}/{block.setting} seed {block.seed}")
            for runs in done:
                for rec in runs:
                    used[rec["method"]] += rec["cpu_seconds"]
                records += runs
    return records, stopped
