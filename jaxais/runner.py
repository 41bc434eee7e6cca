"""The one driver of the task loop (:mod:`jaxais.loop`): batches of runs, sharded over devices.

A batch advances in lockstep groups of :data:`GROUP` runs (``vmap`` in a ``while_loop``, mapped
over the groups: :func:`advance`) in segments, between which the host reads every run's counts.
On a CPU a segment is one kernel per device (:func:`one_kernel`, each device's runs apart:
``jax.shard_map``), so an iteration costs its work, not its operations' dispatch.
:func:`rollout` runs one batch to its end (the GA, recorded trials); :func:`run_pool` refills
the slots of ended runs from a queue (trials, sweeps) and, each segment, puts each device's
running runs side by side (:func:`packed`), so that its groups pair running runs.

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
from jax.experimental.xla_metadata import set_xla_metadata
from jax.extend.core import jaxprs_in_params

from jaxais import distributed, envs
from jaxais.controllers import Controller
from jaxais.envs.struct import pytree_dataclass
from jaxais.loop import (
    COLLISION_RULES,
    FINISHED,
    RUNNING,
    EpisodeConfig,
    Run,
    draws,
    iterate,
    outcome,
    start,
)


@pytree_dataclass
class Batch:
    """Runs [n] advanced together, their poses [n, K, 3] once per chunk (K = 1 unrecorded)
    and the chunks done (one count per device when sharded: :func:`_per_device`)."""

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


GROUP = 2
"""Runs per lockstep group in :func:`advance`: a group ends its segment when its own runs have
ended, so a pool's ended slots cost nothing and its tail steps only the groups still running
(no shrink, no other slot count to compile). Two or more: a lone run compiles to a program
that rounds a rare step differently from the batched one, and its record would then depend on
its batch."""


def advance(
    batch: Batch,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
    length: jax.Array | None = None,
) -> Batch:
    """Every run on by up to ``config.segment`` iterations (``length`` chunks when given: a
    traced int32), in lockstep groups of :data:`GROUP` (one group unless n is a larger
    multiple), each stopping once its runs have ended; iteration t draws from
    ``fold_in(run.key, t)``. One kernel on a CPU (:func:`one_kernel`)."""
    n = batch.runs.t.shape[0]
    g = GROUP if n > GROUP and n % GROUP == 0 else n
    groups = (batch.runs, batch.poses, ctrl_params)

    def each(groups, chunks, world, sim_params, length):
        split = lambda a: a.reshape(n // g, g, *a.shape[1:])
        runs, poses, chunks = jax.lax.map(
            lambda a: _segment(*a, chunks, length, world, sim_params, controller, config),
            jax.tree.map(split, groups),
        )
        merge = lambda a: a.reshape(n, *a.shape[2:])
        return jax.tree.map(merge, (runs, poses)), jnp.max(chunks)

    args = (groups, batch.chunks, world, sim_params)
    if length is None:  # the segment's length compiled in (the GA's programs)
        fixed = max(1, config.segment // config.chunk)
        (runs, poses), chunks = one_kernel(lambda *a: each(*a, fixed))(*args)
    else:
        (runs, poses), chunks = one_kernel(each)(*args, length)
    return Batch(runs=runs, poses=poses, chunks=chunks)


def _segment(runs, poses, ctrl_params, chunks, length, world, sim_params, controller, config):
    """One lockstep group's segment: ``length`` whole chunks or until every run of the group
    has ended. Returns its runs, poses and chunk count."""
    step_all = jax.vmap(iterate, in_axes=(0, 0, None, None, None, None, 0, None))
    n = runs.t.shape[0]

    def chunk_draws(runs: Run):
        """Every iteration's draws of the chunk, [chunk, n, ...], made at once over flat keys.
        A run that ends within the chunk leaves its later draws unused."""
        t = (runs.t[None, :] + jnp.arange(config.chunk)[:, None]).reshape(-1)
        keys = jax.vmap(jax.random.fold_in)(jnp.tile(runs.key, config.chunk), t)
        flat = jax.vmap(draws, in_axes=(0, None))(keys, world)
        return jax.tree.map(lambda a: a.reshape(config.chunk, n, *a.shape[1:]), flat)

    def chunk(carry):
        runs, poses, chunks = carry
        rand = chunk_draws(runs)

        def body(i, r):
            at_i = jax.tree.map(lambda a: a[i], rand)
            tick = chunks * config.chunk + i
            return step_all(at_i, r, tick, world, sim_params, controller, ctrl_params, config)

        runs = jax.lax.fori_loop(0, config.chunk, body, runs)
        if config.record:
            idx = jnp.minimum(chunks + 1, poses.shape[1] - 1)
            poses = jax.lax.dynamic_update_slice_in_dim(poses, runs.sim.pose[:, None], idx, 1)
        return runs, poses, chunks + 1

    end = chunks + length
    cond = lambda c: (c[2] < end) & jnp.any(c[0].status == RUNNING)
    return jax.lax.while_loop(cond, chunk, (runs, poses, chunks))


def one_kernel(f: Callable) -> Callable:
    """``f`` compiled, on a CPU, as one kernel (XLA's "small call" form: the whole loop one LLVM
    function, no per-operation dispatch), by tagging its call in the program, so that every
    program that runs the loop compiles it alike, whatever its batch size or process flags.
    A function with an operation that form cannot emit (:func:`_kernel_can_emit`: a user's
    controller that sorts, say) runs as XLA compiles it by default."""
    if jax.default_backend() != "cpu":
        return f
    # XLA's one-kernel emitter fails on an argument its computation no longer reads (XLA drops
    # the outputs a caller leaves unused, and with them the reads): a scalar the caller keeps
    # reads each argument.
    inner = jax.jit(lambda *args: (f(*args), _read_all(args)))

    def tagged(*args):
        # One trace serves the check and the call (jit caches it by the arguments' shapes).
        if not _kernel_can_emit(inner.trace(*args).jaxpr.jaxpr):
            return f(*args)
        out = set_xla_metadata(inner(*args), xla_cpu_small_call="true", inlineable="false")
        return jax.lax.optimization_barrier(out)[0]

    return tagged


def _read_all(tree) -> jax.Array:
    """A float32 scalar that reads every array of ``tree`` (its first element: a read is all
    the emitter needs; a sum of every element compiled a tenth slower, a loop per argument)."""

    def first(x):
        if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
            x = jax.random.key_data(x)
        x = jnp.ravel(jnp.asarray(x))
        return x[0].astype(jnp.float32) if x.size else jnp.float32(0)

    return sum((first(x) for x in jax.tree.leaves(tree)), jnp.float32(0))


_NOT_IN_ONE_KERNEL = ("scatter", "sort", "top_k", "approx_top_k", "ffi_call", "pallas_call")
_NOT_IN_ONE_KERNEL += ("cholesky", "eig", "lu", "geqrf", "householder", "svd", "schur")
_NOT_IN_ONE_KERNEL += ("hessenberg", "fft", "triangular_solve", "tridiagonal", "psum", "all_")
_NOT_IN_ONE_KERNEL += ("ppermute", "reduce_scatter")
"""Operations (name prefixes) XLA's one-kernel form cannot emit (runtime calls: scatter, sort,
LAPACK, FFT, foreign calls, collectives; XLA's own pass leaves loops that hold them alone); any
host callback too."""


def _kernel_can_emit(jaxpr) -> bool:
    """Whether no operation in ``jaxpr`` (nested ones included) is one of
    :data:`_NOT_IN_ONE_KERNEL` or a callback."""
    for eqn in jaxpr.eqns:
        name = eqn.primitive.name
        if name.startswith(_NOT_IN_ONE_KERNEL) or "callback" in name:
            return False
        for sub in jaxprs_in_params(eqn.params):
            if not _kernel_can_emit(sub):
                return False
    return True


@jax.tree_util.register_static
class _Constant:
    """A world compiled in as constants (the GA's form; the segment's kernel, :func:`one_kernel`,
    takes them as its arguments): static, equal by value, so one compile per world."""

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
    """The runs split over the devices (and the chunks counted on each); a no-op on one."""
    if sharding is None:
        return batch
    split = lambda x: jax.lax.with_sharding_constraint(x, sharding)
    return jax.tree.map(split, batch)


def _per_device(batch: Batch, sharding) -> Batch:
    """``batch`` with a chunk count per device ([devices]), as :func:`_advance` keeps it when
    sharded: each device's loop stops when its own runs have ended."""
    if sharding is None:
        return batch
    return _spread(batch.replace(chunks=jnp.full(sharding.mesh.size, batch.chunks)), sharding)


@functools.partial(jax.jit, static_argnames=_STATIC)
def _start(reset_keys, run_keys, idx, world, sim_params, params, controller, config, sharding):
    """Runs ``idx`` [b] of the queue started (``params``: [n], one per run)."""
    world = world.world if isinstance(world, _Constant) else world
    p = jax.tree.map(lambda a: a[idx], params)
    batch = start_batch(reset_keys[idx], run_keys[idx], world, sim_params, controller, p, config)
    return _per_device(batch, sharding)


def _advance_local(batch, world, sim_params, p, controller, config, sharding, length) -> Batch:
    """:func:`advance` on each device's slots alone (``jax.shard_map``): no collective inside
    the loop, so that it compiles to one kernel (:func:`one_kernel`) on every device."""
    if sharding is None:
        return advance(batch, world, sim_params, controller, p, config, length)
    spec, whole = sharding.spec, jax.sharding.PartitionSpec()
    constant = not any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(world))

    def local(batch, world, sim_params, p, *length):
        batch = advance(batch.replace(chunks=batch.chunks[0]), world, sim_params, controller, p,
                        config, *length)  # fmt: skip
        return batch.replace(chunks=batch.chunks[None])

    if constant:  # a world compiled in stays constants (_Constant)
        fn = lambda batch, sim_params, p, *length: local(batch, world, sim_params, p, *length)
        args, specs = (batch, sim_params, p), (spec, whole, spec)
    else:
        fn, args, specs = local, (batch, world, sim_params, p), (spec, whole, whole, spec)
    if length is not None:
        args, specs = (*args, length), (*specs, whole)
    return jax.shard_map(fn, mesh=sharding.mesh, in_specs=specs, out_specs=spec)(*args)


@functools.partial(jax.jit, static_argnames=_STATIC)
def _advance(batch, idx, world, sim_params, params, controller, config, sharding, length=None):
    """One segment (``length`` chunks when given) of the slots' runs ``idx`` [b], and what the
    host reads of them."""
    world = world.world if isinstance(world, _Constant) else world
    p = jax.tree.map(lambda a: a[idx], params)
    batch = _advance_local(_spread(batch, sharding), world, sim_params, p, controller, config,
                           sharding, length)  # fmt: skip
    runs = batch.runs
    read = {"t": runs.t, "status": runs.status, "collisions": runs.collisions}
    read |= {"trapped": runs.trapped, "locked": runs.locked}
    read |= {f"collisions_{k}": getattr(runs, f"by_{k}") for k in COLLISION_RULES}  # outcome's
    read |= {"boxes": runs.sim.boxes, "goal": runs.sim.goal}  # where the run's world put them
    if controller.stats is not None:
        read |= jax.vmap(controller.stats)(runs.ctrl, p)
    if sharding is not None and jax.process_count() > 1:  # every host reads every run's counts
        read = jax.lax.with_sharding_constraint(read, distributed.replicated(sharding))
    return batch, read


@functools.partial(jax.jit, static_argnames=_STATIC)
def _pool_segment(
    batch, order, tick, length, fresh, idx, reset_keys, run_keys, world, sim_params, params,
    controller, config, sharding,
):  # fmt: skip
    """The pool's one program: each device's slots put in ``order`` [b] (:func:`packed`) and
    on chunk ``tick``, the slots ``fresh`` [b] (re)started with their runs ``idx`` [b] (the
    first call starts every slot), then a segment of ``length`` chunks of every slot, and what
    the host reads of them. Starting inside the segment's program keeps a pool to one compile
    per slot count."""
    batch = _local(_reordered, sharding)(_spread(batch, sharding), order)
    batch = _per_device(batch.replace(chunks=tick), sharding)

    def restart(batch: Batch) -> Batch:
        # _start called as _blank calls it (the statics by keyword: jit's trace cache keys on
        # the call's form), so that the trace _blank made serves here.
        new = _start(reset_keys, run_keys, idx, world, sim_params, params, controller=controller,
                     config=config, sharding=sharding)  # fmt: skip
        runs = jax.tree.map(
            lambda a, b: jnp.where(fresh.reshape(-1, *[1] * (b.ndim - 1)), a, b),
            new.runs,
            batch.runs,
        )
        return batch.replace(runs=runs)

    batch = jax.lax.cond(jnp.any(fresh), restart, lambda b: b, batch)
    return _advance(batch, idx, world, sim_params, params, controller, config, sharding, length)


def _reordered(batch: Batch, order: jax.Array) -> Batch:
    """A device's slots [s] in ``order`` (indices into the whole batch [b], within the device's
    share: taken modulo s). A copy: no run's numbers change."""
    take = lambda a: a[order % a.shape[0]]
    return batch.replace(runs=jax.tree.map(take, batch.runs), poses=take(batch.poses))


def _local(f: Callable, sharding) -> Callable:
    """``f`` on each device's share of its arguments (batch-sharded alike), with no collective;
    ``f`` itself on one device."""
    if sharding is None:
        return f
    return jax.shard_map(f, mesh=sharding.mesh, in_specs=sharding.spec, out_specs=sharding.spec)


def packed(running: np.ndarray, devices: int = 1) -> np.ndarray:
    """A pool's slot order [b] for its next segment: each device's ``running`` slots [b] first
    in its share of them, so that lockstep groups (:data:`GROUP`) pair running runs and
    ended slots cost nothing (without it a group steps on while one of its two runs has long
    ended). Slots stay on their device: moving them would take a collective every segment."""
    share = running.size // devices
    local = np.argsort(~running.reshape(devices, share), axis=1, kind="stable")
    return (local + share * np.arange(devices)[:, None]).reshape(-1).astype(np.int32)


def _blank(
    b: int, reset_keys, run_keys, world, sim_params, params, controller, config, sharding
) -> Batch:
    """A batch of ``b`` ended slots (zeros) in the pool's layout, for its segments to start."""
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

    batch = jax.tree.map(lambda s: zeros(s, sharding), shapes)
    ended = put(np.full(b, FINISHED, np.int32), sharding)  # no slot runs until it is started
    return batch.replace(runs=batch.runs.replace(status=ended))


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


TAIL = 4
"""A pool's segments once its queue is empty, in aligns (``run_pool``'s ``align``). Each
segment ends with the host reading every slot (milliseconds: a lone run's 600 iterations cost
about as much), and with no run waiting to start, a longer one costs only the groups whose runs
end inside it stepping on with an ended run. 4 of 1, 4 and 8 measured best at 300 and 1,000 SIE
trials; 8 at 30 (docs/performance.md)."""


def segment_length(chunk: int, period: int = 1, about: int = 600) -> int:
    """A pool's ``align``: the least multiple of ``chunk`` and ``period`` (the idiotope's) at or
    above ``about``."""
    align = math.lcm(chunk, period)
    return align * max(1, -(-about // align))


def pool_slots(n: int, slots: int, devices: int = 1) -> int:
    """A pool's slot count for ``n`` runs: the power of two per device at or above ``n``, at
    most ``slots``, so that the compile cache serves pools of any size (30, 300 or 1000 trials
    alike). Slots beyond the runs stay ended, and an ended group of slots costs nothing
    (:func:`advance`)."""
    per = -(-min(n, slots) // devices)
    cap = 1 << (max(1, slots // devices).bit_length() - 1)
    return min(1 << (per - 1).bit_length(), cap) * devices


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

    idx = np.arange(b, dtype=np.int32) % n
    queued = min(b, n)  # the next run to start
    live = np.arange(b) < n  # the slot holds a run not yet read out; slots past n stay ended
    fresh = live.copy()  # the slots the next segment (re)starts
    batch = _blank(b, *keys, world, sim_params, params, **static)
    got: dict[str, np.ndarray] = {}
    # The host keeps the pool's tick: each segment starts `length` chunks after the last began,
    # even one whose runs all ended early, so every segment and every new run starts on a
    # multiple of the align and a run's ticks never depend on its start. Once the queue is empty
    # no slot waits for a refill, and the tail's segments are TAIL times as long: fewer stops.
    per, tick = config.segment // config.chunk, 0
    while live.any():
        order = packed(live, d)
        idx, live, fresh = idx[order], live[order], fresh[order]
        length = per if queued < n else per * TAIL
        batch, read = _pool_segment(
            batch, order, np.int32(tick), np.int32(length), fresh, idx, *keys, world, sim_params,
            params, **static,
        )  # fmt: skip
        tick += length
        read = jax.device_get(read)
        fresh = np.zeros(b, bool)
        ended = live & (read["status"] != RUNNING)
        if not ended.any():
            continue
        for name, values in read.items():
            got.setdefault(name, np.zeros((n, *values.shape[1:]), values.dtype))
            got[name][idx[ended]] = values[ended]
        live &= ~ended
        if progress is not None:
            progress(int(ended.sum()))
        new = np.flatnonzero(ended)[: n - queued]
        idx[new] = np.arange(queued, queued + new.size)
        queued += new.size
        live[new] = fresh[new] = True
    counts = {name: got.pop(name) for name in ("t", "status", "collisions", "trapped", "locked")}
    return outcome(types.SimpleNamespace(**counts), config, float(sim_params.dt)) | got
