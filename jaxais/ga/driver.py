"""The GA's host side: evaluation in the maze (:func:`rollout`), generations (:func:`step`,
:func:`run`) with their checks, stop rules and the seed. Every key comes from ``state.key``, so
a run is a function of its initial key however it is split into calls or checkpoints.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.ga import core
from jaxais.ga.config import GAConfig
from jaxais.ga.core import Evaluation, GAState
from jaxais.ga.evaluation import raw_jit, start_keys, summarise_jit
from jaxais.ga.operators import Operators
from jaxais.immune.antibodies import Antibodies
from jaxais.immune.antigens import N_ANTIGENS
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


def rollout(
    keys: jax.Array,
    population: Antibodies,
    world: envs.World,
    sim_params: envs.SimParams,
    config: GAConfig,
) -> dict[str, np.ndarray]:
    """Every robot of ``population`` [P, R, 8] from every start key [S], in one batch of the task
    loop with the LTL controller (:func:`jaxais.ga.evaluation.raw_runs`, one program): NumPy
    [S, P, R] tau, collisions (float32, capped), finished (bool) and L [S, P, R, 8]."""
    episode = config.episode_config()
    raw = _raw(keys, population, world, sim_params, config)
    # Each start as a mean of one: the GA's τ and capped c, run by run.
    ev, _ = summarise_jit(jax.tree.map(lambda x: x[None], raw), episode, float(sim_params.dt))
    return {
        "tau": np.asarray(ev.tau),
        "collisions": np.asarray(ev.collisions),
        "finished": np.asarray(ev.crossings) > 0,
        "L": np.asarray(ev.L),
    }


def _raw(keys, sets, world, sim_params, config) -> dict[str, jax.Array]:
    """:func:`jaxais.ga.evaluation.raw_runs` of ``sets`` from the start ``keys`` [S], the world
    compiled in as constants (the GA's program, one per world, caps and batch shape)."""
    return raw_jit(keys, sets, world, sim_params, config.episode_config())


def evaluate(
    key: jax.Array,
    population: Antibodies,
    world: envs.World,
    sim_params: envs.SimParams,
    config: GAConfig,
) -> Evaluation:
    """Every robot of ``population`` [P, R, 8] from ``config.starts`` starts split from ``key``
    (or from the start keys [S] given), as means: ``make_evaluator(world, sim_params,
    config)(key, population)``'s numbers (:mod:`jaxais.ga.evaluation`)."""
    keys = start_keys(key, config.starts) if jnp.ndim(key) == 0 else key
    raw = _raw(keys, population, world, sim_params, config)
    return summarise_jit(raw, config.episode_config(), float(sim_params.dt))[0]


def measure(
    key: jax.Array,
    sets: Antibodies,
    world: envs.World,
    n_starts: int,
    sim_params: envs.SimParams | None = None,
    config: GAConfig | None = None,
    batch_starts: int | None = None,
) -> Evaluation:
    """The :class:`Evaluation` [K] of sets [K, 8] from ``n_starts`` fresh starts (``config``'s
    caps), in rollouts of at most ``batch_starts`` starts (the results do not depend on it):
    ``make_evaluator(world, sim_params, config, n_starts)(key, sets)``'s numbers."""
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
        jax.device_get(_raw(keys[i : i + chunk], population, world, sim_params, config))
        for i in range(0, n_starts, chunk)
    ]
    raw = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    ev, _ = summarise_jit(raw, config.episode_config(), float(sim_params.dt))
    return jax.tree.map(lambda x: x[:, 0], ev)


def crossing_key(seed: int) -> jax.Array:
    """Keys measuring the seed of GA run ``seed``, which that run never used (it only splits)."""
    return jax.random.fold_in(jax.random.key(seed), _CROSSING_STREAM)


def verify(
    key: jax.Array,
    state: GAState,
    world: envs.World,
    sim_params: envs.SimParams,
    config: GAConfig,
) -> GAState:
    """The success check: each population's best of the last generation runs from
    ``success_starts`` fresh starts (:func:`jaxais.ga.core.check`), so bests come from checks,
    never from the evaluation they were selected on (the winner's curse)."""
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
    """The success stop's confirmation: every best runs ``success_starts`` more fresh starts,
    pooled, so one lucky check does not end the run."""
    if config.success_starts < 1 or not np.all(np.asarray(state.best.starts) >= 1):
        raise ValueError("confirm needs success_starts >= 1 and a checked best everywhere")
    record = measure(key, state.best.antibodies, world, config.success_starts, sim_params, config)
    return core.pool_check(state, record)


def step(
    state: GAState,
    config: GAConfig,
    world: envs.World,
    sim_params: envs.SimParams,
    operators: Operators | None = None,
) -> tuple[GAState, Evaluation]:
    """One generation: evaluate, tell (breeding with ``operators``; default: ``config``'s, see
    :func:`jaxais.ga.operators.default_operators`), and with checks :func:`verify`,
    :func:`confirm` on success, the checked bests as elites. Returns (the next state, this
    evaluation)."""
    key, k_eval, k_tell, k_check, k_confirm = jax.random.split(state.key, 5)
    population, state = core.ask(k_eval, state.replace(key=key), config)  # (ask draws nothing)
    evaluation = evaluate(k_eval, population, world, sim_params, config)
    state = core.tell(k_tell, population, evaluation, state, config, operators)
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
    """Whether every best so far crossed in ``success_rate`` of its pooled check starts."""
    if config.success_rate is None or int(state.generation) == 0:
        return False
    starts = np.asarray(state.best.starts, np.int64)
    crossings = np.asarray(state.best.crossings, np.int64)
    # Counts, not float32 fractions: 7 of 10 meets a rate of 0.7 exactly (as core._passes).
    need = np.ceil(config.success_rate * starts - 1e-4)
    return bool(np.all(starts >= 1) and np.all(crossings >= need))


def stopped_by(state: GAState, config: GAConfig) -> str | None:
    """Why a run stops: ``"success"``, ``"target_f"``, ``"generations"`` (first first), or None."""
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
    operators: Operators | None = None,
) -> GAState:
    """Evolve from a key or a state until :func:`stopped_by`; ``callback(state, evaluation)``
    after every generation; ``progress``: a tqdm bar's description (None: no bar);
    ``operators``: the breeding operators (default: ``config``'s, see
    :func:`jaxais.ga.operators.default_operators`)."""
    from tqdm.auto import tqdm

    sim_params = envs.default_params() if sim_params is None else sim_params
    state = key_or_state if isinstance(key_or_state, GAState) else core.init(key_or_state, config)
    with tqdm(total=config.generations, initial=int(state.generation), desc=progress, unit="gen",
              file=sys.stderr, disable=progress is None) as bar:  # fmt: skip
        while stopped_by(state, config) is None:
            state, evaluation = step(state, config, world, sim_params, operators=operators)
            if callback is not None:
                callback(state, evaluation)
            f = np.asarray(evaluation.fitness)
            bar.set_postfix(best=f"{f.min():.1f}", mean=f"{f.mean():.1f}")
            bar.update(1)
    return state


def best_sets(state: GAState) -> Seed:
    """The LTL seed: each population's best with τ [P], c [P] (rounded) and L [P, 8] of its
    record, which eq (1) needs."""
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
    """The last generation's best set of each population [P, 8], or population 0's ``k`` best
    [k, 8], ascending f (NumPy)."""
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
