"""Behaviours: one antibody's wheel speeds for one iteration (SPEC 5).

Every behaviour is both wheels at a base speed (S, or -S for reverse turn) with at most one wheel
per side reduced by X %: ``v = base * (1 - X / 100)``, X > 100 reversing it [ours]. D names the
reduced wheel: D = left turns left.
"""

from __future__ import annotations

import jax.numpy as jnp

from jaxais.immune.antibodies import (
    FORWARD_TURN,
    LEFT,
    REVERSE_TURN,
    RIGHT,
    STATIC_TURN,
    TRACK_MARKERS,
    WANDER_BOTH,
    WANDER_SINGLE,
    Antibodies,
)

MAX_WHEEL_SPEED = 1000.0  # speed units [ours, e-puck]
STATIC_TURN_REDUCTION = 100.0  # static turn stops side D's wheel, whatever A holds
CENTRE_COLUMN = 7.0  # the camera's middle column, which track markers steers towards


def wheel_speeds(
    u: jnp.ndarray, ab: Antibodies, blue_pixels: jnp.ndarray, blue_centroid: jnp.ndarray
) -> jnp.ndarray:
    """[2] float32 (left, right) speeds of one antibody; ``u`` [2] are the wander types' turn
    draws (made once a bout). Branch-free, as it runs for thousands of robots.

    - 0 wander single: side D reduced by A % with probability F/100.
    - 1 wander both: left by A % with probability F/100, else right by Ra % with Rf/100.
    - 2 forward turn: side D reduced by A %. 3 static turn: side D stopped.
    - 4 reverse turn: both at -S, side D at -S (1 - A/100).
    - 5 track markers: the side of the blue centroid (vs column 7) reduced by A %.
    """
    t = ab.type
    speed = jnp.asarray(ab.speed, jnp.float32)
    angle = jnp.asarray(ab.angle, jnp.float32)
    on_left, on_right = ab.direction == LEFT, ab.direction == RIGHT

    # Which wheel each type reduces this iteration.
    # Wander single and wander both share the first draw: both turn with probability F/100.
    turn_first = u[0] < ab.freq / 100.0
    turn_both_right = ~turn_first & (u[1] < ab.right_freq / 100.0)
    seen = jnp.asarray(blue_pixels) > 0
    track_left = seen & (blue_centroid < CENTRE_COLUMN)
    track_right = seen & (blue_centroid > CENTRE_COLUMN)
    side_d = (t == FORWARD_TURN) | (t == STATIC_TURN) | (t == REVERSE_TURN)
    side_d = side_d | ((t == WANDER_SINGLE) & turn_first)
    reduce_left = (
        (side_d & on_left) | ((t == WANDER_BOTH) & turn_first) | ((t == TRACK_MARKERS) & track_left)
    )
    reduce_right = (
        (side_d & on_right)
        | ((t == WANDER_BOTH) & turn_both_right)
        | ((t == TRACK_MARKERS) & track_right)
    )

    # By how much (%): A, except static turn (always a full stop) and wander both's right (Ra).
    amount = jnp.where(t == STATIC_TURN, STATIC_TURN_REDUCTION, angle)
    right_amount = jnp.where(t == WANDER_BOTH, jnp.asarray(ab.right_angle, jnp.float32), amount)
    base = jnp.where(t == REVERSE_TURN, -speed, speed)
    # (100 - X) / 100 rather than 1 - X / 100: XLA turns the division into a multiplication by
    # 0.01, and only this order keeps a 100 % reduction (static turn) an exact stop.
    left = base * ((100.0 - jnp.where(reduce_left, amount, 0.0)) / 100.0)
    right = base * ((100.0 - jnp.where(reduce_right, right_amount, 0.0)) / 100.0)
    return jnp.clip(jnp.stack([left, right]), -MAX_WHEEL_SPEED, MAX_WHEEL_SPEED)
