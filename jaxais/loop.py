"""The task loop: one robot, one run to the target (shared by the GA's LTL and the STL trials).

Each iteration: read the antigen from the last observation, count collisions, apply the finish
rule and the caps, let the controller learn and act, step the simulator. Written for one run;
:mod:`jaxais.runner` drives batches of runs. The loop runs any
:class:`~jaxais.controllers.Controller` (the protocol is in :mod:`jaxais.controllers`): it knows
nothing of antibodies or networks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.controllers import Controller, Percept
from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.antigens import OBSTACLE_THRESHOLD, antigen, is_collision
from jaxais.io import ArgumentTypeError, check_type

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
        segment: iterations per compiled call of :func:`jaxais.runner.rollout` (progress).
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
        for name in ("collision_cap", "finish_pixels", "finish_streak", "chunk", "segment"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ArgumentTypeError(f"EpisodeConfig.{name} must be an integer, got {value!r}")
        for name in ("stop_at_collision_cap", "record"):
            check_type(getattr(self, name), bool | np.bool_, f"EpisodeConfig.{name}", "a bool")
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
        key: the run's PRNG key; iteration t draws from ``fold_in(key, t)``
            (:func:`jaxais.runner.advance`).
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


def outcome(runs: Run, config: EpisodeConfig, dt: float, xp: Any = np) -> dict[str, Any]:
    """Per-run τ (s, capped), collisions (raw and capped), f = (ρc + τ)/2 with ρ = 8 and the
    capped c (SPEC 9), the failures, trapped and locked time and the status.

    Args:
        runs: a :class:`Run` (or anything with its t, status, collisions, trapped, locked).
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
