"""The argument parser of ``gnc-jax``: one function per subcommand."""

import argparse

from ..tuning.objectives import term_forms
from .arguments import (
    _device,
    _max_failed,
    _max_hours,
    _number,
    _Parser,
    _positive_int,
    _seed,
    _study_limits,
    _where,
)
from .commands import (
    cmd_budget,
    cmd_envelope,
    cmd_list,
    cmd_report,
    cmd_reproduce,
    cmd_run,
    cmd_tune,
)

DESCRIPTION = (
    "Command line: ``gnc-jax list | run | reproduce | envelope | budget | report | tune``."
)
"""The parser's description: the first line of the package's docstring."""


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="gnc-jax", description=DESCRIPTION)
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _add_list(sub)
    _add_run(sub)
    _add_reproduce(sub)
    _add_envelope(sub)
    _add_budget(sub)
    _add_tune(sub)
    _add_report(sub)
    return p


def _add_list(sub) -> None:
    q = sub.add_parser("list", help="list the packaged scenarios")
    q.add_argument("--fields", action="store_true", help="list every scenario field instead")
    q.set_defaults(func=cmd_list)


def _add_run(sub) -> None:
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
    _device(q)
    _study_limits(q)
    q.set_defaults(func=cmd_run)


def _add_reproduce(sub) -> None:
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


def _add_envelope(sub) -> None:
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
        "--batch-cells",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="run the cells as one batch per compiled program (default: on a GPU)",
    )
    _max_hours(q, "an envelope")
    _where(q)
    _device(q)
    q.set_defaults(func=cmd_envelope)


def _add_budget(sub) -> None:
    q = sub.add_parser("budget", help="variance-based error budget: which source drives a metric")
    q.add_argument("scenario", help="packaged scenario name (gnc-jax list) or a .toml path")
    q.add_argument(
        "--runs",
        type=_number("--runs", int, lambda v: True, "an integer"),  # the bound: gj.budget's
        default=200,
        help="runs per design (default 200)",
    )
    q.add_argument("--seed", type=_seed, default=None, help="root seed (default: scenario's)")
    q.add_argument(
        "--metrics", nargs="+", default=None, help="metrics to decompose (default: the system's)"
    )
    q.add_argument(
        "--methods",
        nargs="+",
        default=None,
        help="any of sobol, oat, linear (default: all three)",
    )
    q.add_argument(
        "--groups", action="store_true", help="take the system's source groups as one source each"
    )
    q.add_argument("--out", default=None, help="directory for budget.json and budget.parquet")
    q.add_argument("--set", action="append", metavar="SECTION.FIELD=VALUE", help="override a field")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    _study_limits(q)
    q.set_defaults(func=cmd_budget)


def _add_tune(sub) -> None:
    q = sub.add_parser("tune", help="tune guidance gains on dispersed runs (gradients)")
    q.add_argument("scenario", help="packaged scenario name (gnc-jax list) or a .toml path")
    q.add_argument(
        "--params", required=True, help="comma-separated gains: guidance.los.k1,guidance.los.k2"
    )
    q.add_argument(
        "--objective",
        default=None,
        help=f"e.g. 'miss_rms+10*dv_mean' (terms over the ok runs: {term_forms()}; failed: "
        "the fraction of runs not ok, e.g. 'miss_rms+100*failed'); default: the system's "
        "smooth objective",
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
        "--method",
        choices=("adam", "es", "cma"),
        default="adam",
        help="adam (gradients), es or cma (CMA-ES: pip install 'gnc_jax[tune]')",
    )
    q.add_argument(
        "--mode",
        choices=("auto", "forward", "reverse"),
        default="auto",
        help="gradient mode of adam: forward (a tangent per gain), reverse (cost independent "
        "of the number of gains) or auto (the cheaper by the system's measured costs: reverse "
        "from 10 gains on, the capsule's from 1 on one device)",
    )
    q.add_argument(
        "--learning-rate",
        type=_number("--learning-rate", float, lambda v: 0 < v < float("inf"), "a number > 0"),
        default=0.1,
        help="step of Adam and of the ES's Adam in log-gain units (default 0.1: 10 %%)",
    )
    q.add_argument(
        "--sigma",
        type=_number("--sigma", float, lambda v: 0 < v < float("inf"), "a number > 0"),
        default=0.1,
        help="es and cma: the perturbation (CMA-ES's initial step) in log-gain units (default 0.1)",
    )
    q.add_argument(
        "--population",
        type=_positive_int("--population"),
        default=4,
        help="es: antithetic pairs per step; cma: half the candidates per generation",
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
    _max_hours(q, "a tuning")
    _max_failed(q, "the tuned gains' held-out runs")
    _device(q)
    q.set_defaults(func=cmd_tune)


def _add_report(sub) -> None:
    q = sub.add_parser("report", help="PNG figures of a study directory")
    q.add_argument("dir", help="directory written by gnc-jax run --out")
    q.add_argument("--out", default=None, help="where to write the PNGs (default: DIR)")
    q.set_defaults(func=cmd_report)
