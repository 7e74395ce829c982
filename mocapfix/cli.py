"""Command line: thin click commands over the library. Errors become one line and an
exit code (0 ok, 1 some files failed, 2 unreadable input or usage/config error)."""
from __future__ import annotations

import json
import sys

import click

from mocapfix import __version__
from mocapfix.errors import MocapfixError

EXIT_OK, EXIT_SOME_FAILED, EXIT_USAGE = 0, 1, 2


def _fail(message: str, debug: bool, exc: BaseException | None = None, code: int = EXIT_USAGE):
    if debug and exc is not None:
        raise exc
    click.echo(f"mocapfix: error: {message}", err=True)
    sys.exit(code)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="mocapfix")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
@click.pass_context
def main(ctx, debug):
    """Clean motion-capture files: ASF/AMC, BVH, C3D and Kinect skeleton text."""
    ctx.obj = {"debug": debug}


@main.command()
@click.argument("files", nargs=-1, required=True, type=click.Path())
@click.option("--json", "as_json", is_flag=True, help="Print a JSON list instead of text.")
@click.option("--fps", type=float, default=None,
              help="Frame rate for formats that do not store one (AMC; default 120).")
@click.pass_context
def info(ctx, files, as_json, fps):
    """Frames, rate, joints, units, gaps and tracking state of each FILE."""
    from mocapfix.formats import read
    from mocapfix.info import format_text, summarise

    debug = ctx.obj["debug"]
    summaries, failed = [], 0
    for path in files:
        try:
            options = {"fps": fps} if fps else {}
            summaries.append(summarise(read(path, **options)))
        except MocapfixError as exc:
            if debug:
                raise
            failed += 1
            click.echo(f"mocapfix: error: {exc}", err=True)
            summaries.append({"path": str(path), "error": str(exc)})
    if as_json:
        click.echo(json.dumps(summaries, indent=2))
    else:
        click.echo("\n".join(format_text(s) for s in summaries if "error" not in s))
    if failed:
        sys.exit(EXIT_USAGE)


if __name__ == "__main__":  # pragma: no cover
    main()
