"""The LTL genetic algorithm (SPEC 10), shaped like evosax: ``init`` / ``evaluate`` / ``tell``.

**Fitness sign: LOWER fitness is better** (:data:`LOWER_IS_BETTER`). A robot's fitness is the
paper's f = (ρc + τ)/2 (eq 11, :func:`jaxais.episode.fitness`); selection, elitism and every
"best" in this module minimise it.

One generation:

1. :func:`evaluate`: every robot of every population (P × R antibody sets) runs the ``ga_maze``
   task once, all in ONE vmapped :func:`jaxais.episode.rollout` with the LTL controller (RL on,
   no idiotypic selection; each robot gets a fresh random start pose), giving τ, c, f and the
   final cumulative RL scores L [8] of each robot.
2. :func:`tell` (pure, jit-compiled, fixed shapes): record the evaluation and the best robot of
   each population so far, then breed the next generation inside each population: the
   ``elitism`` best robots survive unchanged; every other child has two parents drawn by roulette
   on 1/(τ + ρc), takes for each antigen the antibody of the parent with the higher L (ties at
   random), and is mutated with :func:`jaxais.antibodies.mutate`.

The PRNG key lives in :class:`GAState`, so a run restored from a checkpoint continues exactly as
an uninterrupted one. :func:`run` loops until ``generations`` generations have been evaluated or
every population's best f is at or below ``target_f``.

Decisions where SPEC 10 is silent [ours]:

- The seed (:func:`best_sets`) holds each population's best robot over the WHOLE run (lowest f
  of any single evaluation; the earliest on ties), with the τ, c and L of that evaluation. With
  elitism the best set is re-evaluated every generation from a new start pose, so the final
  generation's best can be worse than one already seen; the STL's eq (1) needs τ_i and c_i that
  were actually measured for the set it receives.
- Both parents are drawn independently (with replacement; a robot may mate with itself, giving a
  clone before mutation). Crossover is always applied (no crossover rate).
- Elites keep their slot order: the best robot of each population becomes robot 0 of the next
  generation, the second best robot 1, ...
- Diversity (:func:`diversity`, :func:`compare_diversity`) compares final generations: the best
  robot of each of the 5 populations against the 5 best robots of one population of 50.

Known effect of SPEC 10 as written: L is cumulative over a run, so a robot that wanders until the
time cap can out-score a quick finisher on some antigens, and crossover then takes its antibodies.
"""

from __future__ import annotations

import contextlib
import functools
import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any, Final

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.antibodies import Antibodies, antibody_distance, mutate, sample_antibodies
from jaxais.antigens import N_ANTIGENS
from jaxais.controllers import LTL
from jaxais.envs.struct import pytree_dataclass
from jaxais.episode import RHO, EpisodeConfig, fitness, outcome, rollout
from jaxais.seed import Seed

__all__ = [
    "LOWER_IS_BETTER",
    "Best",
    "ConfigError",
    "Evaluation",
    "GAConfig",
    "GAState",
    "abstract_state",
    "best_sets",
    "compare_diversity",
    "crossover",
    "diversity",
    "evaluate",
    "final_sets",
    "init",
    "is_done",
    "next_generation",
    "reached_target",
    "roulette",
    "run",
    "selection_weights",
    "step",
    "tell",
]

LOWER_IS_BETTER: Final = True
"""The GA minimises f = (ρc + τ)/2 (paper eq 11): a lower fitness is a better robot."""


class ConfigError(ValueError):
    """A GA setting is out of range (one-line message; ``field`` names the setting)."""

    def __init__(self, field: str, message: str):
        super().__init__(f"{field} {message}")
        self.field = field
        self.reason = message


def _is_int(value: Any) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def _is_real(value: Any) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


@dataclass(frozen=True)
class GAConfig:
    """Static settings of a GA run (they fix array shapes and the loop length).

    Attributes:
        populations: independent populations P [paper: 5].
        robots: robots (antibody sets) per population R [paper: 10].
        generations: generations G to evaluate [ours: 30].
        mutation: per-gene mutation probability [paper: 0.05].
        elitism: robots of each population copied unchanged into the next generation [ours: 1].
        target_f: stop early once every population's best f is at or below it (None: never).
        tau_cap: time cap of one evaluation, simulated s [ours: 500].
        collision_cap: collision cap of one evaluation [ours: 100].
    """

    populations: int = 5
    robots: int = 10
    generations: int = 30
    mutation: float = 0.05
    elitism: int = 1
    target_f: float | None = None
    tau_cap: float = 500.0
    collision_cap: int = 100

    def __post_init__(self):
        def need(ok: bool, field: str, what: str) -> None:
            if not ok:
                raise ConfigError(field, f"must be {what}, got {getattr(self, field)!r}")

        need(_is_int(self.populations) and self.populations >= 1, "populations", "an integer >= 1")
        need(_is_int(self.robots) and self.robots >= 2, "robots", "an integer >= 2")
        need(_is_int(self.generations) and self.generations >= 1, "generations", "an integer >= 1")
        need(
            _is_real(self.mutation) and 0.0 <= self.mutation <= 1.0,
            "mutation",
            "a probability in [0, 1]",
        )
        need(
            _is_int(self.elitism) and 0 <= self.elitism < self.robots,
            "elitism",
            f"an integer in [0, robots - 1] = [0, {self.robots - 1}]",
        )
        need(
            self.target_f is None
            or (_is_real(self.target_f) and math.isfinite(self.target_f) and self.target_f >= 0),
            "target_f",
            "None or a finite number >= 0",
        )
        need(
            _is_real(self.tau_cap) and math.isfinite(self.tau_cap) and self.tau_cap > 0,
            "tau_cap",
            "a finite number > 0",
        )
        need(
            _is_int(self.collision_cap) and self.collision_cap >= 1,
            "collision_cap",
            "an integer >= 1",
        )

    def episode_config(self) -> EpisodeConfig:
        """The task loop's settings of one evaluation (the LTL caps)."""
        return EpisodeConfig(tau_cap=float(self.tau_cap), collision_cap=int(self.collision_cap))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able values."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GAConfig:
        """Inverse of :meth:`to_dict` (unknown keys are an error)."""
        names = {f.name for f in fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"unknown GA setting {sorted(unknown)[0]!r}")
        return cls(**d)


@pytree_dataclass
class Evaluation:
    """One generation's results.

    Attributes:
        fitness: [P, R] f = (ρc + τ)/2, lower is better.
        tau: [P, R] task time, s (the cap for a failed run).
        collisions: [P, R] int32 collisions (capped).
        L: [P, R, 8] each antibody's cumulative RL score at the end of the run.
        status: [P, R] int32 why the run ended (``jaxais.episode.FINISHED``, ...).
    """

    fitness: jnp.ndarray
    tau: jnp.ndarray
    collisions: jnp.ndarray
    L: jnp.ndarray
    status: jnp.ndarray


@pytree_dataclass
class Best:
    """The best robot of each population so far (lowest f of any single evaluation).

    Attributes:
        antibodies: [P, 8] its set. fitness, tau: [P]. collisions: [P] int32. L: [P, 8].
        generation: [P] int32 the generation of that evaluation (-1 before any).
    """

    antibodies: Antibodies
    fitness: jnp.ndarray
    tau: jnp.ndarray
    collisions: jnp.ndarray
    L: jnp.ndarray
    generation: jnp.ndarray


@pytree_dataclass
class GAState:
    """Everything a GA run needs to continue (saved in every checkpoint).

    Attributes:
        population: [P, R, 8] the sets of generation ``generation``, still to be evaluated.
        evaluated: [P, R, 8] the sets of the last evaluated generation, which ``fitness``,
            ``tau``, ``collisions``, ``L`` and ``status`` describe (before any evaluation: the
            initial population, with f = inf).
        fitness, tau: [P, R] float32. collisions, status: [P, R] int32. L: [P, R, 8] float32.
        best: each population's best robot so far.
        generation: int32 scalar, generations evaluated so far.
        key: typed PRNG key; every random draw of the run comes from it.
    """

    population: Antibodies
    evaluated: Antibodies
    fitness: jnp.ndarray
    tau: jnp.ndarray
    collisions: jnp.ndarray
    L: jnp.ndarray
    status: jnp.ndarray
    best: Best
    generation: jnp.ndarray
    key: jax.Array


def _init(key: jax.Array, P: int, R: int) -> GAState:
    key, k_pop = jax.random.split(key)
    population = sample_antibodies(k_pop, (P, R, N_ANTIGENS))
    inf = jnp.full((P, R), jnp.inf, jnp.float32)
    return GAState(
        population=population,
        evaluated=population,
        fitness=inf,
        tau=inf,
        collisions=jnp.zeros((P, R), jnp.int32),
        L=jnp.zeros((P, R, N_ANTIGENS), jnp.float32),
        status=jnp.zeros((P, R), jnp.int32),
        best=Best(
            antibodies=jax.tree.map(lambda x: x[:, 0], population),
            fitness=jnp.full((P,), jnp.inf, jnp.float32),
            tau=jnp.full((P,), jnp.inf, jnp.float32),
            collisions=jnp.zeros((P,), jnp.int32),
            L=jnp.zeros((P, N_ANTIGENS), jnp.float32),
            generation=jnp.full((P,), -1, jnp.int32),
        ),
        generation=jnp.int32(0),
        key=key,
    )


# Breeding and set-up do little work: compiled for compile speed (envs.jit's quick_compile).
_init_jit = envs.jit(_init, quick_compile=True, static_argnums=(1, 2))


def init(key: jax.Array, config: GAConfig) -> GAState:
    """A run before its first evaluation: random initial populations (SPEC 10).

    Jit-compiled (one small program instead of dozens of eager ones).

    Args:
        key: typed PRNG key of the whole run.
        config: the settings (``populations`` and ``robots`` fix the shapes).

    Returns:
        The state at generation 0 (fitness inf, no best yet).
    """
    return _init_jit(key, config.populations, config.robots)


def abstract_state(config: GAConfig) -> GAState:
    """Shapes and dtypes of a state for ``config`` (``jax.ShapeDtypeStruct`` leaves), no work."""
    return jax.eval_shape(lambda k: _init(k, config.populations, config.robots), jax.random.key(0))


# ------------------------------------------------------------------------------- evaluation

_COMPILED: dict = {}
"""Compiled rollout programs shared by every call (one per batch size, world and caps)."""


@functools.partial(envs.jit, quick_compile=True)
def _rollout_inputs(key: jax.Array, population: Antibodies):
    """(reset keys [n], run keys [n], sets [n, 8]) of the P × R = n robots, in row-major order."""
    n = population.shape[0] * population.shape[1]
    k_reset, k_run = jax.random.split(key)
    flat = jax.tree.map(lambda x: jnp.reshape(x, (n, *x.shape[2:])), population)
    return jax.random.split(k_reset, n), jax.random.split(k_run, n), flat


def evaluate(
    key: jax.Array,
    population: Antibodies,
    world: envs.World,
    sim_params: envs.SimParams,
    config: GAConfig,
    progress: Callable[[int], None] | None = None,
) -> Evaluation:
    """Run every robot of every population once, as one vmapped rollout.

    Args:
        key: typed PRNG key of this generation's evaluation (start poses and run noise).
        population: [P, R, 8] antibody sets.
        world: the LTL world (``ga_maze``).
        sim_params: simulator constants.
        config: caps (``tau_cap``, ``collision_cap``).
        progress: called with simulated iterations done (see :func:`jaxais.episode.rollout`).

    Returns:
        The :class:`Evaluation`, arrays on the host as float32 / int32.
    """
    P, R = population.shape[:2]
    reset_keys, run_keys, flat = _rollout_inputs(key, population)
    episode = config.episode_config()
    batch = rollout(
        reset_keys,
        run_keys,
        world,
        sim_params,
        LTL,
        flat,
        episode,
        progress=progress,
        compiled=_COMPILED,
        # The maze's 16 fixed walls fold into the program: about 2.7x faster (compile_rollout).
        specialise=True,
    )
    out = outcome(batch.runs, episode, float(sim_params.dt))
    # τ and c are stored in float32 / int32; f is recomputed from exactly those values so that
    # (f, τ, c) stay consistent wherever they are read back (checkpoint, seed, summary).
    tau = out["tau"].astype(np.float32).reshape(P, R)
    collisions = out["collisions"].astype(np.int32).reshape(P, R)
    return Evaluation(
        fitness=np.asarray(fitness(tau, collisions.astype(np.float32)), np.float32),
        tau=tau,
        collisions=collisions,
        L=np.asarray(batch.runs.ctrl.L, np.float32).reshape(P, R, N_ANTIGENS),
        status=out["status"].astype(np.int32).reshape(P, R),
    )


# ------------------------------------------------------------------------------- breeding


def selection_weights(tau: jnp.ndarray, collisions: jnp.ndarray, rho: float = RHO) -> jnp.ndarray:
    """Roulette weights 1/(τ + ρc) (SPEC 10), unnormalised.

    The floor only guards a zero denominator (a run cannot finish at τ = 0 without collisions).

    Args:
        tau, collisions: [...] the robots' results.

    Returns:
        [...] float32 weights.
    """
    cost = jnp.asarray(tau, jnp.float32) + rho * jnp.asarray(collisions, jnp.float32)
    return 1.0 / jnp.maximum(cost, 1e-6)


def roulette(key: jax.Array, weights: jnp.ndarray, n: int) -> jnp.ndarray:
    """Draw ``n`` indices with probability proportional to ``weights`` (with replacement).

    Args:
        key: typed PRNG key.
        weights: [R] non-negative weights, not all 0.
        n: draws.

    Returns:
        [n] int32 indices into ``weights``.
    """
    return _roulette(jax.random.uniform(key, (n,)), weights)


def _roulette(u: jnp.ndarray, weights: jnp.ndarray) -> jnp.ndarray:
    """:func:`roulette` from uniforms ``u`` [...] in [0, 1)."""
    cdf = jnp.cumsum(weights)
    # side="right": u falls in [cdf[i-1], cdf[i]) -> i, so a zero-weight robot is never drawn.
    idx = jnp.searchsorted(cdf, u * cdf[-1], side="right")
    return jnp.minimum(idx, weights.shape[0] - 1).astype(jnp.int32)


def crossover(
    key: jax.Array, a: Antibodies, La: jnp.ndarray, b: Antibodies, Lb: jnp.ndarray
) -> Antibodies:
    """RL-assisted crossover of two sets (SPEC 10).

    For each antigen j the child takes the antibody of the parent with the higher L_j; on a
    tie, either parent's with probability 1/2.

    Args:
        key: typed PRNG key (tie-breaks).
        a, b: [8] the parents' sets. La, Lb: [8] their cumulative RL scores.

    Returns:
        [8] the child's set.
    """
    return _crossover(jax.random.uniform(key, La.shape), a, La, b, Lb)


def _crossover(
    u: jnp.ndarray, a: Antibodies, La: jnp.ndarray, b: Antibodies, Lb: jnp.ndarray
) -> Antibodies:
    """:func:`crossover` with tie-break uniforms ``u`` (shape of ``La``); any batch shape."""
    from_a = (La > Lb) | ((La == Lb) & (u < 0.5))
    return jax.tree.map(lambda x, y: jnp.where(from_a, x, y), a, b)


def next_generation(
    key: jax.Array,
    population: Antibodies,
    evaluation: Evaluation,
    config: GAConfig,
) -> Antibodies:
    """Breed the next generation of every population (selection, crossover, mutation, elitism).

    Args:
        key: typed PRNG key.
        population: [P, R, 8] the evaluated sets.
        evaluation: their results.
        config: ``elitism`` and ``mutation``.

    Returns:
        [P, R, 8]: robots 0..elitism-1 of each population are its best robots (ascending f,
        lowest index first on ties), unchanged; the others are mutated children.
    """
    return _breed(key, population, evaluation, config.elitism, config.mutation)


def _breed(
    key: jax.Array,
    population: Antibodies,
    evaluation: Evaluation,
    elitism: int,
    mutation: float | jnp.ndarray,
) -> Antibodies:
    """:func:`next_generation` with the mutation rate as a (traceable) number."""
    P, R = population.shape[:2]
    n_elite, n_child = elitism, R - elitism
    k_u, k_mut = jax.random.split(key)
    # One draw for all roulette spins and crossover tie-breaks: every random primitive costs
    # compile time on CPU, which dominates this small program (cf. antibodies._uniform).
    u = jax.random.uniform(k_u, (P * n_child * (2 + N_ANTIGENS),))
    u = u.reshape(P, n_child, 2 + N_ANTIGENS)
    rows = jnp.arange(P)[:, None]

    # Stable sort: among equal f the lowest index is the elite (deterministic).
    order = jnp.argsort(evaluation.fitness, axis=1, stable=True)[:, :n_elite]  # [P, e]
    elites = jax.tree.map(lambda x: x[rows, order], population)
    weights = selection_weights(evaluation.tau, evaluation.collisions)  # [P, R]
    parents = jax.vmap(_roulette)(u[..., :2], weights)  # [P, n_child, 2]
    pa, pb = parents[..., 0], parents[..., 1]
    children = _crossover(
        u[..., 2:],
        jax.tree.map(lambda x: x[rows, pa], population),
        evaluation.L[rows, pa],
        jax.tree.map(lambda x: x[rows, pb], population),
        evaluation.L[rows, pb],
    )
    children = mutate(k_mut, children, mutation)
    nxt = jax.tree.map(lambda e, ch: jnp.concatenate([e, ch], axis=1), elites, children)
    assert nxt.shape == (P, R, N_ANTIGENS)
    return nxt


def _tell(
    key: jax.Array,
    state: GAState,
    evaluation: Evaluation,
    elitism: int,
    mutation: float | jnp.ndarray,
) -> GAState:
    evaluation = jax.tree.map(jnp.asarray, evaluation)
    P = state.population.shape[0]
    rows = jnp.arange(P)
    i = jnp.argmin(evaluation.fitness, axis=1)  # first index on ties
    f_gen = evaluation.fitness[rows, i]
    # Strictly better only: the earliest of equally good evaluations stays the best.
    better = f_gen < state.best.fitness

    def pick(new, old):
        mask = better.reshape((P,) + (1,) * (old.ndim - 1))
        return jnp.where(mask, new, old)

    best = Best(
        antibodies=jax.tree.map(
            lambda x, o: pick(x[rows, i], o), state.population, state.best.antibodies
        ),
        fitness=pick(f_gen, state.best.fitness),
        tau=pick(evaluation.tau[rows, i], state.best.tau),
        collisions=pick(evaluation.collisions[rows, i], state.best.collisions),
        L=pick(evaluation.L[rows, i], state.best.L),
        generation=pick(jnp.full((P,), state.generation), state.best.generation),
    )
    return GAState(
        population=_breed(key, state.population, evaluation, elitism, mutation),
        evaluated=state.population,
        fitness=evaluation.fitness.astype(jnp.float32),
        tau=evaluation.tau.astype(jnp.float32),
        collisions=evaluation.collisions.astype(jnp.int32),
        L=evaluation.L.astype(jnp.float32),
        status=evaluation.status.astype(jnp.int32),
        best=best,
        generation=state.generation + 1,
        key=state.key,
    )


# The mutation rate is traced, so configs that differ only in it share one compiled program.
_tell_jit = envs.jit(_tell, quick_compile=True, static_argnames="elitism")


def tell(key: jax.Array, state: GAState, evaluation: Evaluation, config: GAConfig) -> GAState:
    """Record ``evaluation`` (of ``state.population``) and breed the next generation.

    Updates each population's best robot so far (strictly lower f only, so the earliest of
    equal evaluations stays), breeds with :func:`next_generation` and advances ``generation``.
    Pure and jit-compiled (fixed shapes); ``state.key`` is passed through unchanged
    (:func:`step` advances it).

    Args:
        key: typed PRNG key of the breeding.
        state: the state whose ``population`` was evaluated.
        evaluation: its results ([P, R] arrays, see :class:`Evaluation`).
        config: ``elitism`` and ``mutation``.

    Returns:
        The state of the next generation.
    """
    warming = _TELL_WARMING.get(_tell_signature(state, config))
    if warming is not None:
        warming.join()
    return _tell_jit(key, state, evaluation, config.elitism, float(config.mutation))


_TELL_WARMING: dict[tuple, threading.Thread] = {}
"""Background compilations of :func:`tell`'s program, one per signature (:func:`_warm_tell`)."""


def _tell_signature(state: GAState, config: GAConfig) -> tuple:
    return (state.population.shape[:2], config.elitism)


def _warm_tell(key: jax.Array, state: GAState, config: GAConfig) -> None:
    """Start compiling :func:`tell`'s program in a background thread, once per signature.

    Breeding is first needed after the first evaluation; compiling it meanwhile (XLA compiles
    outside Python's lock) takes its compilation off a run's critical path. The program lands in
    JAX's compilation cache, where :func:`tell`'s call finds it.
    """
    signature = _tell_signature(state, config)
    if signature in _TELL_WARMING:
        return
    P, R = signature[0]
    f32, i32 = jnp.float32, jnp.int32
    evaluation = Evaluation(
        fitness=jax.ShapeDtypeStruct((P, R), f32),
        tau=jax.ShapeDtypeStruct((P, R), f32),
        collisions=jax.ShapeDtypeStruct((P, R), i32),
        L=jax.ShapeDtypeStruct((P, R, N_ANTIGENS), f32),
        status=jax.ShapeDtypeStruct((P, R), i32),
    )

    def compile_tell() -> None:
        # Any failure here shows up again, with its message, in tell's own call.
        with contextlib.suppress(Exception):
            rate = float(config.mutation)
            _tell_jit.lower(key, state, evaluation, config.elitism, rate).compile()

    thread = threading.Thread(target=compile_tell, name="jaxais-compile-tell", daemon=True)
    _TELL_WARMING[signature] = thread
    thread.start()


def step(
    state: GAState,
    config: GAConfig,
    world: envs.World,
    sim_params: envs.SimParams,
    progress: Callable[[int], None] | None = None,
) -> tuple[GAState, Evaluation]:
    """One generation: evaluate ``state.population``, then :func:`tell`.

    The generation's keys come from ``state.key``, which is advanced, so a run is a pure function
    of its initial key however it is split into calls (or checkpoints).

    Returns:
        (the next state, this generation's evaluation).
    """
    key, k_eval, k_tell = jax.random.split(state.key, 3)
    _warm_tell(k_tell, state, config)
    evaluation = evaluate(k_eval, state.population, world, sim_params, config, progress)
    return tell(k_tell, state.replace(key=key), evaluation, config), evaluation


def is_done(state: GAState, config: GAConfig) -> bool:
    """Whether the run should stop: ``generations`` evaluated, or every best f <= target_f."""
    if int(state.generation) >= config.generations:
        return True
    return reached_target(state, config)


def reached_target(state: GAState, config: GAConfig) -> bool:
    """Whether every population's best f so far is at or below ``target_f`` (False if None)."""
    if config.target_f is None or int(state.generation) == 0:
        return False
    return bool(np.all(np.asarray(state.best.fitness) <= config.target_f))


def run(
    key_or_state: jax.Array | GAState,
    config: GAConfig,
    world: envs.World,
    sim_params: envs.SimParams | None = None,
    callback: Callable[[GAState, Evaluation], None] | None = None,
) -> GAState:
    """Evolve until :func:`is_done`.

    Args:
        key_or_state: a typed PRNG key (a fresh run) or a state to continue.
        config: the settings.
        world: the LTL world.
        sim_params: simulator constants (default :func:`jaxais.envs.default_params`).
        callback: called after every generation with (new state, its evaluation), e.g. to
            save a checkpoint or update a progress bar.

    Returns:
        The final state.
    """
    sim_params = envs.default_params() if sim_params is None else sim_params
    state = key_or_state if isinstance(key_or_state, GAState) else init(key_or_state, config)
    while not is_done(state, config):
        state, evaluation = step(state, config, world, sim_params)
        if callback is not None:
            callback(state, evaluation)
    return state


def best_sets(state: GAState) -> Seed:
    """The LTL seed: each population's best robot over the whole run (see the module notes).

    Returns:
        :class:`jaxais.seed.Seed` with P sets [P, 8], τ [P], c [P] and L [P, 8] (NumPy).

    Raises:
        ValueError: no generation has been evaluated yet.
    """
    if int(state.generation) < 1:
        raise ValueError("best_sets: no generation has been evaluated yet")
    b = jax.tree.map(np.asarray, state.best)
    return Seed(
        antibodies=b.antibodies,
        tau=b.tau.astype(np.float32),
        collisions=b.collisions.astype(np.int32),
        L=b.L.astype(np.float32),
    )


# ------------------------------------------------------------------------------- diversity


def diversity(sets: Antibodies) -> float:
    """Mean pairwise distance between sets (SPEC 10 [ours]).

    For every pair of sets (i < k) and every antigen j, :func:`jaxais.antibodies.antibody_distance`
    between A_ij and A_kj (1 for different types, else the mean normalised attribute
    difference); the result is the mean over all pairs and antigens, in [0, 1].

    Args:
        sets: [K, 8] antibody sets, K >= 2.

    Returns:
        The diversity as a Python float.
    """
    K = sets.shape[0]
    if len(sets.shape) != 2 or K < 2:
        raise ValueError(f"diversity needs [K >= 2, {N_ANTIGENS}] sets, got {sets.shape}")
    d = np.asarray(_set_distances(sets), np.float64).mean(axis=-1)  # [K, K]
    return float(d[np.triu_indices(K, k=1)].mean())


@envs.jit
def _set_distances(sets: Antibodies) -> jnp.ndarray:
    """[K, K, 8] antibody distances between every pair of sets, per antigen."""
    a = jax.tree.map(lambda x: jnp.asarray(x)[:, None, :], sets)
    b = jax.tree.map(lambda x: jnp.asarray(x)[None, :, :], sets)
    return antibody_distance(a, b)


def final_sets(state: GAState, k: int | None = None) -> Antibodies:
    """Sets of the last evaluated generation, for the diversity comparison.

    Args:
        state: a state after at least one generation.
        k: None for the best robot of each population ([P, 8]); an int for the ``k`` best robots
            of population 0 (a single-population run), ascending f.

    Returns:
        [P, 8] or [k, 8] antibody sets (NumPy).
    """
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


def compare_diversity(
    seeds: Sequence[int],
    config: GAConfig,
    world: envs.World,
    sim_params: envs.SimParams | None = None,
    done: Mapping[int, GAState] | None = None,
    on_run: Callable[[str, int], None] | None = None,
) -> dict[str, Any]:
    """Diversity of P independent populations of R against one population of P × R (SPEC 10).

    For each GA seed, two runs with otherwise equal settings: ``config`` (P populations of R;
    its sets are the best robot of each population in the final generation) and one population
    of P × R robots (its sets are the P best robots of the final generation). The two samples
    of :func:`diversity` values are compared with Welch's t-test and the Mann-Whitney U test
    (both two-sided, scipy).

    Args:
        seeds: GA seeds (>= 2 for a test); the run with seed s starts from ``jax.random.key(s)``.
        config: the multi-population settings (P >= 2).
        world: the LTL world.
        sim_params: simulator constants.
        done: finished multi-population states by seed, reused instead of re-running.
        on_run: called after each run with ("multi" or "single", seed), e.g. for progress.

    Returns:
        A JSON-able dict: the settings, per-seed diversities of both arms, their means, and
        the statistics and p-values of both tests (None where undefined, e.g. zero variance).
    """
    from scipy import stats

    if config.populations < 2:
        raise ValueError("compare_diversity: the multi-population arm needs populations >= 2")
    if len(set(seeds)) != len(seeds) or len(seeds) < 2:
        raise ValueError("compare_diversity: give at least 2 distinct seeds")
    sim_params = envs.default_params() if sim_params is None else sim_params
    single = GAConfig(
        **{**config.to_dict(), "populations": 1, "robots": config.populations * config.robots}
    )
    done = done or {}
    multi_values, single_values = [], []
    for s in seeds:
        if s in done:
            state = done[s]
        else:
            state = run(jax.random.key(s), config, world, sim_params)
            if on_run is not None:
                on_run("multi", s)
        multi_values.append(diversity(final_sets(state)))
        state = run(jax.random.key(s), single, world, sim_params)
        if on_run is not None:
            on_run("single", s)
        single_values.append(diversity(final_sets(state, k=config.populations)))

    def finite(x: float) -> float | None:
        return float(x) if math.isfinite(float(x)) else None

    with np.errstate(all="ignore"):
        t = stats.ttest_ind(multi_values, single_values, equal_var=False)
    try:
        u = stats.mannwhitneyu(multi_values, single_values, alternative="two-sided")
        u_stat, u_p = finite(u.statistic), finite(u.pvalue)
    except ValueError:  # all values identical
        u_stat, u_p = None, None
    return {
        "seeds": [int(s) for s in seeds],
        "multi": {
            "populations": config.populations,
            "robots": config.robots,
            "sets": "best robot of each population, final generation",
            "diversity": multi_values,
            "mean": float(np.mean(multi_values)),
        },
        "single": {
            "populations": 1,
            "robots": single.robots,
            "sets": f"{config.populations} best robots of the final generation",
            "diversity": single_values,
            "mean": float(np.mean(single_values)),
        },
        "welch_t": {"statistic": finite(t.statistic), "p_value": finite(t.pvalue)},
        "mann_whitney_u": {"statistic": u_stat, "p_value": u_p},
    }
