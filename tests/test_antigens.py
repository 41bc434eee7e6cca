"""Antigen classification (SPEC 4): thresholds, sides, target seen, helpers, JAX properties."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxais.envs import Observation
from jaxais.immune.antigens import (
    ANTIGEN_NAMES,
    COLLISION_THRESHOLD,
    N_ANTIGENS,
    OBSTACLE_THRESHOLD,
    antigen,
    antigen_of,
    is_collision,
    is_obstacle_or_collision,
    severity,
)

_antigen = jax.jit(antigen)
_batched = jax.jit(jax.vmap(antigen))

RIGHT, REAR, LEFT = 0, 1, 2
SENSOR_SIDE = [RIGHT, RIGHT, RIGHT, REAR, REAR, LEFT, LEFT, LEFT]


def _ir(sensor: int, value: float, background: float = 100.0) -> np.ndarray:
    ir = np.full(8, background, np.float32)
    ir[sensor] = value
    return ir


def _reference(ir: np.ndarray, blue_pixels: int) -> int:
    """Plain-Python SPEC 4."""
    vm = float(np.max(ir))
    side = SENSOR_SIDE[int(np.argmax(ir))]
    if vm < 250:
        return 1 if blue_pixels > 0 else 0
    if vm < 2400:
        return 2 + side
    return 5 + side


def test_constants() -> None:
    assert OBSTACLE_THRESHOLD == 250.0
    assert COLLISION_THRESHOLD == 2400.0
    assert N_ANTIGENS == len(ANTIGEN_NAMES) == 8
    assert ANTIGEN_NAMES[0] == "target unseen"
    assert ANTIGEN_NAMES[1] == "target seen"
    assert ANTIGEN_NAMES[2:5] == ("obstacle right", "obstacle rear", "obstacle left")
    assert ANTIGEN_NAMES[5:] == ("collision right", "collision rear", "collision left")


@pytest.mark.parametrize("sensor", range(8))
@pytest.mark.parametrize(
    ("value", "level"), [(249.9, 0), (250.0, 1), (2399.9, 1), (2400.0, 2), (4095.0, 2)]
)
@pytest.mark.parametrize("blue", [0, 1])
def test_thresholds_and_sides(sensor: int, value: float, level: int, blue: int) -> None:
    side = SENSOR_SIDE[sensor]
    expected = blue if level == 0 else 2 + 3 * (level - 1) + side
    got = _antigen(_ir(sensor, value), jnp.int32(blue))
    assert got.dtype == jnp.int32
    assert int(got) == expected


def test_all_quiet() -> None:
    assert int(_antigen(np.zeros(8, np.float32), jnp.int32(0))) == 0
    assert int(_antigen(np.zeros(8, np.float32), jnp.int32(45))) == 1


def test_blue_pixels_ignored_near_obstacles() -> None:
    # An obstacle antigen wins over target seen: the camera only matters when Vm < 250.
    assert int(_antigen(_ir(6, 300.0), jnp.int32(45))) == 4


def test_tie_goes_to_lowest_sensor() -> None:
    ir = _ir(2, 1000.0)
    ir[5] = 1000.0  # ps2 (right) and ps5 (left) tie: argmax picks ps2
    assert int(_antigen(ir, jnp.int32(0))) == 2


def test_antigen_of_observation() -> None:
    ir = _ir(3, 2500.0)
    obs = Observation(
        ir=jnp.asarray(ir),
        vm=jnp.max(jnp.asarray(ir)),
        blue=jnp.zeros((3, 15), bool),
        blue_pixels=jnp.int32(3),
        goal_pixels=jnp.int32(0),
        blue_centroid=jnp.float32(7.0),
        materials=jnp.zeros(15, jnp.int32),
        depth=jnp.full(15, jnp.inf),
    )
    assert int(jax.jit(antigen_of)(obs)) == 6
    quiet = obs.replace(ir=jnp.zeros(8, jnp.float32), vm=jnp.float32(0.0))
    assert int(jax.jit(antigen_of)(quiet)) == 1


def test_helpers() -> None:
    m = jnp.arange(8)
    np.testing.assert_array_equal(is_obstacle_or_collision(m), [0, 0, 1, 1, 1, 1, 1, 1])
    np.testing.assert_array_equal(is_collision(m), [0, 0, 0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(severity(m), [0, 0, 1, 1, 1, 2, 2, 2])
    assert severity(m).dtype == jnp.int32


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_matches_reference_and_vmap(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # Mix quiet, obstacle and collision scales so every antigen turns up.
    scale = rng.choice([240.0, 2000.0, 4095.0], size=(64, 1))
    ir = (rng.random((64, 8)) * scale).astype(np.float32)
    blue = rng.integers(0, 3, size=64).astype(np.int32)
    got = np.asarray(_batched(ir, blue))
    expected = [_reference(ir[i], int(blue[i])) for i in range(64)]
    np.testing.assert_array_equal(got, expected)
    # Leading batch dimensions also work without vmap.
    np.testing.assert_array_equal(np.asarray(_antigen(ir, blue)), expected)
