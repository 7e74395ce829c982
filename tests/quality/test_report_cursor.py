"""The clean report's plots and its 3D viewer share one time: the viewer's frame is a
cursor line on every plot whose window holds it, a click on a plot sets the viewer's
frame. Rendered by headless Chromium (launched as in test_html_browser.py, network
unresolvable); a probe injected into a copy of the report talks to the sandboxed viewer
only by the messages the report itself uses, and reads the plots' SVG."""
from __future__ import annotations

import html
import json
import re
import subprocess

import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA
from mocapfix.cli import main
from mocapfix.quality.plots import LEFT, RIGHT, WIDTH
from test_html_browser import FLAGS, _chromium
from test_viewer_browser import NO_NETWORK

pytestmark = pytest.mark.slow

PROBE = """<script>
window.__errors = [];
window.addEventListener('error', e => window.__errors.push(String(e.message || e)));
document.addEventListener('securitypolicyviolation', e => window.__errors.push('CSP ' + e.blockedURI));
window.addEventListener('load', async () => {
  const view = document.querySelector('iframe.mocapfix-view'), heard = [];
  window.addEventListener('message', e => { if (e.source === view.contentWindow) heard.push(e.data); });
  const sleep = ms => new Promise(r => setTimeout(r, ms));
  const until = async ok => { for (let k = 0; k < 100 && !ok(); k++) await sleep(50); };
  const last = () => heard.length ? heard[heard.length - 1].frame : null;
  const svgs = [...document.querySelectorAll('svg.plot')];
  const cursors = () => svgs.map(s => { const c = s.querySelector('line.cursor');
    return {visible: c.getAttribute('visibility'), x: Number(c.getAttribute('x1'))}; });
  await until(() => heard.length > 0);                  // the viewer says where it is
  const played = heard.length;
  const [target, spoof, click] = window.__frames;
  view.contentWindow.postMessage({mocapfix: 'frame', frame: target}, '*');
  await until(() => last() === target);
  await sleep(300);                                     // paused there: nothing more comes
  const set = {echo: last(), cursors: cursors(), quiet: last() === target};
  window.postMessage({mocapfix: 'frame', frame: spoof}, '*');     // not from the viewer
  await sleep(200);
  const spoofed = cursors();
  const svg = svgs[0], r = svg.getBoundingClientRect(), k = r.width / svg.viewBox.baseVal.width;
  const [f0, f1] = svg.getAttribute('data-frames').split(' ').map(Number);
  const x = window.__x0 + (window.__x1 - window.__x0) * (click - f0) / Math.max(f1 - 1 - f0, 1);
  svg.dispatchEvent(new MouseEvent('click', {clientX: r.left + x * k, clientY: r.top + 100 * k, bubbles: true}));
  await until(() => last() === click);
  const clicked = {echo: last(), cursors: cursors()};
  document.body.setAttribute('data-probe', JSON.stringify({errors: window.__errors,
    played, set, spoofed, clicked, frames: svgs.map(s => s.getAttribute('data-frames'))}));
});
</script>"""


def _x(frames: str, f: int) -> float:
    f0, f1 = map(int, frames.split())
    return LEFT + (WIDTH - RIGHT - LEFT) * (f - f0) / max(f1 - 1 - f0, 1)


def test_the_viewer_frame_is_a_cursor_on_the_plots_and_a_click_sets_it(tmp_path):
    browser = _chromium()
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walk_markers.c3d"), "-o", str(out),
                                  "-q", "--report", "html"])
    assert r.exit_code == 0, r.output
    text = (out / "walk_markers.c3d.report.html").read_text(encoding="utf-8")
    windows = [tuple(map(int, w.split())) for w in re.findall(r'data-frames="(\d+ \d+)"', text)]
    assert len(windows) >= 2, "too few plots to tell a window that holds the frame from one that does not"
    f0, f1 = windows[0]
    target, click = f0 + (f1 - f0) // 3, f0 + 2 * (f1 - f0) // 3
    spoof = f1 - 1
    setup = (f"<script>window.__frames = {json.dumps([target, spoof, click])}; "
             f"window.__x0 = {LEFT}; window.__x1 = {WIDTH - RIGHT};</script>")
    probed = tmp_path / "probed.html"
    probed.write_text(text.replace("<head>", "<head>" + setup + PROBE, 1), encoding="utf-8")
    # the sandboxed viewer in the report's own process: virtual time then waits for its
    # messages (in a process of its own they arrive after the budget is spent)
    no_network = [f if "disable-features" not in f else f + ",IsolateSandboxedIframes"
                  for f in NO_NETWORK]
    cmd = [browser, *FLAGS, *no_network, f"--user-data-dir={tmp_path / 'profile'}",
           "--window-size=1200,1600", "--virtual-time-budget=20000", "--dump-dom", probed.as_uri()]
    dom = subprocess.run(cmd, capture_output=True, text=True, timeout=180, check=True).stdout
    m = re.search(r'data-probe="([^"]*)"', dom)
    assert m, "the probe did not finish"
    probe = json.loads(html.unescape(m.group(1)))
    assert probe["errors"] == []
    assert probe["played"] >= 1, "the viewer did not report its frame"

    def check(state, frame):
        for frames, cursor in zip(probe["frames"], state["cursors"]):
            a, b = map(int, frames.split())
            assert cursor["visible"] == ("visible" if a <= frame < b else "hidden"), (frames, frame)
            if a <= frame < b:
                assert cursor["x"] == pytest.approx(_x(frames, frame), abs=0.06)

    assert probe["set"]["echo"] == target and probe["set"]["quiet"], "the viewer did not hold the frame"
    check(probe["set"], target)
    assert any(c["visible"] == "hidden" for c in probe["set"]["cursors"]) or all(
        a <= target < b for a, b in windows)
    # a message of the right shape from another window than the viewer moves nothing
    assert probe["spoofed"] == probe["set"]["cursors"]
    # a click on the first plot at `click` sets the viewer there, which the cursors follow
    assert probe["clicked"]["echo"] == click
    check(probe["clicked"], click)
