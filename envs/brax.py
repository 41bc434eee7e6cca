"""The environment of :mod:`jaxais.envs.gymnax` as a brax ``Env``, for brax's training code.

Needs brax (``pip install 'jaxais[brax]'``); nothing else in jaxais imports this module::

    from brax.training.agents.ppo import train as ppo
    from jaxais.envs.brax import BraxEnv

    env = BraxEnv("world1", max_steps=125_000)
    make_policy, params, metrics = ppo.train(env, num_timesteps=..., episode_length=2000, ...)

brax's ``step(state, action)`` takes no key: the wrapper keeps one in ``state.info["rng"]``
(split from the reset's key) and splits it every step. The brax ``State`` holds:

- ``pipeline_state``: the gymnax-style :class:`~jaxais.envs.gymnax.EnvState` (brax's
  ``AutoResetWrapper`` restores the first one at the end of an episode, as for its own envs);
- ``obs`` [11], ``reward``: as :class:`~jaxais.envs.gymnax.EpuckEnv` defines them;
- ``done``: 1.0 when the episode terminated (target found) or was truncated at ``max_steps``;
  ``info["truncation"]`` is 1.0 in the second case (brax's convention; brax's
  ``EpisodeWrapper`` overwrites it with its own ``episode_length`` cap, so keep ``max_steps``
  at or above that, as the default of 125,000 steps is);
- ``metrics``: ``collisions``, ``distance``, ``goal_pixels`` (float32).

:func:`register` adds every built-in world to brax's registry (``brax.envs.create(
"jaxais_world1", episode_length=...)``).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp

from .gymnax import OBS_NAMES, EnvParams, EpuckEnv, make
from .world import BUILTIN_WORLDS, World

try:
    from brax import envs as _brax_envs
    from brax.envs.base import Env as _BraxEnvBase
    from brax.envs.base import State as BraxState
except ImportError as err:  # brax is optional
    raise ImportError(
        "jaxais.envs.brax needs brax: install the brax extra: pip install 'jaxais[brax]'"
    ) from err

__all__ = ["BraxEnv", "BraxState", "register"]


METRICS = ("collisions", "distance", "goal_pixels")
"""Entries of ``State.metrics`` (from the step's info, as float32)."""


def _metrics(info: dict[str, jax.Array]) -> dict[str, jax.Array]:
    return {name: info[name].astype(jnp.float32) for name in METRICS}


class BraxEnv(_BraxEnvBase):
    """A jaxais world as a brax ``Env`` (``reset(rng)``, ``step(state, action)``).

    Args:
        world: a built-in world name, a world file's path, a loaded ``World``, or an
            :class:`~jaxais.envs.gymnax.EpuckEnv` (its default parameters are used).
        params: the environment's parameters (default: the environment's defaults).
        **overrides: as for :func:`jaxais.envs.make` (``max_steps``, ``collision_penalty``, ...).
    """

    def __init__(
        self,
        world: str | Path | World | EpuckEnv = "world1",
        params: EnvParams | None = None,
        **overrides: Any,
    ):
        if isinstance(world, EpuckEnv):
            if overrides:
                raise ValueError("pass overrides to make(), not with an environment")
            self._env = world
        else:
            self._env = make(world, auto_reset=False, **overrides)
        self._params = self._env.default_params if params is None else params

    @property
    def env(self) -> EpuckEnv:
        """The gymnax-style environment underneath."""
        return self._env

    def reset(self, rng: jax.Array) -> BraxState:
        rng, key = jax.random.split(rng)
        obs, state = self._env.reset_env(key, self._params)
        zero = jnp.zeros((), jnp.float32)
        metrics = {name: zero for name in METRICS}
        return BraxState(
            pipeline_state=state,
            obs=obs,
            reward=zero,
            done=zero,
            metrics=metrics,
            info={"rng": rng, "truncation": zero},
        )

    def step(self, state: BraxState, action: jax.Array) -> BraxState:
        rng, key = jax.random.split(state.info["rng"])
        obs, env_state, reward, terminated, truncated, info = self._env.step_env(
            key, state.pipeline_state, action, self._params
        )
        done = (terminated | truncated).astype(jnp.float32)
        return state.replace(
            pipeline_state=env_state,
            obs=obs,
            reward=reward,
            done=done,
            metrics=_metrics(info),
            info={**state.info, "rng": rng, "truncation": truncated.astype(jnp.float32)},
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


def register(prefix: str = "jaxais_") -> tuple[str, ...]:
    """Add every built-in world to brax's registry as ``{prefix}{world}``; returns the names."""
    names = []
    for world in BUILTIN_WORLDS:
        _brax_envs.register_environment(prefix + world, functools.partial(BraxEnv, world))
        names.append(prefix + world)
    return tuple(names)
