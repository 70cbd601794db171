"""Command line: ``gnc-jax list | run | reproduce | envelope | report | tune``.

Every command is one or two calls of the Python API (``gnc_jax.load_scenario``,
``gnc_jax.run_study``, ``Study.save``, ``gnc_jax.reproduce``, ``gnc_jax.report``). Bad input
stops before anything is compiled, with one line naming the field and the allowed values.

The commands import the package inside their functions, on purpose: ``--help`` and argument
errors answer at once, without starting JAX, and JAX is configured by ``gnc_jax`` before use.
"""

import argparse
import os
import pathlib
import re
import sys
import traceback

EXIT_REFUSED = 2  # bad input (or a runaway cost), refused before anything was compiled
EXIT_FAILED_RUNS = 3  # the study ran and its results were written, but too many runs failed
EXIT_INTERNAL = 4  # an unexpected error inside gnc_jax (a bug: please report it)
EXIT_ALL_FAILED = EXIT_FAILED_RUNS  # earlier name
MAX_FAILED = 0.01
"""Default of ``--max-failed``: the fraction of failed runs above which a study exits 3."""
DEBUG_ENV = "GNC_JAX_DEBUG"  # set to 1 to get the traceback of an internal error


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line instead of usage + message
        message = re.sub(r"^argument (\S+): \1: ", r"\1: ", message)  # our types name it
        self.exit(2, f"gnc-jax: error: {message} (see {self.prog} --help)\n")


def _number(name, convert, ok, allowed):
    """An argparse type: ``convert(text)`` checked by ``ok``; one line naming ``name`` else."""

    def parse(text):
        try:
            value = convert(text)
        except ValueError:
            value = None
        if value is None or not ok(value):
            raise argparse.ArgumentTypeError(f"{name}: {text!r}; allowed: {allowed}")
        return value

    return parse


def _positive_int(name):
    return _number(name, int, lambda v: v >= 1, "an integer >= 1")


_seed = _number("--seed", int, lambda v: 0 <= v < 2**32, "an integer in [0, 2^32)")
_hours = _number("--max-hours", float, lambda v: 0 < v < float("inf"), "a number > 0")


def _fraction(name):
    return _number(name, float, lambda v: 0 <= v <= 1, "a number in [0, 1]")


def _too_many_failed(summary: dict, max_failed: float) -> bool:
    return summary["failed"] > max_failed * summary["runs"]


def _print_summary(summary: dict) -> None:
    skip = {"paper", "firings_histogram", "failed_by_status", "description", "warnings"}
    width = max(len(k) for k in summary)
    for key, value in summary.items():
        if key in skip:
            continue
        text = f"{value:.4g}" if isinstance(value, float) else str(value)
        if isinstance(value, list) and value and all(isinstance(v, float) for v in value):
            text = "[" + ", ".join(f"{v:.4g}" for v in value) + "]"
        print(f"  {key:<{width}}  {text}")
    if summary.get("failed_by_status"):
        print(f"  {'failed_by_status':<{width}}  {summary['failed_by_status']}")
    if summary.get("firings_histogram"):
        print(f"  {'firings_histogram':<{width}}  {summary['firings_histogram']}")
    from .reproduction import comparison_rows

    rows = comparison_rows(summary)
    if rows:
        print("  paper vs gnc_jax:")
        for metric, paper, ours in rows:
            print(f"    {metric:<16} {paper:>10} {ours:>10}")


def _print_warnings(scenario) -> None:
    """The scenario's warnings (valid but doubtful settings), one line each, on stderr."""
    from .systems import get_system

    for line in get_system(scenario.kind).warnings(scenario.config):
        print(f"gnc-jax: warning: {line}", file=sys.stderr)


def cmd_list(args) -> int:
    from .scenario import list_scenarios
    from .systems import systems

    if args.fields:
        for kind, system in systems().items():
            print(f"[{kind}]  {system.description}")
            for section, fields in system.schema().items():
                for name, f in fields.items():
                    print(
                        f"  {section}.{name} = {f.default!r}   # {f.allowed()}"
                        + (f"; {f.doc}" if f.doc else "")
                    )
        return 0
    scenarios = list_scenarios()
    width = max(len(s.name) for s in scenarios)
    print(f"{'scenario':<{width}}  {'kind':<9} {'runs':>5}  description")
    for s in scenarios:
        print(f"{s.name:<{width}}  {s.kind:<9} {s.runs:>5}  {s.description}")
    return 0


def _writable_dir(path) -> None:
    """Create ``path`` (and its parents) and check that files can be written in it, before
    any work is spent; raise :class:`~gnc_jax.scenario.ScenarioError` naming it otherwise."""
    import pathlib
    import tempfile

    from .scenario import ScenarioError

    try:
        out = pathlib.Path(path)
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as e:
        raise ScenarioError(
            f"--out {path}: cannot create or write there ({e.strerror or e}); allowed: a "
            "directory that can be created and written"
        ) from None


def _connect(address: str):
    """A Dask client of the scheduler at ``address``, or one line saying why not."""
    from .scenario import ScenarioError

    try:
        from dask.distributed import Client
    except ImportError:
        raise ScenarioError(
            "--scheduler: needs dask.distributed; allowed: pip install 'gnc_jax[cluster]'"
        ) from None
    try:
        return Client(address, timeout=10)
    except (OSError, TimeoutError, ValueError) as e:
        raise ScenarioError(
            f"--scheduler {address}: cannot connect ({type(e).__name__}: {e}); allowed: the "
            "address of a running Dask scheduler, e.g. tcp://host:8786"
        ) from None


def cmd_run(args) -> int:
    from .scenario import ScenarioError, load_scenario
    from .study import run_study

    scenario = load_scenario(args.scenario, overrides=args.set or ())
    if args.out:
        _writable_dir(args.out)
    elif args.resume or args.overwrite:
        raise ScenarioError("--resume/--overwrite: no --out DIR; allowed: with --out DIR")
    _print_warnings(scenario)
    client = None
    if args.scheduler:
        client = _connect(args.scheduler)
    try:
        study = run_study(
            scenario,
            runs=args.runs,
            seed=args.seed,
            chunk_size=args.chunk_size,
            progress=False if args.no_progress else None,
            max_hours=args.max_hours,
            out=args.out,
            resume=args.resume,
            overwrite=args.overwrite,
            client=client,
            workers=args.workers,
        )
    finally:
        if client is not None:
            client.close()
    summary = study.summary()
    print(
        f"{scenario.name}: {study.runs} runs, compile {study.compile_s:.1f} s, "
        f"study {study.wall_s:.2f} s on {study.n_devices} devices"
    )
    _print_summary(summary)
    if args.set:
        print("  (modified by --set: the paper's numbers are for the packaged scenario)")
    if args.out:
        print(f"wrote {args.out}/summary.json, {args.out}/runs/ ({study.runs} runs), scenario.toml")
    if _too_many_failed(summary, args.max_failed):
        print(
            f"gnc-jax: {summary['failed']} of {summary['runs']} runs failed "
            f"({summary['failed_by_status']}), more than --max-failed {args.max_failed:g}",
            file=sys.stderr,
        )
        return EXIT_FAILED_RUNS
    return 0


def cmd_reproduce(args) -> int:
    from .reproduction import reproduce
    from .scenario import ScenarioError, packaged_names

    unknown = sorted(set(args.only or ()) - set(packaged_names()))
    if unknown:
        raise ScenarioError(
            f"--only {unknown[0]}: unknown scenario; allowed: {', '.join(packaged_names())}"
        )
    _writable_dir(args.out)

    summaries = reproduce(
        args.out,
        runs=args.runs,
        only=args.only,
        progress=False if args.no_progress else None,
        max_hours=args.max_hours,
    )
    print(f"wrote {args.out}/reproduce.md")
    bad = [s for s in summaries if _too_many_failed(s, args.max_failed)]
    if bad:
        names = ", ".join(f"{s['scenario']} ({s['failed']}/{s['runs']})" for s in bad)
        print(
            f"gnc-jax: failed runs above --max-failed {args.max_failed:g}: {names}", file=sys.stderr
        )
        return EXIT_FAILED_RUNS
    return 0


def cmd_envelope(args) -> int:
    from .operating_envelope import envelope
    from .scenario import load_scenario

    scenario = load_scenario(args.scenario, overrides=args.set or ())
    _writable_dir(args.out)
    _print_warnings(scenario)
    options = {} if args.load_limit_g is None else {"load_limit_g": args.load_limit_g}
    client = None
    if args.scheduler:
        client = _connect(args.scheduler)
    elif args.workers:
        from .montecarlo import local_cluster

        client = local_cluster(args.workers)
    try:
        env = envelope(
            scenario,
            args.grid,
            runs=args.runs,
            seed=args.seed,
            out=args.out,
            progress=True,
            client=client,
            **options,
        )
    finally:
        if client is not None:
            cluster = client.cluster if args.workers else None
            client.close()
            if cluster is not None:
                cluster.close()
    print(f"wrote {args.out}/cells.parquet and {len(env.metrics)} heat maps")
    return 0


def cmd_report(args) -> int:
    from .report import report

    for path in report(args.dir, args.out):
        print(f"wrote {path}")
    return 0


def _where(q) -> None:
    where = q.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=_positive_int("--workers"),
        default=None,
        help="run the chunks on a local Dask cluster of N worker processes",
    )
    where.add_argument(
        "--scheduler",
        default=None,
        metavar="tcp://HOST:PORT",
        help="run the chunks on an existing Dask cluster",
    )


def cmd_tune(args) -> int:
    from .scenario import load_scenario
    from .tuning import progress_line, tune

    scenario = load_scenario(args.scenario, overrides=args.set or ())
    _writable_dir(args.out)
    names = [n.strip() for n in args.params.split(",") if n.strip()]
    result = tune(
        scenario,
        names,
        args.objective,
        batch=args.batch,
        steps=args.steps,
        seed=args.seed,
        method=args.method,
        learning_rate=args.learning_rate,
        heldout_runs=args.heldout,
        eval_every=args.eval_every,
        eval_runs=args.eval_runs,
        callback=lambda rec: print(progress_line(rec, names), flush=True),
    )
    print(
        f"{scenario.name}: {args.method}, {args.steps} steps of {args.batch} runs, compile "
        f"{result.compile_s:.1f} s, training {result.wall_s:.1f} s"
    )
    for name, a, b in zip(names, result.initial, result.tuned, strict=True):
        print(f"  {name}: {a:.6g} -> {b:.6g}")
    print(result.table())
    paths = result.save(args.out)
    print("wrote " + ", ".join(paths.values()))
    return 0


def _study_limits(q) -> None:
    from .montecarlo import MAX_HOURS

    q.add_argument(
        "--max-hours",
        type=_hours,
        default=MAX_HOURS,
        help=f"refuse a study whose cost estimate exceeds this (default {MAX_HOURS:g} h)",
    )
    q.add_argument(
        "--max-failed",
        type=_fraction("--max-failed"),
        default=MAX_FAILED,
        help=f"exit {EXIT_FAILED_RUNS} when more than this fraction of runs failed "
        f"(default {MAX_FAILED:g})",
    )


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="gnc-jax", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    q = sub.add_parser("list", help="list the packaged scenarios")
    q.add_argument("--fields", action="store_true", help="list every scenario field instead")
    q.set_defaults(func=cmd_list)

    q = sub.add_parser("run", help="run a Monte Carlo study of one scenario")
    q.add_argument("scenario", help="packaged scenario name (gnc-jax list) or a .toml path")
    q.add_argument(
        "--runs",
        type=_positive_int("--runs"),
        default=None,
        help="number of runs (default: the paper's)",
    )
    q.add_argument("--seed", type=_seed, default=None, help="root seed (default: scenario's)")
    q.add_argument(
        "--out",
        default=None,
        help="study directory: runs/ (Parquet chunks, written as they finish), summary.json, "
        "scenario.toml",
    )
    q.add_argument(
        "--set",
        action="append",
        metavar="SECTION.FIELD=VALUE",
        help="override a scenario field (repeatable), e.g. --set guidance.k1=3",
    )
    q.add_argument(
        "--chunk-size",
        type=_positive_int("--chunk-size"),
        default=None,
        help="runs per compiled call (results do not depend on it)",
    )
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    q.add_argument(
        "--resume",
        action="store_true",
        help="continue the study in --out (finished chunks are kept)",
    )
    q.add_argument(
        "--overwrite", action="store_true", help="replace a study already in --out as a whole"
    )
    _where(q)
    _study_limits(q)
    q.set_defaults(func=cmd_run)

    q = sub.add_parser("reproduce", help="every paper scenario, paper vs gnc_jax")
    q.add_argument("--out", required=True, help="output directory")
    q.add_argument(
        "--runs",
        type=_positive_int("--runs"),
        default=None,
        help="override every scenario's run count (quick check)",
    )
    q.add_argument("--only", nargs="+", default=None, help="only these scenarios")
    q.add_argument("--no-progress", action="store_true")
    _study_limits(q)
    q.set_defaults(func=cmd_reproduce)

    q = sub.add_parser("envelope", help="a grid of studies over scenario fields, heat maps")
    q.add_argument("scenario", help="packaged scenario name (gnc-jax list) or a .toml path")
    q.add_argument(
        "--grid",
        action="append",
        required=True,
        metavar="SECTION.FIELD=A:B:N",
        help="an axis: N values from A to B (or V1,V2,...); repeatable, e.g. "
        "--grid entry.fpa_deg=-6.5:-5.5:5 --grid entry.range_km=2500:10000:4",
    )
    q.add_argument("--runs", type=_positive_int("--runs"), default=200, help="runs per cell")
    q.add_argument("--seed", type=_seed, default=None, help="root seed (default: scenario's)")
    q.add_argument("--out", required=True, help="directory for cells.parquet and the PNGs")
    q.add_argument("--set", action="append", metavar="SECTION.FIELD=VALUE", help="override a field")
    q.add_argument(
        "--load-limit-g",
        type=_number("--load-limit-g", float, lambda v: 0 < v < 100, "a number in (0, 100)"),
        default=None,
        help="capsule: the entry corridor's load limit (default 10 g)",
    )
    _where(q)
    q.set_defaults(func=cmd_envelope)

    q = sub.add_parser("tune", help="tune guidance gains on dispersed runs (gradients)")
    q.add_argument("scenario", help="packaged scenario name (gnc-jax list) or a .toml path")
    q.add_argument(
        "--params", required=True, help="comma-separated gains: guidance.los.k1,guidance.los.k2"
    )
    q.add_argument(
        "--objective",
        default=None,
        help="e.g. 'miss_rms+10*dv_mean' (terms: miss_rms, dv_mean, hit_probability, chute_rms, "
        "peak_load(LIMIT_G)); default: the system's smooth objective",
    )
    q.add_argument("--batch", type=_positive_int("--batch"), default=64, help="runs per step")
    q.add_argument("--steps", type=_positive_int("--steps"), default=40, help="optimiser steps")
    q.add_argument("--seed", type=_seed, default=0, help="root seed of the run keys")
    q.add_argument("--out", required=True, help="directory for tuned.toml, training.png, ...")
    q.add_argument(
        "--set",
        action="append",
        metavar="SECTION.FIELD=VALUE",
        help="override a scenario field before tuning (repeatable)",
    )
    q.add_argument(
        "--method", choices=("adam", "es"), default="adam", help="adam (gradients) or es"
    )
    q.add_argument(
        "--learning-rate",
        type=_number("--learning-rate", float, lambda v: 0 < v < float("inf"), "a number > 0"),
        default=0.1,
        help="Adam step in log-gain units (default 0.1: 10 %%)",
    )
    q.add_argument(
        "--heldout",
        type=_number("--heldout", int, lambda v: v >= 0, "an integer >= 0"),
        default=1000,
        help="held-out runs of the paired evaluation (default 1000)",
    )
    q.add_argument(
        "--eval-every",
        type=_number("--eval-every", int, lambda v: v >= 0, "an integer >= 0"),
        default=0,
        help="evaluate the held-out objective every this many steps (0: only at the end)",
    )
    q.add_argument(
        "--eval-runs", type=_positive_int("--eval-runs"), default=256, help="runs of those"
    )
    q.set_defaults(func=cmd_tune)

    q = sub.add_parser("report", help="PNG figures of a study directory")
    q.add_argument("dir", help="directory written by gnc-jax run --out")
    q.add_argument("--out", default=None, help="where to write the PNGs (default: DIR)")
    q.set_defaults(func=cmd_report)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    import gnc_jax  # noqa: F401  (float64 and host devices before JAX starts)

    from .results import ResultsError
    from .scenario import ScenarioError
    from .study import StudyError

    try:
        return args.func(args)
    except (ScenarioError, ResultsError) as e:
        print(f"gnc-jax: error: {e}", file=sys.stderr)
        return EXIT_REFUSED
    except StudyError as e:
        print(f"gnc-jax: error: {e}", file=sys.stderr)
        return EXIT_FAILED_RUNS
    except KeyboardInterrupt:
        print("gnc-jax: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # a bug: one line, the traceback on request
        if os.environ.get(DEBUG_ENV):
            raise
        where = traceback.extract_tb(e.__traceback__)[-1]
        first = str(e).splitlines()[0] if str(e) else ""
        print(
            f"gnc-jax: internal error: {type(e).__name__}: {first}"
            f" (at {pathlib.Path(where.filename).name}:{where.lineno}; this is a bug, please "
            f"report it; {DEBUG_ENV}=1 shows the traceback)",
            file=sys.stderr,
        )
        return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
