"""Antibodies (SPEC 5, paper Table 1): limits, sampling, mutation, dict round trip, distance."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxais.immune.antibodies import (
    ATTRIBUTE_NAMES,
    LIMITS_MAX,
    LIMITS_MIN,
    N_TYPES,
    TYPE_NAMES,
    USES,
    Antibodies,
    antibody_distance,
    attribute_matrix,
    canonical,
    from_dicts,
    mutate,
    sample_antibodies,
    stack,
    take,
    to_dicts,
    within_limits,
)

# One shape for every sampled batch keeps the compiled programs few: 2500 sets of 8.
_sample = jax.jit(lambda key: sample_antibodies(key, (2500, 8)))
_mutate = jax.jit(mutate)
_within = jax.jit(within_limits)
_distance = jax.jit(antibody_distance)
_canonical = jax.jit(canonical)


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


def _equal(a: Antibodies, b: Antibodies) -> np.ndarray:
    """[...] bool: antibody-wise exact equality."""
    same = [
        np.asarray(x) == np.asarray(y)
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    ]
    return np.all(np.stack(same), axis=0)


def test_table_1() -> None:
    # (min, max) per type per attribute, straight from the paper; None = not used.
    table = {
        0: {"S": (50, 400), "F": (10, 90), "A": (10, 110), "D": (0, 1)},
        1: {"S": (50, 400), "F": (10, 90), "A": (10, 110), "Rf": (10, 90), "Ra": (10, 110)},
        2: {"S": (50, 400), "A": (20, 200), "D": (0, 1)},
        3: {"S": (50, 100), "A": (100, 100), "D": (0, 1)},
        4: {"S": (300, 400), "A": (20, 200), "D": (0, 1)},
        5: {"S": (50, 400), "A": (0, 30)},
    }
    assert N_TYPES == len(TYPE_NAMES) == 6
    assert TYPE_NAMES[5] == "track markers"
    for t, row in table.items():
        for k, name in enumerate(ATTRIBUTE_NAMES):
            assert USES[t, k] == (name in row), (t, name)
            if name in row:
                assert (LIMITS_MIN[t, k], LIMITS_MAX[t, k]) == row[name]
            else:
                assert np.isnan(LIMITS_MIN[t, k]) and np.isnan(LIMITS_MAX[t, k])


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_sampled_within_limits(seed: int) -> None:
    ab = _sample(jax.random.key(seed))
    assert ab.shape == (2500, 8)
    assert ab.type.dtype == jnp.int32 and ab.direction.dtype == jnp.int32
    assert ab.speed.dtype == jnp.float32
    assert bool(jnp.all(_within(ab)))


def test_sample_distribution() -> None:
    ab = jax.tree.map(lambda v: np.asarray(v).ravel(), jax.device_get(_sample(jax.random.key(0))))
    x = np.asarray(attribute_matrix(ab))
    counts = np.bincount(ab.type, minlength=N_TYPES) / ab.type.size
    np.testing.assert_allclose(counts, 1 / 6, atol=0.02)
    for t in range(N_TYPES):
        sel = x[ab.type == t]
        for k in np.flatnonzero(USES[t]):
            lo, hi = LIMITS_MIN[t, k], LIMITS_MAX[t, k]
            # Uniform over the whole interval: the extremes of ~3300 draws sit near the ends.
            assert sel[:, k].min() - lo <= 0.01 * (hi - lo) + 1e-6
            assert hi - sel[:, k].max() <= 0.01 * (hi - lo) + 1e-6
            if ATTRIBUTE_NAMES[k] == "D":
                assert set(np.unique(sel[:, k])) == {0.0, 1.0}
                assert abs(sel[:, k].mean() - 0.5) < 0.05
    assert np.all(x[ab.type == 3, 2] == 100.0)  # static turn: A = 100 exactly


def test_sample_shapes() -> None:
    # eval_shape: shapes and dtypes without compiling three more programs.
    key = jax.random.key(0)
    for shape, expected in [((), (8,)), ((5,), (5,)), (((5, 8),), (5, 8))]:
        out = jax.eval_shape(lambda k, s=shape: sample_antibodies(k, *s), key)
        assert out.shape == expected
        assert out.type.dtype == jnp.int32 and out.angle.dtype == jnp.float32


def test_sampling_is_reproducible_and_key_dependent() -> None:
    a = _sample(jax.random.key(7))
    b = _sample(jax.random.key(7))
    c = _sample(jax.random.key(8))
    assert _equal(a, b).all()
    assert not _equal(a, c).all()


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rate=st.floats(0.0, 1.0))
def test_mutated_within_limits(seed: int, rate: float) -> None:
    k1, k2 = jax.random.split(jax.random.key(seed))
    ab = _sample(k1)
    mutated = _mutate(k2, ab, rate)
    assert mutated.shape == (2500, 8)
    assert bool(jnp.all(_within(mutated)))


def test_mutate_rate_zero_is_identity() -> None:
    ab = _sample(jax.random.key(1))
    assert _equal(_mutate(jax.random.key(2), ab, 0.0), ab).all()


def test_mutate_rate_one_changes_almost_everything() -> None:
    ab = _sample(jax.random.key(3))
    m = jax.device_get(_mutate(jax.random.key(4), ab, 1.0))
    assert _equal(m, ab).mean() < 0.01
    # The type is redrawn uniformly, so it stays the same one time in six.
    assert abs((m.type != np.asarray(ab.type)).mean() - 5 / 6) < 0.02
    # Every continuous attribute an unchanged type uses is redrawn (static turn's A is fixed).
    same_type = m.type == np.asarray(ab.type)
    x_old, x_new = np.asarray(attribute_matrix(ab)), np.asarray(attribute_matrix(m))
    for t in range(N_TYPES):
        sel = same_type & (m.type == t)
        for k in np.flatnonzero(USES[t]):
            if ATTRIBUTE_NAMES[k] in ("D",) or LIMITS_MIN[t, k] == LIMITS_MAX[t, k]:
                continue
            assert np.mean(x_old[sel, k] != x_new[sel, k]) > 0.999


def test_mutate_rate_frequency() -> None:
    ab = _sample(jax.random.key(5))
    m = jax.device_get(_mutate(jax.random.key(6), ab, 0.05))
    # Type mutates with probability 0.05 and then changes with probability 5/6.
    assert abs((m.type != np.asarray(ab.type)).mean() - 0.05 * 5 / 6) < 0.008
    # Speed changes when the type mutates or the S gene mutates: 1 - 0.95^2 (static turn S and
    # the rest are continuous, so a redraw always differs).
    assert abs((m.speed != np.asarray(ab.speed)).mean() - (1 - 0.95**2)) < 0.01


def test_within_limits_rejects() -> None:
    good = _one(2, s=100, a=50, d=1)
    assert bool(_within(good))
    bad = [
        _one(2, s=100, a=50, d=1, f=5),  # unused attribute not canonical
        _one(2, s=49.9, a=50, d=1),  # S below min
        _one(2, s=100, a=200.1, d=1),  # A above max
        _one(2, s=100, a=50, d=2),  # D not in {0, 1}
        _one(5, s=100, a=10, d=1),  # track markers has no D
        _one(3, s=80, a=99, d=0),  # static turn A must be 100
        _one(6, s=100, a=50),  # no such type
        _one(-1, s=100, a=50),
        _one(2, s=np.nan, a=50, d=1),
    ]
    for ab in bad:
        assert not bool(_within(ab)), ab
    # Closed limits.
    assert bool(_within(_one(4, s=300, a=200, d=0)))
    assert bool(_within(_one(5, s=400, a=0)))
    # Host antibodies (a file just read) are checked by NumPy, with the same verdicts.
    cases = stack([good, *bad, _one(4, s=300, a=200, d=0)])
    host = jax.tree.map(np.asarray, cases)
    verdict = within_limits(host)
    assert isinstance(verdict, np.ndarray)
    np.testing.assert_array_equal(verdict, np.asarray(_within(cases)))
    np.testing.assert_array_equal(verdict, [True] + [False] * len(bad) + [True])


def test_canonical() -> None:
    messy = _one(5, s=100, a=10, d=1, f=50, rf=20, ra=30)
    clean = _canonical(messy)
    assert _equal(clean, _one(5, s=100, a=10)).all()


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_dict_round_trip(seed: int) -> None:
    ab = take(_sample(jax.random.key(seed)), 0)
    dicts = to_dicts(ab)
    assert [d["antigen"] for d in dicts][:2] == ["target unseen", "target seen"]
    for d, t in zip(dicts, np.asarray(ab.type), strict=True):
        assert d["type"] == TYPE_NAMES[t]
        used = {name for k, name in enumerate(ATTRIBUTE_NAMES) if USES[t, k]}
        assert set(d) == {"antigen", "type"} | used
        if "D" in d:
            assert d["D"] in ("left", "right")
    back = from_dicts(json.loads(json.dumps(dicts)))
    assert _equal(back, ab).all()
    for x, y in zip(jax.tree.leaves(back), jax.tree.leaves(ab), strict=True):
        assert x.dtype == y.dtype


def _valid_dicts() -> list[dict]:
    return [
        {
            "antigen": "target unseen",
            "type": "wander single",
            "S": 300,
            "F": 20,
            "A": 50,
            "D": "left",
        },
        {"type": "track markers", "S": 250, "A": 15},
        {"type": "wander both", "S": 200, "F": 30, "A": 40, "Rf": 30, "Ra": 40},
        {"type": "reverse turn", "S": 350, "A": 150, "D": "right"},
        {"type": "forward turn", "S": 200, "A": 60, "D": "right", "F": None},
        {"type": "static turn", "S": 60, "A": 100, "D": "left"},
        {"type": "reverse turn", "S": 400, "A": 20, "D": "left"},
        {"type": "forward turn", "S": 50, "A": 200, "D": "left"},
    ]


def test_from_dicts_valid() -> None:
    ab = from_dicts(_valid_dicts())
    np.testing.assert_array_equal(ab.type, [0, 5, 1, 4, 2, 3, 4, 2])
    np.testing.assert_array_equal(ab.direction, [0, 0, 0, 1, 1, 0, 0, 0])
    np.testing.assert_array_equal(ab.speed, [300, 250, 200, 350, 200, 60, 400, 50])
    np.testing.assert_array_equal(ab.freq, [20, 0, 30, 0, 0, 0, 0, 0])
    assert bool(jnp.all(_within(ab)))
    assert to_dicts(ab)[0] == {
        "antigen": "target unseen",
        "type": "wander single",
        "S": 300.0,
        "F": 20.0,
        "A": 50.0,
        "D": "left",
    }


@pytest.mark.parametrize(
    ("index", "change", "words"),
    [
        (0, {"S": 401}, ["antibody 0", "'S'", "[50, 400]"]),
        (3, {"S": 299}, ["antibody 3", "'S'"]),
        (5, {"A": 90}, ["antibody 5", "'A'"]),
        (1, {"A": -1}, ["antibody 1", "'A'"]),
        (2, {"Ra": 111}, ["antibody 2", "'Ra'"]),
        (0, {"D": "up"}, ["antibody 0", "'D'"]),
        (0, {"D": None}, ["antibody 0", "'D'", "missing"]),
        (1, {"D": "left"}, ["antibody 1", "'D'", "not used"]),
        (4, {"F": 50}, ["antibody 4", "'F'", "not used"]),
        (2, {"type": "moonwalk"}, ["antibody 2", "'type'"]),
        (6, {"speed": 300}, ["antibody 6", "'speed'", "unknown"]),
        (7, {"S": "fast"}, ["antibody 7", "'S'", "number"]),
        (7, {"S": True}, ["antibody 7", "'S'", "number"]),
        (7, {"S": float("nan")}, ["antibody 7", "'S'"]),
        (7, {"antigen": "target seen"}, ["antibody 7", "'antigen'"]),
    ],
)
def test_from_dicts_errors(index: int, change: dict, words: list[str]) -> None:
    dicts = _valid_dicts()
    dicts[index].update(change)
    if change.get("D", 0) is None:
        del dicts[index]["D"]
    with pytest.raises(ValueError) as err:
        from_dicts(dicts)
    message = str(err.value)
    assert "\n" not in message
    for word in words:
        assert word in message, message


def test_from_dicts_shape_errors() -> None:
    with pytest.raises(ValueError, match="expected 8 antibodies"):
        from_dicts(_valid_dicts()[:7])
    with pytest.raises(ValueError, match="antibody 3"):
        from_dicts([*_valid_dicts()[:3], "wander", *_valid_dicts()[4:]])
    with pytest.raises(ValueError, match="list"):
        from_dicts({"type": "wander single"})
    with pytest.raises(ValueError, match="one set"):
        to_dicts(take(_sample(jax.random.key(0)), slice(0, 5)))


def test_distance_hand_worked() -> None:
    a = _one(2, s=50, a=20, d=0)
    b = _one(2, s=400, a=110, d=0)
    # forward turn: S 350/350 = 1, A 90/180 = 0.5, D 0 -> mean 0.5
    assert float(_distance(a, b)) == pytest.approx(0.5)
    # static turn: S 25/50 = 0.5, A zero range -> 0, D differs -> 1; mean 0.5
    assert float(_distance(_one(3, s=50, a=100, d=0), _one(3, s=75, a=100, d=1))) == pytest.approx(
        0.5
    )
    # track markers: S 0, A 15/30 -> mean 0.25
    assert float(_distance(_one(5, s=200, a=0), _one(5, s=200, a=15))) == pytest.approx(0.25)
    assert float(_distance(a, a)) == 0.0
    assert float(_distance(a, _one(4, s=350, a=20, d=0))) == 1.0


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_distance_properties(seed: int) -> None:
    k1, k2 = jax.random.split(jax.random.key(seed))
    a, b = _sample(k1), _sample(k2)
    d = np.asarray(_distance(a, b))
    assert d.shape == (2500, 8)
    assert np.all((d >= 0) & (d <= 1))
    np.testing.assert_array_equal(d, np.asarray(_distance(b, a)))
    np.testing.assert_array_equal(np.asarray(_distance(a, a)), 0.0)
    np.testing.assert_array_equal(d[np.asarray(a.type) != np.asarray(b.type)], 1.0)


def test_take_and_stack() -> None:
    sets = _sample(jax.random.key(9))
    # Broadcasting: one set against all of them.
    d = np.asarray(_distance(take(sets, 0), sets))
    assert d.shape == (2500, 8)
    np.testing.assert_array_equal(d[0], 0.0)
    one = take(sets, (2, 4))
    assert one.shape == ()
    assert int(one.type) == int(sets.type[2, 4])
    rebuilt = stack([take(sets, i) for i in range(5)])
    assert _equal(rebuilt, take(sets, slice(0, 5))).all()
