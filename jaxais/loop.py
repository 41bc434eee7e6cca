"""The task loop: one robot, one run to the target (the GA's LTL and the STL trials).

Each iteration: antigen, collisions, finish rule and caps, the controller's learn and act, a
simulator step. Any :class:`~jaxais.controllers.Controller` runs here; :mod:`jaxais.runner`
drives batches.
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
from jaxais.io import ArgumentTypeError, check_type, python_scalars

RUNNING, FINISHED, FAILED_COLLISIONS, FAILED_TIME = 0, 1, 2, 3  # Run.status
COLLISION_RULES = ("episode", "reading", "entry")
"""How a run's collisions are counted, each kept apart (:class:`Run`): one per contact episode
[ours, the default]; every iteration whose reading is a collision antigen, Vm >= 2400 (section
4.1's "collision" antigen read literally); every entry into antigens 5-7."""


@dataclass(frozen=True)
class EpisodeConfig:
    """Static settings of a run (they fix loop lengths and buffer shapes).

    Attributes:
        tau_cap: time cap, simulated s [paper: 4000 s STL; ours: 500 s LTL].
        collision_cap: a run with more collisions has failed [paper: 100].
        stop_at_collision_cap: end a run at the cap: off for the STL (the paper's failures
            overlap, SPEC 9), on in the GA (SPEC 10).
        collision_rule: what ``collisions`` counts (and the GA's cap stops on): "episode": one
            per contact episode, antigen 5-7 after Vm < 250 since the last [ours, SPEC 9];
            "entry": every entry into 5-7 (the earlier reading). Every run also counts each
            rule of :data:`COLLISION_RULES` apart; those counts never feed the dynamics.
        finish_pixels, finish_streak: the run ends after more than 40 goal pixels on 3
            consecutive iterations [paper].
        trap_radius, trap_window: trapped while within 0.1 m of one point for >= 10 s, the whole
            stay counted; locked while trapped with ``Controller.choices`` unchanged [ours].
        chunk: iterations per inner loop (one trajectory pose each).
        segment: iterations per compiled call (host checks between).
        record: keep the trajectory.
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
        python_scalars(self)
        if self.collision_rule not in ("episode", "entry"):  # the GA's stop rules
            raise ValueError(
                f"collision_rule must be 'episode' or 'entry', got {self.collision_rule!r}"
            )
        for name in ("collision_cap", "finish_pixels", "finish_streak", "chunk", "segment"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ArgumentTypeError(f"EpisodeConfig.{name} must be an integer, got {value!r}")
        for name in ("stop_at_collision_cap", "record"):
            check_type(getattr(self, name), bool, f"EpisodeConfig.{name}", "a bool")
        names = ("tau_cap", "collision_cap", "finish_streak", "trap_radius", "trap_window")
        for name in (*names, "chunk", "segment"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if self.tau_cap > 1e6:  # iteration counters are int32
            raise ValueError(f"tau_cap must be at most 1e6 s, got {self.tau_cap!r}")
        if self.collision_cap > 2**31 - 1:  # and collision counters
            raise ValueError(f"collision_cap must be below 2**31, got {self.collision_cap!r}")
        if self.finish_pixels < 0:
            raise ValueError(f"finish_pixels must be >= 0, got {self.finish_pixels!r}")

    def max_iterations(self, dt: float) -> int:
        return int(math.ceil(self.tau_cap / dt - 1e-9))

    def trap_iterations(self, dt: float) -> int:
        return max(1, round(self.trap_window / dt))


@pytree_dataclass
class Run:
    """One run in progress (scalars unless shaped).

    Attributes:
        key: iteration t draws from ``fold_in(key, t)``. m_prev, v_prev: last antigen and Vm.
        collisions: uncapped, by ``config.collision_rule``. by_episode, by_reading, by_entry:
            uncapped, by each of :data:`COLLISION_RULES` (counted only). free: Vm < 250 since
            the last contact episode counted.
        streak: iterations in a row past finish_pixels. anchor [2], still: the trap disc's
            centre and the iterations within it; unchanged: those with choices unchanged.
        trapped, locked: iterations counted so (:class:`EpisodeConfig`). status: RUNNING, ...
    """

    sim: envs.State
    obs: envs.Observation
    ctrl: Any
    key: jax.Array
    m_prev: jnp.ndarray
    v_prev: jnp.ndarray
    collisions: jnp.ndarray
    by_episode: jnp.ndarray
    by_reading: jnp.ndarray
    by_entry: jnp.ndarray
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
    """The observation without the pixel maps the loop never reads."""
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
    counts = ("m_prev", "collisions", "streak", "still", "trapped", "unchanged", "locked", "t")
    counts += tuple(f"by_{rule}" for rule in COLLISION_RULES)
    return Run(
        sim=sim,
        obs=obs,
        ctrl=ctrl,
        key=k_run,
        v_prev=jnp.float32(0.0),
        free=jnp.bool_(True),
        anchor=sim.pose[:2],
        status=jnp.int32(RUNNING),
        **dict.fromkeys(counts, jnp.int32(0)),
    )


Draws = tuple[jax.Array, jax.Array, envs.StepNoise]
"""An iteration's randomness: (learn's key, act's key, the simulator step's noise)."""


def draws(key: jax.Array, world: envs.World) -> Draws:
    """An iteration's randomness from its key (the runner makes a chunk's at once: each draw is
    a threefry hash, a loop of its own on CPU)."""
    k_learn, k_act, k_sim = jax.random.split(key, 3)
    return k_learn, k_act, envs.sample_step_noise(k_sim, world)


def iterate(
    rand: Draws,
    run: Run,
    tick: jnp.ndarray,
    world: envs.World,
    sim_params: envs.SimParams,
    controller: Controller,
    ctrl_params: Any,
    config: EpisodeConfig,
) -> Run:
    """One iteration of one run given its randomness, :func:`draws`; an ended run is unchanged.

    ``tick``: iterations since the batch started (unbatched; see :class:`Percept`).
    """
    k_learn, k_act, sim_noise = rand
    obs = run.obs
    m = antigen(obs.ir, obs.blue_pixels)
    hit = is_collision(m)
    now = {
        "episode": hit & run.free,  # one per contact episode (EpisodeConfig)
        "reading": hit,  # every reading of Vm >= 2400
        "entry": hit & ~is_collision(run.m_prev),  # every entry into 5-7
    }
    free = (run.free & ~now["episode"]) | (obs.vm < OBSTACLE_THRESHOLD)
    collisions = run.collisions + now[config.collision_rule].astype(jnp.int32)
    by_rule = {f"by_{k}": getattr(run, f"by_{k}") + now[k].astype(jnp.int32) for k in now}
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
        **{k: jnp.where(live, v, getattr(run, k)) for k, v in by_rule.items()},
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
    """A stay's increment: 0 before the window, all of it at the window, then 1."""
    return jnp.where(stay == window, window, (stay > window).astype(jnp.int32))


def outcome(runs: Run, config: EpisodeConfig, dt: float, xp: Any = np) -> dict[str, Any]:
    """Per-run results of ``runs`` (anything with t, status, collisions, trapped, locked).

    ``xp``: ``numpy`` (on the host, τ in float64) or ``jax.numpy`` (traced). Returns arrays [n]:
    tau (s, capped), collisions (raw), collisions_capped, fitness (SPEC 9), failed_collisions
    (c > cap), failed_time, trapped_s, locked_s, status, iterations, and where ``runs`` has
    them (a :class:`Run`) ``collisions_<rule>`` (raw) of each of :data:`COLLISION_RULES`.
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
    } | {
        f"collisions_{rule}": xp.asarray(getattr(runs, f"by_{rule}"))
        for rule in COLLISION_RULES
        if hasattr(runs, f"by_{rule}")
    }


RHO = 8.0
"""Weight of a collision against a second of task time [paper]."""


def fitness(tau, collisions, rho: float = RHO):
    """Paper eq (11): f = (ρc + τ)/2, lower is better (used for both LTL and STL)."""
    return (rho * collisions + tau) / 2.0
