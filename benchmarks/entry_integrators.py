"""Accuracy per cost of fixed-step integrators on the capsule predictor's arc.

    python benchmarks/entry_integrators.py

The arc is what the first-entry predictor integrates: the vertical-plane model from the
guidance start (N_g = 0.1 g) through the first dip and the Kepler phase, 800 s, with the nominal
first-entry bank. Each method's final position error is measured against scipy's DOP853 at
rtol 1e-12 on the same vector field; the cost is right-hand-side evaluations per arc, and the
throughput a vmapped batch of 1000 arcs (compile time separate, best of 3). The predictor's
step is chosen from this table: the corrector's tolerance is 5 km in range, so a step whose
error is a few tens of metres costs accuracy nothing and saves evaluations.

The second table is the predictor itself (``gnc_jax.guidance.entry.predictor.predict``: the bank
profile, the switch-point and chute location, the second-entry expansion), at the states and
solutions of the corrector cycles of four flights: its predicted range error against a converged
prediction (bank at every RK4 stage, 0.25 s steps), for the step schedules (``predictor_dt_s`` /
``predictor_coast_dt_s``, the coast steps below 0.02 g) and both bank models. With the bank held
over each step (as the law flies it) the error is first order in the step -- about 460 km at
8 s, a hundred times the corrector's tolerance, made up by re-solving every 4 s -- and the coast
steps add about 1 km to it; with the bank at every stage it is fourth order (about 3 km at 8 s)
but each step costs twice as much (a cosine per stage, which XLA's CPU fusion recomputes in
every consumer).
"""

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

import gnc_jax as gj  # first: float64, host devices
from gnc_jax.dynamics.entry import EntryState
from gnc_jax.guidance.entry.base import EntryModel
from gnc_jax.guidance.entry.predictor import predict
from gnc_jax.integrate import RK4, RK6_BUTCHER, integrate_fixed

T_ARC = 800.0


def main():
    sim, law = gj.build(gj.load_scenario("lunar-skip-entry"))
    model = EntryModel(sim.vehicle, sim.earth, sim.atmosphere)
    cos_b = jnp.cos(law.reference.first_entry_bank_rad)
    from gnc_jax.dynamics.entry import entry_state_from_conditions

    y0 = entry_state_from_conditions(sim.entry, sim.earth)

    def field(t, y, a):
        return model.vertical_plane_field(t, y, cos_b)

    # start where the guidance starts: integrate the hold phase finely first
    y_start = integrate_fixed(field, 0.0, y0, 0.05, 600)
    rhs = jax.jit(lambda y: field(0.0, EntryState(y[:3], y[3:]), None))

    def f_np(t, y):
        d = rhs(jnp.asarray(y))
        return np.concatenate([np.asarray(d.r), np.asarray(d.v)])

    s0 = np.concatenate([np.asarray(y_start.r), np.asarray(y_start.v)])
    t0 = time.perf_counter()
    ref = solve_ivp(f_np, (0.0, T_ARC), s0, method="DOP853", rtol=1e-12, atol=1e-6)
    print(
        f"# reference: scipy DOP853 rtol 1e-12, {ref.nfev} evaluations, "
        f"{time.perf_counter() - t0:.1f} s; arc {T_ARC:.0f} s from the guidance start"
    )
    r_ref = ref.y[:3, -1]

    batch = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (1000,) + x.shape), y_start)
    print(
        "| method | step (s) | RHS evals/arc | final position error (m) | "
        "arcs/s (1000, vmapped) | RHS evals/s |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for tab, steps in ((RK4, (0.5, 1.0, 2.0, 4.0, 8.0)), (RK6_BUTCHER, (2.0, 4.0, 8.0, 16.0))):
        for dt in steps:
            n = int(round(T_ARC / dt))

            def arc(y, n=n, dt=dt, tab=tab):
                return integrate_fixed(field, 0.0, y, dt, n, tableau=tab)

            err = float(np.linalg.norm(np.asarray(jax.jit(arc)(y_start).r) - r_ref))
            fn = jax.jit(jax.vmap(arc)).lower(batch).compile()
            best = min(_time(fn, batch) for _ in range(3))
            evals = n * tab.stages
            print(
                f"| {tab.name} | {dt:g} | {evals} | {err:.3g} | {1000 / best:,.0f} | "
                f"{1000 * evals / best:.3g} |"
            )
    prediction_errors(sim, law)


def prediction_errors(sim, law):
    """RMS and largest predicted range error of the predictor's schedules and bank models
    against a converged prediction, at the corrector cycles of four flights."""
    from gnc_jax.montecarlo import simulate_traces

    _, tr = simulate_traces(gj.load_scenario("lunar-skip-entry"), np.arange(4), seed=0)
    runs, steps = np.nonzero(tr["corrector_evals"] > 0)
    runs, steps = runs[::3], steps[::3]

    def at(name):
        return jnp.asarray(tr[name][runs, steps])

    args = (
        EntryState(at("r_m"), at("v_mps")),
        at("t_s"),
        at("pulled_up"),
        at("sigma_0_rad"),
        at("drag_ratio"),
        at("lift_ratio"),
    )

    def batch(variant):
        def one(y, t, pulled, sigma, drag_ratio, lift_ratio):
            m = EntryModel(sim.vehicle, sim.earth, sim.atmosphere, drag_ratio, lift_ratio)
            p = predict(variant, y, t, pulled, sigma, m, sim.target_fixed)
            return p.miss_m, p.steps

        fn = jax.jit(jax.vmap(one)).lower(*args).compile()
        out = jax.block_until_ready(fn(*args))
        return [np.asarray(x) for x in out], min(_time(lambda a: fn(*a), args) for _ in range(3))

    def variant(bank, dt, coast):
        return dataclasses.replace(
            law,
            predictor_bank=bank,
            predictor_dt_s=float(dt),
            predictor_coast_dt_s=float(coast),
            predictor_max_steps=20_000,
        )

    (ref, _), _ = batch(variant("stage", 0.25, 0.25))
    print(
        f"\n# predicted range error at {len(runs)} corrector states of 4 flights, against the "
        "bank at every stage with 0.25 s steps; corrector tolerance 5 km"
    )
    print(
        "| bank | step / coast step (s) | RK4 steps per prediction | range error RMS (km) "
        "| largest (km) | predictions/s (vmapped) |"
    )
    print("|---|---|---:|---:|---:|---:|")
    for bank in ("step", "stage"):
        for dt, coast in ((2, 2), (4, 4), (8, 8), (8, 32), (8, 64), (16, 32)):
            (miss, n), t = batch(variant(bank, dt, coast))
            err = (miss - ref) / 1e3
            print(
                f"| {bank} | {dt} / {coast} | {n.mean():.1f} | {np.sqrt(np.mean(err**2)):.3g} "
                f"| {np.max(np.abs(err)):.3g} | {len(runs) / t:,.0f} |"
            )


def _time(fn, batch):
    t0 = time.perf_counter()
    jax.block_until_ready(fn(batch))
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
