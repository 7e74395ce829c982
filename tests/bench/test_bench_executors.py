"""``mocapfix bench`` over the batch executors (issue 13): -j 2 and a Dask cluster give the
metrics of the sequential run, in its order; a failing method is a row whatever runs it;
the per-(seed, setting) method budget is kept; methods travel as configs, parsed once per
worker process."""
from __future__ import annotations

import json
import os
import pickle
import time

import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA
from mocapfix import bench, formats
from mocapfix.bench import tasks as bench_tasks
from mocapfix.bench.cli import bench as bench_cmd
from mocapfix.config import parse_config

C3D = SAMPLE_DATA / "walk_markers.c3d"
TIMING = {"seconds", "cpu_seconds", "seconds_per_file", "cpu_seconds_per_file"}


def untimed(obj):
    if isinstance(obj, dict):
        return {k: untimed(v) for k, v in obj.items() if k not in TIMING}
    if isinstance(obj, list):
        return [untimed(v) for v in obj]
    return obj


def cleaner(name: str, **params) -> bench.Method:
    return bench.Method(name, "cleaner", parse_config(
        {"version": 1, "pipeline": [{"cleaner": name, **params}]}, f"method {name}"))


def halves():
    """Two labelled halves of the bundled C3D walk (300 frames, 26 markers each)."""
    m = formats.read(C3D)
    return [m.replace(positions=m.positions[a:b], confidence=m.confidence[a:b], source=None,
                      path=f"{C3D}[{a}:{b}]") for a, b in ((0, 300), (300, 600))]


class Raises(bench.Method):
    """Fails on the second half of the walk, and says in which process it ran."""

    def run(self, motion):
        if str(motion.path).endswith("[300:600]"):
            raise RuntimeError(f"kaboom in pid {os.getpid()}")
        return motion.copy(), None


PARENT = os.getpid()


class Dies(bench.Method):
    """Kills its worker process (as the OOM killer would)."""

    def run(self, motion):
        if os.getpid() == PARENT:
            raise RuntimeError("expected to run in a worker process")
        os._exit(3)


class Busy(bench.Method):
    def run(self, motion):
        end = time.process_time() + 0.3           # burn 0.3 s of CPU
        while time.process_time() < end:
            pass
        return motion.copy(), None


@pytest.mark.slow
def test_jobs_2_gives_the_sequential_runs_in_the_same_order():
    methods = [cleaner("gaussian"), cleaner("fill", max_gap=None)]
    kw = dict(seeds=2, settings=["noise", "mixed"])
    one = bench.run(halves(), "occlusion", methods, jobs=1, **kw)
    two = bench.run(halves(), "occlusion", methods, jobs=2, **kw)
    assert len(one.runs) == 2 * 2 * 2 * 2 and "error" not in json.dumps(one.runs)
    assert untimed(one.to_dict(per_file=True)) == untimed(two.to_dict(per_file=True))
    # sequential order: seed, then setting (mixed first: PRIORITY), then file, then method
    keys = [(r["seed"], r["setting"], r["file"].rsplit(".c3d", 1)[1], r["method"]) for r in two.runs]
    assert keys[:4] == [(0, "mixed", "[0:300]", "gaussian"), (0, "mixed", "[0:300]", "fill"),
                        (0, "mixed", "[300:600]", "gaussian"), (0, "mixed", "[300:600]", "fill")]
    assert keys == sorted(keys, key=lambda k: (k[0], k[1] != "mixed", k[2], k[3] != "gaussian"))
    # real numbers: the corruption differs per seed, and fill leaves the noise, gaussian not
    cells = {(r["setting"], r["method"]): r["metrics"]["rmse_mm"] for r in two.summary()}
    assert all(c["std"] > 0 for c in cells.values())
    assert cells[("noise", "gaussian")]["mean"] < cells[("noise", "fill")]["mean"]
    # the tables too, but for the two timing columns
    assert ([line.rsplit("|", 3)[0] for line in one.detail_table().splitlines()]
            == [line.rsplit("|", 3)[0] for line in two.detail_table().splitlines()])


@pytest.mark.slow
def test_cli_jobs_and_dask_scheduler_match_sequential(tmp_path):
    """The CLI options: -j 2 (local worker processes) and --scheduler (a Dask cluster;
    in-process here, as in test_executors, so the test stays fast) give the JSON of -j 1
    but for the timings."""
    import distributed          # a dev dependency: missing it fails, never skips

    base = [str(C3D), "--protocol", "occlusion", "--methods", "gaussian,fill", "--seeds", "2",
            "--settings", "noise", "-q"]
    out = {}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        for name, extra in (("one", []), ("jobs", ["-j", "2"]),
                            ("dask", ["--scheduler", cluster.scheduler_address])):
            r = CliRunner().invoke(bench_cmd, base + extra + ["--json", str(tmp_path / f"{name}.json")])
            assert r.exit_code == 0, r.output
            out[name] = json.loads((tmp_path / f"{name}.json").read_text())
    assert len(out["one"]["runs"]) == 2 * 5          # seeds × (3 baselines + 2 methods)
    assert untimed(out["one"]) == untimed(out["jobs"]) == untimed(out["dask"])
    rmse = {r["method"]: r["metrics"]["rmse_mm"]["mean"] for r in out["dask"]["summary"]}
    assert set(rmse) == {"none", "linear+gaussian", "pca+butterworth", "gaussian", "fill"}
    assert rmse["gaussian"] < rmse["none"] == rmse["fill"]          # fill has no gap to fill


def test_executor_options_are_checked():
    r = CliRunner().invoke(bench_cmd, [str(C3D), "--protocol", "occlusion", "--seeds", "1",
                                       "-j", "2", "--dask-workers", "2"])
    assert r.exit_code == 2 and "-j/--jobs" in r.output


def test_a_method_that_raises_in_a_worker_is_a_row():
    res = bench.run(halves(), "occlusion", [Raises("raises", "cleaner", None), cleaner("gaussian")],
                    seeds=1, settings=["noise"], jobs=2)
    rows = {(r["file"].rsplit(".c3d", 1)[1], r["method"]): r for r in res.runs}
    assert len(rows) == 4
    failed = rows[("[300:600]", "raises")]
    assert failed["error"].startswith("RuntimeError: kaboom in pid ")
    assert int(failed["error"].rsplit(" ", 1)[1]) != os.getpid()   # ran in a worker
    assert "error" not in rows[("[0:300]", "raises")] and "error" not in rows[("[300:600]", "gaussian")]
    row = [r for r in res.summary() if r["method"] == "raises"][0]
    assert row["runs"] == 2 and row["failed"] == 1
    assert "kaboom" in res.to_markdown()


def test_a_killed_worker_gives_error_rows_and_the_bench_ends():
    """More blocks than the pool keeps in flight: the pool breaks at the first kill, and
    every block (in flight or not yet submitted) becomes error rows, not a traceback."""
    m = formats.read(C3D)
    res = bench.run([m], "occlusion", [Dies("dies", "cleaner", None), cleaner("gaussian")],
                    seeds=6, settings=["noise"], jobs=2)
    assert len(res.runs) == 12
    assert all(r["error"].startswith("worker failed: ") for r in res.runs)
    assert "ERR" in res.headline_table()


@pytest.mark.slow
def test_budget_is_checked_per_seed_and_setting_block_with_jobs():
    """Busy uses 0.3 s of CPU per run against a 0.25 s budget: it runs the first block (both
    files, in parallel) and no other; none (a copy) runs all four blocks. As in one process.
    (With a 5 ms budget, none's first run in a fresh worker of a fresh CI install — modules
    compiled on first import — used it up.)"""
    methods = [Busy("busy", "cleaner", None), bench.Method("none", "baseline", None)]
    kw = dict(seeds=2, settings=["noise", "gaps"], method_budget_s=0.25)
    two = bench.run(halves(), "occlusion", methods, jobs=2, **kw)
    one = bench.run(halves(), "occlusion", methods, jobs=1, **kw)
    counts = {}
    for r in two.runs:
        counts.setdefault(r["method"], []).append((r["seed"], r["setting"]))
    assert counts["busy"] == [(0, "noise"), (0, "noise")]          # noise runs before gaps
    assert len(counts["none"]) == 8
    assert any("busy: CPU budget" in n and "ran 2 of 8" in n for n in two.notes)
    assert untimed(one.to_dict()) == untimed(two.to_dict())


def test_methods_pickle_as_configs_and_parse_once_per_process(monkeypatch):
    import mocapfix.config as pl

    methods, _ = bench.resolve_methods(["gaussian", "kalman(tuned)", "svt"],
                                       [str(SAMPLE_DATA.parent / "configs" / "default.yaml")])
    data = pickle.dumps(methods)
    calls = []
    real = pl.parse_config
    monkeypatch.setattr(pl, "parse_config", lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    bench_tasks._METHODS.clear()
    first, again = pickle.loads(data), pickle.loads(data)
    assert [m.describe() for m in first] == [m.describe() for m in methods]
    assert [type(m) for m in first] == [type(m) for m in methods]
    plain = [i for i, m in enumerate(methods) if m.kind != "oracle"]
    assert all(first[i] is again[i] for i in plain)            # cached in this process
    # one parse per pipeline method, not per unpickling ("none" has no pipeline)
    assert sorted(calls) == sorted(str(m.pipeline.source) for m in methods
                                   if m.kind != "oracle" and m.pipeline is not None)
    assert len(data) < 20_000


def test_rotations_protocol_with_jobs():
    amc = formats.read(SAMPLE_DATA / "walker_01.amc")
    methods, _ = bench.resolve_methods(["euler-gaussian"])
    methods = [m for m in methods if m.name in ("none", "euler-gaussian")]
    one = bench.run([amc], "rotations", methods, seeds=2, settings=["spikes"], jobs=1)
    two = bench.run([amc], "rotations", methods, seeds=2, settings=["spikes"], jobs=2)
    assert untimed(one.to_dict()) == untimed(two.to_dict())
    cells = {r["method"]: r["metrics"]["deg_err"] for r in two.summary()}
    assert cells["none"]["mean"] > 0 and cells["none"]["std"] > 0       # two seeds, two spike sets
    assert cells["euler-gaussian"]["mean"] != cells["none"]["mean"]
