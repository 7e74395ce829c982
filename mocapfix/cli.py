"""Command line: thin click commands over the library. Errors become one line and an exit
code; see docs/commands.md "Exit codes". Each command is one function registered on ``main``; the
options every command shares (``-q``, ``-v``, ``--debug``) come from :func:`common`."""
from __future__ import annotations

import atexit
import contextlib
import functools
import gc
import json
import os
import sys

import click

from mocapfix import __version__
from mocapfix.cli_options import (EXIT_OK, EXIT_SOME_FAILED, EXIT_UNREADABLE, EXIT_USAGE,
                                  error_line)
from mocapfix.core.errors import (MocapfixError, UnreadableFileError, name_the_file, one_line,
                                  printable)

EXIT_INTERRUPTED = 130          # Ctrl-C (SIGINT): 128 + 2, as shells report it


def _fail(message: str, debug: bool, exc: BaseException | None = None, code: int = EXIT_USAGE):
    if debug and exc is not None:
        raise exc
    error_line(message)
    sys.exit(code)


class Out:
    """Where a command's lines go, by verbosity: ``-q`` only the lines of level -1 (errors,
    ``check``'s FAILs, the summary), default one line per file, ``-v`` details. Lines are
    flushed as written, so a batch streams off a terminal too."""

    def __init__(self, verbosity: int, err: bool = False):
        self.verbosity, self.err = verbosity, err

    def line(self, text: str, level: int = 0, err: bool | None = None):
        if self.verbosity >= level:
            click.echo(printable(text), err=self.err if err is None else err)
            (sys.stderr if (self.err if err is None else err) else sys.stdout).flush()

    def error(self, text: str):
        click.echo(printable(text), err=True)
        sys.stderr.flush()


def common(fn=None, *, quiet_help: str = "Only errors and the summary."):
    """-q/-v/--debug on a command (``--debug`` also works before the command).
    ``@common(quiet_help=...)`` says what -q keeps where that is more than the errors
    (``check``: its FAIL lines, which a CI log must show)."""
    if fn is None:
        return functools.partial(common, quiet_help=quiet_help)

    @click.option("-q", "--quiet", "quiet", is_flag=True, help=quiet_help)
    @click.option("-v", "--verbose", "verbose", count=True, help="More detail (reasons, notes).")
    @click.option("--debug", "debug_here", is_flag=True, help="Show tracebacks instead of one-line errors.")
    @click.pass_context
    @functools.wraps(fn)
    def wrapper(ctx, *args, quiet, verbose, debug_here, **kwargs):
        root = ctx.find_root()
        if not isinstance(root.obj, dict):
            root.obj = {}
        root.obj["debug"] = bool(root.obj.get("debug")) or debug_here
        ctx.obj = root.obj
        ctx.obj["verbosity"] = -1 if quiet else verbose
        return ctx.invoke(fn, *args, **kwargs)

    return wrapper


class _OneLineErrors(click.Group):
    """The last guard of "never a traceback": an exception that no command turned into its
    one-line error (a bug, or an OS failure at an unforeseen place) is printed as one line
    naming its type, with exit 1 as Python's own; ``--debug`` shows the traceback."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except KeyboardInterrupt:
            # click's "Aborted!" exited 1, which says "some files failed, the others were
            # written" (clean) or "a rule failed" (check); 128 + SIGINT, as a shell says it
            click.echo("\nmocapfix: interrupted", err=True)
            sys.exit(EXIT_INTERRUPTED)
        except BrokenPipeError:
            # the reader of our output went away (`mocapfix info DIR | head`): stop quietly,
            # as the writer of a pipe does; stdout to devnull so the final flush is silent
            with contextlib.suppress(OSError, ValueError):
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            sys.exit(EXIT_SOME_FAILED)
        except Exception as exc:  # noqa: BLE001
            obj = ctx.obj if isinstance(ctx.obj, dict) else {}
            if obj.get("debug"):
                raise
            message = str(exc) if isinstance(exc, MocapfixError) else \
                f"internal error {type(exc).__name__}: {exc} (--debug shows the traceback)"
            click.echo(printable(f"mocapfix: error: {message}"), err=True)
            sys.exit(EXIT_SOME_FAILED)

    def get_command(self, ctx, name):
        if name == "bench" and name not in self.commands:
            _register_bench()
        return super().get_command(ctx, name)

    def list_commands(self, ctx):
        return sorted({*super().list_commands(ctx), "bench"})


@click.group(cls=_OneLineErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="mocapfix")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
@click.pass_context
def main(ctx, debug):
    """Clean motion-capture files: ASF/AMC, BVH, C3D and Kinect skeleton text."""
    from mocapfix.core.memory import retain_freed_memory

    retain_freed_memory()
    _printable_file_names()
    # the last thing before the interpreter's own shutdown (atexit runs its functions last
    # registered first): every object still alive leaves the collector's generations, so
    # the shutdown's collection does not walk them (the 4,500-frame clean of
    # benchmarks/clean_speed.py: ~55 → ~30 ms from the command's end to the process's)
    atexit.unregister(gc.freeze)         # once, however often main runs in one process
    atexit.register(gc.freeze)
    ctx.obj = {"debug": debug}


def _printable_file_names():
    """A file name that is not UTF-8 (bytes on Linux; ``\\udcff`` in Python) must not stop a
    run when a line names it: under a UTF-8 locale Python's stdout/stderr refuse such
    characters ('strict'), so they are printed escaped instead (the C/POSIX locale already
    passes them through as the original bytes)."""
    for stream in (sys.stdout, sys.stderr):
        if getattr(stream, "errors", None) == "strict" and hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):       # a stream that cannot be reconfigured
                pass


def _ctx():
    return click.get_current_context().obj


def _print_warnings(out: Out):
    from mocapfix.config import UNIT_WARNINGS

    for w in UNIT_WARNINGS:
        out.error(f"mocapfix: warning: {w}")
    UNIT_WARNINGS.clear()


def _discover(inputs, include, exclude, out: Out, once_per_file: bool = False,
              checked_unknown: bool = False):
    """Find the inputs and print what was passed over; ``checked_unknown``: the text files
    of no known layout are checked (``check --strict``), not passed over."""
    from mocapfix.batch.discovery import discover_inputs

    found = discover_inputs(inputs, include, exclude, once_per_file=once_per_file)
    unknown = {str(f.path) for f, _ in found.unknown} if checked_unknown else set()
    for path, why in found.skipped:
        if path in unknown:
            continue
        out.line(f"SKIP  {one_line(path)}: {one_line(why)}", level=0 if "not motion" not in why else 1,
                 err=True)
    if found.skipped and out.verbosity == 0:
        quiet_skips = sum("not motion" in why for _, why in found.skipped)
        if quiet_skips:
            out.line(f"note: {quiet_skips} text file(s) are not motion data and were skipped "
                     "(-v lists them)", err=True)
    return found


_pattern_options = [
    click.option("--include", multiple=True, metavar="GLOB",
                 help="Only files (in folders) whose name or relative path matches, ignoring "
                      "case ('*.c3d' takes take.C3D); repeatable."),
    click.option("--exclude", multiple=True, metavar="GLOB",
                 help="Skip files (in folders) whose name or relative path matches, ignoring "
                      "case; repeatable."),
]


def patterns(fn):
    for opt in reversed(_pattern_options):
        fn = opt(fn)
    return fn


from mocapfix.cli_options import executor_spec as _executor_spec  # noqa: E402
from mocapfix.cli_options import executors  # noqa: E402,F401
from mocapfix.cli_options import FPS, FiniteFloatRange, GivenPath, not_empty  # noqa: E402


# -- info --------------------------------------------------------------------------------------

@main.command()
@click.argument("inputs", nargs=-1, required=True, type=GivenPath())
@click.option("--json", "as_json", is_flag=True, help="Print a JSON list instead of text.")
@click.option("--fps", type=FPS, default=None,
              help="Frame rate for formats that do not store one (AMC; default 120).")
@patterns
@common
def info(inputs, as_json, fps, include, exclude):
    """Frames, rate, markers, gaps, tracking state, analog channels, events and force
    plates of each file (INPUT may be a folder). Exit 3 if a file could not be read."""
    from mocapfix.formats import read
    from mocapfix.quality.info import format_text, summarise

    obj = _ctx()
    debug, out = obj["debug"], Out(obj["verbosity"])
    try:
        found = _discover(inputs, include, exclude, out, once_per_file=True)
        if not found.files:              # as clean and check: not a silent success
            raise MocapfixError("no motion files found in " + ", ".join(inputs))
    except MocapfixError as exc:
        _fail(str(exc), debug, exc)
    from mocapfix.batch.tasks import quiet_float_warnings

    quiet_float_warnings()              # (clean and check: in each task, batch.tasks._guarded)
    summaries, failed = [], 0
    for f in found.files:
        try:
            options = {"default_fps": fps} if fps else {}
            s = summarise(read(f.path, **options))
            summaries.append(s)
            if not as_json:
                out.line(format_text(s, verbose=obj["verbosity"] > 0) + "\n", level=-1)
        except BrokenPipeError:
            raise                         # our reader went away: not this file's fault
        except Exception as exc:  # noqa: BLE001 — one bad file must not stop the others
            if debug:
                raise
            failed += 1
            message = name_the_file(f.path, exc if isinstance(exc, MocapfixError) else
                                    f"internal error {type(exc).__name__}: {exc}")
            out.error(f"mocapfix: error: {one_line(message)}")
            summaries.append({"path": str(f.path), "error": message})
    if as_json:
        click.echo(json.dumps(summaries, indent=2))
    if failed:
        sys.exit(EXIT_UNREADABLE)


@main.command()
@click.argument("files", nargs=-1, type=GivenPath(dir_okay=False))
@click.option("--before", "before", type=GivenPath(dir_okay=False), default=None,
              help="The capture as it was (with --after: a before/after overlay).")
@click.option("--after", "after", type=GivenPath(dir_okay=False), default=None,
              help="Its cleaned output.")
@click.option("-o", "--output", "output", type=GivenPath(dir_okay=False), default="view.html",
              show_default=True, help="The HTML file to write.")
@click.option("--open", "open_it", is_flag=True, help="Open the page in the web browser.")
@click.option("--budget", type=FiniteFloatRange(0.05, 1000), default=3.0, show_default=True,
              help="MB the page may hold; longer takes keep every k-th frame.")
@click.option("--fps", type=FPS, default=None,
              help="Frame rate for formats that do not store one (AMC; default 120).")
@common
def view(files, before, after, output, open_it, budget, fps):
    """Write one self-contained HTML page that plays FILE(s) in 3D (no network needed).
    Two files with the same points and frames — a capture and its cleaned output — are
    overlaid as before and after (or name them with --before/--after); other files are
    overlaid as they are. A clean report (OUT.report.json) overlays its input and output,
    the samples each step judged wrong coloured by step."""
    from pathlib import Path

    from mocapfix.formats import read
    from mocapfix.quality import viewer

    obj = _ctx()
    debug = obj["debug"]
    if (before is None) != (after is None):
        _fail("--before and --after go together", debug)
    if before is not None and files:
        _fail("give FILE... or --before/--after, not both", debug)
    if before is None and not files:
        _fail("nothing to view: give FILE... or --before IN --after OUT", debug)
    options = {"default_fps": fps} if fps else {}
    try:
        from mocapfix.batch.discovery import refuse_special_file
        from mocapfix.batch.plan import check_output_file
        from mocapfix.core.fileio import atomic_write_text

        paths = [before, after] if before is not None else list(files)
        for p in paths:                 # as discovery: a FIFO waited forever for a writer
            refuse_special_file(p)
        limit = int(budget * 1e6)
        report = len(paths) == 1 and str(paths[0]).endswith(viewer.REPORT_SUFFIX)
        # `view take.bvh -o take.bvh` replaced the capture with the page; a report's view
        # reads the input and output it names
        read_too = viewer.report_files(paths[0])[:2] if report else ()
        check_output_file(output, "-o", [*paths, *read_too])
        if report:
            page = viewer.from_report(paths[0], budget=limit, **options)
        else:
            motions = [read(p, **options) for p in paths]
            if before is not None or (len(motions) == 2 and viewer.comparable(*motions)):
                page = viewer.before_after(*motions, budget=limit)
            else:
                page = viewer.single(motions, budget=limit)
        atomic_write_text(output, page)
    except (MocapfixError, ValueError, OSError) as exc:
        _fail(one_line(str(exc)), debug, exc)
    Out(obj["verbosity"]).line(f"wrote {output} ({len(page.encode()) / 1e6:.2f} MB)")
    if open_it:
        import webbrowser
        webbrowser.open(Path(output).resolve().as_uri())


# -- cleaners / configs --------------------------------------------------------------------------

@main.command("cleaners")
@click.option("--markdown", is_flag=True, help="Print a Markdown table (as in docs/configs.md).")
def list_cleaners(markdown):
    """List the cleaners a config can name, with their parameters and defaults."""
    from mocapfix.cleaners import registry

    rows = []
    for name, cls in registry().items():
        params = ", ".join(f"{p.name}={p.default}" for p in cls.params) or "–"
        rows.append((name, cls.summary, params))
    if markdown:
        click.echo("| cleaner | what it does | parameters (defaults) |\n|---|---|---|")
        for name, summary, params in rows:
            click.echo(f"| `{name}` | {summary} | {params} |")
        return
    for name, summary, params in rows:
        click.echo(f"{name:<18} {summary}\n{'':<18} {params}")


@main.command("formats")
def list_formats():
    """The file formats mocapfix reads and writes: name (for --to and a config's
    formats:), family (what its points are; a config may name it), suffixes."""
    from mocapfix import formats

    family = {n: f for f, names in formats.FAMILIES.items() for n in names}
    for name in formats.NAMES:
        click.echo(f"{name:<12} {family[name]:<10} {' '.join(formats.suffixes(name))}")


@main.command("configs")
@click.argument("name", required=False)
@click.option("--rules", "rules", is_flag=True, help="Rule sets of `check` instead of pipeline configs.")
def list_configs(name, rules):
    """List the shipped configs (and with --rules the shipped rule sets), or print one.

    A shipped config is named by its preset name: `mocapfix clean -c optical-c3d ...`;
    a rule set likewise: `mocapfix check -r kinect ...`. Copy one to start your own:
    `mocapfix configs optical-c3d > my.yaml`."""
    from mocapfix.core.presets import CONFIG_DIR, RULES_DIR, config_names, config_summary
    from mocapfix.quality.rules import preset_names

    folder, names = (RULES_DIR, preset_names()) if rules else (CONFIG_DIR, config_names())
    if name is None:
        click.echo("rule sets (check -r NAME):" if rules else "pipeline configs (clean -c NAME):")
        for n in names:
            click.echo(f"  {n:<16} {config_summary(folder / f'{n}.yaml')}")
        if not rules:
            click.echo("rule sets: `mocapfix configs --rules`")
        return
    stem = name[:-5] if name.endswith(".yaml") else name
    if stem not in names:
        other = preset_names() if not rules else config_names()
        hint = (" (it is a rule set: add --rules)" if not rules else " (it is a pipeline config: drop --rules)") \
            if stem in other else ""
        _fail(f"no shipped {'rule set' if rules else 'config'} named {name!r}{hint}; "
              f"known: {', '.join(names)}", False)
    click.echo((folder / f"{stem}.yaml").read_text(encoding="utf-8"), nl=False)


# -- clean ---------------------------------------------------------------------------------

def _parse_reports(value: str) -> tuple[str, ...]:
    from mocapfix.cleaning import REPORT_KINDS

    kinds = tuple(k.strip().lower() for k in value.split(",") if k.strip())
    if not kinds:                   # (--report "" meant no reports, silently)
        raise click.BadParameter("--report is empty; use json, md, html (comma-separated) or none")
    bad = [k for k in kinds if k not in REPORT_KINDS and k != "none"]
    if bad:
        raise click.BadParameter(f"unknown report kind(s) {', '.join(bad)}; use json, md, html or none")
    return tuple(k for k in kinds if k != "none")


def _clean_line(r: dict, verbose: bool, graded: bool = True) -> str:
    """A file's line; ``graded`` False (``convert``): DONE instead of the quality status,
    which a conversion does not change (``check`` and the reports judge it)."""
    if r["status"] == "ERROR":
        return f"ERROR {one_line(name_the_file(r['input'], r['error']))}"
    text = (f"{r['status'] if graded else 'DONE':<5} {one_line(r['input'])} -> {one_line(r['output'])} "
            f"(missing {100 * r['missing_before']:.1f} % -> {100 * r['missing_after']:.1f} %, "
            f"{r['seconds']:.2f} s)")
    if r.get("skipped"):
        return f"SKIP  {one_line(r['input'])}: {r['skipped']}"
    if verbose and r.get("reasons"):
        text += "\n      " + "\n      ".join(map(one_line, r["reasons"]))
    if verbose:
        for note in r.get("steps_not_run", []):
            text += f"\n      note: {one_line(note)}"
    for note in r.get("not_carried", []):       # a conversion never drops data silently
        text += f"\n      not carried into {r['format']}: {one_line(note)}"
    return text


def _batch_options(verb: str, reports: str):
    """The options ``clean`` and ``convert`` share (``verb``: "cleaned", "converted";
    ``reports``: the default report kinds)."""
    options = [
        click.option("--report", "reports", default=reports, show_default=True,
                     help="Reports to write beside each output: json, md, html (comma-separated) or none."),
        click.option("-j", "--jobs", default=1, show_default=True, type=click.IntRange(1, 256),
                     help=f"Files {verb} in parallel (process pool)."),
        click.option("--json", "as_json", is_flag=True,
                     help="Print a JSON summary on stdout (per-file lines go to stderr)."),
        click.option("--fps", type=FPS, default=None, help="Frame rate for files that store none (AMC)."),
        click.option("--allow-inside-input", is_flag=True,
                     help="Allow the output folder to lie inside an input folder."),
        click.option("--dry-run", is_flag=True,
                     help=f"Say what would be {verb} and written; write nothing. Refuses (exit 2) "
                          "what the real run would refuse."),
        click.option("--overwrite", is_flag=True,
                     help="Replace outputs (and their reports) left by an earlier run."),
        click.option("--skip-existing", is_flag=True,
                     help="Leave files whose output exists alone (same config and models only)."),
    ]

    def decorate(fn):
        for opt in reversed(options):
            fn = opt(fn)
        return fn
    return decorate


@main.command()
@click.argument("inputs", nargs=-1, required=True, type=GivenPath())
@click.option("-o", "--output", "outdir", required=True, type=GivenPath(file_okay=False),
              help="Output folder; the input tree is mirrored inside it.")
@click.option("-c", "--config", "config_path", callback=not_empty,
              help="Pipeline config: a YAML file or a shipped preset name (`mocapfix configs`). "
                   "Default: default.")
@_batch_options("cleaned", "json")
@click.option("--to", "to", metavar="FORMAT", callback=not_empty,
              help="Write every output in this format (c3d, trc, kinect, ... : `mocapfix "
                   "formats`); default: each input's own. What it cannot carry is named.")
@patterns
@executors
@common
def clean(inputs, outdir, config_path, reports, jobs, as_json, fps, allow_inside_input, dry_run,
          overwrite, skip_existing, to, include, exclude, scheduler, dask_workers):
    """Clean INPUT files or folders with a pipeline of cleaners.

    Files an earlier run of the same config and models finished (recorded in the output
    folder's mocapfix-manifest.jsonl, input and its skeleton unchanged) are skipped, so
    a killed run resumes; any other output that exists already is an error unless
    --overwrite or --skip-existing is given. Exit code 0 when every file was cleaned, 1
    when some failed (the others are still written), 2 for a usage or config error.
    """
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config

    _run_clean(inputs, outdir, lambda: load_config(resolve_config(config_path or "default")),
               reports, jobs, as_json, fps, allow_inside_input, dry_run, overwrite,
               skip_existing, to, include, exclude, scheduler, dask_workers, "cleaned")


@main.command()
@click.argument("inputs", nargs=-1, required=True, type=GivenPath())
@click.option("-o", "--output", "outdir", required=True, type=GivenPath(file_okay=False),
              help="Output folder; the input tree is mirrored inside it, suffixes changed.")
@click.option("--to", "to", required=True, metavar="FORMAT", callback=not_empty,
              help="Output format: c3d, trc, kinect, ... (`mocapfix formats`).")
@_batch_options("converted", "none")
@patterns
@executors
@common
def convert(inputs, outdir, to, reports, jobs, as_json, fps, allow_inside_input, dry_run,
            overwrite, skip_existing, include, exclude, scheduler, dask_workers):
    """Convert INPUT files or folders to another format, cleaning nothing.

    Samples are written as read (a missing sample stays missing: never filled); units are
    the input's, stated in the output where the format has a place for them; what the
    output format cannot carry (rotations into a marker format, analog channels into TRC,
    Kinect tracking states ...) is named per file. Resumes and refuses like `clean`.
    """
    from mocapfix.batch.clean import convert_pipeline

    _run_clean(inputs, outdir, convert_pipeline, reports, jobs, as_json, fps,
               allow_inside_input, dry_run, overwrite, skip_existing, to, include, exclude,
               scheduler, dask_workers, "converted")


def _run_clean(inputs, outdir, make_pipeline, reports, jobs, as_json, fps, allow_inside_input,
               dry_run, overwrite, skip_existing, to, include, exclude, scheduler, dask_workers,
               verb: str):
    """The body of ``clean`` and ``convert`` (``verb``: "cleaned", "converted"): plan,
    run, print, exit."""
    from mocapfix.batch.clean import plan_clean, run_clean, would_do

    obj = _ctx()
    debug = obj["debug"]
    out = Out(obj["verbosity"], err=as_json)
    try:
        if overwrite and skip_existing:   # (the last one given used to win silently)
            raise click.BadParameter("--overwrite and --skip-existing exclude each other; give one")
        kinds = _parse_reports(reports)
        spec = _executor_spec(jobs, scheduler, dask_workers)
        pipeline = make_pipeline()
        _print_warnings(out)
        found = _discover(inputs, include, exclude, out)
        plan = plan_clean(found.files, outdir, pipeline, inputs=inputs, reports=kinds,
                          policy="overwrite" if overwrite else "skip" if skip_existing else None,
                          fps=fps, allow_inside_input=allow_inside_input, dry_run=dry_run, to=to)
    except (click.BadParameter, MocapfixError) as exc:
        _fail(str(exc), debug, exc)
    for j, why in plan.skipped:
        out.line(f"SKIP  {one_line(j.source)}: {why} ({one_line(j.output)})")
    if dry_run:
        todo = would_do(plan)
        for f in todo:
            note = (" (its output path is a folder: the file would fail)" if f.get("output_is_folder")
                    else " (replaces the existing output)" if f["replaces"] else "")
            out.line(f"WOULD {one_line(f['input'])} -> {one_line(f['output'])}{note}", level=-1)
        out.line(f"dry run: {len(todo)} file(s) would be {verb} with {pipeline.source}, "
                 f"{len(plan.skipped)} skipped; nothing written", level=-1, err=True)
        if as_json:                     # (stdout stayed empty: `--json --dry-run | jq` failed)
            click.echo(json.dumps({"dry_run": True, "config": str(pipeline.source), "files": todo,
                                   "skipped": [str(j.source) for j, _ in plan.skipped]}, indent=1))
        sys.exit(EXIT_OK)

    def stream(r):
        out.line(_clean_line(r, obj["verbosity"] > 0, verb == "cleaned"),
                 level=0 if r["status"] != "ERROR" else -1,
                 err=True if r["status"] == "ERROR" else None)
        if debug and r.get("traceback"):
            out.error(r["traceback"].rstrip())

    try:
        results = run_clean(plan, workers=jobs, spec=spec, on_result=stream)
    except MocapfixError as exc:        # e.g. the Dask scheduler cannot be reached
        _fail(str(exc), debug, exc)
    failed = [r for r in results if r["status"] == "ERROR"]
    skipped = [str(j.source) for j, _ in plan.skipped]
    if as_json:
        click.echo(json.dumps({"files": results, "cleaned": len(results) - len(failed),
                               "failed": len(failed), "skipped": skipped,
                               "config": str(pipeline.source),
                               **({"problems": plan.problems} if plan.problems else {})}, indent=1))
    else:
        graded = [r["status"] for r in results if r["status"] != "ERROR" and verb == "cleaned"]
        out.line(f"{verb} {len(results) - len(failed)} of {len(results)} files"
                 + (f" ({len(skipped)} skipped: {'finished earlier' if plan.resumed else 'output exists'})"
                    if skipped else "")
                 + (": " + ", ".join(f"{graded.count(s)} {s}" for s in ("OK", "WARN", "FAIL")
                                      if s in graded) if graded else "")
                 + (f"; {len(failed)} failed (ERROR): " + ", ".join(one_line(r["input"]) for r in failed)
                    if failed else ""), level=-1, err=bool(failed))
    for problem in plan.problems:       # the manifest or the config record not written
        out.error(f"mocapfix: error: {one_line(problem)}")
    sys.exit(EXIT_SOME_FAILED if failed or plan.problems else EXIT_OK)


# -- check ---------------------------------------------------------------------------------

@main.command()
@click.argument("inputs", nargs=-1, required=True, type=GivenPath())
@click.option("-r", "--rules", "rules_path", default=None, callback=not_empty,
              help="Rules: a YAML file or a shipped rule set (`mocapfix configs --rules`). "
                   "Default: default (per format).")
@click.option("--junit", "junit_path", type=GivenPath(dir_okay=False),
              help="Write JUnit XML here (one testcase per file).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON on stdout.")
@click.option("--fail-on", "fail_on", multiple=True, metavar="RULE=VALUE",
              help="Set the fail threshold of a rule (or metric), e.g. --fail-on missing=20%; repeatable.")
@click.option("--exit-zero", is_flag=True, help="Exit 0 even when rules fail or files are unreadable.")
@click.option("--would-clean", "would_clean", metavar="CONFIG", callback=not_empty,
              help="Also run this pipeline in memory and say what it would fill and leave uncertain.")
@click.option("-j", "--jobs", default=1, show_default=True, type=click.IntRange(1, 256),
              help="Files checked in parallel.")
@click.option("--fps", type=FPS, default=None, help="Frame rate for files that store none (AMC).")
@click.option("--strict", is_flag=True,
              help="Check text files in folders that hold a table of numbers in no known layout "
                   "too (they fail as unreadable) instead of listing them as skipped.")
@patterns
@executors
@common(quiet_help="Only FAIL and ERROR lines and the summary.")
def check(inputs, rules_path, junit_path, as_json, fail_on, exit_zero, would_clean, jobs, fps,
          strict, include, exclude, scheduler, dask_workers):
    """Check INPUT files or folders against quality rules without changing anything.

    One line per file as it finishes: OK, WARN (passes), FAIL (a rule failed) or ERROR
    (unreadable). A text file in a folder that holds a table of numbers in no known layout
    is SKIP (a skipped testcase in the JUnit XML; --strict checks it, and it is ERROR).
    Exit 0 all passed, 1 a rule failed, 2 usage or config error, 3 an input could not be
    read.
    """
    import time

    from mocapfix.batch.plan import check_output_file
    from mocapfix.batch.tasks import run_tasks
    from mocapfix.batch.check import CheckTask, exit_code, summary
    from mocapfix.core.fileio import atomic_write_text
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config
    from mocapfix.quality.render import check_junit, check_line
    from mocapfix.quality.rules import load_rules, resolve_rules_path

    obj = _ctx()
    debug = obj["debug"]
    out = Out(obj["verbosity"], err=as_json)
    started = time.perf_counter()
    try:
        spec = _executor_spec(jobs, scheduler, dask_workers)
        if junit_path:
            check_output_file(junit_path, "--junit", inputs, configs=(rules_path, would_clean))
        rules = load_rules(resolve_rules_path(rules_path or "default")).with_fail_on(list(fail_on))
        config = source = None
        if would_clean:
            pipeline = load_config(resolve_config(would_clean))
            _print_warnings(out)
            config, source = pipeline.config(), str(pipeline.source)
        found = _discover(inputs, include, exclude, out, once_per_file=True, checked_unknown=strict)
        if strict:                      # checked like the others: each one an ERROR
            found.files = sorted([*found.files, *(f for f, _ in found.unknown)],
                                 key=lambda f: (str(f.root), str(f.relative)))
        if not found.files and not found.unknown:
            raise MocapfixError("no motion files found in " + ", ".join(inputs))
    except MocapfixError as exc:
        _fail(str(exc), debug, exc)
    task = CheckTask(rules, config, source, {"default_fps": fps} if fps else None)

    def name(f) -> str:
        return str(f.relative if f.root is None else f.root.name / f.relative)

    names = [name(f) for f in found.files]
    results: list = [None] * len(found.files)
    try:
        for n, r in run_tasks(task, [f.path for f in found.files], jobs, spec=spec):
            if "path" not in r:         # a worker that died: the pool's error record
                r["path"] = r.pop("input", str(found.files[n].path))
                r.setdefault("findings", [])
            r["name"] = names[n]
            results[n] = r
            level = -1 if r["status"] in ("FAIL", "ERROR") else 0
            out.line(check_line(r, obj["verbosity"] > 0), level=level)
            if debug and r.get("traceback"):
                out.error(r["traceback"].rstrip())
    except MocapfixError as exc:        # e.g. the Dask scheduler cannot be reached
        _fail(str(exc), debug, exc)
    if not strict:
        results += [{"path": str(f.path), "name": name(f), "status": "SKIP", "skipped": why,
                     "findings": []} for f, why in found.unknown]
    seconds = time.perf_counter() - started
    if junit_path:
        try:
            atomic_write_text(junit_path, check_junit(
                [{**r, "path": r["name"]} for r in results], seconds))
        except MocapfixError as exc:     # the folder went away during the run
            _fail(str(exc), debug, exc)
    s = summary(results)
    if as_json:
        click.echo(json.dumps({"summary": s, "rules": rules.describe(), "files": results}, indent=1))
    out.line(f"checked {s['files']} files: {s['OK']} OK, {s['WARN']} WARN, {s['FAIL']} FAIL, "
             f"{s['ERROR']} ERROR" + (f"; {s['SKIP']} SKIP (not a known layout; --strict fails "
                                      "them)" if s["SKIP"] else ""), level=-1, err=True)
    sys.exit(EXIT_OK if exit_zero else exit_code(results))


# -- train-dictionary ----------------------------------------------------------------------

@main.command("train-dictionary")
@click.argument("training", nargs=-1, required=True, type=GivenPath())
@click.option("-o", "--output", required=True, type=GivenPath(dir_okay=False),
              help="Model file to write (.npz).")
@click.option("--method", default="partlet", show_default=True,
              type=click.Choice(["partlet", "ksvd", "mssa"]),
              help="partlet: robust dictionary learning (Feng 2015); ksvd: K-SVD (Xiao 2015); "
                   "mssa: M-SSA filter bases (Lou 2012).")
@click.option("--atoms", type=click.IntRange(2, 4096), default=None, help="Atoms per partlet (default 128).")
@click.option("--window", type=click.IntRange(1, 200), default=None, help="Window length m in samples (default 16).")
@click.option("--sample-rate", default=None, help="Rate of the window samples (default '120 Hz'; '30 Hz' for Kinect).")
@click.option("--lambda", "lam", default=None, help="Outlier weight of eq. 5 as a length (default '50 mm').")
@click.option("--beta", type=float, default=None, help="Sparsity weight of eq. 5 (default 0.05, relative).")
@click.option("--iterations", type=click.IntRange(1, 1000), default=None, help="Outer training iterations.")
@click.option("--max-windows", type=click.IntRange(10, 10_000_000), default=None,
              help="Training windows per partlet (random subset).")
@click.option("--seed", type=click.IntRange(0), default=None)
@click.option("--bases", type=click.IntRange(1), default=None, help="mssa: number of bases K (default: by energy).")
@click.option("--energy", type=click.FloatRange(0, 1, min_open=True), default=None,
              help="mssa: energy the bases keep (default 0.99).")
@click.option("-j", "--jobs", default=1, show_default=True, type=click.IntRange(1, 256),
              help="Files read in parallel.")
@click.option("--fps", type=FPS, default=None, help="Frame rate for files that store none (AMC).")
@executors
@common
def train_dictionary(training, output, method, atoms, window, sample_rate, lam, beta,
                     iterations, max_windows, seed, bases, energy, jobs, fps, scheduler, dask_workers):
    """Train a model for a trained cleaner from TRAINING files or folders (any format;
    BVH/AMC by forward kinematics) and write it to OUTPUT. Name it in a config with
    `model: PATH` (relative to the config file)."""
    from mocapfix.train import train

    obj = _ctx()
    debug = obj["debug"]
    out = Out(obj["verbosity"])
    bar = None
    if sys.stderr.isatty() and obj["verbosity"] >= 0:
        from tqdm import tqdm

        state = {}

        def progress(stage, n, total):
            nonlocal bar
            if state.get("stage") != stage:
                if bar:
                    bar.close()
                bar = tqdm(total=total, desc=stage, unit="file" if stage == "read" else "partlet",
                           file=sys.stderr, leave=False)
                state["stage"] = stage
            bar.n = n
            bar.refresh()
    else:
        progress = None
    params = {"atoms": atoms, "window": window, "sample_rate": sample_rate, "train_lambda": lam,
              "beta": beta, "train_iterations": iterations, "max_windows": max_windows, "seed": seed,
              "bases": bases, "energy": energy}
    # an option of the other methods was "unknown parameter(s) 'train_iterations', … for
    # cleaner 'mssa'": the cleaner's internal names, not the options the user gave
    foreign = [opt for opt, key in _TRAIN_OPTIONS[method == "mssa"] if params[key] is not None]
    if foreign:
        _fail(f"{', '.join(foreign)} {'does' if len(foreign) == 1 else 'do'} not apply to --method "
              f"{method} (only to " + ("partlet and ksvd)" if method == "mssa" else "mssa)"), debug)
    try:
        from mocapfix.batch.plan import check_output_file

        check_output_file(output, "-o", training)
        summary = train(training, output, method, params, jobs, fps, progress,
                        spec=_executor_spec(jobs, scheduler, dask_workers))
    except UnreadableFileError as exc:
        _fail(str(exc), debug, exc, code=EXIT_UNREADABLE)
    except MocapfixError as exc:
        _fail(str(exc), debug, exc)
    finally:
        if bar:
            bar.close()
    for path, why in summary["skipped"]:
        out.line(f"skipped {path}: {why}", level=0)
    for u in summary["unread"]:
        out.line(f"ERROR {u['error']} (left out of the training)", level=-1, err=True)
    t = summary["training"]
    st = summary["state"]
    if method == "mssa":
        out.line(f"wrote {output}: mssa, {st['bases']} bases of window {st['window']} over "
                 f"{len(st['layout'])} {st['space']} channels at {st['fps']:g} Hz; trained on "
                 f"{len(t['files'])} files, {t['frames']} frames in {t['seconds']:.1f} s; "
                 f"unexplained energy {100 * st['unexplained']:.3f} %", level=-1)
    else:
        out.line(f"wrote {output}: {summary['cleaner']} ({st['method']}), {len(st['joints'])} joints in "
                 f"{len(st['partlets'])} partlets, window {st['window']} at {st['sample_rate']:g} Hz; "
                 f"trained on {len(t['files'])} files, {t['frames']} frames in {t['seconds']:.1f} s; "
                 "unexplained energy " + ", ".join(f"{p} {100 * f:.2f} %" for p, f in st["unexplained"].items()), level=-1)
    if summary["unread"]:
        sys.exit(EXIT_SOME_FAILED)


#: train-dictionary options that do not apply: [False] to partlet/ksvd, [True] to mssa
_TRAIN_OPTIONS = {False: (("--bases", "bases"), ("--energy", "energy")),
                  True: (("--atoms", "atoms"), ("--sample-rate", "sample_rate"), ("--lambda", "train_lambda"),
                         ("--beta", "beta"), ("--iterations", "train_iterations"),
                         ("--max-windows", "max_windows"), ("--seed", "seed"))}


def _register_bench():
    """Add ``bench`` to ``main``: done when it is asked for (:class:`_OneLineErrors`), as
    its import loads the benchmark package (~30 ms of every other command's start-up)."""
    from mocapfix.bench.cli import bench

    main.add_command(bench)

if __name__ == "__main__":  # pragma: no cover
    main()
