"""``mocapfix bench``: corrupt clean captures in controlled, seeded ways, run cleaners or
whole pipelines on them, and measure the error against the clean capture.

How a run goes (one clean file, one protocol setting, one seed):

1. ``truth`` = the file's positions as read (for ASF/AMC and BVH: the forward-kinematics
   joint positions of the stored rotations), less its unlabelled trajectories
   (:mod:`mocapfix.pipeline.unlabelled`: HDM05's ``*0``-``*2``; no pipeline cleans them by default,
   a note names them).
2. The truth is corrupted by :func:`mocapfix.bench.corrupt.apply_protocol` (seed → the same
   corruption for every method: comparisons are paired).
3. The corrupted positions are handed to every method in a Motion that is the file's
   Motion with the corrupted positions and **without** ``rig`` and ``channels``: the
   cleaners see exactly what a pipeline sees (positions, fps, units, names, skeleton
   topology, format), but no rotation channels — those are the uncorrupted truth, and the
   rotation write-back of ``mocapfix clean`` (which would re-impose the file's bone lengths)
   is not part of the measured method. What is measured is the pipeline's position output.
4. Metrics per protocol (units as the papers report them; converted with
   ``motion.metres_per_unit``):

   ========== ======================================================================
   feng2015   ``rmse_cm``: RMSE per marker (Feng 2015 eq. 19) over all samples, cm
   yang2019   ``aje_m`` (mean joint error) and ``abe_m`` (mean |bone-length error|,
              bones of the skeleton; only for files with a skeleton), m (Yang 2019 §IV)
   feng2014   ``rmse_corrupted_cm``: RMSE over the corrupted (missing or noisy) samples
              (Feng 2014 eq. 27), and ``rmse_cm`` over all samples, cm
   occlusion  ``rmse_mm`` overall, ``rmse_corrupted_mm`` on corrupted samples, ``max_mm``
   ========== ======================================================================

   Every protocol also reports ``unfilled_pct``: samples present in the truth but missing
   in the method's output, in % of all samples. Error metrics are computed over the
   samples the method did output and are **never** to be read without ``unfilled_pct``
   (an unfilled gap is not an error of 0). RMSE is the root of the mean squared
   Euclidean error per sample (per marker), not per coordinate.
5. Per (setting, method): each metric is averaged over the files of one seed, then the
   mean ± sample standard deviation (ddof = 1; 0 with one seed) over seeds is reported, with
   the mean cleaning time per file, CPU (``time.process_time``: not inflated by other
   processes) and wall clock (the corruption and the metrics are not timed).

A *method* is a registered cleaner run alone with its defaults, a baseline pipeline
(:data:`BASELINES`, always included), a YAML config (``--configs``) or, when named with
``--methods``, an oracle-tuned baseline (``gaussian(tuned)``, ``wavelet(tuned)``,
``kalman(tuned)``: best grid value per run by the error against the truth, as Feng 2015
tuned its baselines; :mod:`mocapfix.bench.oracle`; the chosen value is in each run's
``tuned``). A method that raises is recorded with its error message, and the bench goes on.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapfix.bench import corrupt
from mocapfix.bench import harm as bench_harm
from mocapfix.bench.tasks import method_in_worker, run_blocks
from mocapfix.core.errors import ConfigError, MocapfixError, UnreadableFileError, name_the_file
from mocapfix.batch.executors import ExecutorSpec
from mocapfix.core.motion import Motion
from mocapfix.pipeline.steps import Pipeline
from mocapfix.config import load_config, parse_config
from mocapfix.pipeline.selection import without_unlabelled

#: baseline pipelines, always benchmarked: name → config dict (``none`` runs nothing).
BASELINES: dict[str, dict | None] = {
    "none": None,
    "linear+gaussian": {"version": 1, "pipeline": [
        # every interior gap filled, as the everyday baseline does (no max_gap)
        {"cleaner": "fill", "method": "linear", "max_gap": None}, {"cleaner": "gaussian"}]},
    "pca+butterworth": {"version": 1, "pipeline": [
        {"cleaner": "fill_pca"}, {"cleaner": "butterworth", "cutoff": "6 Hz"}]},
}

#: further named pipelines, run when asked for with ``--methods`` (issue 6's comparison:
#: interpolation, PCA fill, plain low-rank completion, TSMC as in the paper and as shipped).
NAMED: dict[str, dict] = {
    "linear": {"version": 1, "pipeline": [
        {"cleaner": "fill", "method": "linear", "max_gap": None}]},
    "spline": {"version": 1, "pipeline": [
        {"cleaner": "fill", "method": "spline", "max_gap": None}]},
    # nuclear-norm completion of the centred channels alone: no smoothness term, no sparse
    # errors to speak of, no prior, no bridging, global frame (the paper's SVT baseline),
    # solved to a tight tolerance (a baseline gets its best shot)
    "svt": {"version": 1, "pipeline": [
        {"cleaner": "tsmc", "prior": "none", "beta": 0.0, "alpha": 1e6, "frame": "global",
         "bridge": None, "observed": "keep", "tol": 1e-5, "max_iter": 2000}]},
    "trust+tsmc(paper)": {"version": 1, "pipeline": [
        {"cleaner": "trust"}, {"cleaner": "tsmc", "prior": "none"}]},
    "trust+tsmc": {"version": 1, "pipeline": [{"cleaner": "trust"}, {"cleaner": "tsmc"}]},
    # issue 16's peer: model averaging of five fillers with soft distance constraints
    # (Tits et al. 2018, our implementation; fills gaps only, no denoising)
    "pma": {"version": 1, "pipeline": [{"cleaner": "pma"}]},
    # the animator's filters on Euler curves (rotations protocol; σ and width chosen as the
    # best of a sweep on the shared BVH/AMC files, benchmarks/RESULTS.md)
    "euler-gaussian": {"version": 1, "pipeline": [{"cleaner": "euler_smooth", "sigma": "2 frames"}]},
    "euler-median+gaussian": {"version": 1, "pipeline": [
        {"cleaner": "euler_smooth", "median": 5, "sigma": "1 frames"}]},
}

#: per protocol: (metric key, header, decimals); the first one is the headline metric.
METRICS: dict[str, list[tuple[str, str, int]]] = {
    "feng2015": [("rmse_cm", "RMSE cm", 2)],
    "yang2019": [("aje_m", "AJE m", 4), ("abe_m", "ABE m", 4)],
    "feng2014": [("rmse_corrupted_cm", "RMSE corrupted cm", 2), ("rmse_cm", "RMSE all cm", 2)],
    "occlusion": [("rmse_mm", "RMSE mm", 2), ("rmse_corrupted_mm", "RMSE corrupted mm", 2),
                  ("max_mm", "max mm", 1)],
    "rotations": [("pos_err_pct", "joint error % height", 3), ("pos_err_mm", "joint error mm", 2),
                  ("deg_err", "deg/channel", 3), ("writeback_mm", "write-back max mm", 2)],
    "harm": bench_harm.METRICS,
}
_UNFILLED = ("unfilled_pct", "unfilled %", 1)

#: settings run first within a seed (they matter most when a time budget cuts a method
#: short): the ones the papers single out (Feng 2015 Table IV) and the realistic mixes.
PRIORITY = {
    "feng2015": ["snr20+out10", "snr10", "out20", "snr30", "out5"],
    "yang2019": ["10%", "20%"],
    "feng2014": ["mixed"],
    "occlusion": ["mixed"],
    "rotations": ["mixed"],
}

PROTOCOL_NOTES = {
    "feng2015": "Feng et al. 2015 (IEEE THMS, partlet denoising) §V-A: Gaussian noise at an SNR "
                "(uncentred signal power mean(x²) of the positions in the file's frame, one σ "
                "for the whole motion, every coordinate: MATLAB awgn 'measured'; calibrated "
                "against the paper's tuned baselines, benchmarks/feng2015_calibration.py), "
                "outliers on 5–30 % of samples (U(−50, 50) cm per coordinate; size unspecified "
                "in the paper, calibrated the same way), and mixed (noise, then outliers). "
                "RMSE cm per marker (eq. 19). The paper's baselines are oracle-tuned: compare them with gaussian(tuned), "
                "wavelet(tuned), kalman(tuned).",
    "yang2019": "Yang et al. 2019 (IEEE TIP) §IV-A: a fraction of the joint samples gets "
                "U(−25, 25) cm noise on each coordinate. AJE and ABE in m.",
    "feng2014": "Feng et al. 2014 (TSMC) §4: 40 % samples missing at random; regular gaps "
                "(60-frame windows, 10 markers missing per incomplete frame, ~30 %); Gaussian "
                "σ = 2 ASF units (11.29 cm) per coordinate on 30 % of samples; mixed (30 % "
                "missing, then the noise on 30 % of the rest). RMSE on corrupted samples, cm "
                "(eq. 27, per marker).",
    "occlusion": "Realistic optical capture: gaps of 0.1–1.5 s on a quarter of the markers; "
                 "2 mm jitter with 2 % spikes of 20–100 mm; both; one marker swap. mm.",
    "rotations": "Rotation channels of BVH/AMC (mocapfix.bench.rotations): clean; 0.7° jitter on "
                 "every rotation channel; ±10–40° spikes on one axis of a random joint for 1–3 "
                 "frames from 2 % of the frames; mixed. Scored on what `mocapfix clean` writes "
                 "(after write-back): joint error in % of skeleton height and mm, mean degrees "
                 "per rotation channel, write-back residual.",
    "harm": "Nothing injected (mocapfix.bench.harm): each method on the file as read, scored by "
            "what `mocapfix clean` would change — displacement of the samples seen (RMS, 99.9th "
            "percentile, max, share moved > 5 mm), samples judged wrong, jitter out/in, samples "
            "lost and samples written that were missing (by run length), and every change over "
            "10 mm as a case with the take's evidence for it.",
}


@dataclass
class Method:
    """A named way of cleaning: ``pipeline`` None means no cleaning."""

    name: str
    kind: str  # "baseline" | "cleaner" | "config"
    pipeline: Pipeline | None

    def run(self, motion: Motion) -> tuple[Motion, str | None]:
        """The cleaned motion, and why the method did nothing if every step said it skipped
        (e.g. a rotation-channel cleaner given positions only)."""
        if self.pipeline is None:
            return motion.copy(), None
        out, records = self.pipeline.run(motion)
        reasons = [r.skipped or (r.info or {}).get("skipped") for r in records]
        noop = "; ".join(map(str, reasons)) if records and all(reasons) else None
        return out, noop

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind,
                "config": None if self.pipeline is None else self.pipeline.config()}

    def __reduce__(self):
        """Pickled as its config (small; no loaded model travels), parsed once per worker
        process (:func:`mocapfix.bench.tasks.method_in_worker`)."""
        pipe = self.pipeline
        return (method_in_worker, (type(self), self.name, self.kind,
                                   None if pipe is None else pipe.config(),
                                   None if pipe is None else pipe.source))


def _every_fill(config: dict) -> dict:
    """A baseline's or a single cleaner's config with every fill written
    (``max_fill_error: null``): they are the methods as published, the references the
    configs are measured against; a config (``--configs``) keeps its own gate."""
    return {"max_fill_error": None, **config}


def resolve_methods(names=None, configs=None) -> tuple[list[Method], list[str]]:
    """The baselines, then the named cleaners / baselines (default: every registered
    cleaner when neither ``names`` nor ``configs`` is given), then the configs.

    Returns (methods, notes): a baseline whose cleaners are not registered yet is skipped
    with a note; an unknown name or a bad config raises :class:`ConfigError`."""
    from mocapfix.bench.oracle import TUNED, tuned_method
    from mocapfix.cleaners import registry

    reg = registry()
    notes: list[str] = []
    methods: list[Method] = []
    for name, cfg in BASELINES.items():
        missing = [] if cfg is None else [s["cleaner"] for s in cfg["pipeline"] if s["cleaner"] not in reg]
        if missing:
            notes.append(f"baseline {name!r} skipped: cleaner(s) {', '.join(missing)} not registered")
            continue
        methods.append(Method(name, "baseline", None if cfg is None
                              else parse_config(_every_fill(cfg), f"baseline {name}")))
    if names is None and not configs:
        names = list(reg)
    for name in names or []:
        if name in BASELINES:
            continue
        if name in NAMED:
            methods.append(Method(name, "baseline", parse_config(_every_fill(NAMED[name]),
                                                                 f"method {name}")))
            continue
        if name in TUNED:
            methods.append(tuned_method(name))
            continue
        if name not in reg:
            raise ConfigError(f"unknown method {name!r}: not a registered cleaner "
                              f"({', '.join(reg)}), a baseline ({', '.join(BASELINES)}), a "
                              f"named pipeline ({', '.join(NAMED)}) nor an oracle-tuned "
                              f"baseline ({', '.join(TUNED)})")
        methods.append(Method(name, "cleaner", parse_config(
            _every_fill({"version": 1, "pipeline": [{"cleaner": name}]}), f"method {name}")))
    for path in configs or []:
        stem = Path(path).name.rsplit(".", 1)[0]
        methods.append(Method(f"config:{stem}", "config", load_config(path)))
    seen = set()
    for m in methods:
        if m.name in seen:
            raise ConfigError(f"method {m.name!r} given twice")
        seen.add(m.name)
    return methods, notes


@dataclass
class BenchResult:
    protocol: str
    files: list[str]
    seeds: list[int]
    settings: list[str]
    methods: list[dict]
    notes: list[str] = field(default_factory=list)
    runs: list[dict] = field(default_factory=list)

    # -- aggregation -------------------------------------------------------------------
    def summary(self, per_file: bool = False) -> list[dict]:
        """One row per (setting, method) — per (file, setting, method) when ``per_file`` —
        with mean ± std over seeds of each metric (files averaged within a seed first),
        seconds per file, and the errors if a method failed."""
        keys = [k for k, _, _ in METRICS[self.protocol]] + [_UNFILLED[0]]
        groups: dict[tuple, list[dict]] = {}
        for r in self.runs:
            gkey = ((r["file"],) if per_file else ()) + (r["setting"], r["method"])
            groups.setdefault(gkey, []).append(r)
        rows = []
        for gkey, runs in groups.items():
            row = {"setting": gkey[-2], "method": gkey[-1]}
            if per_file:
                row["file"] = gkey[0]
            ok = [r for r in runs if "error" not in r]
            errors = sorted({r["error"] for r in runs if "error" in r})
            if errors:
                row["errors"] = errors
            skipped = sorted({r["skipped"] for r in ok if "skipped" in r})
            if skipped:
                row["skipped"] = skipped
            row["runs"], row["failed"] = len(runs), len(runs) - len(ok)
            row["seconds_per_file"] = float(np.mean([r["seconds"] for r in ok])) if ok else None
            row["cpu_seconds_per_file"] = (float(np.mean([r["cpu_seconds"] for r in ok]))
                                           if ok else None)
            row["metrics"] = {}
            for k in keys:
                by_seed: dict[int, list[float]] = {}
                for r in ok:
                    v = r["metrics"].get(k)
                    if v is not None and math.isfinite(v):
                        by_seed.setdefault(r["seed"], []).append(v)
                if not by_seed:
                    continue
                per_seed = np.array([np.mean(v) for v in by_seed.values()])
                std = float(np.std(per_seed, ddof=1)) if len(per_seed) > 1 else 0.0
                row["metrics"][k] = {"mean": float(per_seed.mean()), "std": std, "seeds": len(per_seed)}
            rows.append(row)
        method_order = {m["name"]: i for i, m in enumerate(self.methods)}
        setting_order = {s: i for i, s in enumerate(self.settings)}
        rows.sort(key=lambda r: (r.get("file", ""), setting_order.get(r["setting"], 0),
                                 method_order.get(r["method"], 0)))
        return rows

    def to_dict(self, per_file: bool = False) -> dict:
        return {"protocol": self.protocol, "protocol_notes": PROTOCOL_NOTES[self.protocol],
                "files": self.files, "seeds": self.seeds, "settings": self.settings,
                "methods": self.methods, "notes": self.notes,
                "summary": self.summary(per_file=False),
                **({"summary_per_file": self.summary(per_file=True)} if per_file else {}),
                "runs": self.runs}

    def to_json(self, per_file: bool = False) -> str:
        return json.dumps(self.to_dict(per_file), indent=1, allow_nan=False, default=_json_default)

    # -- tables ------------------------------------------------------------------------
    def headline_table(self, rows: list[dict] | None = None) -> str:
        """Methods × settings, headline metric mean ± std; ``(u %)`` marks unfilled output."""
        rows = self.summary() if rows is None else rows
        key, header, dec = METRICS[self.protocol][0]
        methods = list(dict.fromkeys(r["method"] for r in rows))
        cell = {(r["setting"], r["method"]): r for r in rows}
        lines = [f"| method \\ {header} | " + " | ".join(self.settings) + " | CPU s/file |",
                 "|---" * (len(self.settings) + 2) + "|"]
        for m in methods:
            cells, secs = [], []
            for s in self.settings:
                r = cell.get((s, m))
                cells.append(_cell(r, key, dec, flag_unfilled=True, n_seeds=len(self.seeds)))
                if r and r["cpu_seconds_per_file"] is not None:
                    secs.append(r["cpu_seconds_per_file"])
            lines.append(f"| {m} | " + " | ".join(cells) + f" | {np.mean(secs):.3f} |" if secs
                         else f"| {m} | " + " | ".join(cells) + " | – |")
        return "\n".join(lines)

    def detail_table(self, rows: list[dict] | None = None) -> str:
        rows = self.summary() if rows is None else rows
        cols = METRICS[self.protocol] + [_UNFILLED]
        per_file = any("file" in r for r in rows)
        head = (["file"] if per_file else []) + ["setting", "method"] + [h for _, h, _ in cols] + ["CPU s/file", "wall s/file"]
        lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
        for r in rows:
            vals = ([Path(r["file"]).name] if per_file else []) + [r["setting"], r["method"]]
            vals += [_cell(r, k, d, n_seeds=len(self.seeds)) for k, _, d in cols]
            vals.append("–" if r["cpu_seconds_per_file"] is None else f"{r['cpu_seconds_per_file']:.3f}")
            vals.append("–" if r["seconds_per_file"] is None else f"{r['seconds_per_file']:.3f}")
            lines.append("| " + " | ".join(vals) + " |")
        return "\n".join(lines)

    def to_markdown(self, per_file: bool = False) -> str:
        if self.protocol == "harm":           # per file always: a mean hides the damage
            return bench_harm.to_markdown(self)
        key = METRICS[self.protocol][0][1]
        parts = [f"## `{self.protocol}`", "", PROTOCOL_NOTES[self.protocol], "",
                 f"Files: {', '.join(Path(f).name for f in self.files)}; seeds: "
                 f"{', '.join(map(str, self.seeds))}. Cells: mean ± std over seeds; "
                 f"`(u %)` = that % of the samples left unfilled (the error is over the "
                 f"filled ones only); `ERR` = the method failed.", ""]
        if self.notes:
            parts += [f"- note: {n}" for n in self.notes] + [""]
        parts += [f"### {key} (headline)", "", self.headline_table(), "",
                  "### All metrics", "", self.detail_table(), ""]
        if per_file:
            parts += ["### Per file", "", self.detail_table(self.summary(per_file=True)), ""]
        summary = self.summary()
        skipped = sorted({(r["method"], e) for r in summary for e in r.get("skipped", [])})
        if skipped:
            parts += ["Methods that did nothing on these inputs (their rows equal `none`):", ""]
            parts += [f"- {m}: {e}" for m, e in skipped] + [""]
        errors = sorted({(r["method"], e) for r in summary for e in r.get("errors", [])})
        if errors:
            parts += ["### Failures", ""] + [f"- {m}: {e}" for m, e in errors] + [""]
        return "\n".join(parts)


def _cell(row, key, dec, flag_unfilled=False, n_seeds=None) -> str:
    if row is None:
        return "–"
    if row["failed"] == row["runs"]:
        return "ERR"
    st = row["metrics"].get(key)
    if st is None:
        text = "n/a"
    else:
        text = f"{st['mean']:.{dec}f} ± {st['std']:.{dec}f}"
        if n_seeds is not None and st["seeds"] < n_seeds:
            text += f" [{st['seeds']}/{n_seeds} seeds]"
    if flag_unfilled:
        u = row["metrics"].get("unfilled_pct", {}).get("mean", 0.0)
        if u >= 0.05:
            text += f" ({u:.1f} %)"
    if row["failed"]:
        text += f" [{row['failed']} ERR]"
    return text


def _json_default(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(type(obj))


def read_files(files, read_options: dict | None = None, unread: list | None = None,
               take=None) -> list[tuple[str, Motion]]:
    """``(label, motion)`` of each of ``files``: a path read by :func:`mocapfix.formats.read`
    with ``read_options`` (labelled by the path as given), or a Motion. A file that cannot
    be read (malformed, truncated, a folder, a FIFO or device) raises the
    :class:`UnreadableFileError` naming it; with an ``unread`` list it is appended there
    instead, as ``{"path", "error"}`` (the message), and left out.

    ``take(label, motion)``: the motion the benchmark uses, or a ValueError saying why the
    protocol cannot use it (too short, no rotation channels, no sample): such a file is
    refused as one that cannot be read, ``<file>: <why>`` (a :class:`MocapfixError`)."""
    from mocapfix import formats
    from mocapfix.batch.discovery import refuse_special_file

    out = []
    for f in files:
        label = (f.path or "<motion>") if isinstance(f, Motion) else str(f)
        try:
            if isinstance(f, Motion):
                motion = f
            else:
                refuse_special_file(f)          # reading a FIFO waited for a writer forever
                motion = formats.read(f, **(read_options or {}))
        except UnreadableFileError as exc:
            refused = exc
        else:
            try:
                out.append((label, take(label, motion) if take else motion))
                continue
            except ValueError as exc:           # read, but the protocol cannot use it
                refused = MocapfixError(name_the_file(label, exc))
        if unread is None:
            raise refused
        unread.append({"path": label, "error": str(refused)})
    return out


def left_out(unread: list) -> list[str]:
    """The notes naming the files :func:`read_files` left out, and why."""
    return [f"{u['error']} (left out of the benchmark)" for u in unread]


def run(files, protocol: str, methods: list[Method], seeds: int | list[int] = 3,
        settings: list[str] | None = None, notes: list[str] | None = None,
        progress=None, read_options: dict | None = None,
        method_budget_s: float | None = None, jobs: int = 1, spec=None,
        unread: list | None = None) -> BenchResult:
    """Benchmark ``methods`` on ``files`` (paths or Motions) under ``protocol``.

    ``seeds``: a count (seeds 0 … N−1) or a list of seeds. ``settings``: a subset of the
    protocol's settings (default all, in the protocol's order). ``progress(message)`` is
    called once per corrupted motion. Loops run seed by seed, and within a seed setting
    by setting (most informative first, :data:`PRIORITY`) over every file, so that with
    ``method_budget_s`` — a method that has used that many seconds of cleaning is not
    started on the next (seed, setting) block — a slow method still gets whole blocks:
    its cells average fewer seeds (the JSON counts them, the Markdown marks them), or are
    empty for the settings it never reached.

    Where: ``spec`` (:class:`mocapfix.batch.executors.ExecutorSpec`: local processes or Dask),
    else ``jobs`` local processes, one task per (seed, setting, file) block
    (:mod:`mocapfix.bench.tasks`); the runs come back in the order above whatever ran
    them, so only the timing fields depend on the executor.

    ``unread``: an empty list that takes the files that cannot be read, or that the
    protocol cannot use (:func:`read_files`, :func:`mocapfix.bench.corrupt.refusal`; without
    it such a file raises); they are left out, each named in a note, and with none left the
    result holds no run."""
    if protocol not in corrupt.PROTOCOLS:
        raise ConfigError(f"unknown protocol {protocol!r} (known: {', '.join(corrupt.PROTOCOLS)})")
    all_settings = list(corrupt.PROTOCOLS[protocol])
    settings = all_settings if settings is None else list(settings)
    bad = [s for s in settings if s not in all_settings]
    if bad:
        raise ConfigError(f"unknown {protocol} setting(s) {', '.join(bad)} (known: {', '.join(all_settings)})")
    seed_list = list(range(seeds)) if isinstance(seeds, int) else list(seeds)
    if not seed_list:
        raise ConfigError("at least one seed is needed")
    if protocol == "harm":
        if len(seed_list) > 1:       # nothing random: every seed would be the same run
            notes = [*(notes or []), "harm injects nothing: one run per file (seeds ignored)"]
            seed_list = seed_list[:1]
        oracles = [m.name for m in methods if m.kind == "oracle"]
        if oracles:
            raise ConfigError(f"{', '.join(oracles)}: an oracle-tuned method has no truth to "
                              "tune on in the harm protocol")
    result = BenchResult(protocol, [], seed_list, settings, [m.describe() for m in methods],
                         list(notes or []))
    unlabelled = []

    def take(label, motion):        # the truth of a file, or why the protocol cannot use it
        motion, dropped = without_unlabelled(motion)
        if np.isnan(motion.positions).all():
            raise ValueError("no sample present, nothing to benchmark")
        for s in settings:
            why = corrupt.refusal(motion, protocol, s)
            if why:
                raise ValueError(f"{protocol}/{s}: {why}")
        if dropped:
            unlabelled.append(f"{label}: {len(dropped)} unlabelled trajectories left out of "
                              f"the truth ({', '.join(dropped[:8])}"
                              f"{', …' if len(dropped) > 8 else ''}): no pipeline cleans them "
                              "by default")
        return motion

    motions = read_files(files, read_options, unread, take)
    result.notes += left_out(unread or []) + unlabelled
    result.files = [label for label, _ in motions]
    if not motions:
        return result
    order = sorted(settings, key=lambda s: (PRIORITY.get(protocol, []).index(s)
                                            if s in PRIORITY.get(protocol, []) else 99,
                                            settings.index(s)))
    result.runs, stopped = run_blocks(protocol, motions, methods, seed_list, order,
                                      method_budget_s, progress, spec or ExecutorSpec(jobs))
    total = len(seed_list) * len(motions) * len(settings)
    for name, n in stopped.items():
        result.notes.append(f"{name}: CPU budget of {method_budget_s:g} s used up; ran "
                            f"{total - n} of {total} corrupted motions (cells marked "
                            f"[k/{len(seed_list)} seeds] average fewer seeds; '–' = not reached)")
    return result
