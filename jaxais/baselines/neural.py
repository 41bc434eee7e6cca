"""A modern baseline [ours]: a small neural controller trained by OpenES (docs/baseline.md).

Does the 2008 idiotypic network still hold its own against a plain neural policy trained by a
modern black-box optimiser on the same simulator? The policy is a tanh MLP from the first 10
entries of the gymnax observation (no goal pixels: no controller of the paper sees them) to the
wheel speeds, reactive and deterministic; :data:`NEURAL` runs it under the task loop. Training is
OpenES (antithetic pairs, centred ranks, adam; evosax's shape) with common random numbers across
a generation, in ``ga_maze`` where the paper's LTL trains, so the test worlds stay unseen by both.
**Fitness sign: LOWER is better**, as in the paper: minus the mean return.
"""

from __future__ import annotations

import dataclasses
import math
import zipfile
import zlib
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
from jaxais.controllers import Controller, Percept, no_learning, no_state
from jaxais.envs.params import IR_FULL_SCALE, PIXELS
from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.behaviours import MAX_WHEEL_SPEED
from jaxais.io import UserError, atomic_write, atomic_write_json, read_json_object

N_FEATURES = 10  # the gymnax observation less its goal pixels
_HALF_COLUMNS = (envs.CAMERA_COLUMNS - 1) / 2


# ------------------------------------------------------------------------------------ features


def features(ir: jnp.ndarray, blue_pixels: jnp.ndarray, centroid: jnp.ndarray) -> jnp.ndarray:
    """The policy's inputs [10] as the gymnax observation's: ir [8] / 4095, blue_pixels / 45,
    (centroid - 7) / 7 (0 when no blue)."""
    seen = blue_pixels > 0
    c = jnp.where(seen, (centroid - _HALF_COLUMNS) / _HALF_COLUMNS, 0.0)
    tail = jnp.stack([blue_pixels / PIXELS, c])
    return jnp.concatenate([ir / IR_FULL_SCALE, tail]).astype(jnp.float32)


# -------------------------------------------------------------------------------------- policy


@pytree_dataclass
class MLPParams:
    """The policy's weights: w1 [10, H], b1 [H], w2 [H, 2], b2 [2]."""

    w1: jnp.ndarray
    b1: jnp.ndarray
    w2: jnp.ndarray
    b2: jnp.ndarray


_FIELDS = dataclasses.fields(MLPParams)


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
    """:func:`policy` summed in a fixed order, what the controller runs: XLA picks a dot's order
    per program, and a trial must be the same run in a batch or the pool, on one device or two
    (a few of 30 took other paths). Training keeps ``policy`` (the shipped weights)."""
    h = jnp.tanh(_dense_in_order(x, params.w1, params.b1))
    return jnp.tanh(_dense_in_order(h, params.w2, params.b2))


def neural_controller() -> Controller:
    """The MLP as a :class:`~jaxais.controllers.Controller` (params: :class:`MLPParams`); its
    ``stats`` are the STL's keys with "does not apply" values, so its records read alike."""

    def act(key, state, pc: Percept, params: MLPParams):
        del key
        x = features(pc.ir, pc.blue_pixels, pc.centroid)
        return state, policy_in_order(params, x) * MAX_WHEEL_SPEED

    def stats(state, params):
        del state, params
        return {"idiotypic_difference_rate": jnp.float32(jnp.nan), "replaced": jnp.int32(0)}

    return Controller(init=no_state, learn=no_learning, act=act, stats=stats)


NEURAL = neural_controller()


# -------------------------------------------------------------------------------------- OpenES


def centered_ranks(x: jnp.ndarray) -> jnp.ndarray:
    """Ranks of ``x`` [n] mapped onto [-0.5, 0.5]: one outlier cannot dominate an update."""
    n = x.shape[0]
    ranks = jnp.zeros(n).at[jnp.argsort(x)].set(jnp.arange(n, dtype=jnp.float32))
    return ranks / (n - 1) - 0.5


def es_gradient(eps: jnp.ndarray, fitness: jnp.ndarray, sigma: float) -> jnp.ndarray:
    """OpenES's gradient estimate [d] of the shaped fitness [2p] (members mean +- sigma eps
    [p, d], antithetic), for an optax optimiser to descend."""
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
    """OpenES with ``pairs`` antithetic pairs, scale ``sigma``, ``optimizer`` on the gradient."""

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
    """One rollout's return, finished, steps and collisions, up to the step that found the
    target."""

    ret: jnp.ndarray
    finished: jnp.ndarray
    steps: jnp.ndarray
    collisions: jnp.ndarray


def rollout(
    key: jax.Array, params: MLPParams, env: envs.EpuckEnv, env_params: Any, steps: int
) -> Episode:
    """``steps`` steps of the policy in ``env`` (``auto_reset=False``); those after the target
    is found run (fixed shapes) but count nothing."""
    k_reset, k_steps = jax.random.split(key)
    obs, state = env.reset(k_reset, env_params)

    def body(carry, k):
        obs, state, ep = carry
        action = policy(params, obs[:N_FEATURES])  # the goal pixels dropped
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
    """The trained policy (the final mean) and metrics [generations]: the population's
    fitness_mean and fitness_best, the mean's center_fitness, center_finished and
    center_collisions (same episodes, before the update), grad_norm."""

    params: MLPParams
    metrics: dict[str, jnp.ndarray]


def _chunks(generations: int) -> list[tuple[int, int]]:
    """[first, last) generations of each compiled loop: two at a time, three in the last when
    there is an odd number. A loop of one generation would compile as straight-line code, whose
    rounding differs from the loop's; a loop of two or more gives the whole run's bits."""
    if generations < 2:
        return [(0, generations)]
    ends = list(range(2, generations + 1, 2))
    ends[-1] = generations
    return list(zip([0, *ends[:-1]], ends, strict=True))


def make_train(
    config: TrainConfig, progress: Callable[[int, dict[str, Any]], None] | None = None
) -> Callable[[jax.Array], TrainResult]:
    """The training run ``train(key) -> TrainResult``, reproducible from its key: compiled loops
    of two generations (:func:`_chunks`), so that Ctrl-C or SIGTERM takes effect between them (one
    loop over the whole run would hold the signal until its end, minutes later);
    ``progress(generation, metrics)`` is called from inside each generation."""
    env = envs.make(config.world, auto_reset=False, collision_penalty=config.collision_penalty)
    env_params = env.default_params
    _, unravel = ravel_pytree(init_mlp(jax.random.key(0), config.hidden))
    optimizer = (
        optax.adamw(config.learning_rate, weight_decay=config.weight_decay)
        if config.weight_decay
        else optax.adam(config.learning_rate)
    )
    es = openes(config.pairs, config.sigma, optimizer)
    members = config.population + 1  # the population and the mean
    # Rollouts split over the local devices, when they split evenly.
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
            flat_b, keys_b = jax.lax.with_sharding_constraint((flat_b, keys_b), sharding)
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
    def start(key: jax.Array) -> tuple[ESState, jax.Array]:
        """The search's first state and every generation's key [generations]."""
        k_init, k_gens = jax.random.fold_in(key, 0), jax.random.fold_in(key, 1)
        flat, _ = ravel_pytree(init_mlp(k_init, config.hidden))
        return es.init(flat), jax.random.split(k_gens, config.generations)

    @jax.jit
    def run(state: ESState, gens: jax.Array, keys: jax.Array) -> tuple[ESState, dict]:
        return jax.lax.scan(generation, state, (gens, keys))

    def train(key: jax.Array) -> TrainResult:
        state, keys = start(key)
        history = []
        for first, last in _chunks(config.generations):
            state, metrics = run(state, jnp.arange(first, last), keys[first:last])
            history.append(jax.block_until_ready(metrics))  # a signal is seen between loops
        metrics = jax.tree.map(lambda *m: jnp.concatenate(m), *history)
        return TrainResult(params=unravel(state.mean), metrics=metrics)

    return train


# -------------------------------------------------------------------------------------- on disk

PARAMS_FILE = "params.npz"  # w1, b1, w2, b2 (float32)
CONFIG_FILE = "config.json"  # the run's TrainConfig, seed, versions, wall time, final fitness


def default_params_dir() -> Path:
    """The trained weights shipped in ``checkpoints/neural`` (``scripts/train_baseline.py``)."""
    return Path(str(resources.files("jaxais.checkpoints").joinpath("neural")))


def save_params(directory: str | Path, params: MLPParams, info: dict[str, Any]) -> None:
    """Write ``params.npz`` and ``config.json`` (``info``) into ``directory``, atomically."""
    arrays = {f.name: np.asarray(getattr(params, f.name), np.float32) for f in _FIELDS}
    atomic_write(Path(directory, PARAMS_FILE), lambda tmp: np.savez(tmp, **arrays))
    atomic_write_json(Path(directory, CONFIG_FILE), info)


def load_params(directory: str | Path | None = None) -> tuple[MLPParams, dict[str, Any]]:
    """The weights and training record in ``directory`` (default: the shipped ones); a one-line
    UserError naming the file when missing, damaged or not an MLP's."""
    d = default_params_dir() if directory is None else Path(directory)
    path, hint = d / PARAMS_FILE, "train one with scripts/train_baseline.py"
    if not path.is_file():
        raise UserError(f"{d}: not a trained neural controller (no {PARAMS_FILE}; {hint})")
    # np.load would take a .npy, or random bytes as a pickle: only an .npz archive is weights.
    try:
        if not zipfile.is_zipfile(path):
            raise ValueError("not an .npz archive")
        with np.load(path) as z:
            arrays = {f.name: np.asarray(z[f.name], np.float32) for f in _FIELDS}
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise UserError(
            f"{path}: not a trained neural controller's weights ({str(err)[:100]}); {hint}"
        ) from None
    info = read_json_object(d / CONFIG_FILE)
    h = arrays["b1"].shape[0] if arrays["b1"].ndim == 1 else -1
    shapes = {"w1": (N_FEATURES, h), "b1": (h,), "w2": (h, 2), "b2": (2,)}
    for name, shape in shapes.items():
        if arrays[name].shape != shape or not np.all(np.isfinite(arrays[name])):
            raise UserError(f"{path}: {name} must be finite with shape {shape}")
    return MLPParams(**arrays), info
