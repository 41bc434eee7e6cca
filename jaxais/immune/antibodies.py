"""Antibodies: behaviour genes within the attribute limits of the paper's Table 1 (SPEC 5).

An antibody is a type T and the attributes S (speed), F (turn frequency, %), A (turn angle, %
reduction of one wheel's speed), D (0 = left, 1 = right), Rf and Ra (right-turn frequency and
angle, %); one per antigen makes a set [8]. Functions accept any leading batch shape.
Canonical form [ours]: attributes a type does not use are 0. Values are continuous float32,
uniform over Table 1's closed interval [ours].
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

TYPE_NAMES = (
    "wander single",
    "wander both",
    "forward turn",
    "static turn",
    "reverse turn",
    "track markers",
)
N_TYPES = 6
WANDER_SINGLE, WANDER_BOTH, FORWARD_TURN, STATIC_TURN, REVERSE_TURN, TRACK_MARKERS = range(N_TYPES)

ATTRIBUTE_NAMES = ("S", "F", "A", "D", "Rf", "Ra")  # columns of the limits and attribute_matrix
N_ATTRIBUTES = 6
_D = ATTRIBUTE_NAMES.index("D")
_FIELDS = ("speed", "freq", "angle", "direction", "right_freq", "right_angle")
DIRECTION_NAMES = ("left", "right")
LEFT, RIGHT = 0, 1

_ = math.nan
# Table 1 [paper]: [N_TYPES, N_ATTRIBUTES], NaN where a type lacks the attribute; D in {0, 1}.
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
USES = ~np.isnan(LIMITS_MIN)  # [N_TYPES, N_ATTRIBUTES] the attributes each type uses
del _

# NaN-free copies for traced arithmetic (the unused entries are masked by USES anyway).
_LO = np.nan_to_num(LIMITS_MIN, nan=0.0)
_HI = np.nan_to_num(LIMITS_MAX, nan=0.0)
_RANGE = _HI - _LO
_N_USED = USES.sum(axis=1).astype(np.float32)
_IS_D = np.arange(N_ATTRIBUTES) == _D


@pytree_dataclass
class Antibodies:
    """A batch of antibodies [...]: int32 type (``TYPE_NAMES``) and direction (D), float32 speed
    (S), freq (F), angle (A), right_freq (Rf), right_angle (Ra)."""

    type: jnp.ndarray
    speed: jnp.ndarray
    freq: jnp.ndarray
    angle: jnp.ndarray
    direction: jnp.ndarray
    right_freq: jnp.ndarray
    right_angle: jnp.ndarray

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(jnp.shape(self.type))


def _namespace(*trees: Any):
    """NumPy for host arrays only (a file just read: spares JAX's op-by-op compiles), else jnp."""
    host = all(isinstance(x, np.ndarray | np.generic) for x in jax.tree.leaves(trees))
    return np if host else jnp


def attribute_matrix(ab: Antibodies) -> jnp.ndarray:
    """[..., N_ATTRIBUTES] float32, columns ``ATTRIBUTE_NAMES`` (NumPy for NumPy antibodies)."""
    xp = _namespace(ab)
    return xp.stack([xp.asarray(getattr(ab, f), xp.float32) for f in _FIELDS], axis=-1)


def from_matrix(type_: jnp.ndarray, attributes: jnp.ndarray) -> Antibodies:
    """Inverse of :func:`attribute_matrix`: types [...] and attributes [..., N_ATTRIBUTES]
    (NumPy antibodies for NumPy inputs)."""
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
    """``jax.random.uniform(key, shape)`` drawn flat: the same numbers, compiled several times
    faster on CPU (one draw per function, sliced, for the same reason)."""
    return jax.random.uniform(key, (math.prod(shape),)).reshape(shape)


def sample_antibodies(key: jax.Array, shape: int | tuple[int, ...] = (N_ANTIGENS,)) -> Antibodies:
    """Random antibodies of batch ``shape``: type uniform over 0-5, attributes uniform within
    Table 1 (D left or right with probability 1/2)."""
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    return from_uniforms(_uniform(key, shape + (1 + N_ATTRIBUTES,)))


def from_uniforms(u: jnp.ndarray) -> Antibodies:
    """The antibodies that :func:`sample_antibodies` makes from its draw ``u`` [..., 7] (the
    type, then the six attributes); the STL controller slices ``u`` from its own draw."""
    type_ = _to_type(u[..., 0])
    return from_matrix(type_, _to_attributes(type_, u[..., 1:]))


def mutate(key: jax.Array, ab: Antibodies, rate: float | jnp.ndarray = 0.05) -> Antibodies:
    """GA mutation (SPEC 10): each gene (type, six attributes) redrawn within Table 1 with
    probability ``rate`` (traced); a redrawn type redraws all of its antibody's attributes."""
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
    """[...] bool: type in 0-5, used attributes within Table 1's limits, unused ones 0."""
    xp = _namespace(ab)
    valid_type = (ab.type >= 0) & (ab.type < N_TYPES)
    t = xp.clip(ab.type, 0, N_TYPES - 1)
    x = attribute_matrix(ab)
    inside = (x >= xp.asarray(_LO)[t]) & (x <= xp.asarray(_HI)[t])
    ok = xp.where(xp.asarray(USES)[t], inside, x == 0.0)
    return valid_type & xp.all(ok, axis=-1)


def antibody_distance(a: Antibodies, b: Antibodies) -> jnp.ndarray:
    """GA diversity distance [...] in [0, 1] (SPEC 10) [ours]: 1 between types, else the mean
    over used attributes of |a - b| / (max - min) (a zero range counts 0)."""
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
    """One set [8] as 8 dicts in antigen order, e.g. ``{"antigen": "obstacle left", "type":
    "forward turn", "S": 250.0, "A": 80.5, "D": "right"}`` (only the attributes used)."""
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
    """A set [8] from :func:`to_dicts`' form: each dict exactly its type's attributes, within
    Table 1; ValueError names the antibody and field."""
    if isinstance(items, (str, bytes, Mapping)) or not isinstance(items, Sequence):
        raise ValueError(f"antibody set: expected a list of {N_ANTIGENS} dicts")
    if len(items) != N_ANTIGENS:
        raise ValueError(f"antibody set: expected {N_ANTIGENS} antibodies, got {len(items)}")
    parsed = [_parse_one(j, item) for j, item in enumerate(items)]
    types = np.array([t for t, _ in parsed], dtype=np.int32)
    values = np.array([v for _, v in parsed], dtype=np.float32)
    return jax.tree.map(device_array, from_matrix(types, values))
