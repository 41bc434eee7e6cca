"""Behaviours (SPEC 5): wheel speeds of each antibody type, hand-worked and against a reference."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxais.immune.antibodies import (
    LIMITS_MAX,
    LIMITS_MIN,
    N_TYPES,
    USES,
    Antibodies,
    from_matrix,
    take,
)
from jaxais.immune.behaviours import MAX_WHEEL_SPEED, wheel_speeds

N = 20000


def _keyed(key, ab, pixels, centroid):
    """``wheel_speeds`` with its two uniforms drawn from ``key``."""
    return wheel_speeds(jax.random.uniform(key, (2,)), ab, pixels, centroid)


_speeds = jax.jit(_keyed)


@jax.jit
def _batch(key: jax.Array, abs_: Antibodies, pixels: jnp.ndarray, centroid: jnp.ndarray):
    """``vmap(wheel_speeds)`` over N robots with split keys; also each robot's two uniforms."""
    keys = jax.random.split(key, N)
    speeds = jax.vmap(_keyed)(keys, abs_, pixels, centroid)
    return speeds, keys, jax.vmap(lambda k: jax.random.uniform(k, (2,)))(keys)


L, R = 0, 1
KEY = jax.random.key(0)


def _one(t, s=0.0, f=0.0, a=0.0, d=0, rf=0.0, ra=0.0) -> Antibodies:
    return Antibodies(
        type=jnp.int32(t),
        speed=jnp.float32(s),
        freq=jnp.float32(f),
        angle=jnp.float32(a),
        direction=jnp.int32(d),
        right_freq=jnp.float32(rf),
        right_angle=jnp.float32(ra),
    )


def _run(ab: Antibodies, pixels: int = 0, centroid: float = 7.0, key=KEY) -> list[float]:
    out = _speeds(key, ab, jnp.int32(pixels), jnp.float32(centroid))
    assert out.shape == (2,) and out.dtype == jnp.float32
    return np.asarray(out).tolist()


def _reference(u: np.ndarray, ab: Antibodies, pixels: int, centroid: float) -> list[float]:
    """Plain-Python SPEC 5 given the behaviour's two uniforms."""
    t, s, f, a = int(ab.type), float(ab.speed), float(ab.freq), float(ab.angle)
    d, rf, ra = int(ab.direction), float(ab.right_freq), float(ab.right_angle)
    left = right = s
    if t == 0:
        if u[0] < f / 100:
            left, right = (s * (1 - a / 100), s) if d == L else (s, s * (1 - a / 100))
    elif t == 1:
        if u[0] < f / 100:
            left = s * (1 - a / 100)
        elif u[1] < rf / 100:
            right = s * (1 - ra / 100)
    elif t == 2:
        left, right = (s * (1 - a / 100), s) if d == L else (s, s * (1 - a / 100))
    elif t == 3:
        left, right = (0.0, s) if d == L else (s, 0.0)
    elif t == 4:
        left, right = (-s * (1 - a / 100), -s) if d == L else (-s, -s * (1 - a / 100))
    elif t == 5 and pixels > 0:
        if centroid < 7:
            left = s * (1 - a / 100)
        elif centroid > 7:
            right = s * (1 - a / 100)
    return [float(np.clip(v, -1000, 1000)) for v in (left, right)]


@pytest.mark.parametrize(
    ("ab", "expected"),
    [
        # forward turn, S 200: reduce the side-D wheel by A %
        (_one(2, s=200, a=50, d=L), [100, 200]),
        (_one(2, s=200, a=50, d=R), [200, 100]),
        (_one(2, s=200, a=150, d=L), [-100, 200]),  # X > 100: that wheel backs up
        (_one(2, s=200, a=200, d=R), [200, -200]),  # spin on the spot
        # static turn: the side-D wheel stops whatever A holds
        (_one(3, s=80, a=100, d=L), [0, 80]),
        (_one(3, s=80, a=100, d=R), [80, 0]),
        (_one(3, s=80, a=0, d=R), [80, 0]),
        # reverse turn: both at -S, the side-D wheel at -S (1 - A/100)
        (_one(4, s=300, a=50, d=L), [-150, -300]),
        (_one(4, s=300, a=50, d=R), [-300, -150]),
        (_one(4, s=300, a=120, d=L), [60, -300]),
        (_one(4, s=400, a=200, d=R), [-400, 400]),
        # out-of-limit speeds are clipped to the motors' range
        (_one(2, s=1500, a=0, d=L), [1000, 1000]),
        (_one(4, s=1500, a=0, d=L), [-1000, -1000]),
    ],
)
def test_deterministic_types(ab: Antibodies, expected: list[float]) -> None:
    np.testing.assert_allclose(_run(ab), expected, rtol=1e-6)


@pytest.mark.parametrize(
    ("pixels", "centroid", "expected"),
    [
        (5, 3.0, [140, 200]),  # marker to the left: slow the left wheel, turn left
        (5, 11.0, [200, 140]),  # marker to the right
        (5, 7.0, [200, 200]),  # centred
        (5, 6.9, [140, 200]),
        (0, 3.0, [200, 200]),  # no blue pixels: straight even with a stale centroid
        (0, 7.0, [200, 200]),
    ],
)
def test_track_markers(pixels: int, centroid: float, expected: list[float]) -> None:
    np.testing.assert_allclose(_run(_one(5, s=200, a=30), pixels, centroid), expected, rtol=1e-6)


def test_wander_forced_branches() -> None:
    for key in jax.random.split(jax.random.key(2), 5):
        # wander single: F = 0 never turns, F = 100 always turns (A 110 reverses that wheel)
        assert _run(_one(0, s=100, f=0, a=110, d=L), key=key) == [100, 100]
        np.testing.assert_allclose(_run(_one(0, s=100, f=100, a=110, d=L), key=key), [-10, 100])
        np.testing.assert_allclose(_run(_one(0, s=100, f=100, a=50, d=R), key=key), [100, 50])
        # wander both: F = 100 always reduces the left wheel by A
        ab = _one(1, s=100, f=100, a=50, rf=100, ra=110)
        np.testing.assert_allclose(_run(ab, key=key), [50, 100])
        # F = 0, Rf = 100: always the right wheel by Ra
        np.testing.assert_allclose(
            _run(_one(1, s=100, f=0, a=50, rf=100, ra=110), key=key), [100, -10]
        )
        assert _run(_one(1, s=100, f=0, a=50, rf=0, ra=110), key=key) == [100, 100]


def _many(ab: Antibodies) -> np.ndarray:
    """[N, 2] speeds of one antibody under N different keys."""
    abs_ = jax.tree.map(lambda x: np.broadcast_to(np.asarray(x), (N,)), ab)
    speeds, _, _ = _batch(
        jax.random.key(1), abs_, np.zeros(N, np.int32), np.full(N, 7.0, np.float32)
    )
    return np.asarray(speeds)


def test_wander_single_frequency() -> None:
    out = _many(_one(0, s=200, f=30, a=50, d=R))
    turned = np.isclose(out[:, 1], 100.0)
    assert np.allclose(out[:, 0], 200.0)
    assert np.all(turned | np.isclose(out[:, 1], 200.0))
    assert abs(turned.mean() - 0.30) < 0.015


def test_wander_both_frequency() -> None:
    out = _many(_one(1, s=200, f=30, a=50, rf=50, ra=25))
    close = lambda col, value: np.isclose(out[:, col], value)
    left = close(0, 100.0) & close(1, 200.0)
    right = close(0, 200.0) & close(1, 150.0)
    straight = close(0, 200.0) & close(1, 200.0)
    assert np.all(left | right | straight)
    assert abs(left.mean() - 0.30) < 0.015
    assert abs(right.mean() - 0.70 * 0.50) < 0.015  # right only when the left turn did not fire
    assert abs(straight.mean() - 0.35) < 0.015


def _random_antibodies(rng: np.random.Generator, n: int) -> Antibodies:
    """n random canonical antibodies drawn with NumPy (keeps the jitted programs few)."""
    t = rng.integers(0, N_TYPES, n)
    x = LIMITS_MIN[t] + (LIMITS_MAX[t] - LIMITS_MIN[t]) * rng.random((n, 6))
    x[:, 3] = rng.integers(0, 2, n)
    x = np.where(USES[t], x, 0.0)
    return from_matrix(t, x)


def test_every_type_matches_reference_and_loop() -> None:
    rng = np.random.default_rng(0)
    abs_ = jax.device_get(_random_antibodies(rng, N))
    pixels = rng.integers(0, 2, N).astype(np.int32)
    centroid = rng.integers(0, 15, N).astype(np.float32)  # 7 (centred) comes up often
    speeds, keys, us = jax.device_get(_batch(jax.random.key(4), abs_, pixels, centroid))
    assert set(np.unique(abs_.type)) == set(range(N_TYPES))
    assert np.all(np.abs(speeds) <= MAX_WHEEL_SPEED)
    for i in range(3000):
        one = take(abs_, i)
        expected = _reference(us[i], one, pixels[i], centroid[i])
        np.testing.assert_allclose(speeds[i], expected, rtol=1e-5, atol=1e-3)
        if i < 60:
            # jit(vmap(f)) equals a loop of f, up to float rounding (XLA may fuse differently).
            loop = _speeds(keys[i], one, pixels[i], centroid[i])
            np.testing.assert_allclose(speeds[i], np.asarray(loop), rtol=1e-6, atol=1e-4)
