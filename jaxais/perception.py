"""What a controller author needs from a :class:`~jaxais.controllers.Percept`, in one place.

Pure functions of one robot's arrays (``vmap`` them for a batch) and the constants behind them:
IR readings as proximity in [0, 1], the blue centroid as a signed offset, the wheel limit, the
IR sensors' sides and bearings and the antigen thresholds. :func:`jaxais.controllers.
braitenberg_controller` is written with them; a new controller is ``(init, learn, act)``
(:class:`~jaxais.controllers.Controller`) over these.

Conventions: IR ``ps0..ps7`` read 0..4095 (4095 at contact, about 67 beyond 7 cm); the camera's
columns are 0..14, 7 straight ahead, and the centroid is 7 when no blue pixel is seen; wheels
are (left, right) in e-puck speed units, + forward.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxais.envs.params import CAMERA_COLUMNS, IR_BEARINGS_DEG, N_IR
from jaxais.immune.antigens import COLLISION_THRESHOLD, OBSTACLE_THRESHOLD, SENSOR_SIDE
from jaxais.immune.behaviours import CENTRE_COLUMN, MAX_WHEEL_SPEED
from jaxais.immune.reinforcement import CENTRE_HALF_WIDTH

__all__ = [
    "CAMERA_COLUMNS",
    "CENTRE_COLUMN",
    "CENTRE_HALF_WIDTH",
    "COLLISION_THRESHOLD",
    "IR_BEARINGS_DEG",
    "LEFT",
    "MAX_WHEEL_SPEED",
    "N_IR",
    "OBSTACLE_THRESHOLD",
    "PROXIMITY_FROM",
    "PROXIMITY_SPAN",
    "REAR",
    "RIGHT",
    "SENSOR_SIDE",
    "centroid_offset",
    "clip_wheels",
    "proximity",
]

PROXIMITY_FROM = 100.0
"""The IR reading where :func:`proximity` starts to rise from 0: about 6 cm from the body
(``envs.params.IR_TABLE_VALUE``), beyond which a reading is mostly noise."""
PROXIMITY_SPAN = 500.0
"""Readings from ``PROXIMITY_FROM + PROXIMITY_SPAN`` (600, about 1.5 cm) up are proximity 1."""
RIGHT, REAR, LEFT = 0, 1, 2
"""The values of :data:`SENSOR_SIDE` [8]: ps0-ps2 right, ps3-ps4 rear, ps5-ps7 left (the sides
the obstacle and collision antigens name)."""


def proximity(ir: jax.Array) -> jax.Array:
    """IR readings [..., 8] as proximity [..., 8] in [0, 1]: 0 up to a reading of 100 (about
    6 cm), rising linearly to 1 at 600 (about 1.5 cm) and above."""
    return jnp.clip((jnp.asarray(ir) - PROXIMITY_FROM) / PROXIMITY_SPAN, 0.0, 1.0)


def centroid_offset(centroid: jax.Array, blue_pixels: jax.Array) -> jax.Array:
    """The blue centroid's column [...] as an offset [...] in [-1, 1] from straight ahead:
    -1 the image's left edge (column 0), +1 its right edge (14); 0 when no blue pixel is seen
    (``blue_pixels`` [...] == 0)."""
    seen = jnp.asarray(blue_pixels) > 0
    return jnp.where(seen, (centroid - CENTRE_COLUMN) / CENTRE_HALF_WIDTH, 0.0)


def clip_wheels(wheels: jax.Array) -> jax.Array:
    """Wheel speeds [..., 2] (left, right) clipped to the e-puck's [-1000, 1000]
    (:data:`MAX_WHEEL_SPEED`), as every built-in controller returns them."""
    return jnp.clip(wheels, -MAX_WHEEL_SPEED, MAX_WHEEL_SPEED)
