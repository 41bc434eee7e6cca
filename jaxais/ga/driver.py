"""The GA's host side: evaluation in the maze (:func:`rollout`, the one call into the task
loop), the generations (:func:`step`, :func:`run`) with their success checks, the stop rules and
the seed. Every key comes from ``state.key``, so a run is a pure function of its initial key
however it is split into calls or checkpoints.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.controllers import LTL
from jaxais.ga import core
from jaxais.ga.config import GAConfig
from jaxais.ga.core import Evaluation, GAState
from jaxais.immune.antibodies import Antibodies
from jaxais.immune.antigens import N_ANTIGENS
from jaxais.loop import FINISHED, fitness, outcome
from jaxais.runner import rollout as run_batch
from jaxais.seed import Seed

__all__ = [
    "best_sets",
    "confirm",
    "crossing_key",
    "evaluate",
    "final_sets",
    "measure",
    "reached_success",
    "reached_target",
    "rollout",
    "run",
    "start_keys",
    "step",
    "stopped_by",
    "verify",
]

_CROSSING_STREAM = 0x63726F73  # "cros", folded into a run's key by crossing_key


@jax.jit
def _rollout_inputs(keys: jax.Array, population: Antibodies):
    """(reset keys, run keys, sets) [S·n] of S starts of the P × R = n robots, ordered (start,
    population, robot); start s's keys are split from ``keys[s]`` alone."""
    S, n = keys.shape[0], population.shape[0] * population.shape[1]

    def one_start(key):
        k_reset, k_run = jax.random.split(key)
        return jax.random.split(k_reset, n), jax.random.split(k_run, n)

    reset, run = jax.vmap(one_start)(keys)
    flat = jax.tree.map(lambda x: jnp.concatenate([x.reshape(n, *x.shape[2:])] * S), population)
    return reset.reshape(S * n), run.reshape(S * n), flat


def rollout(
    keys: jax.Array,
    population: Antibodies,
    world: envs.World,
    sim_params: envs.SimParams,
    config: GAConfig,
    progress: Callable[[int], None] | None = None,
) -> dict[str, np.ndarray]:
    """Every robot of ``population`` [P, R, 8] from every start key [S], in one batch of the task
    loop with the LTL controller: NumPy [S, P, R] tau, collisions (float32, capped), finished
    (bool) and L [S, P, R, 8]."""
    S, (P, R) = keys.shape[0], population.shape[:2]
    episode = config.episode_config()
    reset_keys, run_keys, flat = _rollout_inputs(keys, population)
    # The world's walls are compiled in as constants (constant_world), which XLA folds: in
    # ga_maze the loop runs several times faster (docs/performance.md); its numbers differ in the
    # last bits from a run with the world an argument, so the GA always runs this way.
    args = (reset_keys, run_keys, world, sim_params, LTL, flat, episode, progress)
    batch = run_batch(*args, constant_world=True)
    out = outcome(batch.runs, episode, float(sim_params.dt))
    return {
        "tau": out["tau"].astype(np.float32).reshape(S, P, R),
        "collisions": out["collisions_capped"].astype(np.float32).reshape(S, P, R),
        "finished": (out["status"] == FINISHED).reshape(S, P, R),
        "L": np.asarray(batch.runs.ctrl.L, np.float32).reshape(S, P, R, N_ANTIGENS),
    }


def _summarise(runs: dict[str, np.ndarray]) -> Evaluation:
    """The :class:`Evaluation` of :func:`rollout`'s arrays: means over the starts (axis 0)."""

    def mean(x: np.ndarray) -> np.ndarray:
        return x.mean(axis=0, dtype=np.float64).astype(np.float32)

    tau, collisions = mean(runs["tau"]), mean(runs["collisions"])
    # f from exactly the stored τ and c, so (f, τ, c) agree wherever they are read back; f is
    # linear, so it is also the mean f.
    return Evaluation(
        fitness=np.asarray(fitness(tau, collisions), np.float32),
        tau=tau,
        collisions=collisions,
        L=mean(runs["L"]),
        crossings=runs["finished"].sum(axis=0).astype(np.int32),
        starts=int(runs["tau"].shape[0]),
    )


def start_keys(key: jax.Array, starts: int) -> jax.Array:
    """[starts] start keys ``jax.random.split(key, starts)``: start s of every robot comes from
    key s alone, so an evaluation is, robot by robot, the mean of one-start evaluations."""
    return jax.random.split(key, starts)


def evaluate(
    key: jax.Array,
    population: Antibodies,
    world: envs.World,
    sim_params: envs.SimParams,
    config: GAConfig,
    progress: Callable[[int], None] | None = None,
) -> Evaluation:
    """Every robot of ``population`` [P, R, 8] from ``config.starts`` random starts (means).

    ``key`` is split into ``config.starts`` start keys, or is an array [S] of start keys (S then
    overrides ``config.starts``). ``progress``: see :func:`jaxais.runner.rollout`.
    """
    keys = start_keys(key, config.starts) if jnp.ndim(key) == 0 else key
    return _summarise(rollout(keys, population, world, sim_params, config, progress))


def measure(
    key: jax.Array,
    sets: Antibodies,
    world: envs.World,
    n_starts: int,
    sim_params: envs.SimParams | None = None,
    config: GAConfig | None = None,
    batch_starts: int | None = None,
) -> Evaluation:
    """Each of K sets [K, 8] from ``n_starts`` fresh random starts (``config``'s caps, default
    :class:`GAConfig`'s), in rollouts of at most ``batch_starts`` starts per set (default all;
    the results do not depend on it). Returns an :class:`Evaluation` of [K] arrays."""
    if not (isinstance(n_starts, int | np.integer) and n_starts >= 1):
        raise ValueError(f"n_starts must be an integer >= 1, got {n_starts!r}")
    if len(sets.shape) != 2 or sets.shape[1] != N_ANTIGENS:
        raise ValueError(f"sets must have shape [K, {N_ANTIGENS}], got {sets.shape}")
    sim_params = envs.default_params() if sim_params is None else sim_params
    config = GAConfig() if config is None else config
    chunk = n_starts if batch_starts is None else max(1, int(batch_starts))
    keys = start_keys(key, n_starts)
    population = jax.tree.map(lambda x: jnp.asarray(x)[:, None], sets)  # [K, 1, 8]
    parts = [
        rollout(keys[i : i + chunk], population, world, sim_params, config)
        for i in range(0, n_starts, chunk)
    ]
    ev = _summarise({k: np.concatenate([p[k] for p in parts]) for k in parts[0]})
    return jax.tree.map(lambda x: x[:, 0], ev)


def crossing_key(seed: int) -> jax.Array:
    """Keys for measuring the seed of the GA run with PRNG seed ``seed``, none of which that run
    used: ``jax.random.fold_in(jax.random.key(seed), "cros")`` (the run splits its key only)."""
    return jax.random.fold_in(jax.random.key(seed), _CROSSING_STREAM)


def verify(
    key: jax.Array,
    state: GAState,
    world: envs.World,
    sim_params: envs.SimParams,
    config: GAConfig,
) -> GAState:
    """The success check: each population's best robot of the last generation (lowest f, the
    first on ties) runs from ``success_starts`` fresh starts, folded in by
    :func:`jaxais.ga.core.check`. A population's best so far thus comes from checks only, never
    from the noisy evaluation it was selected on (the winner's curse)."""
    if config.success_starts < 1 or int(state.generation) < 1:
        raise ValueError("verify needs success_starts >= 1 and an evaluated generation")
    _, sets = core.generation_best(state.evaluated, state.fitness)
    record = measure(key, sets, world, config.success_starts, sim_params, config)
    return core.check(state, record, config)


def confirm(
    key: jax.Array,
    state: GAState,
    world: envs.World,
    sim_params: envs.SimParams,
    config: GAConfig,
) -> GAState:
    """The success stop's confirmation: every best so far runs from ``success_starts`` further
    fresh starts, pooled into its record. A set must pass two independent checks, so one lucky
    check (a set crossing in 70 % passes 19 of 20 once in 130 tries) does not end the run."""
    if config.success_starts < 1 or not np.all(np.asarray(state.best.starts) >= 1):
        raise ValueError("confirm needs success_starts >= 1 and a checked best everywhere")
    record = measure(key, state.best.antibodies, world, config.success_starts, sim_params, config)
    return core.pool_check(state, record)


def step(
    state: GAState,
    config: GAConfig,
    world: envs.World,
    sim_params: envs.SimParams,
    progress: Callable[[int], None] | None = None,
) -> tuple[GAState, Evaluation]:
    """One generation: evaluate, tell; with ``success_starts`` >= 1 :func:`verify`,
    :func:`confirm` when the bests meet ``success_rate``, and (``elitism`` >= 1) each checked best
    becomes its population's elite. Returns (the next state, this evaluation)."""
    key, k_eval, k_tell, k_check, k_confirm = jax.random.split(state.key, 5)
    population, state = core.ask(k_eval, state.replace(key=key), config)  # (ask draws nothing)
    evaluation = evaluate(k_eval, population, world, sim_params, config, progress)
    state = core.tell(k_tell, population, evaluation, state, config)
    if config.success_starts:
        state = verify(k_check, state, world, sim_params, config)
        if reached_success(state, config):
            state = confirm(k_confirm, state, world, sim_params, config)
        if config.elitism >= 1:
            state = core.best_as_elite(state)
    return state, evaluation


def reached_target(state: GAState, config: GAConfig) -> bool:
    """Whether every population's best f so far is at or below ``target_f`` (False if None)."""
    if config.target_f is None or int(state.generation) == 0:
        return False
    return bool(np.all(np.asarray(state.best.fitness) <= config.target_f))


def reached_success(state: GAState, config: GAConfig) -> bool:
    """Whether every population's best so far crossed the maze in at least ``success_rate`` of
    its (pooled) check starts (False if ``success_rate`` is None or there is no best yet)."""
    if config.success_rate is None or int(state.generation) == 0:
        return False
    starts = np.asarray(state.best.starts, np.int64)
    crossings = np.asarray(state.best.crossings, np.int64)
    # Counts, not float32 fractions: 7 of 10 meets a rate of 0.7 exactly (as core._passes).
    need = np.ceil(config.success_rate * starts - 1e-4)
    return bool(np.all(starts >= 1) and np.all(crossings >= need))


def stopped_by(state: GAState, config: GAConfig) -> str | None:
    """Why a run in ``state`` stops: ``"success"``, ``"target_f"``, ``"generations"`` (in that
    order of precedence), or None while it goes on."""
    if reached_success(state, config):
        return "success"
    if reached_target(state, config):
        return "target_f"
    if int(state.generation) >= config.generations:
        return "generations"
    return None


def run(
    key_or_state: jax.Array | GAState,
    config: GAConfig,
    world: envs.World,
    sim_params: envs.SimParams | None = None,
    callback: Callable[[GAState, Evaluation], None] | None = None,
    progress: str | None = None,
) -> GAState:
    """Evolve from a typed PRNG key (a fresh run) or a state until :func:`stopped_by` is set.

    Args:
        callback: called after every generation with (new state, its evaluation), e.g. to save
            a checkpoint.
        progress: None, or the description of a tqdm bar of generations on stderr.
    """
    from tqdm import tqdm

    sim_params = envs.default_params() if sim_params is None else sim_params
    state = key_or_state if isinstance(key_or_state, GAState) else core.init(key_or_state, config)
    total, done = config.generations, int(state.generation)
    with tqdm(total=total, initial=done, desc=progress, unit="gen", file=sys.stderr,
              disable=progress is None) as bar:  # fmt: skip
        while stopped_by(state, config) is None:
            state, evaluation = step(state, config, world, sim_params)
            if callback is not None:
                callback(state, evaluation)
            f = np.asarray(evaluation.fitness)
            bar.set_postfix(best=f"{f.min():.1f}", mean=f"{f.mean():.1f}")
            bar.update(1)
    return state


def best_sets(state: GAState) -> Seed:
    """The LTL seed: each population's best so far, with τ [P], c [P] (rounded: the seed stores
    counts) and L [P, 8] of its record, which the STL's eq (1) needs measured for that set."""
    if int(state.generation) < 1 or not np.all(np.asarray(state.best.starts) >= 1):
        raise ValueError("best_sets: no generation has been evaluated yet")
    b = jax.tree.map(np.asarray, state.best)
    return Seed(
        antibodies=b.antibodies,
        tau=b.tau.astype(np.float32),
        collisions=np.rint(b.collisions).astype(np.int32),
        L=b.L.astype(np.float32),
    )


def final_sets(state: GAState, k: int | None = None) -> Antibodies:
    """Sets of the last evaluated generation (NumPy): with ``k`` None the best robot of each
    population [P, 8]; else the ``k`` best robots of population 0 [k, 8], ascending f."""
    if int(state.generation) < 1:
        raise ValueError("final_sets: no generation has been evaluated yet")
    f = np.asarray(state.fitness)
    sets = jax.tree.map(np.asarray, state.evaluated)
    if k is None:
        i = np.argmin(f, axis=1)
        return jax.tree.map(lambda x: x[np.arange(f.shape[0]), i], sets)
    if not 1 <= k <= f.shape[1]:
        raise ValueError(f"final_sets: k must be in [1, {f.shape[1]}], got {k}")
    order = np.argsort(f[0], kind="stable")[:k]
    return jax.tree.map(lambda x: x[0, order], sets)
