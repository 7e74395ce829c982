"""Rendering of judged measurements: the clean report as JSON, Markdown and a
self-contained HTML page (inline SVG plots, no plotting library; its one script links
the embedded 3D viewer's frame to the plots), and
``check`` results as text lines, JSON and JUnit XML.

Nothing here measures or judges: see :mod:`mocapfix.quality.measure` and :mod:`mocapfix.quality.rules`.
"""
from __future__ import annotations

import html
import json
import re
import socket
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from mocapfix.core.errors import name_the_file, one_line, printable
from mocapfix.core.gaps import LONG_FILL_S
from mocapfix.quality.plots import by_severity, joint_plot
from mocapfix.quality.rules import METRICS, STATUS_ORDER
from mocapfix.pipeline.unlabelled import is_unlabelled


#: pieces of the JSON encoder's output joined at a time (:func:`to_json`)
JSON_PIECES = 65536


def to_json(report: dict) -> str:
    """The report as indented JSON: the text ``json.dumps(report, indent=1,
    allow_nan=False)`` gives. An indented dump is encoded in Python, and ``dumps``
    lists every piece it yields (a key, a comma, an indent: tens of bytes of object
    each) before joining them: the report of a long take's gaps and outliers took ten
    times its text. Here the pieces are joined a block at a time."""
    blocks, pieces = [], []
    for piece in json.JSONEncoder(indent=1, allow_nan=False).iterencode(report):
        pieces.append(piece)
        if len(pieces) == JSON_PIECES:
            blocks.append("".join(pieces))
            pieces.clear()
    blocks.append("".join(pieces))
    return "".join(blocks)


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.1f} %"


def _num(x, fmt="{:.1f}") -> str:
    return "–" if x is None else fmt.format(x)


def ranked(report: dict) -> list[dict]:
    """Joints worst first: status, then missing before, then name."""
    return sorted(report["joints"], key=lambda j: (-STATUS_ORDER[j["status"]],
                                                   -(j["missing_before"] or 0), j["name"]))


def _steps_run(report: dict):
    run = [s for s in report["steps"] if s.get("skipped") != "not for this format"]
    other = [s["step"] for s in report["steps"] if s.get("skipped") == "not for this format"]
    return run, other


def _long_fills(report: dict) -> list[str]:
    """Markdown section listing every fill longer than LONG_FILL_S (none: no section)."""
    rows = [(j["name"], g) for j in report["joints"] for g in j["gaps"]["filled"] if g.get("long")]
    if not rows:
        return []
    out = ["", f"## Long fills (> {LONG_FILL_S:g} s: rebuilt from the model, not measured)", "",
           "| joint | frames | s | confidence | estimated error (mm) | 90 % bound (mm) | filled by |",
           "|---|---|---:|---:|---:|---:|---|"]
    for name, g in sorted(rows, key=lambda r: -r[1]["length"]):
        conf = "–" if g.get("confidence") is None else f"{g['confidence']:.2f}"
        out.append(f"| {_cell(name)} | {g['start']}–{g['start'] + g['length'] - 1} "
                   f"| {g['seconds']:.2f} | {conf} | {_num(g.get('error_mm'))} "
                   f"| {_num(g.get('bound_mm'))}{' (extrapolated)' if g.get('extrapolated') else ''} "
                   f"| {g['filled_by']} |")
    return out


def _fill_summary(f: dict) -> str:
    """The file summary's line on the fills' error estimates and what was left."""
    largest = f.get("fill_bound_max_mm")
    return (f"- fills' 90 % error bound: largest {_num(largest)} mm"
            + (f" ({f['fills_without_estimate']} fills without an estimate)"
               if f.get("fills_without_estimate") else "")
            + f"; samples left as too uncertain to fill: {f.get('samples_left_uncertain', 0)}")


def _gaps_left(report: dict, shown: int = 12) -> list[str]:
    """Markdown section listing the gaps no step filled completely, with the reasons the
    steps gave for refusing their fills (``rejected_by``), and the samples judged wrong and
    left missing (``removed``); gaps of one span and one reason
    share a row (a whole-body dropout is one row, not one per marker). None: no section."""
    fps, frames = report["file"].get("fps") or 0, report["file"]["frames"]
    rows: dict[tuple, list[str]] = {}
    for j in report["joints"]:
        for g in j["gaps"]["unfilled"]:
            why = "; ".join(f"{r['step']}: {r['why']}" for r in g.get("rejected_by", ()))
            if not why and g["length"] == frames:
                why = "never seen in the input"
            rows.setdefault((g["start"], g["length"], g["filled_frames"], why), []).append(j["name"])
        for g in j.get("removed", ()):
            why = f"seen in the input, judged wrong ({g['removed_by']}), no fill trusted"
            rows.setdefault((g["start"], g["length"], 0, why), []).append(j["name"])
    if not rows:
        return []
    out = ["", "## Gaps left unfilled", "",
           "| frames | s | joints | why |", "|---|---:|---|---|"]
    for (start, length, filled, why), names in sorted(rows.items(), key=lambda r: (-r[0][1], r[0][0])):
        more = f", … (+{len(names) - shown})" if len(names) > shown else ""
        part = f" ({filled} filled)" if filled else ""
        secs = f"{length / fps:.2f}" if fps else "–"
        out.append(f"| {start}–{start + length - 1}{part} | {secs} | {len(names)}: "
                   f"{_cell(', '.join(names[:shown]))}{more} | {_cell(why or 'no step could fill it')} |")
    return out


def _unlabelled(report: dict, shown: int = 40) -> list[str]:
    """Markdown section listing the unlabelled trajectories with the reason of each (none:
    no section)."""
    rows = [p for p in report.get("not_cleaned") or [] if is_unlabelled(p["why"])]
    if not rows:
        return []
    out = ["", "## Unlabelled trajectories (not markers of the set: passed through unchanged, "
           "not graded)", "", "| trajectory | why |", "|---|---|"]
    out += [f"| {_cell(p['name'])} | {_cell(p['why'])} |" for p in rows[:shown]]
    if len(rows) > shown:
        out.append(f"| … (+{len(rows) - shown}; the JSON report lists all) | |")
    return out


def _not_cleaned(report: dict, shown: int = 12) -> list[str]:
    """Markdown section naming the other points left alone by design (model outputs,
    points the config excludes), grouped by reason."""
    by_why: dict[str, list[str]] = {}
    for p in report.get("not_cleaned") or []:
        if not is_unlabelled(p["why"]):
            by_why.setdefault(p["why"], []).append(p["name"])
    if not by_why:
        return []
    rig = report.get("file", {}).get("format") in ("bvh", "asfamc")
    out = ["", "## Not cleaned (" + ("their own channels as read, moving with their parents; "
                                     if rig else "passed through unchanged, ") + "not graded)", ""]
    for why, names in by_why.items():
        more = f", … (+{len(names) - shown})" if len(names) > shown else ""
        out.append(f"- {len(names)} × {_md(why)}: {_md(', '.join(names[:shown]))}{more}")
    return out


def _cell(text) -> str:
    """A name in a Markdown table cell: its pipes escaped and line breaks made spaces (a
    C3D label "a|b" split its row into one column too many, in the HTML report too), and
    as :func:`_md`."""
    return _md(" ".join(str(text).splitlines())).replace("|", "\\|")


_HTML_SPECIAL = re.compile(r"[<>&]")
_HTML_ESCAPED = re.compile(r"\\([<>&])")


def _md(text) -> str:
    """Text from a file (a name, a path, a note quoting one) as Markdown text: ``<``, ``>``
    and ``&`` backslash-escaped, so no Markdown viewer takes a label ``<script>`` or
    ``<img onerror=...>`` for HTML, and control characters shown as ``\\xNN`` (see
    :func:`printable`)."""
    return _HTML_SPECIAL.sub(r"\\\g<0>", printable(str(text)))


#: a step's ``info`` lists up to this many items in the Markdown (longer ones: the JSON)
_FINDINGS_ITEMS = 8


def _step_findings(step: dict) -> str:
    """A step's own figures from its ``info``, for people: numbers, words and short lists
    (the rigid joint pairs ``kinect_skeleton`` holds, the gaps a filler filled); per-joint
    tables and long lists stay in the JSON."""
    def text(v) -> str:
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    parts = []
    for key, value in (step.get("info") or {}).items():
        # the file summary counts the points no step cleans
        if key == "points_not_cleaned" or value is None or isinstance(value, (bool, dict)):
            continue
        label = key.replace("_", " ")
        if isinstance(value, (int, float, str)):
            parts.append(f"{label} {_cell(text(value))}")
        elif isinstance(value, list) and 0 < len(value) <= _FINDINGS_ITEMS and all(
                isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in value):
            parts.append(f"{label} {_cell(', '.join(map(text, value)))}")
    return "; ".join(parts)


def to_markdown(report: dict) -> str:
    f = report["file"]
    name = Path(f["path"]).name if f.get("path") else "motion"
    out = [f"# mocapfix report: {_md(one_line(name))}", "",
           f"**Status: {f['status']}** — {f['frames']} frames at {f['fps']} fps, {f['joints']} "
           f"joints/markers ({f['format']}, units {f['units']}).", "",
           f"- file: {_md(one_line(f['path']))}",
           f"- missing before: {_pct(f['missing_before'])}, after: {_pct(f['missing_after'])}",
           f"- samples filled: {f['samples_filled']}, flagged as outliers: {f['samples_flagged']}",
           f"- gaps before: {f['gaps_before']}, after: {f.get('gaps_after', '–')} (input gaps "
           f"not wholly filled: {f['gaps_unfilled']}), "
           f"long fills (> {LONG_FILL_S:g} s): {f.get('long_fills', 0)}",
           _fill_summary(f),
           f"- joints OK / WARN / FAIL: {f['joints_by_status']['OK']} / "
           f"{f['joints_by_status']['WARN']} / {f['joints_by_status']['FAIL']}"
           + (f" ({f['points_not_cleaned']} more points not cleaned"
              + (f", {f['points_unlabelled']} of them unlabelled trajectories"
                 if f.get("points_unlabelled") else "") + ": see below)"
              if f.get("points_not_cleaned") else "")]
    if "writeback_residual_mm" in f:
        wb = f["writeback_residual_mm"]
        out.append(f"- rotation write-back residual: mean {_num(wb['mean'], '{:.3f}')} mm, "
                   f"max {_num(wb['max'], '{:.3f}')} mm")
    for note in f["notes"]:
        out.append(f"- note: {_md(one_line(note))}")
    run, other = _steps_run(report)
    out += ["", "## Steps", "", "| step | cleaner | filled | flagged | mean move (mm) | s |",
            "|---|---|---:|---:|---:|---:|"]
    for s in run:
        label = s["step"] + (f" (skipped: {s['skipped']})" if s.get("skipped") else "")
        out.append(f"| {label} | {s['cleaner']} | {s['filled']} | {s['flagged']} | "
                   f"{_num(s['moved_mean_mm'], '{:.3f}')} | {_num(s['seconds'], '{:.3f}')} |")
    found = [f"- {s['step']}: {summary}" for s in run if (summary := _step_findings(s))]
    if found:
        out += ["", "What the steps found:", ""] + found
    if other:
        out += ["", f"Not run for {f['format']} (the config limits them to other formats): "
                + ", ".join(other) + "."]
    out += ["", "## Joints", "",
            "| joint | status | missing before → after | uncertain | gaps (longest) | outliers | "
            "correction mean / max (mm) | jitter before → after (m/s²) | why |",
            "|---|---|---|---|---|---:|---|---|---|"]
    for j in ranked(report):
        out.append(
            f"| {_cell(j['name'])} | {j['status']} | {_pct(j['missing_before'])} → {_pct(j['missing_after'])} "
            f"| {_pct(j.get('uncertain'))} "
            f"| {j['gaps']['count']} ({j['gaps']['longest_frames']}) | {j['outliers_flagged']} "
            f"| {_num(j['correction_mm']['mean'], '{:.2f}')} / {_num(j['correction_mm']['max'], '{:.1f}')} "
            f"| {_num(j['jitter_before'], '{:.2f}')} → {_num(j['jitter_after'], '{:.2f}')} "
            f"| {_cell('; '.join(j['reasons'])) or '–'} |")
    out += _long_fills(report)
    out += _gaps_left(report)
    out += _unlabelled(report)
    out += _not_cleaned(report)
    rules = report.get("rules") or []
    if rules:
        out += ["", "Rules: " + "; ".join(
            f"{r['name']} ({', '.join(f'{k} {r[k]}' for k in ('warn', 'fail') if k in r)})"
            for r in rules), ""]
    return "\n".join(out)


# -- HTML ------------------------------------------------------------------------------------

def to_html(report: dict, result, n_plots: int = 6, viewer: bool = True) -> str:
    """The report as one page: summary, steps and joints tables, the 3D before/after
    viewer (:func:`mocapfix.quality.viewer.embed`; ``viewer=False``: left out) and
    plots of the joints cleaning changed, worst first (:mod:`mocapfix.quality.plots`)."""
    shape = result.original.positions.shape[:2]
    filled, outliers = np.zeros(shape, bool), np.zeros(shape, bool)
    for r in result.records:
        filled |= r.filled
        outliers |= r.outliers
    plots = [f"<h3>{html.escape(printable(j['name']))} — {j['status']}</h3>"
             + joint_plot(result, j, filled, outliers) for j in by_severity(report)[:n_plots]]
    name = Path(report["file"]["path"]).name if report["file"].get("path") else "motion"
    body = markdown_to_html(to_markdown(report))
    return ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            "<meta http-equiv='Content-Security-Policy' content=\"default-src 'none'; "
            "script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src data:\">"
            f"<title>{html.escape(printable(name))} — mocapfix report</title>"
            "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
            "table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px}"
            "svg.plot{cursor:crosshair}"
            "</style></head><body>" + body + _viewer_section(result, viewer) +
            "<h2>Trajectories of the joints cleaning changed</h2><p>FAIL first, then WARN, then "
            "OK, each the largest change first; each drawn over the frames that changed (changes "
            "far apart: a plot per span, up to 3, the largest first), the strip above it the "
            "whole take with those frames outlined. The red line is the 3D view's frame; click "
            "a plot to show that frame in the view. Grey: input; colour: "
            "cleaned; the change panel is the distance between them and, for a fill, its "
            "distance to the straight line across the gap; rotation panels: the joint's "
            "rotation channels (BVH/AMC). Shading: red missing in the input, green filled (band: "
            "the fill's 90 % error bound), orange judged wrong by a step; Kinect: a bar along the "
            "top, yellow where the joint was Inferred, grey where NotTracked.</p>"
            + ("".join(plots) or "<p>No joint was changed.</p>")
            + (_CURSOR_SCRIPT if viewer else "") + "</body></html>")


#: The report's one script: the 3D viewer's frame (its iframe posts
#: ``{mocapfix: "frame", frame: N}``) drawn as a cursor line on every plot whose window
#: holds it, and a click on a plot sent to the viewer as the frame under the mouse. Only
#: messages of that shape from the viewer's own window are read.
_CURSOR_SCRIPT = """<script>
(function () {
  "use strict";
  const view = document.querySelector("iframe.mocapfix-view");
  if (!view) return;
  const plots = Array.from(document.querySelectorAll("svg.plot"), (svg) => {
    const [f0, f1] = svg.getAttribute("data-frames").split(" ").map(Number);
    const [x0, x1] = svg.getAttribute("data-x").split(" ").map(Number);
    return { svg, f0, f1, x0, x1, span: Math.max(f1 - 1 - f0, 1), cursor: svg.querySelector("line.cursor") };
  });
  const isFrame = (m) => typeof m === "object" && m !== null && m.mocapfix === "frame"
    && Number.isInteger(m.frame) && m.frame >= 0 && Object.keys(m).length === 2;
  window.addEventListener("message", (e) => {
    if (e.source !== view.contentWindow || !isFrame(e.data)) return;
    const f = e.data.frame;
    for (const p of plots) {
      const inside = f >= p.f0 && f < p.f1, x = (p.x0 + (p.x1 - p.x0) * (f - p.f0) / p.span).toFixed(1);
      p.cursor.setAttribute("visibility", inside ? "visible" : "hidden");
      p.cursor.setAttribute("x1", x); p.cursor.setAttribute("x2", x);
    }
  });
  for (const p of plots) {
    p.svg.addEventListener("click", (e) => {
      const r = p.svg.getBoundingClientRect(), x = (e.clientX - r.left) * p.svg.viewBox.baseVal.width / r.width;
      const f = Math.round(p.f0 + (x - p.x0) / (p.x1 - p.x0) * p.span);
      // "*": the sandboxed viewer has no origin to name
      view.contentWindow.postMessage({ mocapfix: "frame", frame: Math.max(p.f0, Math.min(p.f1 - 1, f)) }, "*");
    });
  }
})();
</script>"""


def _viewer_section(result, viewer: bool) -> str:
    if not viewer:
        return ""
    from mocapfix.quality.viewer import embed
    return ("<h2>3D view</h2><p>grey rings: input; colour: cleaned; filled samples coloured "
            "by their estimated error, samples a step judged wrong by step. Drag to orbit, wheel to zoom, hover for names.</p>"
            + embed(result.original, result.cleaned, result.records))


_INLINE = re.compile(r"`([^`]+)`|\*\*([^*]+)\*\*")
_PIPE = re.compile(r"(?<!\\)\|")            # a cell border: a pipe not escaped as \|


def _inline(text: str) -> str:
    """Escape, then turn `code` and **bold** into tags (``\\<`` of :func:`_md` is ``&lt;``)."""
    text = _HTML_ESCAPED.sub(r"\1", text)
    out, pos = [], 0
    for m in _INLINE.finditer(text):
        out.append(html.escape(text[pos:m.start()]))
        out.append(f"<code>{html.escape(m.group(1))}</code>" if m.group(1) is not None
                   else f"<strong>{html.escape(m.group(2))}</strong>")
        pos = m.end()
    out.append(html.escape(text[pos:]))
    return "".join(out)


def markdown_to_html(md: str) -> str:
    """Just enough Markdown (headings, lists, pipe tables, bold, code) for our reports."""
    out, in_table, in_list = [], False, False
    for line in printable(md).splitlines():
        if line.startswith("|"):
            cells = [c.strip().replace("\\|", "|") for c in _PIPE.split(line.strip().strip("|"))]
            if set("".join(cells)) <= set("-:"):
                continue
            tag = "th" if not in_table else "td"
            if not in_table:
                out.append("<table>")
                in_table = True
            out.append("<tr>" + "".join(f"<{tag}>{_inline(c)}</{tag}>" for c in cells) + "</tr>")
            continue
        if in_table:
            out.append("</table>")
            in_table = False
        if line.startswith("- "):
            if not in_list:
                out.append("<ul>")
                in_list = True
            out.append(f"<li>{_inline(line[2:])}</li>")
            continue
        if in_list:
            out.append("</ul>")
            in_list = False
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{_inline(line[level:].strip())}</h{level}>")
        elif line.strip():
            out.append("<p>" + _inline(line) + "</p>")
    if in_table:
        out.append("</table>")
    if in_list:
        out.append("</ul>")
    return "\n".join(out)


# -- check results ------------------------------------------------------------------------

def check_line(result: dict, verbose: bool = False) -> str:
    """One line per file (more with ``verbose``): status, path, the worst findings; a line
    break in a file name or message is shown as ``\\n`` (it would split the file's line)."""
    status, path = result["status"], one_line(result["path"])
    if status == "ERROR":
        return f"ERROR {one_line(name_the_file(result['path'], result['error']))}"
    findings = result.get("findings", [])
    worst = [f for f in findings if f["level"] == status] or findings
    head = f"{status:<5} {path}"
    if verbose:
        lines = [head] + [f"      {f['level']}: {one_line(f['message'])}" for f in findings]
        unlabelled = (result.get("file") or {}).get("unlabelled") or []
        if unlabelled:
            lines.append(f"      not judged: {len(unlabelled)} unlabelled trajectories ("
                         + one_line(", ".join(u["name"] for u in unlabelled[:8]))
                         + (", …" if len(unlabelled) > 8 else "") + ")")
        wc = result.get("would_clean")
        if wc and "error" not in wc:
            lines.append(f"      would clean: fill {wc['samples_filled']} samples, flag "
                         f"{wc['samples_flagged']}, leave {_pct(wc['missing_after'])} missing "
                         f"({wc.get('samples_left_uncertain', 0)} samples as too uncertain to "
                         f"fill; largest fill bound {_num(wc.get('fill_bound_max_mm'))} mm) and "
                         + METRICS["uncertain"].phrase.format(v=_pct(wc["uncertain"])))
        return "\n".join(lines)
    if not worst:
        return head
    more = f"; +{len(findings) - 1} more" if len(findings) > 1 else ""
    return f"{head}  ({one_line(worst[0]['message'])}{more})"


def check_junit(results: list[dict], seconds: float, suite: str = "mocapfix check") -> str:
    """JUnit XML: one testcase per file; a FAIL is a <failure> whose message names the rule
    and the figure (all failing findings in its text), an unreadable file an <error>, a
    file of no known layout a <skipped>, warnings go to <system-out>."""
    failures = sum(r["status"] == "FAIL" for r in results)
    errors = sum(r["status"] == "ERROR" for r in results)
    skipped = sum(r["status"] == "SKIP" for r in results)
    attrs = {"name": suite, "tests": str(len(results)), "failures": str(failures),
             "errors": str(errors), "skipped": str(skipped), "time": f"{seconds:.3f}"}
    root = ET.Element("testsuites", attrs)
    ts = ET.SubElement(root, "testsuite", {**attrs, "timestamp": time.strftime("%Y-%m-%dT%H:%M:%S"),
                                           "hostname": socket.gethostname()})
    for r in results:
        tc = ET.SubElement(ts, "testcase", {"classname": f"mocapfix.check.{r.get('format') or 'unknown'}",
                                            "name": r["path"], "file": r["path"],
                                            "time": f"{r.get('seconds', 0.0):.3f}"})
        findings = r.get("findings", [])
        if r["status"] == "ERROR":
            el = ET.SubElement(tc, "error", {"type": "unreadable", "message": r["error"]})
            el.text = r["error"]
        elif r["status"] == "SKIP":
            ET.SubElement(tc, "skipped", {"message": r["skipped"]})
        elif r["status"] == "FAIL":
            fails = [f for f in findings if f["level"] == "FAIL"]
            first = fails[0]
            el = ET.SubElement(tc, "failure", {"type": first["rule"], "message": first["message"]})
            el.text = "\n".join(f"{f['rule']}: {f['message']}" for f in fails)
        warns = [f for f in findings if f["level"] == "WARN"]
        if warns:
            ET.SubElement(tc, "system-out").text = "\n".join(f"WARN {f['rule']}: {f['message']}"
                                                             for f in warns)
    ET.indent(root)
    text = ET.tostring(root, encoding="unicode")
    # control characters (a file named "a\x01b.bvh", a reader quoting raw bytes) are not
    # allowed in XML 1.0 even as references: written as \xNN text, or CI cannot parse it
    text = _XML_INVALID.sub(lambda m: f"\\x{ord(m.group()):02x}", text)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n"


_XML_INVALID = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff]")
