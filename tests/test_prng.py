"""jaxais.prng: the unrolled threefry draws exactly what JAX's default threefry draws."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxais import prng

# Known-answer tests of Threefry-2x32 with 20 rounds (Salmon et al. 2011, Random123's kat_vectors;
# JAX's own tests use the same): (key, counter) -> output, as 32-bit words.
KAT = [
    ((0x00000000, 0x00000000), (0x00000000, 0x00000000), (0x6B200159, 0x99BA4EFE)),
    ((0xFFFFFFFF, 0xFFFFFFFF), (0xFFFFFFFF, 0xFFFFFFFF), (0x1CB996FC, 0xBB002BE7)),
    ((0x13198A2E, 0x03707344), (0x243F6A88, 0x85A308D3), (0xC4923A9C, 0x483DF7A0)),
]


def _u32(*xs: int) -> list[np.ndarray]:
    return [np.asarray(x, np.uint32) for x in xs]


@pytest.mark.parametrize("hash_fn", [prng.threefry2x32, prng._threefry2x32_host])
@pytest.mark.parametrize(("key", "count", "expected"), KAT)
def test_hash_known_answers(hash_fn, key, count, expected) -> None:
    """The jax.lax hash and its NumPy twin (host key derivation) give Random123's answers."""
    out = hash_fn(*_u32(*key), *_u32(*count))
    assert tuple(int(x) for x in out) == expected


def _numpy_threefry(k1: int, k2: int, x1: np.ndarray, x2: np.ndarray):
    """An independent NumPy Threefry-2x32-20 (uint32 arithmetic wraps modulo 2**32)."""
    rot = lambda x, d: (x << np.uint32(d)) | (x >> np.uint32(32 - d))
    ks = [np.uint32(k1), np.uint32(k2), np.uint32(k1) ^ np.uint32(k2) ^ np.uint32(0x1BD11BDA)]
    x1, x2 = x1 + ks[0], x2 + ks[1]
    rotations = [(13, 15, 26, 6), (17, 29, 16, 24)]
    for i in range(5):
        for r in rotations[i % 2]:
            x1 = x1 + x2
            x2 = rot(x2, r) ^ x1
        x1 = x1 + ks[(i + 1) % 3]
        x2 = x2 + ks[(i + 2) % 3] + np.uint32(i + 1)
    return x1, x2


def test_hash_matches_numpy_on_arrays() -> None:
    rng = np.random.default_rng(0)
    x1, x2 = (rng.integers(0, 2**32, (3, 7), dtype=np.uint64).astype(np.uint32) for _ in "ab")
    with np.errstate(over="ignore"):
        want = _numpy_threefry(0xDEADBEEF, 0x01234567, x1, x2)
    got = prng.threefry2x32(*_u32(0xDEADBEEF, 0x01234567), x1, x2)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(np.asarray(g), w)


def _data(key: jax.Array) -> np.ndarray:
    return np.asarray(jax.random.key_data(key))


@pytest.mark.parametrize("shape", [(), (1,), (3,), (2, 5)])
def test_split_and_fold_in_equal_jax(shape) -> None:
    key = jax.random.key(7)
    fast = prng.unrolled(key)
    assert str(jax.random.key_impl(fast)) != str(jax.random.key_impl(key))
    np.testing.assert_array_equal(
        _data(jax.random.split(fast, shape)), _data(jax.random.split(key, shape))
    )
    for data in (0, 1, 12345, 2**32 - 1):
        np.testing.assert_array_equal(
            _data(jax.random.fold_in(fast, data)), _data(jax.random.fold_in(key, data))
        )


DRAWS = (
    jax.random.uniform,
    jax.random.normal,
    lambda k, s: jax.random.randint(k, s, -5, 100),
    lambda k, s: jax.random.bits(k, s, jnp.uint8),
    lambda k, s: jax.random.bits(k, s, jnp.uint16),
    lambda k, s: jax.random.bits(k, s, jnp.uint32),
)


def _all_draws(key: jax.Array) -> list[jax.Array]:
    """Every draw of DRAWS at several shapes, and a permutation (one compiled program)."""
    out = [draw(key, shape) for shape in [(), (1,), (7,), (3, 5)] for draw in DRAWS]
    return [*out, jax.random.permutation(key, 10)]


def test_draws_equal_jax() -> None:
    key = jax.random.key(2026)
    got = jax.jit(lambda k: _all_draws(prng.unrolled(k)))(key)
    want = jax.jit(_all_draws)(key)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(np.asarray(g), np.asarray(w))


def test_64_bit_draws_equal_jax() -> None:
    with jax.enable_x64(True):
        key = jax.random.key(3)
        fast = prng.unrolled(key)
        np.testing.assert_array_equal(
            np.asarray(jax.random.bits(fast, (5,), jnp.uint64)),
            np.asarray(jax.random.bits(key, (5,), jnp.uint64)),
        )


def test_jit_vmap_equals_loop_and_like_round_trips() -> None:
    keys = jax.random.split(jax.random.key(11), 4)

    def draw(k):
        fast = prng.unrolled(k)
        k1, k2 = jax.random.split(fast)
        return prng.like(k1, k), jax.random.uniform(k2, (6,))

    batched_keys, batched_u = jax.jit(jax.vmap(draw))(keys)
    assert jax.random.key_impl(batched_keys) == jax.random.key_impl(keys)
    for i in range(4):
        k1, k2 = jax.random.split(keys[i])
        np.testing.assert_array_equal(_data(batched_keys[i]), _data(k1))
        np.testing.assert_array_equal(
            np.asarray(batched_u[i]), np.asarray(jax.random.uniform(k2, (6,)))
        )


def test_other_implementations_are_left_alone() -> None:
    rbg = jax.random.key(0, impl="rbg")
    assert prng.unrolled(rbg) is rbg
    with jax.threefry_partitionable(False):  # the original counting: not what UNROLLED draws
        key = jax.random.key(0)
        assert prng.unrolled(key) is key
    key = jax.random.key(0)
    assert prng.like(key, key) is key


@pytest.mark.parametrize("seed", [0, 7, 2**31 + 5, 2**32 - 1])
def test_host_keys_equal_jax(seed) -> None:
    assert prng.host_keys_match(seed)
    key = jax.random.key(seed)
    np.testing.assert_array_equal(prng.host_key(seed), _data(key))
    data = np.asarray([0, 1, 2, 1000, 2**32 - 1], np.uint64)
    want = np.stack([_data(jax.random.fold_in(key, int(d))) for d in data])
    np.testing.assert_array_equal(prng.host_fold_in(prng.host_key(seed), data), want)


def test_host_keys_only_where_they_match() -> None:
    assert not prng.host_keys_match(-1) and not prng.host_keys_match(2**32)
    previous = jax.config.jax_default_prng_impl
    jax.config.update("jax_default_prng_impl", "rbg")
    try:
        assert not prng.host_keys_match(0)
    finally:
        jax.config.update("jax_default_prng_impl", previous)
