"""The ``mocapfix bench`` command (registered by :mod:`mocapfix.cli` with
``main.add_command(bench)``). Thin: parses options and calls :func:`mocapfix.bench.run`
(:func:`mocapfix.bench.kinect.run` for the kinect protocol)."""
from __future__ import annotations

import os
import sys

import click

from mocapfix.cli_options import (EXIT_SOME_FAILED, EXIT_UNREADABLE, EXIT_USAGE, GivenPath,
                                  error_line, executor_spec, executors)
from mocapfix.core.errors import MocapfixError, UnreadableFileError


def _split(value: str | None) -> list[str] | None:
    if value is None:
        return None
    items = [v.strip() for v in value.split(",") if v.strip()]
    if not items:
        raise click.BadParameter("give at least one name")
    return items


def _debug(ctx) -> bool:
    root = ctx.find_root()
    return bool(isinstance(root.obj, dict) and root.obj.get("debug"))


def _fail(ctx, exc: Exception, unread=()):
    """The files left out, then ``exc``, each as an error line; exit 2 (``--debug``: raise)."""
    for u in unread:
        error_line(u["error"])
    if _debug(ctx):
        raise exc
    error_line(str(exc))
    sys.exit(EXIT_USAGE)


@click.command("bench")
@click.argument("clean_files", nargs=-1, required=True, type=GivenPath())
@click.option("--protocol", required=True,
              type=click.Choice(["feng2015", "yang2019", "feng2014", "occlusion", "kinect", "rotations",
                                 "harm"]),
              help="Corruption protocol (see docs/benchmarks.md).")
@click.option("--methods", default=None,
              help="Comma-separated registered cleaners and/or baselines (none, "
                   "linear+gaussian, pca+butterworth), named pipelines, or the oracle-"
                   "tuned gaussian(tuned), wavelet(tuned), kalman(tuned). Default: every "
                   "registered cleaner, "
                   "unless --configs is given. Baselines are always included.")
@click.option("--configs", default=None,
              help="Comma-separated YAML pipeline configs, each benchmarked as one method.")
@click.option("--seeds", default=3, show_default=True, type=click.IntRange(1, 1000),
              help="Number of seeds (0 … N−1); the same corruption is used for every method.")
@click.option("--settings", default=None,
              help="Comma-separated subset of the protocol's settings (default: all).")
@click.option("--json", "json_out", type=GivenPath(dir_okay=False), default=None,
              help="Write every run and the summary as JSON.")
@click.option("--markdown", "md_out", type=GivenPath(dir_okay=False), default=None,
              help="Write the Markdown tables to this file.")
@click.option("--per-file", is_flag=True, help="Also tabulate each file separately.")
@click.option("--quiet", "-q", is_flag=True, help="Do not print the tables or progress.")
@click.option("-j", "--jobs", default=1, show_default=True, type=click.IntRange(1, 256),
              help="Corrupted motions benchmarked in parallel (one task per seed, setting and "
                   "file; not the kinect protocol).")
@executors
@click.pass_context
def bench(ctx, clean_files, protocol, methods, configs, seeds, settings, json_out, md_out,
          per_file, quiet, jobs, scheduler, dask_workers):
    """Corrupt each CLEAN_FILE with a seeded PROTOCOL, clean it with each method and
    print error tables against the clean data (mean ± std over seeds, seconds per file)."""
    from mocapfix import bench as bench_lib
    from mocapfix.batch.plan import check_output_file
    from mocapfix.core.fileio import atomic_write_text, is_stream

    try:                      # before the work: a long run must not end on an unwritable path
        for f in clean_files:   # a misspelt path, as clean, check and train-dictionary say
            if not os.path.exists(f):
                raise UnreadableFileError(f, "no such file")
        given = [c.strip() for c in (configs or "").split(",") if c.strip()]
        for option, path in (("--json", json_out), ("--markdown", md_out)):
            if path:
                check_output_file(path, option, clean_files, configs=given)
        if (json_out and md_out and os.path.realpath(json_out) == os.path.realpath(md_out)
                and not is_stream(json_out)):
            # the Markdown replaced the JSON without a word
            raise MocapfixError(f"--json and --markdown both name {json_out}; give two files")
    except MocapfixError as exc:
        _fail(ctx, exc)
    once = {}
    for f in clean_files:       # a file named twice counted twice in every mean
        once.setdefault(os.path.realpath(f), f)
    if len(once) < len(clean_files) and not quiet:
        click.echo(f"bench: note: {len(clean_files) - len(once)} file(s) given more than once "
                   "(benchmarked once)", err=True)
    clean_files = list(once.values())
    progress = None if quiet else (lambda msg: click.echo(f"bench: {msg}", err=True))
    unread: list[dict] = []     # files that cannot be read or used: named, left out, exit 1
    if protocol == "kinect":  # CMU captures made into Kinect v2 CSVs: its own runner
        from mocapfix.bench import kinect as bench_kinect

        if (jobs > 1 or scheduler or dask_workers) and not quiet:
            click.echo("bench: note: the kinect protocol runs in this process (-j, "
                       "--dask-workers and --scheduler are ignored)", err=True)
        try:
            result = bench_kinect.run(clean_files, configs=_split(configs) or (), seeds=seeds,
                                      scenarios=_split(settings), progress=progress,
                                      unread=unread)
        except (MocapfixError, ValueError) as exc:
            _fail(ctx, exc, unread)
        tables = (lambda: "## `kinect`\n\n" + (bench_kinect.__doc__ or "").split("\n\n")[0]
                  + "\n\n" + result.to_markdown())
        to_json = result.to_json
    else:
        try:
            spec = executor_spec(jobs, scheduler, dask_workers)
            method_list, notes = bench_lib.resolve_methods(_split(methods), _split(configs))
            for n in notes:
                if not quiet:
                    click.echo(f"bench: note: {n}", err=True)
            result = bench_lib.run(clean_files, protocol, method_list, seeds=seeds,
                                   settings=_split(settings), notes=notes, progress=progress,
                                   spec=spec, unread=unread)
        except MocapfixError as exc:
            _fail(ctx, exc, unread)
        tables = (lambda: result.to_markdown(per_file=per_file))
        to_json = (lambda: result.to_json(per_file=per_file))
    for u in unread:
        error_line(u["error"])
    if not result.files:        # nothing benchmarked: no table, no file that claims one
        error_line("no file could be read and used: nothing benchmarked, nothing written")
        sys.exit(EXIT_UNREADABLE)
    markdown = tables()
    try:
        if json_out:
            atomic_write_text(json_out, to_json() + "\n")
        if md_out:
            atomic_write_text(md_out, markdown)
    except MocapfixError as exc:
        _fail(ctx, exc)
    if not quiet:
        click.echo(markdown)
    if unread:
        sys.exit(EXIT_SOME_FAILED)
