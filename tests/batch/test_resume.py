"""Resumable batches (issue 13): the manifest in the output folder lets a re-run skip the
files an earlier run finished — also after that run was killed — and redo only the rest,
with the same outputs as one uninterrupted run. A damaged manifest or config record is
refused or distrusted, an input that changed while it was cleaned is not recorded as
finished, and a file found through two given paths resumes."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA, config_file, hang_guard, no_traceback, output_tree, shared
from mocapfix.core import models
from mocapfix.cli import main
from mocapfix.core.fileio import file_sha256
from mocapfix.batch.manifest import MANIFEST_NAME, run_key
from mocapfix.config import loads_config

BVH = SAMPLE_DATA / "walk.bvh"
KIN = SAMPLE_DATA / "walk_kinect_v2.csv"
CFG = "pipeline:\n  - cleaner: spikes\n  - cleaner: fill\n    max_gap: 0.5 s\n  - cleaner: gaussian\n"


def _inputs(tmp_path, copies=3) -> Path:
    src = tmp_path / "in"
    for n in range(copies):
        shutil.copytree(SAMPLE_DATA, src / f"take{n}")
    return src


def _cfg(tmp_path) -> str:
    p = tmp_path / "cfg.yaml"
    p.write_text(CFG)
    return str(p)


def _records(outdir: Path) -> dict:
    recs = {}
    path = outdir / MANIFEST_NAME
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                r = json.loads(line)
            except ValueError:
                continue
            recs[r["input"]] = r
    return recs


def _done(outdir: Path) -> set:
    return {k for k, r in _records(outdir).items() if r["status"] == "done"}


def _outputs(folder: Path) -> dict:
    return output_tree(folder)


def _run(*args):
    return CliRunner().invoke(main, ["clean", *map(str, args)])


def _background_batch(src, out, cfg, **popen) -> subprocess.Popen:
    """``mocapfix clean src -o out -c cfg -j 2`` started in a process group of its own."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "mocapfix.cli", "clean", str(src), "-o",
                             str(out), "-c", cfg, "-j", "2"], env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, **popen)


def _wait_until_done(out, n: int, proc: subprocess.Popen, seconds: float = 240) -> None:
    """Until ``n`` files of the batch writing ``out`` are finished (or it ended)."""
    deadline = time.monotonic() + seconds
    while len(_done(out)) < n and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)


@pytest.mark.slow
def test_killed_batch_resumes_and_skips_finished_files(tmp_path):
    src, cfg = _inputs(tmp_path), _cfg(tmp_path)
    out = tmp_path / "out"
    proc = _background_batch(src, out, cfg, stderr=subprocess.DEVNULL)
    try:
        _wait_until_done(out, 3, proc)
        os.killpg(proc.pid, signal.SIGKILL)               # the parent and its workers
    finally:
        proc.wait(timeout=30)
    done_at_kill = _done(out)
    total = 12                                            # 3 copies × 4 motion files
    assert 3 <= len(done_at_kill) < total, "the batch finished before it could be killed"
    # atomic outputs: every report under its final name is whole (a SIGKILL may leave a
    # hidden .NAME.XXXXXXXX.part temporary, which the re-run takes away)
    for report in out.rglob("*.report.json"):
        json.loads(report.read_text())

    r = _run(src, "-o", out, "-c", cfg, "-j", "2")
    assert r.exit_code == 0, r.output
    skipped = {line.split()[1].rstrip(":") for line in r.output.splitlines() if line.startswith("SKIP")}
    assert skipped == done_at_kill                        # finished files are not redone ...
    assert f"cleaned {total - len(done_at_kill)} of {total - len(done_at_kill)} files" in r.output
    assert len(_done(out)) == total                       # ... and the rest are
    assert len((out / MANIFEST_NAME).read_text().splitlines()) == total   # compacted
    assert not list(out.rglob("*.part"))                  # no temporary left behind

    fresh = tmp_path / "fresh"
    assert _run(src, "-o", fresh, "-c", cfg).exit_code == 0
    a, b = _outputs(out), _outputs(fresh)
    assert sorted(a) == sorted(b) and len(a) > total
    for rel in a:
        assert a[rel] == b[rel], rel


@pytest.mark.slow
def test_what_a_rerun_redoes(tmp_path):
    src, cfg = _inputs(tmp_path, copies=1), _cfg(tmp_path)
    out = tmp_path / "out"
    assert _run(src, "-o", out, "-c", cfg, "-q").exit_code == 0
    c3d = src / "take0" / "walk_markers.c3d"
    first = _records(out)

    # nothing changed: everything skipped, nothing rewritten
    mtimes = {p: p.stat().st_mtime_ns for p in out.rglob("*.c3d")}
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 0 and r.output.count("finished earlier") == 4 + 1   # 4 lines + summary
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*.c3d")} == mtimes

    # a changed input is not finished: its old output is in the way (exit 2, as before)
    data = bytearray(c3d.read_bytes())
    data[-1] ^= 1
    c3d.write_bytes(bytes(data))
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 2 and "1 output(s) exist already" in r.output and "manifest" in r.output
    # --overwrite redoes everything and records the new input hash
    assert _run(src, "-o", out, "-c", cfg, "--overwrite", "-q").exit_code == 0
    assert _records(out)[str(c3d)]["input_sha256"] != first[str(c3d)]["input_sha256"]

    # another config: not finished either
    other = tmp_path / "other.yaml"
    other.write_text(CFG.replace("0.5 s", "0.25 s"))
    assert _run(src, "-o", out, "-c", other).exit_code == 2

    # an output deleted by hand is redone; the others skipped
    (out / "take0" / "walk.bvh").unlink()
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 0 and "cleaned 1 of 1 files (3 skipped: finished earlier)" in r.output


@pytest.mark.slow
def test_interrupted_output_and_torn_record(tmp_path):
    """A file whose output was written but whose record was not (killed in between) is
    redone without --overwrite; a torn last line of the journal is ignored."""
    src, cfg = _inputs(tmp_path, copies=1), _cfg(tmp_path)
    out = tmp_path / "out"
    assert _run(src, "-o", out, "-c", cfg, "-q").exit_code == 0
    lines = (out / MANIFEST_NAME).read_text().splitlines()
    recs = [json.loads(x) for x in lines]
    victim = next(r for r in recs if r["input"].endswith("walk.bvh"))
    started = {k: v for k, v in victim.items() if k not in ("files", "quality", "input_sha256")}
    started["status"] = "started"
    torn = json.dumps(recs[0])[:40]
    (out / MANIFEST_NAME).write_text("\n".join(lines + [json.dumps(started), torn]))
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 0, r.output
    assert "cleaned 1 of 1 files (3 skipped: finished earlier)" in r.output
    assert _records(out)[victim["input"]]["status"] == "done"


@pytest.mark.slow
def test_failed_file_is_retried(tmp_path):
    src, cfg = _inputs(tmp_path, copies=1), _cfg(tmp_path)
    bad = src / "take0" / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT x\n{\n")
    out = tmp_path / "out"
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 1
    assert _records(out)[str(bad)]["status"] == "failed"
    bad.write_bytes((src / "take0" / "walk.bvh").read_bytes())
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 0 and "cleaned 1 of 1 files (4 skipped: finished earlier)" in r.output


def test_a_rerun_takes_away_the_temporaries_a_killed_run_left(tmp_path):
    """A run killed between writing and renaming leaves ``.NAME.XXXXXXXX.part``; the next
    run that writes NAME removes it, and nothing else: not another file's temporary, not a
    user's file that merely looks alike."""
    src, cfg = _inputs(tmp_path, copies=1), _cfg(tmp_path)
    out = tmp_path / "out"
    (out / "take0").mkdir(parents=True)
    stale = [out / "take0" / ".walk_markers.c3d.k3j_9x2a.part",
             out / "take0" / ".walk_markers.c3d.report.json.abcdefgh.part",
             out / "take0" / ".walker.asf.ikbk1snr.part"]            # the ASF beside an AMC
    kept = [out / "take0" / ".other.c3d.abcdefgh.part",             # not written by this run
            out / "take0" / ".walk_markers.c3d.notes.part",          # not the temporary pattern
            out / "take0" / "walk_markers.c3d.abcdefgh.part"]        # not hidden
    for p in stale + kept:
        p.write_bytes(b"half")
    assert _run(src, "-o", out, "-c", cfg, "-q").exit_code == 0
    assert not any(p.exists() for p in stale)
    assert all(p.exists() for p in kept)


def _subject(tmp_path) -> Path:
    """A folder holding one CMU take and the skeleton it is read with."""
    src = tmp_path / "tr"
    src.mkdir()
    for name in ("asfamc/13.asf", "asfamc/13_39.amc"):
        shutil.copy(shared(name), src)
    return src


def _train_mssa(src: Path, model: Path, *options) -> None:
    r = CliRunner().invoke(main, ["train-dictionary", str(src), "-o", str(model), "--method", "mssa",
                                  *options])
    assert r.exit_code == 0, r.output


@pytest.mark.slow
def test_a_model_retrained_at_the_same_path_is_not_finished(tmp_path):
    # the run key hashed the config text alone, which names the model by path: after
    # retraining the model there a re-run said "SKIP … finished earlier" and kept the
    # output of the old model
    src, model = _subject(tmp_path), tmp_path / "tr_model.npz"
    cfg = tmp_path / "mssa.yaml"
    cfg.write_text(f"version: 1\npipeline:\n  - cleaner: mssa\n    model: {model.name}\n")
    out = tmp_path / "out"
    amc = src / "13_39.amc"
    _train_mssa(src, model)
    assert _run(src, "-o", out, "-c", cfg, "-q").exit_code == 0
    first_output, first = (out / "13_39.amc").read_bytes(), _records(out)[str(amc)]
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 0 and "finished earlier" in r.output, r.output   # same model: skipped

    _train_mssa(src, model, "--window", "24", "--bases", "3")
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 2 and "finished earlier" not in r.output, r.output
    assert "1 output(s) exist already" in r.output and "model" in r.output
    # --skip-existing keeps outputs of this config only, and these are of another model
    r = _run(src, "-o", out, "-c", cfg, "--skip-existing")
    assert r.exit_code == 2 and "two models" in r.output, r.output
    assert (out / "13_39.amc").read_bytes() == first_output
    assert _run(src, "-o", out, "-c", cfg, "--overwrite", "-q").exit_code == 0
    assert (out / "13_39.amc").read_bytes() != first_output
    assert _records(out)[str(amc)]["models_sha256"] != first["models_sha256"]
    assert "finished earlier" in _run(src, "-o", out, "-c", cfg).output


def test_an_edited_skeleton_is_not_finished(tmp_path):
    # an AMC's input hash covered the AMC alone: after the ASF it is read with was edited,
    # a re-run skipped the take as finished, keeping its output and the old ASF beside it
    src, cfg = _subject(tmp_path), _cfg(tmp_path)
    out = tmp_path / "out"
    assert _run(src, "-o", out, "-c", cfg, "-q").exit_code == 0
    assert "finished earlier" in _run(src, "-o", out, "-c", cfg).output
    asf = src / "13.asf"
    text = asf.read_text()
    assert "length 8.12393" in text                        # the left tibia
    asf.write_text(text.replace("length 8.12393", "length 8.5"))
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 2 and "finished earlier" not in r.output, r.output
    assert "1 output(s) exist already" in r.output and "skeleton" in r.output


def test_a_skeleton_edited_while_its_take_is_cleaned_is_not_recorded_as_finished(tmp_path, monkeypatch):
    import mocapfix.cleaning as clean_module

    src, cfg = _subject(tmp_path), _cfg(tmp_path)
    real = clean_module.clean_motion

    def edit_the_skeleton_meanwhile(motion, pipeline, *rest, **options):
        with open(src / "13.asf", "a") as fh:
            fh.write("# edited\n")
        return real(motion, pipeline, *rest, **options)

    monkeypatch.setattr(clean_module, "clean_motion", edit_the_skeleton_meanwhile)
    out = tmp_path / "out"
    r = _run(src, "-o", out, "-c", cfg)
    assert r.exit_code == 1, r.output
    assert "a file read with it changed while it was being cleaned" in r.output
    assert _records(out)[str(src / "13_39.amc")]["status"] == "failed"


@pytest.mark.slow
def test_a_manifest_without_model_and_skeleton_hashes_finishes_nothing(tmp_path):
    # a manifest written before the run key held the models' and the input's companions'
    # hashes cannot tell whether they changed: its files are redone, nothing crashes
    src, model = _subject(tmp_path), tmp_path / "m.npz"
    _train_mssa(src, model)
    cfg = tmp_path / "mssa.yaml"
    cfg.write_text(f"version: 1\npipeline:\n  - cleaner: mssa\n    model: {model}\n")
    out = tmp_path / "out"
    assert _run(src, "-o", out, "-c", cfg, "-q").exit_code == 0
    path = out / MANIFEST_NAME
    old = [{k: v for k, v in json.loads(line).items() if k not in ("models_sha256", "companions_sha256")}
           for line in path.read_text().splitlines()]
    path.write_text("".join(json.dumps(r) + "\n" for r in old))
    r = _run(src, "-o", out, "-c", cfg)
    no_traceback(r)
    assert r.exit_code == 2 and "1 output(s) exist already" in r.output, r.output
    r = _run(src, "-o", out, "-c", cfg, "--skip-existing")     # keeps it, as any output
    no_traceback(r)
    assert r.exit_code == 0 and "output exists" in r.output and "finished earlier" not in r.output
    assert _run(src, "-o", out, "-c", cfg, "-q", "--overwrite").exit_code == 0
    rec = _records(out)[str(src / "13_39.amc")]
    assert rec["models_sha256"] == {str(model): file_sha256(model)}
    assert rec["companions_sha256"] == {str(src / "13.asf"): file_sha256(src / "13.asf")}
    assert "finished earlier" in _run(src, "-o", out, "-c", cfg).output


def test_the_run_key_hashes_every_model_a_step_may_read():
    # a step that names no model picks a shipped one per file: those count too
    ships = models.shipped()
    for step, names in (("cleaner: mssa", ["mssa-cmu"]), ("cleaner: mssa\n    model: self", []),
                        ("cleaner: partlet_dictionary", ["partlet-cmu", "partlet-kinect"]),
                        ("cleaner: mssa\n    model: mssa-cmu\n  - cleaner: mssa", ["mssa-cmu"])):
        pipeline = loads_config(f"version: 1\npipeline:\n  - {step}\n")
        key = run_key(pipeline.dump(), ["json"], None, pipeline.model_files())
        assert key["models_sha256"] == {str(ships[n]): file_sha256(ships[n]) for n in names}, step


def test_a_damaged_manifest_or_config_record_in_the_output_folder(tmp_path):
    # the journal is a text file anyone can edit; a record whose "files" is not a list of
    # names crashed every re-run with a TypeError traceback, a folder in place of the
    # manifest or of the config record with IsADirectoryError (the latter after cleaning)
    import json

    out = tmp_path / "out"
    cfg = config_file(tmp_path)
    assert CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg]).exit_code == 0
    manifest = out / "mocapfix-manifest.jsonl"
    record = json.loads(manifest.read_text().splitlines()[0])
    for damaged in (5, [None], {"a": 1}, "walk.bvh"):
        manifest.write_text(json.dumps({**record, "files": damaged}) + "\n")
        for policy in ([], ["--skip-existing"]):
            r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg, *policy])
            no_traceback(r)
            if policy:             # the existing output is kept, as the option says
                assert r.exit_code == 0 and "output exists" in r.output, r.output
            else:                  # no trustworthy record: an existing output, refused
                assert r.exit_code == 2 and "exist already" in r.output, r.output
    for name in ("mocapfix-manifest.jsonl", "mocapfix-config.yaml"):
        bad = tmp_path / f"bad_{name}"
        (bad / name).mkdir(parents=True)
        r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(bad), "-c", cfg])
        no_traceback(r)
        assert r.exit_code == 2 and name in r.output, r.output
        assert not (bad / "walk.bvh").exists()


def test_an_input_that_changes_while_it_is_cleaned_is_not_recorded_as_finished(tmp_path, monkeypatch):
    # the manifest took the input's sha256 after the clean: a file still being written
    # was recorded with its new content against an output of the old one, and the next
    # run skipped it as "finished earlier", keeping the stale output
    import mocapfix.cleaning as clean_module

    src = tmp_path / "in"
    src.mkdir()
    take = src / "walk.csv"
    take.write_bytes(KIN.read_bytes())
    real = clean_module.clean_motion

    def clean_while_the_file_grows(motion, pipeline, *rest, **options):
        with open(take, "ab") as fh:            # the recorder appends a frame meanwhile
            fh.write(KIN.read_bytes().splitlines(keepends=True)[-1])
        return real(motion, pipeline, *rest, **options)

    monkeypatch.setattr(clean_module, "clean_motion", clean_while_the_file_grows)
    out = tmp_path / "out"
    args = ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path)]
    r = CliRunner().invoke(main, args)
    no_traceback(r)
    assert r.exit_code == 1, r.output
    assert f"ERROR {take}: the file changed while it was being cleaned" in r.output
    assert not (out / "walk.csv").exists()
    monkeypatch.setattr(clean_module, "clean_motion", real)
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0 and "finished earlier" not in r.output, r.output
    assert (out / "walk.csv").is_file()


def test_one_file_found_through_two_given_paths_resumes(tmp_path):
    # `clean in in/sub/x.csv -o out` writes out/sub/x.csv and out/x.csv; the manifest kept
    # one record per input, so the same command run again stopped with exit 2, "1 output(s)
    # exist already … made with another config, report kinds, --fps, version or input"
    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    (src / "sub" / "x.csv").write_bytes(KIN.read_bytes())
    out = tmp_path / "out"
    args = ["clean", str(src), str(src / "sub" / "x.csv"), "-o", str(out), "-c", config_file(tmp_path)]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    assert (out / "sub" / "x.csv").is_file() and (out / "x.csv").is_file()
    r = CliRunner().invoke(main, args)
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert r.output.count("finished earlier") >= 2 and "exist already" not in r.output, r.output


@pytest.mark.parametrize("damage", [
    {"summary": "x"}, {"summary": {"worst": 5}}, {"summary": {"worst": [["a"]]}},
    {"files": [None]}, {"quality": 5}, {"quality": "<script>alert(1)</script>"},
    {"output": None}, {"status": "failed", "error": 5},
])
def test_a_damaged_record_of_another_file_does_not_stop_the_batch_index(tmp_path, damage):
    # with --report html the index lists every record of the folder's manifest: a record
    # (of any file) whose summary, quality, error or files had another type ended the run
    # with "internal error AttributeError/TypeError/ValueError" after its file was
    # cleaned, without the config record; a quality that is markup went into the page
    out = tmp_path / "out"
    cfg = config_file(tmp_path)
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg, "--report", "html"])
    assert r.exit_code == 0, r.output
    manifest = out / MANIFEST_NAME
    record = json.loads(manifest.read_text().splitlines()[0])
    with manifest.open("a") as fh:
        fh.write(json.dumps({**record, "input": str(tmp_path / "other.bvh"), **damage}) + "\n")
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(out), "-c", cfg, "--report", "html"])
    no_traceback(r)
    assert r.exit_code == 0 and "internal error" not in r.output, r.output
    assert (out / "walk_kinect_v2.csv").is_file() and (out / "mocapfix-config.yaml").is_file()
    index = (out / "index.html").read_text(encoding="utf-8")
    assert "walk_kinect_v2.csv" in index and "alert(1)" not in index
    assert "finished earlier" in CliRunner().invoke(
        main, ["clean", str(BVH), "-o", str(out), "-c", cfg, "--report", "html"]).output


@pytest.mark.parametrize("record", ["folder", "fifo", "device", "not_utf8"])
def test_skip_existing_reads_only_a_config_record_that_is_a_file(tmp_path, record):
    # --skip-existing compares the config record of the folder with this run's config: it
    # read whatever was there whole, so a folder was "internal error IsADirectoryError", a
    # FIFO a wait forever, a link to /dev/zero a memory blow-up, bytes that are not UTF-8
    # "internal error UnicodeDecodeError"
    out = tmp_path / "out"
    cfg = config_file(tmp_path)
    assert CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg]).exit_code == 0
    (out / MANIFEST_NAME).unlink()          # no record: the output is "an output that exists"
    path = out / "mocapfix-config.yaml"
    path.unlink()
    if record == "folder":
        path.mkdir()
    elif record == "fifo":
        os.mkfifo(path)
    elif record == "device":               # (/dev/zero: read without end before)
        path.symlink_to("/dev/null")
    else:
        path.write_bytes(b"\xff\xfe version: 1\n")
    output = (out / "walk.bvh").read_bytes()
    with hang_guard(20):
        r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg, "--skip-existing"])
    no_traceback(r)
    assert r.exit_code == 2 and "internal error" not in r.output, r.output
    assert f"{path}: " in r.output and "--skip-existing" in r.output, r.output
    assert (out / "walk.bvh").read_bytes() == output


@pytest.mark.slow
def test_an_interrupted_batch_exits_130_leaves_no_temporary_and_resumes(tmp_path):
    # Ctrl-C (SIGINT to the whole process group) ended the run with click's "Aborted!"
    # and exit 1, which says "some files failed, the others were written"
    src, cfg = _inputs(tmp_path), _cfg(tmp_path)
    out = tmp_path / "out"
    proc = _background_batch(src, out, cfg, stderr=subprocess.PIPE, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        _wait_until_done(out, 2, proc)
        os.killpg(proc.pid, signal.SIGINT)                # as Ctrl-C in a terminal
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
    done = _done(out)
    assert len(done) < 12, "the batch finished before it could be interrupted"
    assert proc.returncode == 130, err
    assert "mocapfix: interrupted" in err and "Traceback" not in err and "Aborted" not in err, err
    assert not list(out.rglob("*.part")) and not (out / ".mocapfix.lock").exists()
    for report in out.rglob("*.report.json"):
        json.loads(report.read_text())
    r = _run(src, "-o", out, "-c", cfg, "-j", "2")
    assert r.exit_code == 0, r.output
    assert len(_done(out)) == 12
