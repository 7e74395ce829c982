#!/usr/bin/env python3
"""Clean every shared file with every shipped config, and compare two such snapshots byte
for byte (timings aside): the check that a refactor changed no behaviour.

    python scripts/output_snapshot.py take OUT [--data ../shared/data] [-j 2]
    python scripts/output_snapshot.py compare OUT_BEFORE OUT_AFTER

``take`` runs ``mocapfix clean DATA -o OUT/<config> -c <config> --report json,md,html`` for
each shipped config (``mocapfix configs``), ``mocapfix check DATA --json --junit`` with
each shipped rule set and ``mocapfix info DATA --json``, through the command line a user
runs.
``compare`` walks both trees: cleaned files, ASF copies and the effective config must be
identical bytes; reports are compared with their timings masked (JSON: every ``seconds``
value; Markdown and HTML: the seconds column of the steps table; JUnit XML: the ``time``
attributes and the timestamp; the effective config: the path of the config it came
from). The manifests (run times, paths) are not compared. Prints each difference and exits 1 if there is one.
About 2 minutes on 2 cores.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SKIPPED = {"mocapfix-manifest.jsonl"}
#: the last cell of a steps-table row (its seconds), in Markdown and in HTML
_MD_SECONDS = re.compile(r"^(\| step \d+ .*\| )[0-9.eE+-]+( \|)$", re.MULTILINE)
_HTML_SECONDS = re.compile(r"(<tr><td>step \d+ (?:(?!</tr>).)*<td>)[0-9.eE+-]+(</td></tr>)")
_XML_TIMES = re.compile(r'(time|timestamp|hostname)="[^"]*"')
#: the effective config's first line names the config file's path (the checkout)
_CONFIG_FROM = re.compile(r"^# effective config of this run \(from .*\)$", re.MULTILINE)


def take(out: Path, data: Path, jobs: int) -> int:
    status = 0
    # the shipped presets, read off the package folder (not imported: the script compares
    # code whose modules may have moved)
    shipped = REPO / "mocapfix" / "configs"
    for name in sorted(p.stem for p in shipped.glob("*.yaml")):
        cmd = [sys.executable, "-m", "mocapfix.cli", "clean", str(data), "-o", str(out / name),
               "-c", name, "--report", "json,md,html", "-j", str(jobs), "-q", "--overwrite"]
        done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
        print(f"{name}: exit {done.returncode} {done.stdout.strip().splitlines()[-1:] or ''}")
        status = max(status, 0 if done.returncode in (0, 1) else done.returncode)
    for name in sorted(p.stem for p in (shipped / "rules").glob("*.yaml")):
        cmd = [sys.executable, "-m", "mocapfix.cli", "check", str(data), "-r", name, "--json",
               "--junit", str(out / f"check-{name}.xml")]
        done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
        (out / f"check-{name}.json").write_text(done.stdout)
        print(f"check -r {name}: exit {done.returncode}")
    done = subprocess.run([sys.executable, "-m", "mocapfix.cli", "info", str(data), "--json"],
                          cwd=REPO, capture_output=True, text=True)
    (out / "info.json").write_text(done.stdout)
    print(f"info: exit {done.returncode}")
    return status


def _masked(path: Path) -> bytes:
    """The file's bytes with its timings masked (reports), or as they are."""
    raw = path.read_bytes()
    name = path.name
    if name == "mocapfix-config.yaml":
        return _CONFIG_FROM.sub("# effective config", raw.decode()).encode()
    if name.endswith(".xml"):
        return _XML_TIMES.sub(r'\1="T"', raw.decode()).encode()
    if name.endswith(".report.json") or name.startswith("check-") and name.endswith(".json"):
        def drop(obj):
            if isinstance(obj, dict):
                return {k: (None if k == "seconds" else drop(v)) for k, v in obj.items()}
            if isinstance(obj, list):
                return [drop(v) for v in obj]
            return obj
        return json.dumps(drop(json.loads(raw)), sort_keys=True).encode()
    if name.endswith(".report.md"):
        return _MD_SECONDS.sub(r"\1T\2", raw.decode()).encode()
    if name.endswith(".report.html"):
        return _HTML_SECONDS.sub(r"\1T\2", raw.decode()).encode()
    return raw


def compare(a: Path, b: Path) -> int:
    files_a = {p.relative_to(a) for p in a.rglob("*") if p.is_file() and p.name not in SKIPPED}
    files_b = {p.relative_to(b) for p in b.rglob("*") if p.is_file() and p.name not in SKIPPED}
    differ = 0
    for rel in sorted(files_a ^ files_b):
        print(f"only in {'before' if rel in files_a else 'after'}: {rel}")
        differ += 1
    for rel in sorted(files_a & files_b):
        if _masked(a / rel) != _masked(b / rel):
            print(f"differs: {rel}")
            differ += 1
    print(f"{len(files_a & files_b)} files compared, {differ} difference(s)")
    return 1 if differ else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="verb", required=True)
    t = sub.add_parser("take")
    t.add_argument("out", type=Path)
    t.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    t.add_argument("-j", "--jobs", type=int, default=2)
    c = sub.add_parser("compare")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    args = ap.parse_args(argv)
    if args.verb == "take":
        return take(args.out, args.data, args.jobs)
    return compare(args.before, args.after)


if __name__ == "__main__":
    sys.exit(main())
