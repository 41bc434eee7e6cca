"""A pool of runs: many more runs than one batch holds, each slot refilled when its run ends.

A batch's task loop runs until its slowest run ends, so in a batch of runs of unequal length the
runs that have ended keep costing (a sweep's few runs at the 4000 s cap would hold thousands of
finished ones). The pool keeps ``slots`` runs live instead: after every segment of the loop the
runs that ended are read out, and their slots start the next runs of the queue.

A run's numbers are those it has in any batch (:func:`jaxais.trials.make_trials`,
:func:`jaxais.trials.run_trials` with recording): its randomness comes from its own keys and its
iteration count alone, and slots are refilled only at batch ticks that are multiples of ``align``
iterations, so a controller's periodic steps (the STL's idiotope, every ``idiotope_period``
iterations, which reads the batch tick) keep their phase. Bit for bit, that holds for
controllers whose arithmetic XLA compiles alike in every program: the STL network and the
neural baseline (tested). A controller with dot products can round
differently here than in a batch's program, or on two devices than on one, since XLA picks a
dot's summation order per program, and over thousands of steps a few of its runs then take
other paths: the same distribution, not the same bits. The neural baseline's MLP did (2 of 30
runs in world1 differed between the pool and one batch), until it summed in a fixed order
(:func:`jaxais.baselines.neural.policy_in_order`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import distributed, envs
from jaxais.controllers import Controller
from jaxais.episode import RUNNING, EpisodeConfig, advance, outcome, start_batch


def _take(tree: Any, idx: jax.Array) -> Any:
    return jax.tree.map(lambda a: a[idx], tree)


@dataclasses.dataclass(frozen=True)
class _Programs:
    """The pool's three compiled steps for one controller, config and slot count."""

    start: Callable[..., Any]
    advance: Callable[..., Any]
    refill: Callable[..., Any]


def _programs(controller: Controller, config: EpisodeConfig, chunks: int, sharding) -> _Programs:
    def spread(batch):
        """The runs split over the devices (jaxais.distributed); a no-op on one device."""
        if sharding is None:
            return batch
        split = lambda x: jax.lax.with_sharding_constraint(x, sharding)
        return batch.replace(runs=jax.tree.map(split, batch.runs), poses=split(batch.poses))

    def readout(batch, params):
        runs = batch.runs
        out = {"t": runs.t, "status": runs.status, "collisions": runs.collisions}
        out["trapped"], out["locked"] = runs.trapped, runs.locked
        if controller.stats is not None:
            out |= jax.vmap(controller.stats)(runs.ctrl, params)
        if sharding is not None:  # every host reads every run's counts
            out = jax.lax.with_sharding_constraint(out, distributed.replicated(sharding))
        return out

    def start(reset_keys, run_keys, idx, world, sim_params, params):
        keys = (reset_keys[idx], run_keys[idx])
        batch = start_batch(*keys, world, sim_params, controller, _take(params, idx), config)
        return spread(batch)

    def step(batch, idx, world, sim_params, params):
        p = _take(params, idx)
        batch = spread(advance(spread(batch), world, sim_params, controller, p, config))
        return batch, readout(batch, p)

    def refill(batch, mask, reset_keys, run_keys, idx, world, sim_params, params):
        fresh = start(reset_keys, run_keys, idx, world, sim_params, params)
        runs = jax.tree.map(
            lambda new, old: jnp.where(mask.reshape(-1, *[1] * (old.ndim - 1)), new, old),
            fresh.runs,
            batch.runs,
        )
        # A segment that stopped early (every live run ended) leaves the tick short of a
        # multiple of the alignment: the next runs start on one.
        aligned = -(-batch.chunks // chunks) * chunks
        return spread(batch.replace(runs=runs, chunks=aligned))

    return _Programs(jax.jit(start), jax.jit(step), jax.jit(refill))


def segment_length(chunk: int, period: int = 1, about: int = 600) -> int:
    """A pool's ``align``: the smallest multiple of ``chunk`` and of a controller's ``period``
    (the STL's idiotope period) at or above ``about`` iterations (one host check each)."""
    align = math.lcm(chunk, period)
    return align * max(1, -(-about // align))


_CACHE: dict = {}
SHRINK = 8
"""Once the queue is empty, the batch shrinks by this factor whenever that many slots are idle
per live run: the last long runs do not pay for a full batch of ended ones (each new size
compiles the loop once)."""


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
    """Run every run to its end, ``slots`` at a time.

    Args:
        reset_keys, run_keys: [n] PRNG keys of the runs (as in :func:`jaxais.episode.rollout`).
        params: the controller's params with a leading axis [n] (one per run).
        slots: runs live at once (the batch size of the compiled loop).
        align: iterations per segment; slots are refilled between segments. A multiple of
            ``config.chunk`` and of every period a controller keeps (600 = 24 chunks of 25 =
            5 idiotope periods of 120).
        progress: called after every segment with the number of runs that ended in it.

    Returns:
        NumPy arrays [n]: :func:`jaxais.episode.outcome`'s and the controller's ``stats``.

    Raises:
        ValueError: ``align`` is not a multiple of ``config.chunk``, or ``slots`` < 1.
    """
    if align % config.chunk or align < config.chunk:
        raise ValueError(f"align must be a multiple of the chunk ({config.chunk}), got {align}")
    if slots < 1:
        raise ValueError(f"slots must be >= 1, got {slots}")
    n = reset_keys.shape[0]
    sharding = distributed.batch_sharding()
    # Slots come in whole multiples of the devices (jaxais.distributed): each holds as many.
    d = 1 if sharding is None else sharding.mesh.size
    b = -(-min(slots, n) // d) * d
    config = dataclasses.replace(config, segment=align, record=False)
    key = (controller, config, sharding)  # jax.jit compiles each batch size on first use
    if key not in _CACHE:
        _CACHE[key] = _programs(controller, config, align // config.chunk, sharding)
    programs = _CACHE[key]

    idx = np.arange(b, dtype=np.int32) % n  # slots past n pad the batch with ended copies
    queued = min(b, n)  # the next run to start
    live = np.arange(b) < n  # the slot holds a run not yet read out
    batch = programs.start(reset_keys, run_keys, idx, world, sim_params, params)
    got: dict[str, np.ndarray] = {}
    while live.any():
        batch, read = programs.advance(batch, idx, world, sim_params, params)
        read = jax.device_get(read)
        ended = live & (read["status"] != RUNNING)
        if not ended.any():
            continue
        for name, values in read.items():
            got.setdefault(name, np.zeros(n, values.dtype))[idx[ended]] = values[ended]
        live &= ~ended
        if progress is not None:
            progress(int(ended.sum()))
        new = np.flatnonzero(ended)[: n - queued]
        if new.size:
            idx[new] = np.arange(queued, queued + new.size)
            queued += new.size
            live[new] = True
            mask = np.zeros(b, bool)
            mask[new] = True
            batch = programs.refill(
                batch, mask, reset_keys, run_keys, idx, world, sim_params, params
            )
        elif b > d and live.sum() <= b // SHRINK:
            # The queue is empty and most slots idle: go on with a batch an eighth the size
            # (ended runs never change, so an idle slot can pad it).
            while b > d and live.sum() <= b // SHRINK:
                b = max(d, -(-(b // SHRINK) // d) * d)
            keep = np.flatnonzero(live)
            keep = np.concatenate([keep, np.full(b - keep.size, np.flatnonzero(~live)[0])])
            batch = batch.replace(runs=_take(batch.runs, keep), poses=batch.poses[keep])
            idx, live = idx[keep], live[keep]
    counts = {name: got.pop(name) for name in ("t", "status", "collisions", "trapped", "locked")}
    return outcome(_Finished(**counts), config, float(sim_params.dt)) | got


@dataclasses.dataclass
class _Finished:
    """The counts of finished runs that :func:`jaxais.episode.outcome` reads."""

    t: np.ndarray
    status: np.ndarray
    collisions: np.ndarray
    trapped: np.ndarray
    locked: np.ndarray


def useful_iterations(result: dict[str, np.ndarray]) -> int:
    """Robot-iterations the runs needed (the pool's useful work)."""
    return int(np.sum(result["iterations"], dtype=np.int64))
