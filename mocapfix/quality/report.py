"""Per-joint quality report of a cleaned file: measured by :mod:`mocapfix.quality.measure`,
judged by the rule engine of :mod:`mocapfix.quality.rules`, rendered by :mod:`mocapfix.quality.render`.

JSON schema ``mocapfix.report/1``::

    {"schema": "mocapfix.report/1", "file": {...summary, "status"...}, "steps": [{"step",
     "cleaner", "seconds", "filled", "flagged", "moved_mean_mm", "info", "judged_wrong":
     [[point, start frame, frames], ...] (only when the step judged samples wrong)}],
     "thresholds": {...}, "rules": [...], "joints": [{"name", "status", "reasons",
     "missing_before", "missing_after", "uncertain", "gaps": {"count", "longest_frames",
     "filled": [{"start", "length", "seconds", "long", "confidence", "filled_by"}],
     "unfilled": [{"start", "length", "filled_frames", "rejected_by"}]}, "outliers_flagged",
     "correction_mm": {"mean", "max", "frame", "cause"}, "jitter_before", "jitter_after" (RMS acceleration,
     m/s²), "bone_variation_before", "bone_variation_after",
     "writeback_residual_mm": {"mean", "max"} }], "bones": [...],
     "not_cleaned": [{"name", "why"}]}

``joints`` holds the points the pipeline cleaned, and only they are graded and counted in
the file summary; points it left alone by design — C3D model outputs (angles, forces,
moments, powers, ...), unlabelled trajectories (``"unlabelled trajectory (Vicon *N
name)"``, ``"unlabelled trajectory (seen on 21 of 700 frames of the take, ...)"``:
:mod:`mocapfix.pipeline.unlabelled`) and markers the config's pipeline-wide ``exclude:`` leaves
out — are listed under ``not_cleaned`` with the reason (``file.points_not_cleaned``
counts them, ``file.points_unlabelled`` the unlabelled ones; absent when there are none).

A filled gap is ``long`` when it spans more than ``mocapfix.core.gaps.LONG_FILL_S`` (0.5 s); its
``confidence`` is the mean per-sample fill confidence (``None`` when the filler gives
none); the file summary counts ``long_fills``, and the Markdown/HTML report lists them.
An unfilled gap has ``rejected_by`` (``[{"step", "why"}]``) when a step filled it but did
not write the fill (it left the capture volume, or jumped further in one frame than the
marker's own data: a step's ``info["rejected_fills"]``).
``uncertain`` is the fraction of a joint's frames that rest on no measurement (missing in
the input; weighted by the cleaned motion's per-sample confidence where it has one).
``outliers_flagged`` counts the samples a step made missing as outliers or rebuilt in
place (a step's ``info["replaced_frames"]``); ``correction_mm.frame`` is the frame of the
largest move and ``cause`` (only when one applies) says a step judged that sample, or a
joint above it in the skeleton, wrong there.
Lengths are in mm whatever the file's unit.
"""
from __future__ import annotations

from mocapfix.quality.measure import CleanResult, measure_cleaning
from mocapfix.quality.render import markdown_to_html, to_html, to_json, to_markdown
from mocapfix.quality.rules import DEFAULT_THRESHOLDS, STATUS_ORDER, report_rules, report_thresholds
from mocapfix.pipeline.selection import EXCLUDED, NO_MARKER_SELECTED
from mocapfix.pipeline.unlabelled import is_unlabelled

SCHEMA = "mocapfix.report/1"

__all__ = ["SCHEMA", "CleanResult", "DEFAULT_THRESHOLDS", "STATUS_ORDER", "build_report",
           "to_json", "to_markdown", "to_html", "markdown_to_html"]


def build_report(result: CleanResult, thresholds: dict | None = None) -> dict:
    """Measure ``result`` and judge it with the report rules: the default thresholds (and
    the file format's own, ``rules.FORMAT_THRESHOLDS``), overridden by a config's validated
    ``report:`` section (``thresholds``)."""
    measured = measure_cleaning(result)
    rules = report_rules(thresholds, result.original.format)
    verdict = rules.judge(measured)
    for j in measured["joints"]:
        j["status"] = verdict.joint_status[j["name"]]
        j["reasons"] = verdict.joint_reasons[j["name"]]
    file = measured["file"]
    file["status"] = verdict.status
    if not measured["joints"] and any(p["why"] == EXCLUDED for p in measured.get("not_cleaned", [])):
        # a markers:/exclude: that selects nothing (a typo?) must not read as a clean pass
        file["notes"].append("the config's markers:/exclude: leave none of this file's "
                             "markers to clean: nothing was cleaned or graded")
        file["reasons"] = ["WARN: " + file["notes"][-1]]      # the line's -v says why
        if STATUS_ORDER[file["status"]] < STATUS_ORDER["WARN"]:
            file["status"] = "WARN"
    elif not measured["joints"] and any(is_unlabelled(p["why"]) for p in measured.get("not_cleaned", [])):
        file["notes"].append("every marker of this file is an unlabelled trajectory: nothing "
                             "was cleaned or graded (a config's unlabelled: {clean: true} "
                             "cleans them)")
    # a step whose own markers:/exclude: select nothing here (a typo?) did not run
    unselected = [f"{s['step']}: its markers:/exclude: select none of the markers cleaned in "
                  "this file; it did not run" for s in measured["steps"]
                  if measured["joints"] and (s.get("info") or {}).get("skipped") == NO_MARKER_SELECTED]
    if unselected:
        file["steps_not_run"] = unselected
        file["notes"].extend(unselected)
    file["joints_by_status"] = {k: sum(j["status"] == k for j in measured["joints"])
                                for k in STATUS_ORDER}
    report = {"schema": SCHEMA, "file": file, "steps": measured["steps"],
              "thresholds": report_thresholds(thresholds, result.original.format),
              "rules": rules.describe(), "joints": measured["joints"]}
    for key in ("bones", "not_cleaned"):
        if key in measured:
            report[key] = measured[key]
    return report
