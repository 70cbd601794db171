"""Gain schedules (gnc_jax.guidance.schedule) and the LOS law's k1, k2 over time to go.

Against independent references: ``numpy.interp``, the constant-gain flight (bit for bit),
central differences of the relaxed closed loop, and the tuner's knot bookkeeping."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax.guidance.schedule import piecewise_linear
from gnc_jax.scenario import ScenarioError
from gnc_jax.tuning import Reparametrisation, resolve_gains, with_schedule_starts

TGO = [0.0, 100.0, 300.0, 600.0, 900.0]  # the short LOS test flight lasts about 900 s


def los(**extra):
    system = gj.get_system("impactor")
    overrides = {**system.test_overrides, "guidance.law": "los", **extra}
    return gj.load_scenario("deep-impact-los", overrides=overrides)


def test_piecewise_linear_matches_numpy_interp_and_its_gradient_is_the_hat_functions():
    rng = np.random.default_rng(0)
    b = np.sort(rng.uniform(0.0, 100.0, 9))
    v = rng.uniform(0.5, 5.0, 9)
    x = np.concatenate([rng.uniform(-20.0, 120.0, 200), b])  # outside, inside, at knots
    got = jax.vmap(lambda xi: piecewise_linear(xi, b, jnp.asarray(v)))(x)
    np.testing.assert_allclose(got, np.interp(x, b, v), rtol=1e-14, atol=1e-14)
    # linear in the values: d/dv_k is the interpolation of the k-th unit vector
    jac = jax.vmap(jax.grad(lambda vv, xi: piecewise_linear(xi, b, vv)), (None, 0))(
        jnp.asarray(v), x[:50]
    )
    hats = np.stack([np.interp(x[:50], b, e) for e in np.eye(9)], axis=1)
    np.testing.assert_allclose(jac, hats, atol=1e-12)
    # equal values give that value exactly, whatever x
    flat = jax.vmap(lambda xi: piecewise_linear(xi, b, jnp.full(9, 4.0)))(x)
    assert np.all(np.asarray(flat) == 4.0)


def test_a_schedule_of_equal_knots_flies_as_the_constant_gain_bit_for_bit():
    plain = gj.run_study(los(), runs=3, seed=5, progress=False)
    equal = los(**{
        "guidance.los.schedule_tgo_s": TGO,
        "guidance.los.k1_schedule": [4.0] * 5,
        "guidance.los.k2_schedule": [1.0] * 5,
    })  # fmt: skip
    same = gj.run_study(equal, runs=3, seed=5, progress=False)
    for field in plain.outcomes:
        np.testing.assert_array_equal(same.outcomes[field], plain.outcomes[field], err_msg=field)
    # and the schedule is flown: tighter tolerances late change the flight
    late = equal.with_overrides({"guidance.los.k1_schedule": [1.5, 1.5, 4.0, 4.0, 4.0]})
    other = gj.run_study(late, runs=3, seed=5, progress=False)
    assert not np.array_equal(other.outcomes["dv_mps"], plain.outcomes["dv_mps"])


def test_gradient_with_respect_to_the_knots_matches_central_differences():
    scenario = los(**{
        "guidance.los.schedule_tgo_s": TGO,
        "guidance.los.k1_schedule": [4.0] * 5,
    })  # fmt: skip
    system = scenario.system
    params, hard_law = gj.build(scenario)
    params = system.reverse_mode(params)
    relaxed = hard_law.relax(temperature=0.1)

    def objective(knots):
        law = eqx.tree_at(lambda l: l.k1_schedule, relaxed, knots)
        keys = jax.vmap(lambda i: gj.run_key(1, i))(jnp.arange(2))
        out = jax.vmap(lambda k: system.simulate(params, law, k)[0])(keys)
        return system.smooth_objective(out)

    # reverse mode through the loop; one program gives the values differenced below too
    value_and_grad = jax.jit(jax.value_and_grad(objective))
    objective = lambda knots: value_and_grad(knots)[0]  # noqa: E731
    x = jnp.asarray(hard_law.k1_schedule)
    grad = np.asarray(value_and_grad(x)[1])
    assert np.all(np.isfinite(grad))
    checked = 0
    for j in range(len(TGO)):
        fds = []
        for h in (1e-5, 1e-6):
            e = jnp.zeros(len(TGO)).at[j].set(h)
            fds.append(float((objective(x + e) - objective(x - e)) / (2 * h)))
        if max(abs(fd) for fd in fds) == 0.0:
            assert grad[j] == 0.0  # a knot the flight never reaches
            continue
        errors = [abs(grad[j] - fd) / abs(fd) for fd in fds if fd]
        assert min(errors) < 5e-3, f"knot {j}: gradient {grad[j]} vs central differences {fds}"
        checked += 1
    assert checked >= 2  # the flight spans several knots


@pytest.mark.parametrize(
    "overrides, message",
    [
        (
            {"guidance.los.k1_schedule": [4.0, 4.0]},
            "guidance.los.schedule_tgo_s: 0 breakpoints for guidance.los.k1_schedule",
        ),
        (
            {
                "guidance.los.schedule_tgo_s": [0.0, 300.0, 200.0],
                "guidance.los.k1_schedule": [4.0] * 3,
            },
            "guidance.los.schedule_tgo_s: [0.0, 300.0, 200.0] is not strictly increasing",
        ),
        (
            {"guidance.los.schedule_tgo_s": TGO, "guidance.los.k2_schedule": [1.0] * 4},
            "guidance.los.k2_schedule: 4 values for 5 breakpoints",
        ),
        (
            {"guidance.los.schedule_tgo_s": TGO, "guidance.los.k1_schedule": [4, 4, 0.0, 4, 4]},
            "guidance.los.k1_schedule: 0.0 is out of range",
        ),
        (
            {"guidance.los.schedule_tgo_s": TGO, "guidance.los.k2_schedule": [1, 1, 5, 1, 1]},
            "guidance.los.k2_schedule: 5 > k1 = 4 (breakpoint 2)",
        ),
    ],
)
def test_bad_schedules_are_refused_in_one_line_naming_the_field(overrides, message):
    with pytest.raises(ScenarioError) as err:
        los(**overrides)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_schedule_is_tuned_knot_by_knot_in_order_from_its_constant_gain():
    names = ["guidance.los.k1_schedule", "guidance.los.k2_schedule"]
    with pytest.raises(ScenarioError, match="guidance.los.schedule_tgo_s: 0 breakpoints"):
        with_schedule_starts(los(), names)
    scenario = with_schedule_starts(los(**{"guidance.los.schedule_tgo_s": TGO}), names)
    assert scenario["guidance.los.k1_schedule"] == [4.0] * 5
    gains = resolve_gains(scenario, names)
    assert [g.name for g in gains][:2] == [
        "guidance.los.k1_schedule[0]",
        "guidance.los.k1_schedule[1]",
    ]
    assert len(gains) == 10
    param = Reparametrisation.of(scenario, gains)
    assert param.below == tuple(range(5, 10)) + (-1,) * 5  # k1[j] above k2[j]
    theta = np.random.default_rng(1).normal(size=10)
    values = np.asarray(param.gains(jnp.asarray(theta)))
    assert np.all(values[:5] >= values[5:])
    np.testing.assert_allclose(param.theta(values), theta, rtol=1e-12)
    with pytest.raises(ScenarioError, match="guidance.los.k1: its schedule k1_schedule is set"):
        resolve_gains(scenario, ["guidance.los.k1"])


def test_skip_entry_tracking_gains_scheduled_over_speed_are_the_constant_gains_interpolated():
    """K(v) of eq. 7 with the tracking multipliers scheduled over speed equals K(v) of the
    constant law whose multipliers are ``numpy.interp`` of the knots at that speed (bit for
    bit with equal knots)."""
    from gnc_jax.guidance.entry.tracking import feedback_gains

    speeds_kmps = [2.0, 4.0, 6.0, 8.0, 10.0]
    k_range = [2.5, 2.0, 3.0, 3.5, 2.5]
    k_hdot = [1.0, 1.0, 1.0, 1.0, 1.0]
    base = gj.load_scenario("lunar-skip-entry")
    scheduled = base.with_overrides({
        "guidance.skip_entry.schedule_speed_kmps": speeds_kmps,
        "guidance.skip_entry.k_range_schedule": k_range,
        "guidance.skip_entry.k_hdot_schedule": k_hdot,
    })  # fmt: skip
    _, constant = gj.build(base)
    _, law = gj.build(scheduled)
    for v in (1500.0, 3000.0, 5000.0, 7300.0, 9999.0, 11000.0):
        got = feedback_gains(law, v)
        k = float(np.interp(v / 1e3, speeds_kmps, k_range))
        reference = eqx.tree_at(lambda l: l.k_range, constant, jnp.asarray(k))
        np.testing.assert_allclose(got, feedback_gains(reference, v), rtol=1e-14, atol=0.0)
        equal = eqx.tree_at(lambda l: l.k_range_schedule, law, jnp.full(5, 2.5))
        flat = feedback_gains(eqx.tree_at(lambda l: l.k_hdot_schedule, equal, jnp.full(5, 1.0)), v)
        np.testing.assert_array_equal(flat, feedback_gains(constant, v))
    with pytest.raises(ScenarioError, match="guidance.skip_entry.k_range_schedule: 4 values"):
        scheduled.with_overrides({"guidance.skip_entry.k_range_schedule": k_range[:4]})
