"""The capsule system's envelope pre-check: the entry corridor and the reachable footprints.

Before an envelope's cells are simulated, :func:`check_cells` flies the nominal vehicle open
loop (:mod:`gnc_jax.guidance.entry.corridor`) to mark the entry angles outside the corridor
infeasible and to report the footprint each target range must lie in; given the study's runs,
each run's own dispersed footprint too (:func:`dispersed_footprints`, :func:`reachability`).
:func:`draw_overlay` draws them on the envelope's heat maps.
"""

import math
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..._random import run_key
from ...dynamics.entry import entry_state_from_conditions
from ...geometry.sphere import unit
from ...guidance.entry.base import EntryModel
from ...guidance.entry.corridor import (
    DT_S,
    EntryEnvelope,
    target_crossrange_span,
    track_footprints,
)
from ...params import from_scenario, schema_of
from ...schema import ScenarioError
from . import simulation as capsule_sim
from .params import Entry, SimulationParams, capsule_params

FOOTPRINT_MARGIN = 0.1  # the acceptance's margin: 10 % of a footprint's width from each edge
FOOTPRINT_TAIL = 0.005  # the dispersed footprint: the ends all but 0.5 % of the runs reach
# runs whose footprints the envelope pre-check flies at most (the first ones of the study: the
# same draws); 2000 runs estimate a fraction near 99.5 % to about 0.2 % (one sigma) at about
# 30 s per entry angle, where a 10,000-run study's every run would take minutes
FOOTPRINT_RUNS_MAX = 2000


def entry_envelope(config: dict) -> EntryEnvelope:
    """The entry corridor and footprint (:class:`~gnc_jax.guidance.entry.corridor.EntryEnvelope`)
    of a validated capsule configuration's nominal vehicle, atmosphere and entry; the
    corridor's undershoot boundary at its ``simulation.load_limit_g``, the load beyond which
    a run reads ``overload``."""
    p = capsule_params(config)
    earth, vehicle, atmosphere, entry = capsule_sim.nominal_models(p)
    model = EntryModel(vehicle, earth, atmosphere)
    return EntryEnvelope(
        model,
        entry,
        p.entry.chute_altitude_m,
        p.simulation.max_time_s,
        float(p.simulation.load_limit_g),
    )


def require_within_load_limit(config: dict) -> None:
    """Refuse, before any design, an entry at which the nominal vehicle's full-lift-up flight
    already peaks above ``simulation.load_limit_g``: no bank history keeps such an entry
    within the limit, so every run would read ``overload``. The one line names
    ``entry.fpa_deg`` with the entry corridor's undershoot boundary (:func:`entry_envelope`,
    the envelope pre-check's), the steepest angle that full lift up keeps within the limit."""
    env = entry_envelope(config)
    fpa = config["entry"]["fpa_deg"]
    load = float(env.flights([fpa], [0.0]).peak_load_g[0, 0])
    if load <= env.load_limit_g:
        return
    field = schema_of(Entry)["fpa_deg"]  # its declared range bounds the corridor search
    steepest = env.corridor(field.lo, field.hi, 0.05).undershoot_deg
    allowed = (
        f"no entry angle in [{field.lo:g}, {field.hi:g}] deg at this speed and vehicle"
        if math.isnan(steepest)
        else f"{steepest:.2f} deg or shallower at this speed and vehicle"
    )
    raise ScenarioError(
        f"entry.fpa_deg: {fpa:g} deg; allowed: {allowed} (full lift up peaks at {load:.3g} g "
        f"here, above simulation.load_limit_g = {env.load_limit_g:g} g: every run would read "
        "overload)"
    )


def _run_models(sim, seed, indices):
    """Models and entry states of the runs ``indices`` of root seed ``seed``: each run's
    dispersed entry state, vehicle and atmosphere
    (:func:`~gnc_jax.systems.capsule.simulation.dispersed_entry` on
    :func:`~gnc_jax.montecarlo.run_key`, the draws of the study)."""

    def one(i):
        y0, vehicle, atmosphere, _ = capsule_sim.dispersed_entry(sim, run_key(seed, i))
        return EntryModel(vehicle, sim.earth, atmosphere), y0

    return jax.vmap(one)(indices)


@jax.jit(static_argnames=("steps",))
def _run_footprints(sim, seed, indices, steps):
    """Footprints (m) of the runs ``indices`` (:func:`_run_models`), flown open loop."""
    models, y0s = _run_models(sim, seed, indices)
    start = unit(entry_state_from_conditions(sim.entry, sim.earth).r)
    return track_footprints(models, y0s, start, sim.entry.azimuth, sim.chute_altitude_m, steps)


def dispersed_footprints(config: dict, runs: int, seed: int) -> np.ndarray:
    """Each Monte Carlo run's own reachable footprint, shape (runs, 2), km: the shortest and
    longest chute range of run ``i`` (0 .. runs - 1) of a study of ``config`` with root seed
    ``seed``, flown open loop at the constant banks of the nominal footprint with its
    landing-edge bisection (:func:`~gnc_jax.guidance.entry.corridor.track_footprint`) by the run's
    own dispersed vehicle, atmosphere and entry state (the same draws as
    :func:`~gnc_jax.run_study`); NaN where no bank lands (a skip-out even with full lift
    down). Ranges along the nominal entry -> target track from the nominal entry point (the
    axis of ``entry.range_km`` and of the runs' downrange errors), so the footprints do not
    depend on ``entry.range_km``. Needs no guidance law and no reference design."""
    sim = capsule_sim.build_from_config(config)
    steps = int(math.ceil(from_scenario(SimulationParams, config).max_time_s / DT_S))
    out = _run_footprints(sim, seed, jnp.arange(runs), steps)
    return np.asarray(out) / 1e3


def target_reach(config: dict, indices, seed: int) -> np.ndarray:
    """Whether runs ``indices`` of a study of ``config`` with root seed ``seed`` can reach the
    target itself, downrange and crossrange, with a bank of one magnitude reversed once (a
    sufficient test: a bank history may do better): each run's crossrange span (km, shape
    (len(indices), 2); > 0 left of the track) at the target's downrange of its own dispersed
    vehicle's three-dimensional constant-magnitude flights with one reversal
    (:func:`~gnc_jax.guidance.entry.corridor.target_crossrange_span`; the study's draws). A
    run reaches the target when its span holds 0; a span whose nearer end is ``d`` km from
    0 misses by about ``d`` km at best with such a bank. About 10,000 flights per run (10-20 s
    each run on a CPU core): an analysis of chosen runs, not part of the pre-check. Needs no
    guidance law and no reference design."""
    sim = capsule_sim.build_from_config(config)
    steps = int(math.ceil(from_scenario(SimulationParams, config).max_time_s / DT_S))
    start = unit(entry_state_from_conditions(sim.entry, sim.earth).r)
    models, y0s = jax.jit(_run_models)(sim, seed, jnp.asarray(indices))
    spans = []
    for k in range(len(indices)):
        model, y0 = jax.tree_util.tree_map(lambda x, k=k: x[k], (models, y0s))
        spans.append(
            target_crossrange_span(model, y0, start, sim.target_fixed, sim.chute_altitude_m, steps)
        )
    return np.asarray(spans).reshape(-1, 2) / 1e3


def reachability(footprints_km: np.ndarray, range_km: float) -> dict[str, float]:
    """Pre-check columns of a target range (km) against the runs' footprints
    (:func:`dispersed_footprints`): ``reachable_fraction`` (runs whose footprint holds the
    range), ``reachable_fraction_margin`` (and ``FOOTPRINT_MARGIN`` of its width from both
    ends), ``no_landing_fraction`` (runs no constant bank lands), and the dispersed footprint
    ``dispersed_footprint_min_km`` .. ``dispersed_footprint_max_km``: the shortest range all
    but ``FOOTPRINT_TAIL`` of the runs can fly down to and the longest they can fly out to
    (of n runs, floor(FOOTPRINT_TAIL n) may lie beyond each end: with 200 runs the
    second-largest shortest range and the second-smallest longest range; a run that lands at
    no bank counts as reaching nothing); NaN when more runs than that cannot get there."""
    lo, hi = footprints_km[:, 0], footprints_km[:, 1]
    w = hi - lo
    lands = np.isfinite(lo)
    inside = lands & (lo <= range_km) & (range_km <= hi)
    spare = FOOTPRINT_MARGIN * w
    margin = lands & (lo + spare <= range_km) & (range_km <= hi - spare)
    beyond = int(math.floor(FOOTPRINT_TAIL * len(lo) + 1e-9))  # runs allowed past an end
    q_lo = np.sort(np.where(lands, lo, np.inf))[len(lo) - 1 - beyond]
    q_hi = np.sort(np.where(lands, hi, -np.inf))[beyond]
    return dict(
        reachable_fraction=float(inside.mean()),
        reachable_fraction_margin=float(margin.mean()),
        no_landing_fraction=float((~lands).mean()),
        dispersed_footprint_min_km=float(q_lo) if np.isfinite(q_lo) else math.nan,
        dispersed_footprint_max_km=float(q_hi) if np.isfinite(q_hi) else math.nan,
    )


def check_cells(configs: list[dict], runs=None, seed=None) -> list[dict]:
    """Entry corridor pre-check (:mod:`gnc_jax.guidance.entry.corridor`): a cell whose entry
    flight-path angle skips out even with full lift down (overshoot) or exceeds the load
    limit (the cell's ``simulation.load_limit_g``) even with full lift up (undershoot) is
    infeasible. Columns: the corridor's ends
    and the nominal vehicle's reachable footprint (constant-bank extreme chute ranges) at
    the cell's angle, whether the target lies inside it (``in_footprint``) and inside it
    with ``FOOTPRINT_MARGIN`` of its width to spare (``in_footprint_margin``).

    Given ``runs`` (and the root ``seed``, default 0; :func:`~gnc_jax.envelope` passes
    the study's), each feasible cell also gets
    the dispersed runs' own footprints (:func:`dispersed_footprints`, the study's draws;
    computed once per entry angle and vehicle, shared by the ranges) and the columns of
    :func:`reachability`, with ``footprint_runs`` (the study's first runs, at most
    ``FOOTPRINT_RUNS_MAX``) and ``footprint_s`` (wall time of the angle's footprints, s)."""
    field = schema_of(Entry)["fpa_deg"]  # its declared range bounds the corridor search
    out, corridors, runs_fp = [], {}, {}
    for cfg in configs:
        env = entry_envelope(cfg)
        fpa = cfg["entry"]["fpa_deg"]
        # the corridor depends on everything but the angle and the target's range
        key = repr({k: v for k, v in cfg.items() if k != "entry"}) + repr(
            {k: v for k, v in cfg["entry"].items() if k not in ("fpa_deg", "range_km")}
        )
        if key not in corridors:
            corridors[key] = env.corridor(field.lo, field.hi, 0.05)
        cor = corridors[key]
        lo, hi = env.footprint(fpa)
        rng = cfg["entry"]["range_km"]
        feasible = cor.contains(fpa)
        if not feasible and not cor.undershoot_deg <= cor.overshoot_deg:
            reason = (
                f"no entry angle in [{field.lo:g}, {field.hi:g}] deg is both captured with "
                f"full lift down and within {env.load_limit_g:g} g with full lift up at this "
                "speed and vehicle"
            )
        elif not feasible:
            side = (
                "overshoot (skips out with full lift down)"
                if fpa > cor.overshoot_deg
                else (f"undershoot (above {env.load_limit_g:g} g with full lift up)")
            )
            reason = (
                f"outside the entry corridor {cor.undershoot_deg:.2f} .. "
                f"{cor.overshoot_deg:.2f} deg: {side}"
            )
        else:
            reason = ""
        w = hi - lo
        columns = dict(
            corridor_undershoot_deg=cor.undershoot_deg,
            corridor_overshoot_deg=cor.overshoot_deg,
            load_limit_g=env.load_limit_g,
            footprint_min_km=lo,
            footprint_max_km=hi,
            in_footprint=bool(lo <= rng <= hi),
            in_footprint_margin=bool(lo + FOOTPRINT_MARGIN * w <= rng <= hi - FOOTPRINT_MARGIN * w),
        )
        if runs is not None and feasible:
            s = 0 if seed is None else int(seed)
            # the runs' footprints depend on everything but the target's range
            fkey = repr(
                {k: v for k, v in cfg.items() if k != "entry"}
                | {"entry": {k: v for k, v in cfg["entry"].items() if k != "range_km"}}
            ) + repr((runs, s))
            n_fp = min(int(runs), FOOTPRINT_RUNS_MAX)
            if fkey not in runs_fp:
                t0 = time.perf_counter()
                fp = dispersed_footprints(cfg, n_fp, s)
                runs_fp[fkey] = fp, time.perf_counter() - t0
            fp, wall = runs_fp[fkey]
            columns.update(reachability(fp, rng), footprint_runs=n_fp, footprint_s=wall)
        out.append(dict(feasible=feasible, reason=reason, columns=columns))
    return out


def draw_overlay(ax, envelope, x_key: str, y_key: str | None) -> None:
    """The entry corridor (lines at its ends) when an axis is ``entry.fpa_deg``, and the
    reachable footprint (shortest and longest constant-bank chute range against the
    angle) when the other is ``entry.range_km``: the nominal vehicle's and, when the
    pre-check computed it, the dispersed runs' (:func:`reachability`, at the grid's
    angles; NaN where more than ``FOOTPRINT_TAIL`` of the runs do not get there)."""
    cells = envelope.cells
    if "entry.fpa_deg" not in (x_key, y_key) or not cells:
        return
    vertical = x_key == "entry.fpa_deg"
    line = ax.axvline if vertical else ax.axhline
    c0 = cells[0]
    for name, style in (("corridor_overshoot_deg", "--"), ("corridor_undershoot_deg", ":")):
        v = c0.get(name)
        if v is not None and np.isfinite(v):
            line(v, color="r", ls=style, lw=1.5, label=name.replace("_", " "))
    other = y_key if vertical else x_key
    if other != "entry.range_km":
        return
    fpas = np.asarray(envelope.axes["entry.fpa_deg"], float)
    dense = np.linspace(fpas.min(), fpas.max(), 25)
    fp = entry_envelope(envelope.scenario.config).footprints(dense)
    lim = ax.get_ylim() if vertical else ax.get_xlim()
    for k, name in ((0, "footprint: shortest range"), (1, "footprint: longest range")):
        xy = (dense, fp[:, k]) if vertical else (fp[:, k], dense)
        ax.plot(*xy, "m-" if k else "m--", lw=2, label=name)
    # the dispersed runs' footprint (the pre-check's columns, one per grid angle)
    by_fpa = {}
    for c in cells:
        if "dispersed_footprint_min_km" in c:
            by_fpa[c["entry.fpa_deg"]] = (
                c["dispersed_footprint_min_km"],
                c["dispersed_footprint_max_km"],
            )
    if by_fpa:
        a = np.array(sorted(by_fpa))
        ends = np.array([by_fpa[x] for x in a], float)
        tail = f"{100 * (1 - FOOTPRINT_TAIL):g} % of runs"
        for k, name in ((0, "shortest"), (1, "longest")):
            xy = (a, ends[:, k]) if vertical else (ends[:, k], a)
            ax.plot(
                *xy,
                "-o" if k else "--o",
                color="C1",
                lw=2,
                ms=4,
                label=f"dispersed footprint ({tail}): {name} range",
            )
    (ax.set_ylim if vertical else ax.set_xlim)(lim)
