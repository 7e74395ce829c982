"""Per-joint quality report: what was wrong with a capture, what each cleaner changed, and
what is still wrong — as JSON (schema below), Markdown, and a self-contained HTML page.

JSON schema ``mocapfix.report/1``::

    {"schema": "mocapfix.report/1", "file": {...summary...}, "steps": [...],
     "thresholds": {...}, "joints": [{"name", "status", "reasons", "missing_before",
     "missing_after", "gaps": {"count", "longest_frames", "filled": [{"start", "length",
     "filled_by"}], "unfilled": [...]}, "outliers_flagged", "correction_mm": {"mean", "max"},
     "jitter_before", "jitter_after" (RMS acceleration, m/s²), "bone_variation_before",
     "bone_variation_after", "writeback_residual_mm": {"mean", "max"} }], "bones": [...]}

Lengths are reported in mm whatever the file's unit. The HTML plots are inline SVG, so
neither the page nor this module needs a plotting library.
"""
from __future__ import annotations

import html
import json
from dataclasses import dataclass

import numpy as np

from mocapfix.gaps import runs
from mocapfix.metrics import bone_lengths, rms_acceleration
from mocapfix.motion import Motion

SCHEMA = "mocapfix.report/1"
STATUS_ORDER = {"OK": 0, "WARN": 1, "FAIL": 2}

#: thresholds (overridable in the config's ``report:`` section)
DEFAULT_THRESHOLDS = {
    "warn_missing_after": 0.0,      # any sample still missing → WARN
    "fail_missing_after": 0.10,     # more than 10 % still missing → FAIL
    "warn_correction_mm": 50.0,     # a sample moved more than this → WARN
    "warn_outlier_fraction": 0.05,  # more than 5 % of samples flagged → WARN
    "warn_writeback_mm": 1.0,       # rotation write-back residual above this → WARN
    "fail_writeback_mm": 20.0,
    "warn_bone_variation": 0.05,    # bone length std/mean after cleaning
}


def _f(x) -> float | None:
    x = float(x)
    return None if not np.isfinite(x) else round(x, 6)


@dataclass
class CleanResult:
    """Everything the report needs about one cleaned file."""

    original: Motion
    cleaned: Motion
    records: list
    writeback_residual: np.ndarray | None = None
    seconds: float = 0.0


def _bones(motion: Motion) -> np.ndarray:
    if motion.skeleton is not None and motion.skeleton.bones:
        return motion.skeleton.bone_array
    return np.zeros((0, 2), dtype=np.intp)


def _who_filled(records, T: int, J: int) -> np.ndarray:
    """(T, J) index into ``records`` of the step that filled each sample (-1: none)."""
    who = np.full((T, J), -1, dtype=np.intp)
    for n, rec in enumerate(records):
        who[rec.filled & (who < 0)] = n
        who[rec.flagged] = -1          # flagged later → a later filler takes over
    return who


def build_report(result: CleanResult, thresholds: dict | None = None) -> dict:
    th = {**DEFAULT_THRESHOLDS, **(thresholds or {})}
    before, after, records = result.original, result.cleaned, result.records
    T, J = before.positions.shape[:2]
    mm = before.metres_per_unit * 1000.0
    miss_b, miss_a = before.missing, after.missing
    flagged = np.zeros((T, J), bool)
    for rec in records:
        flagged |= rec.flagged
    who = _who_filled(records, T, J)
    moved = np.linalg.norm(after.positions - before.positions, axis=-1) * mm
    moved[miss_b | miss_a] = np.nan
    metres = before.metres_per_unit
    jitter_b = rms_acceleration(before.positions, before.fps) * metres if T > 2 else np.full(J, np.nan)
    jitter_a = rms_acceleration(after.positions, after.fps) * metres if T > 2 else np.full(J, np.nan)
    bones = _bones(before)
    var_b = var_a = np.zeros(0)
    if len(bones):
        with np.errstate(invalid="ignore", divide="ignore"):
            lb, la = bone_lengths(before.positions, bones), bone_lengths(after.positions, bones)
            var_b = np.nanstd(lb, axis=0) / np.nanmean(lb, axis=0)
            var_a = np.nanstd(la, axis=0) / np.nanmean(la, axis=0)
    col, start, length = runs(miss_b)
    labels = [r.step for r in records]
    joints = []
    for j in range(J):
        sel = col == j
        gaps_filled, gaps_left = [], []
        for s, n in zip(start[sel], length[sel]):
            span_who = who[s:s + n, j]
            if (span_who >= 0).all():
                steps = np.unique(span_who)
                gaps_filled.append({"start": int(s), "length": int(n),
                                    "filled_by": ", ".join(labels[k] for k in steps)})
            else:
                gaps_left.append({"start": int(s), "length": int(n),
                                  "filled_frames": int((span_who >= 0).sum())})
        mv = moved[:, j]
        has_mv = np.isfinite(mv).any()
        entry = {
            "name": before.names[j],
            "missing_before": _f(miss_b[:, j].mean()) if T else 0.0,
            "missing_after": _f(miss_a[:, j].mean()) if T else 0.0,
            "gaps": {"count": int(sel.sum()),
                     "longest_frames": int(length[sel].max()) if sel.any() else 0,
                     "filled": gaps_filled, "unfilled": gaps_left},
            "outliers_flagged": int(flagged[:, j].sum()),
            "correction_mm": {"mean": _f(np.nanmean(mv)) if has_mv else 0.0,
                              "max": _f(np.nanmax(mv)) if has_mv else 0.0},
            "jitter_before": _f(jitter_b[j]),
            "jitter_after": _f(jitter_a[j]),
        }
        if len(bones):
            mine = bones[:, 1] == j
            if mine.any() and np.isfinite(var_b[mine]).any():
                entry["bone_variation_before"] = _f(np.nanmax(var_b[mine]))
            if mine.any() and np.isfinite(var_a[mine]).any():
                entry["bone_variation_after"] = _f(np.nanmax(var_a[mine]))
        if result.writeback_residual is not None:
            res = result.writeback_residual[:, j] * mm
            entry["writeback_residual_mm"] = {"mean": _f(np.nanmean(res)), "max": _f(np.nanmax(res))}
        entry["status"], entry["reasons"] = _status(entry, th, T)
        joints.append(entry)

    worst = max((STATUS_ORDER[j["status"]] for j in joints), default=0)
    file_status = next(k for k, v in STATUS_ORDER.items() if v == worst)
    report = {
        "schema": SCHEMA,
        "file": {
            "path": before.path,
            "format": before.format,
            "frames": T,
            "fps": _f(before.fps),
            "joints": J,
            "units": before.units,
            "status": file_status,
            "missing_before": _f(miss_b.mean()) if miss_b.size else 0.0,
            "missing_after": _f(miss_a.mean()) if miss_a.size else 0.0,
            "samples_filled": int((miss_b & ~miss_a).sum()),
            "samples_flagged": int(flagged.sum()),
            "gaps_before": int(len(length)),
            "gaps_unfilled": int(sum(len(j["gaps"]["unfilled"]) for j in joints)),
            "joints_by_status": {k: sum(j["status"] == k for j in joints) for k in STATUS_ORDER},
            "seconds": _f(result.seconds),
            "notes": list(before.notes) + [n for n in after.notes if n not in before.notes],
        },
        "steps": [{"step": r.step, "cleaner": r.cleaner, "seconds": _f(r.seconds),
                   "filled": int(r.filled.sum()), "flagged": int(r.flagged.sum()),
                   "moved_mean_mm": _f(np.mean(r.moved) * mm) if r.moved.size else 0.0,
                   **({"skipped": r.skipped} if r.skipped else {}), "info": r.info}
                  for r in records],
        "thresholds": th,
        "joints": joints,
    }
    if len(bones):
        report["bones"] = [{"bone": f"{before.names[a]}-{before.names[b]}",
                            "variation_before": _f(vb), "variation_after": _f(va)}
                           for (a, b), vb, va in zip(bones, var_b, var_a)]
    if result.writeback_residual is not None:
        res = result.writeback_residual * mm
        report["file"]["writeback_residual_mm"] = {"mean": _f(np.nanmean(res)), "max": _f(np.nanmax(res))}
    return report


def _status(entry: dict, th: dict, T: int) -> tuple[str, list[str]]:
    reasons, status = [], "OK"

    def raise_to(level, why):
        nonlocal status
        reasons.append(f"{level}: {why}")
        if STATUS_ORDER[level] > STATUS_ORDER[status]:
            status = level

    ma = entry["missing_after"] or 0.0
    if ma > th["fail_missing_after"]:
        raise_to("FAIL", f"{100 * ma:.1f} % still missing (> {100 * th['fail_missing_after']:g} %)")
    elif ma > th["warn_missing_after"]:
        raise_to("WARN", f"{100 * ma:.1f} % still missing")
    if (entry["correction_mm"]["max"] or 0.0) > th["warn_correction_mm"]:
        raise_to("WARN", f"a sample moved {entry['correction_mm']['max']:.1f} mm (> {th['warn_correction_mm']:g} mm)")
    if T and entry["outliers_flagged"] / T > th["warn_outlier_fraction"]:
        raise_to("WARN", f"{entry['outliers_flagged']} samples flagged as outliers")
    wb = entry.get("writeback_residual_mm")
    if wb and wb["max"] is not None:
        if wb["max"] > th["fail_writeback_mm"]:
            raise_to("FAIL", f"rotation write-back misses by up to {wb['max']:.1f} mm")
        elif wb["max"] > th["warn_writeback_mm"]:
            raise_to("WARN", f"rotation write-back misses by up to {wb['max']:.1f} mm")
    bv = entry.get("bone_variation_after")
    if bv is not None and bv > th["warn_bone_variation"]:
        raise_to("WARN", f"bone length varies by {100 * bv:.1f} %")
    return status, reasons


# -- writers --------------------------------------------------------------------------

def to_json(report: dict) -> str:
    return json.dumps(report, indent=1, allow_nan=False)


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.1f} %"


def _num(x, fmt="{:.1f}") -> str:
    return "–" if x is None else fmt.format(x)


def _ranked(report: dict) -> list[dict]:
    return sorted(report["joints"], key=lambda j: (-STATUS_ORDER[j["status"]],
                                                   -(j["missing_before"] or 0), j["name"]))


def to_markdown(report: dict) -> str:
    f = report["file"]
    out = [f"# mocapfix report: `{f['path']}`", "",
           f"**Status: {f['status']}** — {f['frames']} frames at {f['fps']} fps, {f['joints']} "
           f"joints/markers ({f['format']}, units {f['units']}).", "",
           f"- missing before: {_pct(f['missing_before'])}, after: {_pct(f['missing_after'])}",
           f"- samples filled: {f['samples_filled']}, flagged as outliers: {f['samples_flagged']}",
           f"- gaps before: {f['gaps_before']}, still unfilled: {f['gaps_unfilled']}",
           f"- joints OK / WARN / FAIL: {f['joints_by_status']['OK']} / "
           f"{f['joints_by_status']['WARN']} / {f['joints_by_status']['FAIL']}"]
    if "writeback_residual_mm" in f:
        wb = f["writeback_residual_mm"]
        out.append(f"- rotation write-back residual: mean {_num(wb['mean'], '{:.3f}')} mm, "
                   f"max {_num(wb['max'], '{:.3f}')} mm")
    for note in f["notes"]:
        out.append(f"- note: {note}")
    out += ["", "## Steps", "", "| step | cleaner | filled | flagged | mean move (mm) | s |",
            "|---|---|---:|---:|---:|---:|"]
    for s in report["steps"]:
        name = s["step"] + (f" (skipped: {s['skipped']})" if s.get("skipped") else "")
        out.append(f"| {name} | {s['cleaner']} | {s['filled']} | {s['flagged']} | "
                   f"{_num(s['moved_mean_mm'], '{:.3f}')} | {_num(s['seconds'], '{:.3f}')} |")
    out += ["", "## Joints", "",
            "| joint | status | missing before → after | gaps (longest) | outliers | "
            "correction mean / max (mm) | jitter before → after (m/s²) | why |",
            "|---|---|---|---|---:|---|---|---|"]
    for j in _ranked(report):
        out.append(
            f"| {j['name']} | {j['status']} | {_pct(j['missing_before'])} → {_pct(j['missing_after'])} "
            f"| {j['gaps']['count']} ({j['gaps']['longest_frames']}) | {j['outliers_flagged']} "
            f"| {_num(j['correction_mm']['mean'], '{:.2f}')} / {_num(j['correction_mm']['max'], '{:.1f}')} "
            f"| {_num(j['jitter_before'], '{:.2f}')} → {_num(j['jitter_after'], '{:.2f}')} "
            f"| {'; '.join(j['reasons']) or '–'} |")
    th = report["thresholds"]
    out += ["", "Thresholds: " + ", ".join(f"{k} = {v}" for k, v in th.items()), ""]
    return "\n".join(out)


def _svg_trajectory(before: np.ndarray, after: np.ndarray, filled: np.ndarray,
                    missing_before: np.ndarray, fps: float, title: str, unit_mm: float) -> str:
    """Inline SVG: x, y, z over time before (grey) and after (colour); filled spans shaded."""
    W, H, pad = 760, 170, 30
    T = len(after)
    t = np.arange(T)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{3 * H}" '
             f'viewBox="0 0 {W} {3 * H}" role="img"><title>{html.escape(title)}</title>']
    for axis, colour in enumerate(("#c0392b", "#27ae60", "#2c6fbb")):
        yb, ya = before[:, axis] * unit_mm, after[:, axis] * unit_mm
        both = np.concatenate([yb[np.isfinite(yb)], ya[np.isfinite(ya)]])
        lo, hi = (both.min(), both.max()) if both.size else (0.0, 1.0)
        hi = hi if hi > lo else lo + 1.0
        top = axis * H

        def X(i):
            return pad + (W - 2 * pad) * i / max(T - 1, 1)

        def Y(v):
            return top + H - pad / 2 - (H - pad) * (v - lo) / (hi - lo)

        for mask, fill in ((missing_before, "#f6dada"), (filled, "#d6ecd6")):
            c, s, n = runs(mask[:, None])
            for a, m in zip(s, n):
                parts.append(f'<rect x="{X(a):.1f}" y="{top + pad / 2:.1f}" width="{max(X(a + m) - X(a), 1):.1f}" '
                             f'height="{H - pad:.1f}" fill="{fill}"/>')
        for y, style in ((yb, 'stroke="#999" stroke-width="1"'), (ya, f'stroke="{colour}" stroke-width="1.3"')):
            ok = np.isfinite(y)
            c, s, n = runs(ok[:, None])
            for a, m in zip(s, n):
                step = max(1, m // 1500)
                idx = np.arange(a, a + m, step)
                pts = " ".join(f"{X(i):.1f},{Y(y[i]):.1f}" for i in idx)
                parts.append(f'<polyline fill="none" {style} points="{pts}"/>')
        parts.append(f'<text x="4" y="{top + 14}" font-size="11">{"xyz"[axis]} (mm) {lo:.0f}…{hi:.0f}</text>')
    parts.append(f'<text x="{W - 140}" y="{3 * H - 4}" font-size="11">{T / fps:.2f} s</text></svg>')
    return "".join(parts)


def to_html(report: dict, result: CleanResult, n_plots: int = 6) -> str:
    before, after = result.original, result.cleaned
    md = to_markdown(report)
    filled = np.zeros(before.positions.shape[:2], bool)
    for r in result.records:
        filled |= r.filled
    plots = []
    mm = before.metres_per_unit * 1000.0
    for j in _ranked(report)[:n_plots]:
        k = before.names.index(j["name"])
        plots.append(f"<h3>{html.escape(j['name'])} — {j['status']}</h3>" + _svg_trajectory(
            before.positions[:, k], after.positions[:, k], filled[:, k] & ~after.missing[:, k],
            before.missing[:, k], before.fps, j["name"], mm))
    body = _markdown_to_html(md)
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>mocapfix report</title>"
            "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
            "table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px}"
            "</style></head><body>" + body +
            "<h2>Trajectories of the worst joints</h2><p>grey: input; colour: cleaned; red shading: "
            "missing in the input; green: filled by a cleaner.</p>" + "".join(plots) + "</body></html>")


def _markdown_to_html(md: str) -> str:
    """Just enough Markdown (headings, lists, pipe tables, bold) for our own report."""
    out, in_table, in_list = [], False, False
    for line in md.splitlines():
        esc = html.escape(line)
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if set("".join(cells)) <= set("-:"):
                continue
            tag = "th" if not in_table else "td"
            if not in_table:
                out.append("<table>")
                in_table = True
            out.append("<tr>" + "".join(f"<{tag}>{html.escape(c)}</{tag}>" for c in cells) + "</tr>")
            continue
        if in_table:
            out.append("</table>")
            in_table = False
        if line.startswith("- "):
            if not in_list:
                out.append("<ul>")
                in_list = True
            out.append(f"<li>{html.escape(line[2:])}</li>")
            continue
        if in_list:
            out.append("</ul>")
            in_list = False
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{html.escape(line[level:].strip())}</h{level}>")
        elif line.strip():
            out.append("<p>" + esc.replace("**", "") + "</p>")
    if in_table:
        out.append("</table>")
    if in_list:
        out.append("</ul>")
    return "\n".join(out)
