"""A modern baseline [ours, not in the paper]: a small neural controller trained by OpenES.

The question it answers: does the 2008 idiotypic network (SIE) still hold its own against a
plain neural policy trained by a modern black-box optimiser on the same simulator?

**Policy.** A one-hidden-layer MLP, tanh throughout, from the 10 features a robot's controllers
see (:data:`FEATURE_NAMES`: the 8 IR readings / 4095, blue pixels / 45, the blue centroid in
[-1, 1], 0 when no blue is seen; these are the first 10 entries of the gymnax environment's
observation, :mod:`jaxais.envs.gymnax`, and never its goal pixels, which no controller of the
paper sees) to the two wheel speeds in [-1, 1], x 1000 speed units. It has no memory and draws
no random numbers: a reactive controller, like :func:`jaxais.controllers.braitenberg_controller`
but learned. :data:`NEURAL` runs it under the task loop (``run_trials``, ``make_trials``) like
SIE and HDC; its params are the weights, :class:`MLPParams`.

**Training.** OpenES (Salimans et al. 2017; the shape of evosax's ``OpenES``): antithetic
Gaussian perturbations of the flat weight vector, centred-rank fitness shaping, and the
resulting gradient estimate fed to an optax optimiser (adam). **Fitness sign: LOWER is better**,
as in the paper: a member's fitness is minus its mean return. Every member of a generation runs
the same ``episodes`` episodes (the same start placements and noise: common random numbers, so
a pair's difference measures the perturbation, not its luck), ``steps`` steps each, on
``envs.make(world, auto_reset=False)``: fixed-length rollouts under ``vmap``, the reward summed
up to and including the step that finds the target (the environment's documented reward:
approach to the goal, -1 per collision, +10 on finding the target). The mean of the search
distribution is evaluated on the same episodes each generation (the training curve) and is the
trained policy. :func:`make_train` returns one jitted function, ``train(key) -> TrainResult``:
initialisation and every generation (a ``lax.scan``) in one compiled program.

**Where it trains.** In ``ga_maze``, the world the paper's LTL (the GA that makes SIE's seed)
trains in: the environment supports it (it has a goal, and the Euclidean approach reward points
through the maze's doorways, which step east towards the goal), and the test worlds (world1,
world2, real) then stay unseen by both SIE's seed and this policy, which is the fair comparison.
SIE still adapts online in the test world; the MLP cannot. How well a maze-trained policy
transfers depends much on the training run (docs/baseline.md: five training seeds).
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree

from jaxais import distributed, envs
from jaxais.baselines.config import TrainConfig
from jaxais.controllers import Controller, Percept
from jaxais.envs.params import IR_FULL_SCALE, OBS_NAMES, PIXELS
from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.behaviours import MAX_WHEEL_SPEED
from jaxais.io import atomic_write, atomic_write_json

__all__ = [
    "CONFIG_FILE",
    "ESState",
    "FEATURE_NAMES",
    "LOWER_IS_BETTER",
    "MLPParams",
    "NEURAL",
    "N_FEATURES",
    "OpenES",
    "PARAMS_FILE",
    "TrainConfig",
    "TrainResult",
    "centered_ranks",
    "default_params_dir",
    "es_gradient",
    "features",
    "init_mlp",
    "load_params",
    "make_train",
    "neural_controller",
    "obs_features",
    "openes",
    "percept_features",
    "policy",
    "rollout",
    "save_params",
]

LOWER_IS_BETTER = True
"""ES fitness is minus the return: lower is better, as the paper's f."""
N_FEATURES = 10
"""Policy inputs: the gymnax observation less its goal pixels."""
FEATURE_NAMES = OBS_NAMES[:N_FEATURES]
"""ps0..ps7, blue, centroid."""
_HALF_COLUMNS = (envs.CAMERA_COLUMNS - 1) / 2


# ------------------------------------------------------------------------------------ features


def features(ir: jnp.ndarray, blue_pixels: jnp.ndarray, centroid: jnp.ndarray) -> jnp.ndarray:
    """The policy's inputs [10] from raw readings, scaled as the gymnax observation.

    Args:
        ir: [8] IR readings, 0..4095. blue_pixels: blue pixels seen, 0..45.
        centroid: their mean column, 0..14 (any value when none is seen).

    Returns:
        float32 [10]: ir / 4095, blue_pixels / 45, (centroid - 7) / 7 (0 when no blue).
    """
    seen = blue_pixels > 0
    c = jnp.where(seen, (centroid - _HALF_COLUMNS) / _HALF_COLUMNS, 0.0)
    tail = jnp.stack([blue_pixels / PIXELS, c])
    return jnp.concatenate([ir / IR_FULL_SCALE, tail]).astype(jnp.float32)


def percept_features(pc: Percept) -> jnp.ndarray:
    """The policy's inputs [10] from what the task loop gives a controller."""
    return features(pc.ir, pc.blue_pixels, pc.centroid)


def obs_features(obs: jnp.ndarray) -> jnp.ndarray:
    """The policy's inputs [10] from the gymnax observation [11] (its goal pixels dropped)."""
    return obs[:N_FEATURES]


# -------------------------------------------------------------------------------------- policy


@pytree_dataclass
class MLPParams:
    """The policy's weights.

    Attributes:
        w1: [10, H]. b1: [H]. w2: [H, 2]. b2: [2].
    """

    w1: jnp.ndarray
    b1: jnp.ndarray
    w2: jnp.ndarray
    b2: jnp.ndarray


def init_mlp(key: jax.Array, hidden: int) -> MLPParams:
    """LeCun-normal weights (std 1/sqrt(fan-in)), zero biases."""
    k1, k2 = jax.random.split(key)
    return MLPParams(
        w1=jax.random.normal(k1, (N_FEATURES, hidden)) / math.sqrt(N_FEATURES),
        b1=jnp.zeros(hidden),
        w2=jax.random.normal(k2, (hidden, 2)) / math.sqrt(hidden),
        b2=jnp.zeros(2),
    )


def policy(params: MLPParams, x: jnp.ndarray) -> jnp.ndarray:
    """Wheel speeds (left, right) [2] in [-1, 1] from the features ``x`` [10] (training's)."""
    h = jnp.tanh(x @ params.w1 + params.b1)
    return jnp.tanh(h @ params.w2 + params.b2)


def _dense_in_order(x: jnp.ndarray, w: jnp.ndarray, b: jnp.ndarray) -> jnp.ndarray:
    """``x @ w + b`` for x [K], w [K, M], summed input by input in a fixed order."""
    out = b
    for k in range(x.shape[-1]):
        out = out + x[k] * w[k]
    return out


def policy_in_order(params: MLPParams, x: jnp.ndarray) -> jnp.ndarray:
    """:func:`policy` with its sums in a fixed order: what the controller runs.

    XLA picks a dot's summation order per compiled program, so ``policy``'s last bits differ
    between the task loop's programs (one batch or the refilling pool, one device or two), and
    over a run's thousands of steps a few runs then take other paths (2 of 30 in world1, between
    the pool and one batch). As a fixed sequence of multiply-adds it compiles to the same
    arithmetic in each of those programs, so a trial is the same run whichever plays it
    (``tests/test_neural.py``; two devices against one checked by hand). Training keeps
    ``policy``, so the shipped weights stay what their command makes.
    """
    h = jnp.tanh(_dense_in_order(x, params.w1, params.b1))
    return jnp.tanh(_dense_in_order(h, params.w2, params.b2))


def neural_controller() -> Controller:
    """The MLP as a :class:`~jaxais.controllers.Controller` (params: :class:`MLPParams`).

    No state (a dummy scalar keeps the loop's pytrees non-empty), no learning, no randomness.
    Its ``stats`` are the STL's keys with "does not apply" values (an idiotypic difference
    rate of NaN, nothing replaced), so its trial records read like every other system's.
    """

    def init(key, params):
        del key, params
        return jnp.int32(0)

    def learn(key, state, pc: Percept, params):
        del key, pc, params
        return state

    def act(key, state, pc: Percept, params: MLPParams):
        del key
        return state, policy_in_order(params, percept_features(pc)) * MAX_WHEEL_SPEED

    def stats(state, params):
        del state, params
        return {"idiotypic_difference_rate": jnp.float32(jnp.nan), "replaced": jnp.int32(0)}

    return Controller(init=init, learn=learn, act=act, stats=stats)


NEURAL = neural_controller()
"""The neural controller (one shared instance, so compiled programs are reused)."""


# -------------------------------------------------------------------------------------- OpenES


def centered_ranks(x: jnp.ndarray) -> jnp.ndarray:
    """Ranks of ``x`` [n] mapped linearly onto [-0.5, 0.5] (ties broken by position).

    The lowest value gets -0.5, the highest +0.5: the ES sees only the order of the fitnesses,
    so one outlier episode cannot dominate an update.
    """
    n = x.shape[0]
    ranks = jnp.zeros(n).at[jnp.argsort(x)].set(jnp.arange(n, dtype=jnp.float32))
    return ranks / (n - 1) - 0.5


def es_gradient(eps: jnp.ndarray, fitness: jnp.ndarray, sigma: float) -> jnp.ndarray:
    """OpenES's estimate of the gradient of the expected (shaped) fitness at the mean.

    Args:
        eps: [p, d] the standard normal perturbations; member j is mean + sigma eps_j and
            member p + j is mean - sigma eps_j (antithetic pairs).
        fitness: [2p] the members' fitness (lower is better).
        sigma: the perturbations' scale.

    Returns:
        [d] the gradient estimate, (1 / (2p sigma)) sum_i shaped_i z_i with z = (eps, -eps):
        a descent direction for an optax optimiser (fitness is minimised).
    """
    p = eps.shape[0]
    shaped = centered_ranks(fitness)
    return (shaped[:p] - shaped[p:]) @ eps / (2 * p * sigma)


@pytree_dataclass
class ESState:
    """The search distribution: its mean [d] (the flat weights) and the optimiser's state."""

    mean: jnp.ndarray
    opt_state: Any


class OpenES(NamedTuple):
    """OpenES as pure functions (evosax's verbs), built by :func:`openes`.

    - ``init(mean [d]) -> ESState``;
    - ``ask(key, state) -> (eps [p, d], population [2p, d])``;
    - ``tell(state, eps, fitness [2p]) -> (state, gradient [d])``.
    """

    init: Callable[..., ESState]
    ask: Callable[..., tuple[jnp.ndarray, jnp.ndarray]]
    tell: Callable[..., tuple[ESState, jnp.ndarray]]


def openes(pairs: int, sigma: float, optimizer: optax.GradientTransformation) -> OpenES:
    """OpenES with ``pairs`` antithetic pairs (a population of 2 x pairs), perturbation scale
    ``sigma`` and ``optimizer`` applied to the gradient estimate (:func:`es_gradient`)."""

    def init(mean: jnp.ndarray) -> ESState:
        return ESState(mean=mean, opt_state=optimizer.init(mean))

    def ask(key: jax.Array, state: ESState) -> tuple[jnp.ndarray, jnp.ndarray]:
        eps = jax.random.normal(key, (pairs, state.mean.shape[0]))
        population = state.mean + sigma * jnp.concatenate([eps, -eps])
        return eps, population

    def tell(state: ESState, eps: jnp.ndarray, fitness: jnp.ndarray):
        grad = es_gradient(eps, fitness, sigma)
        updates, opt_state = optimizer.update(grad, state.opt_state, state.mean)
        return ESState(mean=optax.apply_updates(state.mean, updates), opt_state=opt_state), grad

    return OpenES(init=init, ask=ask, tell=tell)


# ------------------------------------------------------------------------------------ training


class Episode(NamedTuple):
    """One fixed-length rollout's results (scalars).

    Attributes:
        ret: reward summed up to and including the step that found the target.
        finished: the target was found. steps: steps until it was (``steps`` if not).
        collisions: collisions counted until then.
    """

    ret: jnp.ndarray
    finished: jnp.ndarray
    steps: jnp.ndarray
    collisions: jnp.ndarray


def rollout(
    key: jax.Array, params: MLPParams, env: envs.EpuckEnv, env_params: Any, steps: int
) -> Episode:
    """One episode of ``steps`` steps of the policy in ``env`` (``auto_reset=False``).

    Steps after the target is found still run (fixed shapes under ``vmap``) but count nothing.
    """
    k_reset, k_steps = jax.random.split(key)
    obs, state = env.reset(k_reset, env_params)

    def body(carry, k):
        obs, state, ep = carry
        action = policy(params, obs_features(obs))
        obs, state, reward, terminated, _, info = env.step(k, state, action, env_params)
        live = ~ep.finished
        ep = Episode(
            ret=ep.ret + jnp.where(live, reward, 0.0),
            finished=ep.finished | terminated,
            steps=ep.steps + live.astype(jnp.int32),
            collisions=jnp.where(live, info["collisions"], ep.collisions),
        )
        return (obs, state, ep), None

    zero = Episode(jnp.float32(0.0), jnp.bool_(False), jnp.int32(0), jnp.int32(0))
    (_, _, ep), _ = jax.lax.scan(body, (obs, state, zero), jax.random.split(k_steps, steps))
    return ep


class TrainResult(NamedTuple):
    """What :func:`make_train`'s ``train`` returns.

    Attributes:
        params: the trained policy (the search distribution's final mean).
        metrics: per generation, arrays [generations]: ``fitness_mean`` and ``fitness_best``
            (the population's, lower is better), ``center_fitness`` (the mean's, on the same
            episodes, before the update), ``center_finished`` (its share of episodes that found
            the target), ``center_collisions`` (its mean collisions), ``grad_norm``.
    """

    params: MLPParams
    metrics: dict[str, jnp.ndarray]


def make_train(
    config: TrainConfig, progress: Callable[[int, dict[str, Any]], None] | None = None
) -> Callable[[jax.Array], TrainResult]:
    """The whole training run as one jitted function, ``train(key) -> TrainResult``.

    Args:
        config: the run's settings.
        progress: optional host callback ``progress(generation, metrics)`` called after every
            generation from inside the compiled loop (``jax.debug.callback``), e.g. a log line.

    Returns:
        ``train(key)``: from ``key`` alone, the initial weights (``fold_in(key, 0)``) and every
        generation's perturbations and episodes (``fold_in(key, 1)``, split per generation);
        the same key gives the same result.
    """
    env = envs.make(config.world, auto_reset=False, collision_penalty=config.collision_penalty)
    env_params = env.default_params
    template = init_mlp(jax.random.key(0), config.hidden)
    _, unravel = ravel_pytree(template)
    optimizer = (
        optax.adamw(config.learning_rate, weight_decay=config.weight_decay)
        if config.weight_decay
        else optax.adam(config.learning_rate)
    )
    es = openes(config.pairs, config.sigma, optimizer)
    members = config.population + 1  # the population and the mean
    # Rollouts split over the local devices (one CPU device per core in the scripts), unless
    # they do not split evenly.
    sharding = distributed.batch_sharding(jax.local_devices())
    if sharding is not None and members * config.episodes % sharding.mesh.size:
        sharding = None

    def evaluate(flat: jnp.ndarray, key: jax.Array):
        """Every member [m, d] on the generation's episodes -> (fitness [m], Episode [m, e])."""
        keys = jax.random.split(key, config.episodes)
        m, e = flat.shape[0], config.episodes
        flat_b = jnp.repeat(flat, e, axis=0)  # [m * e, d]: member i's episodes are rows i*e..
        keys_b = jnp.tile(keys, m)
        if sharding is not None:
            flat_b = jax.lax.with_sharding_constraint(flat_b, sharding)
            keys_b = jax.lax.with_sharding_constraint(keys_b, sharding)
        run = lambda k, w: rollout(k, unravel(w), env, env_params, config.steps)
        eps = jax.vmap(run)(keys_b, flat_b)
        eps = jax.tree.map(lambda a: a.reshape(m, e), eps)
        return -eps.ret.mean(axis=1), eps

    def generation(state: ESState, xs):
        gen, key = xs
        k_ask, k_episodes = jax.random.split(key)
        eps, population = es.ask(k_ask, state)
        fitness, episodes = evaluate(jnp.concatenate([population, state.mean[None]]), k_episodes)
        state, grad = es.tell(state, eps, fitness[:-1])
        metrics = {
            "fitness_mean": fitness[:-1].mean(),
            "fitness_best": fitness[:-1].min(),
            "center_fitness": fitness[-1],
            "center_finished": episodes.finished[-1].mean(),
            "center_collisions": episodes.collisions[-1].mean(),
            "grad_norm": jnp.linalg.norm(grad),
        }
        if progress is not None:
            jax.debug.callback(progress, gen, metrics)
        return state, metrics

    @jax.jit
    def train(key: jax.Array) -> TrainResult:
        k_init, k_gens = jax.random.fold_in(key, 0), jax.random.fold_in(key, 1)
        flat, _ = ravel_pytree(init_mlp(k_init, config.hidden))
        gens = jnp.arange(config.generations)
        state, metrics = jax.lax.scan(
            generation,
            es.init(flat),
            (gens, jax.random.split(k_gens, config.generations)),
        )
        return TrainResult(params=unravel(state.mean), metrics=metrics)

    return train


# -------------------------------------------------------------------------------------- on disk

PARAMS_FILE = "params.npz"
"""The weights: arrays w1, b1, w2, b2 (float32)."""
CONFIG_FILE = "config.json"
"""The training run: its TrainConfig, seed, versions, wall time and final fitness."""


def default_params_dir() -> Path:
    """The trained weights shipped in ``checkpoints/neural`` (``scripts/train_baseline.py``)."""
    return Path(str(resources.files("jaxais.checkpoints").joinpath("neural")))


def save_params(directory: str | Path, params: MLPParams, info: dict[str, Any]) -> None:
    """Write ``params.npz`` and ``config.json`` (``info``, plain JSON) into ``directory``,
    each atomically."""
    d = Path(directory)
    arrays = {f.name: np.asarray(getattr(params, f.name), np.float32) for f in _fields()}

    def write(tmp: Path) -> None:
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        tmp.write_bytes(buf.getvalue())

    atomic_write(d / PARAMS_FILE, write)
    atomic_write_json(d / CONFIG_FILE, info)


def load_params(directory: str | Path | None = None) -> tuple[MLPParams, dict[str, Any]]:
    """The weights and the training record from ``directory`` (default: the shipped ones).

    Raises:
        ValueError: a file is missing, or the arrays are not an MLP's (names, shapes, finite).
    """
    d = default_params_dir() if directory is None else Path(directory)
    try:
        with np.load(d / PARAMS_FILE) as z:
            arrays = {f.name: np.asarray(z[f.name], np.float32) for f in _fields()}
        info = json.loads((d / CONFIG_FILE).read_text())
    except (OSError, KeyError, ValueError) as err:
        raise ValueError(f"{d}: not a trained neural controller ({err})") from err
    h = arrays["b1"].shape[0] if arrays["b1"].ndim == 1 else -1
    shapes = {"w1": (N_FEATURES, h), "b1": (h,), "w2": (h, 2), "b2": (2,)}
    for name, shape in shapes.items():
        if arrays[name].shape != shape or not np.all(np.isfinite(arrays[name])):
            raise ValueError(f"{d / PARAMS_FILE}: {name} must be finite with shape {shape}")
    return MLPParams(**arrays), info


def _fields() -> tuple[dataclasses.Field, ...]:
    return dataclasses.fields(MLPParams)
