"""``mocapfix bench``: corrupt clean captures in seeded ways, clean them, and score the
result against the truth — or, with the ``harm`` protocol, score what a method changes on
files as read.

- :mod:`mocapfix.bench.run` — methods, the run over files, seeds and settings, the tables;
- :mod:`mocapfix.bench.corrupt` — the seeded corruptions of the position protocols;
- :mod:`mocapfix.bench.scoring` — what the methods see and the protocols' metrics;
- :mod:`mocapfix.bench.tasks` — one task per (seed, setting, file) over a batch executor;
- :mod:`mocapfix.bench.rotations`, :mod:`mocapfix.bench.harm`,
  :mod:`mocapfix.bench.kinect` — the protocols with their own corruption or scoring;
- :mod:`mocapfix.bench.oracle` — oracle-tuned baselines;
- :mod:`mocapfix.bench.cli` — the ``mocapfix bench`` command.
"""
from mocapfix.bench.run import (BASELINES, METRICS, NAMED, PROTOCOL_NOTES, BenchResult, Method,
                                resolve_methods, run)
from mocapfix.bench.scoring import cleaner_input, evaluate

__all__ = ["BASELINES", "METRICS", "NAMED", "PROTOCOL_NOTES", "BenchResult", "Method",
           "cleaner_input", "evaluate", "resolve_methods", "run"]
