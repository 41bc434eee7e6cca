"""Behaviours: one antibody's wheel speeds for one iteration (SPEC 5).

Every behaviour is "both wheels at a base speed (S, or -S for reverse turn), with at most one
wheel per side reduced by X %", where reducing by X % means ``v = base * (1 - X / 100)``; X > 100
drives that wheel the other way [ours]. :func:`wheel_speeds` computes the two reductions for the
antibody's type with a few elementwise ``where``s instead of branching, because it runs every
iteration for thousands of robots.

The side D names the wheel that is reduced: D = left slows the left wheel, so the robot turns
left (reverse turn: the left wheel backs up slower, so the robot's rear swings right).
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

MAX_WHEEL_SPEED = 1000.0
"""Wheel speeds are clipped to +-this, speed units [ours, e-puck]."""
STATIC_TURN_REDUCTION = 100.0
"""Static turn stops the wheel on side D (a 100 % reduction), whatever the antibody's A holds."""
CENTRE_COLUMN = 7.0
"""Middle column of the 15-column camera image; track markers steers towards it."""

__all__ = [
    "CENTRE_COLUMN",
    "MAX_WHEEL_SPEED",
    "STATIC_TURN_REDUCTION",
    "wheel_speeds",
]


def wheel_speeds(
    u: jnp.ndarray, ab: Antibodies, blue_pixels: jnp.ndarray, blue_centroid: jnp.ndarray
) -> jnp.ndarray:
    """Left and right wheel speeds of one antibody for one iteration.

    Per type (S speed, F/Rf frequencies %, A/Ra reductions %, D side):

    - 0 wander single: with probability F/100 the wheel on side D is reduced by A %, else both S.
    - 1 wander both: with probability F/100 the left wheel is reduced by A %; otherwise, with
      probability Rf/100, the right wheel is reduced by Ra % (so a right turn has overall
      probability (1 - F/100) Rf/100); otherwise straight.
    - 2 forward turn: the wheel on side D is reduced by A %.
    - 3 static turn: the wheel on side D stopped, the other at S.
    - 4 reverse turn: both wheels at -S, the one on side D at -S (1 - A/100).
    - 5 track markers: the left (right) wheel reduced by A % when the blue centroid is left
      (right) of column 7; straight when centred or when there are no blue pixels.

    Args:
        u: [2] i.i.d. uniforms for the wander types' turn decisions (the controllers draw them
            once a bout, so a bout keeps its decision).
        ab: one antibody (scalar fields).
        blue_pixels: [] int number of blue pixels.
        blue_centroid: [] float mean column of the blue pixels (0 = leftmost, 14 = rightmost).

    Returns:
        [2] float32 (left, right) speeds, clipped to +-``MAX_WHEEL_SPEED``.
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
