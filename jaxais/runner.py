"""The one driver of the task loop (:mod:`jaxais.loop`): batches of runs, sharded over devices.

A batch advances in lockstep (``vmap`` in a ``while_loop``, :func:`advance`) in segments, between
which the host reads every run's counts. :func:`rollout` runs one batch to its end (the GA,
recorded trials); :func:`run_pool` refills the slots of ended runs from a queue (trials, sweeps).

Iteration t of a run draws from ``fold_in(run.key, t)`` alone, and slots refill at ticks that are
multiples of the segment, so a run's numbers depend neither on chunk or segment sizes nor on its
batch, slot or start: bit for bit for controllers that XLA compiles alike in every program (the
STL, the neural baseline: see :func:`jaxais.baselines.neural.policy_in_order`). The programs are
``jax.jit``'s, compiled once per controller, config, batch shape and device set.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import distributed, envs
from jaxais.controllers import Controller
from jaxais.envs.struct import pytree_dataclass
from jaxais.loop import COLLISION_RULES, RUNNING, EpisodeConfig, Run, draws, iterate, outcome, start


@pytree_dataclass
class Batch:
    """Runs [n] advanced together, their poses [n, K, 3] once per chunk (K = 1 unrecorded)
    and the chunks done."""

    runs: Run
    poses: jnp.ndarray
    chunks: jnp.ndarray


def start_batch(
    reset_keys: jax.Array,
    run_keys: jax.Array,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
) -> Batch:
    """Start n runs (``reset_keys``, ``run_keys`` [n]; ``ctrl_params`` batched along axis 0)."""
    runs = jax.vmap(start, in_axes=(0, 0, None, None, None, 0))(
        reset_keys, run_keys, world, sim_params, controller, ctrl_params
    )
    # One pose at the start and one per chunk.
    k = -(-config.max_iterations(float(sim_params.dt)) // config.chunk) + 2 if config.record else 1
    poses = jnp.zeros((reset_keys.shape[0], k, 3)).at[:, 0].set(runs.sim.pose)
    return Batch(runs=runs, poses=poses, chunks=jnp.int32(0))


def advance(
    batch: Batch,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
) -> Batch:
    """Every run on by up to ``config.segment`` iterations (fewer once all ended); iteration t
    draws from ``fold_in(run.key, t)``."""
    step_all = jax.vmap(iterate, in_axes=(0, 0, None, None, None, None, 0, None))
    n_chunks = max(1, config.segment // config.chunk)

    def chunk_draws(runs: Run):
        """Every iteration's draws of the chunk, [chunk, n, ...], made at once over flat keys
        (each threefry hash is a loop of its own on CPU, whatever its size). A run that ends
        within the chunk leaves its later draws unused."""
        n = runs.t.shape[0]
        t = (runs.t[None, :] + jnp.arange(config.chunk)[:, None]).reshape(-1)
        keys = jax.vmap(jax.random.fold_in)(jnp.tile(runs.key, config.chunk), t)
        flat = jax.vmap(draws, in_axes=(0, None))(keys, world)
        return jax.tree.map(lambda a: a.reshape(config.chunk, n, *a.shape[1:]), flat)

    def chunk(batch: Batch) -> Batch:
        rand = chunk_draws(batch.runs)

        def body(i, r):
            at_i = jax.tree.map(lambda a: a[i], rand)
            tick = batch.chunks * config.chunk + i
            return step_all(at_i, r, tick, world, sim_params, controller, ctrl_params, config)

        runs = jax.lax.fori_loop(0, config.chunk, body, batch.runs)
        poses = batch.poses
        if config.record:
            idx = jnp.minimum(batch.chunks + 1, poses.shape[1] - 1)
            poses = jax.lax.dynamic_update_slice_in_dim(poses, runs.sim.pose[:, None], idx, 1)
        return Batch(runs=runs, poses=poses, chunks=batch.chunks + 1)

    def cond(carry):
        i, b = carry
        return (i < n_chunks) & jnp.any(b.runs.status == RUNNING)

    return jax.lax.while_loop(cond, lambda c: (c[0] + 1, chunk(c[1])), (0, batch))[1]


@jax.tree_util.register_static
class _Constant:
    """A world compiled in as constants, which XLA folds (the GA's maze runs several times faster,
    and its numbers are this form's): static, equal by value, so one compile per world."""

    def __init__(self, world: envs.World):
        self.world = world
        leaves, treedef = jax.tree.flatten(world)
        arrays = [np.asarray(x) for x in leaves]
        self.key = treedef, tuple((a.shape, a.dtype.str, a.tobytes()) for a in arrays)

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Constant) and self.key == other.key


_STATIC = ("controller", "config", "sharding")


def _spread(batch: Batch, sharding) -> Batch:
    """The runs split over the devices; a no-op on one device."""
    if sharding is None:
        return batch
    split = lambda x: jax.lax.with_sharding_constraint(x, sharding)
    return batch.replace(runs=jax.tree.map(split, batch.runs), poses=split(batch.poses))


@functools.partial(jax.jit, static_argnames=_STATIC)
def _start(reset_keys, run_keys, idx, world, sim_params, params, controller, config, sharding):
    """Runs ``idx`` [b] of the queue started (``params``: [n], one per run)."""
    world = world.world if isinstance(world, _Constant) else world
    p = jax.tree.map(lambda a: a[idx], params)
    batch = start_batch(reset_keys[idx], run_keys[idx], world, sim_params, controller, p, config)
    return _spread(batch, sharding)


@functools.partial(jax.jit, static_argnames=_STATIC)
def _advance(batch, idx, world, sim_params, params, controller, config, sharding):
    """One segment of the slots' runs ``idx`` [b], and what the host reads of them."""
    world = world.world if isinstance(world, _Constant) else world
    p = jax.tree.map(lambda a: a[idx], params)
    batch = _spread(
        advance(_spread(batch, sharding), world, sim_params, controller, p, config), sharding
    )
    runs = batch.runs
    read = {"t": runs.t, "status": runs.status, "collisions": runs.collisions}
    read |= {"trapped": runs.trapped, "locked": runs.locked}
    read |= {f"collisions_{k}": getattr(runs, f"by_{k}") for k in COLLISION_RULES}  # outcome's
    read |= {"boxes": runs.sim.boxes, "goal": runs.sim.goal}  # where the run's world put them
    if controller.stats is not None:
        read |= jax.vmap(controller.stats)(runs.ctrl, p)
    if sharding is not None:  # every host reads every run's counts
        read = jax.lax.with_sharding_constraint(read, distributed.replicated(sharding))
    return batch, read


@functools.partial(jax.jit, static_argnames=_STATIC)
def _pool_segment(
    batch, fresh, idx, reset_keys, run_keys, world, sim_params, params, controller, config, sharding
):
    """The pool's one program: the slots ``fresh`` [b] (re)started with their runs ``idx`` [b]
    (the first call starts every slot), then one segment of every slot, and what the host reads
    of them. Starting inside the segment's program keeps a pool to one compile per slot count."""

    def restart(batch: Batch) -> Batch:
        p = jax.tree.map(lambda a: a[idx], params)
        new = start_batch(reset_keys[idx], run_keys[idx], world, sim_params, controller, p, config)
        runs = jax.tree.map(
            lambda a, b: jnp.where(fresh.reshape(-1, *[1] * (b.ndim - 1)), a, b),
            new.runs,
            batch.runs,
        )
        # A segment that stopped early (every live run ended) leaves the tick short of a multiple
        # of the segment: the new runs start on one, so a run's ticks never depend on its start.
        chunks = config.segment // config.chunk
        return batch.replace(runs=runs, chunks=-(-batch.chunks // chunks) * chunks)

    batch = jax.lax.cond(jnp.any(fresh), restart, lambda b: b, _spread(batch, sharding))
    return _advance(batch, idx, world, sim_params, params, controller, config, sharding)


@functools.partial(jax.jit, static_argnames=("sharding",))
def _take(batch: Batch, keep: jax.Array, sharding) -> Batch:
    """The slots ``keep`` [b'] of ``batch``, sharded as the pool's programs take them (a shrink
    on the host would hand the next segment a batch of another layout: another compile)."""
    runs, poses = jax.tree.map(lambda a: a[keep], (batch.runs, batch.poses))
    return _spread(batch.replace(runs=runs, poses=poses), sharding)


def _blank(
    b: int, reset_keys, run_keys, world, sim_params, params, controller, config, sharding
) -> Batch:
    """A batch of ``b`` slots of zeros in the pool's layout, for its first segment to start."""
    static = dict(controller=controller, config=config, sharding=sharding)
    shapes = jax.eval_shape(
        functools.partial(_start, **static),
        reset_keys, run_keys, np.zeros(b, np.int32), world, sim_params, params,
    )  # fmt: skip

    def put(a: np.ndarray, layout) -> jax.Array:
        """A host array laid out as ``layout``, which may span other processes' devices."""
        return a if layout is None else jax.make_array_from_callback(a.shape, layout, a.__getitem__)

    impl = jax.random.key_impl(reset_keys)

    def zeros(s: jax.ShapeDtypeStruct, layout) -> jax.Array:
        if jax.dtypes.issubdtype(s.dtype, jax.dtypes.prng_key):
            data = jax.eval_shape(jax.random.key_data, s)
            return jax.random.wrap_key_data(
                put(np.zeros(data.shape, data.dtype), layout), impl=impl
            )
        return put(np.zeros(s.shape, s.dtype), layout)

    runs, poses = jax.tree.map(lambda s: zeros(s, sharding), (shapes.runs, shapes.poses))
    whole = None if sharding is None else distributed.replicated(sharding)
    return Batch(runs=runs, poses=poses, chunks=zeros(shapes.chunks, whole))


def rollout(
    reset_keys: jax.Array,
    run_keys: jax.Array,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
    progress: Callable[[int], None] | None = None,
    constant_world: bool = False,
) -> Batch:
    """The final :class:`Batch` of n runs run to their ends, sharded over the local devices.

    Args:
        reset_keys, run_keys: [n] keys (world placement; everything else).
        ctrl_params: batched [n]. progress: called with the iterations of each segment.
        constant_world: compile ``world`` in as constants (the GA's way).
    """
    n = reset_keys.shape[0]
    sharding = distributed.batch_sharding(jax.local_devices())
    d = 1 if sharding is None else sharding.mesh.size
    idx = np.arange(-(-n // d) * d, dtype=np.int32) % n
    world = _Constant(world) if constant_world else world
    static = dict(controller=controller, config=config, sharding=sharding)
    batch = _start(reset_keys, run_keys, idx, world, sim_params, ctrl_params, **static)
    done = 0
    while True:
        batch, read = _advance(batch, idx, world, sim_params, ctrl_params, **static)
        read = jax.device_get(read)
        if progress is not None:
            progress(int(read["t"].max()) - done)
        done = int(read["t"].max())
        if not np.any(read["status"] == RUNNING):
            break
    return batch.replace(runs=jax.tree.map(lambda x: x[:n], batch.runs), poses=batch.poses[:n])


def segment_length(chunk: int, period: int = 1, about: int = 600) -> int:
    """A pool's ``align``: the least multiple of ``chunk`` and ``period`` (the idiotope's) at or
    above ``about``."""
    align = math.lcm(chunk, period)
    return align * max(1, -(-about // align))


SHRINK = 8
"""With the queue empty, the batch shrinks by this factor once that many slots idle per live run
(a power of two stays one), after :func:`patience` segments so: a smaller batch costs another
compile (or cache load), which a short tail does not repay."""
EAGER = 64
"""Slots per device from which a pool shrinks as soon as most idle: there an iteration's cost
grows with its slots (about 1.5 us each on a CPU core), so the smaller batch repays its compile
within a segment or two."""
IDLE_BUDGET = 512
"""Below :data:`EAGER`, an iteration costs mostly its kernels' dispatch (about 12 us, whatever
the slots), a smaller batch saves little, and another slot count costs a compile (or a cache
load of about a second): the pool waits this many idle slot-segments first (:func:`patience`)."""


def patience(slots_per_device: int) -> int:
    """Segments a pool of ``slots_per_device`` waits, idle, before it shrinks: none from
    :data:`EAGER` slots up, else ``IDLE_BUDGET / slots`` (19k iterations for 16 slots: a long,
    time-capped tail repays it, a few late finishers do not)."""
    return 1 if slots_per_device >= EAGER else max(1, IDLE_BUDGET // slots_per_device)


def pool_slots(n: int, slots: int, devices: int = 1) -> int:
    """A pool's slot count for ``n`` runs: a power of two per device, so that the compile cache
    serves pools of any size (30, 300 or 1000 trials alike). The power of two at or above
    ``n`` if it pads by at most a quarter, else the one below (its slots refill); at most
    ``slots``."""
    per = -(-min(n, slots) // devices)
    up = 1 << (per - 1).bit_length()
    b = up if up * 4 <= per * 5 else max(1, up // 2)
    cap = 1 << (max(1, slots // devices).bit_length() - 1)
    return min(b, cap) * devices


def run_pool(
    reset_keys: jax.Array,
    run_keys: jax.Array,
    params: Any,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    config: EpisodeConfig,
    slots: int = 1024,
    align: int = 600,
    progress: Callable[[int], None] | None = None,
) -> dict[str, np.ndarray]:
    """Every run to its end, ``slots`` at a time (:func:`pool_slots`), sharded over every
    process's devices; one compiled program per slot count.

    Args:
        reset_keys, run_keys, params: [n] as :func:`rollout`'s.
        align: iterations per segment, between refills: a multiple of ``config.chunk`` and of
            every period a controller keeps (:func:`segment_length`).
        progress: called with the runs that ended in each segment.

    Returns:
        NumPy arrays [n]: :func:`jaxais.loop.outcome`'s, the controller's ``stats``, and each
        run's ``boxes`` [n, B, 2] and ``goal`` [n, 2].
    """
    if align % config.chunk or align < config.chunk:
        raise ValueError(f"align must be a multiple of the chunk ({config.chunk}), got {align}")
    if slots < 1:
        raise ValueError(f"slots must be >= 1, got {slots}")
    n = reset_keys.shape[0]
    sharding = distributed.batch_sharding()
    # Slots come in whole multiples of the devices: each holds as many.
    d = 1 if sharding is None else sharding.mesh.size
    b = pool_slots(n, slots, d)
    config = dataclasses.replace(config, segment=align, record=False)
    static = dict(controller=controller, config=config, sharding=sharding)
    keys = (reset_keys, run_keys)

    idx = np.arange(b, dtype=np.int32) % n  # slots past n pad the batch with ended copies
    queued = min(b, n)  # the next run to start
    live = np.arange(b) < n  # the slot holds a run not yet read out
    fresh = np.ones(b, bool)  # the slots the next segment (re)starts
    idle = 0  # segments run with the queue empty and most slots idle
    batch = _blank(b, *keys, world, sim_params, params, **static)
    got: dict[str, np.ndarray] = {}
    while live.any():
        batch, read = _pool_segment(batch, fresh, idx, *keys, world, sim_params, params, **static)
        read = jax.device_get(read)
        fresh = np.zeros(b, bool)
        ended = live & (read["status"] != RUNNING)
        idle = idle + 1 if queued == n and live.sum() - ended.sum() <= b // SHRINK else 0
        if not ended.any() and (b <= d or idle < patience(b // d)):
            continue
        for name, values in read.items():
            got.setdefault(name, np.zeros((n, *values.shape[1:]), values.dtype))
            got[name][idx[ended]] = values[ended]
        live &= ~ended
        if progress is not None and ended.any():
            progress(int(ended.sum()))
        new = np.flatnonzero(ended)[: n - queued]
        if new.size:
            idx[new] = np.arange(queued, queued + new.size)
            queued += new.size
            live[new] = fresh[new] = True
        elif b > d and live.sum() <= b // SHRINK and idle >= patience(b // d):
            # The queue is empty and most slots have idled long enough: go on with a batch an
            # eighth the size (ended runs never change, so an idle slot can pad it).
            while b > d and live.sum() <= b // SHRINK:
                b = max(d, b // SHRINK)
            keep = np.flatnonzero(live)
            keep = np.concatenate([keep, np.full(b - keep.size, np.flatnonzero(~live)[0])])
            batch = _take(batch, keep.astype(np.int32), sharding)
            idx, live, fresh, idle = idx[keep], live[keep], fresh[keep], 0
    counts = {name: got.pop(name) for name in ("t", "status", "collisions", "trapped", "locked")}
    return outcome(types.SimpleNamespace(**counts), config, float(sim_params.dt)) | got
