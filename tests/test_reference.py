"""The JAX simulator against the plain NumPy reference (``tests/reference_sim.py``).

Both are fed the same start state, wheel commands and random draws (the step's ``StepNoise``),
and must agree within float32 tolerance: each step from the JAX state, and over whole runs side
by side. Camera materials must agree exactly except where two surfaces are hit at (nearly) the
same distance, where the JAX ray caster's packed surface index may pick either.
"""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest
import reference_sim as ref
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxais import envs
from jaxais.envs import geometry as env_geometry
from jaxais.envs import params as env_params
from jaxais.envs import sim as env_sim

PARAMS_NP = ref.params_to_numpy(envs.default_params())
REL_T = 2e-5
"""Relative error allowed on a JAX hit distance (packed index: < 1e-5, plus float32)."""


def _angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs((np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi)


def assert_state_close(jax_state: dict, ref_state: dict, atol: float = 1e-5) -> None:
    """Poses within ``atol`` (m and rad); timers, turn directions, goal, boxes and t equal."""
    for key in ("pose", "wanderers"):
        j, r = jax_state[key].reshape(-1, 3), ref_state[key].reshape(-1, 3)
        np.testing.assert_allclose(j[:, :2], r[:, :2], rtol=0, atol=atol, err_msg=key)
        assert _angle_diff(j[:, 2], r[:, 2]).max(initial=0.0) <= atol, key
    np.testing.assert_array_equal(jax_state["wander_timer"], ref_state["wander_timer"])
    np.testing.assert_array_equal(jax_state["wander_dir"], ref_state["wander_dir"])
    np.testing.assert_allclose(jax_state["goal"], ref_state["goal"], rtol=0, atol=1e-7)
    np.testing.assert_allclose(jax_state["boxes"], ref_state["boxes"], rtol=0, atol=1e-7)
    assert int(jax_state["t"]) == int(ref_state["t"])


def ambiguous_columns(ref_obs: dict) -> np.ndarray:
    """[15] bool: camera columns whose outcome float32 rounding may legitimately change.

    A column is ambiguous when surfaces of different materials are hit within ``REL_T`` of the
    first hit, when the first hit lies within ``REL_T`` of the camera's range, or when a pixel
    row's line of sight passes within 1e-6 m of the seen surface's top or of the floor.
    """
    n_ir, params = ref.N_IR, PARAMS_NP
    pix = params["camera_fov"] / ref.CAMERA_COLUMNS
    out = np.zeros(ref.CAMERA_COLUMNS, bool)
    for col in range(ref.CAMERA_COLUMNS):
        t = ref_obs["ray_t"][n_ir + col]
        if not math.isfinite(t):
            continue
        hits = ref_obs["ray_hits"][n_ir + col]
        near = hits <= t * (1 + REL_T) + 1e-9
        tie = len(set(ref_obs["surface_material"][near].tolist())) > 1
        at_range = abs(t - params["camera_range"]) <= REL_T * t
        top = ref_obs["ray_height"][n_ir + col] - params["camera_height"]
        rises = [math.tan(pix * (1 - row)) * t for row in range(ref.CAMERA_ROWS)]
        edge = any(min(abs(r - top), abs(r + params["camera_height"])) < 1e-6 for r in rises)
        out[col] = tie or at_range or edge
    return out


def assert_obs_close(jax_obs: dict, ref_obs: dict, ir_atol: float = 0.5) -> None:
    """IR and depth within tolerance; camera pixels equal outside ambiguous columns."""
    np.testing.assert_allclose(jax_obs["ir"], ref_obs["ir"], rtol=1e-5, atol=ir_atol)
    np.testing.assert_allclose(jax_obs["vm"], ref_obs["vm"], rtol=1e-5, atol=ir_atol)
    amb = ambiguous_columns(ref_obs)
    ok = ~amb
    np.testing.assert_array_equal(jax_obs["materials"][ok], ref_obs["materials"][ok])
    np.testing.assert_array_equal(jax_obs["blue"][:, ok], ref_obs["blue"][:, ok])
    np.testing.assert_allclose(jax_obs["depth"][ok], ref_obs["depth"][ok], rtol=REL_T, atol=1e-6)
    if not amb.any():
        assert int(jax_obs["blue_pixels"]) == ref_obs["blue_pixels"]
        assert int(jax_obs["goal_pixels"]) == ref_obs["goal_pixels"]
        np.testing.assert_allclose(jax_obs["blue_centroid"], ref_obs["blue_centroid"], rtol=1e-6)


def _start(sim, world: envs.World, seed: int):
    """A reset batch: robots 0-3 where reset put them, 4-5 at random clear poses, 6-7 against
    the south and the west wall, heading into them at an angle; in robots 1-5's worlds the
    first wanderer (if any) starts 2 cm from the south wall, heading into it at an angle (so
    that it must turn away, to the left or to the right)."""
    rng = np.random.default_rng(seed)
    state, _ = sim.reset(world, sim.keys(seed))
    arena = np.asarray(world.arena, np.float64)
    width = arena[2] - arena[0]
    r = PARAMS_NP["body_radius"]
    poses = ref.state_to_numpy(state)["pose"].copy()
    poses[4:6, :2] = arena[:2] + rng.uniform(size=(2, 2)) * (arena[2:] - arena[:2])
    poses[4:6, 2] = rng.uniform(-np.pi, np.pi, 2)
    poses[6] = [arena[0] + 0.5 * width, arena[1] + r + 0.003, -np.pi / 2 + 0.5]
    poses[7] = [arena[0] + r + 0.003, 0.5 * (arena[1] + arena[3]), np.pi - 0.5]
    state = sim.with_poses(state, sim.clear_poses(state, world, poses))
    if world.n_wanderers:
        batch = ref.state_to_numpy(state)
        wanderers = batch["wanderers"].copy()
        for i in range(1, 6):
            turn = 0.4 if i % 2 else -0.4
            pose = [arena[0] + (0.2 + 0.1 * i) * width, arena[1] + r + 0.02, -np.pi / 2 + turn]
            one = ref.unbatch(batch, i)
            one["wanderers"] = one["wanderers"].copy()
            one["wanderers"][0] = np.asarray(pose, np.float32)
            if ref.clearances(one, ref.world_to_numpy(world), PARAMS_NP).min() > 1e-4:
                wanderers[i] = one["wanderers"]
        state = state.replace(wanderers=np.asarray(wanderers, np.float32))
    return state, rng


def _commands(rng: np.random.Generator, batch: int) -> np.ndarray:
    """Wheel commands [batch, 2]: random, including out-of-range speeds that must be clipped;
    robots 6 and 7 drive straight ahead at full speed (into their walls)."""
    wheels = rng.uniform(-1300.0, 1300.0, (batch, 2))
    wheels[6:] = 1000.0
    return wheels


def test_constants_mirror_the_simulator() -> None:
    assert ref.N_IR == env_params.N_IR
    assert (ref.CAMERA_ROWS, ref.CAMERA_COLUMNS) == (envs.CAMERA_ROWS, envs.CAMERA_COLUMNS)
    assert (ref.NONE, ref.WALL, ref.MARKER, ref.GOAL) == (
        envs.NONE,
        envs.WALL,
        envs.MARKER,
        envs.GOAL,
    )
    assert ref.ROBOT_HEIGHT == env_sim.ROBOT_HEIGHT
    assert ref.WANDER_SPEED == env_sim.WANDER_SPEED
    assert ref.WANDER_TURN_PROB == env_sim.WANDER_TURN_PROB
    assert ref.WANDER_TURN_STEPS == env_sim.WANDER_TURN_STEPS
    assert ref.WANDER_AVOID_GAP == env_sim.WANDER_AVOID_GAP
    resolve = inspect.signature(env_geometry.resolve_disc).parameters
    assert resolve["iters"].default == ref.COLLISION_ITERS
    assert resolve["skin"].default == ref.COLLISION_SKIN
    assert set(ref.STATE_FIELDS) == set(envs.State.__dataclass_fields__)
    assert set(ref.NOISE_FIELDS) == set(envs.StepNoise.__dataclass_fields__)
    assert set(ref.OBS_FIELDS) == set(envs.Observation.__dataclass_fields__)
    assert set(ref.PARAM_FIELDS) == set(envs.SimParams.__dataclass_fields__)
    assert set(ref.WORLD_ARRAYS) | set(ref.WORLD_STATICS) == set(envs.World.__dataclass_fields__)


@pytest.mark.parametrize("name", envs.BUILTIN_WORLDS)
def test_step_matches_reference(sim, name: str) -> None:
    """Every step from the JAX state, and a whole run side by side from the same start.

    In ``real`` the reference replays the step's noise draws (wheels, IR, pixels); the other
    worlds are noiseless. Wanderers' random walks use the same uniforms in both.
    """
    world = sim.world(name)
    wnp = ref.world_to_numpy(world)
    state, rng = _start(sim, world, seed=11)
    alone = [ref.unbatch(ref.state_to_numpy(state), i) for i in range(sim.batch)]
    contacts = turning = 0
    for t in range(25):
        wheels = _commands(rng, sim.batch)
        new, obs, noise, gaps = sim.step(world, sim.keys(1000 + t), state, wheels)
        before, after = ref.state_to_numpy(state), ref.state_to_numpy(new)
        obs_np, noise_np = ref.obs_to_numpy(obs), ref.noise_to_numpy(noise)
        contacts += int((gaps < 1e-3).sum())
        turning += int((after["wander_timer"] > 0).sum())
        for i in range(sim.batch):
            noise_i = ref.unbatch(noise_np, i)
            ref_state, ref_obs = ref.ref_step(
                ref.unbatch(before, i), wheels[i], noise_i, wnp, PARAMS_NP
            )
            assert_state_close(ref.unbatch(after, i), ref_state)
            assert_obs_close(ref.unbatch(obs_np, i), ref_obs)
            # Side by side: the reference runs on its own state; float32 drift stays tiny. (Its
            # readings are not compared: a drift of microns may move a ray across a corner.)
            alone[i], _ = ref.ref_step(alone[i], wheels[i], noise_i, wnp, PARAMS_NP)
            assert_state_close(ref.unbatch(after, i), alone[i], atol=2e-5)
        state = new
    assert contacts > 0, "the run should exercise collision resolution"
    assert turning > 0 or world.n_wanderers == 0, "the run should exercise random turns"


@settings(max_examples=8, deadline=None, derandomize=True)
@given(
    fractions=st.lists(st.tuples(*[st.floats(0.0, 1.0)] * 3), min_size=8, max_size=8),
    speeds=st.lists(st.tuples(*[st.floats(-1500.0, 1500.0)] * 2), min_size=8, max_size=8),
    seed=st.integers(0, 2**16),
)
def test_random_steps_match_reference(sim, fractions, speeds, seed) -> None:
    """Random poses (world2, the densest layout) and commands, a few steps each."""
    world = sim.world("world2")
    wnp = ref.world_to_numpy(world)
    state, _ = sim.reset(world, sim.keys(seed))
    state = sim.with_poses(state, sim.random_clear_poses(state, world, fractions))
    for t in range(3):
        new, obs, noise, _ = sim.step(world, sim.keys(seed + t + 1), state, speeds)
        before, after = ref.state_to_numpy(state), ref.state_to_numpy(new)
        obs_np, noise_np = ref.obs_to_numpy(obs), ref.noise_to_numpy(noise)
        for i in range(sim.batch):
            ref_state, ref_obs = ref.ref_step(
                ref.unbatch(before, i), speeds[i], ref.unbatch(noise_np, i), wnp, PARAMS_NP
            )
            assert_state_close(ref.unbatch(after, i), ref_state)
            assert_obs_close(ref.unbatch(obs_np, i), ref_obs)
        state = new


@settings(max_examples=4, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**16))
def test_random_views_match_reference(sim, probe_world, seed: int) -> None:
    """``observe`` against ``ref_sense`` in the probe world, with the goal and the thin-wall box
    placed at random, mostly somewhere in front of the robot (near, far, beyond camera range,
    partly hidden)."""
    rng = np.random.default_rng(seed)
    wnp = ref.world_to_numpy(probe_world)
    arena = wnp["arena"]
    states = []
    while len(states) < 32:
        x, y = rng.uniform(arena[:2] + 0.04, arena[2:] - 0.04)
        th = rng.uniform(-np.pi, np.pi)
        d, a = rng.uniform(0.1, 2.4), rng.uniform(-0.16, 0.16)
        goal = np.array([x + d * np.cos(th + a), y + d * np.sin(th + a)])
        goal = np.clip(goal, arena[:2] + 0.05, arena[2:] - 0.05)
        d, a = rng.uniform(0.05, 1.5), rng.uniform(-0.25, 0.25)
        box = np.array([x + d * np.cos(th + a), y + d * np.sin(th + a)])
        if rng.uniform() < 0.5:
            box = rng.uniform(arena[:2], arena[2:])
        if rng.uniform() < 0.2:
            goal = rng.uniform(arena[:2], arena[2:])
        state = {
            "pose": np.array([x, y, th]),
            "wanderers": np.zeros((0, 3)),
            "wander_timer": np.zeros(0, np.int32),
            "wander_dir": np.zeros(0),
            "goal": goal,
            "boxes": box[None],
            "t": np.int32(0),
        }
        if ref.clearances(state, wnp, PARAMS_NP).min() > 0:
            f32 = {k: v.astype(np.float32) for k, v in state.items() if v.dtype.kind == "f"}
            states.append(envs.State(**(state | f32)))
    obs = sim.observe(probe_world, states)
    assert (obs["goal_pixels"] > 0).sum() >= 6  # the views do see the goal, often
    for i, state in enumerate(states):
        assert_obs_close(ref.unbatch(obs, i), ref.ref_sense(state, None, wnp, PARAMS_NP))
