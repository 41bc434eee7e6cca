"""A gymnax-style face on the simulator: ``make("world1")`` -> an environment for RL code.

The environment is the paper's STL task as a reinforcement-learning problem: drive an e-puck to
the blue goal in a world, without crashing. It follows gymnax 1.0's interface without depending
on gymnax: frozen pytree dataclasses for the state and the parameters, pure functions with the
key first, simple box spaces::

    from jaxais import envs

    env = envs.make("world1", max_steps=2000)
    params = env.default_params
    obs, state = env.reset(key, params)
    obs, state, reward, terminated, truncated, info = env.step(key, state, action, params)

Unlike gymnax's 5-tuple ``(obs, state, reward, done, info)``, ``step`` returns terminated and
truncated apart (as gymnasium does); gymnax's ``done`` is ``terminated | truncated``.

**Observation** (:data:`OBS_NAMES`): a float32 vector [11]:

- 0-7: the IR readings ps0..ps7 scaled to [0, 1] (reading / 4095; 1 is touching, about 0.016
  with nothing in range, where the e-puck reads about 67);
- 8: blue pixels seen (marker or goal) / 45, in [0, 1];
- 9: the blue centroid column scaled to [-1, 1] (-1 = leftmost column, +1 = rightmost, so
  positive means the target is to the right); 0 when no blue pixel is seen;
- 10: goal pixels / 45, in [0, 1].

**Action**: float32 [2], (left, right) wheel speeds in [-1, 1], clipped to that range and scaled
to the e-puck's +-1000 speed units (``SimParams.max_speed``).

**Reward** per step, with the defaults of :class:`EnvParams`:

- ``progress_scale`` (10) x the decrease in Euclidean distance from the robot's centre to the
  goal's centre over the step, in metres (positive when approaching);
- minus ``collision_penalty`` (1.0) when a collision is counted this step: the maximum IR reading
  reaches ``collision_level`` (2400, the paper's collision threshold) and the robot has been free
  of obstacles (maximum IR reading below ``clear_level``, 250) since the last counted collision:
  one penalty per contact episode (SPEC 9), not one per step of contact;
- plus ``finish_bonus`` (10) on the step that terminates the episode by finding the target.

**Terminated**: the paper's finish rule: more than ``finish_pixels`` (40) goal pixels on
``finish_streak`` (3) consecutive steps. **Truncated**: the step count reaches ``max_steps``
(default 125,000 steps = the paper's 4000 s cap at 32 ms a step) without terminating; the two
are never both true.

**Info**: ``collisions`` (counted so far this episode), ``distance`` (robot to goal centre, m,
after the step), ``goal_pixels``, ``max_ir`` (the raw maximum IR reading, 0..4095), ``discount``
(0.0 when terminated, else 1.0, as gymnax's).

``step`` auto-resets as gymnax's does: when an episode ends, the returned observation and state
are those of a fresh episode (from a key split off the step's key), while reward, terminated,
truncated and info describe the step that ended it. ``make(..., auto_reset=False)`` turns that
off and ``step_env`` never resets: stepping on after the end is the caller's business (a robot
parked at the target keeps terminating, and earning the bonus, every step). Unbatched the reset
runs only when an episode ends; under ``vmap`` it runs on every step (``lax.cond`` becomes a
select), and a reset (placing boxes, goal and robots by trial and error) costs several steps
(docs/performance.md). For large batches of long episodes, ``auto_reset=False`` and a reset
between rollouts is cheaper.

Everything is jit- and vmap-able; the only randomness is the keys passed in (the reset's
placements, the simulator's sensor and wanderer noise each step). ``reset`` and ``step`` are
jitted (for the environment object) so that a plain Python loop runs at compiled speed.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .params import CAMERA_COLUMNS, CAMERA_ROWS, N_IR, SimParams, default_params
from .sim import Observation, State, observe
from .sim import reset as sim_reset
from .sim import step as sim_step
from .struct import pytree_dataclass
from .world import World, load_world

IR_FULL_SCALE = 4095.0
"""The IR reading at contact; readings are divided by it."""
PIXELS = CAMERA_COLUMNS * CAMERA_ROWS
"""Camera pixels (45); pixel counts are divided by it."""
PAPER_TIME_CAP = 4000.0
"""The paper's time cap, simulated seconds."""
OBS_NAMES = tuple(f"ps{k}" for k in range(N_IR)) + ("blue", "centroid", "goal")
"""Names of the observation's entries, in order."""


@pytree_dataclass
class EnvParams:
    """The world, the robot and the task's constants (every field a traced leaf).

    A batch of parameters is one ``vmap``; worlds loaded with one ``Capacity`` (and equal static
    fields) share one compiled program.

    Attributes:
        world: the world (``load_world``). sim: the robot's constants (``default_params``).
        max_steps: the episode is truncated after this many steps [paper: 4000 s = 125,000].
        progress_scale: reward per metre of approach to the goal.
        collision_penalty: subtracted once per counted collision (contact episode).
        finish_bonus: added on the step that finds the target.
        collision_level: maximum IR reading that makes a contact [paper: 2400].
        clear_level: maximum IR reading below which the robot is free of obstacles [paper: 250].
        finish_pixels: more than this many goal pixels ... [paper: 40]
        finish_streak: ... on this many consecutive steps finish the episode [paper: 3].
    """

    world: World
    sim: SimParams
    max_steps: int = round(PAPER_TIME_CAP / 0.032)
    progress_scale: float = 10.0
    collision_penalty: float = 1.0
    finish_bonus: float = 10.0
    collision_level: float = 2400.0
    clear_level: float = 250.0
    finish_pixels: int = 40
    finish_streak: int = 3


@pytree_dataclass
class EnvState:
    """One episode in progress.

    Attributes:
        sim: the simulator's state (pose, wanderers, goal, boxes; ``sim.t`` counts the steps).
        collisions: int32, collisions counted so far (one per contact episode).
        free: bool, no obstacle seen (max IR < clear_level) since the last counted collision.
        streak: int32, consecutive steps with more than finish_pixels goal pixels.
    """

    sim: State
    collisions: jnp.ndarray
    free: jnp.ndarray
    streak: jnp.ndarray


@dataclasses.dataclass(frozen=True)
class Box:
    """A box space like gymnax's ``Box``: arrays of ``shape`` with ``low <= x <= high``."""

    low: np.ndarray
    high: np.ndarray
    shape: tuple[int, ...]
    dtype: Any = jnp.float32

    def sample(self, key: jax.Array) -> jax.Array:
        """A uniform draw from the box."""
        return jax.random.uniform(key, self.shape, self.dtype, self.low, self.high)

    def contains(self, x: jax.Array) -> jax.Array:
        """Whether ``x`` lies in the box (a bool scalar)."""
        x = jnp.asarray(x)
        return jnp.all(x >= self.low) & jnp.all(x <= self.high)


def features(ob: Observation) -> jnp.ndarray:
    """The simulator's observation as the environment's float32 vector [11] (:data:`OBS_NAMES`)."""
    seen = ob.blue_pixels > 0
    half = (CAMERA_COLUMNS - 1) / 2
    centroid = jnp.where(seen, (ob.blue_centroid - half) / half, 0.0)
    tail = jnp.stack([ob.blue_pixels / PIXELS, centroid, ob.goal_pixels / PIXELS])
    return jnp.concatenate([ob.ir / IR_FULL_SCALE, tail]).astype(jnp.float32)


def goal_distance(sim: State) -> jnp.ndarray:
    """Distance from the robot's centre to the goal's centre, m."""
    return jnp.linalg.norm(sim.pose[:2] - sim.goal)


class EpuckEnv:
    """The STL task (reach the goal, avoid collisions) with gymnax 1.0's methods.

    Build it with :func:`make`. See the module docstring for the observation, action, reward,
    termination and info. Methods take ``params`` last; ``None`` means ``default_params``.
    """

    def __init__(self, params: EnvParams, auto_reset: bool = True):
        self._params = params
        self.auto_reset = auto_reset
        self._reset = jax.jit(self.reset_env)
        self._step = jax.jit(self._step_impl)

    @property
    def default_params(self) -> EnvParams:
        return self._params

    @property
    def name(self) -> str:
        return f"jaxais-{self._params.world.name}"

    @property
    def num_actions(self) -> int:
        """Size of the (continuous) action vector: the two wheel speeds."""
        return 2

    def observation_space(self, params: EnvParams | None = None) -> Box:
        low = np.zeros(len(OBS_NAMES), np.float32)
        low[OBS_NAMES.index("centroid")] = -1.0
        return Box(low, np.ones(len(OBS_NAMES), np.float32), (len(OBS_NAMES),))

    def action_space(self, params: EnvParams | None = None) -> Box:
        return Box(-np.ones(2, np.float32), np.ones(2, np.float32), (2,))

    def reset(self, key: jax.Array, params: EnvParams | None = None) -> tuple[jax.Array, EnvState]:
        """A fresh episode: ``(obs [11], state)``; placements and sensor noise from ``key``."""
        params = self._params if params is None else params
        return self._reset(key, params)

    def step(
        self,
        key: jax.Array,
        state: EnvState,
        action: jax.Array,
        params: EnvParams | None = None,
    ) -> tuple[jax.Array, EnvState, jax.Array, jax.Array, jax.Array, dict[str, jax.Array]]:
        """One 32 ms step, auto-resetting at the end of an episode (unless ``auto_reset=False``).

        Args:
            key: PRNG key for this step (the simulator's noise, and a reset if the episode ends).
            state: the episode's state. action: [2] wheel speeds in [-1, 1].
            params: the environment's parameters (default: ``default_params``).

        Returns:
            ``(obs [11], state, reward, terminated, truncated, info)``; gymnax's ``done`` is
            ``terminated | truncated``.
        """
        params = self._params if params is None else params
        return self._step(key, state, action, params)

    def _step_impl(self, key, state, action, params):
        k_step, k_reset = jax.random.split(key)
        obs, new, reward, terminated, truncated, info = self.step_env(k_step, state, action, params)
        if self.auto_reset:
            # A real branch when unbatched; under vmap both sides run (a select).
            obs, new = jax.lax.cond(
                terminated | truncated,
                lambda: self.reset_env(k_reset, params),
                lambda: (obs, new),
            )
        return obs, new, reward, terminated, truncated, info

    def reset_env(self, key: jax.Array, params: EnvParams) -> tuple[jax.Array, EnvState]:
        """:meth:`reset` without jit and without defaults (gymnax's name)."""
        k_reset, k_obs = jax.random.split(key)
        sim = sim_reset(k_reset, params.world, params.sim)
        ob = observe(k_obs, sim, params.world, params.sim)
        state = EnvState(
            sim=sim,
            collisions=jnp.zeros((), jnp.int32),
            free=jnp.ones((), bool),
            streak=jnp.zeros((), jnp.int32),
        )
        return features(ob), state

    def step_env(
        self, key: jax.Array, state: EnvState, action: jax.Array, params: EnvParams
    ) -> tuple[jax.Array, EnvState, jax.Array, jax.Array, jax.Array, dict[str, jax.Array]]:
        """One step without auto-reset (gymnax's name); arguments and results as :meth:`step`."""
        wheels = jnp.clip(jnp.asarray(action, jnp.float32), -1.0, 1.0) * params.sim.max_speed
        sim, ob = sim_step(key, state.sim, wheels, params.world, params.sim)
        before, after = goal_distance(state.sim), goal_distance(sim)
        # One collision per contact episode (SPEC 9): a contact counts when the robot has been
        # clear of obstacles since the last counted one.
        counted = (ob.vm >= params.collision_level) & state.free
        free = (state.free & ~counted) | (ob.vm < params.clear_level)
        collisions = state.collisions + counted.astype(jnp.int32)
        streak = jnp.where(ob.goal_pixels > params.finish_pixels, state.streak + 1, 0)
        terminated = streak >= params.finish_streak
        truncated = (sim.t >= params.max_steps) & ~terminated
        reward = (
            params.progress_scale * (before - after)
            - params.collision_penalty * counted
            + params.finish_bonus * terminated
        ).astype(jnp.float32)
        new = EnvState(sim=sim, collisions=collisions, free=free, streak=streak.astype(jnp.int32))
        info = {
            "collisions": collisions,
            "distance": after,
            "goal_pixels": ob.goal_pixels,
            "max_ir": ob.vm,
            "discount": jnp.where(terminated, 0.0, 1.0).astype(jnp.float32),
        }
        return features(ob), new, reward, terminated, truncated, info

    def is_terminal(self, state: EnvState, params: EnvParams | None = None) -> jax.Array:
        """Whether ``state`` ends an episode (terminated or truncated)."""
        params = self._params if params is None else params
        return (state.streak >= params.finish_streak) | (state.sim.t >= params.max_steps)

    def discount(self, state: EnvState, params: EnvParams | None = None) -> jax.Array:
        """0.0 once the target is found, else 1.0 (gymnax's ``discount``)."""
        params = self._params if params is None else params
        return jnp.where(state.streak >= params.finish_streak, 0.0, 1.0)

    def __repr__(self) -> str:
        return f"EpuckEnv({self._params.world.name!r}, max_steps={self._params.max_steps})"


_PARAM_NAMES = tuple(
    f.name for f in dataclasses.fields(EnvParams) if f.name not in ("world", "sim")
)


def make(
    world: str | Path | World = "world1",
    *,
    sim_params: SimParams | None = None,
    auto_reset: bool = True,
    **overrides: float,
) -> EpuckEnv:
    """The environment of a world: a built-in name (``world1``, ``world2``, ``real``,
    ``ga_maze``), a world file's path, or a loaded :class:`World`.

    Args:
        world: which world.
        sim_params: the robot's constants (default: ``default_params()``).
        auto_reset: whether ``step`` starts a new episode when one ends (gymnax does).
        **overrides: :class:`EnvParams` fields, e.g. ``max_steps=2000``, ``collision_penalty=5``.

    Raises:
        WorldError: the world file is missing or malformed.
        ValueError: an unknown or invalid override.
    """
    unknown = sorted(set(overrides) - set(_PARAM_NAMES))
    if unknown:
        raise ValueError(
            f"unknown environment parameter(s): {', '.join(unknown)} "
            f"(known: {', '.join(_PARAM_NAMES)})"
        )
    for name in ("max_steps", "finish_streak"):
        if name in overrides and (int(overrides[name]) != overrides[name] or overrides[name] < 1):
            raise ValueError(f"{name} must be a positive integer, got {overrides[name]!r}")
    w = world if isinstance(world, World) else load_world(world)
    sim = default_params() if sim_params is None else sim_params
    fields = {"max_steps": round(PAPER_TIME_CAP / sim.dt), **overrides}
    for name in ("max_steps", "finish_pixels", "finish_streak"):
        if name in fields:
            fields[name] = int(fields[name])
    return EpuckEnv(EnvParams(world=w, sim=sim, **fields), auto_reset=auto_reset)
