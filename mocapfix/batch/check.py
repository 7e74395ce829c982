"""``mocapfix check``: measure capture files as read and judge them against rules, without
changing anything (a CI gate for capture archives).

Per file the result is ``OK``/``WARN``/``FAIL`` (quality, from the rules; with
``--would-clean``, a pipeline that cannot clean the file is a ``FAIL`` too) or ``ERROR``
(the file could not be read). Exit codes: 0 every file passed (WARN passes), 1 a rule failed,
2 usage or config error, 3 an input could not be read (takes precedence over 1).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from mocapfix.core.errors import MocapfixError, name_the_file
from mocapfix.quality.rules import Finding, RuleSet

EXIT_PASS, EXIT_FAILED, EXIT_USAGE, EXIT_UNREADABLE = 0, 1, 2, 3


def check_motion(motion, rules: RuleSet, pipeline=None) -> dict:
    """Measure and judge one motion; with ``pipeline``, also what cleaning would do (in
    memory, nothing written). Unlabelled trajectories are passed over as the rules'
    ``unlabelled:`` says (by default: not judged, listed in ``file["unlabelled"]``)."""
    from mocapfix.quality.measure import measure_input

    measured = measure_input(motion, unlabelled=rules.unlabelled)
    verdict = rules.judge(measured)
    result = {"path": motion.path, "format": motion.format, "status": verdict.status,
              "findings": [f.as_dict() for f in verdict.findings],
              "file": measured["file"], "joints": measured["joints"]}
    if pipeline is not None:
        try:
            result["would_clean"] = would_clean(motion, pipeline)
        except MocapfixError as exc:
            # the file was read and judged; the pipeline the gate asked about cannot clean
            # it (a trained cleaner with no model for this skeleton, ...): a failed check,
            # not an unreadable input
            message = f"the --would-clean pipeline cannot clean this file: {exc}"
            result["status"] = "FAIL"
            result["findings"].insert(0, Finding("would_clean", "pipeline", "FAIL", None, "",
                                                 message).as_dict())
            result["would_clean"] = {"error": str(exc)}
    return result


def would_clean(motion, pipeline) -> dict:
    """What ``pipeline`` would fill, move and leave uncertain (figures of clean's report)."""
    from mocapfix.cleaning import clean_motion
    from mocapfix.quality.report import build_report

    report = build_report(clean_motion(motion, pipeline), pipeline.report)
    f, joints = report["file"], report["joints"]
    T = max(f["frames"], 1)
    return {
        "status": f["status"],
        "samples_filled": f["samples_filled"],
        "samples_flagged": f["samples_flagged"],
        "missing_after": f["missing_after"],
        "uncertain": sum(j["uncertain"] or 0.0 for j in joints) / max(len(joints), 1),
        "moved_max_mm": max((j["correction_mm"]["max"] or 0.0 for j in joints), default=0.0),
        "gaps_unfilled": f["gaps_unfilled"],
        "fill_bound_max_mm": f.get("fill_bound_max_mm"),
        "samples_left_uncertain": f.get("samples_left_uncertain", 0),
        "joints_uncertain": [j["name"] for j in joints if (j["uncertain"] or 0.0) * T >= 1
                             and j["status"] != "OK"][:20],
    }


@dataclass
class CheckTask:
    """Check one file (picklable, for a process pool or another executor)."""

    rules: RuleSet
    config: dict | None = None
    config_source: str | None = None
    read_options: dict | None = None

    def __call__(self, path) -> dict:
        from mocapfix.formats import read

        path = getattr(path, "path", path)
        started = time.perf_counter()
        try:
            motion = read(path, **(self.read_options or {}))
            if motion.n_frames == 0:
                raise MocapfixError(f"{path}: holds no frames")
            pipeline = None
            if self.config is not None:
                from mocapfix.batch.clean import _pipeline
                pipeline = _pipeline(self.config, self.config_source or "<config>")
            result = check_motion(motion, self.rules, pipeline)
        except MocapfixError as exc:
            result = {"path": str(path), "status": "ERROR", "error": name_the_file(path, exc),
                      "findings": []}
        except Exception as exc:  # noqa: BLE001 — one bad file must not stop the batch
            from mocapfix.batch.tasks import internal_error

            result = internal_error({"path": str(path), "status": "ERROR", "findings": [],
                                     "error": f"{path}: internal error {type(exc).__name__}: {exc}"})
        result["path"] = str(path)
        result["seconds"] = round(time.perf_counter() - started, 4)
        return result


def exit_code(results: list[dict]) -> int:
    if any(r["status"] == "ERROR" for r in results):
        return EXIT_UNREADABLE
    if any(r["status"] == "FAIL" for r in results):
        return EXIT_FAILED
    return EXIT_PASS


def summary(results: list[dict]) -> dict:
    """Counts by status; ``files`` counts the captures checked (not the SKIPped files of
    no known layout, which pass)."""
    counts = {k: sum(r["status"] == k for r in results) for k in ("OK", "WARN", "FAIL", "ERROR", "SKIP")}
    return {"files": len(results) - counts["SKIP"], **counts, "exit_code": exit_code(results)}
