"""Names from a file are text, never markup or terminal control (issue 40, item 7): a C3D
label ``<script>`` or ``<img onerror>`` reaches neither the Markdown report (a viewer
renders HTML in Markdown) nor the HTML report as a tag, an ESC or BEL byte is shown as
``\\xNN`` in both, and ``info`` keeps a name with a line break on its line."""
from __future__ import annotations

import json
import re

from click.testing import CliRunner
from conftest import config_file, no_traceback

from mocapfix.cli import main

LABELS = ["<script>alert(1)</script>", "<img src=x onerror=alert(1)>", "\x1b[31mred\x07", "a&b"]


def _capture(tmp_path, labels):
    from malformed_corpus import c3d_bytes, small_c3d_points

    src = tmp_path / "in" / "names.c3d"
    src.parent.mkdir()
    src.write_bytes(c3d_bytes(small_c3d_points(T=200, P=len(labels)), labels))
    return src


def test_hostile_labels_are_text_in_the_markdown_and_html_reports(tmp_path):
    src = _capture(tmp_path, LABELS)
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "--report", "md,html,json",
                                  "-c", config_file(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    md = (out / "names.c3d.report.md").read_text()
    page = (out / "names.c3d.report.html").read_text()
    assert not re.search(r"(?<!\\)<(script|img|/script)", md)
    # the page's one script is the report's own (the viewer's time cursor)
    from mocapfix.quality.render import _CURSOR_SCRIPT
    assert page.count(_CURSOR_SCRIPT) == 1
    page = page.replace(_CURSOR_SCRIPT, "")
    assert "<script" not in page and "<img" not in page
    for text in (md, page):
        assert "\x1b" not in text and "\x07" not in text
    # Markdown: backslash escapes (rendered as the characters, not as tags)
    assert r"\<script\>alert(1)\</script\>" in md and r"\<img src=x onerror=alert(1)\>" in md
    assert r"\x1b[31mred\x07" in md and r"a\&b" in md
    # HTML: entities, once (not "&amp;lt;")
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page and "&amp;lt;" not in page
    assert "&lt;img src=x onerror=alert(1)&gt;" in page and "a&amp;b" in page
    # the JSON keeps the names as read (it is data, not a page)
    names = [j["name"] for j in json.loads((out / "names.c3d.report.json").read_text())["joints"]]
    assert sorted(names) == sorted(LABELS)


def test_info_keeps_a_name_with_a_line_break_on_its_line(tmp_path):
    src = _capture(tmp_path, ["a\nb", "\x1b[2Jc", "d"])
    r = CliRunner().invoke(main, ["info", str(src)])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    names = next(line for line in r.output.splitlines() if line.strip().startswith("names"))
    assert re.search(r"a\\nb, \\x1b\[2Jc, d", names), names
    assert "\x1b" not in r.output
