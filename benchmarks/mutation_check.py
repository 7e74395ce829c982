#!/usr/bin/env python3
"""Mutation check of the accuracy tests: each mutant of the default C3D pipeline
(benchmarks/mutants.py) is applied to mocapfix inside a pytest run of the accuracy tests;
a mutant is caught when at least one test fails. The control ("none") must pass.
Prints a Markdown table; exit status 1 when a mutant survives or the control fails.

    MOCAPFIX_REQUIRE_DATA=1 python benchmarks/mutation_check.py [MUTANT ...]

One pytest process per mutant (the accuracy cases are cached per process): about
3–6 min each on 2 cores.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
TESTS = ["tests/config/test_default_accuracy.py", "tests/cleaners/test_tsmc.py"]

sys.path.insert(0, str(HERE))
from mutants import MUTANTS  # noqa: E402


def run(mutant: str) -> tuple[int, int, list[str], float]:
    env = dict(os.environ, MOCAPFIX_MUTANT=mutant,
               PYTHONPATH=os.pathsep.join(filter(None, [str(HERE), os.environ.get("PYTHONPATH")])))
    env.setdefault("OMP_NUM_THREADS", "1")
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "mutants", "-p", "no:cacheprovider",
                           "-rf", *TESTS], cwd=REPO, env=env, capture_output=True, text=True)
    out = proc.stdout
    failed = sorted(set(re.findall(r"^FAILED (\S+)", out, flags=re.M)))
    passed = sum(int(n) for n in re.findall(r"(\d+) passed", out.splitlines()[-1] if out else ""))
    if proc.returncode not in (0, 1):
        failed.append(f"pytest exit {proc.returncode}: {out[-300:]}{proc.stderr[-300:]}")
    return passed, len(failed), failed, time.perf_counter() - t0


def main(names: list[str]) -> int:
    names = names or list(MUTANTS)
    # the mutants never touch the baselines: compute them once, in the first run
    os.environ.setdefault("MOCAPFIX_BASELINE_CACHE", tempfile.mkdtemp(prefix="mocapfix-baselines-"))
    print("| mutant | what | tests failed | caught by (first 3) | s |")
    print("|---|---|---:|---|---:|")
    bad = False
    for name in names:
        passed, n_failed, failed, seconds = run(name)
        short = ", ".join(f.split("::", 1)[-1] for f in failed[:3])
        if name == "none":
            ok = n_failed == 0
            verdict = "control passes" if ok else "CONTROL FAILS"
        else:
            ok = n_failed > 0
            verdict = short if ok else "SURVIVED"
        bad |= not ok
        print(f"| {name} | {MUTANTS[name]} | {n_failed} of {n_failed + passed} | {verdict} | "
              f"{seconds:.0f} |", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
