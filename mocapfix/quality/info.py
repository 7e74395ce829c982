"""What ``mocapfix info`` says about a file: shape, rate, units, markers, unlabelled
trajectories (:mod:`mocapfix.pipeline.unlabelled`: counted apart, not in the missing figures),
gaps, and per format what the file holds besides (C3D: analog channels, events, force plates; Kinect:
tracking state and time stamps). Gap figures come from :mod:`mocapfix.quality.measure`, the same
measurements ``check`` and the clean report use."""
from __future__ import annotations

import numpy as np

from mocapfix.formats import MARKER_FORMATS
from mocapfix.core.errors import one_line
from mocapfix.quality.measure import measure_input
from mocapfix.core.motion import Motion
from mocapfix.pipeline.unlabelled import UNLABELLED


def _strings(source, key) -> list[str]:
    param = source.param(key)
    if param is None or param.bytes_per_element != -1:
        return []
    return [v.strip("\x00 ") for v in param.value]


def _scalar(source, key, kind="float"):
    param = source.param(key)
    return None if param is None else param.scalar(kind)


def c3d_details(motion: Motion) -> dict:
    """Analog channels, rates, events and force plates of a C3D file."""
    src = motion.source
    if src is None or not hasattr(src, "analog_per_frame"):
        return {}
    words = src.analog.shape[1] if src.analog.ndim == 2 else 0
    per = max(src.analog_per_frame, 1)
    channels = words // per if src.analog_per_frame else 0
    labels = _strings(src, "ANALOG:LABELS")[:channels]
    rate = _scalar(src, "ANALOG:RATE")
    plates = _scalar(src, "FORCE_PLATFORM:USED", "uint")
    types = src.param("FORCE_PLATFORM:TYPE")
    type_values = types.value if types is not None else None
    events = [{"time": round(e["time"], 4), "label": e["label"]} for e in src.events]
    events += [{"time": round(e["time"], 4), "label": e["label"], "context": e["context"]}
               for e in src.parameter_events]
    return {
        "analog": {"channels": int(channels),
                   "rate": float(rate) if rate else (float(motion.fps) * src.analog_per_frame
                                                     if channels else None),
                   "labels": labels},
        "events": events,
        "force_plates": {"count": int(plates) if plates is not None else 0,
                         "types": [int(t) for t in np.ravel(type_values)][:int(plates or 0)]
                         if isinstance(type_values, np.ndarray) else []},
        "storage": src.storage,
    }


def summarise(motion: Motion) -> dict:
    measured = measure_input(motion, swaps=False, outliers=False)
    f = measured["file"]
    summary = {
        "path": motion.path,
        "format": motion.format,
        "frames": f["frames"],
        "fps": round(float(motion.fps), 6),
        "duration_s": round(float(motion.duration), 6),
        "joints": f["joints"],
        "model_outputs": sum(kind != "marker" for kind in motion.kinds or ()),
        "unlabelled": f.get("unlabelled", []),
        "names": list(motion.names),
        "units": motion.units,
        "skeleton": motion.skeleton is not None or motion.rig is not None,
        "rotations": motion.rig is not None,
        "missing_fraction": f["missing"],
        "gaps": f["gaps"],
        "interior_gaps": f["interior_gaps"],
        "longest_gap_frames": f["longest_gap_frames"],
        "longest_gap_s": f["longest_gap_s"],
        "never_observed": f["never_seen"],
        "empty_frames": f["empty_frames"],
        "frames_outside_take": f.get("frames_outside_take", []),
        "held_frames": f["held_frames"],
        "cut_frames": f["cut_frames"],
        "notes": list(motion.notes),
    }
    if motion.format == "kinect":
        summary["dropped_frames"] = f["dropped_frames"]
        summary["timestamp_jumps"] = f["timestamp_jumps"]
        if "tracking" in f:
            summary["tracking"] = f["tracking"]
    if motion.format == "c3d":
        summary.update(c3d_details(motion))
    return summary


def _take(s: dict) -> str:
    """Where the missing figures are counted when the file has empty frames at its ends."""
    outside = s.get("frames_outside_take") or []
    if not outside:
        return ""
    first = outside[0][1] if outside[0][0] == 0 else 0
    last = s["frames"] - (outside[-1][1] if outside[-1][0] > 0 else 0) - 1
    return f"; in the take, frames {first}–{last}"


def _list(names, limit):
    shown = ", ".join(map(one_line, names[:limit]))
    more = len(names) - limit
    return f"{shown}{f' … (+{more}; -v lists all)' if more > 0 else ''}"


def format_text(summary: dict, verbose: bool = False) -> str:
    s = summary
    limit = 10 ** 6 if verbose else 12
    lines = [
        one_line(s["path"]),
        f"  format      {s['format']}",
        f"  frames      {s['frames']} at {s['fps']:g} fps ({s['duration_s']:.2f} s)",
        f"  {'markers' if s['format'] in MARKER_FORMATS else 'joints':<11} {s['joints']}"
        + (f" + {len(s['unlabelled'])} unlabelled trajector{'y' if len(s['unlabelled']) == 1 else 'ies'}"
           if s.get("unlabelled") else "")
        + (f" + {s['model_outputs']} model outputs" if s.get("model_outputs") else "")
        + f"  (units {s['units']}; "
        f"skeleton {'yes' if s['skeleton'] else 'no'}; rotations {'yes' if s['rotations'] else 'no'})",
        f"  names       {_list(s['names'], limit)}",
        f"  missing     {100 * s['missing_fraction']:.1f} % in {s['gaps']} gaps "
        f"({s['interior_gaps']} interior), longest {s['longest_gap_frames']} frames"
        f" ({s['longest_gap_s'] or 0:.2f} s)" + _take(s),
    ]
    if s.get("unlabelled"):
        lines.append("  unlabelled  not cleaned or judged by default: " + _list(
            [f"{u['name']} ({u['why'].removeprefix(UNLABELLED).strip(' ()')})"
             for u in s["unlabelled"]], 6 if not verbose else limit))
    if s["never_observed"]:
        lines.append(f"  never seen  {_list(s['never_observed'], 8 if not verbose else limit)}")
    if s["empty_frames"]:
        spans = [f"{a}–{a + n - 1}" + (f" ({n / s['fps']:.2f} s)" if s["fps"] else "")
                 for a, n in s["empty_frames"]]
        total = sum(n for _, n in s["empty_frames"])
        lines.append(f"  empty       {total} frames with no "
                     f"{'marker' if s['format'] in MARKER_FORMATS else 'joint'} seen: "
                     f"{_list(spans, 4 if not verbose else limit)}")
    if "analog" in s:
        a = s["analog"]
        rate = f" at {a['rate']:g} Hz" if a.get("rate") else ""
        lines.append(f"  analog      {a['channels']} channels{rate}"
                     + (f": {_list(a['labels'], limit)}" if a["labels"] else ""))
        fp = s["force_plates"]
        lines.append(f"  plates      {fp['count']} force plates"
                     + (f" (types {', '.join(map(str, fp['types']))})" if fp["types"] else ""))
        ev = s["events"]
        lines.append(f"  events      {len(ev)}" + (": " + _list(
            [f"{e.get('context', '')} {e['label']} {e['time']:.2f} s".strip() for e in ev], limit)
            if ev else ""))
    if "tracking" in s:
        t = s["tracking"]
        lines.append(f"  tracking    tracked {100 * t['tracked']:.1f} %, inferred "
                     f"{100 * t['inferred']:.1f} %, not tracked {100 * t['not_tracked']:.1f} %")
    if s.get("dropped_frames"):
        lines.append(f"  timing      {s['dropped_frames']} dropped frames, "
                     f"{s['timestamp_jumps']} irregular time steps")
    if s.get("held_frames"):
        lines.append(f"  held        {s['held_frames']} frames repeat the frame before them "
                     "exactly (no new measurement; clean cleans each once)")
    if s.get("cut_frames"):
        shown = ", ".join(map(str, s["cut_frames"][:10])) + (", ..." if len(s["cut_frames"]) > 10 else "")
        lines.append(f"  cuts        the take jumps as a whole at frames {shown} (takes joined? "
                     "clean cleans each part on its own)")
    for note in s["notes"]:
        lines.append(f"  note        {note}")
    return "\n".join(lines)
