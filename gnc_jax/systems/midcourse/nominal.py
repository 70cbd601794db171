"""The nominal transfer of a midcourse scenario: a Lambert conic from Earth to Mars,
retargeted in the full force model to the aim point (seed 001 §4's reference trajectory)."""

import dataclasses
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._types import Vector3
from ...constants import SECONDS_PER_DAY
from ...dynamics.ephemeris import GM_SUN, planet_index, planet_state
from ...dynamics.heliocentric import HeliocentricModel, steps_to_encounter
from ...geometry.bplane import check_b_plane_frame
from ...geometry.kepler import propagate_kepler
from ...geometry.lambert import solve_lambert
from ...guidance.midcourse import NewtonTargeter
from .params import MidcourseErrors
from .simulation import MidcourseSimulation


class NominalTransfer(NamedTuple):
    """The nominal transfer a scenario defines (see `design_nominal`)."""

    r0_m: Vector3  # heliocentric state at the first fix, EME2000
    v0_mps: Vector3
    v_lambert_mps: Vector3  # the Sun-only Lambert conic's velocity at the first fix
    c3_km2s2: float  # launch energy of the Lambert conic
    v_inf_arrival_mps: float  # arrival excess speed of the Lambert conic
    design_iterations: int


STEP_PROBE = 1_000_000
"""Step budget with which a nominal transfer that could not be targeted is targeted again, to
tell a step budget that ran out from an infeasible transfer (the upper bound of
``dynamics.max_steps``)."""


class StepBudgetError(ValueError):
    """The integrator's step budget (``max_steps``) runs out before the encounter while the
    nominal transfer is targeted. ``needed``: the steps the targeted transfer takes from the
    first fix to the encounter (``None`` when that is within the budget: an intermediate
    Newton iterate needed more)."""

    def __init__(self, max_steps: int, needed: int | None):
        self.max_steps, self.needed = max_steps, needed
        super().__init__(
            f"{max_steps} integrator steps do not reach the encounter; the targeted nominal "
            f"transfer takes {needed} from the first fix"
            if needed is not None
            else f"{max_steps} integrator steps do not reach the encounter from every Newton "
            f"iterate of the nominal transfer's targeting ({STEP_PROBE} do)"
        )


@eqx.filter_jit
def _steps(model: HeliocentricModel, t0_s, y0, t_max_s):
    return steps_to_encounter(model, t0_s, y0, t_max_s)


def _check_step_budget(design: MidcourseSimulation, targeter: NewtonTargeter) -> None:
    """Raise `StepBudgetError` when ``design`` (whose targeting did not converge) converges
    with a budget of `STEP_PROBE` steps."""
    model = design.model
    if model.max_steps >= STEP_PROBE:
        return
    probe = dataclasses.replace(design, model=dataclasses.replace(model, max_steps=STEP_PROBE))
    result = _retarget(probe, targeter)
    if not bool(result.converged):
        return
    x = jnp.concatenate([design.r0_m, design.v0_mps + result.p])
    steps, _ = _steps(probe.model, design.t_first_fix_s, x, design.t_max_s)
    raise StepBudgetError(model.max_steps, int(steps) if int(steps) > model.max_steps else None)


@eqx.filter_jit
def _retarget(sim: MidcourseSimulation, targeter: NewtonTargeter):
    x = jnp.concatenate([sim.r0_m, sim.v0_mps])
    return targeter.solve(sim.guidance_context.problem(sim.t_first_fix_s, x), sim.aim, jnp.zeros(3))


_NOMINAL_CACHE: dict = {}


def design_nominal(sim: MidcourseSimulation, t_launch_s: float) -> NominalTransfer:
    """Nominal state at the first fix: Lambert conic, then full-model targeting.

    1. Zero-revolution Lambert arc (Sun only, Izzo) from the Earth–Moon barycentre at
       ``t_launch_s`` to Mars at the nominal encounter epoch (`geometry.lambert`);
    2. that conic propagated (Kepler) to the first-fix epoch;
    3. the velocity there retargeted by Newton iteration (autodiff K, 12 iterations) in the full
       model to the aim point and the encounter epoch, |ΔB| < 1 m, |Δt| < 1 ms.

    ``sim`` supplies the model, epochs and aim (its r0/v0 are ignored). Results are cached per
    process, keyed by every input. Raises `BPlaneError` when the arrival asymptote is parallel
    to the reference normal, `StepBudgetError` when step 3 does not converge because a
    propagation to the encounter needs more than the model's ``max_steps`` steps (it converges
    with `STEP_PROBE`), and ``ValueError`` when it does not converge otherwise.
    """
    # Only the model, epochs, aim and reference plane matter; everything else is reset so that
    # every scenario variant shares one compiled design function and one cached result.
    aim3 = jnp.concatenate([sim.aim[:2], jnp.zeros(1)])
    design = MidcourseSimulation(
        model=sim.model,
        r0_m=jnp.zeros(3),
        v0_mps=jnp.zeros(3),
        t_first_fix_s=sim.t_first_fix_s,
        fix_interval_s=jnp.asarray(SECONDS_PER_DAY),
        t_encounter_s=sim.t_encounter_s,
        t_max_s=sim.t_max_s,
        aim=aim3,
        ref_normal=sim.ref_normal,
        goal=jnp.zeros(2),
        errors=MidcourseErrors(),
    )
    leaves = [jnp.asarray(x).tolist() for x in jax.tree_util.tree_leaves(design)]
    key = (repr(leaves), repr(jax.tree_util.tree_structure(design)), float(t_launch_s))
    if key in _NOMINAL_CACHE:
        return _NOMINAL_CACHE[key]
    t_enc = float(sim.t_encounter_s)
    t_fix = float(sim.t_first_fix_s)
    r_earth, v_earth = planet_state(planet_index("earth"), t_launch_s)
    r_mars, v_mars = planet_state(sim.model.target, t_enc)
    v1, v2 = solve_lambert(r_earth, r_mars, t_enc - t_launch_s, GM_SUN)
    check_b_plane_frame(v2 - v_mars, sim.ref_normal)
    r0, v0 = propagate_kepler(r_earth, v1, t_fix - t_launch_s, GM_SUN)
    design = eqx.tree_at(lambda s: (s.r0_m, s.v0_mps), design, (r0, v0))
    targeter = NewtonTargeter(tolerance=jnp.array([1.0, 1.0, 1e-3]), iterations=12)
    result = _retarget(design, targeter)
    if not bool(result.converged):
        miss = jax.device_get(result.q - aim3)
        if not np.all(np.isfinite(miss)):  # a propagation failed (its step budget ran out?)
            _check_step_budget(design, targeter)
        raise ValueError(
            "the nominal transfer could not be targeted to the aim point in the full model "
            f"(residual B_R, B_T, t = {miss[0]:.3g} m, {miss[1]:.3g} m, {miss[2]:.3g} s)"
        )
    nominal = NominalTransfer(
        r0_m=r0,
        v0_mps=v0 + result.p,
        v_lambert_mps=v0,
        c3_km2s2=float(jnp.sum((v1 - v_earth) ** 2)) / 1e6,
        v_inf_arrival_mps=float(jnp.linalg.norm(v2 - v_mars)),
        design_iterations=int(result.iterations),
    )
    if len(_NOMINAL_CACHE) >= 16:
        _NOMINAL_CACHE.pop(next(iter(_NOMINAL_CACHE)))
    _NOMINAL_CACHE[key] = nominal
    return nominal


__all__ = ["NominalTransfer", "STEP_PROBE", "StepBudgetError", "design_nominal"]
