"""The :mod:`jaxais.envs.gymnax` environment as a brax ``Env`` (``pip install 'jaxais[brax]'``).

``ppo.train(BraxEnv("world1"), ...)`` (``examples/brax_ppo.py``); :func:`register` adds the
built-in worlds to brax's registry as ``jaxais_{world}``. ``step`` takes no key: one rides in
``info["rng"]``. ``pipeline_state`` is the :class:`~jaxais.envs.gymnax.EnvState`; ``done`` is 1.0
when terminated or truncated, ``info["truncation"]`` 1.0 in the second case (brax's
``EpisodeWrapper`` overwrites it with its ``episode_length`` cap: keep ``max_steps_in_episode``
above that). ``metrics`` (:data:`METRICS`) per step: ``collision`` (1.0 when one is counted),
``progress`` (m toward the goal), ``found``; ``info["invalid_action"]``: the action was not
finite (the step dropped, as in the gymnax face; eagerly such an action, or one of another
shape, is refused). brax's ``AutoResetWrapper`` restarts from
``info["first_pipeline_state"]``: so that episodes do not all restart from one placement,
``reset`` draws ``resets`` placements and ``step`` writes a random one there (a gather, not a
reset); ``resets=0`` keeps brax's behaviour.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .gymnax import (
    OBS_NAMES,
    EnvParams,
    EpuckEnv,
    check_action,
    check_params,
    goal_distance,
    make,
)
from .struct import check_type
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


METRICS = ("collision", "progress", "found")  # State.metrics, float32 per step


def _device_put_replicated(x: Any, devices: list) -> Any:
    """``x`` stacked once per device, sharded over ``devices`` (brax main's definition)."""
    mesh = jax.sharding.Mesh(np.array(devices), ("replicas",))
    sharding = jax.NamedSharding(mesh, jax.P("replicas"))
    stack = lambda a: (jnp if isinstance(a, jax.Array) else np).stack([a] * len(devices))
    return jax.tree.map(lambda a: jax.device_put(stack(a), sharding), x)


# brax 0.14.2 (the newest release) calls jax.device_put_replicated, which jax 0.10 removed;
# brax's main branch inlines the definition above (commit 303d89d). Drop when brax > 0.14.2.
jax.device_put_replicated = getattr(jax, "device_put_replicated", _device_put_replicated)


class BraxEnv(_BraxEnvBase):
    """A world (as :func:`~jaxais.envs.gymnax.make` takes it, with its ``overrides``, or an
    ``EpuckEnv``) as a brax ``Env``; ``resets``: placements drawn per ``reset`` (0: none)."""

    def __init__(
        self,
        world: str | Path | World | EpuckEnv = "world1",
        params: EnvParams | None = None,
        resets: int = 16,
        **overrides: Any,
    ):
        if "backend" in overrides:  # brax.envs.get_environment's argument (mjx, generalized...)
            raise ValueError(
                f"backend={overrides['backend']!r} is an argument of brax's get_environment, not "
                "of BraxEnv: jaxais has one simulator, leave it out"
            )
        check_type(resets, int | np.integer, "resets", "a non-negative integer")
        if resets < 0:
            raise ValueError(f"resets must be a non-negative integer, got {resets!r}")
        if params is not None:
            check_params(params)
        if isinstance(world, EpuckEnv):
            if overrides:
                raise ValueError("pass overrides to make(), not with an environment")
            self._env = world
        else:
            self._env = make(world, auto_reset=False, **overrides)
        self._params = self._env.default_params if params is None else params
        self._resets = int(resets)

    @property
    def env(self) -> EpuckEnv:
        return self._env

    def reset(self, rng: jax.Array) -> BraxState:
        rng, key = jax.random.split(rng)
        # One (vmapped) reset program for the start and the pool: the start is the pool's first.
        keys = jax.random.split(key, max(self._resets, 1))
        pool = jax.vmap(self._env.reset_env, (0, None))(keys, self._params)
        obs, state = jax.tree.map(lambda a: a[0], pool)
        zero = jnp.zeros((), jnp.float32)
        # invalid_action: the step's action was not finite, and was dropped (its state kept).
        info = {"rng": rng, "truncation": zero, "invalid_action": jnp.zeros((), bool)}
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
        check_action(action)  # eagerly its shape and values; traced, its shape
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
        new_info = {**state.info, "rng": rng, "truncation": truncated.astype(jnp.float32),
                    "invalid_action": info["invalid_action"]}  # fmt: skip
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
    """Add every built-in world to brax's registry as ``{prefix}{world}``; returns the names (a
    world on ``JAXAIS_WORLDS`` is made by name: ``BraxEnv("NAME")``)."""
    for world in BUILTIN_WORLDS:
        _brax_envs.register_environment(prefix + world, functools.partial(_factory, world))
    return tuple(prefix + world for world in BUILTIN_WORLDS)
