"""The task loop shared by the GA (LTL) and the STL trials: one robot, one run to the target.

Each iteration: read the antigen from the last observation, count collisions, apply the finish
rule and the caps, let the controller learn and act, step the simulator. Written for one run;
:func:`rollout` advances a batch of runs in lockstep with ``vmap`` inside a ``while_loop``, in
segments so that a Python driver can show progress and stop as soon as every run has ended.

The loop runs any :class:`~jaxais.controllers.Controller` (the protocol is in
:mod:`jaxais.controllers`): it knows nothing of antibodies or networks.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import _speed, envs
from jaxais.controllers import Controller, Percept
from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.antigens import OBSTACLE_THRESHOLD, antigen, is_collision

# Why a run ended (failed_by codes).
RUNNING, FINISHED, FAILED_COLLISIONS, FAILED_TIME = 0, 1, 2, 3
FAILED_BY_NAME = {FINISHED: None, FAILED_COLLISIONS: "collisions", FAILED_TIME: "time"}


@dataclass(frozen=True)
class EpisodeConfig:
    """Static settings of a run (they fix loop lengths and buffer shapes).

    Attributes:
        tau_cap: time cap, simulated seconds [paper: 4000 s STL, ours: 500 s LTL].
        collision_cap: collision cap [paper: 100]; a run with more collisions has failed.
        stop_at_collision_cap: end a run when it reaches the collision cap. The paper's STL runs
            did not stop there (its text speaks of failing robots with "thousands" of
            collisions, and SPEC 9 reads its failure columns as overlapping), so this is off by
            default; the GA's evaluation turns it on (its LTL caps, SPEC 10).
        collision_rule: "episode" counts one collision per contact episode: the antigen enters
            5-7 and the robot has been free of obstacles (Vm < 250) since the last counted one
            [ours, SPEC 9]; "entry" counts every entry into 5-7 from another antigen (the
            earlier reading, which also counts the chatter of one long contact).
        finish_pixels: a run ends after more than this many goal pixels ... [paper: 40]
        finish_streak: ... on this many consecutive iterations [paper: 3].
        trap_radius, trap_window: a robot is trapped while it has stayed within ``trap_radius``
            m of one point for at least ``trap_window`` s; the whole stay counts as trapped time
            [ours: 0.1 m, under three body diameters; 10 s]. It is *locked* while it is trapped
            and its controller's choices (``Controller.choices``: for the STL, the antibody
            selected for each antigen) have not changed over the whole stay: the same antibody
            keeps being selected for its antigen while the robot does not move away [ours].
        chunk: iterations per inner loop; trajectories are sampled once per chunk.
        segment: iterations per compiled call of :func:`rollout`'s driver (progress granularity).
        record: keep the trajectory (one pose per chunk).
    """

    tau_cap: float = 4000.0
    collision_cap: int = 100
    stop_at_collision_cap: bool = False
    collision_rule: str = "episode"
    finish_pixels: int = 40
    finish_streak: int = 3
    trap_radius: float = 0.1
    trap_window: float = 10.0
    chunk: int = 25
    segment: int = 5000
    record: bool = False

    def __post_init__(self):
        if self.collision_rule not in ("episode", "entry"):
            raise ValueError(
                f"collision_rule must be 'episode' or 'entry', got {self.collision_rule!r}"
            )
        names = ("tau_cap", "collision_cap", "finish_streak", "trap_radius", "trap_window")
        for name in (*names, "chunk", "segment"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if self.tau_cap > 1e6:  # iteration counters are int32
            raise ValueError(f"tau_cap must be at most 1e6 s, got {self.tau_cap!r}")
        if self.finish_pixels < 0:
            raise ValueError(f"finish_pixels must be >= 0, got {self.finish_pixels!r}")

    def max_iterations(self, dt: float) -> int:
        """Iterations until the time cap."""
        return int(math.ceil(self.tau_cap / dt - 1e-9))

    def trap_iterations(self, dt: float) -> int:
        """Iterations within the trap disc after which a robot counts as trapped."""
        return max(1, round(self.trap_window / dt))


@pytree_dataclass
class Run:
    """One run in progress.

    Attributes:
        sim: simulator state. obs: last observation. ctrl: controller state.
        key: the run's PRNG key; iteration t draws from ``fold_in(key, t)`` (:func:`advance`).
        m_prev, v_prev: previous antigen and Vm. collisions: collisions so far (uncapped).
        free: Vm has been under 250 (clear of obstacles) since the last counted collision, so
            the next collision antigen starts a new contact episode (the episode rule).
        streak: consecutive iterations with more than finish_pixels goal pixels.
        anchor: [2] centre of the current trap disc. still: iterations spent within it.
        trapped: iterations counted as trapped (EpisodeConfig.trap_radius, trap_window).
        unchanged: iterations spent within the disc with the controller's choices unchanged.
        locked: iterations counted as locked (trapped with unchanged choices, EpisodeConfig).
        t: iterations so far. status: RUNNING, FINISHED, FAILED_COLLISIONS or FAILED_TIME.
    """

    sim: envs.State
    obs: envs.Observation
    ctrl: Any
    key: jax.Array
    m_prev: jnp.ndarray
    v_prev: jnp.ndarray
    collisions: jnp.ndarray
    free: jnp.ndarray
    streak: jnp.ndarray
    anchor: jnp.ndarray
    still: jnp.ndarray
    trapped: jnp.ndarray
    unchanged: jnp.ndarray
    locked: jnp.ndarray
    t: jnp.ndarray
    status: jnp.ndarray


def _carried(obs: envs.Observation) -> envs.Observation:
    """The part of an observation the loop reads next iteration (the pixel maps are dropped)."""
    return obs.replace(blue=None, materials=None, depth=None)


def start(
    reset_key: jax.Array,
    run_key: jax.Array,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
) -> Run:
    """A run at t = 0: the world reset from ``reset_key``, everything else from ``run_key``."""
    k_obs, k_ctrl, k_run = jax.random.split(run_key, 3)
    sim = envs.reset(reset_key, world, sim_params)
    obs = _carried(envs.observe(k_obs, sim, world, sim_params))
    ctrl = controller.init(k_ctrl, ctrl_params)
    return Run(
        sim=sim,
        obs=obs,
        ctrl=ctrl,
        key=k_run,
        m_prev=jnp.int32(0),
        v_prev=jnp.float32(0.0),
        collisions=jnp.int32(0),
        free=jnp.bool_(True),
        streak=jnp.int32(0),
        anchor=sim.pose[:2],
        still=jnp.int32(0),
        trapped=jnp.int32(0),
        unchanged=jnp.int32(0),
        locked=jnp.int32(0),
        t=jnp.int32(0),
        status=jnp.int32(RUNNING),
    )


def iterate(
    key: jax.Array,
    run: Run,
    tick: jnp.ndarray,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
) -> Run:
    """One iteration of one run; a run that has ended is unchanged.

    Args:
        key: this iteration's PRNG key, split between learn, act and the simulator step.
        tick: iterations since the batch started (unbatched; see :class:`Percept`).
    """
    draws = _draws(key, world)
    return _iterate(draws, run, tick, world, sim_params, controller, ctrl_params, config)


def _draws(key: jax.Array, world: envs.World) -> tuple[jax.Array, jax.Array, envs.StepNoise]:
    """An iteration's randomness from its key: (learn's key, act's key, the step's noise)."""
    k_learn, k_act, k_sim = jax.random.split(key, 3)
    return k_learn, k_act, envs.sample_step_noise(k_sim, world)


def _iterate(
    draws: tuple[jax.Array, jax.Array, envs.StepNoise],
    run: Run,
    tick: jnp.ndarray,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
) -> Run:
    """:func:`iterate` given its randomness, ``_draws(key, world)``."""
    k_learn, k_act, sim_noise = draws
    obs = run.obs
    m = antigen(obs.ir, obs.blue_pixels)
    if config.collision_rule == "episode":  # one per contact episode (EpisodeConfig)
        counted_now = is_collision(m) & run.free
        free = (run.free & ~counted_now) | (obs.vm < OBSTACLE_THRESHOLD)
    else:  # every entry into 5-7
        counted_now = is_collision(m) & ~is_collision(run.m_prev)
        free = run.free
    collisions = run.collisions + counted_now.astype(jnp.int32)
    streak = jnp.where(obs.goal_pixels > config.finish_pixels, run.streak + 1, 0)
    stop_c = collisions >= config.collision_cap
    status = jnp.select(
        [
            streak >= config.finish_streak,
            stop_c & config.stop_at_collision_cap,
            run.t >= config.max_iterations(sim_params.dt),
        ],
        [FINISHED, FAILED_COLLISIONS, FAILED_TIME],
        RUNNING,
    ).astype(jnp.int32)
    percept = Percept(
        m=m,
        m_prev=run.m_prev,
        v=obs.vm,
        v_prev=run.v_prev,
        ir=obs.ir,
        blue_pixels=obs.blue_pixels,
        centroid=obs.blue_centroid,
        t=run.t,
        tick=tick,
    )
    ctrl = controller.learn(k_learn, run.ctrl, percept, ctrl_params)
    ctrl, wheels = controller.act(k_act, ctrl, percept, ctrl_params)
    sim, new_obs = envs.step_with_noise(run.sim, wheels, sim_noise, world, sim_params)
    new_obs = _carried(new_obs)
    # Trapped time: a stay within trap_radius of the anchor counts, whole, once it lasts the
    # window (at the window all of it is added, then one iteration at a time).
    pos = sim.pose[:2]
    away = jnp.sum((pos - run.anchor) ** 2) > config.trap_radius**2
    still = jnp.where(away, 0, run.still + 1)
    window = config.trap_iterations(sim_params.dt)
    trapped = run.trapped + _stay_counted(still, window)
    # Locked: the same stay with no choice changed (a first choice for a situation is no change).
    if controller.choices is None:
        unchanged = jnp.int32(0)
    else:
        before, after = controller.choices(run.ctrl), controller.choices(ctrl)
        changed = jnp.any((after != before) & (before >= 0))
        unchanged = jnp.where(away | changed, 0, run.unchanged + 1)
    locked = run.locked + _stay_counted(unchanged, window)
    # The iteration that detects the end records the counts and status and moves nothing; a run
    # that ended earlier keeps everything. One select over the whole run, three over the counts.
    live = run.status == RUNNING
    counted = run.replace(
        collisions=jnp.where(live, collisions, run.collisions),
        streak=jnp.where(live, streak, run.streak),
        status=jnp.where(live, status, run.status),
    )
    moved = counted.replace(
        sim=sim,
        obs=new_obs,
        ctrl=ctrl,
        m_prev=m,
        v_prev=percept.v,
        free=free,
        anchor=jnp.where(away, pos, run.anchor),
        still=still,
        trapped=trapped,
        unchanged=unchanged,
        locked=locked,
        t=run.t + 1,
    )
    return jax.tree.map(lambda a, b: jnp.where(live & (status == RUNNING), a, b), moved, counted)


def _stay_counted(stay: jnp.ndarray, window: int) -> jnp.ndarray:
    """Iterations a stay adds to its count: none before the window, all of it at the window,
    then one per iteration."""
    return jnp.where(stay == window, window, (stay > window).astype(jnp.int32))


@pytree_dataclass
class Batch:
    """A batch of runs advanced together, with the optional trajectory buffer.

    Attributes:
        runs: Run with a leading batch axis [n].
        poses: [n, K, 3] poses sampled once per chunk (K = 1 when not recording).
        chunks: number of chunks done (the trajectory's fill level).
    """

    runs: Run
    poses: jnp.ndarray
    chunks: jnp.ndarray


def trajectory_length(config: EpisodeConfig, dt: float) -> int:
    """Pose samples kept per run: one at the start and one per chunk."""
    return -(-config.max_iterations(dt) // config.chunk) + 2 if config.record else 1


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
    n, k = reset_keys.shape[0], trajectory_length(config, float(sim_params.dt))
    poses = jnp.zeros((n, k, 3)).at[:, 0].set(runs.sim.pose)
    return Batch(runs=runs, poses=poses, chunks=jnp.int32(0))


def advance(
    batch: Batch,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
) -> Batch:
    """Advance every run by up to ``config.segment`` iterations, stopping early once all ended.

    Iteration t of a run is ``iterate`` with the key ``fold_in(run.key, t)``: its numbers do
    not depend on the chunk and segment sizes, nor on the other runs of the batch.
    """
    step_all = jax.vmap(_iterate, in_axes=(0, 0, None, None, None, None, 0, None))
    n_chunks = max(1, config.segment // config.chunk)

    def chunk_draws(runs: Run):
        """Every iteration's draws of the chunk, [chunk, n, ...]: each derivation and draw is a
        threefry hash, a loop of its own on CPU whatever its size, so they are made once for
        the chunk, over flat [chunk * n] keys. A run that ends within the chunk stops counting
        t, but then its iterations change nothing, so those draws are unused."""
        n = runs.t.shape[0]
        t = (runs.t[None, :] + jnp.arange(config.chunk)[:, None]).reshape(-1)
        keys = jax.vmap(jax.random.fold_in)(jnp.tile(runs.key, config.chunk), t)
        draws = jax.vmap(_draws, in_axes=(0, None))(keys, world)
        return jax.tree.map(lambda a: a.reshape(config.chunk, n, *a.shape[1:]), draws)

    def chunk(batch: Batch) -> Batch:
        draws = chunk_draws(batch.runs)

        def body(i, r):
            return step_all(
                jax.tree.map(lambda a: a[i], draws),
                r,
                batch.chunks * config.chunk + i,
                world,
                sim_params,
                controller,
                ctrl_params,
                config,
            )

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


def _signature(tree: Any) -> tuple:
    """Hashable shapes and dtypes of a pytree (what a compiled program depends on)."""
    leaves, treedef = jax.tree.flatten(tree)
    return treedef, tuple((jnp.shape(x), jnp.result_type(x)) for x in leaves)


def _fingerprint(tree: Any) -> tuple:
    """Hashable structure, shapes, dtypes and values of a pytree of small arrays."""
    leaves, treedef = jax.tree.flatten(tree)
    arrays = [np.asarray(x) for x in leaves]
    return treedef, tuple((a.shape, a.dtype.str, a.tobytes()) for a in arrays)


class Programs(NamedTuple):
    """The compiled task loop of one controller and batch shape (:func:`compile_rollout`).

    start(reset_keys, run_keys, world, sim_params, ctrl_params) -> Batch;
    advance(batch, world, sim_params, ctrl_params) -> Batch.
    """

    start: Callable[..., Batch]
    advance: Callable[..., Batch]


def batch_sharding(n: int, devices: list | None = None) -> jax.sharding.NamedSharding | None:
    """The sharding of a batch of ``n`` runs along its first axis over ``devices``.

    Args:
        n: batch size; it must be a multiple of the device count (:func:`rollout` pads to one).
        devices: default ``jax.local_devices()``.

    Returns:
        A ``NamedSharding`` over a 1-D ``("batch",)`` mesh, or None for a single device.
    """
    devices = jax.local_devices() if devices is None else list(devices)
    if len(devices) < 2:
        return None
    if n % len(devices):
        raise ValueError(f"a batch of {n} runs does not split over {len(devices)} devices")
    mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))


def compile_rollout(
    reset_keys: jax.Array,
    run_keys: jax.Array,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
    sharding: jax.sharding.NamedSharding | None = None,
) -> Programs:
    """Compile :func:`start_batch` and :func:`advance` for these shapes.

    The arguments may be arrays or ``jax.ShapeDtypeStruct``s. With a ``sharding``
    (:func:`batch_sharding`) the runs and their trajectories stay split along the batch over
    its devices and XLA partitions both programs; the runs never exchange data, so every run's
    numbers are those of one device.
    """
    return _compile(
        reset_keys, run_keys, world, sim_params, controller, ctrl_params, config, sharding, False
    )


def _compile(
    reset_keys: jax.Array,
    run_keys: jax.Array,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
    sharding: jax.sharding.NamedSharding | None,
    fixed_world: bool,
) -> Programs:
    """:func:`compile_rollout`; with ``fixed_world`` the world is compiled into the programs as
    constants (XLA folds them), which then ignore the ``world`` they are given."""

    def task_start(rk, uk, w, sp, cp):
        return start_batch(rk, uk, world if fixed_world else w, sp, controller, cp, config)

    def task_advance(batch, w, sp, cp):
        return advance(batch, world if fixed_world else w, sp, controller, cp, config)

    placement = {}
    if sharding is not None:
        replicated = jax.sharding.NamedSharding(sharding.mesh, jax.sharding.PartitionSpec())
        placement["out_shardings"] = Batch(runs=sharding, poses=sharding, chunks=replicated)
    # The start runs once per batch: compiled for compile speed (jaxais._speed.start_options).
    start = jax.jit(task_start, compiler_options=_speed.start_options(), **placement)
    start = start.lower(reset_keys, run_keys, world, sim_params, ctrl_params).compile()
    loop = jax.jit(task_advance, **placement)
    loop = loop.lower(start.out_info, world, sim_params, ctrl_params).compile()
    return Programs(start=start, advance=loop)


def _pad_batch(tree: Any, pad: int) -> Any:
    """``tree`` with ``pad`` copies of its first run appended along the batch axis."""
    return jax.tree.map(lambda x: jnp.concatenate([x, jnp.repeat(x[:1], pad, axis=0)]), tree)


def rollout(
    reset_keys: jax.Array,
    run_keys: jax.Array,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
    progress: Callable[[int], None] | None = None,
    compiled: dict | None = None,
    timings: dict[str, float] | None = None,
) -> Batch:
    """Run a batch to the end: every run finished or stopped by a cap.

    With several devices (``jax.local_devices()``) the batch is sharded over them
    (:func:`batch_sharding`), padded with copies of its first run to a multiple of the device
    count; the copies are dropped from the result. Every run's numbers are those of one device.

    Args:
        reset_keys, run_keys: [n] PRNG keys (world placement; everything else).
        ctrl_params: controller parameters with a leading batch axis [n].
        progress: called with the iterations done after every segment (e.g. tqdm's update).
        compiled: optional cache dict, so repeated calls with the same controller and batch
            shapes reuse the compiled programs (:func:`compile_rollout`).
        timings: optional dict; ``compile_s`` and ``run_s`` are added to it.

    Returns:
        The final :class:`Batch` of the n runs.
    """
    return _rollout(
        reset_keys,
        run_keys,
        world,
        sim_params,
        controller,
        ctrl_params,
        config,
        progress,
        compiled,
        timings,
        fixed_world=False,
    )


def _rollout(
    reset_keys: jax.Array,
    run_keys: jax.Array,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
    progress: Callable[[int], None] | None,
    compiled: dict | None,
    timings: dict[str, float] | None,
    fixed_world: bool,
) -> Batch:
    """:func:`rollout`; with ``fixed_world`` the programs are compiled for this world's values
    (:func:`_compile`), and a world with other values compiles programs of its own."""
    cache = compiled if compiled is not None else {}
    n = reset_keys.shape[0]
    pad = -n % jax.local_device_count()
    if pad:
        reset_keys, run_keys, ctrl_params = _pad_batch((reset_keys, run_keys, ctrl_params), pad)
    sharding = batch_sharding(n + pad)
    if sharding is not None:
        reset_keys, run_keys, ctrl_params = jax.device_put(
            (reset_keys, run_keys, ctrl_params), sharding
        )
    signature = (
        (controller, config, fixed_world, sharding),
        _fingerprint(world) if fixed_world else _signature(world),
        _signature((reset_keys, run_keys, sim_params, ctrl_params)),
    )
    t0 = time.perf_counter()
    if signature not in cache:
        cache[signature] = _compile(
            reset_keys,
            run_keys,
            world,
            sim_params,
            controller,
            ctrl_params,
            config,
            sharding,
            fixed_world,
        )
    programs = cache[signature]
    t1 = time.perf_counter()
    batch = programs.start(reset_keys, run_keys, world, sim_params, ctrl_params)
    done_before = 0
    while True:
        batch = programs.advance(batch, world, sim_params, ctrl_params)
        t = int(np.max(np.asarray(batch.runs.t)))
        if progress is not None:
            progress(t - done_before)
        done_before = t
        if not np.any(np.asarray(batch.runs.status) == RUNNING):
            break
    if pad:
        batch = batch.replace(runs=jax.tree.map(lambda x: x[:n], batch.runs), poses=batch.poses[:n])
    if timings is not None:
        timings["compile_s"] = timings.get("compile_s", 0.0) + (t1 - t0)
        timings["run_s"] = timings.get("run_s", 0.0) + (time.perf_counter() - t1)
    return batch


def outcome(runs: Run, config: EpisodeConfig, dt: float, xp: Any = np) -> dict[str, Any]:
    """Per-run τ (s, capped), collisions (raw and capped), f = (ρc + τ)/2 with ρ = 8 and the
    capped c (SPEC 9), the failures, trapped and locked time and the status.

    Args:
        xp: ``numpy`` (default: on the host, τ in float64) or ``jax.numpy`` (inside a traced
            function, :func:`jaxais.trials.make_trials`).

    Returns:
        Arrays [n]: tau, collisions (raw), collisions_capped, fitness, failed_collisions
        (c > cap), failed_time (the time cap reached), trapped_s, locked_s, status,
        iterations.
    """
    status = xp.asarray(runs.status)
    t = xp.asarray(runs.t)
    tau = xp.minimum(t * dt, config.tau_cap)
    raw = xp.asarray(runs.collisions)
    capped = xp.minimum(raw, config.collision_cap)
    return {
        "tau": tau,
        "collisions": raw,
        "collisions_capped": capped,
        "fitness": fitness(tau, capped),
        "failed_collisions": raw > config.collision_cap,
        "failed_time": status == FAILED_TIME,
        "trapped_s": xp.asarray(runs.trapped) * dt,
        "locked_s": xp.asarray(runs.locked) * dt,
        "status": status,
        "iterations": t,
    }


RHO = 8.0
"""Weight of a collision against a second of task time [paper]."""


def fitness(tau, collisions, rho: float = RHO):
    """Paper eq (11): f = (ρc + τ)/2, lower is better (used for both LTL and STL)."""
    return (rho * collisions + tau) / 2.0
