"""Antibodies: behaviour genes with the attribute limits of the paper's Table 1 (SPEC 5).

An antibody is a behaviour type ``T`` plus the attributes S (speed, units), F (turn frequency,
% of iterations), A (turn angle, % reduction of one wheel's speed), D (turn direction, 0 = left,
1 = right), Rf (right-turn frequency, %) and Ra (right-turn angle, %). A set holds one antibody
per antigen (shape ``[8]``); the STL keeps five sets (``[5, 8]``); every function here accepts any
leading batch shape.

Canonical form [ours]: attributes a type does not use are 0 (D included), so that equality,
files and :func:`antibody_distance` are clean. Sampling and mutation always
produce canonical antibodies and :func:`within_limits` checks it.

Attribute values are continuous float32 draws, uniform over the closed Table 1 interval [ours:
the paper does not say whether they are integers].
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from numbers import Real
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import device_array, pytree_dataclass
from jaxais.immune.antigens import ANTIGEN_NAMES, N_ANTIGENS

__all__ = [
    "ATTRIBUTE_NAMES",
    "Antibodies",
    "DIRECTION_NAMES",
    "FORWARD_TURN",
    "LEFT",
    "LIMITS_MAX",
    "LIMITS_MIN",
    "N_ANTIGENS",
    "N_ATTRIBUTES",
    "N_TYPES",
    "REVERSE_TURN",
    "RIGHT",
    "STATIC_TURN",
    "TRACK_MARKERS",
    "TYPE_NAMES",
    "USES",
    "WANDER_BOTH",
    "WANDER_SINGLE",
    "antibody_distance",
    "attribute_matrix",
    "canonical",
    "from_dicts",
    "from_matrix",
    "from_uniforms",
    "mutate",
    "sample_antibodies",
    "sample_attributes",
    "stack",
    "take",
    "to_dicts",
    "within_limits",
]

TYPE_NAMES = (
    "wander single",
    "wander both",
    "forward turn",
    "static turn",
    "reverse turn",
    "track markers",
)
N_TYPES = 6
WANDER_SINGLE, WANDER_BOTH, FORWARD_TURN, STATIC_TURN, REVERSE_TURN, TRACK_MARKERS = range(6)

ATTRIBUTE_NAMES = ("S", "F", "A", "D", "Rf", "Ra")
"""Attribute columns of the limit tables and of :func:`attribute_matrix`."""
N_ATTRIBUTES = 6
_D = ATTRIBUTE_NAMES.index("D")
_FIELDS = ("speed", "freq", "angle", "direction", "right_freq", "right_angle")
DIRECTION_NAMES = ("left", "right")
LEFT, RIGHT = 0, 1

_ = math.nan
# Table 1 of the paper, one row per type, columns S, F, A, D, Rf, Ra; NaN = the type has no such
# attribute. D is stored as the integer range {0, 1}.
LIMITS_MIN = np.array(
    [
        [50, 10, 10, 0, _, _],  # 0 wander single
        [50, 10, 10, _, 10, 10],  # 1 wander both
        [50, _, 20, 0, _, _],  # 2 forward turn
        [50, _, 100, 0, _, _],  # 3 static turn
        [300, _, 20, 0, _, _],  # 4 reverse turn
        [50, _, 0, _, _, _],  # 5 track markers
    ],
    dtype=np.float32,
)
"""[N_TYPES, N_ATTRIBUTES] lower limits of Table 1 (NaN where the type lacks the attribute)."""
LIMITS_MAX = np.array(
    [
        [400, 90, 110, 1, _, _],
        [400, 90, 110, _, 90, 110],
        [400, _, 200, 1, _, _],
        [100, _, 100, 1, _, _],
        [400, _, 200, 1, _, _],
        [400, _, 30, _, _, _],
    ],
    dtype=np.float32,
)
"""[N_TYPES, N_ATTRIBUTES] upper limits of Table 1 (NaN where the type lacks the attribute)."""
USES = ~np.isnan(LIMITS_MIN)
"""[N_TYPES, N_ATTRIBUTES] bool, which attributes each type uses."""
del _

# NaN-free copies for traced arithmetic (the unused entries are masked by USES anyway).
_LO = np.nan_to_num(LIMITS_MIN, nan=0.0)
_HI = np.nan_to_num(LIMITS_MAX, nan=0.0)
_RANGE = _HI - _LO
_N_USED = USES.sum(axis=1).astype(np.float32)
_IS_D = np.arange(6) == ATTRIBUTE_NAMES.index("D")


@pytree_dataclass
class Antibodies:
    """A batch of antibodies; every field has the same leading shape (``[8]`` for a set).

    Attributes:
        type: [...] int32 behaviour type 0-5 (see ``TYPE_NAMES``).
        speed: [...] float32 S, wheel speed units.
        freq: [...] float32 F, % of iterations that turn (wander types).
        angle: [...] float32 A, % reduction of the turning wheel's speed.
        direction: [...] int32 D, 0 = left, 1 = right.
        right_freq: [...] float32 Rf, % of iterations with a right turn (wander both).
        right_angle: [...] float32 Ra, % reduction of the right wheel (wander both).
    """

    type: jnp.ndarray
    speed: jnp.ndarray
    freq: jnp.ndarray
    angle: jnp.ndarray
    direction: jnp.ndarray
    right_freq: jnp.ndarray
    right_angle: jnp.ndarray

    @property
    def shape(self) -> tuple[int, ...]:
        """The batch shape (``()`` for one antibody, ``(8,)`` for a set)."""
        return tuple(jnp.shape(self.type))


def _namespace(*trees: Any):
    """NumPy for host arrays only (e.g. a file just read), else ``jax.numpy``.

    Host data cut and checked with NumPy spares a script's start JAX's op-by-op compilations.
    """
    host = all(isinstance(x, np.ndarray | np.generic) for x in jax.tree.leaves(trees))
    return np if host else jnp


def attribute_matrix(ab: Antibodies) -> jnp.ndarray:
    """The attributes as one array, columns ``ATTRIBUTE_NAMES`` (D as 0.0 / 1.0).

    Returns:
        [..., N_ATTRIBUTES] float32 (NumPy for antibodies of NumPy arrays).
    """
    xp = _namespace(ab)
    return xp.stack([xp.asarray(getattr(ab, f), xp.float32) for f in _FIELDS], axis=-1)


def from_matrix(type_: jnp.ndarray, attributes: jnp.ndarray) -> Antibodies:
    """Inverse of :func:`attribute_matrix`.

    Args:
        type_: [...] int behaviour types.
        attributes: [..., N_ATTRIBUTES] float, columns ``ATTRIBUTE_NAMES``.

    Returns:
        Antibodies of NumPy arrays when both inputs are NumPy arrays (host data, e.g. a parsed
        file: cut by NumPy, where JAX would compile each slice op by op), else of JAX arrays.
    """
    xp = _namespace(type_, attributes)
    attributes = xp.asarray(attributes, xp.float32)
    cols = {f: attributes[..., i] for i, f in enumerate(_FIELDS)}
    cols["direction"] = xp.round(cols["direction"]).astype(xp.int32)
    return Antibodies(type=xp.asarray(type_, xp.int32), **cols)


def canonical(ab: Antibodies) -> Antibodies:
    """Zero the attributes each antibody's type does not use (types outside 0-5 are kept)."""
    uses = jnp.asarray(USES)[jnp.clip(ab.type, 0, N_TYPES - 1)]
    return from_matrix(ab.type, jnp.where(uses, attribute_matrix(ab), 0.0))


def _to_attributes(type_: jnp.ndarray, u: jnp.ndarray) -> jnp.ndarray:
    """[..., N_ATTRIBUTES] canonical attributes for ``type_`` from uniforms ``u`` in [0, 1)."""
    values = jnp.asarray(_LO)[type_] + jnp.asarray(_RANGE)[type_] * u
    values = jnp.where(_IS_D, jnp.floor(2.0 * u), values)  # D: 0 or 1, each with probability 1/2
    return jnp.where(jnp.asarray(USES)[type_], values, 0.0)


def _to_type(u: jnp.ndarray) -> jnp.ndarray:
    """[...] int32 types, uniform over 0-5, from uniforms ``u`` [...] in [0, 1)."""
    # The clip only guards float rounding at u -> 1.
    return jnp.minimum(jnp.floor(N_TYPES * u), N_TYPES - 1).astype(jnp.int32)


def _uniform(key: jax.Array, shape: tuple[int, ...]) -> jnp.ndarray:
    """``jax.random.uniform(key, shape)``, drawn flat and reshaped.

    With JAX's default partitionable threefry the numbers are identical (the counters run over
    the flattened index), but XLA on CPU compiles the flat draw several times faster than a
    multi-dimensional one. Sampling and mutation also make one draw each and slice it, since
    every random primitive adds compile time, which dominates these short programs.
    """
    return jax.random.uniform(key, (math.prod(shape),)).reshape(shape)


def sample_attributes(key: jax.Array, type_: jnp.ndarray) -> Antibodies:
    """Fresh canonical attributes for given types, uniform within Table 1.

    S, F, A, Rf and Ra are uniform on the type's [min, max] (static turn's A is exactly 100);
    D is 0 or 1 with probability 1/2 for the types that use it.

    Args:
        key: typed PRNG key.
        type_: [...] int behaviour types 0-5.

    Returns:
        Antibodies of shape ``type_.shape``.
    """
    type_ = jnp.asarray(type_, jnp.int32)
    u = _uniform(key, type_.shape + (N_ATTRIBUTES,))
    return from_matrix(type_, _to_attributes(type_, u))


def sample_antibodies(key: jax.Array, shape: int | tuple[int, ...] = (N_ANTIGENS,)) -> Antibodies:
    """Random antibodies: type uniform over 0-5, then attributes as :func:`sample_attributes`.

    Args:
        key: typed PRNG key.
        shape: batch shape, e.g. ``()`` for one antibody, ``(8,)`` for a set or ``(5, 8)`` for
            the STL's five sets.
    """
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    return from_uniforms(_uniform(key, shape + (1 + N_ATTRIBUTES,)))


def from_uniforms(u: jnp.ndarray) -> Antibodies:
    """The antibodies that :func:`sample_antibodies` makes from its draw ``u`` [..., 7] (the
    type, then the six attributes); the STL controller slices ``u`` from its own draw."""
    type_ = _to_type(u[..., 0])
    return from_matrix(type_, _to_attributes(type_, u[..., 1:]))


def mutate(key: jax.Array, ab: Antibodies, rate: float | jnp.ndarray = 0.05) -> Antibodies:
    """GA mutation (SPEC 10): resample each gene within Table 1 with probability ``rate``.

    The type and each of the six attributes of every antibody mutate independently. A mutated
    type is redrawn uniformly over 0-5 (it may come out unchanged) and then all of that
    antibody's attributes are redrawn for the new type. A mutated attribute the type does not use
    stays 0. ``rate = 0`` returns ``ab`` unchanged; ``rate = 1`` redraws everything.

    Args:
        key: typed PRNG key.
        ab: canonical antibodies, any batch shape.
        rate: per-gene mutation probability (may be traced).

    Returns:
        Antibodies with the shape of ``ab``.
    """
    n = 1 + N_ATTRIBUTES
    u = _uniform(key, ab.shape + (2 * n,))
    hit = u[..., :n] < rate
    type_hit, attr_hit = hit[..., 0], hit[..., 1:]
    new_type = jnp.where(type_hit, _to_type(u[..., n]), ab.type)
    # One fresh draw for the final type serves both cases: a whole-antibody redraw after a type
    # mutation, and single-attribute redraws (same type, so the same limits) otherwise.
    fresh = _to_attributes(new_type, u[..., n + 1 :])
    attributes = jnp.where(type_hit[..., None] | attr_hit, fresh, attribute_matrix(ab))
    return from_matrix(new_type, attributes)


def within_limits(ab: Antibodies) -> jnp.ndarray:
    """Whether each antibody is a valid canonical Table 1 antibody.

    Valid: type in 0-5, every used attribute finite and within its closed limits (D in {0, 1}),
    every unused attribute exactly 0.

    Returns:
        [...] bool with the batch shape of ``ab`` (NumPy for antibodies of NumPy arrays).
    """
    xp = _namespace(ab)
    valid_type = (ab.type >= 0) & (ab.type < N_TYPES)
    t = xp.clip(ab.type, 0, N_TYPES - 1)
    x = attribute_matrix(ab)
    inside = (x >= xp.asarray(_LO)[t]) & (x <= xp.asarray(_HI)[t])
    ok = xp.where(xp.asarray(USES)[t], inside, x == 0.0)
    return valid_type & xp.all(ok, axis=-1)


def antibody_distance(a: Antibodies, b: Antibodies) -> jnp.ndarray:
    """Distance between antibodies for the GA diversity measure (SPEC 10) [ours].

    1 for different types; otherwise the mean, over the attributes the type uses, of
    ``|a - b| / (max - min)`` with Table 1's limits (D: 0 same, 1 different). An attribute with
    zero range (static turn's A) contributes 0 but still counts in the mean. The result is in
    [0, 1] for antibodies within limits.

    Args:
        a, b: antibodies with broadcastable batch shapes.

    Returns:
        [...] float32 distances.
    """
    t = jnp.clip(a.type, 0, N_TYPES - 1)
    span = jnp.asarray(_RANGE)[t]
    diff = jnp.abs(attribute_matrix(a) - attribute_matrix(b))
    norm = jnp.where(span > 0, diff / jnp.where(span > 0, span, 1.0), 0.0)
    norm = jnp.where(jnp.asarray(USES)[t], norm, 0.0)
    same_type_distance = jnp.sum(norm, axis=-1) / jnp.asarray(_N_USED)[t]
    return jnp.where(a.type == b.type, same_type_distance, 1.0).astype(jnp.float32)


def take(ab: Antibodies, index: Any) -> Antibodies:
    """Index every field alike, e.g. ``take(sets, (i, m))`` is antibody ``A_im`` of ``[5, 8]``."""
    return jax.tree_util.tree_map(lambda x: x[index], ab)


def stack(antibodies: Sequence[Antibodies], axis: int = 0) -> Antibodies:
    """Stack antibodies of equal shape along a new batch axis."""
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs, axis=axis), *antibodies)


def _short_float(x: float) -> float:
    # The shortest decimal that reads back as the same float32: readable and an exact round trip.
    return float(str(np.float32(x)))


def to_dicts(ab: Antibodies) -> list[dict[str, Any]]:
    """A human-readable set: one dict per antigen, only the attributes its type uses.

    Example entry: ``{"antigen": "obstacle left", "type": "forward turn", "S": 250.0,
    "A": 80.5, "D": "right"}``.

    Args:
        ab: one set, shape ``[8]`` (host or device arrays, not traced).

    Returns:
        8 dicts, in antigen order.
    """
    if ab.shape != (N_ANTIGENS,):
        raise ValueError(f"to_dicts expects one set of shape ({N_ANTIGENS},), got {ab.shape}")
    types = np.asarray(ab.type)
    x = np.asarray(attribute_matrix(ab))
    out = []
    for j in range(N_ANTIGENS):
        t = int(types[j])
        if not 0 <= t < N_TYPES:
            raise ValueError(f"antibody {j} ({ANTIGEN_NAMES[j]}): type {t} is not in 0-5")
        entry: dict[str, Any] = {"antigen": ANTIGEN_NAMES[j], "type": TYPE_NAMES[t]}
        for k, name in enumerate(ATTRIBUTE_NAMES):
            if USES[t, k]:
                entry[name] = DIRECTION_NAMES[int(x[j, k])] if k == _D else _short_float(x[j, k])
        out.append(entry)
    return out


def _parse_one(j: int, item: Any) -> tuple[int, list[float]]:
    where = f"antibody {j} ({ANTIGEN_NAMES[j]})"
    if not isinstance(item, Mapping):
        raise ValueError(f"{where}: expected a dict, got {type(item).__name__}")
    unknown = set(item) - {"antigen", "type", *ATTRIBUTE_NAMES}
    if unknown:
        raise ValueError(f"{where}: unknown field {sorted(map(str, unknown))[0]!r}")
    if "antigen" in item and item["antigen"] != ANTIGEN_NAMES[j]:
        raise ValueError(
            f"{where}: field 'antigen' is {item['antigen']!r}, expected {ANTIGEN_NAMES[j]!r}"
            " (antibodies must be listed in antigen order)"
        )
    if item.get("type") not in TYPE_NAMES:
        raise ValueError(
            f"{where}: field 'type' must be one of {TYPE_NAMES}, got {item.get('type')!r}"
        )
    t = TYPE_NAMES.index(item["type"])
    values = [0.0] * N_ATTRIBUTES
    for k, name in enumerate(ATTRIBUTE_NAMES):
        value = item.get(name)
        if not USES[t, k]:
            if value is not None:
                raise ValueError(f"{where}: field {name!r} is not used by type {item['type']!r}")
            continue
        if value is None:
            raise ValueError(f"{where}: field {name!r} is missing (required by {item['type']!r})")
        if k == _D:
            if value not in DIRECTION_NAMES:
                raise ValueError(f"{where}: field 'D' must be 'left' or 'right', got {value!r}")
            values[k] = float(DIRECTION_NAMES.index(value))
            continue
        if isinstance(value, bool) or not isinstance(value, Real):
            raise ValueError(f"{where}: field {name!r} must be a number, got {value!r}")
        v32 = np.float32(value)  # check the value that will be stored
        lo, hi = LIMITS_MIN[t, k], LIMITS_MAX[t, k]
        if not lo <= v32 <= hi:
            raise ValueError(
                f"{where}: field {name!r} = {value!r} is outside [{lo:g}, {hi:g}] for type"
                f" {item['type']!r}"
            )
        values[k] = float(v32)
    return t, values


def from_dicts(items: Sequence[Mapping[str, Any]]) -> Antibodies:
    """Parse and validate a set written by :func:`to_dicts` (or by hand).

    Each dict needs ``"type"`` (a name from ``TYPE_NAMES``) and exactly the attributes that type
    uses (D as ``"left"``/``"right"``, numbers within Table 1); ``"antigen"`` is optional but, if
    given, must name the antigen at that position. Unused attributes may be absent or ``None``.

    Args:
        items: 8 dicts in antigen order.

    Returns:
        Canonical Antibodies of shape ``[8]``.

    Raises:
        ValueError: a one-line message naming the antibody and the offending field.
    """
    if isinstance(items, (str, bytes, Mapping)) or not isinstance(items, Sequence):
        raise ValueError(f"antibody set: expected a list of {N_ANTIGENS} dicts")
    if len(items) != N_ANTIGENS:
        raise ValueError(f"antibody set: expected {N_ANTIGENS} antibodies, got {len(items)}")
    parsed = [_parse_one(j, item) for j, item in enumerate(items)]
    types = np.array([t for t, _ in parsed], dtype=np.int32)
    values = np.array([v for _, v in parsed], dtype=np.float32)
    return jax.tree.map(device_array, from_matrix(types, values))
