"""The LTL genetic algorithm (SPEC 10): selection, crossover, mutation, elitism, bests, robust
evaluation, success checks and stop, crossing rates, diversity.

Every compiled program is shared: breeding is tested through ``ga.tell`` with one tiny config
(2 populations x 4 robots, one start each, success checks of 4 starts: every rollout is a batch
of 8), and the GA runs use the same config and a 2 s time cap, so the maze's rollout compiles
once for the session (``tiny_run`` below is shared with the other GA tests). Crossings need a
robot that can reach the goal within 2 s: those tests run in ``EASY``, a small room with the goal
block right in front of the start.
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxais import envs, ga, runner
from jaxais.checkpointing import state_to_tree
from jaxais.controllers import LTL
from jaxais.experiments.diversity import compare_diversity, diversity
from jaxais.immune.antibodies import (
    LIMITS_MIN,
    Antibodies,
    antibody_distance,
    sample_antibodies,
    within_limits,
)
from jaxais.loop import EpisodeConfig

TINY = ga.GAConfig(populations=2, robots=4, generations=2, tau_cap=2.0, starts=1, success_starts=4)
"""The tests' GA: every test that evaluates robots uses this config (batches of 8 runs)."""
NOCHECK = ga.GAConfig(**{**TINY.to_dict(), "success_starts": 0, "success_rate": None})
"""TINY without success checks: the generations' evaluations make the bests."""

EASY = """
# A small room; the goal block fills the camera of a robot at the start, so most sets finish in
# three iterations and some turn away first (crossings vary from set to set).
name = "easy"
[arena]
width = 0.6
height = 0.4
wall_height = 0.1
[robot]
start_region = [0.12, 0.17, 0.16, 0.23]
start_heading = [-0.3, 0.3]
[goal]
shape = "box"
half_size = [0.05, 0.08]
height = 0.1
region = [0.38, 0.19, 0.4, 0.21]
"""


@functools.cache
def maze() -> envs.World:
    return envs.load_world("ga_maze")


@pytest.fixture(scope="session")
def easy(tmp_path_factory: pytest.TempPathFactory) -> envs.World:
    path = tmp_path_factory.mktemp("worlds") / "easy.toml"
    path.write_text(EASY)
    return envs.load_world(path)


@functools.cache
def tiny_run(seed: int = 0, generations: int = 2) -> ga.GAState:
    """A finished tiny GA run (cached: other tests reuse it)."""
    config = ga.GAConfig(**{**TINY.to_dict(), "generations": generations})
    return ga.run(jax.random.key(seed), config, maze())


def hand_sets(types: list[list[int]], speed: float = 100.0) -> Antibodies:
    """Canonical sets [K, 8] of the given types, every used attribute at its lower limit, S set.

    Built in NumPy (eager JAX ops would compile one small program each).
    """
    t = np.asarray(types, np.int32)
    x = np.nan_to_num(LIMITS_MIN[t], nan=0.0).astype(np.float32)
    x[..., 0] = np.where(t == 4, 300.0, np.where(t == 3, min(speed, 100.0), speed))
    cols = ("speed", "freq", "angle", "direction", "right_freq", "right_angle")
    fields = {c: x[..., k] for k, c in enumerate(cols)}
    fields["direction"] = fields["direction"].astype(np.int32)
    return Antibodies(type=t, **fields)


def evaluation(f, tau=None, c=None, L=None, crossings=None, starts: int = 1) -> ga.Evaluation:
    f = np.asarray(f, np.float32)
    tau = 2 * f if tau is None else np.asarray(tau, np.float32)
    c = np.zeros(f.shape, np.float32) if c is None else np.asarray(c, np.float32)
    L = np.zeros((*f.shape, 8), np.float32) if L is None else np.asarray(L, np.float32)
    crossings = np.zeros(f.shape, np.int32) if crossings is None else np.asarray(crossings)
    return ga.Evaluation(
        fitness=f, tau=tau, collisions=c, L=L, crossings=crossings.astype(np.int32), starts=starts
    )


# ------------------------------------------------------------------------------- config


def test_lower_is_better_is_declared_once():
    assert ga.LOWER_IS_BETTER is True
    assert "LOWER fitness is better" in ga.__doc__


@pytest.mark.parametrize(
    "field, value",
    [
        ("populations", 0),
        ("robots", 1),
        ("generations", 0),
        ("mutation", 1.5),
        ("mutation", -0.1),
        ("elitism", 4),
        ("elitism", -1),
        ("target_f", float("nan")),
        ("tau_cap", 0.0),
        ("tau_cap", float("inf")),
        ("collision_cap", 0),
        ("robots", 2.5),
        ("populations", True),
        ("starts", 0),
        ("starts", 1.5),
        ("success_starts", -1),
        ("success_rate", 0.0),
        ("success_rate", 1.5),
        ("success_rate", float("nan")),
        ("success_rate", True),
    ],
)
def test_config_rejects_out_of_range_values(field, value):
    with pytest.raises(ga.ConfigError) as info:
        ga.GAConfig(**{**TINY.to_dict(), field: value})
    assert info.value.field == field
    assert "\n" not in str(info.value) and str(info.value).startswith(field)


def test_a_success_stop_needs_success_checks():
    with pytest.raises(ga.ConfigError) as info:
        ga.GAConfig(success_starts=0, success_rate=0.8)
    assert info.value.field == "success_starts" and "success_rate" in str(info.value)
    assert ga.GAConfig(success_starts=0, success_rate=None).success_starts == 0


def test_config_defaults_and_round_trip():
    c = ga.GAConfig()
    assert (c.populations, c.robots, c.generations, c.mutation, c.elitism) == (5, 10, 200, 0.05, 1)
    assert (c.tau_cap, c.collision_cap, c.target_f) == (500.0, 100, None)
    assert (c.starts, c.success_starts, c.success_rate, c.crossover) == (1, 10, 0.95, "uniform")
    with pytest.raises(ga.ConfigError, match="crossover"):
        ga.GAConfig(crossover="best")
    assert ga.GAConfig.from_dict(c.to_dict()) == c
    assert c.episode_config().tau_cap == 500.0
    assert c.episode_config().stop_at_collision_cap  # the LTL caps end a run (SPEC 10)


# ------------------------------------------------------------------------------- selection

_roulette = jax.jit(ga.roulette, static_argnums=2)


def test_roulette_frequencies_match_inverse_cost():
    tau = np.array([100.0, 200.0, 500.0, 50.0, 500.0], np.float32)
    c = np.array([0, 10, 100, 2, 0], np.int32)
    w = np.asarray(ga.selection_weights(tau, c))
    np.testing.assert_allclose(w, 1.0 / (tau + 8.0 * c), rtol=1e-6)
    n = 200_000
    idx = np.asarray(_roulette(jax.random.key(1), jnp.asarray(w), n))
    freq = np.bincount(idx, minlength=5) / n
    expected = w / w.sum()
    # Binomial standard error at n = 2e5 is below 0.0012; 5 sigma.
    np.testing.assert_allclose(freq, expected, atol=0.006)


def test_roulette_never_draws_a_zero_weight():
    w = jnp.array([0.0, 1.0, 0.0, 3.0])
    idx = np.asarray(_roulette(jax.random.key(2), w, 200_000))
    assert set(np.unique(idx)) == {1, 3}


# ------------------------------------------------------------------------------- crossover

_crossover = jax.jit(ga.crossover, static_argnames="rl_assisted")


def test_crossover_takes_the_higher_scoring_antibody_per_antigen():
    sets = hand_sets([[0] * 8, [5] * 8])
    a = jax.tree.map(lambda x: x[0], sets)
    b = jax.tree.map(lambda x: x[1], sets)
    La = jnp.array([5.0, 0.0, 3.0, 1.0, 2.0, 2.0, 9.0, 0.5])
    Lb = jnp.array([1.0, 4.0, 3.0, 2.0, 2.0, 1.0, 0.0, 7.0])
    winner_a = np.array([True, False, None, False, None, True, True, False])
    ties = np.array([w is None for w in winner_a])
    from_a_counts = np.zeros(8)
    n = 200
    for k in range(n):
        child = _crossover(jax.random.key(k), a, La, b, Lb)
        from_a = np.asarray(child.type) == 0
        np.testing.assert_array_equal(from_a[~ties], winner_a[~ties].astype(bool))
        from_a_counts += from_a
    # Ties go either way, about half the time each.
    assert np.all(np.abs(from_a_counts[ties] / n - 0.5) < 0.15)


def test_uniform_crossover_ignores_the_scores():
    sets = hand_sets([[0] * 8, [5] * 8])
    a, b = (jax.tree.map(lambda x, i=i: x[i], sets) for i in (0, 1))
    La, Lb = jnp.full(8, 100.0), jnp.zeros(8)  # RL-assisted would take all of a
    n = 200
    from_a = sum(
        np.asarray(_crossover(jax.random.key(k), a, La, b, Lb, rl_assisted=False).type) == 0
        for k in range(n)
    )
    # Each antigen from either parent, about half the time each (binomial sd 0.035; 4 sd).
    assert np.all(np.abs(from_a / n - 0.5) < 0.15), from_a


# ------------------------------------------------------------------------------- tell

_within = jax.jit(within_limits)
MUT0 = ga.GAConfig(**{**TINY.to_dict(), "mutation": 0.0})
MUT1 = ga.GAConfig(**{**TINY.to_dict(), "mutation": 1.0})
NORATE = ga.GAConfig(**{**MUT0.to_dict(), "success_rate": None})


def fresh_state(seed: int, config: ga.GAConfig = TINY) -> ga.GAState:
    return ga.init(jax.random.key(seed), config)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rate=st.sampled_from([0.05, 1.0]))
def test_next_generation_stays_within_table_1(seed, rate):
    config = TINY if rate == 0.05 else MUT1
    state = fresh_state(0, config)
    f = np.random.default_rng(seed).uniform(1, 300, (2, 4))
    new = ga.tell(jax.random.key(seed), state.population, evaluation(f), state, config)
    assert bool(np.all(np.asarray(_within(new.population))))


def test_elite_survives_unchanged_and_children_come_from_parents():
    state = fresh_state(3, MUT0)
    f = np.array([[40.0, 10.0, 30.0, 20.0], [5.0, 50.0, 5.0, 60.0]])
    new = ga.tell(jax.random.key(4), state.population, evaluation(f), state, MUT0)
    pop, old = jax.tree.map(np.asarray, new.population), jax.tree.map(np.asarray, state.population)
    for p, elite in ((0, 1), (1, 0)):  # population 1: a tie, the lowest index wins
        for name in ("type", "speed", "freq", "angle", "direction", "right_freq", "right_angle"):
            np.testing.assert_array_equal(getattr(pop, name)[p, 0], getattr(old, name)[p, elite])
    # Without mutation every child antibody is some parent's antibody for that antigen.
    for p in range(2):
        for r in range(1, 4):
            for j in range(8):
                assert any(
                    pop.type[p, r, j] == old.type[p, q, j]
                    and pop.speed[p, r, j] == old.speed[p, q, j]
                    for q in range(4)
                )
    assert int(new.generation) == 1
    np.testing.assert_array_equal(np.asarray(new.fitness), f.astype(np.float32))


def test_the_checked_best_becomes_the_elite():
    """With checks, each population's checked best so far takes robot 0's place (the elite
    slot) after breeding; a population without a checked best keeps its bred elite."""
    state = fresh_state(7, MUT0)
    state = ga.tell(
        jax.random.key(1), state.population, evaluation(np.full((2, 4), 3.0)), state, MUT0
    )
    other = fresh_state(8, MUT0).population  # sets that are in neither population
    best = state.best.replace(
        antibodies=jax.tree.map(lambda x: x[:, 2], other),
        starts=jnp.array([10, 0], jnp.int32),
    )
    new = ga.best_as_elite(state.replace(best=best))
    for name in ("type", "speed", "freq", "angle", "direction", "right_freq", "right_angle"):
        got, bred = getattr(new.population, name), getattr(state.population, name)
        np.testing.assert_array_equal(got[0, 0], getattr(other, name)[0, 2])
        np.testing.assert_array_equal(got[1, 0], bred[1, 0])
        np.testing.assert_array_equal(got[:, 1:], bred[:, 1:])


def test_the_checked_best_is_the_elite_through_a_real_run(success_run):
    state = jax.tree.map(np.asarray, success_run.replace(key=jax.random.key_data(success_run.key)))
    for a, b in zip(
        jax.tree.leaves(state.population), jax.tree.leaves(state.best.antibodies), strict=True
    ):
        np.testing.assert_array_equal(a[:, 0], b)


@pytest.mark.slow
def test_elite_survives_through_a_real_run_without_checks():
    state = ga.run(jax.random.key(0), NOCHECK, maze())
    state = jax.tree.map(np.asarray, state.replace(key=jax.random.key_data(state.key)))
    best = np.argmin(state.fitness, axis=1)
    for p in range(2):
        for name in ("type", "speed", "freq", "angle", "direction", "right_freq", "right_angle"):
            np.testing.assert_array_equal(
                getattr(state.population, name)[p, 0], getattr(state.evaluated, name)[p, best[p]]
            )


def test_best_is_kept_until_strictly_beaten():
    config = ga.GAConfig(**{**NOCHECK.to_dict(), "mutation": 0.0})
    s0 = fresh_state(5, config)
    s1 = ga.tell(
        jax.random.key(1),
        s0.population,
        evaluation([[9.0, 7.0, 8.0, 9.0], [3.0, 4.0, 5.0, 6.0]]),
        s0,
        config,
    )
    np.testing.assert_array_equal(np.asarray(s1.best.fitness), [7.0, 3.0])
    np.testing.assert_array_equal(np.asarray(s1.best.generation), [0, 0])
    np.testing.assert_array_equal(np.asarray(s1.best.tau), [14.0, 6.0])
    s2 = ga.tell(
        jax.random.key(2),
        s1.population,
        evaluation([[6.0, 9.0, 9.0, 9.0], [3.0, 9.0, 9.0, 9.0]]),
        s1,
        config,
    )
    np.testing.assert_array_equal(np.asarray(s2.best.fitness), [6.0, 3.0])
    np.testing.assert_array_equal(np.asarray(s2.best.generation), [1, 0])  # a tie keeps the old
    # Population 0's best is now robot 0 of generation 1 (the elite of generation 0).
    np.testing.assert_array_equal(
        np.asarray(s2.best.antibodies.speed[0]), np.asarray(s1.population.speed[0, 0])
    )
    seed = ga.best_sets(s2)
    assert seed.antibodies.type.shape == (2, 8) and seed.tau.dtype == np.float32
    assert seed.collisions.dtype == np.int32


def test_with_checks_tell_leaves_the_bests_to_verify():
    state = fresh_state(5, MUT0)
    new = ga.tell(
        jax.random.key(1), state.population, evaluation(np.full((2, 4), 3.0)), state, MUT0
    )
    np.testing.assert_array_equal(np.asarray(new.best.starts), [0, 0])
    assert np.all(np.isinf(np.asarray(new.best.fitness)))
    with pytest.raises(ValueError, match="no generation"):
        ga.best_sets(new)


def test_tell_compiles_once_per_config():
    before = ga.tell._cache_size()
    state = fresh_state(6)
    for k in range(3):
        ev = evaluation(np.full((2, 4), 1.0 + k))
        state = ga.tell(jax.random.key(k), state.population, ev, state, TINY)
    assert ga.tell._cache_size() - before <= 1


def test_stop_rules_and_target():
    state = tiny_run()
    assert ga.stopped_by(state, TINY) == "generations"
    more = ga.GAConfig(**{**TINY.to_dict(), "generations": 5})
    assert ga.stopped_by(state, more) is None
    best = float(np.max(np.asarray(state.best.fitness)))
    reach = ga.GAConfig(**{**more.to_dict(), "target_f": best})
    assert ga.reached_target(state, reach)
    assert ga.stopped_by(state, reach) == "target_f"
    # Nothing crosses the maze in 2 s: the success stop cannot fire.
    assert not ga.reached_success(state, more)
    starts = np.asarray(state.best.starts)  # checked, pooled where a set stayed best
    assert np.all(starts >= 4) and np.all(starts % 4 == 0)


# ------------------------------------------------------------------------------- runs


def test_run_is_reproducible_and_consistent():
    a = tiny_run(0)
    b = ga.run(jax.random.key(0), TINY, maze())
    ta, tb = state_to_tree(a), state_to_tree(b)
    assert ta.keys() == tb.keys()
    for name in ta:
        np.testing.assert_array_equal(ta[name], tb[name], err_msg=name)
    f = np.asarray(a.fitness)
    np.testing.assert_allclose(f, (8 * np.asarray(a.collisions) + np.asarray(a.tau)) / 2)
    assert np.all(np.asarray(a.tau) <= TINY.tau_cap) and np.all(np.asarray(a.L) >= 0)
    assert int(a.generation) == 2
    seed = ga.best_sets(a)
    np.testing.assert_array_equal(seed.tau, np.asarray(a.best.tau))
    np.testing.assert_array_equal(seed.collisions, np.rint(np.asarray(a.best.collisions)))


# ------------------------------------------------------------------------------- robust runs


@pytest.mark.slow
def test_robust_evaluation_is_the_mean_of_one_start_evaluations(easy):
    """Three starts per robot, in one rollout, give each robot the mean τ, c, L and f of three
    one-start evaluations from the same start keys (and the sum of their crossings)."""
    population = fresh_state(11).population
    keys = ga.start_keys(jax.random.key(12), 3)
    params = envs.default_params()
    three = ga.evaluate(keys, population, easy, params, TINY)
    ones = [ga.evaluate(keys[s : s + 1], population, easy, params, TINY) for s in range(3)]
    assert three.starts == 3 and all(e.starts == 1 for e in ones)
    for name in ("tau", "collisions", "L"):
        stacked = np.stack([np.asarray(getattr(e, name)) for e in ones])
        want = stacked.mean(axis=0, dtype=np.float64).astype(np.float32)
        np.testing.assert_array_equal(np.asarray(getattr(three, name)), want, err_msg=name)
    np.testing.assert_allclose(
        np.asarray(three.fitness), np.mean([np.asarray(e.fitness) for e in ones], 0), rtol=1e-6
    )
    crossings = sum(np.asarray(e.crossings) for e in ones)
    np.testing.assert_array_equal(np.asarray(three.crossings), crossings)
    assert 0 < crossings.sum() < 3 * 8  # some robots cross, not all: the test means something
    # A single key is split into config.starts start keys.
    by_key = ga.evaluate(jax.random.key(12), population, easy, params, TINY)
    np.testing.assert_array_equal(np.asarray(by_key.tau), np.asarray(ones[0].tau))


@pytest.mark.slow
def test_crossing_rates_do_not_depend_on_batching(easy):
    sets = jax.tree.map(lambda x: x[:, 0], fresh_state(13).population)  # [2, 8]
    key, params = jax.random.key(14), envs.default_params()
    whole = ga.measure(key, sets, easy, 8, params, TINY)
    ev = ga.measure(key, sets, easy, 8, params, TINY, batch_starts=4)
    for name in ("fitness", "tau", "collisions", "L", "crossings"):
        np.testing.assert_array_equal(getattr(whole, name), getattr(ev, name), err_msg=name)
    rate = ev.crossing_rate
    assert rate.shape == (2,) and np.all((rate >= 0) & (rate <= 1))
    np.testing.assert_array_equal(rate, np.asarray(ev.crossings) / 8)
    assert ev.starts == 8 and ev.L.shape == (2, 8)
    # The measurement's keys are not the run's: fold_in, not split.
    run_keys = jax.random.split(jax.random.key(0), 4)
    assert not np.any(
        np.all(jax.random.key_data(run_keys) == jax.random.key_data(ga.crossing_key(0)), axis=1)
    )


SUCCESS = ga.GAConfig(**{**TINY.to_dict(), "generations": 6, "success_rate": 0.5})


@pytest.fixture(scope="module")
def success_run(easy: envs.World) -> ga.GAState:
    return ga.run(jax.random.key(3), SUCCESS, easy)


def test_the_success_stop_fires(success_run):
    state = success_run
    assert ga.stopped_by(state, SUCCESS) == "success"
    assert ga.reached_success(state, SUCCESS) and int(state.generation) < SUCCESS.generations
    starts, crossings = np.asarray(state.best.starts), np.asarray(state.best.crossings)
    assert np.all(crossings >= 0.5 * starts)
    # The stop came after a confirmation: every best has two checks or more behind it.
    assert np.all(starts >= 2 * SUCCESS.success_starts)
    # The same run without the stop goes on to the cap.
    plain = ga.GAConfig(**{**SUCCESS.to_dict(), "success_rate": None, "generations": 2})
    assert not ga.reached_success(state, plain)


def test_confirm_pools_fresh_starts_into_every_best(easy, success_run):
    state = success_run
    more = ga.confirm(jax.random.key(9), state, easy, envs.default_params(), SUCCESS)
    before, after = jax.tree.map(np.asarray, state.best), jax.tree.map(np.asarray, more.best)
    np.testing.assert_array_equal(after.starts, before.starts + SUCCESS.success_starts)
    assert np.all(after.crossings >= before.crossings)
    assert np.all(after.crossings <= before.crossings + SUCCESS.success_starts)
    sets = zip(jax.tree.leaves(after.antibodies), jax.tree.leaves(before.antibodies), strict=True)
    for a, b in sets:
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(after.fitness, (8 * after.collisions + after.tau) / 2, rtol=1e-6)


def test_resume_with_checks_equals_uninterrupted(easy):
    config = ga.GAConfig(**{**SUCCESS.to_dict(), "success_rate": 1.0, "generations": 3})
    straight = ga.run(jax.random.key(5), config, easy)
    first = ga.run(jax.random.key(5), ga.GAConfig(**{**config.to_dict(), "generations": 1}), easy)
    tree = state_to_tree(first)
    from jaxais.checkpointing import state_from_tree

    restored = state_from_tree(tree, config, str(jax.random.key_impl(first.key)))
    resumed = ga.run(restored, config, easy)
    a, b = state_to_tree(straight), state_to_tree(resumed)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def _verify_state(best_same: bool) -> tuple[ga.GAState, ga.Evaluation]:
    """A state whose population 0's generation best is (or is not) its best so far, which has
    18 crossings in 20 starts, and a check of 20 more starts with 20 crossings."""
    state = fresh_state(21, MUT0)
    for k in range(2):  # the check is of generation 1
        state = ga.tell(
            jax.random.key(k), state.population, evaluation([[5.0, 1.0, 9.0, 9.0]] * 2), state, MUT0
        )
    cand = jax.tree.map(lambda x: np.asarray(x)[:, 1], state.evaluated)
    other = cand.replace(speed=cand.speed + 1.0)  # another set (only compared, never run)
    best = state.best.replace(
        antibodies=cand if best_same else other,
        fitness=np.array([60.0, 60.0], np.float32),
        tau=np.array([120.0, 120.0], np.float32),
        collisions=np.array([0.0, 0.0], np.float32),
        L=np.full((2, 8), 2.0, np.float32),
        crossings=np.array([18, 18], np.int32),
        starts=np.array([20, 20], np.int32),
        generation=np.array([0, 0], np.int32),
    )
    record = ga.Evaluation(
        fitness=np.array([40.0, 70.0], np.float32),
        tau=np.array([80.0, 140.0], np.float32),
        collisions=np.array([0.0, 0.0], np.float32),
        L=np.full((2, 8), 4.0, np.float32),
        crossings=np.array([20, 20], np.int32),
        starts=20,
    )
    return state.replace(best=best), record


def test_a_check_of_the_best_set_is_pooled():
    state, record = _verify_state(best_same=True)
    best = ga.check(state, record, MUT0).best
    np.testing.assert_array_equal(np.asarray(best.starts), [40, 40])
    np.testing.assert_array_equal(np.asarray(best.crossings), [38, 38])
    np.testing.assert_allclose(np.asarray(best.tau), [100.0, 130.0])
    np.testing.assert_allclose(np.asarray(best.fitness), [50.0, 65.0])  # (8c + τ)/2
    np.testing.assert_allclose(np.asarray(best.L), 3.0)


def test_a_passing_check_outranks_a_failing_best():
    state, record = _verify_state(best_same=False)
    # 18 of 20 fails a rate of 0.95 and 20 of 20 passes it: the check wins even at higher f.
    best = ga.check(state, record, MUT0).best
    np.testing.assert_array_equal(np.asarray(best.fitness), [40.0, 70.0])
    np.testing.assert_array_equal(np.asarray(best.generation), [1, 1])
    # Without a success rate (2 never passes), plain f decides.
    best = ga.check(state, record, NORATE).best
    np.testing.assert_array_equal(np.asarray(best.fitness), [40.0, 60.0])
    np.testing.assert_array_equal(np.asarray(best.starts), [20, 20])


def test_best_sets_needs_an_evaluation():
    with pytest.raises(ValueError, match="no generation"):
        ga.best_sets(fresh_state(0))


# ------------------------------------------------------------------------------- diversity


def test_diversity_of_hand_made_sets():
    assert diversity(hand_sets([[0] * 8] * 5)) == 0.0
    # Every pair differs in type at every antigen.
    assert diversity(hand_sets([[k] * 8 for k in range(5)])) == pytest.approx(1.0)
    # Sets 0 and 1 equal, set 2 of other types: pairs (0,1) = 0, (0,2) = (1,2) = 1.
    assert diversity(hand_sets([[0] * 8, [0] * 8, [1] * 8])) == pytest.approx(2 / 3)
    # Track markers uses S and A: S 50 vs 400 is a full-range difference, A equal -> 1/2.
    two = hand_sets([[5] * 8, [5] * 8])
    two = two.replace(speed=np.asarray([[50.0] * 8, [400.0] * 8], np.float32))
    assert diversity(two) == pytest.approx(0.5)
    # Half the antigens differ in type -> 1/2.
    assert diversity(hand_sets([[0] * 8, [0] * 4 + [2] * 4])) == pytest.approx(0.5)


def test_diversity_matches_a_loop_over_pairs():
    sets = jax.tree.map(
        np.asarray, jax.jit(sample_antibodies, static_argnums=1)(jax.random.key(7), (5, 8))
    )
    distance = jax.jit(antibody_distance)
    total, n = 0.0, 0
    for i in range(5):
        for k in range(i + 1, 5):
            a = jax.tree.map(lambda x, i=i: x[i], sets)
            b = jax.tree.map(lambda x, k=k: x[k], sets)
            total += float(np.mean(np.asarray(distance(a, b))))
            n += 1
    assert diversity(sets) == pytest.approx(total / n, rel=1e-6)
    with pytest.raises(ValueError):
        diversity(jax.tree.map(lambda x: x[:1], sets))


def test_final_sets():
    state = tiny_run()
    f = np.asarray(state.fitness)
    sets = ga.final_sets(state)
    assert sets.type.shape == (2, 8)
    np.testing.assert_array_equal(
        sets.type[1], np.asarray(state.evaluated.type)[1, np.argmin(f[1])]
    )
    top = ga.final_sets(state, k=3)
    order = np.argsort(f[0], kind="stable")[:3]
    np.testing.assert_array_equal(top.speed, np.asarray(state.evaluated.speed)[0, order])


@pytest.mark.slow
def test_compare_diversity_reports_both_tests():
    out = compare_diversity([0, 1], TINY, maze(), done={0: tiny_run(0)})
    assert out["single"]["robots"] == 8 and out["multi"]["populations"] == 2
    assert len(out["multi"]["diversity"]) == 2 and len(out["single"]["diversity"]) == 2
    assert all(0.0 <= d <= 1.0 for d in out["multi"]["diversity"] + out["single"]["diversity"])
    for test in ("welch_t", "mann_whitney_u"):
        p = out[test]["p_value"]
        assert p is None or 0.0 <= p <= 1.0
    with pytest.raises(ValueError):
        compare_diversity([0], TINY, maze())


@pytest.mark.slow
def test_rollout_programs_per_world(tmp_path):
    # With a constant world (the GA's way), the task loop bakes the world into its programs: a
    # world with the same shapes but other values must get programs of its own, and the same
    # world's values must reuse them. Otherwise both worlds share one program, the world an
    # argument.
    source = (Path(envs.__file__).parent / "worlds" / "ga_maze.toml").read_text()
    assert "start_region = [0.1, 0.08, 0.28, 0.3]" in source
    moved = tmp_path / "moved.toml"
    moved.write_text(source.replace("[0.1, 0.08, 0.28, 0.3]", "[1.6, 0.08, 1.75, 0.3]"))
    a, b = maze(), envs.load_world(moved)
    assert jax.tree.map(jnp.shape, a) == jax.tree.map(jnp.shape, b)

    params, config = envs.default_params(), EpisodeConfig(tau_cap=0.2)
    sets = sample_antibodies(jax.random.key(0), (2, 8))
    reset_keys = jax.random.split(jax.random.key(1), 2)
    run_keys = jax.random.split(jax.random.key(2), 2)

    def final_x(world, constant_world):
        batch = runner.rollout(
            reset_keys, run_keys, world, params, LTL, sets, config, None, constant_world
        )
        return np.asarray(batch.runs.sim.pose[:, 0])

    programs = runner._advance._cache_size
    before = programs()
    x_a, x_b = final_x(a, True), final_x(b, True)
    assert programs() == before + 2
    assert np.all(x_a < 0.5) and np.all(x_b > 1.5)  # each ran in its own world
    np.testing.assert_array_equal(final_x(maze(), True), x_a)  # the same values: no new program
    assert programs() == before + 2
    np.testing.assert_array_equal(final_x(a, False), x_a)
    np.testing.assert_array_equal(final_x(b, False), x_b)
    assert programs() == before + 3
