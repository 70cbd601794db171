"""A toy system registered from outside the package: a planar double-integrator intercept.

A pursuer with a bounded acceleration chases a target moving at constant velocity in a plane;
the state is the relative position and velocity (target minus pursuer), the truth is exact
(a double integrator is integrated exactly with a piecewise-constant acceleration) and the
pursuer measures the relative position with Gaussian noise at every step (a fixed-gain
alpha-beta filter). Two laws form its family: proportional navigation ("pn") and a
proportional-derivative law on the zero-effort miss ("zem"). The miss is the closest approach
of the final relative state.

Nothing here lives inside ``gnc_jax/``: this is what a user writes to add a system. The tests
check that ``run``, ``summary.json``, ``report`` and the family tests work for it unchanged.
"""

import pathlib
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import gnc_jax as gj
from gnc_jax.guidance.base import AbstractGuidanceLaw, register_law
from gnc_jax.params import param
from gnc_jax.schema import Field, ScenarioError
from gnc_jax.systems import AbstractSystem, register_system
from gnc_jax.systems.loop import with_status


class ToyParams(eqx.Module):
    r0: jax.Array  # relative position target - pursuer, m
    v0: jax.Array  # relative velocity, m/s
    sigma_r0: jax.Array  # 1-sigma initial position dispersion, m
    sigma_meas: jax.Array  # measurement noise, m
    a_max: jax.Array  # acceleration bound, m/s^2
    dt: float = eqx.field(static=True)
    steps: int = eqx.field(static=True)


class ToyNav(NamedTuple):
    r: jax.Array
    v: jax.Array


class ToyOutcome(NamedTuple):
    status: jax.Array
    miss_m: jax.Array
    dv_mps: jax.Array
    dispersion_m: jax.Array


class ToyTrace(NamedTuple):
    t_s: jax.Array
    r_m: jax.Array
    accel: jax.Array


class AbstractToyGuidance(AbstractGuidanceLaw):
    laws: ClassVar[dict[str, type]] = {}


@register_law("pn")
class ToyPN(AbstractToyGuidance):
    """a = N V_c lambda_dot (perpendicular to the line of sight)."""

    n: jax.Array = param(3.0, lo=0.5, hi=10.0, doc="navigation constant", tunable=True)

    def init(self, nav, ctx):
        return jnp.zeros(())

    def step(self, state, nav, t, ctx):
        r, v = nav.r, nav.v
        r2 = jnp.dot(r, r)
        lam_dot = (r[0] * v[1] - r[1] * v[0]) / r2
        vc = -jnp.dot(r, v) / jnp.sqrt(r2)
        u_perp = jnp.array([-r[1], r[0]]) / jnp.sqrt(r2)
        return self.n * vc * lam_dot * u_perp, state


@register_law("zem")
class ToyZEM(AbstractToyGuidance):
    """a = k ZEM / t_go^2 with t_go = -|r|^2 / (r . v)."""

    k: jax.Array = param(3.0, lo=0.1, hi=20.0, doc="zero-effort-miss gain", tunable=True)

    def init(self, nav, ctx):
        return jnp.zeros(())

    def step(self, state, nav, t, ctx):
        r, v = nav.r, nav.v
        t_go = jnp.maximum(-jnp.dot(r, r) / jnp.dot(r, v), 1.0)
        zem = r + v * t_go
        return self.k * zem / t_go**2, state


def _closest_approach(r, v):
    t = jnp.clip(-jnp.dot(r, v) / jnp.dot(v, v), 0.0, None)
    return jnp.linalg.norm(r + v * t)


@register_system
class ToySystem(AbstractSystem):
    name = "toy-intercept"
    description = "planar double-integrator intercept (a user's system, kept in the tests)"
    sections: ClassVar[dict[str, dict[str, Field]]] = {
        "geometry": {
            "range_m": Field("float", 10000.0, lo=100.0, hi=1e6, units="m"),
            "closing_speed_mps": Field("float", 100.0, lo=1.0, hi=1e4, units="m/s"),
            "lateral_speed_mps": Field("float", 5.0, lo=-1e3, hi=1e3, units="m/s"),
            "dispersion_m": Field("float", 50.0, lo=0.0, hi=1e4, units="m"),
        },
        "vehicle": {"accel_max_mps2": Field("float", 5.0, lo=0.0, lo_open=True, hi=100.0)},
        "navigation": {"noise_m": Field("float", 1.0, lo=0.0, hi=1e3, units="m")},
        "guidance": {"dt_s": Field("float", 0.5, lo=0.01, hi=10.0, units="s")},
    }
    law_family = AbstractToyGuidance
    default_law = "pn"
    metrics = ("miss_rms_m", "dv_mean_mps")
    paper_labels: ClassVar[dict[str, str]] = {"miss_rms_m": "miss RMS (m)"}
    example = str(pathlib.Path(__file__).with_name("toy.toml"))
    test_overrides: ClassVar[dict[str, Any]] = {}

    def check(self, config):
        g = config["geometry"]
        if g["range_m"] / g["closing_speed_mps"] < 10 * config["guidance"]["dt_s"]:
            raise ScenarioError("geometry.range_m: too short for ten guidance steps")

    step_seconds = 1e-7  # a guidance step of the double integrator, roughly

    def steps_per_run(self, config):
        g = config["geometry"]
        return g["range_m"] / g["closing_speed_mps"] / config["guidance"]["dt_s"]

    def build(self, scenario):
        g, c = scenario.config["geometry"], scenario.config
        f = lambda x: jnp.asarray(x, jnp.float64)  # noqa: E731
        dt = c["guidance"]["dt_s"]
        steps = int(np.ceil(g["range_m"] / g["closing_speed_mps"] / dt)) - 2
        params = ToyParams(
            r0=f([g["range_m"], 0.0]),
            v0=f([-g["closing_speed_mps"], g["lateral_speed_mps"]]),
            sigma_r0=f(g["dispersion_m"]),
            sigma_meas=f(c["navigation"]["noise_m"]),
            a_max=f(c["vehicle"]["accel_max_mps2"]),
            dt=dt,
            steps=steps,
        )
        return params, self.build_law(scenario.config)

    def simulate(self, params, law, key, record=False):
        p = params
        d = p.sigma_r0 * jax.random.normal(jax.random.fold_in(key, 0), (2,))
        r, v = p.r0 + d, p.v0
        noise = jax.random.normal(jax.random.fold_in(key, 1), (p.steps, 2))

        def step(carry, inputs):
            r, v, r_hat, v_hat, state, dv = carry
            i, w = inputs
            a, state = law.step(state, ToyNav(r_hat, v_hat), i * p.dt, None)
            a = a * jnp.minimum(1.0, p.a_max / jnp.sqrt(jnp.dot(a, a) + 1e-30))
            # the pursuer accelerates: the relative acceleration is -a
            r_new = r + v * p.dt - 0.5 * a * p.dt**2
            v_new = v - a * p.dt
            z = r_new + p.sigma_meas * w
            r_pred, v_pred = r_hat + v_hat * p.dt - 0.5 * a * p.dt**2, v_hat - a * p.dt
            res = z - r_pred
            carry = (
                r_new,
                v_new,
                r_pred + 0.5 * res,
                v_pred + 0.1 * res / p.dt,
                state,
                dv + jnp.sqrt(jnp.dot(a, a) + 1e-30) * p.dt,
            )
            return carry, (ToyTrace(i * p.dt, r_new, a) if record else None)

        init = (r, v, r, v, law.init(ToyNav(r, v), None), jnp.zeros(()))
        (r, v, *_, dv), trace = jax.lax.scan(step, init, (jnp.arange(p.steps), noise))
        out = ToyOutcome(jnp.zeros((), jnp.int32), _closest_approach(r, v), dv, jnp.linalg.norm(d))
        return with_status(
            out, [(out.miss_m > 0.5 * jnp.linalg.norm(p.r0), gj.Status.time_out)]
        ), trace

    def smooth_objective(self, outcomes):
        return jnp.mean(outcomes.miss_m) + 0.1 * jnp.mean(outcomes.dv_mps)

    def statistics(self, outcomes, ok):
        if not ok.any():
            return {}
        miss = outcomes["miss_m"][ok]
        return dict(
            miss_rms_m=float(np.sqrt(np.mean(miss**2))),
            dv_mean_mps=float(np.mean(outcomes["dv_mps"][ok])),
        )

    def figures(self, summary, runs, scenario, out, traces=None):
        from gnc_jax.plotting import pyplot

        plt = pyplot()
        fig, ax = plt.subplots()
        ax.hist(runs["miss_m"], bins=20)
        ax.set_xlabel("miss (m)")
        path = out / "miss.png"
        fig.savefig(path)
        plt.close(fig)
        return [path]
