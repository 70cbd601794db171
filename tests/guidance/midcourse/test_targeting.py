"""Newton B-plane targeting: the linear solves against numpy, the fixed-iteration Newton loop on
closed-form maps, and the three sensitivity methods against each other on the real transfer."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax.guidance.midcourse import (
    SENSITIVITIES,
    SENSITIVITY_METHODS,
    AbstractMidcourseGuidance,
    AutodiffSensitivity,
    AutonomousCorrection,
    CentralDifferenceSensitivity,
    FunctionProblem,
    NewtonTargeter,
    STMSensitivity,
    solve_linear_targeting,
)
from gnc_jax.systems.midcourse import simulation as midcourse


@pytest.mark.parametrize("n,m", [(3, 3), (3, 2), (2, 3), (1, 3)])
def test_linear_solutions_match_numpy(n, m):
    rng = np.random.default_rng(n * 10 + m)
    k = rng.normal(size=(n, m)) * np.array([3e7, 1e7, 1e4])[:n, None]
    dq = rng.normal(size=n) * 1e6
    dp = np.asarray(solve_linear_targeting(jnp.asarray(k), jnp.asarray(dq)))
    if n == m:  # eq. 6: the unique solution
        np.testing.assert_allclose(k @ dp, dq, rtol=1e-10)
    elif n > m:  # eq. 9: least squares
        np.testing.assert_allclose(dp, np.linalg.lstsq(k, dq, rcond=None)[0], rtol=1e-9)
    else:  # eq. 12: minimum norm, i.e. the pseudo-inverse solution
        np.testing.assert_allclose(dp, np.linalg.pinv(k) @ dq, rtol=1e-9)
        np.testing.assert_allclose(k @ dp, dq, rtol=1e-10)


def _toy_map(p):
    """A smooth nonlinear map R³ -> R³ with a known Jacobian (the 'STM' of the toy)."""
    a = jnp.array([[2.0, 0.5, 0.1], [0.3, 1.5, -0.2], [0.1, -0.4, 1.0]])
    return a @ p + 0.05 * jnp.sin(p) * jnp.array([1.0, 2.0, 3.0]) + 0.02 * (p @ p)


def _toy_with_jacobian(p):
    return _toy_map(p), jax.jacfwd(_toy_map)(p)  # stands in for the variational equations


def _member(name, epsilon=1e-6):
    """The registered sensitivity method ``name``, built as ``build`` builds it."""
    return SENSITIVITY_METHODS[name].from_config({"sensitivity": name, "epsilon_mps": epsilon})


def test_registry_holds_the_scenario_names():
    """Every name the scenario schema allows is a registered method, and nothing else."""
    assert SENSITIVITIES == tuple(SENSITIVITY_METHODS)
    schema = gj.get_system("midcourse").schema()
    assert set(SENSITIVITIES) == set(schema["guidance.autonomous"]["sensitivity"].choices)
    assert [type(_member(n)) for n in ("autodiff", "central_difference", "stm")] == [
        AutodiffSensitivity,
        CentralDifferenceSensitivity,
        STMSensitivity,
    ]
    assert float(_member("central_difference", 2e-4).epsilon) == 2e-4
    assert AbstractMidcourseGuidance.laws["autonomous"] is AutonomousCorrection


def test_stm_without_variational_equations_is_an_error():
    targeter = NewtonTargeter(tolerance=jnp.full(3, 1e-10), sensitivity=STMSensitivity())
    with pytest.raises(ValueError, match="no variational equations"):
        targeter.solve(FunctionProblem(_toy_map), jnp.ones(3), jnp.zeros(3))


def test_central_difference_step_is_differentiable():
    """ε is an array leaf: d K / d ε of a cubic is the closed form 2 ε (K_cd = 3p² + ε²)."""
    problem = FunctionProblem(lambda p: p**3)
    k_of = lambda e: CentralDifferenceSensitivity(e).q_and_jacobian(problem, jnp.ones(1))[1][0, 0]
    np.testing.assert_allclose(k_of(0.1), 3.0 + 0.01, rtol=1e-12)
    np.testing.assert_allclose(jax.grad(k_of)(0.1), 0.2, rtol=1e-9)


@pytest.mark.parametrize("method", SENSITIVITIES)
def test_newton_converges_and_vmaps_like_a_loop(method):
    targeter = NewtonTargeter(
        tolerance=jnp.full(3, 1e-10), sensitivity=_member(method), iterations=8
    )
    targets = jnp.array([[1.0, -0.5, 0.3], [0.2, 0.2, 0.2], [-1.0, 0.7, 1.5]])
    problem = FunctionProblem(_toy_map, _toy_with_jacobian)
    solve = lambda q_t: targeter.solve(problem, q_t, jnp.zeros(3))
    batch = jax.jit(jax.vmap(solve))(targets)
    assert bool(jnp.all(batch.converged))
    np.testing.assert_allclose(jax.vmap(_toy_map)(batch.p), targets, atol=1e-10)
    one = jax.jit(solve)
    for i in range(3):
        single = one(targets[i])
        np.testing.assert_allclose(batch.p[i], single.p, rtol=1e-12, atol=1e-14)
        assert int(batch.iterations[i]) == int(single.iterations)
    assert int(batch.iterations.max()) < 8  # converged with iterations to spare
    np.testing.assert_allclose(batch.q_initial, jnp.zeros((3, 3)), atol=1e-15)


def test_newton_least_squares_and_minimum_norm_solutions():
    k = jnp.array([[1.0, 2.0], [0.5, -1.0], [2.0, 0.3]])
    q_t = jnp.array([1.0, 2.0, -0.5])  # inconsistent: no exact solution (n > m)
    result = NewtonTargeter(tolerance=jnp.full(3, 1e-9), iterations=3).solve(
        FunctionProblem(lambda p: k @ p), q_t, jnp.zeros(2)
    )
    np.testing.assert_allclose(result.p, np.linalg.lstsq(k, q_t, rcond=None)[0], rtol=1e-12)
    assert not bool(result.converged)  # residual left: flagged, not hidden
    kt = k.T  # n < m: the smallest correction meeting the target
    result = NewtonTargeter(tolerance=jnp.full(2, 1e-9), iterations=3).solve(
        FunctionProblem(lambda p: kt @ p), q_t[:2], jnp.zeros(3)
    )
    np.testing.assert_allclose(result.p, np.linalg.pinv(kt) @ q_t[:2], rtol=1e-12)
    assert bool(result.converged)


@pytest.fixture(scope="module")
def transfer():
    """The packaged default scenario's simulation and the nominal state at the first fix."""
    sim, law = gj.build(gj.load_scenario("phoenix-midcourse"))
    return sim, jnp.concatenate([sim.r0_m, sim.v0_mps])


@functools.partial(jax.jit, static_argnames="method")
def _sensitivity(sim, x, method, epsilon=1e-3):
    return midcourse.sensitivity(sim, _member(method, epsilon), sim.t_first_fix_s, x)


def _row_relative(k, k_ref):
    """max |K - K_ref| / max |row of K_ref|: rows have different units (m, s per m/s)."""
    k, k_ref = np.asarray(k), np.asarray(k_ref)
    return (np.abs(k - k_ref) / np.abs(k_ref).max(axis=1, keepdims=True)).max()


def test_autodiff_equals_central_difference_in_the_stable_region(transfer):
    """Acceptance: 1e-6 relative with ε = 2e-4 m/s (stable region 3e-5..3e-4 m/s for all
    partials; below it integration noise, above it the arrival-time row's curvature)."""
    sim, x = transfer
    q_ad, k_ad = _sensitivity(sim, x, "autodiff")
    q_cd, k_cd = _sensitivity(sim, x, "central_difference", 2e-4)
    np.testing.assert_allclose(q_ad, q_cd, rtol=0, atol=1e-2)  # same trajectory (m, s)
    assert _row_relative(k_cd, k_ad) < 1e-6
    # the partials are large: a 1 m/s error moves B by ~10^4 km
    assert np.abs(np.asarray(k_ad[:2])).max() > 1e7
    # outside the stable region the difference quotient departs (the paper's Fig. 1)
    _, k_big = _sensitivity(sim, x, "central_difference", 3.0)
    assert _row_relative(k_big, k_ad) > 1e-2


def test_stm_sensitivity_equals_autodiff(transfer):
    """Variational equations with the same adaptive steps: 1e-10 measured, 1e-8 asserted."""
    sim, x = transfer
    _, k_ad = _sensitivity(sim, x, "autodiff")
    q_stm, k_stm = _sensitivity(sim, x, "stm")
    assert _row_relative(k_stm, k_ad) < 1e-8
    # and the nominal is on its aim point (B_R, B_T, t): the design converged
    np.testing.assert_allclose(q_stm, sim.aim, atol=2.0)
