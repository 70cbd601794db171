import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax.dynamics.atmosphere import Atmosphere, exponential_density, us76_density

# U.S. Standard Atmosphere 1976 (NOAA-S/T 76-1562), Table I, geometric altitude (km) ->
# density (kg/m^3) as printed to four significant figures.
US76_PUBLISHED = {
    0: 1.2250,
    11: 3.6480e-1,
    20: 8.8910e-2,
    50: 1.0269e-3,
    86: 6.958e-6,
    90: 3.416e-6,
    100: 5.604e-7,
    110: 9.708e-8,
    120: 2.222e-8,
    150: 2.076e-9,
    200: 2.541e-10,
    300: 1.916e-11,
    500: 5.215e-13,
    700: 3.070e-14,
    1000: 3.561e-15,
}


def test_us76_matches_ussa1976_to_120km():
    ussa1976 = pytest.importorskip("ussa1976")
    z = np.arange(0.0, 120e3 + 1.0, 50.0)  # dense: 5 points per table interval
    reference = ussa1976.compute(z=z, variables=["rho"])["rho"].values
    rel_err = np.asarray(jax.jit(us76_density)(z)) / reference - 1.0
    assert np.max(np.abs(rel_err)) < 0.01
    # Below 86 km both evaluate the same closed-form layers: much tighter than 1 %.
    assert np.max(np.abs(rel_err[z <= 86e3])) < 2e-3


@pytest.mark.parametrize("alt_km", sorted(US76_PUBLISHED))
def test_us76_matches_published_table(alt_km):
    rho = float(us76_density(alt_km * 1e3))
    assert rho == pytest.approx(US76_PUBLISHED[alt_km], rel=1.5e-3)


def test_us76_monotone_and_positive_to_1000km_and_beyond():
    z = jnp.linspace(-2e3, 1.2e6, 200_001)
    rho = jax.jit(us76_density)(z)
    assert bool(jnp.all(rho > 0.0))
    assert bool(jnp.all(jnp.diff(rho) < 0.0))


def test_us76_gradient_matches_finite_difference():
    # Points away from the table nodes and on both sides of layer boundaries.
    alts = jnp.array(
        [
            123.0,
            5_555.5,
            11_100.3,
            47_123.4,
            85_987.0,
            86_013.0,
            99_990.1,
            114_997.0,
            133_333.3,
            451_234.5,
            987_654.3,
        ]
    )
    log_rho = jax.jit(lambda h: jnp.log(us76_density(h)))
    grad = jax.jit(jax.vmap(jax.grad(log_rho)))(alts)
    step = 1e-2  # m
    fd = (log_rho(alts + step) - log_rho(alts - step)) / (2 * step)
    assert bool(jnp.all(jnp.isfinite(grad)))
    np.testing.assert_allclose(grad, fd, rtol=1e-6)
    # d ln(rho)/dh = -1/H: a physical scale height (5 km low down, ~250 km in the He exosphere).
    assert bool(jnp.all((-1.0 / grad > 5e3) & (-1.0 / grad < 3e5)))


def test_exponential_density_closed_form():
    h = jnp.array([0.0, 7200.0, 50e3])
    np.testing.assert_allclose(exponential_density(h), 1.225 * np.exp(-np.array(h) / 7200.0))
    np.testing.assert_allclose(exponential_density(1000.0, 2.0, 500.0), 2.0 * np.exp(-2.0))


@pytest.mark.parametrize("model", ["us76", "exponential"])
def test_atmosphere_module_selects_model_and_scales(model):
    reference = {"us76": us76_density, "exponential": exponential_density}[model]
    h = jnp.linspace(0.0, 150e3, 7)
    atmosphere = Atmosphere(model=model, density_scale=1.3)
    np.testing.assert_allclose(atmosphere.density(h), 1.3 * reference(h), rtol=1e-14)
    # The dispersion multiplier is an array leaf: a batch of atmospheres vmaps.
    scales = jnp.array([0.7, 1.0, 1.3])
    batch = jax.vmap(lambda s: Atmosphere(model=model, density_scale=s).density(60e3))(scales)
    np.testing.assert_allclose(batch, scales * reference(60e3), rtol=1e-14)


def test_atmosphere_rejects_unknown_model():
    with pytest.raises(ValueError, match="unknown atmosphere model"):
        Atmosphere(model="msis")


def test_us76_bucket_lookup_finds_the_interval_numpy_searchsorted_finds():
    """The bucketed interval search (no binary search under vmap) against numpy's
    searchsorted on the table nodes: at every node, one ulp either side, bucket edges and
    random altitudes inside and outside 0-1000 km."""
    from gnc_jax.dynamics import atmosphere as a

    nodes = a._US76_ALT_M
    edges = nodes[0] + a._US76_BUCKET_M * np.arange(-4, a._US76_BUCKETS.shape[0] + 4)
    z = np.concatenate(
        [
            nodes,
            np.nextafter(nodes, -np.inf),
            np.nextafter(nodes, np.inf),
            edges,
            np.nextafter(edges, -np.inf),
            np.random.default_rng(0).uniform(-5e3, 1.1e6, 100_000),
            [-1e30, 1e30, np.inf, -np.inf],
        ]
    )
    expected = np.clip(np.searchsorted(nodes, z, side="right") - 1, 0, len(nodes) - 2)
    np.testing.assert_array_equal(np.asarray(jax.jit(a._us76_interval)(z)), expected)
