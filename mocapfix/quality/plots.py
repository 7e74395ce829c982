"""The HTML report's plots: inline SVG, no plotting library (the report's one script only moves
the time cursor line each plot holds).

Each plotted joint is drawn over the span cleaning changed (with a margin) at the full
plot width, under a thin strip of the whole take that marks where that span is: a 3-frame
edit in a 63 s take is a few hundred pixels wide instead of a fraction of one. Changes far
apart in time get a plot each (up to :data:`MOST_SPANS`, the largest first; the page says
how many more there are). The panels
are x, y, z before and after, the change (distance moved; for a fill, its distance to the
straight bridge between the gap's ends, with the fill's estimated error and 90 % bound),
and for BVH/AMC the joint's rotation channels when a step changed them. Kinect tracking
states (Inferred, NotTracked) are shaded. Curves longer than the plot is wide are reduced
to the minimum and maximum of each pixel column, so a one-frame spike stays visible.
"""
from __future__ import annotations

import html
from dataclasses import dataclass, field

import numpy as np

from mocapfix.core.errors import printable
from mocapfix.core.gaps import runs
from mocapfix.quality.rules import STATUS_ORDER

WIDTH, LEFT, RIGHT = 1000, 64, 12
PANEL_H, TOP_PAD, BOTTOM = 150, 10, 26
STRIP_H = 34
XYZ_COLOURS = ("#c0392b", "#27ae60", "#2c6fbb")
CHANGE_COLOUR, BRIDGE_COLOUR = "#8e44ad", "#e67e22"
#: shading of frames, drawn in this order: (class, fill colour)
SHADES = {"missing": "#f6dada", "filled": "#d6ecd6", "outlier": "#fbe3c8",
          "inferred": "#f1c40f", "nottracked": "#7f8c8d"}
#: Kinect tracking states: a bar this high along the top of a panel, over the shading of
#: the samples missing and filled there
STATES, STATE_BAR = ("inferred", "nottracked"), 6
X_TITLE = "time (s)"
#: the least value range of a panel (mm or degrees): round-off is not blown up to fill it
MIN_SPAN = 1.0
#: frames of context each side of a changed span, at least (and changes closer than this
#: are drawn together)
MARGIN = 10
#: a change smaller than this share of the joint's largest (or than 1 µm) is round-off,
#: not an edit: it does not widen the span a plot is zoomed to
CHANGE_FLOOR = 0.01


@dataclass
class Panel:
    """One plot panel: ``lines`` are (values over the whole take, stroke, width), the
    first drawn first; ``band`` (lo, hi) a shaded envelope (NaN where there is none);
    ``zero``: the value axis starts at 0; ``legend``: short lines of text in the panel."""
    label: str
    lines: list = field(default_factory=list)
    band: tuple | None = None
    zero: bool = False
    legend: list = field(default_factory=list)


def ticks(lo: float, hi: float, n: int = 4) -> list[float]:
    """Round tick values inside [lo, hi] (1-2-5 steps, about ``n`` intervals), at least two
    of them: rounding the step up (2 → 5) can leave a single multiple in the range."""
    span = hi - lo
    if not np.isfinite(span) or span <= 0:
        return [lo]
    raw = span / n
    mag = 10 ** np.floor(np.log10(raw))
    steps = [m * mag for m in (0.5, 1, 2, 5, 10)]
    k = next(i for i, m in enumerate(steps) if m >= raw)
    while True:
        step = steps[k]
        first = np.ceil(lo / step) * step
        out = [float(v) for v in np.arange(first, hi + step * 1e-9, step)]
        if len(out) >= 2 or k == 0:
            return out
        k -= 1


def fmt_tick(v: float, step: float) -> str:
    """A tick value with as many decimals as its step needs (39.95, 40, 40.05: not 40 thrice)."""
    decimals = max(0, int(-np.floor(np.log10(step) + 1e-9))) if step > 0 else 0
    text = f"{v:.{decimals}f}"
    return text[1:] if float(text) == 0 and text.startswith("-") else text     # not "-0"


def _tick_labels(values: list[float]) -> list[str]:
    return [fmt_tick(v, values[1] - values[0] if len(values) > 1 else 0.0) for v in values]


def _text_width(text: str, size: float) -> float:
    """A generous estimate of a sans-serif label's width in px (no layout engine here)."""
    return 0.62 * size * len(text)


def decimate(x: np.ndarray, y: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """The points of a polyline through (x, y) at most two per pixel column: each column's
    minimum and maximum, in the order the curve visits them, so that a spike of one sample
    among thousands is still drawn at its full height. Short curves are returned as they are."""
    if len(x) <= 2 * columns:
        return x, y
    col = np.floor((x - x[0]) * (columns / max(x[-1] - x[0], 1e-12))).astype(np.intp)
    starts = np.flatnonzero(np.r_[True, col[1:] != col[:-1]])
    lo, hi = np.minimum.reduceat(y, starts), np.maximum.reduceat(y, starts)
    falling = y[starts] > (lo + hi) / 2
    ys = np.where(falling[:, None], np.c_[hi, lo], np.c_[lo, hi]).ravel()
    return np.repeat(x[starts], 2), ys


def _points(x: np.ndarray, y: np.ndarray) -> str:
    return " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(x.tolist(), y.tolist()))


def svg_plot(panels: list[Panel], shading: list[tuple[str, np.ndarray]], fps: float,
             title: str, window: tuple[int, int] | None = None, start_s: float = 0.0,
             overview: np.ndarray | None = None) -> str:
    """Inline SVG of ``panels`` over the frames ``window`` (start, stop; default the whole
    take) at the full plot width, each with time (s from ``start_s``) and value axes; the
    ``shading`` masks (class in :data:`SHADES`, (T,) bool) drawn behind every panel. With
    ``overview`` (a (T,) bool of the frames changed), a strip of the whole take on top
    marks those frames and the window shown below it."""
    T = len(shading[0][1]) if shading else len(panels[0].lines[0][0])
    f0, f1 = window or (0, T)
    inner_w = WIDTH - LEFT - RIGHT
    strip = STRIP_H if overview is not None else 0
    height = strip + PANEL_H * len(panels)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" class="plot" width="{WIDTH}" '
             f'height="{height}" viewBox="0 0 {WIDTH} {height}" role="img" '
             f'data-frames="{f0} {f1}" data-x="{LEFT} {WIDTH - RIGHT}"><title>{html.escape(printable(title))}</title>']

    def seconds(i):
        return i / fps if fps else i

    def X(i):
        return LEFT + inner_w * (np.asarray(i, float) - f0) / max(f1 - 1 - f0, 1)

    if overview is not None:
        parts.append(_overview(overview, T, f0, f1, seconds, start_s))
    duration = seconds(f1 - 1) - seconds(f0)
    t_start = start_s + seconds(f0)
    title_left = WIDTH - RIGHT - _text_width(X_TITLE, 10)
    x_ticks = []
    values = ticks(t_start, t_start + duration, 6)
    for v, text in zip(values, _tick_labels(values)):
        x = float(X(f0 + (v - t_start) * (fps or 1)))
        if x + _text_width(text, 10) / 2 < title_left - 4:
            x_ticks.append((x, text))
    runs_of = {cls: runs(mask[f0:f1, None])[1:] for cls, mask in shading}
    for p, panel in enumerate(panels):
        top = strip + p * PANEL_H + TOP_PAD
        inner = PANEL_H - TOP_PAD - BOTTOM
        shown = [y[f0:f1] for y, _, _ in panel.lines]
        if panel.band is not None:
            shown += [b[f0:f1] for b in panel.band]
        both = np.concatenate(shown) if shown else np.zeros(0)
        both = both[np.isfinite(both)]
        lo, hi = (float(both.min()), float(both.max())) if both.size else (0.0, 1.0)
        if panel.zero:
            lo = 0.0
        if hi - lo < MIN_SPAN:
            lo, hi = (0.0, MIN_SPAN) if panel.zero else ((lo + hi - MIN_SPAN) / 2, (lo + hi + MIN_SPAN) / 2)

        def Y(v, lo=lo, hi=hi, top=top, inner=inner):
            return top + inner - inner * (np.asarray(v, float) - lo) / (hi - lo)

        parts.append(f'<g class="panel" data-axis="{html.escape(panel.label)}">')
        for cls, (s, n) in runs_of.items():
            for a, m in zip((s + f0).tolist(), n.tolist()):
                x_a = float(X(a - 0.5 if a > f0 else a))
                x_b = float(X(a + m - 0.5 if a + m < f1 else f1 - 1))
                h = STATE_BAR if cls in STATES else inner
                parts.append(f'<rect class="{cls}" x="{x_a:.1f}" y="{top:.1f}" '
                             f'width="{max(x_b - x_a, 1):.1f}" height="{h:.1f}" fill="{SHADES[cls]}"/>')
        if panel.band is not None:
            parts += _band(panel.band, f0, f1, X, Y)
        x0, x1, yb0 = LEFT, WIDTH - RIGHT, top + inner
        parts.append(f'<line class="axis x" x1="{x0}" y1="{yb0:.1f}" x2="{x1}" y2="{yb0:.1f}" stroke="#333"/>')
        parts.append(f'<line class="axis y" x1="{x0}" y1="{top:.1f}" x2="{x0}" y2="{yb0:.1f}" stroke="#333"/>')
        values = ticks(lo, hi)
        for v, text in zip(values, _tick_labels(values)):
            y = float(Y(v))
            parts.append(f'<line x1="{x0 - 4}" y1="{y:.1f}" x2="{x0}" y2="{y:.1f}" stroke="#333"/>'
                         f'<text class="tick y" x="{x0 - 6}" y="{y + 4:.1f}" font-size="10" '
                         f'text-anchor="end">{text}</text>')
        for x, text in x_ticks:
            parts.append(f'<line x1="{x:.1f}" y1="{yb0:.1f}" x2="{x:.1f}" y2="{yb0 + 4:.1f}" stroke="#333"/>'
                         f'<text class="tick x" x="{x:.1f}" y="{yb0 + 15:.1f}" font-size="10" '
                         f'text-anchor="middle">{text}</text>')
        parts.append(f'<text class="label y" x="12" y="{top + inner / 2:.1f}" font-size="11" '
                     f'transform="rotate(-90 12 {top + inner / 2:.1f})" text-anchor="middle">'
                     f'{html.escape(panel.label)}</text>')
        parts.append(f'<text class="label x" x="{WIDTH - RIGHT}" y="{yb0 + 15:.1f}" font-size="10" '
                     f'text-anchor="end">{X_TITLE}</text>')
        for y, stroke, width in panel.lines:
            seg = y[f0:f1]
            _, s, n = runs(np.isfinite(seg)[:, None])
            for a, m in zip(s.tolist(), n.tolist()):
                xs, ys = decimate(X(np.arange(f0 + a, f0 + a + m)), seg[a:a + m], inner_w)
                parts.append(f'<polyline fill="none" stroke="{stroke}" stroke-width="{width}" '
                             f'points="{_points(xs, Y(ys))}"/>')
        for i, line in enumerate(panel.legend):
            parts.append(f'<text class="legend" x="{LEFT + 8}" y="{top + 12 + 12 * i:.1f}" '
                         f'font-size="10">{html.escape(line)}</text>')
        parts.append("</g>")
    # the report's script moves it to the 3D viewer's frame (hidden outside the window)
    parts.append(f'<line class="cursor" x1="{LEFT}" y1="{strip}" x2="{LEFT}" y2="{height}" '
                 f'stroke="#e00" stroke-width="1.5" visibility="hidden"/>')
    parts.append("</svg>")
    return "".join(parts)


def _band(band, f0, f1, X, Y) -> list[str]:
    """Polygons between ``band``'s lower and upper curves over each run where both exist."""
    lo, hi = (b[f0:f1] for b in band)
    _, s, n = runs((np.isfinite(lo) & np.isfinite(hi))[:, None])
    out = []
    for a, m in zip(s.tolist(), n.tolist()):
        xs = X(np.arange(f0 + a, f0 + a + m))
        pts = _points(np.r_[xs, xs[::-1]], Y(np.r_[hi[a:a + m], lo[a:a + m][::-1]]))
        out.append(f'<polygon class="bound" fill="#27ae60" fill-opacity="0.18" points="{pts}"/>')
    return out


def _overview(changed: np.ndarray, T: int, f0: int, f1: int, seconds, start_s: float) -> str:
    """The whole take as a thin strip: a tick for each run of changed frames, the shown
    window outlined, the take's start and end times at its ends."""
    inner_w = WIDTH - LEFT - RIGHT

    def X(i):
        return LEFT + inner_w * i / max(T, 1)

    y0, h = 4, STRIP_H - 18
    out = [f'<g class="overview"><rect x="{LEFT}" y="{y0}" width="{inner_w}" height="{h}" '
           f'fill="#f4f4f4" stroke="#bbb"/>']
    _, s, n = runs(changed[:, None])
    for a, m in zip(s.tolist(), n.tolist()):
        out.append(f'<rect class="changed" x="{X(a):.1f}" y="{y0}" width="{max(X(a + m) - X(a), 1):.1f}" '
                   f'height="{h}" fill="{CHANGE_COLOUR}"/>')
    out.append(f'<rect class="window" x="{X(f0):.1f}" y="{y0 - 2}" width="{max(X(f1) - X(f0), 2):.1f}" '
               f'height="{h + 4}" fill="none" stroke="#333" stroke-width="1.5"/>')
    t0, t1 = start_s, start_s + seconds(T - 1)
    out.append(f'<text x="{LEFT - 4}" y="{y0 + h - 4}" font-size="10" text-anchor="end">{t0:.4g} s</text>'
               f'<text x="{WIDTH - RIGHT}" y="{y0 + h + 12}" font-size="10" text-anchor="end">'
               f'whole take, {t1:.4g} s: the frames drawn below are outlined</text></g>')
    return "".join(out)


def svg_trajectory(before: np.ndarray, after: np.ndarray, filled: np.ndarray,
                   missing_before: np.ndarray, fps: float, title: str, unit_mm: float,
                   labels: tuple[str, ...] = ("x (mm)", "y (mm)", "z (mm)", "change (mm)"),
                   start_s: float = 0.0) -> str:
    """Inline SVG of a whole (T, 3) curve: three coordinates over time before (grey) and
    after (colour), and the distance between them; missing spans shaded red, filled green.
    ``labels`` name the three coordinates and the change, in mm unless they say otherwise:
    the values are multiplied by ``unit_mm``. (The report draws :func:`joint_plot`.)"""
    panels = [Panel(labels[a], [(before[:, a] * unit_mm, "#999", 1), (after[:, a] * unit_mm, c, 1.3)])
              for a, c in enumerate(XYZ_COLOURS)]
    panels.append(Panel(labels[3], [(np.linalg.norm(after - before, axis=1) * unit_mm, CHANGE_COLOUR, 1.3)],
                        zero=True))
    return svg_plot(panels, [("missing", missing_before), ("filled", filled)], fps, title,
                    start_s=start_s)


# -- the report's choice and drawing of joints ---------------------------------------------

def change_size(joint: dict) -> float:
    """What changed in a joint, in mm: its largest correction or fill bound."""
    return max(joint["correction_mm"]["max"] or 0.0, joint.get("fill_bound_mm") or 0.0)


def by_severity(report: dict) -> list[dict]:
    """The joints cleaning changed (samples filled or flagged, or moved), FAIL first, then
    WARN, then OK, and within a status by :func:`change_size`, then by the share of samples
    filled or flagged; joints never seen and still missing are left out (nothing to plot)."""
    T = report["file"]["frames"] or 1

    def share(j):
        return (j["missing_before"] or 0) - (j["missing_after"] or 0) + j["outliers_flagged"] / T

    shown = [j for j in report["joints"] if (j["missing_after"] or 0) < 1.0
             and (share(j) > 0 or change_size(j) > 0)]
    return sorted(shown, key=lambda j: (-STATUS_ORDER[j["status"]], -change_size(j), -share(j), j["name"]))


def bridge_distance(before: np.ndarray, after: np.ndarray, filled: np.ndarray) -> np.ndarray:
    """(T,) distance of each filled sample of ``after`` to the straight line between the
    input's samples at the ends of its gap (held constant at a gap with one end): what the
    filler added beyond linear interpolation. NaN outside the fills."""
    out = np.full(len(after), np.nan)
    ok = ~np.isnan(before).any(axis=1)
    _, s, n = runs(filled[:, None])
    for a, m in zip(s.tolist(), n.tolist()):
        left = before[a - 1] if a > 0 and ok[a - 1] else None
        right = before[a + m] if a + m < len(before) and ok[a + m] else None
        if left is None and right is None:
            continue
        left = right if left is None else left
        right = left if right is None else right
        w = (np.arange(1, m + 1) / (m + 1))[:, None]
        out[a:a + m] = np.linalg.norm(after[a:a + m] - (left + w * (right - left)), axis=1)
    return out


def rotation_channels(motion, name: str) -> tuple[list[int], list[str], float]:
    """The channel columns of ``name``'s rotation in ``motion`` (BVH/AMC), their axis
    letters and the factor to degrees; no columns when the motion has no rig or the joint
    no rotation."""
    rig = motion.rig
    if rig is None or motion.channels is None or name not in rig.names:
        return [], [], 1.0
    j = rig.names.index(name)
    return list(rig.rot_columns[j]), list(rig.rot_axes[j]), 1.0 if rig.degrees else 180.0 / np.pi


#: plots a joint gets at most, one per span of changed frames, the largest first
MOST_SPANS = 3


def _windows(changed: np.ndarray, size: np.ndarray, most: int = MOST_SPANS
             ) -> tuple[list[tuple[int, int]], int]:
    """The frames to draw, as (start, stop) windows, the largest ``size`` first, and how
    many more spans were left out: each span of changed frames (changes closer than
    :data:`MARGIN` frames are one span) widened by max(:data:`MARGIN`, half its length)
    each side within the take, windows that then overlap drawn as one; at most ``most``.
    The whole take when nothing changed. Every span stays marked on each plot's strip."""
    T = len(changed)
    if not changed.any():
        return [(0, T)], 0
    # the centred part of the full convolution: "same" gives the kernel's length, not T,
    # for a take shorter than the kernel (a 3-frame take broke its HTML report)
    near = np.convolve(changed, np.ones(2 * MARGIN + 1))[MARGIN:MARGIN + T] > 0
    _, s, _ = runs(near[:, None])
    at = np.flatnonzero(changed)
    # every span holds a changed frame: its first and last one
    new_span = np.flatnonzero(np.diff(np.searchsorted(s, at, side="right")))
    a, b = at[np.r_[0, new_span + 1]], at[np.r_[new_span, at.size - 1]] + 1
    margin = np.maximum(MARGIN, (b - a + 1) // 2)
    lo, hi = np.maximum(0, a - margin), np.minimum(T, b + margin)
    peak = np.maximum.reduceat(np.where(near, size, -np.inf), s)
    joined = np.r_[0, np.flatnonzero(lo[1:] >= np.maximum.accumulate(hi)[:-1]) + 1]
    lo, hi = lo[joined], np.maximum.reduceat(hi, joined)
    peak = np.maximum.reduceat(peak, joined)
    order = np.argsort(-peak, kind="stable")
    shown = order[:most]
    return [(int(lo[i]), int(hi[i])) for i in shown], int(order.size - shown.size)


def joint_plot(result, joint: dict, filled_any: np.ndarray, outliers_any: np.ndarray) -> str:
    """The plots of one joint of a report, one per span of changed frames
    (:func:`_windows`; see the module docstring), then a line naming the spans left out
    when there are more; ``filled_any`` and
    ``outliers_any`` are the (T, J) samples any step filled / judged wrong."""
    before, after = result.original, result.cleaned
    k = before.names.index(joint["name"])
    mm = before.metres_per_unit * 1000.0
    pb, pa = before.positions[:, k] * mm, after.positions[:, k] * mm
    miss_b = before.missing[:, k]
    filled = filled_any[:, k] & ~after.missing[:, k]
    moved = np.linalg.norm(pa - pb, axis=1)
    moved_present = np.nan_to_num(moved)
    changed = filled | outliers_any[:, k] | (miss_b != after.missing[:, k])
    changed |= moved_present > max(1e-3, CHANGE_FLOOR * moved_present.max(initial=0.0))
    cols, axes, to_deg = rotation_channels(before, joint["name"])
    rot_b = before.channels[:, cols] * to_deg if cols else np.zeros((len(pb), 0))
    rot_a = after.channels[:, cols] * to_deg if cols and after.channels is not None else rot_b
    rot_change = np.abs(rot_a - rot_b).max(axis=1, initial=0.0) if cols else np.zeros(len(pb))
    changed |= rot_change > max(1e-6, CHANGE_FLOOR * rot_change.max(initial=0.0))
    fills = [f for f in joint["gaps"]["filled"] if f.get("bound_mm") is not None]
    bound = np.full(len(pb), np.nan)
    for f in fills:
        bound[f["start"]:f["start"] + f["length"]] = f["bound_mm"]
    # the largest change in mm or, for a rotation channel, degrees
    size = np.maximum.reduce([moved_present, np.nan_to_num(bound), rot_change])
    windows, more = _windows(changed, size)
    panels = [Panel(f"{'xyz'[a]} (mm)", [(pb[:, a], "#999", 1), (pa[:, a], c, 1.3)],
                    band=(pa[:, a] - bound, pa[:, a] + bound) if fills else None)
              for a, c in enumerate(XYZ_COLOURS)]
    bridge = bridge_distance(pb, pa, filled)
    rotations = []
    if cols and rot_change.max(initial=0.0) > 0:
        rotations = [Panel(f"{ax} rotation (°)", [(rot_b[:, i], "#999", 1), (rot_a[:, i], "#16a085", 1.3)])
                     for i, ax in enumerate(axes)]

    def change_panel(window):
        legend = []
        if filled.any():
            legend.append("orange: a fill's distance to the straight line between its gap's ends")
        in_view = [f for f in fills if f["start"] < window[1] and window[0] < f["start"] + f["length"]]
        legend += [f"fill of frames {f['start']}–{f['start'] + f['length'] - 1}: estimated error "
                   f"{f['error_mm']:.1f} mm, 90 % bound {f['bound_mm']:.1f} mm (green band above)"
                   for f in in_view[:3]]
        return Panel("change (mm)", [(moved, CHANGE_COLOUR, 1.3), (bridge, BRIDGE_COLOUR, 1.3)],
                     zero=True, legend=legend)

    shading = [("missing", miss_b), ("filled", filled), ("outlier", outliers_any[:, k] & ~filled)]
    if before.format == "kinect" and before.confidence is not None:
        conf = np.nan_to_num(before.confidence[:, k])
        shading += [("inferred", (conf > 0) & (conf < 1)), ("nottracked", conf <= 0)]
    plots = [svg_plot(panels + [change_panel(w)] + rotations, shading, before.fps, joint["name"],
                      w, overview=changed) for w in windows]
    if more:
        plots.append(f'<p class="more-spans">+{more} more span{"s" if more > 1 else ""} '
                     "changed (marked on the strip above each plot)</p>")
    return "".join(plots)
