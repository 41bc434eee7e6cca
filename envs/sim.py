"""The e-puck world as pure functions of one robot: ``reset``, ``observe`` and ``step``.

A step's draws (:func:`sample_step_noise`) are apart from the deterministic
:func:`step_with_noise`, so a NumPy reference (tests/reference_sim.py) replays the same step.
Batch with ``jax.vmap(step, in_axes=(0, 0, 0, None, None))``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .geometry import (
    Scene,
    cast_rays,
    kind_gaps,
    min_gap,
    ray_padding,
    reduce_pair,
    resolve_disc,
)
from .params import CAMERA_COLUMNS, CAMERA_ROWS, GOAL, MARKER, N_IR, WALL, SimParams
from .struct import pytree_dataclass
from .world import World

ROBOT_HEIGHT = 0.05  # an e-puck body as the camera sees it, m [ours]
WANDER_SPEED = 300.0  # a wandering e-puck's cruise wheel speed [ours]
WANDER_TURN_PROB = 0.02  # chance per iteration that a cruising wanderer starts a turn [ours]
WANDER_TURN_STEPS = (10, 50)  # a random turn's length range, iterations [ours]
WANDER_AVOID_GAP = 0.03  # a wanderer spins away from a surface closer ahead, m [ours]
PLACEMENT_TRIES = 32  # candidates per object placed at reset (the first clear one is used)
PLACEMENT_CLEARANCE = 0.01  # minimum gap between objects placed at reset, m [ours]


@pytree_dataclass
class State:
    """Everything about one run that changes: pose [3] (x, y, heading), wanderers [W, 3],
    wander_timer [W] (iterations left in a turn; 0 cruising), wander_dir [W] (+1 left), goal [2],
    boxes [B, 2] (centres drawn at reset), t (iterations since reset)."""

    pose: jnp.ndarray
    wanderers: jnp.ndarray
    wander_timer: jnp.ndarray
    wander_dir: jnp.ndarray
    goal: jnp.ndarray
    boxes: jnp.ndarray
    t: jnp.ndarray


@pytree_dataclass
class Observation:
    """The sensors after a step: ir [8] (ps0..ps7, 0..4095) and their maximum vm; blue [3, 15]
    (marker or goal pixels after camera noise, row 0 the top), blue_pixels, goal_pixels (in
    columns seeing the goal), blue_centroid (mean column, 0 leftmost; 7 when none); materials
    [15] and depth [15] (m, inf out of range) of each column's first surface."""

    ir: jnp.ndarray
    vm: jnp.ndarray
    blue: jnp.ndarray
    blue_pixels: jnp.ndarray
    goal_pixels: jnp.ndarray
    blue_centroid: jnp.ndarray
    materials: jnp.ndarray
    depth: jnp.ndarray


@pytree_dataclass
class StepNoise:
    """One step's draws: normals wheel [2] and ir [8] (every world, SPEC 2); uniforms camera
    [2] (blob missed?, shifted which way?) and wander [W, 3] (turn?, length, direction)."""

    wheel: jnp.ndarray
    ir: jnp.ndarray
    camera: jnp.ndarray
    wander: jnp.ndarray


# ---------------------------------------------------------------------------------- scene


def _bounds(centre: jnp.ndarray, half: jnp.ndarray) -> jnp.ndarray:
    return jnp.concatenate([centre - half, centre + half], axis=-1)


def _append(kind: tuple, rows: jnp.ndarray, material: int, height) -> tuple:
    """One kind of surface's (geometry, material, height, valid) with ``rows`` [N, ...] added."""
    n = rows.shape[0]
    extra = (rows, jnp.full(n, material), jnp.full(n, height), jnp.ones(n, bool))
    return tuple(jnp.concatenate(pair) for pair in zip(kind, extra, strict=True))


def build_scene(state: State, world: World, params: SimParams, exclude: int = -1) -> Scene:
    """The scene seen by robot ``exclude`` (0 the robot, 1.. wanderers; -1 none): robots are
    circles of material wall, the goal a box or circle of material goal."""
    robots = jnp.concatenate([state.pose[None, :2], state.wanderers[:, :2]], axis=0)
    if exclude >= 0:  # a robot never sees itself: drop it (statically, so no work is wasted)
        robots = jnp.concatenate([robots[:exclude], robots[exclude + 1 :]], axis=0)
    n_r = robots.shape[0]
    robot_circ = jnp.concatenate([robots, jnp.full((n_r, 1), params.body_radius)], axis=1)
    box = _bounds(state.boxes, world.box_half)
    boxes = (box, world.box_material, world.box_height, world.box_valid)
    circs = (world.pillar, world.pillar_material, world.pillar_height, world.pillar_valid)
    circs = _append(circs, robot_circ, WALL, ROBOT_HEIGHT)
    if world.goal_shape == "box":
        boxes = _append(boxes, _bounds(state.goal, world.goal_half)[None], GOAL, world.goal_height)
    else:
        ball = jnp.concatenate([state.goal, world.goal_half[:1]])[None]
        circs = _append(circs, ball, GOAL, world.goal_height)
    box, box_mat, box_h, box_valid = boxes
    circ, circ_mat, circ_h, circ_valid = circs
    return Scene(
        seg=world.seg,
        seg_material=world.seg_material,
        seg_height=world.seg_height,
        seg_valid=world.seg_valid,
        box=box,
        box_material=box_mat.astype(jnp.int32),
        box_height=box_h,
        box_valid=box_valid,
        circ=circ,
        circ_material=circ_mat.astype(jnp.int32),
        circ_height=circ_h,
        circ_valid=circ_valid,
    )


# ---------------------------------------------------------------------------------- motion


def wheel_to_body(wheels: jnp.ndarray, params: SimParams) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Wheel speeds [2] (left, right; speed units) -> (forward speed m/s, turn rate rad/s)."""
    lin = wheels * params.speed_unit * params.wheel_radius
    return 0.5 * (lin[0] + lin[1]), (lin[1] - lin[0]) / params.axle


def integrate_pose(pose: jnp.ndarray, v: jnp.ndarray, w: jnp.ndarray, dt) -> jnp.ndarray:
    """Exact differential-drive arc over ``dt`` from pose [3] at speed v and turn rate w."""
    x, y, th = pose
    th1 = th + w * dt
    straight = jnp.abs(w) < 1e-6
    w_safe = jnp.where(straight, 1.0, w)
    dx = jnp.where(straight, v * dt * jnp.cos(th), v / w_safe * (jnp.sin(th1) - jnp.sin(th)))
    dy = jnp.where(straight, v * dt * jnp.sin(th), -v / w_safe * (jnp.cos(th1) - jnp.cos(th)))
    th1 = th1 - 2.0 * jnp.pi * jnp.round(th1 / (2.0 * jnp.pi))  # wrap to [-pi, pi]
    return jnp.stack([x + dx, y + dy, th1])


def _move(pose, wheels, scene, params):
    v, w = wheel_to_body(wheels, params)
    # The barrier computes the arc once per robot: XLA fused it into every surface's collision
    # test, slower and with copies an ulp apart.
    cand = jax.lax.optimization_barrier(integrate_pose(pose, v, w, params.dt))
    xy = resolve_disc(pose[:2], cand[:2], params.body_radius, scene)
    return jnp.concatenate([xy, cand[2:]])


def _wander_wheels(k: int, state: State, u: jnp.ndarray, scene: Scene, params: SimParams):
    """Wheel speeds, timer and turn direction of wanderer ``k`` (avoid-obstacles random walk)."""
    pose = state.wanderers[k]
    c, s = jnp.cos(pose[2]), jnp.sin(pose[2])
    # A surface is ahead when its normal (surface -> robot) points against the heading; the
    # wanderer spins away from the side that the nearby surfaces ahead push it from.
    near, push_left = False, 0.0
    for gap, nx, ny in kind_gaps(pose[:2], params.body_radius, scene):
        close = (nx * c + ny * s < 0.0) & (gap < WANDER_AVOID_GAP)
        lateral = jnp.where(close, (WANDER_AVOID_GAP - gap) * (c * ny - s * nx), 0.0)
        # One two-output reduction: plain ones would be computed once per wheel (reduce_pair).
        any_close, push = reduce_pair(close, lateral, jnp.logical_or, jnp.add, False, 0.0)
        near, push_left = near | any_close, push_left + push
    away = jnp.where(push_left >= 0.0, 1.0, -1.0)
    timer, turn = state.wander_timer[k], state.wander_dir[k]
    lo, hi = WANDER_TURN_STEPS
    start = (timer == 0) & (u[0] < WANDER_TURN_PROB)
    timer = jnp.where(start, lo + jnp.floor(u[1] * (hi - lo)).astype(jnp.int32), timer)
    turn = jnp.where(start, jnp.where(u[2] < 0.5, 1.0, -1.0), turn)
    turning = timer > 0
    v = WANDER_SPEED
    spin = jnp.stack([-away * v, away * v])
    arc = jnp.stack([v * (1.0 - 0.8 * (turn > 0)), v * (1.0 - 0.8 * (turn < 0))])
    wheels = jnp.where(near, spin, jnp.where(turning, arc, jnp.stack([v, v])))
    timer = jnp.where(near, timer, jnp.maximum(timer - 1, 0))
    return wheels, timer, turn


# ---------------------------------------------------------------------------------- sensing


def ir_reading(distance: jnp.ndarray, params: SimParams) -> jnp.ndarray:
    """IR reading(s) at ``distance`` (m from the rim): the table interpolated, its last value
    beyond it (Webots' e-puck returns about 67 with nothing in range, not 0: SPEC 2)."""
    return _table(distance, params.ir_dist, params.ir_value)


def ir_noise_std(distance: jnp.ndarray, params: SimParams) -> jnp.ndarray:
    """Relative std of the IR reading(s) at ``distance`` (Webots' calibrated table, SPEC 2)."""
    return _table(distance, params.ir_dist, params.ir_noise)


def _table(distance: jnp.ndarray, x: jnp.ndarray, y: jnp.ndarray) -> jnp.ndarray:
    """``jnp.interp(distance, x, y)`` for increasing ``x``, written as a telescoping sum of
    clipped ramps (a few fused ops instead of a search and a gather)."""
    d = distance[..., None]
    ramp = jnp.clip((d - x[:-1]) / (x[1:] - x[:-1]), 0.0, 1.0)
    return y[0] + jnp.sum(ramp * (y[1:] - y[:-1]), axis=-1)


def _shift_columns(a: jnp.ndarray, by: int) -> jnp.ndarray:
    """``a`` [..., 15] moved ``by`` (+-1) columns to the right, the vacated column False."""
    empty = jnp.zeros_like(a[..., :1])
    return jnp.concatenate([empty, a[..., :-1]] if by > 0 else [a[..., 1:], empty], axis=-1)


def _unit(angles: jnp.ndarray) -> jnp.ndarray:
    return jnp.stack([jnp.cos(angles), jnp.sin(angles)], axis=-1)


def _rotate(vecs: jnp.ndarray, c: jnp.ndarray, s: jnp.ndarray) -> jnp.ndarray:
    """Rotate [N, 2] vectors by the angle whose cosine and sine are c, s."""
    return jnp.stack([c * vecs[:, 0] - s * vecs[:, 1], s * vecs[:, 0] + c * vecs[:, 1]], axis=1)


def sense(state: State, noise: StepNoise, world: World, params: SimParams) -> Observation:
    """IR and camera readings of the robot in ``state``, with ``noise`` applied."""
    scene = build_scene(state, world, params, exclude=0)
    centre, th = state.pose[:2], state.pose[2]
    c, s = jnp.cos(th), jnp.sin(th)
    # Ray directions: fixed offsets from the heading rotated by it (two transcendentals, not 46).
    # IR rays leave the centre along each bearing (the rim is body_radius along the same ray);
    # camera rays leave the lens on the front rim, one per column, column 0 leftmost.
    pix = params.camera_fov / CAMERA_COLUMNS
    cols = jnp.arange(CAMERA_COLUMNS)
    cam_offsets = 0.5 * params.camera_fov - (cols + 0.5) * pix
    # Padded here to the vector lanes (copies of the last ray, dropped below), before the
    # rotation, cast_rays copies no robot's rays.
    n_rays = N_IR + CAMERA_COLUMNS
    pad = ray_padding(n_rays)
    units = _unit(jnp.concatenate([params.ir_bearings, cam_offsets]))
    dirs = _rotate(jnp.concatenate([units, jnp.repeat(units[-1:], pad, axis=0)]), c, s)
    lens = centre + params.body_radius * jnp.stack([c, s])
    origins = jnp.concatenate(
        [jnp.broadcast_to(centre, (N_IR, 2)), jnp.broadcast_to(lens, (CAMERA_COLUMNS + pad, 2))]
    )
    t, mat, height = (v[:n_rays] for v in cast_rays(origins, dirs, scene))

    rim = jnp.maximum(t[:N_IR] - params.body_radius, 0.0)
    # Webots' per-distance relative noise in every world, and the world's own on top (the two
    # independent Gaussians combined into one with the summed variance).
    std = jnp.sqrt(ir_noise_std(rim, params) ** 2 + world.ir_noise**2)
    ir = jnp.clip(ir_reading(rim, params) * (1.0 + std * noise.ir), 0.0, params.ir_value[0])

    depth, cmat, ch = t[N_IR:], mat[N_IR:], height[N_IR:]
    in_range = depth <= params.camera_range
    cmat = jnp.where(in_range, cmat, 0)
    # Row k (0 = top) looks at elevation e_k = +pix, 0, -pix and sees the surface where
    # atan(-camera_height / d) <= e_k <= atan((height - camera_height) / d), i.e. with
    # d tan(e_k) between those two heights (no arctangent needed).
    rise = jnp.tan(pix * (CAMERA_ROWS // 2 - jnp.arange(CAMERA_ROWS)))[:, None] * depth[None, :]
    covers = (rise <= ch[None, :] - params.camera_height) & (rise >= -params.camera_height)
    is_blue = ((cmat == MARKER) | (cmat == GOAL))[None, :]
    blue = covers & is_blue
    goal_cols = jnp.broadcast_to((cmat == GOAL)[None, :], blue.shape)
    if world.camera_miss > 0 or world.camera_shift > 0:
        # Camera noise acts on the blob, never on single pixels, so it cannot invent a target
        # (SPEC 2): the blob is missed, or shifted one column left or right.
        u_shift = noise.camera[1]
        left = u_shift < 0.5 * world.camera_shift
        right = ~left & (u_shift < world.camera_shift)
        shifted = lambda a: jnp.where(
            left, _shift_columns(a, -1), jnp.where(right, _shift_columns(a, 1), a)
        )
        seen = noise.camera[0] >= world.camera_miss
        blue, goal_cols = shifted(blue) & seen, shifted(goal_cols)
    n_blue = jnp.sum(blue, dtype=jnp.int32)
    goal_px = jnp.sum(blue & goal_cols, dtype=jnp.int32)
    col_sum = jnp.sum(blue * cols[None, :])
    centroid = jnp.where(n_blue > 0, col_sum / jnp.maximum(n_blue, 1), (CAMERA_COLUMNS - 1) / 2)
    return Observation(
        ir=ir,
        vm=jnp.max(ir),
        blue=blue,
        blue_pixels=n_blue,
        goal_pixels=goal_px,
        blue_centroid=centroid.astype(jnp.float32),
        materials=cmat.astype(jnp.int32),
        depth=jnp.where(in_range, depth, jnp.inf),
    )


# ---------------------------------------------------------------------------------- API


def sample_step_noise(key: jax.Array, world: World) -> StepNoise:
    """Every random number of a step (zeros for noise the world turns off), sliced from one
    uniform draw: each threefry hash is a loop of its own on CPU."""
    n_w = world.n_wanderers
    noisy_camera = world.camera_miss > 0 or world.camera_shift > 0
    n_u = 3 * n_w + (2 if noisy_camera else 0)
    n_z = (2 if world.wheel_noise > 0 else 0) + N_IR
    u = jax.random.uniform(key, (n_u + n_z,))
    # Normals as jax.random.normal makes them, sqrt(2) erfinv(v) of v uniform in (-1, 1); v = -1
    # (u = 0) moves to the next float, where erfinv is finite.
    v = jnp.maximum(2.0 * u[n_u:] - 1.0, np.nextafter(np.float32(-1.0), np.float32(0.0)))
    u, z = u[:n_u], np.sqrt(np.float32(2.0)) * jax.lax.erf_inv(v)
    wander, u = u[: 3 * n_w].reshape(n_w, 3), u[3 * n_w :]
    # A blob is never missed or shifted below a probability of 0: a clean camera gets ones.
    camera = u if noisy_camera else jnp.ones(2)
    wheel, ir = (z[:2], z[2:]) if world.wheel_noise > 0 else (jnp.zeros(2), z)
    return StepNoise(wheel=wheel, ir=ir, camera=camera, wander=wander)


def step_with_noise(
    state: State, wheel_speeds: jnp.ndarray, noise: StepNoise, world: World, params: SimParams
) -> tuple[State, Observation]:
    """One iteration (dt) given the step's random draws; see :func:`step`."""
    wheels = jnp.clip(wheel_speeds, -params.max_speed, params.max_speed)
    if world.wheel_noise > 0:
        wheels = wheels * (1.0 + world.wheel_noise * noise.wheel)
    pose = _move(state.pose, wheels, build_scene(state, world, params, exclude=0), params)
    state = state.replace(pose=pose)
    # Wanderers move one after another against everyone's latest position, so none steps into a
    # robot that already moved; rows are stacked, not scattered (slow on CPU).
    poses = [state.wanderers[k] for k in range(world.n_wanderers)]
    timers, dirs = [], []
    for k in range(world.n_wanderers):
        scene = build_scene(state, world, params, exclude=k + 1)
        w_wheels, timer, turn = _wander_wheels(k, state, noise.wander[k], scene, params)
        poses[k] = _move(poses[k], w_wheels, scene, params)
        timers.append(timer)
        dirs.append(turn)
        state = state.replace(wanderers=jnp.stack(poses))
    if world.n_wanderers:
        state = state.replace(wander_timer=jnp.stack(timers), wander_dir=jnp.stack(dirs))
    state = state.replace(t=state.t + 1)
    return state, sense(state, noise, world, params)


def step(
    key: jax.Array, state: State, wheel_speeds: jnp.ndarray, world: World, params: SimParams
) -> tuple[State, Observation]:
    """One iteration: the robot driven at ``wheel_speeds`` [2] (left, right; clipped), the
    wanderers moved, the sensors read. Returns (state, observation)."""
    return step_with_noise(state, wheel_speeds, sample_step_noise(key, world), world, params)


def observe(key: jax.Array, state: State, world: World, params: SimParams) -> Observation:
    """Sensor readings in ``state`` (e.g. after reset), with noise from ``key``."""
    return sense(state, sample_step_noise(key, world), world, params)


def _place(key: jax.Array, region: jnp.ndarray, radius, scene: Scene) -> jnp.ndarray:
    """The first of ``PLACEMENT_TRIES`` points drawn in ``region`` where a disc of ``radius``
    clears ``scene`` (the first point if none does)."""
    u = jax.random.uniform(key, (PLACEMENT_TRIES, 2))
    cands = region[:2] + u * (region[2:] - region[:2])
    clear = jax.vmap(lambda c: min_gap(c, radius, scene) >= 0)(cands)
    return cands[jnp.argmax(clear)]


def reset(key: jax.Array, world: World, params: SimParams) -> State:
    """A fresh run: boxes, goal, robot, wanderers placed in that order, each at the first of
    ``PLACEMENT_TRIES`` candidates in its region clear of those before."""
    n_b, n_w = world.box_half.shape[0], world.n_wanderers
    k_box, k_goal, k_pos, k_head, k_wand, k_wh = jax.random.split(key, 6)
    far = jnp.full((2,), -100.0)
    state = State(
        pose=jnp.concatenate([far, jnp.zeros(1)]),
        wanderers=jnp.tile(jnp.array([-100.0, -100.0, 0.0]), (n_w, 1)),
        wander_timer=jnp.zeros(n_w, jnp.int32),
        wander_dir=jnp.ones(n_w),
        goal=far,
        boxes=jnp.tile(far, (n_b, 1)),
        t=jnp.zeros((), jnp.int32),
    )
    # Parked objects sit far outside the arena, so scenes built while placing ignore them.

    def place_box(b, state):
        # A box is tested as its circumscribed disc: conservative and cheap.
        r = jnp.linalg.norm(world.box_half[b]) + PLACEMENT_CLEARANCE
        scene = build_scene(state, world, params)
        xy = _place(jax.random.fold_in(k_box, b), world.box_region[b], r, scene)
        return state.replace(boxes=state.boxes.at[b].set(xy))

    # A loop rather than unrolled code: one copy of the placement test in the compiled program.
    state = jax.lax.fori_loop(0, n_b, place_box, state)
    scene = build_scene(state, world, params)
    r = jnp.linalg.norm(world.goal_half) if world.goal_shape == "box" else world.goal_half[0]
    state = state.replace(goal=_place(k_goal, world.goal_region, r + PLACEMENT_CLEARANCE, scene))

    def place_robot(key, region, state, exclude):
        scene = build_scene(state, world, params, exclude=exclude)
        return _place(key, region, params.body_radius + PLACEMENT_CLEARANCE, scene)

    heading = jax.random.uniform(
        k_head, (), minval=world.start_heading[0], maxval=world.start_heading[1]
    )
    xy = place_robot(k_pos, world.start_region, state, exclude=0)
    state = state.replace(pose=jnp.concatenate([xy, heading[None]]))
    wh = jax.random.uniform(k_wh, (n_w,), minval=-jnp.pi, maxval=jnp.pi)
    for k, kw in enumerate(jax.random.split(k_wand, max(n_w, 1))[:n_w]):
        xy = place_robot(kw, world.wanderer_region[k], state, exclude=k + 1)
        state = state.replace(
            wanderers=state.wanderers.at[k].set(jnp.concatenate([xy, wh[k : k + 1]]))
        )
    return state
