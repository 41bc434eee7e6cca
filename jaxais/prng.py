"""JAX's default PRNG (threefry2x32) with the hash unrolled, for the task loop's random draws.

On CPU, JAX lowers the threefry2x32 hash as a rolled five-step loop: a ``while`` in the compiled
program, with loop-carried copies, for every ``split``, ``uniform`` and ``normal``. The task loop
draws a chunk's randomness with six such hashes; in a profile of 30 STL trials their loops took
about a fifth of the loop's time. :data:`UNROLLED_THREEFRY` is a PRNG implementation that computes
the same hash with the same key schedule and counters as JAX's partitionable threefry
(``jax_threefry_partitionable``, JAX's default), written out as straight-line code that XLA
fuses. Its keys hold the same two words, and every draw equals ``jax.random``'s with the default
implementation bit for bit (tested for split, fold_in, bits, uniform, normal, randint and
permutation), so a run's results do not depend on which of the two drew them. Measured on a
2-core CPU (30 SIE trials in world1, interleaved runs): the trials' run time 5.7-6.0 -> 5.0-5.6 s,
the same results.json byte for byte.

Use :func:`unrolled` on a default key inside a compiled loop and :func:`like` to hand the key back
in its original implementation. Programs compiled for compile speed (a batch's start, with
``quick_compile``) keep the rolled hash: there the unrolled one lowered and compiled more slowly
(world1's start for 30 trials: lowering 0.45 -> 0.8 s, compiling 2.1 -> 2.3-2.9 s).

The same hash in NumPy derives small sets of keys on the host (:func:`host_fold_in`, e.g. a
batch's trial keys), where compiling a program for them would cost more than running it.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.extend.random import define_prng_impl, threefry_prng_impl

_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))
"""Threefry-2x32's rotation constants, used alternately by the five groups of four rounds."""
_PARITY = np.uint32(0x1BD11BDA)
"""The constant of the third key word (Salmon et al., 2011)."""


def _rotate_left(x: jax.Array, d: int) -> jax.Array:
    left = jax.lax.shift_left(x, np.uint32(d))
    return jax.lax.bitwise_or(left, jax.lax.shift_right_logical(x, np.uint32(32 - d)))


def _threefry_rounds(k1, k2, x1, x2, add, xor, rotate_left):
    """Threefry-2x32's key schedule and 20 rounds, given the uint32 operations of an array type
    (so that the JAX hash and its NumPy twin share one schedule)."""
    ks = (k1, k2, xor(xor(k1, k2), _PARITY))
    x1, x2 = add(x1, ks[0]), add(x2, ks[1])
    for group in range(5):
        for r in _ROTATIONS[group % 2]:
            x1 = add(x1, x2)
            x2 = xor(x1, rotate_left(x2, r))
        # Key injection after every four rounds, with the group number added.
        x1 = add(x1, ks[(group + 1) % 3])
        x2 = add(add(x2, ks[(group + 2) % 3]), np.uint32(group + 1))
    return x1, x2


def threefry2x32(
    k1: jax.Array, k2: jax.Array, x1: jax.Array, x2: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """The Threefry-2x32 hash of counters (x1, x2) under key (k1, k2), 20 rounds, unrolled.

    Written in ``jax.lax`` operations, which trace and lower several times faster than
    ``jax.numpy``'s operators (no dtype promotion, no nested jit): the hash is traced again at
    every draw the compiled programs lower.

    Args:
        k1, k2: the key's words (uint32 scalars).
        x1, x2: uint32 counters, any (same) shape.

    Returns:
        Two uint32 arrays of the counters' shape.
    """
    return _threefry_rounds(k1, k2, x1, x2, jax.lax.add, jax.lax.bitwise_xor, _rotate_left)


def _threefry2x32_host(k1: np.ndarray, k2: np.ndarray, x1: np.ndarray, x2: np.ndarray):
    """:func:`threefry2x32` in NumPy, on the host (uint32 arithmetic wraps modulo 2**32)."""
    rotate = lambda x, d: (x << np.uint32(d)) | (x >> np.uint32(32 - d))
    with np.errstate(over="ignore"):
        return _threefry_rounds(k1, k2, x1, x2, np.add, np.bitwise_xor, rotate)


def host_keys_match(seed: int) -> bool:
    """Whether :func:`host_key` and :func:`host_fold_in` give ``jax.random``'s keys for ``seed``:
    JAX's default implementation is threefry2x32 and the seed fits in 32 bits."""
    return jax.config.jax_default_prng_impl == "threefry2x32" and 0 <= seed < 2**32


def host_key(seed: int) -> np.ndarray:
    """The data of ``jax.random.key(seed)`` ([2] uint32), computed with NumPy.

    For ``0 <= seed < 2**32`` under JAX's default threefry2x32 (see :func:`host_keys_match`).
    """
    return np.asarray([0, seed], np.uint32)


def host_fold_in(key: np.ndarray, data: np.ndarray) -> np.ndarray:
    """The data of ``jax.random.fold_in(key, d)`` for each ``d`` in ``data``, with NumPy.

    Small derivations (a batch's trial keys) need no compiled program this way.

    Args:
        key: [2] uint32 threefry2x32 key data. data: [n] non-negative ints below 2**32.

    Returns:
        [n, 2] uint32 key data.
    """
    k1, k2 = np.uint32(key[0]), np.uint32(key[1])
    data = np.asarray(data, np.uint32)
    x1, x2 = _threefry2x32_host(k1, k2, np.zeros_like(data), data)
    return np.stack([x1, x2], axis=-1)


def _counters(shape: tuple[int, ...]) -> tuple[jax.Array, jax.Array]:
    """(high, low) words of a 64-bit row-major counter over ``shape`` (JAX's iota_2x32_shape)."""
    size = math.prod(shape)
    if size >= 2**32:
        raise NotImplementedError(f"at most 2**32 random values per draw, asked for {size}")
    low = jax.lax.iota(np.uint32, size).reshape(shape)
    return jnp.zeros(shape, np.uint32), low


def _split(key: jax.Array, shape: tuple[int, ...]) -> jax.Array:
    bits = threefry2x32(key[0], key[1], *_counters(shape))
    return jnp.stack(bits, axis=-1)


def _fold_in(key: jax.Array, data: jax.Array) -> jax.Array:
    data = jnp.asarray(data, np.uint32)
    bits = threefry2x32(key[0], key[1], jnp.zeros((1,), np.uint32), data[None])
    return jnp.concatenate(bits)


def _random_bits(key: jax.Array, bit_width: int, shape: tuple[int, ...]) -> jax.Array:
    b1, b2 = threefry2x32(key[0], key[1], *_counters(shape))
    if bit_width == 64:
        hi, lo = b1.astype(np.uint64), b2.astype(np.uint64)
        return jax.lax.shift_left(hi, np.uint64(32)) | lo
    if bit_width not in (8, 16, 32):
        raise TypeError(f"random bits must be 8, 16, 32 or 64 wide, got {bit_width}")
    return (b1 ^ b2).astype(f"uint{bit_width}")


UNROLLED_THREEFRY = define_prng_impl(
    key_shape=(2,),
    seed=threefry_prng_impl.seed,
    split=_split,
    random_bits=_random_bits,
    fold_in=_fold_in,
    name="threefry2x32_unrolled",
    tag="fru",
)
"""threefry2x32 (partitionable) with an unrolled hash: the same draws as JAX's default."""


def _same_draws(key: jax.Array) -> bool:
    """Whether :data:`UNROLLED_THREEFRY` draws what ``key``'s own implementation draws."""
    return str(jax.random.key_impl(key)) == "threefry2x32" and jax.config.jax_threefry_partitionable


def unrolled(key: jax.Array) -> jax.Array:
    """``key`` (typed, any shape) in :data:`UNROLLED_THREEFRY`, where that draws the same.

    Keys of other implementations, or threefry under ``jax_threefry_partitionable=False`` (which
    counts differently), come back unchanged.
    """
    if not _same_draws(key):
        return key
    return jax.random.wrap_key_data(jax.random.key_data(key), impl=UNROLLED_THREEFRY)


def like(key: jax.Array, reference: jax.Array) -> jax.Array:
    """``key`` rewrapped in ``reference``'s implementation (the inverse of :func:`unrolled`)."""
    impl = jax.random.key_impl(reference)
    if jax.random.key_impl(key) == impl:
        return key
    return jax.random.wrap_key_data(jax.random.key_data(key), impl=impl)
