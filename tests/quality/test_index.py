"""The batch index ``OUTDIR/index.html`` of ``clean --report html``: a row per file (those
of earlier runs too), worst first, each linking to its report; names escaped; the shared
data's batch links every report; sorting by a column in headless Chromium."""
from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from urllib.parse import unquote

import pytest
from click.testing import CliRunner

from conftest import DATA, SAMPLE_DATA, need
from mocapfix.cli import main


def _rows(page: str) -> list[tuple[str, str, str]]:
    """(status, link target, file text) per row."""
    out = []
    for row in re.findall(r"<tr>(.*?)</tr>", page, re.DOTALL)[1:]:
        status = re.search(r'class="(\w+)">', row).group(1)
        m = re.search(r'<a href="([^"]*)">(.*?)</a>', row)
        out.append((status, unquote(html.unescape(m.group(1))) if m else "",
                    html.unescape(m.group(2)) if m else ""))
    return out


def _clean(inputs, out, *extra):
    r = CliRunner().invoke(main, ["clean", *map(str, inputs), "-o", str(out), "-q", *extra])
    assert r.exit_code in (0, 1), r.output
    return r


def test_a_batch_with_html_reports_has_an_index(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for name in ("walk.bvh", "walk_markers.c3d", "walk_kinect_v2.csv"):
        shutil.copy(SAMPLE_DATA / name, src / name)
    hostile = src / "<script>alert(1)<\u2044script>\"'&#.c3d"
    shutil.copy(SAMPLE_DATA / "walk_markers.c3d", hostile)
    _clean([src], tmp_path / "out", "--report", "json,html")
    page = (tmp_path / "out" / "index.html").read_text(encoding="utf-8")
    rows = _rows(page)
    assert len(rows) == 4
    assert "<script>alert" not in page
    assert {text for _, _, text in rows} == {"walk.bvh", "walk_markers.c3d", "walk_kinect_v2.csv",
                                            hostile.name}
    order = [s for s, _, _ in rows]
    rank = {"FAIL": 0, "WARN": 1, "OK": 2}
    assert order == sorted(order, key=rank.get), "not worst first"
    for status, target, text in rows:
        report = tmp_path / "out" / target
        assert target == text + ".report.html" and report.is_file(), target
        data = json.loads((tmp_path / "out" / (text + ".report.json")).read_text())
        assert data["file"]["status"] == status


def test_the_index_lists_the_files_of_earlier_runs(tmp_path):
    _clean([SAMPLE_DATA / "walk.bvh"], tmp_path / "out", "--report", "html")
    _clean([SAMPLE_DATA / "walk_markers.c3d"], tmp_path / "out", "--report", "html")
    texts = {t for _, _, t in _rows((tmp_path / "out" / "index.html").read_text(encoding="utf-8"))}
    assert texts == {"walk.bvh", "walk_markers.c3d"}


def test_no_html_reports_no_index(tmp_path):
    _clean([SAMPLE_DATA / "walk.bvh"], tmp_path / "out")
    assert not (tmp_path / "out" / "index.html").exists()


@pytest.mark.slow
def test_the_shared_data_batch_index_links_every_report(tmp_path):
    data = need(DATA)
    _clean([data], tmp_path / "out", "--report", "html", "-j", "2")
    page = (tmp_path / "out" / "index.html").read_text(encoding="utf-8")
    rows = _rows(page)
    inputs = [p for p in data.rglob("*") if p.is_file() and p.suffix.lower() != ".asf"
              and p.name != "SOURCES.md"]
    assert len(rows) == len(inputs)
    assert all((tmp_path / "out" / target).is_file() for _, target, _ in rows)

    from test_html_browser import FLAGS, _chromium
    browser = _chromium()
    probe = """<script>window.addEventListener('load', () => {
      const th = [...document.querySelectorAll('th')].find(t => t.textContent === 'frames');
      th.click();
      const frames = [...document.querySelectorAll('tbody tr')].map(r => Number(r.cells[2].dataset.v));
      document.body.setAttribute('data-probe', JSON.stringify(frames));
    });</script>"""
    probed = tmp_path / "probed.html"
    probed.write_text(page.replace("<head>", "<head>" + probe, 1), encoding="utf-8")
    dom = subprocess.run([browser, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                          "--virtual-time-budget=3000", "--dump-dom", probed.as_uri()],
                         capture_output=True, text=True, timeout=120, check=True).stdout
    frames = json.loads(html.unescape(re.search(r'data-probe="([^"]*)"', dom).group(1)))
    assert len(frames) == len(rows) and frames == sorted(frames)


def test_a_record_edited_by_hand_goes_into_the_page_as_text():
    # the manifest is a text file anyone may edit; its load drops records of another shape,
    # and what reaches the page is escaped all the same (a status went into class="...")
    from pathlib import Path

    from mocapfix.quality.index import index_html

    rec = {"input": "a.c3d", "output": "a<b>.c3d", "status": "done",
           "quality": '"><script>x()</script>', "files": [], "summary": {"frames": 3}}
    page = index_html([rec], Path("/tmp/out"))
    assert "<script>x()" not in page and "a<b>" not in page
    assert "&quot;&gt;&lt;script&gt;x()" in page and "a&lt;b&gt;.c3d" in page
