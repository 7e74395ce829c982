"""The Python API a notebook uses: clean or check a motion (or a file) in one call, with a
shipped preset, a config file or a :class:`~mocapfix.pipeline.steps.Pipeline`, and
overrides as keyword arguments. The batch commands (``mocapfix clean``/``check``) run the
same code per file; for folders from Python see :func:`mocapfix.batch.clean.clean_batch`.
"""
from __future__ import annotations

from pathlib import Path

from typing import TYPE_CHECKING

from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion

if TYPE_CHECKING:                       # imported when used: `mocapfix --help` stays fast
    from mocapfix.pipeline.steps import Pipeline

__all__ = ["load_config", "clean", "check"]


def load_config(name_or_path) -> Pipeline:
    """A pipeline from a shipped preset name or a YAML file.

    Parameters
    ----------
    name_or_path : str or path-like
        ``"default"``, ``"optical-c3d"``, ``"kinect"``, ``"animation-bvh"`` (``mocapfix
        configs`` lists them), or the path of a config file.

    Examples
    --------
    >>> import mocapfix
    >>> pipeline = mocapfix.load_config("default")
    >>> [step.cleaner.name for step in pipeline.steps][:3]
    ['swaps', 'trust', 'fill_ensemble']
    """
    from mocapfix.config import load_config as load_file
    from mocapfix.core.presets import resolve_config

    return load_file(resolve_config(_given(name_or_path, "config")))


def _given(name_or_path, what: str):
    """``name_or_path``, refused when it is an empty string: ``""`` is the current folder
    as a path, and the error was ": is a folder, not a config file" (the CLI refuses
    ``-c ""`` likewise)."""
    if isinstance(name_or_path, str) and not name_or_path.strip():
        raise ConfigError(f"the {what} is an empty name (an unset variable?); give a preset "
                          "name or a file")
    return name_or_path


def _pipeline(config, overrides: dict) -> Pipeline:
    """``config`` (a preset name, a path, a Pipeline or a config mapping) with
    ``overrides``: top-level config keys (``max_fill_error="30 mm"``, ``exclude=[...]``)
    or, under a cleaner's name, parameters for every step of that cleaner
    (``butterworth={"cutoff": "8 Hz"}``)."""
    from mocapfix.config import _TOP_KEYS, parse_config
    from mocapfix.pipeline.steps import Pipeline

    if isinstance(config, Pipeline):
        pipeline = config
    elif isinstance(config, dict):
        pipeline = parse_config(config, "<config mapping>")
    else:
        pipeline = load_config(config)
    if not overrides:
        return pipeline
    data = pipeline.config()
    names = {step["cleaner"] for step in data["pipeline"]}
    for key, value in overrides.items():
        if key in _TOP_KEYS - {"version", "pipeline"}:
            data[key] = value
        elif key in names:
            if not isinstance(value, dict):
                raise ConfigError(f"override {key}=: give the parameters of cleaner {key!r} "
                                  f"as a mapping, e.g. {key}={{'name': value}}")
            for step in data["pipeline"]:
                if step["cleaner"] == key:
                    step.update(value)
        else:
            raise ConfigError(f"override {key!r} is neither a config key "
                              f"({', '.join(sorted(_TOP_KEYS - {'version', 'pipeline'}))}) nor "
                              f"a cleaner of this pipeline ({', '.join(sorted(names))})")
    return parse_config(data, f"{pipeline.source} with overrides {sorted(overrides)}")


def _motion(motion_or_path, fps: float | None) -> Motion:
    if isinstance(motion_or_path, Motion):
        return motion_or_path
    from mocapfix.batch.discovery import refuse_special_file
    from mocapfix.core.quantity import frame_rate
    from mocapfix.formats import read

    if fps is not None:         # "abc" was the file's fault: "malformed asfamc file (ValueError"
        try:
            fps = frame_rate(fps)
        except ValueError as exc:
            raise ConfigError(f"fps: {exc}") from None
    refuse_special_file(motion_or_path)     # a FIFO waited for a writer forever
    return read(Path(motion_or_path), default_fps=fps)


def clean(motion_or_path, config="default", *, fps: float | None = None,
          **overrides) -> tuple[Motion, dict]:
    """Clean one motion as ``mocapfix clean`` cleans a file, in memory.

    Parameters
    ----------
    motion_or_path : Motion or path-like
        A motion (:func:`mocapfix.read`, :meth:`Motion.from_arrays`) or a file to read.
    config : str, path-like, Pipeline or dict, default "default"
        A shipped preset name, a config file, a parsed pipeline or a config mapping.
    fps : float, optional
        The rate of a file that stores none (AMC), as ``--fps``.
    **overrides
        Top-level config keys (``max_fill_error="30 mm"``, ``exclude=["*Angle*"]``) or,
        under a cleaner's name, a mapping of its parameters (``butterworth={"cutoff":
        "8 Hz"}``). Bare numbers for physical parameters get the YAML rule: read in the
        parameter's default unit, with a warning.

    Returns
    -------
    (Motion, dict)
        The cleaned motion (BVH/AMC: channels written back) and the report
        (``report["file"]["status"]``, per joint ``report["joints"]``; the JSON report's
        schema, ``mocapfix.report/1``).

    Examples
    --------
    >>> import mocapfix
    >>> cleaned, report = mocapfix.clean("sample_data/walk_markers.c3d")
    >>> report["file"]["status"] in ("OK", "WARN", "FAIL")
    True
    >>> cleaned, report = mocapfix.clean("sample_data/walk_markers.c3d", "optical-c3d",
    ...                                  butterworth={"cutoff": "8 Hz"})
    >>> [step["cleaner"] for step in report["steps"]][-1]
    'butterworth'
    """
    from mocapfix.cleaning import clean_motion
    from mocapfix.quality.report import build_report

    pipeline = _pipeline(config, overrides)
    result = clean_motion(_motion(motion_or_path, fps), pipeline)
    return result.cleaned, build_report(result, pipeline.report)


def check(motion_or_path, rules="default", *, fps: float | None = None,
          would_clean=None) -> dict:
    """Judge one motion against quality rules as ``mocapfix check`` judges a file.

    Parameters
    ----------
    motion_or_path : Motion or path-like
    rules : str or path-like, default "default"
        A shipped rule set (``mocapfix configs --rules``) or a rules file.
    fps : float, optional
        The rate of a file that stores none (AMC).
    would_clean : str, path-like or Pipeline, optional
        Also run this pipeline in memory and say what it would fill and leave.

    Returns
    -------
    dict
        ``status`` (OK, WARN, FAIL), ``findings`` (rule, level, message), and the measured
        ``file`` and ``joints``.

    Examples
    --------
    >>> import mocapfix
    >>> result = mocapfix.check("sample_data/walk.bvh")
    >>> result["status"], result["findings"][0]["rule"]
    ('WARN', 'outliers')
    """
    from mocapfix.batch.check import check_motion
    from mocapfix.quality.rules import load_rules, resolve_rules_path

    pipeline = None if would_clean is None else _pipeline(would_clean, {})
    return check_motion(_motion(motion_or_path, fps),
                        load_rules(resolve_rules_path(_given(rules, "rule set"))),
                        pipeline)
