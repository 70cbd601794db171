"""The skip-entry law's corrector (seed 003 eqs. 11-15): the first-entry bank sigma_0 whose
predicted range error is zero, by the bounded regula falsi of :mod:`gnc_jax.root_finding`, a
fixed-iteration ``lax`` loop over the predictions of :mod:`gnc_jax.guidance.entry.predictor`.
Each function takes the law (:class:`~gnc_jax.guidance.entry.skip_entry.SkipEntryGuidance`) for
its bounds, tolerance and loop sizes.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._numerics import loop_shape
from ...root_finding import RegulaFalsiResult, RootStatus, regula_falsi
from .phases import is_direct
from .predictor import (
    finished_prediction,
    integrating,
    predict,
    prediction_origin,
    predictor_start,
    predictor_step,
    profile,
)
from .state import SkipEntryState

# Predictor steps a corrector cycle takes between two looks at which predictions ended (see
# correct below): a look costs about a step (a prediction's end and the next one's
# start, for every run of the batch) and a finished prediction waits for it half a round on
# average; at 16 s steps a 256-run chunk's corrector time is least at 8 (16: the same, 4: 7 %
# more).
ROUND_STEPS = 8
# Step carries kept by the one prediction reverse mode differentiates at a solution
# (loop_kind "checkpointed"): a prediction takes about 50 steps, so none is recomputed
PREDICTION_CHECKPOINTS = 64


def _where(pick, new, old):
    return jax.tree_util.tree_map(lambda a, b: jnp.where(pick, a, b), new, old)


def warm_start(law, state: SkipEntryState, speed):
    """The corrector's first guess at ``speed``: with ``corrector_start = "secant"`` the
    bank the last solution's profile planned for this speed (the root it would have
    if the flight went as planned), else the last solution sigma_0 itself (seed 003)."""
    if law.corrector_start != "secant":
        return state.sigma_0
    planned = profile(law, state.sigma_0, state.plan_speed, speed)
    return jnp.where(jnp.isnan(state.plan_speed), state.sigma_0, planned)


def corrector_cycle(law, state: SkipEntryState, y, t, speed, ctx, model, pulled, active):
    """The corrector on a predictor-corrector step (every ``pc_every`` control steps),
    else the previous solution. Returns the result and whether it is a new solution: only
    an ``active`` run (in phase 1) does any work."""

    def pc(_):
        res = correct(
            law,
            y,
            t,
            pulled,
            warm_start(law, state, speed),
            model,
            ctx.target_fixed,
            active,
            state.corrector_slope,
            state.dip_altitude_m,
            ctx.loop_kind,
        )
        return res._replace(slope=jnp.asarray(res.slope, dtype=float))

    def no_pc(_):
        z = jnp.zeros((), int)
        return RegulaFalsiResult(
            x=state.sigma_0,
            f_x=jnp.zeros(()),
            converged=jnp.asarray(True),
            n_evals_early_exit=z,
            n_evals_total=z,
            status=z,
            aux=state.predicted_crossrange,
            cost=jnp.zeros(()),
            slope=state.corrector_slope,
        )

    if ctx.cycle_start is None:
        is_pc_step = (state.step % ctx.pc_every) == 0
    else:
        is_pc_step = ctx.cycle_start
    active = active & is_pc_step  # (should the cond be batched, an idle step predicts nothing)
    if isinstance(is_pc_step, bool):  # the caller's clock, known at trace time
        return (pc if is_pc_step else no_pc)(None), active
    res = jax.lax.cond(is_pc_step, pc, no_pc, None)
    return res, active


def correct(
    law,
    y,
    t,
    pulled_up,
    sigma_prev,
    model,
    target_fixed,
    enabled,
    slope=None,
    dip_altitude_m=None,
    loop_kind="lax",
):
    """Bounded regula falsi on sigma_0 (seed 003 eqs. 11-15), at most
    1 + n_bracket + n_iter predictions.

    Warm-started at the previous solution; with ``corrector_start = "secant"`` and the
    previous cycle's ``slope`` (m/rad), a miss of the warm start is followed by the secant
    step on that slope instead of the Δσ step of eq. 15. The result's ``aux`` is the
    predicted crossrange at the switch point of the solution, its ``cost`` the number of
    predictor RK4 steps taken by all predictions of the cycle, its ``slope`` this
    cycle's.

    The predictions of the whole cycle are one loop over predictor steps, in rounds of
    ``ROUND_STEPS``: after each round, a run whose prediction has ended gives its range
    error to the root finder (the :class:`~gnc_jax.root_finding.RegulaFalsi` machine) and
    starts the prediction it proposes next. Under ``vmap`` the loop runs until the run
    with the most predictor steps in the cycle is done; with a loop per prediction slot
    instead, every slot runs as long as its slowest run, which at 16 s steps costs a
    256-run chunk's corrector 7 % more. The solve is the same either way.

    ``loop_kind`` (static) ``"fixed"``: the rounds are a ``lax.scan`` of the most rounds a
    solve can take (bounded, so never cut short) and a round's steps a masked ``lax.scan`` of
    ``ROUND_STEPS`` (the arithmetic of the vmapped ``while_loop``, whose body runs for every
    run and keeps the finished ones' state), every round run and a solved run's carry held:
    no loop predicate, nothing for a GPU to wait on between rounds. ``"checkpointed"``: the
    ``lax`` solve, differentiated in reverse mode by the implicit function theorem at its
    solution (:func:`implicit_correct`) instead of through its rounds. ``"held"``: the ``lax``
    solve passing no derivative at all."""

    if loop_kind == "held":
        held = jax.lax.stop_gradient(
            (law, y, t, pulled_up, sigma_prev, model, target_fixed, slope, dip_altitude_m)
        )
        law, y, t, pulled_up, sigma_prev, model, target_fixed, slope, dip_altitude_m = held
        loop_kind = "lax"
    if loop_kind == "checkpointed":
        return implicit_correct(
            law, y, t, pulled_up, sigma_prev, model, target_fixed, enabled, slope, dip_altitude_m
        )
    secant = law.corrector_start == "secant"
    solver = regula_falsi(
        law.bracket_step_rad,
        law.bank_min_rad,
        law.bank_max_rad,
        law.direct_range_tolerance_m if is_direct(law) else law.range_tolerance_m,
        law.n_bracket,
        law.n_iter,
        illinois=True,
        decreasing=True,
        enabled=enabled,
        slope=slope if secant else None,
        anderson_bjorck=secant,
    )
    origin = prediction_origin(law, y, t, pulled_up, model, dip_altitude_m)
    z = jnp.zeros(())
    s = solver.init(sigma_prev, z, z)
    x, active = solver.propose(s)

    def steps(c, sigma_0):
        """Up to ROUND_STEPS steps of the prediction."""
        fixed = not loop_shape().early_exit  # a GPU's layout: no predicate read back per step
        if loop_kind == "fixed" or fixed:

            def masked(c, _):
                new = predictor_step(law, c, sigma_0, origin.speed_mps, model)
                return _where(integrating(law, c), new, c), None

            # Fixed, a round is unrolled whole: a loop inside the rounds' loop makes XLA copy
            # every carried array of a round (the vmapped rounds keep the finished runs' state).
            unroll = ROUND_STEPS if fixed else 1
            return jax.lax.scan(masked, c, None, length=ROUND_STEPS, unroll=unroll)[0]
        c, _ = jax.lax.while_loop(
            lambda cj: integrating(law, cj[0]) & (cj[1] < ROUND_STEPS),
            lambda cj: (
                predictor_step(law, cj[0], sigma_0, origin.speed_mps, model),
                cj[1] + 1,
            ),
            (c, jnp.asarray(0, jnp.int32)),
        )
        return c

    def round_(carry):
        s, x, c = carry
        c = steps(c, x)
        end = ~integrating(law, c)
        p = finished_prediction(law, c, y, t, model, target_fixed)
        s = _where(end, solver.absorb(s, x, p.miss_m, p.crossrange_m, p.steps.astype(float)), s)
        x_next, active = solver.propose(s)
        c_next = predictor_start(law, origin, x_next, active, model)
        return s, jnp.where(end, x_next, x), _where(end, c_next, c)

    c = predictor_start(law, origin, x, active, model)
    # each prediction ends within ceil(max_steps / ROUND_STEPS) rounds
    most = solver.n_evals_total * -(-law.predictor_max_steps // ROUND_STEPS)
    if loop_kind == "fixed":  # every round runs, a solved run's carry held: no predicate

        def masked_round(sxc, _):
            return _where(solver.done(sxc[0]), sxc, round_(sxc)), None

        s, _, _ = jax.lax.scan(masked_round, (s, x, c), None, length=most)[0]
    else:
        s, _, _ = jax.lax.while_loop(lambda sxc: ~solver.done(sxc[0]), round_, (s, x, c))
    return solver.result(s)


def implicit_correct(
    law, y, t, pulled_up, sigma_prev, model, target_fixed, enabled, slope=None, dip_altitude_m=None
):
    """:func:`correct` with the ``lax`` loops (``loop_kind = "checkpointed"``), whose solution
    sigma_0 and predicted crossrange carry the derivative of the root itself in reverse mode
    (the implicit function theorem): with f the predicted range error and chi the crossrange
    of the prediction of sigma_0 from the cycle's state and model theta,
    d sigma_0 = -(df/dtheta) dtheta / (df/dsigma_0) and
    d chi = dchi/dsigma_0 d sigma_0 + dchi/dtheta dtheta, from one prediction at the solution.
    The reverse pass differentiates that one prediction instead of every prediction of every
    round of the solve, and the solution's derivative no longer depends on the path the
    iterations took (the warm start, the bracketing). The values are those of ``"lax"``.

    A solve that found no bracket (its sigma_0 the best candidate tried, often a bound) and an
    idle run (sigma_0 the previous one, clipped) pass no derivative to the cycle's state: the
    former is held, the latter is the previous solution's. The slope df/dsigma_0 is at most
    -range_tolerance_m / bracket_step_rad (a flatter range error leaves the root undefined
    within a bracket step), which bounds the derivative of a near-degenerate solve."""
    sg = jax.lax.stop_gradient
    inputs = (law, y, t, pulled_up, model, target_fixed, dip_altitude_m)
    law_, y_, t_, up_, model_, target_, dip_ = sg(inputs)
    res = correct(
        law_, y_, t_, up_, sg(sigma_prev), model_, target_, enabled, sg(slope), dip_, "lax"
    )
    held = ~enabled | (res.status == RootStatus.not_bracketed)
    x, aux = _at_root(inputs, res.x, res.aux, held)
    previous = jnp.clip(sigma_prev, law.bank_min_rad, law.bank_max_rad)
    return res._replace(x=jnp.where(enabled, x, previous), aux=aux)


@eqx.filter_custom_vjp
def _at_root(inputs, x, aux, held):
    """``(x, aux)``, the solution of :func:`implicit_correct` and its crossrange, whose
    reverse-mode derivative with respect to ``inputs`` is the root's."""
    return x, aux


@_at_root.def_fwd
def _at_root_fwd(perturbed, inputs, x, aux, held):
    del perturbed
    return (x, aux), None


@_at_root.def_bwd
def _at_root_bwd(residuals, g, perturbed, inputs, x, aux, held):
    del residuals
    g_x, g_aux = (jnp.zeros_like(x) if a is None else a for a in g)
    law = inputs[0]

    def prediction(sigma, inputs, checkpoints=None):
        law, y, t, up, model, target, dip = inputs
        p = predict(law, y, t, up, sigma, model, target, ~held, dip, checkpoints)
        return p.miss_m, p.crossrange_m

    # the slopes in sigma_0 by forward mode, then one reverse pass with their combination
    _, (f_s, chi_s) = jax.jvp(lambda s: prediction(s, inputs), (x,), (jnp.ones_like(x),))
    tolerance = law.direct_range_tolerance_m if is_direct(law) else law.range_tolerance_m
    flattest = -tolerance / law.bracket_step_rad
    f_s = jnp.where(jnp.isfinite(f_s), jnp.minimum(f_s, flattest), flattest)
    g_sigma = g_x + g_aux * jnp.where(jnp.isfinite(chi_s), chi_s, 0.0)
    g_f = jnp.where(held, 0.0, -g_sigma / f_s)
    g_chi = jnp.where(held, 0.0, g_aux)
    # only the perturbed leaves (not the law's tables, the vehicle's constants...) get one
    moving, fixed = eqx.partition(inputs, perturbed)
    _, vjp = eqx.filter_vjp(
        lambda m: prediction(x, eqx.combine(m, fixed), PREDICTION_CHECKPOINTS), moving
    )
    (grads,) = vjp((g_f, g_chi))
    # a held run's prediction took no step: whatever its derivative, it passes none
    return jax.tree_util.tree_map(lambda a: jnp.where(held, 0.0, a), grads)
