"""Python API walk-through: a skip-entry dispersion study, a gain sweep and gain sensitivities.

python examples/capsule_study.py
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import gnc_jax as gj  # import first: float64 and one XLA device per core
from gnc_jax.statistics import interval_text

# 1. The packaged seed 003 scenario: 1000 dispersed runs, saved and plotted (Figs. 4-6).
scenario = gj.load_scenario("lunar-skip-entry")
study = gj.run_study(scenario, runs=1000, seed=0)
s = study.summary()
# a 3σ interval is n/a from fewer than two ok runs (no spread), as is a study with no ok run
sigma3 = {
    axis: s.get(f"{axis}_err_km", {}).get("three_sigma") for axis in ("downrange", "crossrange")
}
print(
    f"chute 3σ: downrange {interval_text(sigma3['downrange'], 'km')}, "
    f"crossrange {interval_text(sigma3['crossrange'], 'km')}; failed {s['failed']}; "
    f"{s['wall_s']:.1f} s for {study.runs} runs after {s['compile_s']:.1f} s compile"
)
study.save("results/example-skip-entry", overwrite=True)
print(gj.report("results/example-skip-entry"))

# 2. Sweep the range gain of the second-entry tracking law (same draws for every value; a new
#    gain reuses the compiled executable).
for k_range in (1.5, 2.0, 2.5, 3.0):
    t = gj.run_study(
        scenario.with_overrides({"guidance.skip_entry.k_range": k_range}), runs=300, seed=1
    )
    o = {k: v[t.ok] for k, v in t.outcomes.items()}  # the ok runs: a failed run is no sample
    print(
        f"k_range = {k_range}: downrange std {np.std(o['downrange_err_km']):.3f} km, "
        f"worst |miss| {np.max(np.hypot(o['downrange_err_km'], o['crossrange_err_km'])):.2f} km, "
        f"failed {t.runs - len(o['status'])}"
    )

# 3. Sensitivity of the chute downrange error to the four tracking gains, forward mode
#    through the whole closed loop. The evaluation program's predictor rounds are `while_loop`s,
#    which reverse mode cannot cross; `gj.tune` flies a checkpointed loop that it can.
sim, law = gj.build(scenario)
names = ("k_range", "k_drag_load", "k_hdot", "k_range_rate")


def downrange(gains, i):
    tuned = eqx.tree_at(lambda l: tuple(getattr(l, n) for n in names), law, tuple(gains))
    return scenario.system.simulate(sim, tuned, gj.run_key(0, i))[0].downrange_err_km


gains = jnp.stack([getattr(law, n) for n in names])
jac = jax.jit(jax.vmap(jax.jacfwd(downrange), in_axes=(None, 0)))(gains, jnp.arange(8))
print("d downrange (km) / d", names, "mean over 8 runs:", np.asarray(jac.mean(axis=0)))
