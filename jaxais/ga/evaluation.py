"""The GA's evaluation as one pure, jittable function: every set runs ``ga_maze`` (or any world)
from S starts with the LTL controller, to its end, inside one program.

:func:`make_evaluator` returns ``evaluate_sets(key, sets)``, which closes over the world as
constants, as the GA compiles it (XLA folds them: the maze runs several times faster, with
numbers of its own in the last bits), so a user's ``jax.jit`` of it (QDax's, evosax's) gives the
GA's numbers key for key. :mod:`jaxais.ga.driver` runs the same traced functions
(:func:`raw_runs`, :func:`summarise`). Two things keep the numbers the GA's in any program: the
simulator's constants pass through an optimisation barrier (the GA traces them, and XLA folding
them rounds a few steps otherwise), and the means over starts are NumPy's (float64 sums, in an
x64 scope when S > 1; τ from a table of float64 products).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.controllers import LTL
from jaxais.envs.struct import pytree_dataclass
from jaxais.ga.config import GAConfig
from jaxais.ga.core import Evaluation
from jaxais.immune.antibodies import Antibodies
from jaxais.immune.antigens import N_ANTIGENS
from jaxais.io import ArgumentTypeError, check_int
from jaxais.loop import FINISHED, RUNNING, EpisodeConfig, fitness
from jaxais.runner import _Constant, advance, start_batch

__all__ = [
    "Descriptors",
    "flat_runs",
    "make_evaluator",
    "raw_jit",
    "raw_runs",
    "start_keys",
    "summarise",
]

Grid = tuple[int, int]


@pytree_dataclass
class Descriptors:
    """Behavioural descriptors of sets [...] run from S starts: ``final_pose`` [..., S, 3]
    (x, y m; heading rad) where each run ended, and ``visits`` [..., rows, cols] (None without
    a grid): the fraction of each run's time in each cell of the arena (its poses once per
    ``EpisodeConfig.chunk`` iterations, south-west cell first), mean over the starts."""

    final_pose: jnp.ndarray
    visits: jnp.ndarray | None = None


def start_keys(key: jax.Array, starts: int) -> jax.Array:
    """[starts] keys: start s of every set from key s alone (a mean of one-start runs)."""
    return jax.random.split(key, starts)


def _inputs(keys: jax.Array, sets: Antibodies) -> tuple[jax.Array, jax.Array, Antibodies]:
    """(reset keys, run keys, sets) [S·n] of S starts of the n sets, ordered (start, set);
    start s's keys are split from ``keys[s]`` alone."""
    S, n = keys.shape[0], math.prod(sets.shape[:-1])

    def one_start(key):
        k_reset, k_run = jax.random.split(key)
        return jax.random.split(k_reset, n), jax.random.split(k_run, n)

    reset, run = jax.vmap(one_start)(keys)
    flat = jax.tree.map(lambda x: jnp.concatenate([x.reshape(n, *x.shape[-1:])] * S), sets)
    return reset.reshape(S * n), run.reshape(S * n), flat


def _visits(poses: jnp.ndarray, t: jnp.ndarray, arena: np.ndarray, grid: Grid, chunk: int):
    """[n, rows, cols] fraction of each run's poses [n, K, 3] (the start, then one per chunk)
    up to its end ``t`` [n] in each cell of ``arena`` (xmin, ymin, xmax, ymax)."""
    rows, cols = grid
    x0, y0, x1, y1 = (float(v) for v in arena)
    col = jnp.clip(jnp.floor((poses[..., 0] - x0) / (x1 - x0) * cols), 0, cols - 1)
    row = jnp.clip(jnp.floor((poses[..., 1] - y0) / (y1 - y0) * rows), 0, rows - 1)
    cell = (row * cols + col).astype(jnp.int32)  # [n, K]
    taken = jnp.arange(poses.shape[1])[None, :] <= -(-t[:, None] // chunk)  # up to the end
    counts = jnp.sum(jax.nn.one_hot(cell, rows * cols) * taken[..., None], axis=1)
    return (counts / jnp.sum(taken, axis=1, keepdims=True)).reshape(-1, rows, cols)


def flat_runs(
    reset_keys: jax.Array,
    run_keys: jax.Array,
    flat: Antibodies,
    world: envs.World,
    sim_params: envs.SimParams,
    episode: EpisodeConfig,
    grid: Grid | None = None,
) -> dict[str, jnp.ndarray]:
    """n runs (keys [n], sets [n, 8]) to their ends in one batch with the LTL controller
    (traceable; ``world`` concrete, compiled in): [n] ``t``, ``status``, raw ``collisions``,
    ``L`` [n, 8], final ``pose`` [n, 3], with a ``grid`` ``visits`` [n, rows, cols]."""
    world = world.world if isinstance(world, _Constant) else world
    episode = dataclasses.replace(episode, record=grid is not None)
    # Traced, as the GA's programs take them: folded in as constants, a few steps round otherwise.
    sim_params = jax.lax.optimization_barrier(sim_params)
    b = start_batch(reset_keys, run_keys, world, sim_params, LTL, flat, episode)
    b = jax.lax.while_loop(
        lambda b: jnp.any(b.runs.status == RUNNING),
        lambda b: advance(b, world, sim_params, LTL, flat, episode),
        b,
    )
    runs = b.runs
    out = {"t": runs.t, "status": runs.status, "collisions": runs.collisions}
    out |= {"L": runs.ctrl.L, "pose": runs.sim.pose}
    if grid is not None:
        out["visits"] = _visits(b.poses, runs.t, np.asarray(world.arena), grid, episode.chunk)
    return out


def _unflatten(out: dict, S: int, batch: tuple[int, ...]) -> dict:
    """[S·n, ...] arrays as [S, *batch, ...]."""
    return jax.tree.map(lambda x: x.reshape(S, *batch, *x.shape[1:]), out)


def raw_runs(
    keys: jax.Array,
    sets: Antibodies,
    world: envs.World,
    sim_params: envs.SimParams,
    episode: EpisodeConfig,
    grid: Grid | None = None,
) -> dict[str, jnp.ndarray]:
    """Every set of ``sets`` [..., 8] from every start key [S] (:func:`flat_runs`, traceable):
    [S, ...] arrays."""
    out = flat_runs(*_inputs(keys, sets), world, sim_params, episode, grid)
    return _unflatten(out, keys.shape[0], sets.shape[:-1])


def _tau_table(episode: EpisodeConfig, dt: float) -> np.ndarray:
    """[max iterations + 1] float32 τ of t iterations, as NumPy computes it on the host
    (float64 t·dt, capped), so traced and host τ agree bit for bit without float64 on device."""
    t = np.arange(episode.max_iterations(dt) + 1)
    return np.minimum(t * dt, episode.tau_cap).astype(np.float32)


def _mean(x: jnp.ndarray) -> jnp.ndarray:
    """float32 mean over axis 0 as NumPy's ``x.mean(0, dtype=float64)``: a float64 sum in order,
    divided, rounded once (an x64 scope; one start needs none)."""
    if x.shape[0] == 1:
        return x[0]
    with jax.enable_x64(True):
        rows = [x[s].astype(jnp.float64) for s in range(x.shape[0])]
        return (functools.reduce(jnp.add, rows) / x.shape[0]).astype(jnp.float32)


def summarise(
    raw: dict[str, jnp.ndarray], episode: EpisodeConfig, dt: float
) -> tuple[Evaluation, Descriptors]:
    """:func:`raw_runs`'s [S, ...] arrays as an :class:`~jaxais.ga.core.Evaluation` [...] (means
    over the starts; f from the stored τ and c) and :class:`Descriptors` (traceable)."""
    S = raw["t"].shape[0]
    table = _tau_table(episode, dt)
    tau = _mean(jnp.asarray(table)[jnp.clip(raw["t"], 0, table.shape[0] - 1)])
    c = _mean(jnp.minimum(raw["collisions"], episode.collision_cap).astype(jnp.float32))
    evaluation = Evaluation(
        # f from exactly the stored τ and c, so (f, τ, c) agree wherever they are read back; f
        # is linear, so it is also the mean f.
        fitness=fitness(tau, c).astype(jnp.float32),
        tau=tau,
        collisions=c,
        L=_mean(jnp.asarray(raw["L"], jnp.float32)),
        crossings=jnp.sum(raw["status"] == FINISHED, axis=0).astype(jnp.int32),
        starts=int(S),
    )
    pose = jnp.moveaxis(jnp.asarray(raw["pose"]), 0, -2)  # [..., S, 3]
    visits = raw.get("visits")
    return evaluation, Descriptors(pose, None if visits is None else jnp.mean(visits, axis=0))


def _check_grid(grid: Grid | None) -> Grid | None:
    if grid is None:
        return None
    ok = isinstance(grid, tuple | list) and len(grid) == 2
    if not ok or not all(isinstance(g, int) and not isinstance(g, bool) and g >= 1 for g in grid):
        raise ValueError(f"grid must be (rows, cols), two integers >= 1, got {grid!r}")
    return (int(grid[0]), int(grid[1]))


def make_evaluator(
    world: envs.World | str = "ga_maze",
    sim_params: envs.SimParams | None = None,
    config: GAConfig | None = None,
    starts: int | None = None,
    grid: Grid | None = None,
) -> Callable[[jax.Array, Antibodies], tuple[Evaluation, Descriptors]]:
    """The GA's evaluation as a pure function ``evaluate_sets(key, sets)``.

    Args:
        world: a World or a world's name (compiled in as constants, as the GA compiles it).
        sim_params: the simulator's constants (default ``envs.default_params()``).
        config: the GA's settings: its caps and, unless ``starts`` is given, its ``starts``.
        starts: starts per set (S), each split from the key as the GA splits them.
        grid: (rows, cols) of the visit grid descriptor (None: no grid, the GA's own program;
            with one, each run's poses are kept, which costs about half as much again).

    Returns:
        ``evaluate_sets(key, sets)``: sets [..., 8] (any batch shape), a key -> (Evaluation
        [...], Descriptors [...]); jittable, vmappable over keys, key for key the numbers of
        :func:`jaxais.ga.driver.evaluate` (``starts``) and :func:`~jaxais.ga.driver.measure`.
    """
    world = envs.load_world(world) if isinstance(world, str) else world
    if not isinstance(world, envs.World):
        raise ArgumentTypeError(f"world must be a World or a world's name, got {world!r:.60}")
    sim_params = envs.default_params() if sim_params is None else sim_params
    config = GAConfig() if config is None else config
    starts = config.starts if starts is None else starts
    starts = check_int(starts, "starts", low=1)  # its type, then its range
    grid, episode, dt = _check_grid(grid), config.episode_config(), float(sim_params.dt)

    def evaluate_sets(key: jax.Array, sets: Antibodies) -> tuple[Evaluation, Descriptors]:
        if sets.shape[-1:] != (N_ANTIGENS,):
            raise ValueError(f"sets must have shape [..., {N_ANTIGENS}], got {sets.shape}")
        raw = raw_runs(start_keys(key, starts), sets, world, sim_params, episode, grid)
        return summarise(raw, episode, dt)

    return evaluate_sets


_inputs_jit = jax.jit(_inputs)
_flat_jit = jax.jit(flat_runs, static_argnames=("world", "episode", "grid"))


def raw_jit(
    keys: jax.Array,
    sets: Antibodies,
    world: envs.World,
    sim_params: envs.SimParams,
    episode: EpisodeConfig,
    grid: Grid | None = None,
) -> dict[str, jax.Array]:
    """:func:`raw_runs` as the GA runs it: the world compiled in as constants, one program per
    world, caps and number of runs (S·n: 5 × 10 robots from one start and 5 sets from 10 share
    it)."""
    world = constant(world)
    out = _flat_jit(*_inputs_jit(keys, sets), world, sim_params, episode, grid)
    return _unflatten(out, keys.shape[0], sets.shape[:-1])


summarise_jit = jax.jit(summarise, static_argnames=("episode", "dt"))
""":func:`summarise`, jitted: the GA's means over starts, however its runs were batched."""


def constant(world: envs.World) -> _Constant:
    """``world`` as a static argument, compiled in, equal by value (a :func:`flat_runs` that
    receives one reads its world)."""
    return _Constant(world)
