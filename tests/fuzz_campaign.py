"""The long fuzz campaign, on demand::

    python tests/fuzz_campaign.py --per-family 200 --timeout 300 --out fuzz.json

draws ``--per-family`` cases per registered system with the strategies of
``tests/fuzzing.py`` (hypothesis, generation only, seed ``--seed``), runs each in a worker
process with a per-case time limit (a case over it is killed and counted as a ``hang``, and
the worker restarted), writes the counts per family and every failing case with its overrides
(a reproducer, minimised by dropping overrides that do not matter) to ``--out``, and prints a
table. ``--systems`` restricts the families; the toy system of ``tests/toy_system.py`` is
included when named (it is a test fixture, not a product).

Reproduce one case::

    python -c "import gnc_jax as gj; s = gj.get_system('intercept'); \
gj.run_study(gj.load_scenario(s.example, {**s.test_overrides, 'guidance.dt_s': 1e-300}), runs=2)"
"""

import argparse
import datetime
import json
import os
import pathlib
import platform
import selectors
import shutil
import signal
import subprocess
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))


class Worker:
    """A process that runs cases (``python fuzz_campaign.py --worker``) one JSON line at a
    time, killed and restarted when a case exceeds its time limit or the process dies."""

    def __init__(self, log_path: str | os.PathLike | None = None):
        self.log_path = log_path
        # designed references (the capsule's) go to a scratch cache, not the user's
        self.cache = tempfile.mkdtemp(prefix="gnc_jax_fuzz_cache_")
        self.proc: subprocess.Popen | None = None
        self.started = 0

    def _start(self):
        env = dict(os.environ, GNC_JAX_CACHE=self.cache)
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(HERE.parent), env.get("PYTHONPATH", "")) if p
        )
        log = open(self.log_path, "a") if self.log_path else subprocess.DEVNULL  # noqa: SIM115
        self.proc = subprocess.Popen(
            [sys.executable, str(HERE / "fuzz_campaign.py"), "--worker"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=log,
            text=True,
            env=env,
        )
        self.started += 1
        ready = self._read_line(120.0)
        if ready != "ready":
            raise RuntimeError(f"fuzz worker did not start: {ready!r}")

    def _read_line(self, timeout: float) -> str | None:
        with selectors.DefaultSelector() as sel:
            sel.register(self.proc.stdout, selectors.EVENT_READ)
            if not sel.select(timeout):
                return None
            line = self.proc.stdout.readline()
        return line.strip() if line else ""

    def kill(self):
        if self.proc is not None and self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        self.proc = None

    def stop(self):
        self.kill()
        shutil.rmtree(self.cache, ignore_errors=True)

    def run(self, case, timeout: float):
        """The :class:`fuzzing.Result` of ``case``, at most ``timeout`` seconds after it is
        sent (then ``hang``, and the worker is restarted for the next case)."""
        from fuzzing import Result

        if self.proc is None or self.proc.poll() is not None:
            self._start()
        t0 = time.perf_counter()
        request = {"system": case.system, "overrides": case.overrides, "outside": case.outside}
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        line = self._read_line(timeout)
        seconds = time.perf_counter() - t0
        if line is None:
            self.kill()
            return Result("hang", f"over the {timeout:g} s limit", seconds)
        if not line:
            code = self.proc.wait()
            self.proc = None
            return Result("traceback", f"the worker process died (exit code {code})", seconds)
        return Result(**json.loads(line))


def _serve():
    """Worker side: read cases from stdin, write results to stdout (one JSON line each)."""
    import dataclasses

    protocol = os.fdopen(os.dup(sys.stdout.fileno()), "w", buffering=1)
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # prints of the package go to the log
    sys.stdout = sys.stderr
    import fuzzing
    import toy_system  # noqa: F401  (registers the toy system)

    protocol.write("ready\n")
    for line in sys.stdin:
        request = json.loads(line)
        case = fuzzing.Case(request["system"], request["overrides"], tuple(request["outside"]))
        print(f"case {request}", file=sys.stderr, flush=True)
        result = fuzzing.run_case(case)
        print(f"-> {result.outcome} {result.seconds:.1f} s {result.message[:300]}", file=sys.stderr)
        protocol.write(json.dumps(dataclasses.asdict(result)) + "\n")


def _minimise(worker, case, outcome: str, timeout: float):
    """Drop overrides one at a time while the case still comes to ``outcome``."""
    from fuzzing import Case

    overrides = dict(case.overrides)
    for key in list(overrides):
        if len(overrides) == 1:
            break
        trial = {k: v for k, v in overrides.items() if k != key}
        if (
            key != "guidance.law"
            and worker.run(Case(case.system, trial), timeout).outcome == outcome
        ):
            overrides = trial
    return overrides


def _recorder(worker, timeout, name, tally, records, failures):
    """The body of one family's campaign: run a case, count it, keep it."""
    from fuzzing import FAILURES

    def record(case):
        result = worker.run(case, timeout)
        tally["tried"] += 1
        tally[result.outcome] += 1
        tally["seconds_total"] += result.seconds
        tally["seconds_max"] = max(tally["seconds_max"], result.seconds)
        entry = dict(system=name, overrides=case.overrides, **vars(result))
        records.append(entry)
        print(
            f"{name:14s} {tally['tried']:4d} {result.outcome:9s} {result.seconds:6.1f} s "
            f"{json.dumps(case.overrides)[:110]}",
            flush=True,
        )
        if result.outcome in FAILURES:
            failures.append(entry)

    return record


def campaign(systems, per_family: int, timeout: float, seed: int, log_path, minimise=True):
    """Run the campaign; ``(counts per family, failures, every case)``."""
    import fuzzing
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hseed

    worker = Worker(log_path)
    counts, failures, records = {}, [], []
    try:
        for name in systems:
            tally = dict.fromkeys(("tried", *fuzzing.OUTCOMES), 0)
            tally["seconds_total"] = tally["seconds_max"] = 0.0
            counts[name] = tally

            record = _recorder(worker, timeout, name, tally, records, failures)
            one = hseed(seed)(
                settings(
                    max_examples=per_family,
                    deadline=None,
                    database=None,
                    phases=[Phase.generate],
                    suppress_health_check=list(HealthCheck),
                )(given(case=fuzzing.cases(name))(record))
            )
            one()
        if minimise:
            for record in failures:
                if record["outcome"] != "hang":
                    case = fuzzing.Case(record["system"], record["overrides"])
                    record["minimal"] = _minimise(worker, case, record["outcome"], timeout)
    finally:
        worker.stop()
    for tally in counts.values():
        tally["seconds_total"] = round(tally["seconds_total"], 1)
        tally["seconds_max"] = round(tally["seconds_max"], 1)
    return counts, failures, records


def table(counts: dict) -> str:
    columns = ("tried", "ran", "refused", "flagged", "traceback", "hang", "nan_stats", "invariant")
    lines = [f"{'family':14s} " + " ".join(f"{c:>9s}" for c in columns) + "   wall s (max case)"]
    for name, tally in counts.items():
        cells = " ".join(f"{tally[c]:9d}" for c in columns)
        lines.append(
            f"{name:14s} {cells}   {tally['seconds_total']:.0f} ({tally['seconds_max']:.0f})"
        )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--per-family", type=int, default=200)
    parser.add_argument("--timeout", type=float, default=300.0, help="per-case limit, s")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--systems", default="", help="comma-separated (default: built-in)")
    parser.add_argument("--out", default="fuzz.json")
    parser.add_argument("--no-minimise", action="store_true")
    args = parser.parse_args(argv)
    if args.worker:
        return _serve()
    import toy_system  # noqa: F401  (the toy system, when --systems names it)

    import gnc_jax as gj

    builtin = [s for s in gj.systems() if s != "toy-intercept"]
    systems = [s for s in args.systems.split(",") if s] or builtin
    started = datetime.datetime.now().isoformat(timespec="seconds")
    t0 = time.perf_counter()
    counts, failures, records = campaign(
        systems,
        args.per_family,
        args.timeout,
        args.seed,
        str(args.out) + ".log",
        minimise=not args.no_minimise,
    )
    report = dict(
        started=started,
        wall_s=round(time.perf_counter() - t0, 1),
        machine=f"{platform.machine()} {os.cpu_count()} cores, {platform.python_version()}",
        per_family=args.per_family,
        timeout_s=args.timeout,
        seed=args.seed,
        counts=counts,
        failures=failures,
        cases=records,
    )
    pathlib.Path(args.out).write_text(json.dumps(report, indent=1, default=repr) + "\n")
    print(table(counts))
    print(f"{len(failures)} failing cases; details in {args.out}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
