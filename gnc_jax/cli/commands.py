"""The subcommands, one function each: ``args`` in, exit code out."""

import contextlib
import sys
from pathlib import Path

from .exit_codes import EXIT_FAILED_RUNS
from .output import _failed_runs_line, _print_summary, _print_warnings, _too_many_failed


def _writable_dir(path) -> bool:
    """Create ``path`` (and its parents) and check that files can be written in it, before
    any work is spent; raise :class:`~gnc_jax.scenario.ScenarioError` naming it otherwise.
    Returns whether ``path`` was created here."""
    import pathlib
    import tempfile

    from ..scenario import ScenarioError

    try:
        out = pathlib.Path(path)
        created = not out.exists()
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as e:
        raise ScenarioError(
            f"--out {path}: cannot create or write there ({e.strerror or e}); allowed: a "
            "directory that can be created and written"
        ) from None
    return created


@contextlib.contextmanager
def _out_dir(path):
    """``--out`` created and checked before any work (:func:`_writable_dir`; nothing for
    ``None``); removed again when the command stops (refused, interrupted) before writing
    anything into a directory it created."""
    created = path is not None and _writable_dir(path)
    try:
        yield
    except BaseException:
        if created and not any(Path(path).iterdir()):
            Path(path).rmdir()
        raise


def _device(args) -> None:
    """``--device`` checked before anything else (a GPU where JAX finds none: one line)."""
    from ..backend import select

    select(args.device)


def _connect(address: str):
    """A Dask client of the scheduler at ``address``, or one line saying why not."""
    from ..backend import require
    from ..scenario import ScenarioError

    client_class = require("dask.distributed", "--scheduler").Client
    try:
        return client_class(address, timeout=10)
    except (OSError, TimeoutError, ValueError) as e:
        raise ScenarioError(
            f"--scheduler {address}: cannot connect ({type(e).__name__}: {e}); allowed: the "
            "address of a running Dask scheduler, e.g. tcp://host:8786"
        ) from None


def cmd_list(args) -> int:
    from ..scenario import list_scenarios
    from ..systems import systems

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


def cmd_run(args) -> int:
    _device(args)
    from ..scenario import ScenarioError, load_scenario
    from ..study import run_study

    scenario = load_scenario(args.scenario, overrides=args.set or ())
    if not args.out and (args.resume or args.overwrite):
        raise ScenarioError("--resume/--overwrite: no --out DIR; allowed: with --out DIR")
    with _out_dir(args.out or None):
        _print_warnings(scenario)
        client = _connect(args.scheduler) if args.scheduler else None
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
                device=args.device,
            )
        finally:
            if client is not None:
                client.close()
    summary = study.summary()
    print(
        f"{scenario.name}: {study.runs} runs, compile {study.compile_s:.1f} s, "
        f"study {study.wall_s:.2f} s, write {study.write_s:.2f} s on {summary['machine']}"
    )
    _print_summary(summary)
    if args.set:
        print("  (modified by --set: the paper's numbers are for the packaged scenario)")
    if args.out:
        print(f"wrote {args.out}/summary.json, {args.out}/runs/ ({study.runs} runs), scenario.toml")
    if _too_many_failed(summary, args.max_failed):
        print(_failed_runs_line(summary, args.max_failed), file=sys.stderr)
        return EXIT_FAILED_RUNS
    return 0


def cmd_reproduce(args) -> int:
    from ..reproduction import reproduce
    from ..scenario import ScenarioError, packaged_names

    unknown = sorted(set(args.only or ()) - set(packaged_names()))
    if unknown:
        raise ScenarioError(
            f"--only {unknown[0]}: unknown scenario; allowed: {', '.join(packaged_names())}"
        )
    with _out_dir(args.out):
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
    _device(args)
    from ..operating_envelope import envelope
    from ..scenario import load_scenario

    scenario = load_scenario(args.scenario, overrides=args.set or ())
    with _out_dir(args.out):
        _print_warnings(scenario)
        client = None
        if args.scheduler:
            client = _connect(args.scheduler)
        elif args.workers:
            from ..montecarlo import local_cluster

            client = local_cluster(args.workers, "--workers")
        try:
            env = envelope(
                scenario,
                args.grid,
                runs=args.runs,
                seed=args.seed,
                out=args.out,
                progress=True,
                client=client,
                device=args.device,
                batch_cells=args.batch_cells,
                max_hours=args.max_hours,
            )
        finally:
            if client is not None:
                cluster = client.cluster if args.workers else None
                client.close()
                if cluster is not None:
                    cluster.close()
    print(f"wrote {args.out}/cells.parquet and {len(env.metrics)} heat maps")
    return 0


def cmd_budget(args) -> int:
    from ..budget import METHODS, budget
    from ..scenario import load_scenario

    scenario = load_scenario(args.scenario, overrides=args.set or ())
    with _out_dir(args.out):
        _print_warnings(scenario)
        result = budget(
            scenario,
            runs=args.runs,
            seed=args.seed,
            metrics=args.metrics,
            groups=True if args.groups else None,
            methods=tuple(args.methods or METHODS),
            max_hours=args.max_hours,
            progress=False if args.no_progress else None,
        )
        print(
            f"{scenario.name}: budget of {len(result.factors)} sources, {result.runs} runs per "
            f"design, compile {result.compile_s:.1f} s, wall {result.wall_s:.1f} s"
        )
        if result.inactive:
            print(f"  zero (left out): {', '.join(result.inactive)}")
        if result.linear_error:
            print(f"  linear method not available: {result.linear_error}")
        print(result)
        if args.out:
            paths = result.save(args.out)
            print("wrote " + ", ".join(str(p) for p in paths))
    failed = 1.0 - result.counts["all_on_ok"] / result.runs
    if failed > args.max_failed:
        print(
            f"gnc-jax: {failed:.1%} of the study's runs failed, more than --max-failed "
            f"{args.max_failed:g} (the budget keeps the runs that are ok in every design)",
            file=sys.stderr,
        )
        return EXIT_FAILED_RUNS
    return 0


def cmd_report(args) -> int:
    from ..report import report

    for path in report(args.dir, args.out):
        print(f"wrote {path}")
    return 0


def cmd_tune(args) -> int:
    _device(args)
    from ..scenario import load_scenario
    from ..tuning import progress_line, resolve_gains, tune, with_schedule_starts
    from ..tuning.result import save_interrupted

    scenario = load_scenario(args.scenario, overrides=args.set or ())
    names = [n.strip() for n in args.params.split(",") if n.strip()]
    history = []
    gain_names: list[str] = []  # one per tuned value: a schedule's knots each

    def step_done(rec):
        if not gain_names:  # tune has resolved the same names by its first step
            gains = resolve_gains(with_schedule_starts(scenario, names), names)
            gain_names.extend(g.name for g in gains)
        history.append(rec)
        print(progress_line(rec, gain_names), flush=True)

    with _out_dir(args.out):
        try:
            result = tune(
                scenario,
                names,
                args.objective,
                batch=args.batch,
                steps=args.steps,
                seed=args.seed,
                method=args.method,
                gradient=args.mode,
                learning_rate=args.learning_rate,
                sigma=args.sigma,
                population=args.population,
                heldout_runs=args.heldout,
                eval_every=args.eval_every,
                eval_runs=args.eval_runs,
                callback=step_done,
                device=args.device,
                max_hours=args.max_hours,
            )
        except KeyboardInterrupt:
            if history:  # the steps done are kept; the command still exits as interrupted
                path = save_interrupted(history, args.steps, args.out)
                print(
                    f"{scenario.name}: interrupted after {len(history)} of {args.steps} steps; "
                    f"their training record in {path}",
                    file=sys.stderr,
                )
            raise
    print(
        f"{scenario.name}: {args.method}"
        + (f" ({result.gradient} mode)" if result.gradient else "")
        + f", {args.steps} steps of {args.batch} runs, compile "
        f"{result.compile_s:.1f} s, training {result.wall_s:.1f} s"
    )
    for name, a, b in zip(result.names, result.initial, result.tuned, strict=True):
        print(f"  {name}: {a:.6g} -> {b:.6g}")
    print(result.table())
    paths = result.save(args.out)
    print("wrote " + ", ".join(paths.values()))
    heldout = result.heldout
    if heldout and _too_many_failed(
        dict(failed=heldout["failed"]["tuned"], runs=heldout["runs"]), args.max_failed
    ):
        print(
            f"gnc-jax: {heldout['failed']['tuned']} of {heldout['runs']} held-out runs failed "
            f"with the tuned gains ({heldout['failed']['initial']} with the initial gains), "
            f"more than --max-failed {args.max_failed:g}",
            file=sys.stderr,
        )
        return EXIT_FAILED_RUNS
    return 0
