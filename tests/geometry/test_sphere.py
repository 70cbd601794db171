"""Great-circle helpers against numpy spherical trigonometry."""

import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax.geometry.sphere import (
    along_cross_track,
    along_track_to_go,
    central_angle,
    crossrange_to_target,
    destination,
    range_rate_to_target,
)


def random_unit(rng):
    x = rng.normal(size=3)
    return x / np.linalg.norm(x)


def test_central_angle_matches_arccos_and_is_accurate_when_small():
    rng = np.random.default_rng(0)
    for _ in range(50):
        a, b = random_unit(rng), random_unit(rng)
        assert float(central_angle(jnp.asarray(a), jnp.asarray(b))) == pytest.approx(
            np.arccos(np.clip(a @ b, -1, 1)), abs=1e-12
        )
    a = np.array([1.0, 0.0, 0.0])
    tiny = 1e-9  # acos(cos(1e-9)) would give 0 in float64
    b = np.array([np.cos(tiny), np.sin(tiny), 0.0])
    assert float(central_angle(jnp.asarray(a), jnp.asarray(b))) == pytest.approx(tiny, rel=1e-9)


def test_destination_travels_the_angle_along_the_heading():
    lat, lon = np.radians(-3.34), np.radians(63.54)
    start = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    az, ang = np.radians(34.3), 8000e3 / 6378137.0
    end = np.asarray(destination(jnp.asarray(start), az, ang))
    assert np.linalg.norm(end) == pytest.approx(1.0)
    assert np.arccos(start @ end) == pytest.approx(ang, rel=1e-12)
    # initial heading by the spherical formula tan(az) = sin(dlon) cos(lat2) /
    # (cos(lat1) sin(lat2) - sin(lat1) cos(lat2) cos(dlon))
    lat2, lon2 = np.arcsin(end[2]), np.arctan2(end[1], end[0])
    dlon = lon2 - lon
    az_check = np.arctan2(
        np.sin(dlon) * np.cos(lat2),
        np.cos(lat) * np.sin(lat2) - np.sin(lat) * np.cos(lat2) * np.cos(dlon),
    )
    assert az_check == pytest.approx(az, abs=1e-12)


def test_along_and_cross_track_recover_a_constructed_point():
    start = jnp.array([1.0, 0.0, 0.0])
    target = destination(start, 0.3, 1.2)
    heading_at_target = 0.3  # only used to build the point: go along, then across
    beyond = destination(start, heading_at_target, 1.2 + 0.01)  # 0.01 rad past the target
    along, cross = (float(x) for x in along_cross_track(beyond, start, target))
    assert along == pytest.approx(0.01, abs=1e-12) and abs(cross) < 1e-12
    # a point off to the left of the track: positive cross-track
    n = np.cross(np.asarray(start), np.asarray(target))
    n /= np.linalg.norm(n)
    left = np.cos(0.002) * np.asarray(target) + np.sin(0.002) * n
    along, cross = (float(x) for x in along_cross_track(jnp.asarray(left), start, target))
    assert cross == pytest.approx(0.002, rel=1e-9) and abs(along) < 1e-9


def test_crossrange_and_range_rate_signs():
    r = jnp.array([6.4e6, 0.0, 0.0])
    v = jnp.array([0.0, 0.0, 7000.0])  # heading north at the equator; left is west (-y)
    west_target = jnp.array([np.cos(0.5), -np.sin(0.5) * 0.1, np.sin(0.5)])
    west_target = west_target / jnp.linalg.norm(west_target)
    assert float(crossrange_to_target(r, v, west_target)) > 0
    north_target = jnp.array([np.cos(0.5), 0.0, np.sin(0.5)])
    assert float(range_rate_to_target(r, v, north_target)) == pytest.approx(-7000.0 / 6.4e6)
    assert float(along_track_to_go(r, v, north_target)) == pytest.approx(0.5)
