"""The simulator's physics and sensors against hand-worked values, and its JAX properties.

Kinematics and wall contact run in ``ga_maze`` (no wanderers, no noise); sensors are probed in a
bare world written to a temporary file; overlap is checked in every built-in world.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference_sim as ref
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxais import envs
from jaxais.envs import geometry

K = 0.00683 * 0.0205
"""Wheel rim speed per speed unit, m/s (speed unit x wheel radius)."""
DT, AXLE, R = 0.032, 0.053, 0.037
STEPS = 40


def _angle_diff(a, b) -> np.ndarray:
    return np.abs((np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi)


def _arc(pose, left: float, right: float, time: float) -> np.ndarray:
    """Closed-form differential-drive pose after ``time`` at constant wheel speeds."""
    x, y, th = pose
    v, w = 0.5 * (left + right) * K, (right - left) * K / AXLE
    if w == 0:
        return np.array([x + v * time * math.cos(th), y + v * time * math.sin(th), th])
    th1 = th + w * time
    return np.array(
        [
            x + v / w * (math.sin(th1) - math.sin(th)),
            y - v / w * (math.cos(th1) - math.cos(th)),
            th1,
        ]
    )


# Robots of the ga_maze run: start pose and (left, right) command. 0-4 stay clear of walls in
# the first chamber (x in [0, 0.5]); 5-7 drive into a wall, head-on or at an angle.
MAZE_RUN = [
    ((0.25, 0.3, math.pi / 2), (500.0, 500.0)),  # straight north
    ((0.15, 0.5, 0.3), (1500.0, 1500.0)),  # straight, clipped to 1000
    ((0.25, 0.5, 0.0), (-300.0, 300.0)),  # spin left
    ((0.25, 0.5, 1.0), (200.0, 400.0)),  # arc left
    ((0.25, 0.5, -2.0), (-800.0, 200.0)),  # arc backwards
    ((0.25, 0.06, -math.pi / 2), (1000.0, 1000.0)),  # head-on into the south wall
    ((0.1, 0.06, -math.pi / 2 + 0.6), (1000.0, 1000.0)),  # south wall at an angle: slides east
    ((0.06, 0.3, math.pi - 0.6), (1000.0, 1000.0)),  # west wall at an angle: slides north
]


@pytest.fixture(scope="module")
def maze_run(sim) -> tuple[np.ndarray, np.ndarray]:
    """Poses [STEPS + 1, 8, 3] and robot clearances [STEPS, 8] of the ga_maze run."""
    world = sim.world("ga_maze")
    state, _ = sim.reset(world, sim.keys(0))
    state = sim.with_poses(state, [p for p, _ in MAZE_RUN])
    wheels = np.array([w for _, w in MAZE_RUN])
    poses, gaps = [np.asarray(state.pose, np.float64)], []
    for t in range(STEPS):
        state, _, _, gap = sim.step(world, sim.keys(t), state, wheels)
        poses.append(np.asarray(state.pose, np.float64))
        gaps.append(gap[:, 0])
    return np.stack(poses), np.stack(gaps)


def test_straight_at_the_hand_worked_speed(maze_run) -> None:
    poses, _ = maze_run
    start = np.asarray(MAZE_RUN[0][0])
    # 500 units x 0.00683 rad/s x 0.0205 m = 0.0700075 m/s, due north.
    np.testing.assert_allclose(poses[1, 0], start + [0, 0.0700075 * DT, 0], atol=1e-6)
    np.testing.assert_allclose(poses[-1, 0], start + [0, 0.0700075 * DT * STEPS, 0], atol=1e-5)
    # 1500 is clipped to 1000: 0.140015 m/s along heading 0.3.
    start = np.asarray(MAZE_RUN[1][0])
    d = 0.140015 * DT * STEPS
    np.testing.assert_allclose(
        poses[-1, 1], start + [d * math.cos(0.3), d * math.sin(0.3), 0], atol=1e-5
    )


def test_spin_in_place(maze_run) -> None:
    poses, _ = maze_run
    start = np.asarray(MAZE_RUN[2][0])
    rate = (300 - (-300)) * 0.00683 * 0.0205 / 0.053  # 1.58507 rad/s
    np.testing.assert_array_equal(poses[:, 2, :2], np.broadcast_to(start[:2], (STEPS + 1, 2)))
    headings = start[2] + rate * DT * np.arange(STEPS + 1)
    assert _angle_diff(poses[:, 2, 2], headings).max() < 1e-5
    assert np.all(np.abs(poses[:, 2, 2]) <= np.pi + 1e-6)  # wrapped


@pytest.mark.parametrize("robot", [3, 4])
def test_arc_matches_closed_form(maze_run, robot: int) -> None:
    poses, _ = maze_run
    start, (left, right) = MAZE_RUN[robot]
    for n in (1, 7, STEPS):
        want = _arc(start, left, right, n * DT)
        np.testing.assert_allclose(poses[n, robot, :2], want[:2], atol=1e-5)
        assert _angle_diff(poses[n, robot, 2], want[2]) < 1e-5


def test_wall_contact_and_slide(maze_run) -> None:
    poses, gaps = maze_run
    v = 1000 * K
    assert gaps.min() >= -1e-5
    # Head-on: stops in contact with the south wall (y = 0), x unchanged.
    assert 0.0 <= gaps[-1, 5] < 1e-4
    np.testing.assert_allclose(poses[-1, 5, :2], [0.25, R], atol=1e-4)
    # At an angle: stays in contact and slides; the wall takes only the normal component.
    th = MAZE_RUN[6][0][2]
    assert 0.0 <= gaps[-1, 6] < 1e-4
    np.testing.assert_allclose(poses[-1, 6, 1], R, atol=1e-4)
    np.testing.assert_allclose(poses[-1, 6, 0], 0.1 + v * math.cos(th) * DT * STEPS, atol=1e-5)
    th = MAZE_RUN[7][0][2]
    assert 0.0 <= gaps[-1, 7] < 1e-4
    np.testing.assert_allclose(poses[-1, 7, 0], R, atol=1e-4)
    np.testing.assert_allclose(poses[-1, 7, 1], 0.3 + v * math.sin(th) * DT * STEPS, atol=1e-5)
    np.testing.assert_allclose(poses[:, 5:, 2], np.broadcast_to(poses[0, 5:, 2], (STEPS + 1, 3)))
    # Once in contact they stay in contact (pressed against the wall, neither through nor off).
    for robot in (5, 6, 7):
        touching = np.flatnonzero(gaps[:, robot] < 1e-4)
        assert touching.size and np.all(gaps[touching[0] :, robot] < 1e-4), robot


unit = st.floats(0.0, 1.0)
speed = st.floats(-1500.0, 1500.0)


@pytest.mark.parametrize("name", envs.BUILTIN_WORLDS)
@settings(max_examples=5, deadline=None)
@given(
    fractions=st.lists(st.tuples(unit, unit, unit), min_size=8, max_size=8),
    speeds=st.lists(st.tuples(speed, speed), min_size=8, max_size=8),
    seed=st.integers(0, 2**16),
)
def test_no_overlap_ever(sim, name: str, fractions, speeds, seed: int) -> None:
    """Random clear starts, commands and keys: the robot and the wanderers never overlap
    anything (robots 0-3 drive their random command, 4-7 full speed ahead into whatever)."""
    world = sim.world(name)
    state, gaps = sim.reset(world, sim.keys(seed))
    assert gaps.min() >= 0.0
    state = sim.with_poses(state, sim.random_clear_poses(state, world, fractions))
    wheels = np.asarray(speeds)
    wheels[4:] = 1000.0
    for t in range(15):
        state, _, _, gaps = sim.step(world, sim.keys(seed + 1 + t), state, wheels)
        assert gaps.min() >= -1e-5, (t, gaps.min())


# ---------------------------------------------------------------------------------- sensors


def _probe(pose, goal=(1.65, 1.8), box=(2.7, 1.6)) -> envs.State:
    """A probe-world state with NumPy leaves (the box and goal where given)."""
    f32 = lambda a: np.asarray(a, np.float32)
    return envs.State(
        pose=f32(pose),
        wanderers=np.zeros((0, 3), np.float32),
        wander_timer=np.zeros(0, np.int32),
        wander_dir=np.zeros(0, np.float32),
        goal=f32(goal),
        boxes=f32([box]),
        t=np.int32(0),
    )


def _facing_west_wall(sensor: int, rim: float) -> envs.State:
    """The robot ``rim`` m from the west wall (x = 0) with ``sensor`` pointing straight at it."""
    bearing = math.radians(envs.params.IR_BEARINGS_DEG[sensor])
    return _probe((R + rim, 1.0, math.pi - bearing))


def test_ir_equals_the_table_at_its_distances(sim, probe_world) -> None:
    table = np.asarray(envs.params.IR_TABLE_VALUE)
    dists = np.asarray(envs.params.IR_TABLE_DIST)
    states = [_facing_west_wall(s, d) for s in range(envs.N_IR) for d in dists]
    ir = sim.observe(probe_world, states)["ir"].reshape(envs.N_IR, len(dists), envs.N_IR)
    for s in range(envs.N_IR):
        np.testing.assert_allclose(ir[s, :, s], table, rtol=1e-4, atol=0.5, err_msg=f"ps{s}")


def test_ir_monotone_and_the_last_value_beyond_range(sim, probe_world) -> None:
    dists = np.linspace(0.0, 0.1, 41)
    obs = sim.observe(probe_world, [_facing_west_wall(0, d) for d in dists])
    reading = obs["ir"][:, 0]
    assert np.all(np.diff(reading) <= 1e-3)
    assert np.all(reading[dists < 0.07 - 1e-6] > 60.0)
    # Beyond the table Webots' e-puck returns its last value, not 0 (SPEC 2).
    np.testing.assert_allclose(reading[dists > 0.07 + 1e-4], 67.19, rtol=1e-5)
    # Between table points the reading is the straight line between them (0.025 m: midway).
    mid = np.argmin(np.abs(dists - 0.025))
    np.testing.assert_allclose(reading[mid], (383.84 + 234.93) / 2, atol=0.5)
    beyond = sim.observe(probe_world, [_facing_west_wall(0, d) for d in (0.0705, 0.08, 0.5)])
    np.testing.assert_allclose(beyond["ir"], 67.19, rtol=1e-5)
    np.testing.assert_allclose(beyond["vm"], 67.19, rtol=1e-5)


LENS_X = 0.5 + R
"""Lens of a robot at (0.5, 1.0) heading east."""


def _goal_ahead(depth: float, heading: float = 0.0, box=(2.7, 1.6)) -> envs.State:
    """Robot at (0.5, 1.0); the goal block's west face ``depth`` m east of the lens."""
    return _probe((0.5, 1.0, heading), goal=(LENS_X + depth + 0.05, 1.0), box=box)


@pytest.fixture(scope="module")
def camera(sim, probe_world) -> dict[str, dict[str, np.ndarray]]:
    cases = {
        "close": _goal_ahead(0.15),
        "centred": _goal_ahead(0.8),
        "left": _goal_ahead(0.8, heading=-0.1),
        "right": _goal_ahead(0.8, heading=0.1),
        "behind_wall": _goal_ahead(0.8, box=(1.0, 1.0)),
        "marker": _probe((2.2, 0.4, 0.0)),
        "out_of_range": _probe((0.1, 1.0, 0.0), goal=(2.9, 1.0)),
        "rows_far": _probe((0.1, 1.0, 0.0), goal=(0.1 + R + 1.7 + 0.05, 1.0)),
        "rows_near": _probe((0.1, 1.0, 0.0), goal=(0.1 + R + 1.2 + 0.05, 1.0)),
        "away": _goal_ahead(0.8, heading=math.pi),
    }
    obs = sim.observe(probe_world, list(cases.values()))
    return {name: ref.unbatch(obs, i) for i, name in enumerate(cases)}


def test_camera_sees_the_goal_when_facing_it(camera) -> None:
    close = camera["close"]
    assert close["goal_pixels"] == close["blue_pixels"] == 45  # > 40 when close
    assert np.all(close["materials"] == envs.GOAL)
    # The face is square to the heading: column c's ray meets it at 0.15 / cos(its offset).
    offsets = 0.14 - 0.02 * np.arange(15)
    np.testing.assert_allclose(close["depth"], 0.15 / np.cos(offsets), rtol=2e-5)
    centred = camera["centred"]
    # The 0.1 m face at 0.8 m spans +-0.0624 rad: columns 4..10 (offsets 0, +-0.02, ..., +-0.06).
    assert centred["blue_pixels"] == centred["goal_pixels"] == 21
    np.testing.assert_array_equal(centred["blue"].any(axis=0), np.abs(np.arange(15) - 7) <= 3)
    assert centred["blue_centroid"] == pytest.approx(7.0)
    assert camera["left"]["goal_pixels"] > 0 and camera["left"]["blue_centroid"] < 7.0
    assert camera["right"]["goal_pixels"] > 0 and camera["right"]["blue_centroid"] > 7.0
    assert camera["away"]["blue_pixels"] == 0 and camera["away"]["blue_centroid"] == 7.0


def test_camera_does_not_see_through_walls(camera) -> None:
    obs = camera["behind_wall"]
    assert obs["blue_pixels"] == obs["goal_pixels"] == 0
    np.testing.assert_array_equal(obs["materials"], envs.WALL)
    np.testing.assert_allclose(obs["depth"][7], 1.0 - 0.01 - LENS_X, rtol=1e-4)


def test_camera_marker_range_and_rows(camera) -> None:
    marker = camera["marker"]
    assert marker["blue_pixels"] == 45 and marker["goal_pixels"] == 0
    far = camera["out_of_range"]  # goal 2.7 m away, beyond the 2 m camera range
    assert far["blue_pixels"] == 0
    np.testing.assert_array_equal(far["materials"][6:9], envs.NONE)
    assert np.all(np.isinf(far["depth"][6:9]))
    # A 0.1 m high goal seen from 0.03 m: the bottom row (0.02 rad down) meets the floor before
    # it beyond 0.03 / tan(0.02) = 1.4998 m, so at 1.7 m only the upper two rows are blue.
    rows_far = camera["rows_far"]["blue"]
    np.testing.assert_array_equal(rows_far[:, 6:9], [[True] * 3, [True] * 3, [False] * 3])
    assert camera["rows_far"]["goal_pixels"] == 6
    assert camera["rows_near"]["blue"][:, 7].all()


# ---------------------------------------------------------------------------------- JAX


# Tolerances of the loop-versus-vmap comparison (XLA compiles the two differently); a packed
# ray-cast distance may round to the neighbouring multiple of 64 ulp (see geometry.cast_rays).
LOOP_RTOL = {"ir": (1e-5, 0.5), "vm": (1e-5, 0.5), "depth": (2e-5, 0.0)}


def test_vmap_equals_a_loop_of_single_steps(sim) -> None:
    world = sim.world("world1")
    state, _ = sim.reset(world, sim.keys(3))
    rng = np.random.default_rng(3)
    for t in range(3):
        keys = sim.keys(100 + t)
        wheels = rng.uniform(-1000, 1000, (sim.batch, 2)).astype(np.float32)
        new, obs, _, _ = sim.step(world, keys, state, wheels)
        batched = {**ref.state_to_numpy(new), **ref.obs_to_numpy(obs)}
        for i in range(sim.batch):
            one_state, one_obs = sim.step_one(
                world, keys[i], jax.tree.map(lambda a, i=i: a[i], state), wheels[i]
            )
            one = {**ref.state_to_numpy(one_state), **ref.obs_to_numpy(one_obs)}
            for name, got in one.items():
                want = batched[name][i]
                if got.dtype.kind == "f":
                    rtol, atol = LOOP_RTOL.get(name, (0.0, 1e-5))
                    np.testing.assert_allclose(got, want, rtol=rtol, atol=atol, err_msg=name)
                else:
                    np.testing.assert_array_equal(got, want, err_msg=name)
        state = new


def test_same_key_same_trajectory(sim) -> None:
    """In ``real`` (noise and wanderers): robots 0 and 1 share every key, robot 2 starts the same
    but steps with other keys."""
    world = sim.world("real")
    reset_keys = sim.keys(7)
    reset_keys = jnp.stack([reset_keys[0]] * 3 + list(reset_keys[3:]))
    state, _ = sim.reset(world, reset_keys)
    leaves = [np.asarray(x) for x in jax.tree.leaves(state)]
    for x in leaves:
        np.testing.assert_array_equal(x[0], x[1])
        np.testing.assert_array_equal(x[0], x[2])
    wheels = np.full((sim.batch, 2), 400.0)
    runs = []
    for _ in range(2):
        s, traj = state, []
        for t in range(10):
            keys = sim.keys(50 + t)
            keys = jnp.stack([keys[0], keys[0]] + list(keys[2:]))
            s, obs, _, _ = sim.step(world, keys, s, wheels)
            parts = (
                s.pose,
                s.wanderers.reshape(sim.batch, -1),
                obs.ir,
                obs.blue.reshape(sim.batch, -1),
            )
            traj.append(np.concatenate([np.asarray(p, np.float64) for p in parts], axis=1))
        runs.append(np.stack(traj))
    np.testing.assert_array_equal(runs[0], runs[1])  # reproducible
    np.testing.assert_array_equal(runs[0][:, 0], runs[0][:, 1])  # same key, same trajectory
    assert np.abs(runs[0][:, 0] - runs[0][:, 2]).max() > 1e-4  # different key, different one


def test_padded_ray_cast_equals_one_ray_at_a_time() -> None:
    """cast_rays pads 23 rays to 24 (see geometry.cast_rays): no ray's answer may change."""
    seg = jnp.array([[0.0, 0.0, 1.0, 0.0], [1.0, 0.0, 1.0, 1.0], [0.0, 1.0, 0.0, 0.0]])
    box = jnp.array([[0.6, 0.6, 0.8, 0.8]])
    circ = jnp.array([[0.3, 0.7, 0.05], [0.7, 0.3, 0.1]])
    scene = envs.Scene(
        seg=seg,
        seg_material=jnp.array([1, 2, 1]),
        seg_height=jnp.array([0.1, 0.2, 0.1]),
        seg_valid=jnp.array([True, True, False]),  # the west wall is padding: never hit
        box=box,
        box_material=jnp.array([3]),
        box_height=jnp.array([0.3]),
        box_valid=jnp.array([True]),
        circ=circ,
        circ_material=jnp.array([1, 1]),
        circ_height=jnp.array([0.05, 0.06]),
        circ_valid=jnp.array([True, True]),
    )
    rng = np.random.default_rng(7)
    angles = rng.uniform(-np.pi, np.pi, 23)
    origins = jnp.asarray(rng.uniform(0.05, 0.95, (23, 2)), jnp.float32)
    dirs = jnp.asarray(np.stack([np.cos(angles), np.sin(angles)], 1), jnp.float32)
    together = jax.jit(envs.cast_rays)(origins, dirs, scene)
    alone = jax.jit(jax.vmap(lambda o, d: envs.cast_rays(o[None], d[None], scene)))(origins, dirs)
    for got, want in zip(together, alone, strict=True):
        assert got.shape == (23,)
        np.testing.assert_array_equal(got, np.asarray(want)[:, 0])
    t, material = np.asarray(together[0]), np.asarray(together[1])
    hit = np.isfinite(t)
    assert hit.any() and not hit.all()  # both cases are exercised
    assert np.all(material[hit] != 0) and np.all(material[~hit] == 0)


def test_reduce_pair_equals_two_reductions() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=(64, 19)).astype(np.float32)
    b = rng.uniform(-1, 1, (64, 19)).astype(np.float32)
    pair = jax.jit(
        jax.vmap(lambda x, y: geometry.reduce_pair(x, y, jnp.add, jnp.minimum, 0, np.inf))
    )
    sums, mins = pair(a, b)
    np.testing.assert_allclose(sums, a.astype(np.float64).sum(1), rtol=0, atol=1e-5)
    np.testing.assert_array_equal(mins, b.min(1))  # a min is exact whatever the order
    flags = jax.jit(
        jax.vmap(lambda x, y: geometry.reduce_pair(x > 1.5, y, jnp.logical_or, jnp.add, 0, 0))
    )(a, b)[0]
    np.testing.assert_array_equal(flags, (a > 1.5).any(1))
    assert flags.any() and not flags.all()


def test_push_out_matches_the_numpy_reference(sim) -> None:
    """resolve_disc (x and y pushes summed by reduce_pair) against the reference's plain loops."""
    world, params = sim.world("world1"), sim.params
    state = jax.tree.map(lambda x: x[0], sim.reset(world, sim.keys(5))[0])
    rng = np.random.default_rng(11)
    n = 256  # centres all over the arena, each moved up to 5 mm
    old = rng.uniform(world.arena[:2], world.arena[2:], (n, 2)).astype(np.float32)
    new = old + rng.uniform(-0.005, 0.005, (n, 2)).astype(np.float32)

    @jax.jit
    def moved(state, old, new):
        scene = envs.build_scene(state, world, params)
        return jax.vmap(lambda o, p: geometry.resolve_disc(o, p, params.body_radius, scene))(
            old, new
        )

    got = np.asarray(moved(state, old, new))
    scene = ref.build_scene(
        ref.state_to_numpy(state), ref.world_to_numpy(world), sim.params_np, exclude=-1
    )
    radius = float(params.body_radius)
    want = np.array([ref.resolve_disc(o, p, radius, scene) for o, p in zip(old, new, strict=True)])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)  # float32 vs float64, as for steps
    pushed = np.linalg.norm(want - new, axis=1) > 1e-6
    assert pushed.any() and not pushed.all()  # some discs were pushed out, some moved freely


@pytest.mark.slow
def test_ir_noise_has_the_webots_relative_std(sim) -> None:
    """IR readings in a noiseless world spread by Webots' per-distance relative std (SPEC 2)."""
    world = sim.world("world1")
    state, _ = sim.reset(world, sim.keys(7))
    keys = jax.random.split(jax.random.key(3), 2000)
    obs = jax.jit(jax.vmap(envs.observe, in_axes=(0, None, None, None)))(
        keys, jax.tree.map(lambda a: a[0], state), world, sim.params
    )
    ir = np.asarray(obs.ir)  # one pose, 2000 independent noise draws
    clean = np.asarray(
        jax.jit(envs.observe)(
            keys[0], jax.tree.map(lambda a: a[0], state), world, sim.quiet_params
        ).ir
    )
    far = clean < 67.2  # nothing within 7 cm: the last table value and its noise (0.04897)
    assert far.any()
    rel = ir[:, far] / clean[far] - 1.0
    assert abs(rel.std() - 0.04897) < 0.003
    assert abs(rel.mean()) < 0.003


@pytest.mark.slow
def test_camera_noise_never_invents_a_target(sim, probe_world) -> None:
    """Blob-level camera noise (SPEC 2): a clear view never reads "target seen"; a view of the
    goal is missed at about the miss rate, shifted by one column at about the shift rate, and
    never gains pixels."""
    world = probe_world.replace(camera_miss=0.05, camera_shift=0.1)
    observe = jax.jit(jax.vmap(envs.observe, in_axes=(0, None, None, None)))
    keys = jax.random.split(jax.random.key(5), 4000)
    clear = observe(keys, _goal_ahead(0.5, heading=math.pi), world, sim.quiet_params)
    assert int(np.asarray(clear.blue_pixels).max()) == 0
    goal = _goal_ahead(0.5, box=(2.7, 0.4))
    seen = observe(keys, goal, world, sim.quiet_params)
    clean = jax.jit(envs.observe)(keys[0], goal, probe_world, sim.quiet_params)
    n_clean, centroid = int(clean.blue_pixels), float(clean.blue_centroid)
    pixels, centroids = np.asarray(seen.blue_pixels), np.asarray(seen.blue_centroid)
    assert 0 < n_clean < 45 and (pixels <= n_clean).all()
    assert abs((pixels == 0).mean() - 0.05) < 0.015
    moved = (pixels > 0) & (np.abs(centroids - centroid) > 1e-4)
    assert abs(moved.mean() - 0.1 * 0.95) < 0.02
