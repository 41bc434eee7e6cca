"""The GA core, pure and jitted, shaped like evosax: :func:`init`, :func:`ask`, :func:`tell`,
and the bests' updates by the success checks (:func:`check`, :func:`pool_check`,
:func:`best_as_elite`). LOWER fitness is better. The config and the breeding operators
(:mod:`jaxais.ga.operators`, passed in) are static arguments (one compile per pair); P
populations of R robots, each an antibody set [8].
"""

from __future__ import annotations

import functools
from typing import Final

import jax
import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass, static_field
from jaxais.ga.config import GAConfig
from jaxais.ga.operators import Operator, Operators, default_operators
from jaxais.immune.antibodies import Antibodies, sample_antibodies
from jaxais.immune.antigens import N_ANTIGENS
from jaxais.loop import fitness

__all__ = [
    "LOWER_IS_BETTER",
    "Best",
    "Evaluation",
    "GAState",
    "abstract_state",
    "ask",
    "best_as_elite",
    "check",
    "init",
    "next_generation",
    "pool_check",
    "tell",
]

LOWER_IS_BETTER: Final = True  # the GA minimises f = (ρc + τ)/2 (paper eq 11)
_jit = functools.partial(jax.jit, static_argnames="config")


@pytree_dataclass
class Evaluation:
    """Robots run from ``starts`` (static) starts each: float32 [...] means of τ and capped c, f
    of those, L [..., 8]; int32 [...] ``crossings``, the starts that finished within the cap."""

    fitness: jnp.ndarray
    tau: jnp.ndarray
    collisions: jnp.ndarray
    L: jnp.ndarray
    crossings: jnp.ndarray
    starts: int = static_field(default=1)

    @property
    def crossing_rate(self) -> np.ndarray:
        """[...] fraction of the starts in which each robot crossed the maze."""
        return np.asarray(self.crossings) / self.starts


@pytree_dataclass
class Best:
    """Each population's best robot so far: its set [P, 8], its evaluation's or pooled checks'
    record ([P]; L [P, 8]; starts 0 before any) and its first generation ([P], -1 before)."""

    antibodies: Antibodies
    fitness: jnp.ndarray
    tau: jnp.ndarray
    collisions: jnp.ndarray
    L: jnp.ndarray
    crossings: jnp.ndarray
    starts: jnp.ndarray
    generation: jnp.ndarray


@pytree_dataclass
class GAState:
    """Everything a GA run needs to continue (each checkpoint): ``population`` [P, R, 8] to
    evaluate as generation ``generation``; ``evaluated`` [P, R, 8] and its results [P, R] (f =
    inf before any); ``best``; ``key``, from which the driver splits every generation's keys."""

    population: Antibodies
    evaluated: Antibodies
    fitness: jnp.ndarray
    tau: jnp.ndarray
    collisions: jnp.ndarray
    L: jnp.ndarray
    crossings: jnp.ndarray
    best: Best
    generation: jnp.ndarray
    key: jax.Array


@_jit
def init(key: jax.Array, config: GAConfig) -> GAState:
    """Generation 0: random populations (SPEC 10), f = inf, no best yet."""
    P, R = config.populations, config.robots
    key, k_pop = jax.random.split(key)
    population = sample_antibodies(k_pop, (P, R, N_ANTIGENS))
    inf = jnp.full((P, R), jnp.inf, jnp.float32)
    results = {  # the last evaluation's fields, as GAState (and Best, per population) hold them
        "fitness": inf,
        "tau": inf,
        "collisions": jnp.zeros((P, R), jnp.float32),
        "L": jnp.zeros((P, R, N_ANTIGENS), jnp.float32),
        "crossings": jnp.zeros((P, R), jnp.int32),
    }
    best = Best(
        antibodies=jax.tree.map(lambda x: x[:, 0], population),
        **{name: x[:, 0] for name, x in results.items()},
        starts=jnp.zeros((P,), jnp.int32),
        generation=jnp.full((P,), -1, jnp.int32),
    )
    return GAState(
        population=population,
        evaluated=population,
        **results,
        best=best,
        generation=jnp.int32(0),
        key=key,
    )


def abstract_state(config: GAConfig) -> GAState:
    """Shapes and dtypes of a state for ``config`` (``jax.ShapeDtypeStruct`` leaves), no work."""
    return jax.eval_shape(functools.partial(init, config=config), jax.random.key(0))


def ask(key: jax.Array, state: GAState, config: GAConfig) -> tuple[Antibodies, GAState]:
    """The [P, R, 8] sets to evaluate next, and the state; draws nothing (:func:`tell` breeds,
    so a checkpoint holds the bred population)."""
    del key, config
    return state.population, state


def _check_shape(op: Operator, what: str, got: tuple[int, ...], want: tuple[int, ...]) -> None:
    """A one-line error naming the operator whose result has the wrong shape (at trace time)."""
    if tuple(got) != tuple(want):
        raise ValueError(f"{what} {op.name!r} returned shape {tuple(got)}, expected {want}")


def next_generation(
    key: jax.Array,
    population: Antibodies,
    evaluation: Evaluation,
    config: GAConfig,
    operators: Operators | None = None,
) -> Antibodies:
    """Breed every population [P, R, 8]: robots 0..elitism-1 are its best (ascending f, lowest
    index on ties), unchanged; the others are ``operators.mutation`` of ``operators.crossover``
    of two parents that ``operators.selection`` draws per population (default:
    :func:`~jaxais.ga.operators.default_operators` of ``config``: roulette, drawn independently,
    so a robot may mate with itself). Keys: ``split(key, 3)`` for the parents (split once per
    population), the crossover and the mutation."""
    ops = default_operators(config) if operators is None else operators
    evaluation = jax.tree.map(jnp.asarray, evaluation)
    P, R = population.shape[:2]
    n_elite, n_child = config.elitism, R - config.elitism
    k_parents, k_ties, k_mut = jax.random.split(key, 3)
    rows = jnp.arange(P)[:, None]
    order = jnp.argsort(evaluation.fitness, axis=1, stable=True)[:, :n_elite]  # [P, e]
    elites = jax.tree.map(lambda x: x[rows, order], population)

    def select(k: jax.Array, one: Evaluation) -> jnp.ndarray:  # one population's [2, n_child]
        drawn = ops.selection(k, one, 2 * n_child)
        _check_shape(ops.selection, "selection", jnp.shape(drawn), (2 * n_child,))
        return jnp.asarray(drawn, jnp.int32).reshape(2, n_child)

    parents = jax.vmap(select)(jax.random.split(k_parents, P), evaluation)  # [P, 2, n_child]
    pa, pb = parents[:, 0], parents[:, 1]
    pick = lambda tree, i: jax.tree.map(lambda x: x[rows, i], tree)  # [P, n_child, ...]
    children = ops.crossover(
        k_ties,
        pick(population, pa),
        pick(evaluation, pa),
        pick(population, pb),
        pick(evaluation, pb),
    )
    _check_shape(ops.crossover, "crossover", children.shape, (P, n_child, N_ANTIGENS))
    children = ops.mutation(k_mut, children)
    _check_shape(ops.mutation, "mutation", children.shape, (P, n_child, N_ANTIGENS))
    return jax.tree.map(lambda e, ch: jnp.concatenate([e, ch], axis=1), elites, children)


def _rows(x: jnp.ndarray, mask: jnp.ndarray) -> jnp.ndarray:
    """``mask`` [P] shaped to broadcast against ``x`` [P, ...]."""
    return mask.reshape((-1,) + (1,) * (x.ndim - 1))


def _record_best(
    best: Best, sets: Antibodies, record: Evaluation, generation: jnp.ndarray, better: jnp.ndarray
) -> Best:
    """``best`` with each population's entry replaced by ``record`` of ``sets`` ([P] arrays)
    where ``better`` [P]."""
    P = best.fitness.shape[0]

    def pick(new, old):
        return jnp.where(_rows(old, better), jnp.asarray(new, old.dtype), old)

    return Best(
        antibodies=jax.tree.map(pick, sets, best.antibodies),
        fitness=pick(record.fitness, best.fitness),
        tau=pick(record.tau, best.tau),
        collisions=pick(record.collisions, best.collisions),
        L=pick(record.L, best.L),
        crossings=pick(record.crossings, best.crossings),
        starts=pick(jnp.full((P,), record.starts, jnp.int32), best.starts),
        generation=pick(jnp.full((P,), generation, jnp.int32), best.generation),
    )


def generation_best(sets: Antibodies, f: jnp.ndarray) -> tuple[jnp.ndarray, Antibodies]:
    """Index [P] (the first on ties) and sets [P, 8] of each population's lowest f [P, R]."""
    i = jnp.argmin(f, axis=1)
    return i, jax.tree.map(lambda x: x[jnp.arange(f.shape[0]), i], sets)


@functools.partial(jax.jit, static_argnames=("config", "operators"))
def tell(
    key: jax.Array,
    population: Antibodies,
    evaluation: Evaluation,
    state: GAState,
    config: GAConfig,
    operators: Operators | None = None,
) -> GAState:
    """Record the evaluation [P, R] of ``population`` and breed the next generation with
    ``operators`` (static; default: :func:`~jaxais.ga.operators.default_operators` of
    ``config``), by :func:`next_generation`.

    Without checks (``success_starts`` = 0) a strictly lower f becomes the population's best;
    with checks the bests are left to :func:`check`. ``state.key`` is the driver's.
    """
    evaluation = jax.tree.map(jnp.asarray, evaluation)
    best = state.best
    if config.success_starts == 0:
        i, sets = generation_best(population, evaluation.fitness)
        record = jax.tree.map(lambda x: x[jnp.arange(i.shape[0]), i], evaluation)
        best = _record_best(best, sets, record, state.generation, record.fitness < best.fitness)
    return GAState(
        population=next_generation(key, population, evaluation, config, operators),
        evaluated=population,
        fitness=evaluation.fitness.astype(jnp.float32),
        tau=evaluation.tau.astype(jnp.float32),
        collisions=evaluation.collisions.astype(jnp.float32),
        L=evaluation.L.astype(jnp.float32),
        crossings=evaluation.crossings.astype(jnp.int32),
        best=best,
        generation=state.generation + 1,
        key=state.key,
    )


def _passes(crossings: jnp.ndarray, starts: jnp.ndarray, rate: float) -> jnp.ndarray:
    """Whether ``crossings`` of ``starts`` (>= 1) reach the fraction ``rate`` (counted, not
    compared as float32 fractions: 7 of 10 meets 0.7 exactly)."""
    need = jnp.ceil(rate * starts.astype(jnp.float32) - 1e-4)
    return (starts >= 1) & (crossings.astype(jnp.float32) >= need)


def _pool(best: Best, record: Evaluation) -> Best:
    """``best``'s record pooled with a further ``record`` [P] of the same sets: means weighted
    by starts, counts added, f recomputed from the pooled τ and c."""
    n0 = best.starts.astype(jnp.float32)
    n1 = jnp.float32(record.starts)
    n = n0 + n1

    def mean(a, b):
        w0, w1 = (n0 / n), (n1 / n)
        if a.ndim > 1:
            w0, w1 = w0[:, None], w1[:, None]
        return (w0 * a + w1 * jnp.asarray(b, jnp.float32)).astype(jnp.float32)

    tau, collisions = mean(best.tau, record.tau), mean(best.collisions, record.collisions)
    return best.replace(
        fitness=fitness(tau, collisions).astype(jnp.float32),
        tau=tau,
        collisions=collisions,
        L=mean(best.L, record.L),
        crossings=best.crossings + jnp.asarray(record.crossings, jnp.int32),
        starts=best.starts + jnp.int32(record.starts),
    )


@_jit
def check(state: GAState, record: Evaluation, config: GAConfig) -> GAState:
    """Fold the success check ``record`` [P] of each population's generation best into the
    bests: pooled where it is the best's own set (so a set that stays best is measured ever more
    precisely), else a replacement where it ranks higher: a set that meets ``success_rate``
    ranks above one that does not, then the strictly lower f wins."""
    _, sets = generation_best(state.evaluated, state.fitness)
    best = state.best
    same = best.starts >= 1
    for a, b in zip(jax.tree.leaves(sets), jax.tree.leaves(best.antibodies), strict=True):
        same = same & jnp.all(a == b, axis=-1)
    # Without a success rate, 2 never passes: plain f decides.
    rate = jnp.float32(2.0 if config.success_rate is None else config.success_rate)
    n_record = jnp.full_like(best.starts, record.starts)
    new_pass = _passes(jnp.asarray(record.crossings), n_record, rate)
    old_pass = _passes(best.crossings, best.starts, rate)
    better = (new_pass & ~old_pass) | ((new_pass == old_pass) & (record.fitness < best.fitness))
    replaced = _record_best(best, sets, record, state.generation - 1, better)
    pooled = _pool(best, record)
    return state.replace(
        best=jax.tree.map(lambda a, b: jnp.where(_rows(a, same), a, b), pooled, replaced)
    )


@jax.jit
def pool_check(state: GAState, record: Evaluation) -> GAState:
    """The confirmation ``record`` [P] of every best so far, pooled into its record."""
    return state.replace(best=_pool(state.best, record))


@jax.jit
def best_as_elite(state: GAState) -> GAState:
    """Each population's robot 0 (its elite) replaced by its checked best so far: one unlucky
    evaluation would lose a good set (bests crossing 36 of 40 checks fell under 10 %)."""
    checked = state.best.starts >= 1  # [P]

    def put(pop: jnp.ndarray, best: jnp.ndarray) -> jnp.ndarray:
        return pop.at[:, 0].set(jnp.where(_rows(best, checked), best, pop[:, 0]))

    return state.replace(population=jax.tree.map(put, state.population, state.best.antibodies))
