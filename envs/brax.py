"""The environment of :mod:`jaxais.envs.gymnax` as a brax ``Env``, for brax's training code.

Needs brax (``pip install 'jaxais[brax]'``); nothing else in jaxais imports this module. brax's
trainers take it as it is: ``ppo.train(BraxEnv("world1"), ...)`` (``examples/brax_ppo.py``).

brax's ``step(state, action)`` takes no key: the wrapper keeps one in ``state.info["rng"]``
(split from the reset's key) and splits it every step. The brax ``State`` holds:

- ``pipeline_state``: the gymnax-style :class:`~jaxais.envs.gymnax.EnvState`;
- ``obs`` [11], ``reward``: as :class:`~jaxais.envs.gymnax.EpuckEnv` defines them;
- ``done``: 1.0 when the episode terminated (target found) or was truncated at
  ``max_steps_in_episode``; ``info["truncation"]`` is 1.0 in the second case (brax's convention;
  brax's ``EpisodeWrapper`` overwrites it with its own ``episode_length`` cap, so keep
  ``max_steps_in_episode`` at or above that, as the default of 125,000 steps is);
- ``metrics`` (:data:`METRICS`), per step as brax's ``EpisodeWrapper`` sums them:
  ``collision`` (1.0 on the step that counted a collision), ``progress`` (metres of approach
  to the goal this step) and ``found`` (1.0 on the step that found the target); keys added by
  brax's wrappers (``reward``) are kept.

Auto-reset: brax's ``AutoResetWrapper`` (``brax.envs.training.wrap``, used by its trainers)
restarts a finished episode from ``info["first_pipeline_state"]``. So that episodes do not all
restart from their environment's first placement, ``reset`` samples ``resets`` placements (16 by
default; the first is the episode's) into ``info["placements"]`` and every ``step`` writes a
random one of them into ``info["first_pipeline_state"]``/``info["first_obs"]`` when those keys
are there: a gather, not a reset (which under ``vmap`` would run every step). ppo's
``num_resets_per_eval`` draws new pools; ``resets=0`` keeps brax's behaviour.

:func:`register` adds every built-in world to brax's registry (``brax.envs.create(
"jaxais_world1", episode_length=...)``, ``brax.envs.get_environment(name, backend=...)``).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .gymnax import OBS_NAMES, EnvParams, EpuckEnv, goal_distance, make
from .world import BUILTIN_WORLDS, World

try:
    from brax import envs as _brax_envs
    from brax.envs.base import Env as _BraxEnvBase
    from brax.envs.base import State as BraxState
except ImportError as err:  # brax is optional
    raise ImportError(
        "jaxais.envs.brax needs brax: install the brax extra: pip install 'jaxais[brax]'"
    ) from err

__all__ = ["METRICS", "BraxEnv", "BraxState", "register"]


METRICS = ("collision", "progress", "found")
"""Entries of ``State.metrics``, per step (float32)."""


def _device_put_replicated(x: Any, devices: list) -> Any:
    """``x`` stacked once per device, sharded over ``devices``: brax's own replacement."""
    mesh = jax.sharding.Mesh(np.array(devices), ("replicas",))
    sharding = jax.NamedSharding(mesh, jax.P("replicas"))
    stack = lambda a: (jnp if isinstance(a, jax.Array) else np).stack([a] * len(devices))
    return jax.tree.map(lambda a: jax.device_put(stack(a), sharding), x)


try:
    jax.device_put_replicated  # noqa: B018
except AttributeError:
    # brax 0.14.2 (the newest release) calls jax.device_put_replicated, which jax 0.10 removed;
    # brax's main branch inlines this definition (commit 303d89d). Drop when brax > 0.14.2.
    jax.device_put_replicated = _device_put_replicated


class BraxEnv(_BraxEnvBase):
    """A jaxais world as a brax ``Env`` (``reset(rng)``, ``step(state, action)``).

    Args:
        world: a built-in world name, a world file's path, a loaded ``World``, or an
            :class:`~jaxais.envs.gymnax.EpuckEnv` (its default parameters are used).
        params: the environment's parameters (default: the environment's defaults).
        resets: placements sampled per ``reset`` for brax's auto-reset to draw from (0: none).
        **overrides: as for :func:`jaxais.envs.make` (``max_steps_in_episode``, ...).
    """

    def __init__(
        self,
        world: str | Path | World | EpuckEnv = "world1",
        params: EnvParams | None = None,
        resets: int = 16,
        **overrides: Any,
    ):
        if isinstance(world, EpuckEnv):
            if overrides:
                raise ValueError("pass overrides to make(), not with an environment")
            self._env = world
        else:
            self._env = make(world, auto_reset=False, **overrides)
        if int(resets) != resets or resets < 0:
            raise ValueError(f"resets must be a non-negative integer, got {resets!r}")
        self._params = self._env.default_params if params is None else params
        self._resets = int(resets)

    @property
    def env(self) -> EpuckEnv:
        """The gymnax-style environment underneath."""
        return self._env

    def reset(self, rng: jax.Array) -> BraxState:
        rng, key = jax.random.split(rng)
        # One (vmapped) reset program for the start and the pool: the start is the pool's first.
        keys = jax.random.split(key, max(self._resets, 1))
        pool = jax.vmap(self._env.reset_env, (0, None))(keys, self._params)
        obs, state = jax.tree.map(lambda a: a[0], pool)
        zero = jnp.zeros((), jnp.float32)
        info = {"rng": rng, "truncation": zero}
        if self._resets:
            info["placements"] = pool
        return BraxState(
            pipeline_state=state,
            obs=obs,
            reward=zero,
            done=zero,
            metrics={name: zero for name in METRICS},
            info=info,
        )

    def step(self, state: BraxState, action: jax.Array) -> BraxState:
        rng, key, k_pick = jax.random.split(state.info["rng"], 3)
        before = state.pipeline_state
        obs, env_state, reward, terminated, info = self._env.step_env(
            key, before, action, self._params
        )
        truncated = self._env.is_truncated(env_state, self._params)
        metrics = {
            "collision": info["collisions"] - before.collisions,
            "progress": goal_distance(before.sim) - info["distance"],
            "found": terminated,
        }
        new_info = {**state.info, "rng": rng, "truncation": truncated.astype(jnp.float32)}
        if self._resets and "first_pipeline_state" in state.info:
            pick = jax.random.randint(k_pick, (), 0, self._resets)
            first_obs, first = jax.tree.map(lambda a: a[pick], state.info["placements"])
            new_info.update(first_pipeline_state=first, first_obs=first_obs)
        return state.replace(
            pipeline_state=env_state,
            obs=obs,
            reward=reward,
            done=(terminated | truncated).astype(jnp.float32),
            metrics={**state.metrics, **{k: v.astype(jnp.float32) for k, v in metrics.items()}},
            info=new_info,
        )

    @property
    def observation_size(self) -> int:
        return len(OBS_NAMES)

    @property
    def action_size(self) -> int:
        return self._env.num_actions

    @property
    def backend(self) -> str:
        return "jaxais"


def _factory(world: str, backend: str | None = None, **kwargs: Any) -> BraxEnv:
    # brax's get_environment passes backend= (mjx, generalized, ...); jaxais has one simulator.
    return BraxEnv(world, **kwargs)


def register(prefix: str = "jaxais_") -> tuple[str, ...]:
    """Add every built-in world to brax's registry as ``{prefix}{world}``; returns the names."""
    names = []
    for world in BUILTIN_WORLDS:
        _brax_envs.register_environment(prefix + world, functools.partial(_factory, world))
        names.append(prefix + world)
    return tuple(names)
