"""Command line: ``gnc-jax list | run | reproduce | envelope | budget | report | tune``.

Every command is one or two calls of the Python API (``gnc_jax.load_scenario``,
``gnc_jax.run_study``, ``Study.save``, ``gnc_jax.reproduce``, ``gnc_jax.report``). Bad input
stops before anything is compiled, with one line naming the field and the allowed values.

The commands import the package inside their functions, on purpose: ``--help`` and argument
errors answer at once, without starting JAX, and JAX is configured by ``gnc_jax`` before use.
"""

import os
import pathlib
import sys
import traceback

from .arguments import _seed
from .exit_codes import (
    DEBUG_ENV,
    EXIT_ALL_FAILED,
    EXIT_FAILED_RUNS,
    EXIT_INTERNAL,
    EXIT_REFUSED,
    MAX_FAILED,
)
from .output import _print_warnings
from .parser import build_parser


class _UntilThePipeCloses:
    """``sys.stdout`` while a command runs: once the reader of a pipe has stopped (``| head``)
    the rest of the output is dropped and the command carries on to its own exit code, so
    that a study whose runs failed still exits 3 however its summary was read."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._drop()
            return len(text)

    def flush(self):
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._drop()

    def _drop(self):
        try:  # the stream's own flush (at exit too) then writes to nothing
            os.dup2(os.open(os.devnull, os.O_WRONLY), self._stream.fileno())
        except (OSError, ValueError, AttributeError):
            self._stream = open(os.devnull, "w")  # noqa: SIM115  (lives as long as stdout)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    import gnc_jax  # noqa: F401  (float64 and host devices before JAX starts)

    from ..results import ResultsError
    from ..scenario import ScenarioError
    from ..study import StudyError

    stdout, sys.stdout = sys.stdout, _UntilThePipeCloses(sys.stdout)
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
    except BrokenPipeError:  # the output was piped to a reader that stopped (e.g. `| head`)
        try:  # Python's own flush at exit would fail again on the closed pipe
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 0
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
    finally:
        sys.stdout = stdout


__all__ = [
    "main",
    "build_parser",
    "EXIT_REFUSED",
    "EXIT_FAILED_RUNS",
    "EXIT_INTERNAL",
    "EXIT_ALL_FAILED",
    "MAX_FAILED",
    "DEBUG_ENV",
    "_seed",
    "_print_warnings",
]
