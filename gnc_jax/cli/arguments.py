"""Argument types that answer bad input in one line naming the option, and the option
groups several subcommands share."""

import argparse
import re

from .exit_codes import EXIT_FAILED_RUNS, MAX_FAILED


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


def _max_hours(q, what: str = "a study") -> None:
    from ..montecarlo import MAX_HOURS

    q.add_argument(
        "--max-hours",
        type=_hours,
        default=MAX_HOURS,
        help=f"refuse {what} whose cost estimate exceeds this (default {MAX_HOURS:g} h)",
    )


def _max_failed(q, what: str = "runs") -> None:
    q.add_argument(
        "--max-failed",
        type=_fraction("--max-failed"),
        default=MAX_FAILED,
        help=f"exit {EXIT_FAILED_RUNS} when more than this fraction of {what} failed "
        f"(default {MAX_FAILED:g})",
    )


def _study_limits(q) -> None:
    _max_hours(q)
    _max_failed(q)


def _device(q) -> None:
    q.add_argument(
        "--device",
        choices=("cpu", "gpu", "auto"),
        default=None,
        help="where the runs run: cpu, gpu (needs JAX's GPU build: pip install "
        "'gnc_jax[cuda12]') or auto (default: a GPU where JAX finds one)",
    )
