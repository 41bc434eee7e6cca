"""The STL task as a gymnax 1.0 environment: ``make("world1")`` or ``gymnax.make("jaxais/world1")``.

Drive an e-puck to the blue goal without crashing (README "gymnax"). ``register_gymnax()`` adds
the built-in worlds to gymnax's registry (evosax's ``GymnaxProblem`` finds them); gymnax's
wrappers take the env as it is. Tools written for gymnax before 1.0, whose ``step`` returned five
values (rejax 0.1), take ``make(..., legacy_step=True)`` (an :class:`EpuckEnv` itself) or
gymnax's ``LegacyStepAPIWrapper``.

- obs [11] float32 (``OBS_NAMES``): IR ps0..ps7 / 4095; blue pixels / 45; blue centroid column
  in [-1, 1] (0 when none seen); goal pixels / 45.
- action [2]: (left, right) wheel speeds, clipped to [-1, 1], times ``SimParams.max_speed``.
- reward: ``progress_scale`` x metres gained toward the goal, minus ``collision_penalty`` per
  counted collision (one per contact episode, SPEC 9), plus ``finish_bonus`` on finding it.
- terminated: the paper's finish rule; truncated: ``max_steps_in_episode`` steps; never both.
- info: ``collisions``, ``distance`` (m), ``goal_pixels``, ``max_ir``, ``discount``,
  ``invalid_action`` (the action was not finite: the step was dropped, the state kept, reward 0);
  ``step`` adds gymnax's ``terminated``, ``truncated``, ``final_observation``.

Auto-reset is cheap: ``reset`` also draws ``reset_pool`` starts into the state and an ended
episode restarts from one (a gather and a select), where gymnax's ``step`` runs ``reset_env``
every step (10-15x a step under ``vmap``). ``refresh_pool=True`` redraws the start an ended
episode took, so a loop that resets once meets fresh placements (a ``cond``: free unbatched, a
fresh start every step under ``vmap``). ``auto_reset=False``: ``step`` never resets.

Environments are equal (and hash alike) when their class, settings and ``default_params``
are, so a deep copy shares its original's compiled ``reset`` and ``step``; gymnax's wrappers
around one deep-copy and pickle as themselves.
Outside jit, ``make``, ``reset`` and ``step`` reject ``EnvParams`` fields of the wrong type, out
of range or out of order, and bad keys and actions, with a one-line ``ValueError``; traced values
are not checked, but an action's shape is (it is static) and a non-finite action is flagged.
"""

from __future__ import annotations

import copyreg
import functools
import hashlib
from pathlib import Path
from typing import Any

import gymnax
import jax
import jax.numpy as jnp
import numpy as np
from gymnax.environments import environment, spaces

from .params import (
    CAMERA_COLUMNS,
    IR_FULL_SCALE,
    IR_TABLE_VALUE,
    OBS_NAMES,
    PIXELS,
    SimParams,
    default_params,
)
from .sim import Observation, State
from .sim import observe as sim_observe
from .sim import reset as sim_reset
from .sim import step as sim_step
from .struct import ArgumentTypeError, check_type, pytree_dataclass
from .world import BUILTIN_WORLDS, World, load_world

PAPER_TIME_CAP = 4000.0
"""The paper's time cap, simulated seconds."""
RESET_POOL = 8
"""Episode starts drawn per environment by ``reset`` for the auto-reset (``make(reset_pool=)``)."""


@pytree_dataclass
class EnvParams:
    """The world, the robot and the task's constants, every field a traced leaf (one ``vmap``
    batches them). Truncated after ``max_steps_in_episode`` [paper: 4000 s = 125,000 steps]; a
    contact is max IR >= ``collision_level`` [paper: 2400] after max IR < ``clear_level``
    [paper: 250]; found is > ``finish_pixels`` goal pixels [paper: 40] on ``finish_streak``
    consecutive steps [paper: 3]."""

    world: World
    sim: SimParams
    max_steps_in_episode: int = round(PAPER_TIME_CAP / 0.032)
    progress_scale: float = 10.0
    collision_penalty: float = 1.0
    finish_bonus: float = 10.0
    collision_level: float = 2400.0
    clear_level: float = 250.0
    finish_pixels: int = 40
    finish_streak: int = 3


# field: (low, high, integer): every value finite. A penalty or bonus of the wrong sign rewards
# collisions or punishes finding the goal.
_RANGES = {
    "max_steps_in_episode": (1, np.inf, True),
    "progress_scale": (-np.inf, np.inf, False),
    "collision_penalty": (0, np.inf, False),
    "finish_bonus": (0, np.inf, False),
    "collision_level": (0, IR_FULL_SCALE, False),
    "clear_level": (0, IR_FULL_SCALE, False),
    "finish_pixels": (0, PIXELS, True),
    "finish_streak": (1, np.inf, True),
}
IR_FLOOR = float(IR_TABLE_VALUE[-1])  # the IR reading with nothing in range (SPEC 2)


def check_params(params: Any) -> EnvParams:
    """``params``, or a one-line ``ValueError`` naming a concrete field of the wrong type (a bool
    or a string is no number), out of range, or levels out of order (a contact needs
    ``IR_FLOOR < clear_level <= collision_level``: else no second one is ever counted)."""
    if not isinstance(params, EnvParams):
        raise ArgumentTypeError(
            f"params must be an EnvParams (env.default_params.replace(...)), "
            f"got {type(params).__name__}"
        )
    concrete = {}
    for name, (low, high, integer) in _RANGES.items():
        value = getattr(params, name)
        if isinstance(value, jax.core.Tracer):
            continue
        kind = "an integer" if integer else "a number"
        x = np.asarray(value) if isinstance(value, np.ndarray | jax.Array) else value
        if not isinstance(x, np.ndarray):
            check_type(x, int | float | np.integer | np.floating, f"EnvParams.{name}", kind)
            x = np.asarray(x)
        elif x.dtype.kind not in "iuf":
            raise ArgumentTypeError(f"EnvParams.{name} must be {kind}, got {x.dtype} {value!r:.40}")
        x = x.astype(np.float64)
        ok = np.isfinite(x) & (x >= low) & (x <= high)
        if not np.all(ok & (x == np.round(x)) if integer else ok):
            what = (
                f"{kind} in [{low:g}, {high:g}]" if high < np.inf
                else f"{kind} >= {low:g}" if low > -np.inf
                else "a finite number"
            )  # fmt: skip
            raise ValueError(f"EnvParams.{name} must be {what}, got {value!r}")
        concrete[name] = x
    if "clear_level" in concrete and np.any(concrete["clear_level"] <= IR_FLOOR):
        raise ValueError(
            f"EnvParams.clear_level must exceed {IR_FLOOR:g}, the IR reading with nothing in range"
            f" (levels are raw readings 0..4095, not the observation's), got {params.clear_level!r}"
        )
    if {"clear_level", "collision_level"} <= concrete.keys() and np.any(
        concrete["clear_level"] > concrete["collision_level"]
    ):
        raise ValueError(
            f"EnvParams.clear_level ({params.clear_level!r}) must be <= collision_level "
            f"({params.collision_level!r}): a contact counts at collision_level, the next once "
            "the reading falls below clear_level"
        )
    return params


def check_key(key: Any) -> None:
    """A one-line ValueError unless ``key`` is a PRNG key (``jax.random.key(0)``) or an array."""
    if not isinstance(key, jax.Array | np.ndarray):
        got = type(key).__name__
        raise ArgumentTypeError(f"key must be a PRNG key (jax.random.key(0)), got {got}")


def check_action(action: Any, eager: bool = True) -> None:
    """A one-line ValueError unless ``action`` has shape (2,) (a traced one too: its shape is
    static) and, concrete and ``eager``, is finite."""
    traced = isinstance(action, jax.core.Tracer)
    try:
        a = action if traced else np.asarray(action, np.float64)
        bad = np.shape(a) != (2,) or (eager and not traced and not np.all(np.isfinite(a)))
    except (TypeError, ValueError):  # not numbers, or a ragged list
        a, bad = action, True
    if bad:
        shape = f"shape {np.shape(a)}" if traced else " ".join(f"{action!r:.80}".split())
        raise ValueError(
            f"action must be 2 finite wheel speeds (left, right) in [-1, 1], shape (2,), got "
            f"{shape}"
        )


def check_env_args(params: Any, auto_reset: Any, reset_pool: Any) -> None:
    """The environment's constructor arguments: types first, then ranges (one line each)."""
    check_type(auto_reset, bool | np.bool_, "auto_reset", "True or False")
    check_type(reset_pool, int | np.integer, "reset_pool", "a positive integer")
    if reset_pool < 1:
        raise ValueError(f"reset_pool must be a positive integer, got {reset_pool!r}")
    check_params(params)


@pytree_dataclass
class EnvState:
    """One episode: ``sim`` (``sim.t`` counts steps), int32 ``collisions`` so far, bool ``free``
    (clear since the last counted one), int32 ``streak`` of finish-rule steps, and the auto-reset's
    ``starts`` ``(obs [K, 11], sim State [K, ...])`` (None without auto-reset)."""

    sim: State
    collisions: jnp.ndarray
    free: jnp.ndarray
    streak: jnp.ndarray
    starts: tuple[jnp.ndarray, State] | None = None


def features(ob: Observation) -> jnp.ndarray:
    """The simulator's observation as the environment's float32 vector [11] (``OBS_NAMES``)."""
    seen = ob.blue_pixels > 0
    half = (CAMERA_COLUMNS - 1) / 2
    centroid = jnp.where(seen, (ob.blue_centroid - half) / half, 0.0)
    tail = jnp.stack([ob.blue_pixels / PIXELS, centroid, ob.goal_pixels / PIXELS])
    return jnp.concatenate([ob.ir / IR_FULL_SCALE, tail]).astype(jnp.float32)


def goal_distance(sim: State) -> jnp.ndarray:
    """Distance from the robot's centre to the goal's centre, m."""
    return jnp.linalg.norm(sim.pose[:2] - sim.goal)


def _fresh(sim: State) -> EnvState:
    """The state at an episode's start (no pool)."""
    zero = jnp.zeros((), jnp.int32)
    return EnvState(sim=sim, collisions=zero, free=jnp.ones((), bool), streak=zero)


class EpuckEnv(environment.Environment):
    """The STL task as a gymnax 1.0 environment (build it with :func:`make`); ``params=None``
    means ``default_params``."""

    def __init__(
        self,
        params: EnvParams,
        auto_reset: bool = True,
        reset_pool: int = RESET_POOL,
        refresh_pool: bool = False,
    ):
        check_env_args(params, auto_reset, reset_pool)
        check_type(refresh_pool, bool | np.bool_, "refresh_pool", "True or False")
        self._params = params
        self.auto_reset = auto_reset
        self.reset_pool = reset_pool
        self.refresh_pool = refresh_pool
        self._digest: bytes | None = None

    @property
    def default_params(self) -> EnvParams:
        return self._params

    @property
    def name(self) -> str:
        return f"jaxais/{self._params.world.name}"

    @property
    def num_actions(self) -> int:
        return 2

    def observation_space(self, params: EnvParams | None = None) -> spaces.Box:
        low = np.zeros(len(OBS_NAMES), np.float32)
        low[OBS_NAMES.index("centroid")] = -1.0
        return spaces.Box(low, np.ones(len(OBS_NAMES), np.float32), (len(OBS_NAMES),))

    def action_space(self, params: EnvParams | None = None) -> spaces.Box:
        return spaces.Box(-np.ones(2, np.float32), np.ones(2, np.float32), (2,))

    def _checked(self, params: EnvParams | None) -> EnvParams:
        # The defaults substituted outside jit: they reach the program as arguments, not
        # constants (as gymnax's own reset and step would bake them in).
        return self._params if params is None else check_params(params)

    def reset(self, key: jax.Array, params: EnvParams | None = None) -> tuple[jax.Array, EnvState]:
        """A fresh episode: ``(obs [11], state)``; placements and sensor noise from ``key``."""
        check_key(key)
        return self._reset(key, self._checked(params))

    @functools.partial(jax.jit, static_argnames="self")
    def _reset(self, key, params):
        return self.reset_env(key, params)

    def step(
        self,
        key: jax.Array,
        state: EnvState,
        action: jax.Array,
        params: EnvParams | None = None,
    ) -> tuple[jax.Array, EnvState, jax.Array, jax.Array, jax.Array, dict[str, jax.Array]]:
        """One 32 ms step of wheel speeds ``action`` [2], a new episode after the last (with
        auto-reset): ``(obs [11], state, reward, terminated, truncated, info)``. A wrong action
        shape is refused, under jit too (when traced); a non-finite action eagerly, and under jit
        it leaves the state as it was (``info["invalid_action"]``)."""
        check_key(key)
        check_action(action)
        return self._step(key, state, action, self._checked(params))

    @functools.partial(jax.jit, static_argnames="self")
    def _step(self, key, state, action, params):
        k_step, k_reset = jax.random.split(key)
        obs, new, reward, terminated, info = self.step_env(k_step, state, action, params)
        truncated = self.is_truncated(new, params)
        info = {**info, "terminated": terminated, "truncated": truncated, "final_observation": obs}
        if self.auto_reset:
            # A gather and a select (the starts were drawn by reset), the pool kept out of both.
            i = jax.random.randint(k_reset, (), 0, self.reset_pool)
            start_obs, start = jax.tree.map(lambda x: x[i], state.starts)
            done = terminated | truncated
            obs, new = jax.tree.map(
                lambda a, b: jnp.where(done, a, b),
                (start_obs, _fresh(start)),
                (obs, new.replace(starts=None)),
            )
            starts = state.starts
            if self.refresh_pool:
                # From a key of its own: the episodes are refresh_pool=False's until a slot is
                # taken a second time.
                k_fresh = jax.random.fold_in(k_reset, 1)
                starts = jax.lax.cond(
                    done, lambda: self._redraw(k_fresh, starts, i, params), lambda: starts
                )
            new = new.replace(starts=starts)
        return obs, new, reward, terminated, truncated, info

    def _redraw(self, key, starts, i, params):
        """``starts`` with slot ``i`` replaced by a fresh start from ``key``."""
        fresh_obs, fresh = self._start(key, params)
        return jax.tree.map(lambda pool, x: pool.at[i].set(x), starts, (fresh_obs, fresh.sim))

    def reset_env(self, key: jax.Array, params: EnvParams) -> tuple[jax.Array, EnvState]:
        """:meth:`reset` without jit, defaults or checks (gymnax's name)."""
        obs, state = self._start(key, params)
        if self.auto_reset:
            keys = jax.random.split(jax.random.fold_in(key, 1), self.reset_pool)
            pool_obs, pool = jax.vmap(self._start, in_axes=(0, None))(keys, params)
            state = state.replace(starts=(pool_obs, pool.sim))
        return obs, state

    def _start(self, key: jax.Array, params: EnvParams) -> tuple[jax.Array, EnvState]:
        k_reset, k_obs = jax.random.split(key)
        state = _fresh(sim_reset(k_reset, params.world, params.sim))
        return self.observe(k_obs, state, None, params), state

    def observe(self, key: jax.Array, state: EnvState, action: Any, params: EnvParams) -> jax.Array:
        """The observation [11] of ``state`` with sensor noise from ``key`` (gymnax's hook)."""
        return features(sim_observe(key, state.sim, params.world, params.sim))

    def step_env(
        self, key: jax.Array, state: EnvState, action: jax.Array, params: EnvParams
    ) -> tuple[jax.Array, EnvState, jax.Array, jax.Array, dict[str, jax.Array]]:
        """One step, no reset: ``(obs, state, reward, terminated, info)`` (gymnax's). The action's
        shape is checked as it is traced; a non-finite action keeps ``state`` (reward 0, not
        terminated) and sets ``info["invalid_action"]``."""
        check_action(action, eager=False)
        action = jnp.asarray(action, jnp.float32)
        invalid = ~jnp.all(jnp.isfinite(action))
        # The step runs on a safe action, then is dropped: NaN must not reach the state.
        action = jnp.where(invalid, 0.0, action)
        wheels = jnp.clip(action, -1.0, 1.0) * params.sim.max_speed
        sim, ob = sim_step(key, state.sim, wheels, params.world, params.sim)
        before, after = goal_distance(state.sim), goal_distance(sim)
        # One collision per contact episode (SPEC 9): a contact counts when the robot has been
        # clear of obstacles since the last counted one.
        counted = (ob.vm >= params.collision_level) & state.free
        free = (state.free & ~counted) | (ob.vm < params.clear_level)
        collisions = state.collisions + counted.astype(jnp.int32)
        streak = jnp.where(ob.goal_pixels > params.finish_pixels, state.streak + 1, 0)
        terminated = streak >= params.finish_streak
        reward = (
            params.progress_scale * (before - after)
            - params.collision_penalty * counted
            + params.finish_bonus * terminated
        ).astype(jnp.float32)
        new = state.replace(
            sim=sim, collisions=collisions, free=free, streak=streak.astype(jnp.int32)
        )
        # The step is dropped for a non-finite action (the pool of starts is not touched).
        keep = lambda old, now: jnp.where(invalid, old, now)
        new = new.replace(**{k: jax.tree.map(keep, getattr(state, k), getattr(new, k))
                             for k in ("sim", "collisions", "free", "streak")})  # fmt: skip
        reward = jnp.where(invalid, 0.0, reward).astype(jnp.float32)
        terminated = terminated & ~invalid
        info = {
            "collisions": new.collisions,
            "distance": jnp.where(invalid, before, after),
            "goal_pixels": ob.goal_pixels,
            "max_ir": ob.vm,
            "discount": jnp.where(terminated, 0.0, 1.0).astype(jnp.float32),
            "invalid_action": invalid,
        }
        return features(ob), new, reward, terminated, info

    def is_terminated(self, state: EnvState, params: EnvParams) -> jax.Array:
        """Whether the target was found: the natural end (gymnax's ``is_terminal``)."""
        return state.streak >= params.finish_streak

    def is_truncated(self, state: EnvState, params: EnvParams) -> jax.Array:
        """Whether ``max_steps_in_episode`` steps ran without finding the target."""
        return (state.sim.t >= params.max_steps_in_episode) & ~self.is_terminated(state, params)

    def _key(self) -> tuple:
        """What decides the environment: class, settings and a digest of ``default_params``
        (its tree structure, static fields included, and every leaf's bytes)."""
        if self._digest is None:
            leaves, tree = jax.tree.flatten(self._params)
            if any(isinstance(x, jax.core.Tracer) for x in leaves):
                return (type(self), id(self))  # params traced: only itself is equal
            h = hashlib.sha256(repr(tree).encode())
            for x in map(np.asarray, leaves):
                h.update(f"{x.dtype.str}{x.shape}".encode())
                h.update(np.ascontiguousarray(x).tobytes())
            self._digest = h.digest()
        settings = (self.auto_reset, self.reset_pool, self.refresh_pool)
        return (type(self), settings, self._digest)

    # Equal environments share compiled programs: reset and step are jitted with the
    # environment static, so a copy (gymnax's GymnaxToGymWrapper and rejax deep-copy theirs)
    # hits its original's cache.
    def __eq__(self, other: object) -> bool:
        if self is other:
            return True
        return isinstance(other, EpuckEnv) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        name = type(self).__name__
        return f"{name}({self.name!r}, max_steps_in_episode={self._params.max_steps_in_episode})"


class LegacyEpuckEnv(EpuckEnv):
    """:class:`EpuckEnv` with gymnax 0.0's five-value ``step``: ``(obs, state, reward, done,
    info)``, ``done = terminated | truncated`` (info keeps both)."""

    def step(self, key, state, action, params=None):
        obs, state, reward, terminated, truncated, info = super().step(key, state, action, params)
        return obs, state, reward, terminated | truncated, info


def make(
    world: str | Path | World = "world1",
    *,
    sim_params: SimParams | None = None,
    auto_reset: bool = True,
    reset_pool: int = RESET_POOL,
    refresh_pool: bool = False,
    legacy_step: bool = False,
    **overrides: float,
) -> EpuckEnv:
    """The environment of a world (built-in name, file path or :class:`World`); ``overrides``
    are :class:`EnvParams` fields; ``refresh_pool``: each auto-reset redraws the start it took;
    ``legacy_step``: a :class:`LegacyEpuckEnv`. Raises ``WorldError``/``ValueError`` (one line)
    on bad input."""
    unknown = sorted(set(overrides) - set(_RANGES))
    if unknown:
        raise ValueError(
            f"unknown environment parameter(s): {', '.join(unknown)} (known: {', '.join(_RANGES)})"
        )
    if sim_params is not None and not isinstance(sim_params, SimParams):
        raise ValueError(
            f"sim_params must be a SimParams (envs.default_params(...)), "
            f"got {type(sim_params).__name__}"
        )
    check_type(world, str | Path | World, "world", "a world's name, a TOML path or a World")
    check_type(legacy_step, bool | np.bool_, "legacy_step", "True or False")
    check_type(auto_reset, bool | np.bool_, "auto_reset", "True or False")
    check_type(reset_pool, int | np.integer, "reset_pool", "a positive integer")
    if reset_pool < 1:
        raise ValueError(f"reset_pool must be a positive integer, got {reset_pool!r}")
    check_type(refresh_pool, bool | np.bool_, "refresh_pool", "True or False")
    w = world if isinstance(world, World) else load_world(world)
    sim = default_params() if sim_params is None else sim_params
    fields = {"max_steps_in_episode": round(PAPER_TIME_CAP / sim.dt), **overrides}
    params = check_params(EnvParams(world=w, sim=sim, **fields))
    params = params.replace(**{k: int(getattr(params, k)) for k, r in _RANGES.items() if r[2]})
    env = LegacyEpuckEnv if legacy_step else EpuckEnv
    return env(
        params,
        auto_reset=bool(auto_reset),
        reset_pool=int(reset_pool),
        refresh_pool=bool(refresh_pool),
    )


def register_gymnax() -> tuple[str, ...]:
    """Register the built-in worlds with gymnax as ``jaxais/{world}`` (``make``'s kwargs); a
    world on ``JAXAIS_WORLDS`` is made by name with ``make("NAME")``."""
    names = tuple(f"jaxais/{world}" for world in BUILTIN_WORLDS)
    for name, world in zip(names, BUILTIN_WORLDS, strict=True):
        if name not in gymnax.registered_envs:
            gymnax.register(name, functools.partial(make, world))
    return names


def _wraps_env(wrapper: Any) -> bool:
    """Whether ``wrapper``'s chain of ``_env`` attributes ends at an :class:`EpuckEnv`."""
    inner = vars(wrapper).get("_env")
    while inner is not None and not isinstance(inner, EpuckEnv):
        inner = getattr(inner, "__dict__", {}).get("_env")
    return inner is not None


def _rebuilt(cls: type, attributes: dict[str, Any]) -> Any:
    """A ``cls`` instance holding ``attributes`` (its ``__init__`` not run)."""
    obj = object.__new__(cls)
    obj.__dict__.update(attributes)
    return obj


def _reduce_wrapper(wrapper: Any) -> Any:
    # gymnax's wrappers forward every missing attribute to their env, so copy and pickle, which
    # look up __setstate__ on an empty instance before its _env is set, recurse without end.
    # Around this env they are rebuilt from their attributes (deep-copied first) instead; around
    # any other, gymnax's own behaviour is kept.
    if _wraps_env(wrapper):
        return _rebuilt, (type(wrapper), vars(wrapper))
    return wrapper.__reduce_ex__(4)


def _register_wrappers() -> None:
    """Register :func:`_reduce_wrapper` for gymnax's attribute-forwarding wrapper classes."""
    from gymnax.wrappers import compat, purerl

    classes, todo = [], [purerl.GymnaxWrapper, compat.LegacyStepAPIWrapper]
    while todo:
        cls = todo.pop()
        classes.append(cls)
        todo += cls.__subclasses__()
    for cls in classes:
        copyreg.pickle(cls, _reduce_wrapper)


_register_wrappers()
