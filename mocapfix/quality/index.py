"""The batch index: ``OUTDIR/index.html``, one row per file a ``clean`` run made or failed
on (from the output folder's manifest, so a resumed run lists the files of earlier runs
too), with its status, frames, missing before and after, samples filled and flagged, the
worst joints and a link to its HTML report. Worst first; a click on a column heading
sorts by it (a few lines of inline script; without script the table stays worst first).
Self-contained: no network, every name and path escaped."""
from __future__ import annotations

import html
import os
from pathlib import Path
from urllib.parse import quote

STATUS_ORDER = {"ERROR": 0, "FAIL": 1, "WARN": 2, "OK": 3}

_SORT = """<script>
for (const th of document.querySelectorAll('th')) th.addEventListener('click', () => {
  const table = th.closest('table'), body = table.tBodies[0], k = th.cellIndex;
  const up = th.dataset.dir !== 'up'; th.dataset.dir = up ? 'up' : 'down';
  const key = td => td.dataset.v !== undefined ? Number(td.dataset.v) : td.textContent;
  const rows = [...body.rows].sort((a, b) => {
    const x = key(a.cells[k]), y = key(b.cells[k]);
    return (x < y ? -1 : x > y ? 1 : 0) * (up ? 1 : -1);
  });
  rows.forEach(r => body.appendChild(r));
});
</script>"""


def _shown(text: str) -> str:
    """Escaped text of a name; a file name's undecodable bytes (held as surrogates) as U+FFFD."""
    return html.escape(os.fsencode(text).decode("utf-8", "replace"))


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.1f} %"


def _cell(text: str, value: float | None = None) -> str:
    v = "" if value is None else f' data-v="{value:g}"'
    return f"<td{v}>{_shown(text)}</td>"


def _row(rec: dict) -> str:
    s = rec.get("summary") or {}
    status = rec["quality"] if rec.get("status") == "done" else "ERROR"
    output = rec.get("output") or Path(rec["input"]).name
    report = next((f for f in rec.get("files", []) if f.endswith(".report.html")), None)
    link = (f'<a href="{html.escape(quote(os.fsencode(Path(report).as_posix())))}">'
            f"{_shown(output)}</a>" if report else _shown(output))
    worst = ", ".join(f"{name} ({st})" for name, st in s.get("worst", []))
    if status == "ERROR":
        worst = rec.get("error", "")

    def num(key):
        return s.get(key) if isinstance(s.get(key), (int, float)) else None
    shown = html.escape(str(status), quote=True)     # the manifest is a file anyone may edit
    cells = [f'<td data-v="{STATUS_ORDER.get(status, 9)}" class="{shown}">{shown}</td>',
             f"<td>{link}</td>",
             _cell(str(s["frames"]) if num("frames") is not None else "–", num("frames")),
             _cell(_pct(num("missing_before")), num("missing_before")),
             _cell(_pct(num("missing_after")), num("missing_after")),
             _cell(str(s.get("samples_filled", "–")), num("samples_filled")),
             _cell(str(s.get("samples_flagged", "–")), num("samples_flagged")),
             _cell(worst)]
    return "<tr>" + "".join(cells) + "</tr>"


def index_html(records: list[dict], outdir: Path) -> str:
    """The page for the manifest ``records`` of ``outdir`` (one per input and output)."""
    records = sorted(records, key=lambda r: (
        STATUS_ORDER.get(r.get("quality") if r.get("status") == "done" else "ERROR", 9),
        str(r.get("output", ""))))
    counts = {}
    for r in records:
        status = r.get("quality") if r.get("status") == "done" else "ERROR"
        counts[status] = counts.get(status, 0) + 1
    summary = ", ".join(f"{n} {s}" for s, n in sorted(counts.items(), key=lambda kv: STATUS_ORDER.get(kv[0], 9)))
    head = "".join(f"<th>{h}</th>" for h in ("status", "file", "frames", "missing before",
                                             "missing after", "filled", "flagged", "worst joints"))
    rows = "".join(_row(r) for r in records)
    return ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            "<meta http-equiv='Content-Security-Policy' content=\"default-src 'none'; "
            "script-src 'unsafe-inline'; style-src 'unsafe-inline'\">"
            f"<title>{_shown(outdir.name)} — mocapfix batch</title><style>"
            "body{font-family:sans-serif;max-width:1200px;margin:2em auto}"
            "table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ccc;padding:3px 7px}"
            "th{cursor:pointer;background:#f3f3f3}td[data-v]{text-align:right}"
            ".FAIL,.ERROR{background:#fdd}.WARN{background:#ffe9b3}.OK{background:#dfd}"
            "</style></head><body>"
            f"<h1>{_shown(outdir.name)}</h1><p>{len(records)} files: {html.escape(summary)}. "
            "Click a heading to sort.</p>"
            f"<table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>"
            + _SORT + "</body></html>")
