"""Hostile configs: wrong types where a list is expected, YAML alias bombs, deep nesting,
bytes that are not UTF-8. Each must be one ConfigError naming the file, quickly and in
little memory — never a TypeError, RecursionError or UnicodeDecodeError traceback. A key
given twice is refused (merge keys still load); a config or rules path that is a folder
says so, and one that is a pipe is read."""
from __future__ import annotations

import os
import threading
import time
import tracemalloc

import pytest
from click.testing import CliRunner

from mocapfix.cli import main
from mocapfix.core.errors import ConfigError
from mocapfix.config import load_config, loads_config
from mocapfix.core.yamlsafe import load_yaml
from conftest import FILL_CONFIG, SAMPLE_DATA, config_file, hang_guard, no_traceback

BVH, KIN = SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_kinect_v2.csv"
GOOD_STEP = "pipeline:\n  - cleaner: butterworth\n"


def _bomb(levels: int = 9, width: int = 10) -> list[str]:
    """The classic 'billion laughs': width**levels leaves from ~levels*width aliases."""
    lines = ["l0: &l0 [" + ", ".join(["lol"] * width) + "]"]
    for i in range(1, levels):
        lines.append(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * width) + "]")
    return lines


def _refused_quickly(text, pattern, source="bad.yaml"):
    loads_config(GOOD_STEP)  # imports done before memory is traced
    tracemalloc.start()
    started = time.perf_counter()
    try:
        with hang_guard(10), pytest.raises(ConfigError, match=pattern) as err:
            loads_config(text, source)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - started < 5
    assert peak < 50e6, f"{peak / 1e6:.0f} MB to refuse a config"
    assert source in str(err.value)
    return str(err.value)


@pytest.mark.parametrize("value", ["5", "{c3d: 1}", "[[c3d]]", "[5]", "true"])
def test_formats_of_the_wrong_type_is_a_config_error(value):
    msg = _refused_quickly(f"pipeline:\n  - cleaner: butterworth\n    formats: {value}\n", "'formats'")
    assert "step 1" in msg


def test_formats_given_as_an_alias_list():
    text = ("pipeline:\n  - cleaner: butterworth\n    formats: &f [c3d]\n"
            "  - cleaner: butterworth\n    formats: [*f]\n")
    assert "step 2" in _refused_quickly(text, "'formats'")
    # an alias to a valid list is fine
    pipe = loads_config("pipeline:\n  - cleaner: butterworth\n    formats: &f [c3d, bvh]\n"
                        "  - cleaner: gaussian\n    formats: *f\n")
    assert pipe.steps[1].formats == ("c3d", "bvh")


def test_parameter_names_must_be_strings():
    _refused_quickly("pipeline:\n  - cleaner: butterworth\n    1: 2\n", "parameter names")
    _refused_quickly("1: x\nfoo: y\n" + GOOD_STEP, "unknown top-level")


def test_alias_bomb_in_a_step_is_refused_fast():
    text = GOOD_STEP + "    cutoff:\n" + "".join(f"      {line}\n" for line in _bomb())
    _refused_quickly(text, "aliases expand to more than")


def test_alias_bomb_under_report_is_refused_fast():
    text = GOOD_STEP + "report:\n" + "".join(f"  {line}\n" for line in _bomb())
    _refused_quickly(text, "aliases expand to more than")


def test_alias_bomb_at_top_level_and_through_merge_keys():
    _refused_quickly("\n".join(_bomb()) + "\n" + GOOD_STEP, "aliases expand")
    merge = ["m0: &m0 {a: 1, b: 2}"] + [f"m{i}: &m{i} {{<<: *m{i - 1}, x{i}: [*m{i - 1}, *m{i - 1}, *m{i - 1}]}}"
                                         for i in range(1, 14)]
    _refused_quickly("\n".join(merge) + "\n" + GOOD_STEP, "aliases expand")


def test_recursive_and_undefined_aliases():
    _refused_quickly("pipeline: &p [{cleaner: butterworth, x: *p}]\n", "recursive")
    _refused_quickly("pipeline: [{cleaner: butterworth, cutoff: *nothing}]\n", "(alias|anchor)")


@pytest.mark.parametrize("depth", [100, 20_000])
def test_deep_nesting_is_a_config_error_not_a_recursion_error(depth):
    flow = GOOD_STEP + "    cutoff: " + "[" * depth + "]" * depth + "\n"
    _refused_quickly(flow, "nested deeper than")
    block = GOOD_STEP + "    cutoff:\n" + "".join("  " * (i + 3) + "-\n" for i in range(min(depth, 300)))
    _refused_quickly(block, "nested deeper than")


def test_nesting_within_the_bound_loads():
    assert load_yaml("x: " + "[" * 60 + "]" * 60, "n.yaml") is not None


def test_non_utf8_bytes_name_the_file_and_offset(tmp_path):
    path = tmp_path / "latin.yaml"
    path.write_bytes(GOOD_STEP.encode() + b"    # caf\xe9 cr\xe8me\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    msg = str(err.value)
    assert str(path) in msg and "UTF-8" in msg and "0xe9" in msg and "line 3" in msg
    path.write_bytes(GOOD_STEP.encode("utf-16"))
    with pytest.raises(ConfigError, match="UTF-16"):
        load_config(path)
    # a UTF-8 byte-order mark is fine
    path.write_bytes(b"\xef\xbb\xbf" + GOOD_STEP.encode())
    assert load_config(path).steps[0].cleaner.name == "butterworth"


def test_oversized_config_is_refused(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_bytes(GOOD_STEP.encode() + b"#" * (2 << 20) + b"\n")
    with pytest.raises(ConfigError, match="more than"):
        load_config(path)


def test_small_aliases_still_work():
    pipe = loads_config("pipeline:\n  - cleaner: butterworth\n    cutoff: &c 8 Hz\n"
                        "  - cleaner: butterworth\n    cutoff: *c\n")
    assert [s.cleaner.hertz("cutoff") for s in pipe.steps] == [8.0, 8.0]


def test_load_yaml_refuses_unsafe_loaders():
    import yaml

    with pytest.raises(TypeError):
        load_yaml("a: 1", loader=yaml.UnsafeLoader)
    with pytest.raises(ConfigError):
        load_yaml("a: !!python/object/apply:os.system ['echo hacked']", "x.yaml")


@pytest.mark.parametrize("name, data", [
    ("bomb.yaml", ("pipeline:\n  - cleaner: butterworth\n    x:\n"
                   + "".join(f"      {line}\n" for line in _bomb())).encode()),
    ("deep.yaml", b"pipeline: [{cleaner: butterworth, x: " + b"[" * 20000 + b"]" * 20000 + b"}]\n"),
    ("latin1.yaml", b"pipeline: [{cleaner: butterworth}]\n# caf\xe9\n"),
    ("formats.yaml", b"pipeline: [{cleaner: butterworth, formats: 5}]\n"),
])
def test_cli_reports_a_bad_config_in_one_line_with_exit_2(tmp_path, name, data):
    from click.testing import CliRunner

    from mocapfix.cli import main
    from conftest import SAMPLE_DATA

    config = tmp_path / name
    config.write_bytes(data)
    with hang_guard(20):
        result = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walk.bvh"), "-o",
                                           str(tmp_path / "out"), "-c", str(config)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and str(config) in result.output
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").rglob("*.bvh"))


def test_a_key_given_twice_in_a_config_or_rules_file_is_refused(tmp_path):
    # YAML keeps the last of two equal keys without a word: "max_gap: 5 s" after
    # "max_gap: 0.5 s" ran with five seconds, a second "pipeline:" replaced the first
    twice = FILL_CONFIG + "    max_gap: 5 s\n"
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(tmp_path / "out"),
                                  "-c", config_file(tmp_path, twice, "twice.yaml")])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert "twice.yaml (line 5): key 'max_gap' appears twice" in r.output and "line 4" in r.output
    assert not (tmp_path / "out").exists()
    two_pipelines = "version: 1\npipeline: []\npipeline:\n  - cleaner: fill\n"
    r = CliRunner().invoke(main, ["check", str(BVH), "--would-clean",
                                  config_file(tmp_path, two_pipelines, "two.yaml")])
    assert r.exit_code == 2 and "key 'pipeline' appears twice" in r.output, r.output
    rules = "version: 1\nrules:\n  - metric: missing\n    warn: 5 %\n    warn: 50 %\n"
    r = CliRunner().invoke(main, ["check", str(BVH), "-r", config_file(tmp_path, rules, "rules.yaml")])
    assert r.exit_code == 2 and "rules.yaml (line 5): key 'warn' appears twice" in r.output, r.output


def test_merge_keys_and_equal_keys_in_different_mappings_still_load():
    from mocapfix.config import loads_config

    text = ("version: 1\npipeline:\n  - &f {cleaner: fill, max_gap: 0.5 s}\n"
            "  - <<: *f\n    max_gap: 0.2 s\n  - cleaner: butterworth\n    cutoff: 6 Hz\n")
    pipeline = loads_config(text)
    steps = pipeline.config()["pipeline"]
    assert [s["cleaner"] for s in steps] == ["fill", "fill", "butterworth"]
    assert [s.get("max_gap") for s in steps[:2]] == ["0.5 s", "0.2 s"]


def test_config_or_rules_path_that_is_a_folder_says_so(tmp_path):
    # a folder given to -c / -r / --would-clean was "no such config file or preset"
    folder = tmp_path / "my.yaml"
    folder.mkdir()
    for args, what in ((["clean", str(KIN), "-o", str(tmp_path / "out"), "-c", str(folder)], "config"),
                       (["check", str(KIN), "--would-clean", str(folder)], "config"),
                       (["check", str(KIN), "-r", str(folder)], "rules")):
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        assert r.exit_code == 2, (args, r.output)
        assert f"{folder}: is a folder, not a {what} file" in r.output, (args, r.output)
    assert not (tmp_path / "out").exists()


def _release_writer(fifo):
    """Let a thread blocked opening ``fifo`` to write go on and drain what it writes,
    never blocking here (with no writer left the read ends at once, on EOF)."""
    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    os.set_blocking(fd, True)
    with os.fdopen(fd, "rb") as fh:
        fh.read()


def test_config_from_a_pipe_is_read(tmp_path):
    # `-c <(…)` (a pipe, not a regular file) was "no such config file or preset"
    fifo = tmp_path / "cfg.pipe"
    os.mkfifo(fifo)
    text = b"version: 1\npipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n"
    writer = threading.Thread(target=lambda: fifo.write_bytes(text), daemon=True)
    writer.start()
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(tmp_path / "out"), "-c", str(fifo)])
    if writer.is_alive():           # without the fix nobody opens the pipe to read
        _release_writer(fifo)
    writer.join(10)
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert "max_gap: 0.5 s" in (tmp_path / "out" / "mocapfix-config.yaml").read_text()
