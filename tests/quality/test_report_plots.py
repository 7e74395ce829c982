"""The HTML report's plots (issue 38): ordered by severity, zoomed to what changed with the
whole take as context, a fill's panel showing the fill, BVH/AMC rotation channels, Kinect
tracking states, and tick labels clear of the axis title. Each is read back from the SVG."""
from __future__ import annotations

import html
import re
import subprocess

import numpy as np
import pytest

from mocapfix import formats
from mocapfix.cleaning import clean_motion
from mocapfix.config import loads_config
from mocapfix.core.motion import Motion
from mocapfix.quality.measure import CleanResult
from mocapfix.quality.plots import WIDTH, bridge_distance, svg_trajectory
from mocapfix.quality.report import build_report, to_html

from conftest import SAMPLE_DATA

MM_C3D = {"fps": 100.0, "units": "mm", "metres_per_unit": 0.001, "format": "c3d"}
POLYLINE = re.compile(r'<polyline[^>]*stroke="([^"]+)"[^>]*points="([^"]*)"')


def _line(T, fps=100.0):
    t = np.arange(T) / fps
    return np.stack([1000 * t, 200 * np.sin(2 * t), np.full(T, 900.0)], axis=1)


def _plots(page: str) -> dict[str, str]:
    """Each plotted joint's name → its SVG, in page order."""
    found = re.findall(r"<h3>(.*?) — \w+</h3>(<svg.*?</svg>)", page, re.S)
    return {html.unescape(name): svg for name, svg in found}


def _panel(svg: str, axis: str) -> str:
    return re.search(rf'<g class="panel" data-axis="{re.escape(axis)}">(.*?)</g>', svg, re.S).group(1)


def _points(points: str) -> np.ndarray:
    return np.array([[float(v) for v in p.split(",")] for p in points.split()])


def test_plots_come_worst_status_first_then_largest_change():
    """A: a 10-frame gap filled (OK, share of samples filled 5 %); B: one sample moved
    300 mm (WARN). The old order (share filled first) drew A first."""
    T = 200
    a = _line(T)
    before = np.stack([a, a + [0, 0, -400.0], a + [0, 300.0, 0]], axis=1)
    after = before.copy()
    before[50:60, 0] = np.nan
    before[120, 1] += [300.0, 0, 0]
    after[30, 2] += [7.0, 0, 0]                # C: OK, a 7 mm change
    result = CleanResult(Motion(before, ["A", "B", "C"], **MM_C3D), Motion(after, ["A", "B", "C"], **MM_C3D), [])
    report = build_report(result)
    status = {j["name"]: j["status"] for j in report["joints"]}
    assert status == {"A": "OK", "B": "WARN", "C": "OK"}
    assert list(_plots(to_html(report, result, viewer=False))) == ["B", "C", "A"]


def test_a_three_frame_edit_in_a_long_take_is_drawn_wide_with_the_take_as_context():
    T = 6000
    before = _line(T)[:, None, :]
    after = before.copy()
    before[3000:3003, 0] += [0, 0, 80.0]        # a 3-frame glitch the cleaner took out
    result = CleanResult(Motion(before, ["A"], **MM_C3D), Motion(after, ["A"], **MM_C3D), [])
    svg = _plots(to_html(build_report(result), result, viewer=False))["A"]
    (points,) = [p for _, p in POLYLINE.findall(_panel(svg, "change (mm)"))]
    xy = _points(points)
    moved = xy[xy[:, 1] < xy[:, 1].max() - 1]               # above the 0 mm baseline
    assert len(moved) == 3
    assert moved[-1, 0] - moved[0, 0] > 60                   # two frame steps: > 60 px (was 0.25)
    # the strip above: the whole take, the glitch marked, the window drawn outlined
    strip = re.search(r'<g class="overview">(.*?)</g>', svg, re.S).group(1)
    window = re.search(r'class="window" x="([\d.]+)"[^>]*width="([\d.]+)"', strip)
    changed = re.search(r'class="changed" x="([\d.]+)"', strip)
    x0, w = float(window.group(1)), float(window.group(2))
    assert x0 <= float(changed.group(1)) <= x0 + w and w < 10


def test_long_curves_keep_at_most_two_points_a_pixel_column_and_their_spikes():
    T = 60000
    before = _line(T)
    after = before.copy()
    after[31234, 2] += 500.0                   # one sample among 60,000
    svg = svg_trajectory(before, after, np.zeros(T, bool), np.zeros(T, bool), 100.0, "A", 1.0)
    (grey, z), = [[_points(p) for _, p in POLYLINE.findall(_panel(svg, "z (mm)"))]]
    assert len(z) <= 2 * WIDTH and len(grey) <= 2 * WIDTH
    assert z[:, 1].min() < grey[:, 1].min() - 50            # the spike is drawn, up (y down)


def test_a_fill_panel_shows_its_distance_to_the_straight_bridge_and_its_bound():
    T, fps = 400, 100.0
    t = np.arange(T) / fps
    a = np.stack([300 * np.sin(3 * t), 200 * np.cos(2 * t), 900 + 50 * np.sin(5 * t)], axis=1)
    pos = np.stack([a, a + [0, 0, -400.0]], axis=1)
    pos[200:225, 1] = np.nan
    motion = Motion(pos, ["A", "B"], fps, units="mm", metres_per_unit=0.001, format="c3d")
    result = clean_motion(motion, loads_config("pipeline:\n  - cleaner: fill\n    method: pchip\n"))
    report = build_report(result)
    fill = report["joints"][1]["gaps"]["filled"][0]
    assert fill["bound_mm"] is not None
    change = _panel(_plots(to_html(report, result, viewer=False))["B"], "change (mm)")
    lines = POLYLINE.findall(change)
    bridge = [_points(p) for stroke, p in lines if stroke == "#e67e22"]
    assert len(bridge) == 1 and len(bridge[0]) == 25
    assert np.ptp(bridge[0][:, 1]) > 20                # not flat: the fill bends off the line
    assert f"90 % bound {fill['bound_mm']:.1f} mm" in change
    # the distance itself: a straight fill is 0 from its bridge, a bowed one its bow
    before = np.zeros((7, 3))
    before[2:5] = np.nan
    before[5:] = [4.0, 0, 0]
    after = before.copy()
    after[2:5] = [[1.0, 3, 0], [2.0, 0, 0], [3.0, 0, 0]]
    before[:2] = [[0.0, 0, 0], [0.0, 0, 0]]
    d = bridge_distance(before, after, np.isnan(before[:, 0]))
    np.testing.assert_allclose(d[2:5], [3.0, 0.0, 0.0])
    assert np.isnan(d[[0, 1, 5, 6]]).all()


def test_a_remade_bvh_rotation_is_drawn_as_its_channels_before_and_after():
    m = formats.read(SAMPLE_DATA / "walk.bvh")
    elbow = m.names.index("LeftElbow")
    col = m.rig.rot_columns[elbow][0]
    ch = m.channels.copy()
    ch[150:152, col] += 40.0                                  # a 2-frame 40° glitch
    spiked = m.replace(channels=ch, positions=m.rig.positions(ch))
    pipe = loads_config("pipeline:\n  - cleaner: rotation_outliers\n")
    result = clean_motion(spiked, pipe)
    report = build_report(result, pipe.report)
    assert 150 in report["steps"][0]["info"]["replaced_frames"]["LeftElbow"]
    svg = _plots(to_html(report, result, n_plots=len(m.names), viewer=False))["LeftElbow"]
    axis = m.rig.rot_axes[elbow][0]
    (grey, remade) = [_points(p) for _, p in POLYLINE.findall(_panel(svg, f"{axis} rotation (°)"))]
    assert np.ptp(grey[:, 1]) > np.ptp(remade[:, 1]) + 10    # the 40° spike, gone after
    for other in m.rig.rot_axes[elbow][1:]:
        assert f'data-axis="{other} rotation (°)"' in svg
    assert 'data-axis="x (mm)"' in svg                         # besides the position plot


def test_kinect_inferred_and_not_tracked_stretches_are_shaded():
    path = SAMPLE_DATA / "walk_kinect_v2.csv"
    m = formats.read(path)
    pipe = loads_config("pipeline:\n  - cleaner: kinect_skeleton\n  - cleaner: fill\n")
    result = clean_motion(m, pipe)
    plots = _plots(to_html(build_report(result, pipe.report), result, n_plots=len(m.names), viewer=False))
    conf = m.confidence
    for name, cls, state in (("HandLeft", "inferred", 0.5), ("FootLeft", "nottracked", 0.0)):
        frames = np.flatnonzero(conf[:, m.names.index(name)] == state)
        assert frames.size, name
        svg = plots[name]
        f0, f1 = (int(v) for v in re.search(r'data-frames="(\d+) (\d+)"', svg).group(1, 2))
        first, last = 64 + (WIDTH - 76) * (frames[[0, -1]] - f0) / (f1 - 1 - f0)
        (x, w), *_ = [(float(a), float(b)) for a, b in
                      re.findall(rf'<rect class="{cls}" x="([\d.]+)" y="[\d.]+" width="([\d.]+)"',
                                 _panel(svg, "x (mm)"))]
        assert x <= first and x + w >= last
    assert 'class="inferred"' not in plots["SpineShoulder"]   # tracked throughout


def test_no_x_tick_label_reaches_the_axis_title():
    """A 10 s take: the tick at 10 s stood centred on the panel's right end, under "time (s)"."""
    T = 1001
    a = _line(T)
    svg = svg_trajectory(a, a, np.zeros(T, bool), np.zeros(T, bool), 100.0, "A", 1.0)
    title_right = float(re.search(r'<text class="label x" x="([\d.]+)"', svg).group(1))
    title_left = title_right - 0.62 * 10 * len("time (s)")     # anchored at its end
    for x, label in re.findall(r'<text class="tick x" x="([\d.]+)"[^>]*>([^<]*)<', svg):
        assert float(x) + 0.62 * 10 * len(label) / 2 < title_left, label


PROBE = """<script>window.addEventListener('load', () => {
  const over = [];
  document.querySelectorAll('svg.plot g.panel').forEach(p => {
    const ts = [...p.querySelectorAll('text')].map(t => [t.textContent, t.getBoundingClientRect()]);
    ts.forEach(([a, r], i) => ts.slice(i + 1).forEach(([b, s]) => {
      if (r.left < s.right && s.left < r.right && r.top < s.bottom && s.top < r.bottom) over.push([a, b]);
    }));
  });
  document.body.setAttribute('data-overlaps', JSON.stringify(over));
});</script>"""


@pytest.mark.slow
def test_no_text_of_a_plot_overlaps_another_in_chromium(tmp_path):
    """Laid out by headless Chromium (as tests/quality/test_html_browser.py): no two texts
    of a panel (tick labels, axis titles, the fill legend) overlap, on a 10 s take."""
    from test_html_browser import FLAGS, _chromium
    browser = _chromium()
    T = 1001
    pos = np.stack([_line(T), _line(T) + [0, 0, -400.0]], axis=1)
    pos[500:520, 1] = np.nan
    motion = Motion(pos, ["A", "B"], 100.0, units="mm", metres_per_unit=0.001, format="c3d")
    result = clean_motion(motion, loads_config("pipeline:\n  - cleaner: fill\n    method: linear\n"))
    page = tmp_path / "r.html"
    svg = svg_trajectory(pos[:, 0], pos[:, 0], np.zeros(T, bool), np.zeros(T, bool), 100.0, "A", 1.0)
    page.write_text(to_html(build_report(result), result, viewer=False)
                    .replace("</body>", svg + PROBE + "</body>"), encoding="utf-8")
    dom = subprocess.run([browser, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                          "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
                         capture_output=True, text=True, timeout=120, check=True).stdout
    overlaps = html.unescape(re.search(r'data-overlaps="([^"]*)"', dom).group(1))
    assert overlaps == "[]"


def _windows_of(page: str, name: str) -> list[tuple[str, tuple[int, int]]]:
    """The SVGs drawn for ``name`` (up to the next joint's heading) and their windows."""
    part = page.split(f"<h3>{name} — ", 1)[1].split("<h3>", 1)[0]
    return [(svg, tuple(map(int, w.split()))) for svg, w in
            re.findall(r'(<svg[^>]*data-frames="(\d+ \d+)".*?</svg>)', part, re.S)]


def test_changes_far_apart_get_a_zoomed_plot_each_largest_first():
    """Two edits of one joint 40 s apart: each its own plot, drawn wide (before: one plot
    zoomed to the larger; the other only a tick on the strip)."""
    T, fps = 6000, 100.0
    before = _line(T, fps)[:, None, :]
    after = before.copy()
    before[1000:1003, 0] += [0, 0, 40.0]        # 10 s: 3 frames, 40 mm
    before[5000:1005 + 4000, 0] += [0, 0, 90.0]  # 50 s: 5 frames, 90 mm (the larger)
    result = CleanResult(Motion(before, ["A"], **MM_C3D), Motion(after, ["A"], **MM_C3D), [])
    page = to_html(build_report(result), result, viewer=False)
    plots = _windows_of(page, "A")
    assert [w for _, w in plots] == [(4990, 5015), (990, 1013)]
    assert "more span" not in page
    for (svg, (f0, f1)), (a, n) in zip(plots, [(5000, 5), (1000, 3)]):
        assert f0 <= a and a + n <= f1
        (points,) = [p for _, p in POLYLINE.findall(_panel(svg, "change (mm)"))]
        xy = _points(points)
        moved = xy[xy[:, 1] < xy[:, 1].max() - 1]
        assert len(moved) == n and moved[-1, 0] - moved[0, 0] > 60      # drawn wide (in one plot: < 1 px)


def test_at_most_three_spans_are_plotted_and_the_rest_are_counted():
    T = 6000
    before = _line(T)[:, None, :]
    after = before.copy()
    for k, start in enumerate(range(500, 5500, 1000)):     # five edits, growing
        before[start:start + 2, 0] += [0, 0, 20.0 + 10 * k]
    result = CleanResult(Motion(before, ["A"], **MM_C3D), Motion(after, ["A"], **MM_C3D), [])
    page = to_html(build_report(result), result, viewer=False)
    assert [w[0] + 10 for _, w in _windows_of(page, "A")] == [4500, 3500, 2500]
    assert '<p class="more-spans">+2 more spans' in page


@pytest.mark.parametrize("T", [3, 5, 20])
def test_a_take_shorter_than_the_plot_margin_gets_its_html_report(T):
    """A take of fewer than 2 × MARGIN + 1 frames with a change: the spans were found on a
    mask of the kernel's length (21), not the take's, and the HTML report of the cleaned
    3-frame HDM05 slice (optical-c3d) was 'internal error ValueError: operands could not
    be broadcast together with shapes (21,) (3,)'."""
    before = _line(T)[:, None, :]
    after = before.copy()
    after[T // 2, 0] += [0, 0, 5.0]
    result = CleanResult(Motion(before, ["A"], **MM_C3D), Motion(after, ["A"], **MM_C3D), [])
    page = to_html(build_report(result), result, viewer=False)
    assert [w for _, w in _windows_of(page, "A")] == [(0, T)]
