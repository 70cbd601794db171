"""What :func:`~gnc_jax.tuning.tune` returns (:class:`TuneResult`): the tuned scenario,
the training history, the held-out table, and the files and figure it writes."""

import dataclasses
import json
import pathlib
from typing import Any

from ..scenario import Scenario
from .evaluation import heldout_table, ranking_key


@dataclasses.dataclass
class TuneResult:
    """What :func:`tune` returns.

    Attributes:
        scenario: the scenario as given; tuned_scenario: the same with the tuned gains.
        names: the tuned gains' scenario names; initial, tuned: their values (file units).
        objective: the objective's spec; method: ``"adam"`` or ``"es"``.
        history: one dict per step: ``step``, ``objective`` (training batch; smooth for adam,
            hard for es), ``gains``, ``temperature``, ``runs`` (simulated so far), ``wall_s``
            (after compilation, evaluations excluded), ``heldout`` and ``heldout_failed``
            (the objective and the failed runs on the ``eval_runs`` held-out runs) where
            evaluated, and
            ``nonfinite_gradient`` (adam) where that many gradient components were not finite
            and were taken as 0.
        heldout: the paired held-out evaluation (:func:`evaluate_heldout`), or ``None``.
        training_check: the hard objective on the first ``runs`` training runs of the start
            (``initial``), the last step (``last``) and the result (``tuned``, at
            ``selected_step``; -1: the start): a relaxation that misled the tuner shows there,
            without looking at the held-out runs, and ``failed``: the failed runs of each
            (``None`` when ``check_runs=0``).
        compile_s, wall_s: compilation and training wall time.
    """

    scenario: Scenario
    tuned_scenario: Scenario
    names: list[str]
    initial: list[float]
    tuned: list[float]
    objective: str
    method: str
    seed: int
    batch: int
    steps: int
    history: list[dict]
    heldout: dict | None
    compile_s: float
    wall_s: float
    training_check: dict | None = None
    gradient: str | None = None  # adam's gradient mode, "forward" or "reverse" (None: es, cma)

    @property
    def tuned_gains(self) -> dict[str, float]:
        return dict(zip(self.names, self.tuned, strict=True))

    def best_heldout(self) -> dict | None:
        """The ``eval_every`` held-out record that ranks first (``None`` without one), ranked
        as the tuner's checks rank (:func:`~.evaluation.ranking_key`): fewest failed runs, then
        the lowest objective, the earliest of equal records; the objective alone could pick a
        record that fails more runs. A target for :meth:`runs_to_reach`."""
        records = [h for h in self.history if h.get("heldout") is not None]
        rank = lambda h: ranking_key(h["heldout"], h.get("heldout_failed", 0))
        return min(records, key=rank, default=None)

    def runs_to_reach(self, target: float | dict, failed: int = 0):
        """``(runs, wall_s)`` at the first held-out evaluation that ranks no worse than the
        target (``None`` if none does): ``target`` is an objective reached with ``failed``
        failed held-out runs, or a held-out record of a history (another method's, whose
        ``heldout`` and ``heldout_failed`` it takes). Records rank as the tuner's checks do
        (:func:`~.evaluation.ranking_key`): fewer failed runs first, then the objective, so
        an evaluation that fails more runs never reaches the target."""
        if isinstance(target, dict):
            target, failed = target["heldout"], target.get("heldout_failed", 0)
        goal = ranking_key(target, failed)
        for h in self.history:
            if h.get("heldout") is not None:
                if ranking_key(h["heldout"], h.get("heldout_failed", 0)) <= goal:
                    return h["runs"], h["wall_s"]
        return None

    def table(self) -> str:
        lines = []
        c = self.training_check
        if c:
            at = "the start" if c["selected_step"] < 0 else f"step {c['selected_step']}"
            lines.append(
                f"training runs 0..{c['runs'] - 1}, hard logic: start {c['initial']:.5g}, last "
                f"step {c['last']:.5g}, result ({at}) {c['tuned']:.5g}"
            )
            failed = c.get("failed", {})
            if any(failed.values()):
                lines[-1] += " (failed runs: " + ", ".join(f"{k} {v}" for k, v in failed.items())
                lines[-1] += ")"
        lines.append(heldout_table(self.heldout) if self.heldout else "(no held-out evaluation)")
        return "\n".join(lines)

    def summary(self) -> dict[str, Any]:
        out = {
            k: getattr(self, k)
            for k in ("names", "initial", "tuned", "objective", "method", "seed", "batch")
        }
        if self.gradient:
            out["gradient"] = self.gradient
        out.update(steps=self.steps, compile_s=self.compile_s, wall_s=self.wall_s)
        out["training_check"] = self.training_check
        if self.heldout:
            out["heldout"] = {k: v for k, v in self.heldout.items() if k != "outcomes"}
        return out

    def save(self, out_dir) -> dict[str, str]:
        """Write ``tuned.toml`` (runnable with ``gnc-jax run``), ``training.json`` (history),
        ``heldout.json`` and ``training.png`` into ``out_dir``."""
        out = pathlib.Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {
            "tuned": out / "tuned.toml",
            "training": out / "training.json",
            "heldout": out / "heldout.json",
            "figure": out / "training.png",
        }
        paths["tuned"].write_text(self.tuned_scenario.to_toml())
        paths["training"].write_text(json.dumps(self.history, indent=1))
        paths["heldout"].write_text(json.dumps(self.summary(), indent=1))
        plot_training(self, paths["figure"])
        return {k: str(v) for k, v in paths.items()}


def save_interrupted(history: list[dict], steps: int, out_dir) -> pathlib.Path:
    """Write ``training.json`` of a tuning stopped before its result: ``{"interrupted": true,
    "steps": the steps asked for, "history": the records of the steps done}`` (a finished
    tuning's is the list of records alone)."""
    path = pathlib.Path(out_dir) / "training.json"
    record = dict(interrupted=True, steps=steps, history=history)
    path.write_text(json.dumps(record, indent=1))
    return path


def plot_training(result: TuneResult, path) -> None:
    """``training.png``: the objective and each gain per step."""
    from ..plotting import pyplot

    plt = pyplot()
    steps = [h["step"] for h in result.history]  # the gains and objective before its update
    fields: dict[str, list[int]] = {}  # a schedule's knots share an axis
    for i, name in enumerate(result.names):
        fields.setdefault(name.split("[")[0], []).append(i)
    n = len(fields)
    fig, axes = plt.subplots(n + 1, 1, figsize=(6.4, 2.0 * (n + 1)), sharex=True)
    axes[0].plot(steps, [h["objective"] for h in result.history], label="training batch")
    relaxed = any(h.get("temperature") is not None for h in result.history)
    label = "training batch" + (
        " (relaxed)" if relaxed else " (hard)" if result.method == "es" else ""
    )
    axes[0].lines[0].set_label(label)
    # a check after step s's update is of the gains plotted at s + 1
    checks = [(h["step"] + 1, h["check"]) for h in result.history if h.get("check") is not None]
    if result.training_check:
        checks.insert(0, (0, result.training_check["initial"]))
    if checks:
        axes[0].plot(*zip(*checks, strict=True), "s", label="hard check, training runs")
    ev = [(h["step"], h["heldout"]) for h in result.history if h.get("heldout") is not None]
    if ev:
        axes[0].plot(*zip(*ev, strict=True), "o-", label="held-out (hard)")
    axes[0].legend(fontsize=8)
    selected = (result.training_check or {}).get("selected_step")
    if selected is not None:
        for ax in axes:
            ax.axvline(selected + 1, color="0.6", lw=0.8, ls="--")
    axes[0].set_ylabel("objective")
    axes[0].set_title(f"{result.scenario.name}: {result.objective} ({result.method})", fontsize=9)
    for ax, (field, members) in zip(axes[1:], fields.items(), strict=True):
        for i in members:
            ax.plot(steps, [h["gains"][i] for h in result.history], lw=0.8)
        ax.set_ylabel(
            field.split(".")[-1] + (f" ({len(members)} knots)" if len(members) > 1 else "")
        )
    axes[-1].set_xlabel("step")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
