"""A plain NumPy reference of one simulator step: the oracle the JAX simulator is tested against.

Written for one robot, one ray and one surface at a time, in float64 and with Python loops, so
that each rule of SPEC sections 1-3 reads as it is stated. :func:`ref_step` mirrors
:func:`jaxais.envs.step_with_noise` (clipping, wheel noise, exact arc, push-out collision
resolution with the same passes, skin and revert rule, the wanderers' avoid-obstacles random
walk, then the IR and camera readings) and :func:`ref_sense` mirrors the sensing alone.

This module does not import JAX. It reads the simulator's dataclasses (``World``, ``SimParams``,
``State``, ``StepNoise``) by attribute name through ``np.asarray``, so they can be passed in
directly; dicts with the same keys work too. Batched (vmapped) containers must be indexed to one
robot first (see :func:`unbatch`).

Known, deliberate differences from the JAX code, which the tests allow for:

- The JAX ray caster stores the surface index in the low mantissa bits of the hit distance, so
  its distances are rounded down by a relative error below 1e-5, and among surfaces hit within
  that error it picks the lower index. Here distances are exact (float64) and ties go to the
  lower index only when exactly equal.
- Everything here is float64; the simulator is float32.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

# Constants mirrored from params.py, geometry.py and sim.py (tests check that they agree).
N_IR = 8
CAMERA_COLUMNS = 15
CAMERA_ROWS = 3
NONE, WALL, MARKER, GOAL = 0, 1, 2, 3
ROBOT_HEIGHT = 0.05
WANDER_SPEED = 300.0
WANDER_TURN_PROB = 0.02
WANDER_TURN_STEPS = (10, 50)
WANDER_AVOID_GAP = 0.03
COLLISION_ITERS = 1
"""Push-out passes per move (``geometry.resolve_disc``'s default)."""
COLLISION_SKIN = 2e-5
"""Clearance a push-out leaves, m (``geometry.resolve_disc``'s default)."""
STRAIGHT_TURN_RATE = 1e-6
"""Below this turn rate (rad/s) a move is integrated as a straight line."""
NORMAL_EPS = 1e-9
"""A disc centre closer than this to a surface has no normal; +x is used."""
PARALLEL_EPS = 1e-12
"""A ray whose direction crosses a segment's by less than this misses it."""

WORLD_ARRAYS = (
    "arena",
    "seg",
    "seg_material",
    "seg_height",
    "seg_valid",
    "box_half",
    "box_region",
    "box_material",
    "box_height",
    "box_valid",
    "pillar",
    "pillar_material",
    "pillar_height",
    "pillar_valid",
    "goal_half",
    "goal_height",
    "goal_region",
    "start_region",
    "start_heading",
    "wanderer_region",
)
WORLD_STATICS = ("name", "goal_shape", "ir_noise", "camera_miss", "camera_shift", "wheel_noise")
PARAM_FIELDS = (
    "dt",
    "speed_unit",
    "wheel_radius",
    "axle",
    "body_radius",
    "max_speed",
    "camera_fov",
    "camera_range",
    "camera_height",
    "ir_dist",
    "ir_value",
    "ir_noise",
    "ir_bearings",
)
STATE_FIELDS = ("pose", "wanderers", "wander_timer", "wander_dir", "goal", "boxes", "t")
NOISE_FIELDS = ("wheel", "ir", "camera", "wander")
OBS_FIELDS = (
    "ir",
    "vm",
    "blue",
    "blue_pixels",
    "goal_pixels",
    "blue_centroid",
    "materials",
    "depth",
)

INF = math.inf


# ---------------------------------------------------------------------------------- conversion


def _get(obj: Any, name: str) -> Any:
    return obj[name] if isinstance(obj, Mapping) else getattr(obj, name)


def _array(value: Any) -> np.ndarray:
    """Floats become float64, integers int64, booleans stay bool."""
    a = np.asarray(value)
    if a.dtype.kind == "f":
        return a.astype(np.float64)
    if a.dtype.kind in "iu":
        return a.astype(np.int64)
    return a


def _to_numpy(obj: Any, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    return {name: _array(_get(obj, name)) for name in names}


def world_to_numpy(world: Any) -> dict[str, Any]:
    """A ``World`` (or dict) as a dict of NumPy arrays plus its static fields as Python values."""
    out: dict[str, Any] = _to_numpy(world, WORLD_ARRAYS)
    for name in WORLD_STATICS:
        out[name] = _get(world, name)
    return out


def params_to_numpy(params: Any) -> dict[str, Any]:
    """``SimParams`` as a dict: scalars as Python floats, the tables as float64 arrays."""
    out: dict[str, Any] = _to_numpy(params, PARAM_FIELDS)
    for name, value in out.items():
        if value.ndim == 0:
            out[name] = float(value)
    return out


def state_to_numpy(state: Any) -> dict[str, np.ndarray]:
    """A ``State`` (one robot's, or a batch's) as a dict of NumPy arrays."""
    return _to_numpy(state, STATE_FIELDS)


def noise_to_numpy(noise: Any) -> dict[str, np.ndarray]:
    """A ``StepNoise`` (one robot's, or a batch's) as a dict of NumPy arrays."""
    return _to_numpy(noise, NOISE_FIELDS)


def obs_to_numpy(obs: Any) -> dict[str, np.ndarray]:
    """An ``Observation`` (one robot's, or a batch's) as a dict of NumPy arrays."""
    return _to_numpy(obs, OBS_FIELDS)


def unbatch(batch: Mapping[str, Any], i: int) -> dict[str, Any]:
    """Row ``i`` of every array in a dict made from a batched container."""
    return {k: v[i] if isinstance(v, np.ndarray) else v for k, v in batch.items()}


def _world(world: Any) -> dict[str, Any]:
    return world if isinstance(world, Mapping) else world_to_numpy(world)


def _params(params: Any) -> dict[str, Any]:
    return params if isinstance(params, Mapping) else params_to_numpy(params)


# ---------------------------------------------------------------------------------- geometry


class Surface(NamedTuple):
    """One surface of the scene.

    Attributes:
        kind: "segment", "box" or "circle".
        geom: (x1, y1, x2, y2) for a segment, (xmin, ymin, xmax, ymax) for a box, (x, y, r) for
            a circle.
        material: NONE, WALL, MARKER or GOAL.
        height: m.
    """

    kind: str
    geom: tuple[float, ...]
    material: int
    height: float


def ray_hit(o: tuple[float, float], d: tuple[float, float], s: Surface) -> float:
    """Distance along the ray ``o + t d`` (``|d| = 1``, t >= 0) to surface ``s``; inf on a miss.

    A ray starting inside a box or circle hits it at t = 0.
    """
    ox, oy = o
    dx, dy = d
    if s.kind == "segment":
        x1, y1, x2, y2 = s.geom
        ex, ey = x2 - x1, y2 - y1
        wx, wy = x1 - ox, y1 - oy
        denom = dx * ey - dy * ex  # cross(d, e)
        if abs(denom) <= PARALLEL_EPS:
            return INF
        t = (wx * ey - wy * ex) / denom  # along the ray
        u = (wx * dy - wy * dx) / denom  # along the segment, 0..1
        return t if t >= 0.0 and 0.0 <= u <= 1.0 else INF
    if s.kind == "box":
        # Slab method: intersect the ray's parameter interval with each axis' slab.
        t_near, t_far = 0.0, INF
        for o_k, d_k, lo, hi in ((ox, dx, s.geom[0], s.geom[2]), (oy, dy, s.geom[1], s.geom[3])):
            if abs(d_k) < 1e-9:  # parallel to this slab: inside it or never
                if not lo <= o_k <= hi:
                    return INF
                continue
            t1, t2 = (lo - o_k) / d_k, (hi - o_k) / d_k
            t_near, t_far = max(t_near, min(t1, t2)), min(t_far, max(t1, t2))
        return t_near if t_far >= t_near else INF
    cx, cy, r = s.geom
    wx, wy = cx - ox, cy - oy
    b = wx * dx + wy * dy  # centre's projection on the ray
    c2 = wx * wx + wy * wy - r * r  # < 0: the origin is inside
    disc = b * b - c2
    if disc < 0.0:
        return INF
    if c2 < 0.0:
        return 0.0
    t = b - math.sqrt(disc)
    return t if t >= 0.0 else INF


def cast_ray(
    o: tuple[float, float], d: tuple[float, float], scene: list[Surface]
) -> tuple[float, int, float, list[float]]:
    """The first surface along a ray.

    Returns:
        (distance, inf on a miss; its material, NONE on a miss; its height, 0 on a miss;
         the distance to every surface of ``scene``, in order).
    """
    hits = [ray_hit(o, d, s) for s in scene]
    best, t = -1, INF
    for k, h in enumerate(hits):
        if h < t:  # strict: an exact tie goes to the earlier surface, as in the simulator
            best, t = k, h
    if best < 0:
        return INF, NONE, 0.0, hits
    return t, scene[best].material, scene[best].height, hits


def disc_gap(p: tuple[float, float], radius: float, s: Surface) -> tuple[float, float, float]:
    """Clearance between a disc and a surface, with the unit normal from the surface to ``p``.

    Returns:
        (gap = distance from the centre to the surface minus ``radius`` (minus the circle's
         radius for a circle); nx, ny).
    """
    px, py = p
    extra = 0.0
    if s.kind == "segment":
        x1, y1, x2, y2 = s.geom
        ex, ey = x2 - x1, y2 - y1
        u = ((px - x1) * ex + (py - y1) * ey) / max(ex * ex + ey * ey, 1e-12)
        u = min(max(u, 0.0), 1.0)
        vx, vy = px - (x1 + u * ex), py - (y1 + u * ey)
    elif s.kind == "box":
        xmin, ymin, xmax, ymax = s.geom
        vx, vy = px - min(max(px, xmin), xmax), py - min(max(py, ymin), ymax)
    else:
        cx, cy, extra = s.geom
        vx, vy = px - cx, py - cy
    dist = math.hypot(vx, vy)
    if dist > NORMAL_EPS:
        nx, ny = vx / dist, vy / dist
    else:
        nx, ny = 1.0, 0.0
    return dist - extra - radius, nx, ny


def min_gap(p: tuple[float, float], radius: float, scene: list[Surface]) -> float:
    """Smallest clearance (m) between a disc and the scene; negative means overlap."""
    return min((disc_gap(p, radius, s)[0] for s in scene), default=INF)


def resolve_disc(
    p_old: tuple[float, float],
    p_new: tuple[float, float],
    radius: float,
    scene: list[Surface],
    iters: int = COLLISION_ITERS,
    skin: float = COLLISION_SKIN,
) -> tuple[float, float]:
    """Move a disc from ``p_old`` to ``p_new`` without overlap.

    Each pass moves the disc out of every surface closer than ``skin``, along that surface's
    normal, to ``skin`` clearance (all surfaces' pushes of a pass are summed). If the disc still
    overlaps something after ``iters`` passes it stays at ``p_old``.
    """
    x, y = p_new
    for _ in range(iters):
        push_x = push_y = 0.0
        for s in scene:
            gap, nx, ny = disc_gap((x, y), radius, s)
            if gap < skin:
                push_x += (skin - gap) * nx
                push_y += (skin - gap) * ny
        x, y = x + push_x, y + push_y
    if min_gap((x, y), radius, scene) >= 0.0:
        return x, y
    return float(p_old[0]), float(p_old[1])


# ---------------------------------------------------------------------------------- scene


def build_scene(
    state: Mapping[str, np.ndarray],
    world: Mapping[str, Any],
    params: Mapping[str, Any],
    exclude: int,
) -> list[Surface]:
    """Every valid surface around robot ``exclude`` (0 = the robot, k = wanderer k-1, -1 = none).

    The order is the simulator's: segments; boxes, then a goal block; pillars, then the robots,
    then a goal ball.
    """
    segments, boxes, circles = [], [], []
    for k in range(len(world["seg"])):
        if world["seg_valid"][k]:
            segments.append(
                Surface(
                    "segment",
                    tuple(float(v) for v in world["seg"][k]),
                    int(world["seg_material"][k]),
                    float(world["seg_height"][k]),
                )
            )
    for k in range(len(world["box_half"])):
        if world["box_valid"][k]:
            (cx, cy), (hx, hy) = state["boxes"][k], world["box_half"][k]
            boxes.append(
                Surface(
                    "box",
                    (cx - hx, cy - hy, cx + hx, cy + hy),
                    int(world["box_material"][k]),
                    float(world["box_height"][k]),
                )
            )
    for k in range(len(world["pillar"])):
        if world["pillar_valid"][k]:
            circles.append(
                Surface(
                    "circle",
                    tuple(float(v) for v in world["pillar"][k]),
                    int(world["pillar_material"][k]),
                    float(world["pillar_height"][k]),
                )
            )
    robots = [state["pose"][:2]] + [w[:2] for w in state["wanderers"]]
    for k, (x, y) in enumerate(robots):
        if k != exclude:
            circles.append(
                Surface("circle", (float(x), float(y), params["body_radius"]), WALL, ROBOT_HEIGHT)
            )
    (gx, gy), (hx, hy) = state["goal"], world["goal_half"]
    goal_h = float(world["goal_height"])
    if world["goal_shape"] == "box":
        boxes.append(Surface("box", (gx - hx, gy - hy, gx + hx, gy + hy), GOAL, goal_h))
    else:
        circles.append(Surface("circle", (float(gx), float(gy), float(hx)), GOAL, goal_h))
    return segments + boxes + circles


# ---------------------------------------------------------------------------------- motion


def wheel_to_body(wheels, params: Mapping[str, Any]) -> tuple[float, float]:
    """Wheel speeds (left, right; speed units) -> (forward speed m/s, turn rate rad/s)."""
    left, right = (float(w) * params["speed_unit"] * params["wheel_radius"] for w in wheels)
    return 0.5 * (left + right), (right - left) / params["axle"]


def wrap_angle(a: float) -> float:
    """``a`` wrapped to [-pi, pi] (round half to even, as ``jnp.round``)."""
    return a - 2.0 * math.pi * float(np.round(a / (2.0 * math.pi)))


def integrate_pose(pose, v: float, w: float, dt: float) -> tuple[float, float, float]:
    """Exact differential-drive motion over ``dt``: an arc of radius v / w, or a straight line."""
    x, y, th = (float(c) for c in pose)
    th1 = th + w * dt
    if abs(w) < STRAIGHT_TURN_RATE:
        x1, y1 = x + v * dt * math.cos(th), y + v * dt * math.sin(th)
    else:
        x1 = x + v / w * (math.sin(th1) - math.sin(th))
        y1 = y - v / w * (math.cos(th1) - math.cos(th))
    return x1, y1, wrap_angle(th1)


def move(pose, wheels, scene: list[Surface], params: Mapping[str, Any]) -> np.ndarray:
    """Drive one robot for ``dt`` and resolve collisions; the heading is never blocked."""
    v, w = wheel_to_body(wheels, params)
    x, y, th = integrate_pose(pose, v, w, params["dt"])
    x, y = resolve_disc((float(pose[0]), float(pose[1])), (x, y), params["body_radius"], scene)
    return np.array([x, y, th])


def wander_wheels(
    pose, timer: int, turn: float, u, scene: list[Surface], params: Mapping[str, Any]
) -> tuple[np.ndarray, int, float]:
    """One wanderer's avoid-obstacles random walk.

    A surface closer than ``WANDER_AVOID_GAP`` whose normal points against the heading is
    "ahead"; with any ahead, the wanderer spins on the spot away from the side they push it from
    (its timer paused). Otherwise a cruising wanderer (timer 0) starts, with probability
    ``WANDER_TURN_PROB`` (uniform ``u[0]``), a random arc of ``u[1]``-drawn length towards the
    ``u[2]``-drawn side; while the timer runs it arcs, else it drives straight.

    Args:
        pose: [3] its pose. timer: iterations left in a turn. turn: +1 left, -1 right.
        u: [3] uniforms of this step. scene: everything but itself.

    Returns:
        ((left, right) wheel speeds, new timer, new turn direction).
    """
    c, s = math.cos(pose[2]), math.sin(pose[2])
    near, push_left = False, 0.0
    for surface in scene:
        gap, nx, ny = disc_gap((float(pose[0]), float(pose[1])), params["body_radius"], surface)
        if nx * c + ny * s < 0.0 and gap < WANDER_AVOID_GAP:
            near = True
            push_left += (WANDER_AVOID_GAP - gap) * (c * ny - s * nx)  # normal . left
    away = 1.0 if push_left >= 0.0 else -1.0
    lo, hi = WANDER_TURN_STEPS
    timer, turn = int(timer), float(turn)
    if timer == 0 and u[0] < WANDER_TURN_PROB:
        timer = lo + math.floor(u[1] * (hi - lo))
        turn = 1.0 if u[2] < 0.5 else -1.0
    v = WANDER_SPEED
    if near:
        return np.array([-away * v, away * v]), timer, turn
    if timer > 0:
        wheels = np.array([v * (1.0 - 0.8 * (turn > 0)), v * (1.0 - 0.8 * (turn < 0))])
    else:
        wheels = np.array([v, v])
    return wheels, max(timer - 1, 0), turn


# ---------------------------------------------------------------------------------- sensing


def ir_reading(rim_distance: float, params: Mapping[str, Any]) -> float:
    """Piecewise-linear table reading at a distance from the body rim; the last value beyond."""
    return float(np.interp(rim_distance, params["ir_dist"], params["ir_value"]))


def _shift(a: np.ndarray, by: int) -> np.ndarray:
    """``a`` [..., 15] moved ``by`` columns to the right (negative: left), vacated columns False."""
    out = np.zeros_like(a)
    if by > 0:
        out[..., by:] = a[..., :-by]
    elif by < 0:
        out[..., :by] = a[..., -by:]
    else:
        out[...] = a
    return out


def ref_sense(state: Any, noise: Any, world: Any, params: Any) -> dict[str, Any]:
    """IR and camera readings of the robot in ``state``, with ``noise`` applied.

    Args:
        state: one robot's ``State`` (or its dict).
        noise: one robot's ``StepNoise`` (or its dict), used where the world is noisy; ``None``
            reads without noise whatever the world says.
        world, params: as for the simulator.

    Returns:
        The fields of ``Observation`` (``ir``, ``vm``, ``blue`` [3, 15], ``blue_pixels``,
        ``goal_pixels``, ``blue_centroid``, ``materials`` [15], ``depth`` [15]) plus, for tests
        that must tell a real mismatch from a near tie: ``ray_t`` [23] exact first-hit distance
        of the 8 IR rays then the 15 camera rays (not cut at camera range), ``ray_height`` [23],
        ``ray_hits`` [23, P] every surface's hit distance and ``surface_material`` [P].
    """
    world, params, state = _world(world), _params(params), state_to_numpy(state)
    if noise is None:
        world = {**world, "ir_noise": 0.0, "camera_miss": 0.0, "camera_shift": 0.0}
        params = {**params, "ir_noise": np.zeros_like(params["ir_noise"])}
    else:
        noise = noise_to_numpy(noise)
    scene = build_scene(state, world, params, exclude=0)
    x, y, th = (float(v) for v in state["pose"])
    r = params["body_radius"]

    # IR: rays from the centre along each bearing; the sensor sits on the rim of the same ray.
    rays = [((x, y), float(b)) for b in params["ir_bearings"]]
    # Camera: one ray per column from the lens on the front rim, column 0 leftmost.
    pix = params["camera_fov"] / CAMERA_COLUMNS
    lens = (x + r * math.cos(th), y + r * math.sin(th))
    rays += [(lens, 0.5 * params["camera_fov"] - (col + 0.5) * pix) for col in range(15)]
    ray_t, ray_mat, ray_h, ray_hits = [], [], [], []
    for origin, bearing in rays:
        t, mat, h, hits = cast_ray(origin, (math.cos(th + bearing), math.sin(th + bearing)), scene)
        ray_t.append(t)
        ray_mat.append(mat)
        ray_h.append(h)
        ray_hits.append(hits)

    rims = [max(t - r, 0.0) for t in ray_t[:N_IR]]
    ir = np.array([ir_reading(d, params) for d in rims])
    if noise is not None:
        table = np.interp(rims, params["ir_dist"], params["ir_noise"])
        std = np.sqrt(table**2 + world["ir_noise"] ** 2)
        ir = np.clip(ir * (1.0 + std * noise["ir"]), 0.0, params["ir_value"][0])

    materials = np.zeros(CAMERA_COLUMNS, np.int64)
    depth = np.full(CAMERA_COLUMNS, INF)
    blue = np.zeros((CAMERA_ROWS, CAMERA_COLUMNS), bool)
    cam_h = params["camera_height"]
    for col in range(CAMERA_COLUMNS):
        t, mat, h = ray_t[N_IR + col], ray_mat[N_IR + col], ray_h[N_IR + col]
        if t > params["camera_range"]:
            continue
        materials[col], depth[col] = mat, t
        if mat not in (MARKER, GOAL):
            continue
        for row in range(CAMERA_ROWS):
            # Row 0 looks up by one pixel, row 2 down by one: it sees the surface where the
            # line of sight at distance t lies between the floor and the surface's top.
            rise = math.tan(pix * (CAMERA_ROWS // 2 - row)) * t
            blue[row, col] = -cam_h <= rise <= h - cam_h
    goal_cols = np.broadcast_to(materials == GOAL, blue.shape)
    if noise is not None:  # the blob missed, or shifted one column left or right
        shift = 0
        if noise["camera"][1] < 0.5 * world["camera_shift"]:
            shift = -1
        elif noise["camera"][1] < world["camera_shift"]:
            shift = 1
        blue, goal_cols = (_shift(a, shift) for a in (blue, goal_cols))
        if noise["camera"][0] < world["camera_miss"]:
            blue = np.zeros_like(blue)
    n_blue = int(blue.sum())
    goal_px = int((blue & goal_cols).sum())
    cols = np.broadcast_to(np.arange(CAMERA_COLUMNS), blue.shape)
    centroid = float(cols[blue].mean()) if n_blue else (CAMERA_COLUMNS - 1) / 2
    return {
        "ir": ir,
        "vm": float(ir.max()),
        "blue": blue,
        "blue_pixels": n_blue,
        "goal_pixels": goal_px,
        "blue_centroid": centroid,
        "materials": materials,
        "depth": depth,
        "ray_t": np.array(ray_t),
        "ray_height": np.array(ray_h),
        "ray_hits": np.array(ray_hits).reshape(len(rays), len(scene)),
        "surface_material": np.array([s.material for s in scene], np.int64),
    }


# ---------------------------------------------------------------------------------- step


def ref_step(
    state: Any, wheel_speeds: Any, noise: Any, world: Any, params: Any
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """One iteration, as :func:`jaxais.envs.step_with_noise`.

    The robot's commanded speeds are clipped to ``max_speed`` and, in a noisy world, scaled by
    ``1 + wheel_noise * noise.wheel``; it moves against the scene as it was. Then each wanderer in
    turn chooses its wheels and moves against everyone's latest position. Finally the robot's
    sensors are read (:func:`ref_sense`).

    Args:
        state: one robot's ``State`` (or its dict). wheel_speeds: [2] (left, right), speed units.
        noise: one robot's ``StepNoise`` (or its dict). world, params: as for the simulator.

    Returns:
        (new state as a dict of NumPy arrays, observation dict as :func:`ref_sense`).
    """
    world, params, state = _world(world), _params(params), state_to_numpy(state)
    noise = noise_to_numpy(noise)
    state = {k: v.copy() for k, v in state.items()}

    wheels = np.clip(
        np.asarray(wheel_speeds, np.float64), -params["max_speed"], params["max_speed"]
    )
    if world["wheel_noise"] > 0:
        wheels = wheels * (1.0 + world["wheel_noise"] * noise["wheel"])
    scene = build_scene(state, world, params, exclude=0)
    state["pose"] = move(state["pose"], wheels, scene, params)

    for k in range(len(state["wanderers"])):
        scene = build_scene(state, world, params, exclude=k + 1)
        w_wheels, timer, turn = wander_wheels(
            state["wanderers"][k],
            state["wander_timer"][k],
            state["wander_dir"][k],
            noise["wander"][k],
            scene,
            params,
        )
        state["wanderers"][k] = move(state["wanderers"][k], w_wheels, scene, params)
        state["wander_timer"][k] = timer
        state["wander_dir"][k] = turn
    state["t"] = state["t"] + 1
    return state, ref_sense(state, noise, world, params)


def clearances(state: Any, world: Any, params: Any) -> np.ndarray:
    """[1 + W] clearance (m) of the robot and of each wanderer to everything else."""
    world, params, state = _world(world), _params(params), state_to_numpy(state)
    robots = [state["pose"]] + list(state["wanderers"])
    return np.array(
        [
            min_gap(
                (float(p[0]), float(p[1])),
                params["body_radius"],
                build_scene(state, world, params, exclude=k),
            )
            for k, p in enumerate(robots)
        ]
    )
