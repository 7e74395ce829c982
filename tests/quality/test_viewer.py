"""The viewer page without a browser (test_viewer_browser.py renders it): what the page
holds decodes back to the motion within half a quantisation step, a before layer stored
as its differences rebuilds exactly, the size budget holds, names cannot end the data's
<script> element, and `mocapfix view` refuses what it cannot show."""
from __future__ import annotations

import base64
import json
import re
from importlib import resources

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA
from mocapfix.cli import main
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.formats import read, write
from mocapfix.quality import viewer


def _data(page: str) -> dict:
    m = re.search(r'<script type="application/json" id="mocapfix-data">(.*?)</script>', page, re.DOTALL)
    return json.loads(m.group(1))


def _codes(entry) -> np.ndarray:
    raw = np.frombuffer(base64.b64decode(entry["positions"]), "<i2")
    return raw.reshape(entry["frames"], len(entry["names"]), 3)


def _metres(entry, codes) -> np.ndarray:
    out = np.asarray(entry["origin"]) + (codes + 32767.0) * np.asarray(entry["step"])
    out[codes[..., 0] == viewer.MISSING] = np.nan
    return out


def _walk(T=4500, J=41, seed=0, gaps=True) -> Motion:
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None] / 120.0
    base = rng.uniform(-300, 300, (1, J, 3)) + np.array([0, 0, 900.0])
    pos = base + 200 * np.sin(2 * np.pi * 0.5 * t + rng.uniform(0, 6, J))[..., None]
    pos[:, :, 0] += 1000 * t                                       # walks 37 m
    if gaps:
        for j in range(0, J, 3):
            s = rng.integers(0, T - 200)
            pos[s:s + rng.integers(10, 200), j] = np.nan
    return Motion(pos, [f"M{j}" for j in range(J)], 120.0,
                  skeleton=Skeleton(np.r_[-1, np.arange(J - 1)]))


def test_positions_decode_within_half_a_step():
    motion = _walk(600, 12)
    data = _data(viewer.single([motion]))
    (entry,) = data["layers"]
    assert data["stride"] == 1 and entry["frames"] == 600
    assert entry["bones"] == [[j - 1, j] for j in range(1, 12)]
    back = _metres(entry, _codes(entry))
    metres = motion.positions * 0.001
    assert np.array_equal(np.isnan(back), np.isnan(metres))
    ok = ~np.isnan(metres)
    err = np.abs(back - metres)[ok].reshape(-1)
    assert err.max() <= max(entry["step"]) / 2 + 1e-9


def test_model_outputs_are_not_drawn():
    motion = _walk(50, 6, gaps=False)
    motion.kinds = ["marker", "marker", "angle", "marker", "force", "marker"]
    (entry,) = _data(viewer.single([motion]))["layers"]
    assert entry["names"] == ["M0", "M1", "M3", "M5"]
    assert entry["bones"] == [[0, 1]]


def _rebuilt(b, a) -> np.ndarray:
    """The before layer's metres from the after layer's codes, as viewer.js rebuilds it."""
    codes = _codes(a).astype(np.int32)
    if "delta" in b:
        codes += np.frombuffer(base64.b64decode(b["delta"]), "i1").reshape(codes.shape)
    index = np.frombuffer(base64.b64decode(b["diffIndex"]), "<u4")
    values = np.frombuffer(base64.b64decode(b["diffValues"]), "<i2").reshape(-1, 3)
    flat = codes.reshape(-1, 3)
    flat[index] = values
    return _metres(b, codes)


@pytest.mark.parametrize("jitter", [0.0, 0.5])
def test_a_before_layer_is_its_differences_and_rebuilds_exactly(jitter):
    before = _walk(900, 20, seed=1)
    after = before.copy()
    gone = np.isnan(after.positions)
    after.positions[gone] = 0.0                                    # "filled"
    after.positions += np.random.default_rng(0).normal(0, jitter, after.positions.shape)
    after.positions[100:110, 3] += 40.0                            # "moved" beyond a delta
    after.fill_errors = {"M0": [[5, 10, 2.5, 6.0, "fill", True, False]]}
    page = viewer.before_after(before, after)
    data = _data(page)
    b, a = data["layers"]
    assert (b["role"], a["role"], b["base"]) == ("before", "after", 1) and "positions" not in b
    assert ("delta" in b) == (jitter > 0)
    assert a["fills"] == [[0, 5, 10, 2.5, 6.0]]
    rebuilt = _rebuilt(b, a)
    assert np.array_equal(np.isnan(rebuilt), np.isnan(before.positions))
    ok = ~np.isnan(before.positions)
    assert np.abs(rebuilt - before.positions * 0.001)[ok].max() <= max(b["step"]) / 2 + 1e-9
    stored = sum(len(b.get(key, "")) for key in ("delta", "diffIndex", "diffValues"))
    assert stored < 0.6 * len(a["positions"])


def test_a_before_and_after_must_match():
    a, b = _walk(100, 5, gaps=False), _walk(101, 5, gaps=False)
    assert not viewer.comparable(a, b)
    with pytest.raises(ValueError):
        viewer.before_after(a, b)


@pytest.mark.parametrize("overlay", [False, True])
def test_a_4500_frame_41_marker_capture_fits_3_mb_whole(overlay):
    before = _walk()
    after = before.copy()
    after.positions[np.isnan(after.positions)] = 1.0
    page = viewer.before_after(before, after) if overlay else viewer.single([before])
    data = _data(page)
    assert data["stride"] == 1, "frames were dropped"
    assert len(page.encode()) <= 3_000_000


def test_a_smaller_budget_keeps_every_kth_frame_and_holds():
    motion = _walk()
    data = _data(viewer.single([motion], budget=500_000))
    assert data["stride"] > 1 and data["bytes"] <= 500_000
    (entry,) = data["layers"]
    assert entry["frames"] == len(range(0, 4500, data["stride"]))
    assert entry["fps"] == pytest.approx(120.0 / data["stride"])


def test_the_runs_judged_wrong_count_in_the_budget():
    # a long take's report lists tens of thousands of flagged runs: they do not shrink with
    # the frame stride, so the frames drawn make room for them (the page of a 150,000-frame
    # take's report was 4.8 MB for a 3 MB budget, 2.3 MB of it flags)
    motion = _walk()
    layer = viewer.Layer(motion, "after: walk", "after")
    layer.flag_kinds = ["step 2 (trust)"]
    layer.flags = [[j % 41, j % 4500, 1, 0] for j in range(150_000)]
    page = viewer.to_html([layer], "walk", 3_000_000)
    data = _data(page)
    assert len(page.encode()) <= 3_000_000
    assert data["stride"] > 1 and len(data["layers"][0]["flags"]) == 150_000


HOSTILE = ["</script><script>alert(1)</script>", "<!--", "a&b", "q\"'`", "line\u2028sep\nnl",
           "{{DATA}}", "x" * 10_000]


def test_names_cannot_end_the_data_element():
    motion = _walk(20, len(HOSTILE), gaps=False)
    motion.names = list(HOSTILE)
    motion.path = "/tmp/{{SCRIPT}}<b>.c3d"
    page = viewer.single([motion])
    assert page.count("</script>") == 2                  # the data's and the viewer's
    assert "<b>" not in page and "\u2028" not in page
    assert "<title>{{SCRIPT}}&lt;b&gt;.c3d — mocapfix view</title>" in page
    assert page.count("window.mocapfixView =") == 1
    assert _data(page)["layers"][0]["names"] == HOSTILE


def test_kinect_tracking_state_is_carried():
    motion = read(SAMPLE_DATA / "walk_kinect_v2.csv")
    motion.confidence[5:9, 2] = 0.5                            # Inferred
    (entry,) = _data(viewer.single([motion]))["layers"]
    level = np.frombuffer(base64.b64decode(entry["confidence"]), "u1").reshape(entry["frames"], -1)
    assert (level[5:9, 2] == 128).all() and level[~np.isnan(motion.positions[..., 0])].min() >= 128
    assert "confidence" not in _data(viewer.single([read(SAMPLE_DATA / "walk.bvh")]))["layers"][0]


def test_the_template_and_script_are_package_data():
    files = resources.files("mocapfix.quality")
    assert "{{DATA}}" in files.joinpath("viewer.html").read_text(encoding="utf-8")
    js = files.joinpath("viewer.js").read_text(encoding="utf-8")
    assert "</script" not in js and "http" not in js


def test_view_writes_a_page(tmp_path):
    out = tmp_path / "v.html"
    r = CliRunner().invoke(main, ["view", str(SAMPLE_DATA / "walk.bvh"), "-o", str(out)])
    assert r.exit_code == 0, r.output
    data = _data(out.read_text(encoding="utf-8"))
    assert data["layers"][0]["label"] == "walk.bvh" and data["up"] == 1


def test_view_of_two_unrelated_files_overlays_them(tmp_path):
    out = tmp_path / "v.html"
    r = CliRunner().invoke(main, ["view", str(SAMPLE_DATA / "walk.bvh"),
                                  str(SAMPLE_DATA / "walk_markers.c3d"), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert [L["role"] for L in _data(out.read_text(encoding="utf-8"))["layers"]] == ["motion"] * 2


@pytest.mark.parametrize("args,message", [
    ([], "nothing to view"),
    (["--before", str(SAMPLE_DATA / "walk.bvh")], "go together"),
    (["--before", str(SAMPLE_DATA / "walk.bvh"), "--after", str(SAMPLE_DATA / "walk_markers.c3d")],
     "differ in frames or point names"),
])
def test_view_usage_errors(tmp_path, args, message):
    r = CliRunner().invoke(main, ["view", *args, "-o", str(tmp_path / "v.html")])
    assert r.exit_code == 2 and message in r.output, r.output


def test_view_of_an_unreadable_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"not a c3d")
    r = CliRunner().invoke(main, ["view", str(bad), "-o", str(tmp_path / "v.html")])
    assert r.exit_code != 0 and "Traceback" not in r.output and r.output.count("\n") == 1, r.output


def test_a_cleaned_c3d_read_back_gives_its_fills_and_their_errors(tmp_path):
    from mocapfix.formats import write
    from mocapfix.formats.c3d import listed_fills

    motion = read(SAMPLE_DATA / "walk_markers.c3d")
    motion.positions[40:52, 3] = np.nan
    write(motion, tmp_path / "gap.c3d")
    r = CliRunner().invoke(main, ["clean", str(tmp_path / "gap.c3d"), "-o", str(tmp_path / "out"), "-q"])
    assert r.exit_code == 0, r.output
    after = read(tmp_path / "out" / "gap.c3d")
    assert not after.missing[40:52, 3].any()
    runs = listed_fills(after)
    assert (motion.names[3], 40, 12) in [r[:3] for r in runs]
    fills = viewer.Layer(after, "after", "after").fills
    assert [f[:3] for f in fills] == [[after.names.index(r[0]), r[1], r[2]] for r in runs]
    assert all(f[3] is None or f[3] >= 0 for f in fills)
    assert viewer.Layer(read(SAMPLE_DATA / "walk_markers.c3d"), "x", "after").fills == []


@pytest.mark.parametrize("config,embedded", [("", True), ("report: {viewer: false}\n", False)])
def test_the_html_report_embeds_the_viewer_unless_told(tmp_path, config, embedded):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("version: 1\npipeline: []\n" + config)
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walk.bvh"), "-o", str(tmp_path / "out"),
                                  "-c", str(cfg), "--report", "html", "-q"])
    assert r.exit_code == 0, r.output
    report = (tmp_path / "out" / "walk.bvh.report.html").read_text(encoding="utf-8")
    assert ('<iframe class="mocapfix-view"' in report) == embedded


def test_report_viewer_must_be_a_boolean(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("version: 1\npipeline: []\nreport: {viewer: 0}\n")
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walk.bvh"), "-o", str(tmp_path / "out"),
                                  "-c", str(cfg)])
    assert r.exit_code == 2 and "viewer must be true or false" in r.output, r.output


def test_a_file_name_that_is_not_utf8_is_viewed(tmp_path):
    name = tmp_path / "take\udcff.bvh"
    name.write_bytes((SAMPLE_DATA / "walk.bvh").read_bytes())
    out = tmp_path / "v.html"
    r = CliRunner().invoke(main, ["view", str(name), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert _data(out.read_text(encoding="utf-8"))["layers"][0]["label"] == "take\ufffd.bvh"


def test_samples_a_step_judged_wrong_are_runs_by_step():
    from mocapfix.cleaning import clean_motion
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config

    motion = read(SAMPLE_DATA / "walk_markers.c3d")
    motion.positions[50, 4] += 300.0
    result = clean_motion(motion, load_config(resolve_config("default")), None)
    data = _data(viewer.before_after(result.original, result.cleaned, records=result.records))
    after = data["layers"][1]
    assert after["flagKinds"], "no step judged the spike wrong"
    hits = [f for f in after["flags"] if f[0] == 4 and f[1] <= 50 < f[1] + f[2]]
    assert hits and all(0 <= f[3] < len(after["flagKinds"]) for f in after["flags"])


def test_fill_estimates_of_any_number_type_or_none_are_carried():
    before = _walk(60, 3, gaps=False)
    after = before.copy()
    after.fill_errors = {"M0": [[1, 2, np.float32(1.5), np.float32(3.0), "fill", True, False]],
                         "M1": [[3, 4, float("nan"), None, "fill", True, False]],
                         "M2": [[5, 6, 1.0, 2.0, "fill", False, False]]}        # left, not written
    data = _data(viewer.before_after(before, after))
    assert data["layers"][1]["fills"] == [[0, 1, 2, 1.5, 3.0], [1, 3, 4, None, None]]


def test_view_of_a_clean_report_colours_what_the_report_viewer_does(tmp_path):
    """The report's JSON carries the runs each step judged wrong: the page of `mocapfix
    view REPORT.json` holds the same flags as the viewer the clean report embeds."""
    from mocapfix.cleaning import clean_motion
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config

    motion = read(SAMPLE_DATA / "walk_markers.c3d")
    motion.positions[50, 4] += 300.0
    motion.positions[200:210, 6] = np.nan
    source = tmp_path / "spike.c3d"
    write(motion.replace(source=None), source)
    r = CliRunner().invoke(main, ["clean", str(source), "-o", str(tmp_path / "out"), "-q",
                                  "--report", "json"])
    assert r.exit_code == 0, r.output
    out = tmp_path / "v.html"
    r = CliRunner().invoke(main, ["view", str(tmp_path / "out" / "spike.c3d.report.json"), "-o", str(out)])
    assert r.exit_code == 0, r.output
    page = _data(out.read_text(encoding="utf-8"))
    assert [L["role"] for L in page["layers"]] == ["before", "after"]
    result = clean_motion(read(source), load_config(resolve_config("default")), None)
    embedded = _data(viewer.before_after(result.original, result.cleaned, records=result.records))
    assert page["layers"][1]["flagKinds"] and page["layers"][1]["flags"]
    for key in ("flags", "flagKinds", "names"):
        assert page["layers"][1][key] == embedded["layers"][1][key], key
    assert page["layers"][1]["fills"], "the cleaned C3D's fills are not coloured"


@pytest.mark.parametrize("gone", ["input", "output"])
def test_view_of_a_report_whose_files_moved_is_one_clear_error(tmp_path, gone):
    source = tmp_path / "walk.bvh"
    source.write_bytes((SAMPLE_DATA / "walk.bvh").read_bytes())
    r = CliRunner().invoke(main, ["clean", str(source), "-o", str(tmp_path / "out"), "-q",
                                  "--report", "json"])
    assert r.exit_code == 0, r.output
    (source if gone == "input" else tmp_path / "out" / "walk.bvh").rename(tmp_path / "moved.bvh")
    r = CliRunner().invoke(main, ["view", str(tmp_path / "out" / "walk.bvh.report.json"),
                                  "-o", str(tmp_path / "v.html")])
    assert r.exit_code == 2 and "Traceback" not in r.output and r.output.count("\n") == 1, r.output
    assert "are gone" in r.output and f"{gone} " in r.output, r.output
    assert not (tmp_path / "v.html").exists()
