"""Tables for benchmarks/RESULTS.md ("Rotation channels") from the JSON of

    mocapfix bench --protocol rotations --seeds 3 --per-file --json rot.json \\
        --methods euler-gaussian,euler-median+gaussian,rotation_smooth,rotation_outliers,rotation_denoise,mssa \\
        --configs configs/animation-bvh.yaml,configs/default.yaml ../shared/data/bvh/*.bvh ../shared/data/asfamc/*.amc

    python benchmarks/rotation_tables.py rot.json

Prints: joint error (% of skeleton height) per method and setting, each config's ratio to
the better of the two animator's baselines, animation-bvh.yaml per file (ratio to the
better baseline on that file; the worst file per setting), and mssa per file (CMU ASF
files, none in the training corpus: shipped model; BVH files: bases learned from the file).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

BASELINES = ("euler-gaussian", "euler-median+gaussian")


def main(path):
    data = json.loads(Path(path).read_text())
    rows = data["summary"]
    settings = data["settings"]
    methods = list(dict.fromkeys(r["method"] for r in rows))
    cell = {(r["setting"], r["method"]): r["metrics"] for r in rows}

    def val(s, m, k="pos_err_pct"):
        return cell.get((s, m), {}).get(k, {}).get("mean", float("nan"))

    print("| method | " + " | ".join(settings) + " | mm (mixed) | deg/ch (mixed) | write-back max mm (mixed) |")
    print("|---" * (len(settings) + 4) + "|")
    for m in methods:
        print(f"| {m} | " + " | ".join(f"{val(s, m):.3f}" for s in settings)
              + f" | {val('mixed', m, 'pos_err_mm'):.2f} | {val('mixed', m, 'deg_err'):.3f} | "
              f"{val('mixed', m, 'writeback_mm'):.2f} |")
    print()
    print("| ratio to the better baseline | " + " | ".join(s for s in settings if s != "clean") + " |")
    print("|---" * len(settings) + "|")
    for m in methods:
        if m in BASELINES or m == "none":
            continue
        ratios = [val(s, m) / min(val(s, b) for b in BASELINES) for s in settings if s != "clean"]
        print(f"| {m} | " + " | ".join(f"{r:.2f}×" for r in ratios) + " |")
    print()
    per = data.get("summary_per_file", [])
    files = list(dict.fromkeys(r["file"] for r in per))
    pcell = {(r["file"], r["setting"], r["method"]): r["metrics"].get("pos_err_pct", {}).get("mean")
             for r in per}
    config = next((m for m in methods if m.startswith("config:animation-bvh")), None)
    if config:
        print(f"| file ({config}) | " + " | ".join(settings) + " |")
        print("|---" * (len(settings) + 1) + "|")
        worst = {}
        for f in files:
            cells = []
            for s in settings:
                ours = pcell.get((f, s, config), float("nan"))
                if s == "clean":
                    cells.append(f"{ours:.3f}")
                    continue
                ratio = ours / min(pcell.get((f, s, b), float("nan")) for b in BASELINES)
                cells.append(f"{ours:.3f} ({ratio:.2f}×)")
                if ratio > worst.get(s, ("", 0.0))[1]:
                    worst[s] = (Path(f).name, ratio)
            print(f"| {Path(f).name} | " + " | ".join(cells) + " |")
        print()
        print("Worst file: " + "; ".join(f"{s} {n} {r:.2f}×" for s, (n, r) in worst.items()))
        print()
    print("| file | bases | " + " | ".join(f"{s}: mssa / none / euler-gaussian" for s in settings) + " |")
    print("|---" * (len(settings) + 2) + "|")
    for f in files:
        bases = "shipped mssa-cmu" if f.endswith(".amc") else "self"
        cells = [f"{pcell.get((f, s, 'mssa'), float('nan')):.3f} / {pcell.get((f, s, 'none'), float('nan')):.3f} / "
                 f"{pcell.get((f, s, 'euler-gaussian'), float('nan')):.3f}" for s in settings]
        print(f"| {Path(f).name} | {bases} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(sys.argv[1])
