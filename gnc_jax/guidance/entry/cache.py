"""The designed references, kept on disk: each designed once per entry, vehicle and design
setting (:func:`reference_for`), then found in the user's cache or in the copies packaged with
gnc_jax (``gnc_jax/guidance/entry/references/``)."""

import hashlib
import importlib.resources
import json
import os
import pathlib
import sys

import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from ...schema import ScenarioError
from .design import design_at_the_edge, design_with_fallback, edge_notice
from .design_reach import require_design_reach
from .nominal import NominalProblem
from .reach import require_reachable
from .reference import ReferenceTrajectory
from .tabulate import tabulate_reference

#: bump when the design procedure changes, so that cached references are redesigned
REFERENCE_VERSION = 5


def cache_dir():
    """Where designed references are kept: ``$GNC_JAX_CACHE`` or ``~/.cache/gnc_jax``."""
    return pathlib.Path(os.environ.get("GNC_JAX_CACHE", pathlib.Path.home() / ".cache" / "gnc_jax"))


_MEMORY: dict = {}


def reference_for(problem: NominalProblem, description: dict, **design_kwargs):
    """The designed reference of ``problem``, designed once and cached.

    ``description`` (JSON-serialisable) identifies the problem; its hash names the cache file
    (``reference-<hash>.npz`` in :func:`cache_dir`, then the packaged copy shipped with
    gnc_jax). It holds the scenario's ``entry`` and ``vehicle`` sections, which the refusals
    quote. A cache miss first refuses a target the design cannot reach
    (:func:`~gnc_jax.guidance.entry.reach.require_reachable` and
    :func:`~gnc_jax.guidance.entry.design_reach.require_design_reach`, a few seconds), then runs
    :func:`~gnc_jax.guidance.entry.design.design` (about a minute), refuses a design that did
    not converge (:func:`~gnc_jax.guidance.entry.design.require_design`), tabulates the
    reference (:func:`~gnc_jax.guidance.entry.tabulate.tabulate_reference`, about 20 s) and
    saves it. Returns ``(ReferenceTrajectory, DesignResult-like dict)``.
    """
    blob = json.dumps(
        {"problem": description, "design": design_kwargs, "version": REFERENCE_VERSION},
        sort_keys=True,
    )
    digest = hashlib.sha256(blob.encode()).hexdigest()[:16]
    if digest in _MEMORY:
        return _MEMORY[digest]
    name = f"reference-{digest}.npz"
    packaged = importlib.resources.files("gnc_jax.guidance.entry") / "references" / name
    path = cache_dir() / name
    source = path if path.is_file() else (packaged if packaged.is_file() else None)
    if source is not None:
        with source.open("rb") as fh:
            data = dict(np.load(fh))
        if "edge_notice" in data:  # designed at the edge of the footprint: say it again
            print(str(data["edge_notice"]), file=sys.stderr, flush=True)
    else:
        entry, vehicle = description["entry"], description["vehicle"]
        print(
            "gnc_jax: designing the reference trajectory of this entry and vehicle (once; the "
            "first design of a process compiles, 1-3 min, later ones take about 10 s; cached in "
            f"{path})",
            file=sys.stderr,
            flush=True,
        )
        steps = design_kwargs.get("steps", 20)
        # stages: the reach check, the optimiser's steps, the tabulation; the first of each
        # compiles, so the bar's rate is only a rough guide
        with tqdm(total=steps + 2, desc="reference design", unit="stage", file=sys.stderr) as bar:
            bar.set_postfix_str("reach check")
            guess = design_kwargs.get("sigma_1_guess")
            try:
                _, _, nearest = require_reachable(problem, entry, vehicle, guess)
            except ScenarioError as refusal:  # beyond the design's banks: at the edge
                if not str(refusal).startswith("entry.range_km"):
                    raise
                nearest, edge = None, refusal
            if nearest is not None:  # inside the hull of the banks' ranges: in the design's?
                require_design_reach(problem, entry, vehicle)
            bar.update()

            retry = []

            def stepped(step, objective):
                if step == 1 and bar.n > 1:  # design_with_fallback's fine retry: more stages
                    retry.append(True)
                    bar.total += steps
                    bar.refresh()
                label = "fine-step retry, " if retry else ""
                bar.set_postfix_str(f"{label}step {step}/{steps}, objective {objective:.4g}")
                bar.update()

            notice = None
            if nearest is None:
                d = design_at_the_edge(problem, entry, vehicle, edge)
                notice = edge_notice(entry, d)
            else:
                kwargs = dict(design_kwargs, sigma_1_guess=nearest if guess is None else guess)
                d = design_with_fallback(problem, entry, vehicle, callback=stepped, **kwargs)
            bar.set_postfix_str("tabulating the reference")
            ref = tabulate_reference(problem, d)
            bar.update()
        data = {f: np.asarray(getattr(ref, f)) for f in ReferenceTrajectory.__dataclass_fields__}
        data["objective_history"] = np.asarray(d.objective_history)
        if notice is not None:
            data["edge_notice"] = np.asarray(notice)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savez(path, **data)
        except OSError:  # read-only home: keep it in memory only
            pass
    ref = ReferenceTrajectory(
        **{f: jnp.asarray(data[f]) for f in ReferenceTrajectory.__dataclass_fields__}
    )
    info = {"digest": digest, "objective_history": data["objective_history"].tolist()}
    _MEMORY[digest] = (ref, info)
    return ref, info
