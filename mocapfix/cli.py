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


@main.command("cleaners")
@click.option("--markdown", is_flag=True, help="Print a Markdown table (as in the README).")
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


def _parse_reports(value: str) -> tuple[str, ...]:
    from mocapfix.clean import REPORT_KINDS

    kinds = tuple(k.strip().lower() for k in value.split(",") if k.strip())
    bad = [k for k in kinds if k not in REPORT_KINDS and k != "none"]
    if bad:
        raise click.BadParameter(f"unknown report kind(s) {', '.join(bad)}; use json, md, html or none")
    return tuple(k for k in kinds if k != "none")


@main.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path())
@click.option("-o", "--output", "outdir", required=True, type=click.Path(file_okay=False),
              help="Output folder; the input tree is mirrored inside it.")
@click.option("-c", "--config", "config_path", type=click.Path(dir_okay=False),
              help="Pipeline config (YAML). Default: the shipped configs/default.yaml.")
@click.option("--report", "reports", default="json", show_default=True,
              help="Reports to write beside each output: json, md, html (comma-separated) or none.")
@click.option("-j", "--jobs", default=1, show_default=True, type=click.IntRange(1, 256),
              help="Files cleaned in parallel (process pool).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary on stdout.")
@click.option("--fps", type=float, default=None, help="Frame rate for files that store none (AMC).")
@click.option("--allow-inside-input", is_flag=True,
              help="Allow the output folder to lie inside an input folder.")
@click.pass_context
def clean(ctx, inputs, outdir, config_path, reports, jobs, as_json, fps, allow_inside_input):
    """Clean INPUT files or folders with a pipeline of cleaners.

    Exit code 0 when every file was cleaned, 1 when some failed (the others are still
    written), 2 for a usage or config error.
    """
    from pathlib import Path

    from mocapfix.batch import discover, run_batch
    from mocapfix.fileio import atomic_write_text
    from mocapfix.pipeline import default_config_path, load_config

    debug = ctx.obj["debug"]
    try:
        kinds = _parse_reports(reports)
        pipeline = load_config(config_path or default_config_path())
        job_list = discover(inputs, outdir, allow_inside_input)
        if not job_list:
            raise MocapfixError("no motion files found in " + ", ".join(inputs))
    except click.BadParameter as exc:
        _fail(str(exc), debug, exc)
    except MocapfixError as exc:
        _fail(str(exc), debug, exc)
    Path(outdir).mkdir(parents=True, exist_ok=True)
    atomic_write_text(Path(outdir) / "mocapfix-config.yaml",
                      f"# effective config of this run (from {pipeline.source})\n" + pipeline.dump())
    results = run_batch(job_list, pipeline.config(), str(pipeline.source), kinds, jobs,
                        {"fps": fps} if fps else None)
    failed = [r for r in results if r["status"] == "ERROR"]
    if as_json:
        click.echo(json.dumps({"files": results, "cleaned": len(results) - len(failed),
                               "failed": len(failed), "config": str(pipeline.source)}, indent=1))
    else:
        for r in results:
            if r["status"] == "ERROR":
                click.echo(f"FAILED  {r['error']}", err=True)
            else:
                click.echo(f"{r['status']:<7} {r['input']} -> {r['output']} "
                           f"(missing {100 * r['missing_before']:.1f} % -> {100 * r['missing_after']:.1f} %, "
                           f"{r['seconds']:.2f} s)")
        click.echo(f"cleaned {len(results) - len(failed)} of {len(results)} files"
                   + (f"; {len(failed)} failed: " + ", ".join(r["input"] for r in failed) if failed else ""),
                   err=bool(failed))
    sys.exit(EXIT_SOME_FAILED if failed else EXIT_OK)


@main.command("train-dictionary")
@click.argument("training", nargs=-1, required=True, type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Model file to write (.npz).")
@click.option("--method", default="partlet", show_default=True,
              type=click.Choice(["partlet", "ksvd", "mssa"]),
              help="partlet: robust dictionary learning (Feng 2015); ksvd: K-SVD (Xiao 2015); "
                   "mssa: M-SSA filter bases (Lou 2012).")
@click.option("--atoms", type=click.IntRange(2, 4096), default=None, help="Atoms per partlet (default 128).")
@click.option("--window", type=click.IntRange(1, 200), default=None, help="Window length m in samples (default 8).")
@click.option("--sample-rate", default=None, help="Rate of the window samples, e.g. '30 Hz' (default).")
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
@click.option("--fps", type=float, default=None, help="Frame rate for files that store none (AMC).")
@click.pass_context
def train_dictionary(ctx, training, output, method, atoms, window, sample_rate, lam, beta,
                     iterations, max_windows, seed, bases, energy, jobs, fps):
    """Train a model for a trained cleaner from TRAINING files or folders (any format;
    BVH/AMC by forward kinematics) and write it to OUTPUT. Name it in a config with
    `model: PATH` (relative to the config file)."""
    from mocapfix.train import train

    debug = ctx.obj["debug"]
    bar = None
    if sys.stderr.isatty():
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
    try:
        summary = train(training, output, method, params, jobs, fps, progress)
    except MocapfixError as exc:
        _fail(str(exc), debug, exc)
    finally:
        if bar:
            bar.close()
    t = summary["training"]
    st = summary["state"]
    if method == "mssa":
        click.echo(f"wrote {output}: mssa, {st['bases']} bases of window {st['window']} over "
                   f"{len(st['layout'])} {st['space']} channels at {st['fps']:g} Hz; trained on "
                   f"{len(t['files'])} files, {t['frames']} frames in {t['seconds']:.1f} s; "
                   f"unexplained energy {100 * st['unexplained']:.3f} %")
        return
    click.echo(f"wrote {output}: {summary['cleaner']} ({st['method']}), {len(st['joints'])} joints in "
               f"{len(st['partlets'])} partlets, window {st['window']} at {st['sample_rate']:g} Hz; "
               f"trained on {len(t['files'])} files, {t['frames']} frames in {t['seconds']:.1f} s; "
               "unexplained energy " + ", ".join(f"{p} {100 * f:.2f} %" for p, f in st["unexplained"].items()))


def _register_bench():
    from mocapfix.bench_cli import bench

    main.add_command(bench)


_register_bench()

if __name__ == "__main__":  # pragma: no cover
    main()
