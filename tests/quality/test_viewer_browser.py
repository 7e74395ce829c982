"""`mocapfix view` as a person sees it: the page of a shared capture of each format, a
before/after overlay of a gap-filled C3D and pages of hostile names, rendered by headless
Chromium (launched as in test_html_browser.py) with every host name unresolvable. A probe
injected into a copy of the page reads the canvas pixels at two frames, toggles the layers,
hovers joints and records script errors, CSP violations, alerts and resource requests."""
from __future__ import annotations

import html
import json
import re
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA, shared
from mocapfix.cli import main
from mocapfix.formats import read, write
from test_html_browser import FLAGS, _chromium

# slow: headless Chromium renders each page (~2 s a page)
pytestmark = pytest.mark.slow

NO_NETWORK = ["--host-resolver-rules=MAP * ~NOTFOUND", "--disable-features=NetworkPrediction"]

PROBE = """<script>
window.__errors = []; window.__alerts = 0;
window.alert = () => { window.__alerts++; };
for (const kind of ['error', 'warn']) {
  const orig = console[kind];
  console[kind] = (...a) => { window.__errors.push(kind + ': ' + a.join(' ')); orig(...a); };
}
window.addEventListener('error', e => window.__errors.push(String(e.message || e)));
window.addEventListener('unhandledrejection', e => window.__errors.push(String(e.reason)));
document.addEventListener('securitypolicyviolation', e => window.__errors.push('CSP ' + e.blockedURI));
window.addEventListener('load', () => {
  const v = window.mocapfixView, c = document.getElementById('view'), g = c.getContext('2d');
  const snap = () => g.getImageData(0, 0, c.width, c.height).data;
  // the layers' colours are bright; the background, grid and axes are not
  const bright = d => { let n = 0; for (let i = 0; i < d.length; i += 4)
    if (Math.max(d[i], d[i + 1], d[i + 2]) > 120) n++; return n; };
  const differ = (a, b) => { let n = 0; for (let i = 0; i < a.length; i += 4)
    if (a[i] !== b[i] || a[i + 1] !== b[i + 1] || a[i + 2] !== b[i + 2]) n++; return n; };
  const frames = v.main.frames, seen = [];
  for (let f = 0; f < frames; f += Math.max(1, Math.floor(frames / 50))) {
    v.setFrame(f); if (v.drawn().reduce((a, b) => a + b, 0) > 0) seen.push(f); }
  const f0 = seen.length ? seen[0] : 0, f1 = seen.length ? seen[Math.floor(seen.length / 2)] : 0;
  v.setFrame(f0); const a = snap(); v.setFrame(f0); const a2 = snap();
  v.setFrame(f1); const b = snap();
  const boxes = [...document.querySelectorAll('#legend input')];
  const alone = boxes.map((box, k) => {
    boxes.forEach((o, m) => { if ((o.checked) !== (m === k)) o.click(); });
    const d = snap(); return {bright: bright(d), drawn: v.drawn()};
  });
  boxes.forEach(o => { if (!o.checked) o.click(); });
  const both = snap();
  boxes.forEach((o, m) => { if (o.checked !== (m === boxes.length - 1)) o.click(); });
  const lastOnly = snap();
  boxes.forEach(o => { if (!o.checked) o.click(); });
  // orbit (drag) and zoom (wheel) with the mouse, then speed and play from the controls
  v.setFrame(f1); const still = snap();
  const at = (type, x, y, extra) => (type === 'mousedown' ? c : window).dispatchEvent(
    new MouseEvent(type, Object.assign({clientX: x, clientY: y, bubbles: true}, extra || {})));
  at('mousedown', 300, 300); at('mousemove', 420, 330); at('mouseup', 420, 330);
  const orbited = differ(still, snap());
  c.dispatchEvent(new WheelEvent('wheel', {deltaY: -400, clientX: 400, clientY: 300, bubbles: true, cancelable: true}));
  const zoomed = differ(still, snap());
  const speed = document.getElementById('speed'); speed.value = '2'; speed.dispatchEvent(new Event('change'));
  document.getElementById('play').click();
  const playing = document.getElementById('play').textContent;
  document.getElementById('play').click();
  // hover every drawn point at a frame where it is seen; keep what the tooltip says
  const tip = document.getElementById('tip'), r = c.getBoundingClientRect(), hovered = {};
  const want = new Set(window.__hover || []);
  let filledTip = null, filledPixel = null;
  for (const f of seen) {
    v.setFrame(f);
    const picks = v.picks();
    for (const p of picks) {
      const L = v.layers[p[2]], name = L.names[p[3]];
      // a point another one hides (within the 8 px of a hover) is hovered at another frame
      if (picks.some(q => q !== p && (q[0] - p[0]) ** 2 + (q[1] - p[1]) ** 2 <= 64)) continue;
      const mark = L.mark ? L.mark[p[4]] : 0;
      if (!(want.has(name) && !(name in hovered)) && !(mark === 1 && filledTip === null)) continue;
      window.dispatchEvent(new MouseEvent('mousemove', {clientX: p[0] + r.left, clientY: p[1] + r.top}));
      if (want.has(name)) hovered[name] = tip.hidden ? null : tip.textContent;
      if (mark === 1 && filledTip === null) {
        filledTip = tip.textContent;
        filledPixel = [...g.getImageData(Math.round(p[0]), Math.round(p[1]), 1, 1).data];
      }
    }
  }
  document.body.setAttribute('data-probe', JSON.stringify({
    errors: window.__errors, alerts: window.__alerts, title: document.title,
    resources: performance.getEntriesByType('resource').map(e => e.name),
    scripts: document.scripts.length, images: document.images.length,
    iframes: document.querySelectorAll('iframe,object,embed').length,
    ready: Number(document.body.getAttribute('data-ready')),
    brightA: bright(a), brightB: bright(b), changed: differ(a, b), repeat: differ(a, a2),
    alone: alone, bothVsLast: differ(both, lastOnly),
    labels: v.layers.map(L => L.label), counts: v.counts,
    legend: document.getElementById('legend').innerText,
    hovered: hovered, filledTip: filledTip, filledPixel: filledPixel,
    orbited: orbited, zoomed: zoomed, playing: playing,
  }));
});
</script>"""


def _probe(page, tmp_path, hover=()):
    """Run the probe on a copy of ``page``; returns its findings."""
    browser = _chromium()
    probed = tmp_path / "probed.html"
    names = json.dumps(list(hover)).replace("<", "\\u003c")
    setup = f"<script>window.__hover = {names};</script>"
    text = page.read_text(encoding="utf-8")
    assert text.count("<head>") == 1
    probed.write_text(text.replace("<head>", "<head>" + setup + PROBE, 1), encoding="utf-8")
    cmd = [browser, *FLAGS, *NO_NETWORK, f"--user-data-dir={tmp_path / 'profile'}",
           "--window-size=1000,700", "--virtual-time-budget=5000", "--dump-dom", probed.as_uri()]
    dom = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=True).stdout
    m = re.search(r'data-probe="([^"]*)"', dom)
    assert m, "the probe did not run (page not loaded?)"
    return json.loads(html.unescape(m.group(1)))


def _view(tmp_path, *args):
    out = tmp_path / "view.html"
    r = CliRunner().invoke(main, ["view", *map(str, args), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return out


def _check_clean_page(probe, layers=1):
    assert probe["errors"] == [] and probe["alerts"] == 0
    assert probe["resources"] == [], "the page asked for something over the network"
    assert probe["scripts"] == 4 and probe["images"] == 0 and probe["iframes"] == 0
    assert probe["ready"] > 0
    assert len(probe["alone"]) == layers


@pytest.mark.parametrize("relpath", ["c3d/cmu_85_02.c3d", "bvh/cmu_cgspeed_131_03.bvh",
                                     "asfamc/18_15.amc", "kinect/kv2_laban_Ges01_wavehand.csv",
                                     "kinect/kv1_utkinect_joints_s02_e01.txt"])
def test_a_shared_capture_plays(tmp_path, relpath):
    path = shared(relpath)
    probe = _probe(_view(tmp_path, path), tmp_path)
    _check_clean_page(probe)
    assert probe["title"].startswith(path.name)
    assert probe["brightA"] > 50 and probe["brightB"] > 50, "nothing drawn"
    assert probe["repeat"] == 0, "the same frame drawn twice differs"
    assert probe["changed"] > 50, "advancing the frame did not change the picture"
    assert probe["orbited"] > 50 and probe["zoomed"] > 50, "the mouse does not move the camera"
    assert probe["playing"] == "Pause"
    motion = read(path)
    assert probe["labels"] == [path.name]
    assert max(probe["alone"][0]["drawn"]) <= motion.n_joints


def test_before_after_of_a_gap_filled_c3d(tmp_path):
    path = shared("c3d/ktk_tennis_serve_nan.c3d")
    r = CliRunner().invoke(main, ["clean", str(path), "-o", str(tmp_path / "out"), "-q"])
    assert r.exit_code == 0, r.output
    cleaned = tmp_path / "out" / path.name
    before, after = read(path), read(cleaned)
    filled = int((before.missing & ~after.missing).sum())
    assert filled > 0, "the cleaner filled nothing: pick another file"

    probe = _probe(_view(tmp_path, path, cleaned), tmp_path)
    _check_clean_page(probe, layers=2)
    assert probe["labels"] == ["before: " + path.name, "after: " + path.name]
    # both layers are drawn, each alone and together
    (b, a) = probe["alone"]
    assert b["bright"] > 50 and a["bright"] > 50
    assert b["drawn"][0] > 0 and b["drawn"][1] == 0 and a["drawn"][0] == 0 and a["drawn"][1] > 0
    assert probe["bothVsLast"] > 0, "the before layer adds nothing to the picture"
    assert probe["counts"]["filled"] == filled
    # moved: beyond 3x the median move of the samples seen in both, and at least 1 mm
    both = ~before.missing & ~after.missing
    move = np.linalg.norm(after.positions - before.positions, axis=2)[both] * before.metres_per_unit
    moved = int((move >= max(0.001, 3 * np.median(move))).sum())
    assert abs(probe["counts"]["changed"] - moved) <= 2, (probe["counts"], moved)
    # a filled sample carries the error estimate the cleaned C3D lists, in its own colour
    assert re.search(r"filled, est\. error \d+\.\d mm", probe["filledTip"]), probe["filledTip"]
    assert probe["filledPixel"][:3] != [0x4f, 0xc3, 0xf7]
    assert "filled, est. error" in probe["legend"]


# -- hostile names: shown as text, never run ------------------------------------------------

ATTACKS = ["<script>alert(1)</script>", "</script><img src=x onerror=alert(2)>",
           "quote\"'`${alert(3)}", "{{DATA}}"]


def _hostile_c3d(folder):
    motion = read(SAMPLE_DATA / "walk_markers.c3d")
    names = list(motion.names)
    # C3D labels hold at most 255 characters
    hostile = ATTACKS + ["new\nline<b>", "L" * 255]
    names[1:1 + len(hostile)] = hostile
    path = folder / "hostile.c3d"
    write(motion.replace(names=names, source=None), path)
    return path, hostile


def _rename_tokens(text, renames):
    for old, new in renames.items():
        text = re.sub(rf"(?<![\w]){old}(?![\w])", lambda m, new=new: new, text)
    return text


def _hostile_bvh(folder):
    # BVH names are single tokens: no spaces or newlines; the readers refuse a field longer
    # than 1,000 characters (a 10,000-character name: _hostile_motion)
    hostile = ["<script>alert(1)</script>", "</script><img\tsrc=x\tonerror=alert(2)>".replace("\t", "_"),
               "quote\"'`${alert(3)}", "{{DATA}}", "N" * 1000]
    renames = dict(zip(["Spine", "Chest", "Neck", "LeftShoulder", "RightShoulder"], hostile))
    text = (SAMPLE_DATA / "walk.bvh").read_text()
    for old, new in renames.items():
        text = re.sub(rf"(JOINT) {old}\n", lambda m, new=new: f"{m.group(1)} {new}\n", text)
    path = folder / "hostile.bvh"
    path.write_text(text)
    return path, hostile


def _hostile_amc(folder):
    hostile = ["<script>alert(1)</script>", "</script><img_src=x_onerror=alert(2)>",
               "quote\"'`${alert(3)}", "{{DATA}}", "N" * 1000]
    renames = dict(zip(["lowerback", "upperback", "neck", "lhumerus", "rhumerus"], hostile))
    for name in ("walker.asf", "walker_01.amc"):
        (folder / name).write_text(_rename_tokens((SAMPLE_DATA / name).read_text(), renames))
    return folder / "walker_01.amc", hostile


def _hostile_kinect(folder):
    # Kinect files carry no names (the joints are the SDK's): the hostile part is the file
    # name, shown in the title and the legend
    name = "<img src=x onerror=alert(1)>\"'\nk{{DATA}}.csv"
    path = folder / name
    path.write_bytes((SAMPLE_DATA / "walk_kinect_v2.csv").read_bytes())
    return path, []


def _hostile_motion(folder):
    """No reader: a Motion named as no file format allows (10,000 characters, newlines)."""
    from mocapfix.quality import viewer

    motion = read(SAMPLE_DATA / "walk.bvh")
    hostile = ATTACKS + ["new\nline<b>x</b>", "M" * 10_000]
    motion.names[1:1 + len(hostile)] = hostile
    motion.path = str(folder / "motion.bvh")
    page = folder / "page.html"
    page.write_text(viewer.single([motion]), encoding="utf-8")
    return page, hostile


@pytest.mark.parametrize("make", [_hostile_c3d, _hostile_bvh, _hostile_amc, _hostile_kinect,
                                  _hostile_motion],
                         ids=["c3d", "bvh", "amc", "kinect", "in-memory"])
def test_hostile_names_are_text(tmp_path, make):
    folder = tmp_path / "in"
    folder.mkdir()
    path, hostile = make(folder)
    if make is _hostile_motion:
        page, path = path, path.with_name("motion.bvh")
    else:
        motion = read(path)
        missing = [h[:40] for h in hostile if h not in motion.names]
        assert not missing, f"the reader did not keep {missing}"
        page = _view(tmp_path, path)
    probe = _probe(page, tmp_path, hover=hostile)
    _check_clean_page(probe)
    def flat(text):                       # as the page lays text out
        return " ".join(text.split())
    assert probe["title"] == flat(f"{path.name} — mocapfix view")
    assert probe["labels"] == [path.name]
    assert flat(path.name) in flat(probe["legend"])
    for name in hostile:
        shown = probe["hovered"].get(name)
        assert shown is not None, f"{name[:40]!r} was not hovered"
        text = name if len(name) <= 300 else name[:300] + "…"
        assert shown == text + "\n" + path.name


def test_the_clean_report_embeds_the_viewer(tmp_path):
    """The HTML report of `clean` holds the before/after viewer in a sandboxed iframe; its
    document, taken out of ``srcdoc``, plays as the page of `mocapfix view` does."""
    path = shared("c3d/ktk_tennis_serve_nan.c3d")
    r = CliRunner().invoke(main, ["clean", str(path), "-o", str(tmp_path / "out"), "-q",
                                  "--report", "html"])
    assert r.exit_code == 0, r.output
    report = (tmp_path / "out" / (path.name + ".report.html")).read_text(encoding="utf-8")
    frames = re.findall(r'<iframe class="mocapfix-view"[^>]*sandbox="allow-scripts"[^>]*'
                        r'srcdoc="([^"]*)"></iframe>', report)
    assert len(frames) == 1
    page = tmp_path / "embedded.html"
    page.write_text(html.unescape(frames[0]), encoding="utf-8")
    probe = _probe(page, tmp_path)
    _check_clean_page(probe, layers=2)
    assert probe["counts"]["filled"] > 0 and "filled, est. error" in probe["filledTip"]
    # the samples a step judged wrong, by step (the report knows the steps; a file does not)
    assert re.search(r"judged wrong by step \d+ \(\w+\)", probe["legend"]), probe["legend"]


@pytest.mark.parametrize("frames,seen", [(1, True), (40, False), (0, False)],
                         ids=["one-frame", "nothing-seen", "no-frames"])
def test_degenerate_takes_load_without_errors(tmp_path, frames, seen):
    from mocapfix.core.motion import Motion
    from mocapfix.quality import viewer

    pos = np.zeros((frames, 3, 3)) if seen else np.full((frames, 3, 3), np.nan)
    page = tmp_path / "v.html"
    page.write_text(viewer.single([Motion(pos, ["a", "b", "c"], 30.0)]), encoding="utf-8")
    probe = _probe(page, tmp_path)
    _check_clean_page(probe)


def test_view_of_a_clean_report_overlays_its_files_and_colours_by_step(tmp_path):
    """`mocapfix view OUT.report.json` after a real `clean --report json,html`: the input
    and output as before/after, the samples each step judged wrong in the step's colour,
    as the report's own viewer shows them."""
    path = shared("c3d/ktk_tennis_serve_nan.c3d")
    r = CliRunner().invoke(main, ["clean", str(path), "-o", str(tmp_path / "out"), "-q",
                                  "--report", "json,html"])
    assert r.exit_code == 0, r.output
    report = tmp_path / "out" / (path.name + ".report.json")
    probe = _probe(_view(tmp_path, report), tmp_path)
    _check_clean_page(probe, layers=2)
    assert probe["labels"] == ["before: " + path.name, "after: " + path.name]
    (b, a) = probe["alone"]
    assert b["drawn"][0] > 0 and b["drawn"][1] == 0 and a["drawn"][0] == 0 and a["drawn"][1] > 0
    assert probe["bothVsLast"] > 0, "the before layer adds nothing to the picture"
    before, after = read(path), read(tmp_path / "out" / path.name)
    assert probe["counts"]["filled"] == int((before.missing & ~after.missing).sum())
    assert re.search(r"judged wrong by step \d+ \(\w+\)", probe["legend"]), probe["legend"]
