"""The HTML report as a person sees it: rendered by headless Chromium (Debian's
``chromium``; ``.ci/run`` installs it), screenshot taken, and the laid-out page inspected
by a small script injected into a copy of the report: no script errors, every plot panel
with non-empty, rendered tick labels on both axes and axis titles, the file name as the
page title, no raw Markdown, no step rows for other formats."""
from __future__ import annotations

import html
import json
import os
import re
import shutil
import struct
import subprocess

import pytest
from click.testing import CliRunner

from mocapfix.cli import main
from conftest import SAMPLE_DATA

# slow: headless Chromium renders each report (~3 s a page)
pytestmark = pytest.mark.slow

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--hide-scrollbars"]

PROBE = """<script>
window.__errors = [];
window.addEventListener('error', e => window.__errors.push(String(e.message || e)));
window.addEventListener('load', () => {
  const rendered = t => t.textContent.trim() !== '' && t.getBBox().width > 0;
  const plots = [...document.querySelectorAll('svg.plot')].map(svg =>
    [...svg.querySelectorAll('g.panel')].map(p => ({
      axis: p.getAttribute('data-axis'),
      xticks: [...p.querySelectorAll('text.tick.x')].filter(rendered).length,
      yticks: [...p.querySelectorAll('text.tick.y')].filter(rendered).length,
      xlabel: (p.querySelector('text.label.x') || {textContent: ''}).textContent.trim(),
      ylabel: (p.querySelector('text.label.y') || {textContent: ''}).textContent.trim(),
      lines: p.querySelectorAll('polyline').length,
    })));
  const steps = [...document.querySelectorAll('table')][0];
  document.body.setAttribute('data-probe', JSON.stringify({
    errors: window.__errors, title: document.title, plots: plots,
    backticks: document.body.innerText.includes('`'),
    stepRows: steps ? [...steps.querySelectorAll('tr')].slice(1).map(r => r.innerText) : [],
  }));
});
</script>"""


def _chromium():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    if os.environ.get("CI") or os.environ.get("MOCAPFIX_REQUIRE_DATA") == "1":
        pytest.fail("headless Chromium is not installed (.ci/run installs Debian's chromium)")
    pytest.skip("headless Chromium is not installed (apt-get install chromium)")


def _render(browser, page, tmp_path):
    profile = tmp_path / f"profile-{page.stem}"
    common = [browser, *FLAGS, f"--user-data-dir={profile}", "--window-size=1200,2400"]
    shot = tmp_path / f"{page.stem}.png"
    subprocess.run([*common, f"--screenshot={shot}", page.as_uri()], capture_output=True,
                   timeout=120, check=True)
    dom = subprocess.run([*common, "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
                         capture_output=True, text=True, timeout=120, check=True).stdout
    return shot, dom


@pytest.mark.parametrize("sample", ["walk_markers.c3d", "walk_kinect_v2.csv"])
def test_report_page_in_headless_chromium(tmp_path, sample):
    browser = _chromium()
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / sample), "-o", str(out), "--report", "html"])
    assert r.exit_code == 0, r.output
    report = out / (sample + ".report.html")
    probed = tmp_path / report.name
    probed.write_text(report.read_text().replace("<head>", "<head>" + PROBE, 1))
    shot, dom = _render(browser, probed, tmp_path)

    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert struct.unpack(">II", data[16:24]) == (1200, 2400)

    m = re.search(r'data-probe="([^"]*)"', dom)
    assert m, "the probe did not run (page not loaded?)"
    probe = json.loads(html.unescape(m.group(1)))
    assert probe["errors"] == []
    assert probe["title"].startswith(sample)
    assert not probe["backticks"]
    assert probe["plots"], "no plots on the page"
    for plot in probe["plots"]:
        assert [p["axis"] for p in plot] == ["x (mm)", "y (mm)", "z (mm)", "change (mm)"]
        for panel in plot:
            assert panel["xticks"] >= 2 and panel["yticks"] >= 2, panel
            assert panel["xlabel"] == "time (s)" and panel["ylabel"] == panel["axis"]
            assert panel["lines"] >= 1
    # steps the default config limits to other formats get no row
    rows = " ".join(probe["stepRows"])
    if sample.endswith(".c3d"):
        assert "spikes" not in rows and "tsmc" in rows
    else:
        assert "tsmc" not in rows and "kinect_skeleton" in rows
