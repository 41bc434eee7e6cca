"""Antigens: the one environmental situation presented to the controller each iteration (SPEC 4).

With ``Vm`` the maximum IR reading (paper section 4.1):

- ``Vm < 250``: 0 target unseen / 1 target seen (at least one blue pixel [ours]);
- ``250 <= Vm < 2400``: 2 obstacle right / 3 obstacle rear / 4 obstacle left;
- ``Vm >= 2400``: 5 collision right / 6 collision rear / 7 collision left.

The side is the sensor group holding ``Vm`` [ours]: right ps0-ps2, rear ps3-ps4, left ps5-ps7.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp
import numpy as np

if TYPE_CHECKING:  # only for annotations: antigens must not need the simulator to import
    from jaxais.envs import Observation


OBSTACLE_THRESHOLD = 250.0  # Vm from here: an obstacle antigen (2-4) [paper]
COLLISION_THRESHOLD = 2400.0  # Vm from here: a collision antigen (5-7) [paper]

N_ANTIGENS = 8
TARGET_UNSEEN = 0
TARGET_SEEN = 1
OBSTACLE_RIGHT, OBSTACLE_REAR, OBSTACLE_LEFT = 2, 3, 4
COLLISION_RIGHT, COLLISION_REAR, COLLISION_LEFT = 5, 6, 7
ANTIGEN_NAMES = (
    "target unseen",
    "target seen",
    "obstacle right",
    "obstacle rear",
    "obstacle left",
    "collision right",
    "collision rear",
    "collision left",
)

# [8] side of each IR sensor ps0..ps7, 0 right, 1 rear, 2 left [ours, e-puck bearings].
SENSOR_SIDE = np.array([0, 0, 0, 1, 1, 2, 2, 2], dtype=np.int32)


def antigen(ir: jnp.ndarray, blue_pixels: jnp.ndarray) -> jnp.ndarray:
    """int32 antigen 0-7 [...] of IR readings [..., 8] and blue pixel counts [...]; among
    sensors sharing the maximum, the lowest-numbered decides the side."""
    ir = jnp.asarray(ir, jnp.float32)
    vm = jnp.max(ir, axis=-1)
    side = jnp.asarray(SENSOR_SIDE)[jnp.argmax(ir, axis=-1)]
    # level 0 clear, 1 obstacle, 2 collision; antigen = 2 + 3 (level - 1) + side for level >= 1.
    obstacle, collision = vm >= OBSTACLE_THRESHOLD, vm >= COLLISION_THRESHOLD
    level = obstacle.astype(jnp.int32) + collision.astype(jnp.int32)
    clear = (jnp.asarray(blue_pixels) > 0).astype(jnp.int32)
    return jnp.where(level == 0, clear, 3 * level - 1 + side).astype(jnp.int32)


def antigen_of(obs: Observation) -> jnp.ndarray:
    """The antigen of an :class:`~jaxais.envs.Observation`."""
    return antigen(obs.ir, obs.blue_pixels)


def is_obstacle_or_collision(m: jnp.ndarray) -> jnp.ndarray:
    """True for antigens 2-7 (something within IR range)."""
    return jnp.asarray(m) >= OBSTACLE_RIGHT


def is_collision(m: jnp.ndarray) -> jnp.ndarray:
    """True for antigens 5-7."""
    return jnp.asarray(m) >= COLLISION_RIGHT


def severity(m: jnp.ndarray) -> jnp.ndarray:
    """int32 ``lev`` of SPEC 6: 0 for antigens 0-1, 1 for obstacles, 2 for collisions."""
    return is_obstacle_or_collision(m).astype(jnp.int32) + is_collision(m).astype(jnp.int32)
