"""Python API walk-through: an impactor dispersion study, a gain sweep and a gradient.

python examples/impactor_study.py
"""

import equinox as eqx
import jax
import jax.numpy as jnp

import gnc_jax as gj  # import first: float64 and one XLA device per core

# 1. A Monte Carlo study of the packaged seed 000 scenario, saved and plotted.
scenario = gj.load_scenario("deep-impact-los")
study = gj.run_study(scenario, runs=500, seed=0)
summary = study.summary()
print(
    f"LOS law: miss RMS {summary['miss_rms_m']:.1f} m, Δv mean {summary['dv_mean_mps']:.2f} m/s "
    f"({summary['wall_s']:.2f} s for {study.runs} runs after {summary['compile_s']:.1f} s compile)"
)
study.save("results/example-los", overwrite=True)
print(gj.report("results/example-los"))

# 2. A sweep of the miss tolerance k1 with --set-style overrides (same draws for every k1).
for k1 in (2.0, 3.0, 4.0, 6.0):
    s = gj.run_study(scenario.with_overrides({"guidance.los.k1": k1}), runs=500, seed=0).summary()
    print(
        f"k1 = {k1}: miss RMS {s['miss_rms_m']:6.1f} m, Δv mean {s['dv_mean_mps']:.2f} m/s, "
        f"firings max {s['firings_max']}"
    )

# 3. Gradient of a smoothed cost with respect to (k1, k2) through the relaxed engine switch.
sim, law = gj.build(scenario)
relaxed = law.relax(temperature=0.1)  # the smooth engine switch, for gradients


def cost(gains):
    tuned = eqx.tree_at(lambda l: (l.k1, l.k2), relaxed, (gains[0], gains[1]))
    out = jax.vmap(lambda i: scenario.system.simulate(sim, tuned, gj.run_key(0, i))[0])(
        jnp.arange(16)
    )
    return jnp.mean(jnp.sqrt(out.miss_m**2 + 1.0)) + 10.0 * jnp.mean(out.dv_mps)


print("d cost / d (k1, k2) =", jax.jit(jax.grad(cost))(jnp.array([4.0, 1.0])))
