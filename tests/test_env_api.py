"""The gymnax environment (``jaxais.envs.make``, ``gymnax.make("jaxais/world1")``), gymnax's
wrappers on it, its cheap auto-reset, its checks of bad input;
its brax face: tests/test_brax.py.

Every test shares one environment per auto-reset setting, so each compiled function (reset,
step, step without auto-reset, its vmapped batch) compiles once. Parameters that
a test changes (``max_steps_in_episode``) are traced leaves: they reuse the same programs.
"""

from __future__ import annotations

import copy
import functools
import pickle
from pathlib import Path

import gymnax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _python import run_python
from gymnax.environments import environment, spaces
from gymnax.wrappers import (
    FlattenObservationWrapper,
    GymnaxToGymWrapper,
    LegacyStepAPIWrapper,
    LogWrapper,
)

from jaxais import envs
from jaxais.envs import gymnax as genv

ROOT = Path(__file__).resolve().parent.parent
FAR = jnp.array([[-100.0, -100.0, 0.0]])
"""A wanderer parked outside the arena (as reset parks objects), where it meets nothing."""


@pytest.fixture(scope="module")
def env() -> genv.EpuckEnv:
    return envs.make("world1")


@pytest.fixture(scope="module")
def env_no_reset() -> genv.EpuckEnv:
    return envs.make("world1", auto_reset=False)


@pytest.fixture(scope="module")
def vstep(env_no_reset):
    """``env_no_reset.step`` jitted over a batch (keys, states, actions; shared params)."""
    return jax.jit(jax.vmap(env_no_reset.step, in_axes=(0, 0, 0, None)))


def _placed(env, key, pose, goal=None) -> genv.EnvState:
    """A fresh episode with the robot at ``pose`` (and the goal at ``goal``), wanderer parked."""
    _, state = env.reset(key)
    sim = state.sim.replace(pose=jnp.asarray(pose, jnp.float32), wanderers=FAR)
    if goal is not None:
        sim = sim.replace(goal=jnp.asarray(goal, jnp.float32))
    return state.replace(sim=sim)


def test_make_and_spaces(env):
    assert isinstance(env, envs.EpuckEnv) and isinstance(env, environment.Environment)
    assert env.num_actions == 2 and env.name == "jaxais/world1"
    params = env.default_params
    assert params.max_steps_in_episode == 125_000  # the paper's 4000 s at 32 ms
    assert params.world.name == "world1"
    small = envs.make("world1", max_steps_in_episode=100).default_params
    assert small.max_steps_in_episode == 100
    with pytest.raises(ValueError, match="unknown environment parameter"):
        envs.make("world1", max_steps=100)
    with pytest.raises(ValueError, match="max_steps_in_episode"):
        envs.make("world1", max_steps_in_episode=0)
    with pytest.raises(envs.WorldError):
        envs.make("no_such_world.toml")
    obs_space, act_space = env.observation_space(params), env.action_space(params)
    assert isinstance(obs_space, spaces.Box) and isinstance(act_space, spaces.Box)
    assert obs_space.shape == (len(genv.OBS_NAMES),) == (11,)
    assert act_space.shape == (2,)
    np.testing.assert_array_equal(act_space.low, -1.0)
    np.testing.assert_array_equal(act_space.high, 1.0)


@pytest.mark.slow
def test_reset_step_shapes_match_spaces(env):
    key = jax.random.key(0)
    obs, state = env.reset(key, env.default_params)
    space = env.observation_space()
    assert obs.shape == space.shape and obs.dtype == jnp.float32
    assert bool(space.contains(obs))
    assert int(state.sim.t) == 0 and int(state.collisions) == 0
    action = env.action_space().sample(jax.random.key(1))
    assert bool(env.action_space().contains(action))
    obs, state, reward, terminated, truncated, info = env.step(key, state, action)
    assert obs.shape == space.shape and obs.dtype == jnp.float32
    assert bool(space.contains(obs))
    assert reward.shape == () and reward.dtype == jnp.float32
    assert terminated.shape == truncated.shape == () and terminated.dtype == jnp.bool_
    assert truncated.dtype == jnp.bool_
    assert {"collisions", "distance", "goal_pixels", "max_ir", "discount"} <= set(info)
    assert {"terminated", "truncated", "final_observation"} <= set(info)
    np.testing.assert_array_equal(info["final_observation"], obs)  # no episode ended
    assert int(state.sim.t) == 1
    # The IR part of the observation is the raw reading / 4095.
    np.testing.assert_allclose(float(jnp.max(obs[:8])) * 4095.0, float(info["max_ir"]), rtol=1e-5)


def test_same_key_same_result_and_keys_matter(env):
    _, state = env.reset(jax.random.key(3))
    action = jnp.array([0.5, 0.2])
    a = env.step(jax.random.key(4), state, action)
    b = env.step(jax.random.key(4), state, action)
    c = env.step(jax.random.key(5), state, action)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0], c[0])  # the IR noise comes from the step's key
    o1, s1 = env.reset(jax.random.key(3))
    np.testing.assert_array_equal(s1.sim.pose, state.sim.pose)


@pytest.mark.slow
def test_jit_vmap_step_equals_loop(env, env_no_reset, vstep):
    n = 3
    keys = jax.random.split(jax.random.key(7), n)
    states = [env.reset(k)[1] for k in keys]
    actions = jax.random.uniform(jax.random.key(8), (n, 2), minval=-1.0, maxval=1.0)
    step_keys = jax.random.split(jax.random.key(9), n)
    params = env_no_reset.default_params
    loop = [env_no_reset.step(step_keys[i], states[i], actions[i], params) for i in range(n)]
    batched = vstep(step_keys, jax.tree.map(lambda *x: jnp.stack(x), *states), actions, params)
    for i in range(n):
        one = jax.tree.map(lambda x, i=i: x[i], batched)
        for x, y in zip(jax.tree.leaves(loop[i]), jax.tree.leaves(one), strict=True):
            np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-5)


def test_bad_actions_under_jit_and_vmap(env_no_reset, vstep):
    # A wrong shape is refused as the step is traced (eval_shape or jit: nothing compiles); a
    # non-finite action under jit and vmap is flagged for its env alone, whose state stays put.
    key, state = jax.random.key(0), env_no_reset.reset(jax.random.key(0))[1]
    for trace in (functools.partial(jax.eval_shape, env_no_reset.step), jax.jit(env_no_reset.step)):
        with pytest.raises(ValueError, match=r"shape \(2,\), got shape \(3,\)"):
            trace(key, state, jnp.zeros(3))
    keys = jax.random.split(jax.random.key(7), 3)
    # Stacked on the host: eager jnp ops would compile a program per leaf.
    states = jax.tree.map(lambda *x: np.stack(x), *[env_no_reset.reset(k)[1] for k in keys])
    actions = np.array([[0.5, 0.5], [np.nan, 0.0], [0.2, np.inf]], np.float32)
    out = jax.device_get(vstep(keys, states, actions, env_no_reset.default_params))
    obs, new, reward, terminated, _, info = out
    np.testing.assert_array_equal(info["invalid_action"], [False, True, True])
    np.testing.assert_array_equal(new.sim.t, [1, 0, 0])
    for leaf, was in zip(jax.tree.leaves(new), jax.tree.leaves(states), strict=True):
        np.testing.assert_array_equal(leaf[1:], was[1:])  # the flagged envs: as they were
    assert not np.array_equal(new.sim.pose[0], states.sim.pose[0])  # the valid one moved
    np.testing.assert_array_equal(reward[1:], 0.0)
    assert np.all(np.isfinite(obs)) and not np.any(terminated)


def _expected_rewards(d0, distance, max_ir, params):
    """Progress minus one penalty per contact episode, by hand (SPEC 9's counting rule)."""
    rewards, free, prev = [], True, d0
    for d, vm in zip(distance, max_ir, strict=True):
        counted = vm >= params.collision_level and free
        free = (free and not counted) or vm < params.clear_level
        rewards.append(params.progress_scale * (prev - d) - params.collision_penalty * counted)
        prev = d
    return np.asarray(rewards)


def test_reward_drive_into_a_wall(env):
    # Facing the south wall from 0.25 m: drive in, press on, back off clear, drive in again.
    state = _placed(env, jax.random.key(11), [0.75, 0.25, -np.pi / 2])
    params = env.default_params
    d0 = float(genv.goal_distance(state.sim))
    script = [(1.0, 1.0)] * 70 + [(-1.0, -1.0)] * 40 + [(1.0, 1.0)] * 60
    rewards, dist, vm, counts = [], [], [], []
    for t, action in enumerate(script):
        _, state, r, term, trunc, info = env.step(jax.random.key(100 + t), state, jnp.array(action))
        assert not bool(term) and not bool(trunc)
        rewards.append(float(r))
        dist.append(float(info["distance"]))
        vm.append(float(info["max_ir"]))
        counts.append(int(info["collisions"]))
    vm = np.asarray(vm)
    assert np.sum(vm >= 2400) > 20  # long contacts, pressed against the wall
    assert np.min(vm[70:110]) < 250  # backed off clear between them
    expected = _expected_rewards(d0, dist, vm, params)
    np.testing.assert_allclose(rewards, expected, atol=1e-5)
    # One penalty per contact episode: two contacts, two penalties, however long each lasts.
    assert counts[-1] == 2 == int(state.collisions)
    assert np.sum(np.diff([0, *counts]) == 1) == 2


def test_terminated_after_three_goal_steps(env):
    # Close up in front of the goal block (half size 0.05 m), facing it, standing still.
    goal = [0.75, 1.35]
    state = _placed(env, jax.random.key(12), [0.75, 1.35 - 0.05 - 0.037 - 0.05, np.pi / 2], goal)
    stop = jnp.zeros(2)
    out = []
    for t in range(3):
        out.append(env.step(jax.random.key(200 + t), state, stop))
        state = out[-1][1]
    assert all(int(o[5]["goal_pixels"]) > 40 for o in out)
    assert [bool(o[3]) for o in out] == [False, False, True]
    assert not any(bool(o[4]) for o in out)
    # Standing still: no progress, so the rewards are the finish bonus alone.
    assert [float(o[2]) for o in out] == [0.0, 0.0, env.default_params.finish_bonus]
    assert float(out[2][5]["discount"]) == 0.0
    # Auto-reset: the episode that finished is replaced by one of the starts reset drew; the
    # info keeps the observation that ended it.
    assert int(state.sim.t) == 0 and int(state.streak) == 0 and bool(state.free)
    pool_obs, pool = out[2][1].starts
    i = int(np.argmax(np.all(np.asarray(pool.pose) == np.asarray(state.sim.pose), axis=1)))
    np.testing.assert_array_equal(pool.pose[i], state.sim.pose)
    np.testing.assert_array_equal(pool_obs[i], out[2][0])
    assert float(out[2][5]["final_observation"][10]) * 45 > 40  # the goal filled the camera


def test_truncated_at_max_steps(env):
    params = env.default_params.replace(max_steps_in_episode=5)
    _, state = env.reset(jax.random.key(13), params)
    env.step(jax.random.key(299), state, jnp.zeros(2), env.default_params)  # compiled here
    size = genv.EpuckEnv._step._cache_size()
    flags = []
    for t in range(5):
        _, new, _, term, trunc, _ = env.step(jax.random.key(300 + t), state, jnp.zeros(2), params)
        flags.append((bool(term), bool(trunc)))
        if t < 4:
            state = new
    assert flags == [(False, False)] * 4 + [(False, True)]
    ended = state.replace(sim=state.sim.replace(t=5))
    assert bool(env.is_truncated(ended, params)) and not bool(env.is_terminal(ended, params))
    assert int(new.sim.t) == 0  # auto-reset
    # max_steps_in_episode is traced: no new compilation.
    assert genv.EpuckEnv._step._cache_size() == size


def test_legacy_step_gives_gymnax_0_0s_five_values(env):
    # rejax 0.1 unpacks five values from step: done = terminated | truncated, the rest as is.
    legacy = envs.make("world1", legacy_step=True)
    params = env.default_params.replace(max_steps_in_episode=1)
    _, state = env.reset(jax.random.key(5), params)
    key, action = jax.random.key(6), jnp.array([0.3, -0.2])
    *same, term, trunc, info = env.step(key, state, action, params)
    out = legacy.step(key, state, action, params)
    assert len(out) == 5 and bool(out[3]) and bool(trunc) and not bool(term)
    jax.tree.map(np.testing.assert_array_equal, (*same, info), (*out[:3], out[4]))
    assert isinstance(legacy, environment.Environment) and repr(legacy).startswith("Legacy")


def test_first_episode_does_not_depend_on_the_pool(env, env_no_reset):
    # reset draws the auto-reset's starts from a key of their own: the first episode is the same
    # with or without them.
    key = jax.random.key(21)
    obs, state = env.reset(key)
    obs0, state0 = env_no_reset.reset(key)
    np.testing.assert_array_equal(obs, obs0)
    for x, y in zip(jax.tree.leaves(state.sim), jax.tree.leaves(state0.sim), strict=True):
        np.testing.assert_array_equal(x, y)
    pool_obs, pool = state.starts
    assert state0.starts is None and pool_obs.shape == (genv.RESET_POOL, 11)
    assert len(np.unique(np.asarray(pool.pose), axis=0)) == genv.RESET_POOL  # distinct starts


@pytest.mark.slow  # compiles a step with a reset in it
def test_refresh_pool_redraws_the_start_each_auto_reset_took(env):
    refreshing = envs.make("world1", refresh_pool=True)
    params = env.default_params.replace(max_steps_in_episode=1)  # every step ends an episode
    _, state = env.reset(jax.random.key(41), params)  # reset is the same with or without it
    region = np.asarray(params.world.start_region)
    for t in range(3):
        key, action = jax.random.key(410 + t), jnp.array([0.3, 0.5])
        obs, new, *_ = refreshing.step(key, state, action, params)
        kept_obs, kept, *_ = env.step(key, state, action, params)
        # The episodes are those without refreshing; only the slot just taken is redrawn.
        np.testing.assert_array_equal(obs, kept_obs)
        jax.tree.map(np.testing.assert_array_equal, new.sim, kept.sim)
        jax.tree.map(np.testing.assert_array_equal, kept.starts, state.starts)
        before, after = np.asarray(state.starts[1].pose), np.asarray(new.starts[1].pose)
        (i,) = np.flatnonzero(np.any(before != after, axis=1))
        np.testing.assert_array_equal(before[i], new.sim.pose)  # the start taken ...
        x, y, _ = after[i]  # ... replaced by a fresh one in the start region
        assert region[0] <= x <= region[2] and region[1] <= y <= region[3]
        assert np.all(np.isfinite(new.starts[0][i])) and int(new.starts[1].t[i]) == 0
        state = new


def test_auto_reset_costs_about_nothing_under_vmap(env, env_no_reset):
    # Under vmap no reset is skipped: gymnax's own step (a fresh reset_env every step, as this
    # environment's step ran one before) costs several steps; ours picks a start reset drew.
    # XLA's flop counts of the programs (traced and lowered, not compiled), not a timing.
    n, p = 4, env.default_params
    keys = jax.random.split(jax.random.key(0), n)
    _, states = jax.eval_shape(jax.vmap(env.reset, in_axes=(0, None)), keys, p)

    def flops(step, states):
        batched = jax.jit(jax.vmap(step, in_axes=(0, 0, 0, None)))
        return batched.lower(keys, states, jnp.zeros((n, 2)), p).cost_analysis()["flops"]

    step_env = flops(env.step_env, states)
    assert flops(env.step, states) < 1.2 * step_env
    gymnax_step = functools.partial(environment.Environment.step, env_no_reset)
    assert flops(gymnax_step, states.replace(starts=None)) > 3 * step_env


def test_gymnax_registry_and_wrappers_run_unmodified(env):
    names = envs.register_gymnax()
    assert "jaxais/world1" in names and envs.register_gymnax() == names  # once
    made, made_params = gymnax.make("jaxais/world2", max_steps_in_episode=7, reset_pool=2)
    assert isinstance(made, envs.EpuckEnv) and made.name == "jaxais/world2"
    assert made_params.max_steps_in_episode == 7 and made.reset_pool == 2
    # gymnasium's API through gymnax's wrapper (which deep-copies the env: an equal one, sharing
    # its compiled reset and step).
    gym_env = GymnaxToGymWrapper(env, env.default_params.replace(max_steps_in_episode=3))
    obs, _ = gym_env.reset(seed=1)
    assert gym_env.observation_space.shape == (11,) and gym_env.action_space.shape == (2,)
    assert gym_env.observation_space.contains(np.asarray(obs))
    flags = [gym_env.step(np.array([0.2, 0.2], np.float32))[2:4] for _ in range(3)]
    assert [(bool(a), bool(b)) for a, b in flags] == [(False, False)] * 2 + [(False, True)]
    # Tools written for the older 5-tuple step take gymnax's LegacyStepAPIWrapper.
    _, state = env.reset(jax.random.key(2))
    legacy = LegacyStepAPIWrapper(env)
    out = jax.eval_shape(legacy.step, jax.random.key(3), state, jnp.zeros(2), env.default_params)
    assert len(out) == 5 and out[3].dtype == jnp.bool_ and out[0].shape == (11,)


def test_copies_are_equal_and_share_compiled_programs(env):
    key = jax.random.key(31)
    env.reset(key)
    size = genv.EpuckEnv._reset._cache_size()
    for twin in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        assert twin == env and hash(twin) == hash(env) and twin is not env
        jax.tree.map(np.testing.assert_array_equal, twin.reset(key), env.reset(key))
    assert genv.EpuckEnv._reset._cache_size() == size  # the copies ran the original's program
    # Another world, parameter, setting or step API is another environment.
    others = [
        envs.make("world2"),
        envs.make("world1", max_steps_in_episode=3),
        envs.make("world1", refresh_pool=True),
        envs.make("world1", legacy_step=True),
    ]
    assert all(other != env for other in others) and len({env, *others}) == 5


def test_gymnax_wrappers_deep_copy_as_themselves(env):
    # gymnax's wrappers forward unknown attributes to the env: the env's own __deepcopy__ used
    # to answer for them with the bare env (logging lost, six values where five were wanted).
    key, action = jax.random.key(32), jnp.array([0.4, 0.1])
    params = env.default_params.replace(max_steps_in_episode=1)  # the step ends the episode
    obs, state = env.reset(key, params)
    ref = env.step(key, state, action, params)
    for wrap in (LogWrapper, FlattenObservationWrapper, LegacyStepAPIWrapper):
        twin = copy.deepcopy(wrap(env))
        assert type(twin) is wrap and twin._env == env and twin._env is not env, wrap
        # The wrappers' own code, outside their jit (which would compile each anew); inside it
        # the env's reset and step run as compiled for `env`.
        twin_obs, twin_state = wrap.reset.__wrapped__(twin, key, params)
        np.testing.assert_array_equal(twin_obs, obs)
        out = wrap.step.__wrapped__(twin, key, twin_state, action, params)
        np.testing.assert_array_equal(out[0], ref[0])
        np.testing.assert_array_equal(out[2], ref[2])
        if wrap is LegacyStepAPIWrapper:
            assert len(out) == 5 and bool(out[3]) and bool(ref[4])  # done = truncated
        else:
            assert len(out) == 6 and bool(out[4])
        if wrap is LogWrapper:  # its episode statistics, kept
            assert int(out[5]["returned_episode"]) == 1
            np.testing.assert_allclose(out[5]["returned_episode_returns"], ref[2])


def test_bad_input_is_one_line_naming_it_outside_jit(env):
    def refused(match, fn, *args, **kwargs):
        with pytest.raises(ValueError, match=match) as info:
            fn(*args, **kwargs)
        assert "\n" not in str(info.value)

    refused("^sim_params must be a SimParams", envs.make, "world1", sim_params="x")
    refused("EnvParams.progress_scale must be a finite number, got nan", envs.make,
            progress_scale=float("nan"))  # fmt: skip
    refused(r"EnvParams.finish_pixels must be an integer in \[0, 45\], got -1", envs.make,
            finish_pixels=-1)  # fmt: skip
    refused(r"EnvParams.collision_level .* in \[0, 4095\], got -5", envs.make, collision_level=-5)
    refused("reset_pool must be a positive integer", envs.make, reset_pool=0)
    refused("reset_pool must be a positive integer, got bool", envs.make, reset_pool=True)
    refused("legacy_step must be True or False", envs.make, legacy_step="yes")
    refused("refresh_pool must be True or False, got int 1", envs.make, refresh_pool=1)
    key, params = jax.random.key(0), env.default_params
    refused("params must be an EnvParams", env.reset, key, {"max_steps_in_episode": 3})
    refused("EnvParams.finish_streak must be an integer >= 1", env.reset, key,
            params.replace(finish_streak=0))  # fmt: skip
    _, state = env.reset(key)
    refused("EnvParams.clear_level", env.step, key, state, jnp.zeros(2),
            params.replace(clear_level=float("nan")))  # fmt: skip
    refused(r"action must be 2 finite wheel speeds .*0\.3", env.step, key, state, [0.1, 0.2, 0.3])
    refused("action must be 2 finite wheel speeds .*nan", env.step, key, state, [np.nan, 0.0])
    # Inside jit (traced values) nothing is checked: what an optimiser proposes runs as given.
    bad = params.replace(finish_pixels=-1, progress_scale=jnp.nan)
    out = jax.eval_shape(env.step, key, state, jnp.array([jnp.nan, 0.0]), bad)
    assert out[0].shape == (11,)


def test_simulator_and_task_loop_do_not_import_gymnax():
    # Importing gymnax takes seconds: the simulator, the task loop and the trials load without
    # it; the gymnax face loads it on first use.
    code = (
        "import sys\n"
        "import jaxais.baselines.neural, jaxais.envs as envs, jaxais.loop, jaxais.trials\n"
        "print('gymnax' in sys.modules)\n"
        "envs.make\n"
        "print('gymnax' in sys.modules)\n"
    )
    out = run_python(code)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["False", "True"]
