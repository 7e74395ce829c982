"""What ``mocapfix info`` says about a file: shape, rate, units, gaps, tracking state."""
from __future__ import annotations

import numpy as np

from mocapfix.gaps import runs
from mocapfix.motion import Motion


def summarise(motion: Motion) -> dict:
    missing = motion.missing
    col, start, length = runs(missing)
    T, J = missing.shape
    summary = {
        "path": motion.path,
        "format": motion.format,
        "frames": T,
        "fps": round(float(motion.fps), 6),
        "duration_s": round(float(motion.duration), 6),
        "joints": J,
        "units": motion.units,
        "skeleton": motion.skeleton is not None or motion.rig is not None,
        "rotations": motion.rig is not None,
        "missing_fraction": float(missing.mean()) if missing.size else 0.0,
        "gaps": int(len(length)),
        "interior_gaps": int(np.sum((start > 0) & (start + length < T))),
        "longest_gap_frames": int(length.max()) if len(length) else 0,
        "never_observed": [motion.names[j] for j in range(J) if T and missing[:, j].all()],
        "notes": list(motion.notes),
    }
    if motion.confidence is not None and motion.confidence.size:
        conf = motion.confidence
        summary["tracking"] = {
            "tracked": float(np.mean(conf >= 1.0)),
            "inferred": float(np.mean((conf > 0) & (conf < 1.0))),
            "not_tracked": float(np.mean(conf <= 0)),
        }
    return summary


def format_text(summary: dict) -> str:
    s = summary
    lines = [
        f"{s['path']}",
        f"  format      {s['format']}",
        f"  frames      {s['frames']} at {s['fps']:g} fps ({s['duration_s']:.2f} s)",
        f"  joints      {s['joints']}  (units {s['units']}; "
        f"skeleton {'yes' if s['skeleton'] else 'no'}; rotations {'yes' if s['rotations'] else 'no'})",
        f"  missing     {100 * s['missing_fraction']:.1f} % in {s['gaps']} gaps "
        f"({s['interior_gaps']} interior), longest {s['longest_gap_frames']} frames",
    ]
    if s["never_observed"]:
        shown = ", ".join(s["never_observed"][:8])
        more = len(s["never_observed"]) - 8
        lines.append(f"  never seen  {shown}{f' … (+{more})' if more > 0 else ''}")
    if "tracking" in s:
        t = s["tracking"]
        lines.append(f"  tracking    tracked {100 * t['tracked']:.1f} %, inferred "
                     f"{100 * t['inferred']:.1f} %, not tracked {100 * t['not_tracked']:.1f} %")
    for note in s["notes"]:
        lines.append(f"  note        {note}")
    return "\n".join(lines)
