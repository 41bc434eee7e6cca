"""Reinforcement (SPEC 6, paper Table 2): every score row, the ranged rows' bounds, penalties."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxais.immune.reinforcement import (
    OBSTACLE_LIMIT,
    PENALTY_IDIOTYPIC,
    PENALTY_NON_IDIOTYPIC,
    UNSEEN_LIMIT,
    PenaltyCounters,
    init_counters,
    penalty_size,
    rl_score,
    update_penalty,
)

_score = jax.jit(rl_score)
_score_batch = jax.jit(jax.vmap(rl_score))

OBSTACLES = range(2, 8)
SEQ_LEN = 600


def _s(m_prev, m, v_prev=0.0, v=0.0, centroid=7.0) -> float:
    out = _score(
        jnp.int32(m_prev), jnp.int32(m), jnp.float32(v_prev), jnp.float32(v), jnp.float32(centroid)
    )
    assert out.shape == () and out.dtype == jnp.float32
    return float(out)


def _reference(m_prev, m, v_prev, v, centroid) -> float:
    """Plain-Python SPEC 6."""
    lev = lambda a: 0 if a < 2 else (1 if a < 5 else 2)
    if m_prev == 0:
        return {0: 0.05, 1: 0.10}.get(m, -0.05)
    if m_prev == 1:
        if m == 1:
            return 0.05 * (1 - abs(centroid - 7) / 7)
        return -0.10 if m == 0 else -0.05
    if m < 2:
        return 0.10 if m == 0 else 0.20
    fall = (v_prev - v) / v_prev if v_prev > 0 else (0.0 if v == v_prev else -1.0)
    r = 0.25 * (lev(m_prev) - lev(m)) + 0.25 * np.clip(fall, -1, 1)
    r -= 0.10 * (m == m_prev and v >= v_prev)
    return float(np.clip(r, -0.40, 0.50))


@pytest.mark.parametrize(("v_prev", "v"), [(0.0, 0.0), (100.0, 3000.0), (3000.0, 100.0)])
def test_fixed_rows(v_prev: float, v: float) -> None:
    # The fixed rows ignore Vm and the centroid.
    assert _s(0, 0, v_prev, v, 2.0) == pytest.approx(0.05)
    assert _s(1, 0, v_prev, v, 2.0) == pytest.approx(-0.10)
    assert _s(0, 1, v_prev, v, 2.0) == pytest.approx(0.10)
    for o in OBSTACLES:
        assert _s(o, 0, v_prev, v, 2.0) == pytest.approx(0.10)
        assert _s(o, 1, v_prev, v, 2.0) == pytest.approx(0.20)
        assert _s(0, o, v_prev, v, 2.0) == pytest.approx(-0.05)
        assert _s(1, o, v_prev, v, 2.0) == pytest.approx(-0.05)


@pytest.mark.parametrize(
    ("centroid", "expected"),
    [(7.0, 0.05), (0.0, 0.0), (14.0, 0.0), (3.5, 0.025), (10.5, 0.025), (12.6, 0.01)],
)
def test_kept_marker(centroid: float, expected: float) -> None:
    assert _s(1, 1, 100.0, 200.0, centroid) == pytest.approx(expected, abs=1e-7)


@pytest.mark.parametrize(
    ("m_prev", "m", "v_prev", "v", "expected"),
    [
        (2, 2, 1000.0, 800.0, 0.25 * 0.2),  # same obstacle, Vm fell 20 %
        (2, 2, 1000.0, 1000.0, -0.10),  # no progress
        (2, 2, 500.0, 1000.0, -0.25 - 0.10),  # Vm doubled: relative fall clipped to -1
        (5, 5, 3000.0, 3000.0, -0.10),  # stuck in the same collision
        (5, 5, 3000.0, 2500.0, 0.25 * 500 / 3000),
        (2, 4, 800.0, 900.0, 0.25 * -0.125),  # side changed: no "same antigen" penalty
        (3, 3, 800.0, 900.0, 0.25 * -0.125 - 0.10),
        (6, 3, 2400.0, 2400.0, 0.25),  # collision -> obstacle, Vm level
        (5, 2, 3000.0, 1500.0, 0.25 + 0.25 * 0.5),
        (2, 5, 1000.0, 1500.0, -0.25 - 0.25 * 0.5),  # -0.375, just inside the lower bound
        (2, 5, 1000.0, 1700.0, -0.40),  # -0.25 - 0.25 * 0.7 = -0.425, clipped
        (2, 5, 1000.0, 2500.0, -0.40),  # -0.25 - 0.25 * 1 (clipped fall) = -0.50, clipped
        (4, 4, 300.0, 4095.0, -0.35),  # the worst same-antigen case stays inside
        (7, 2, 4095.0, 0.0, 0.50),  # the upper bound: one level better, Vm fell 100 %
    ],
)
def test_obstacle_row(m_prev: int, m: int, v_prev: float, v: float, expected: float) -> None:
    assert _s(m_prev, m, v_prev, v) == pytest.approx(expected, abs=1e-6)


def test_obstacle_row_upper_bound() -> None:
    # The formula's components peak at 0.25 + 0.25, so +0.50 is reached but never passed, even
    # for readings a simulator cannot produce (a negative previous Vm).
    assert _s(7, 2, 4095.0, 0.0) == pytest.approx(0.50)
    assert _s(7, 2, -1000.0, -3000.0) == pytest.approx(0.50)
    assert _s(5, 4, 1e9, -1e9) == pytest.approx(0.50)


def test_v_prev_zero_is_finite() -> None:
    assert _s(2, 2, 0.0, 0.0) == pytest.approx(-0.10)  # no change, same antigen
    assert _s(2, 2, 0.0, 300.0) == pytest.approx(-0.25 - 0.10)  # rise from 0: fall clipped to -1
    assert _s(5, 2, 0.0, 300.0) == pytest.approx(0.25 - 0.25)
    assert np.isfinite(_s(6, 6, 0.0, 1e-9))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_matches_reference_and_bounds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 256
    m_prev = rng.integers(0, 8, n).astype(np.int32)
    m = rng.integers(0, 8, n).astype(np.int32)
    v_prev = rng.choice([0.0, 250.0, 1000.0, 2400.0, 4095.0], n) * rng.random(n).round(1)
    v = rng.choice([0.0, 250.0, 1000.0, 2400.0, 4095.0], n) * rng.random(n).round(1)
    v_prev, v = v_prev.astype(np.float32), v.astype(np.float32)
    v[::7] = v_prev[::7]  # exercise "V_t >= V_{t-1}" with equality
    centroid = (rng.random(n) * 14).astype(np.float32)
    got = np.asarray(_score_batch(m_prev, m, v_prev, v, centroid))
    expected = [
        _reference(int(m_prev[i]), int(m[i]), float(v_prev[i]), float(v[i]), float(centroid[i]))
        for i in range(n)
    ]
    np.testing.assert_allclose(got, expected, atol=1e-6)
    assert np.all((got >= -0.40 - 1e-7) & (got <= 0.50 + 1e-7))


def test_vmap_equals_loop() -> None:
    rng = np.random.default_rng(0)
    n = 256  # the batch size of the reference test: no new compile
    args = (
        rng.integers(0, 8, n).astype(np.int32),
        rng.integers(0, 8, n).astype(np.int32),
        (rng.random(n) * 4095).astype(np.float32),
        (rng.random(n) * 4095).astype(np.float32),
        (rng.random(n) * 14).astype(np.float32),
    )
    batched = np.asarray(_score_batch(*args))
    for i in range(n):
        assert batched[i] == pytest.approx(float(_score(*(a[i] for a in args))), abs=1e-7)


# --- penalties ---------------------------------------------------------------------------------


def _scan(counters: PenaltyCounters, ms: jnp.ndarray):
    return jax.lax.scan(update_penalty, counters, ms)


_update = jax.jit(update_penalty)
_run_penalties = jax.jit(lambda ms: _scan(init_counters(), ms))


def _fires(ms: list[int]) -> tuple[list[int], PenaltyCounters]:
    """1-based iterations at which a penalty fires, for a sequence padded with antigen 1."""
    assert len(ms) <= SEQ_LEN
    padded = np.ones(SEQ_LEN, np.int32)  # antigen 1 resets both runs and never fires
    padded[: len(ms)] = ms
    final, fire = _run_penalties(jnp.asarray(padded))
    return (np.flatnonzero(np.asarray(fire)) + 1).tolist(), final


def test_constants() -> None:
    assert (UNSEEN_LIMIT, OBSTACLE_LIMIT) == (250, 15)
    assert (PENALTY_IDIOTYPIC, PENALTY_NON_IDIOTYPIC) == (0.5, 1.0)
    assert float(penalty_size(True)) == 0.5
    assert float(penalty_size(False)) == 1.0
    np.testing.assert_array_equal(penalty_size(jnp.array([True, False])), [0.5, 1.0])


def test_unseen_penalty_fires_on_251st_and_repeats() -> None:
    fires, _ = _fires([0] * 560)
    assert fires == [251, 502]


def test_unseen_counter_restarts() -> None:
    counters = init_counters()
    for _ in range(250):
        counters, fire = _update(counters, 0)
        assert not bool(fire)
    assert int(counters.unseen_run) == 250
    counters, fire = _update(counters, 0)
    assert bool(fire) and int(counters.unseen_run) == 0
    counters, fire = _update(counters, 0)
    assert not bool(fire) and int(counters.unseen_run) == 1
    assert counters.unseen_run.dtype == jnp.int32 and counters.obstacle_run.dtype == jnp.int32


def test_obstacle_penalty_fires_on_16th_and_repeats() -> None:
    # Any mix of antigens 2-7 counts as one run: the robot is still among obstacles.
    fires, _ = _fires([2, 5, 3, 7, 4, 6] * 8)
    assert fires == [16, 32, 48]
    fires, _ = _fires([6] * 15)
    assert fires == []
    fires, _ = _fires([6] * 16)
    assert fires == [16]


def test_runs_reset_when_group_changes() -> None:
    assert _fires([0] * 250 + [1] + [0] * 250)[0] == []
    assert _fires([0] * 250 + [3] + [0] * 250)[0] == []
    assert _fires([0] * 250 + [3] + [0] * 251)[0] == [502]
    assert _fires([2] * 15 + [0] + [2] * 15)[0] == []
    assert _fires([2] * 15 + [1] + [2] * 15 + [0] + [5] * 16)[0] == [48]
    # One obstacle iteration restarts the unseen run.
    assert _fires(([0] * 200 + [4]) * 2)[0] == []


def test_final_counters() -> None:
    _, final = _fires([0] * 10 + [2] * 7)
    # The padding (antigen 1) resets both runs.
    assert (int(final.unseen_run), int(final.obstacle_run)) == (0, 0)
    counters = init_counters()
    for m in [0] * 10 + [2] * 7:
        counters, _ = _update(counters, m)
    assert (int(counters.unseen_run), int(counters.obstacle_run)) == (0, 7)


def test_penalty_vmap() -> None:
    # Batched over robots with different antigen streams.
    ms = np.ones((3, SEQ_LEN), np.int32)
    ms[0, :300] = 0
    ms[1, :20] = 5
    batched = jax.jit(jax.vmap(lambda s: _scan(init_counters(), s)))
    _, fire = batched(jnp.asarray(ms))
    assert [(np.flatnonzero(np.asarray(f)) + 1).tolist() for f in fire] == [[251], [16], []]


# --- encounters [ours: jaxais.immune.readings] ----------------------------------------------------

_run_encounters = jax.jit(
    lambda ms, gap: jax.lax.scan(lambda c, m: update_penalty(c, m, True, gap), init_counters(), ms)
)


def _encounter_fires(ms: list[int], gap: int = 70) -> list[int]:
    """1-based iterations at which the encounter penalty fires (sequence padded with 1s)."""
    padded = np.ones(SEQ_LEN, np.int32)
    padded[: len(ms)] = ms
    _, fire = _run_encounters(jnp.asarray(padded), gap)
    return (np.flatnonzero(np.asarray(fire)) + 1).tolist()


def test_encounters_count_entries_not_iterations() -> None:
    # Unbroken contact is one encounter, however long (Table 2's no-progress term scores it).
    assert _encounter_fires([5] * 400) == []
    # Hovering at the threshold: antigen 2 every other iteration, 16 entries fire on the 16th.
    hover = [2, 0] * 20
    assert _encounter_fires(hover) == [31]
    # The literal reading never catches the hoverer: every clear iteration ends its run.
    assert _fires(hover)[0] == []


def test_encounter_run_ends_only_after_the_gap() -> None:
    # 15 encounters, then 69 clear iterations (under the gap of 70): the 16th still fires.
    seq = [2, 0] * 15 + [0] * 68 + [3]
    assert _encounter_fires(seq) == [len(seq)]
    # 70 clear iterations end the run: the next entry is the first of a new run.
    seq = [2, 0] * 15 + [0] * 69 + [3]
    assert _encounter_fires(seq) == []
    # A gap of 1 makes every clear iteration end the run.
    assert _encounter_fires([2, 0] * 20, gap=1) == []


def test_encounter_penalty_restarts_and_repeats() -> None:
    assert _encounter_fires([4, 1] * 48) == [31, 63, 95]
