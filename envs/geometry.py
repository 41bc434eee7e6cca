"""Ray casting and disc collision against a 2D scene of segments, boxes and circles.

Everything is written for one robot (one set of rays or one disc); batch with ``vmap``.
Boxes are axis-aligned rectangles; circles are pillars, robots and the goal ball.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .struct import pytree_dataclass

INF = jnp.inf
_EPS = 1e-12


@pytree_dataclass
class Scene:
    """Every surface one robot can see or touch, with fixed shapes.

    Attributes:
        seg: [S, 4] (x1, y1, x2, y2); seg_material, seg_height, seg_valid: [S].
        box: [B, 4] bounds (xmin, ymin, xmax, ymax); box_material, box_height, box_valid: [B].
        circ: [C, 3] (x, y, r); circ_material, circ_height, circ_valid: [C].
    """

    seg: jnp.ndarray
    seg_material: jnp.ndarray
    seg_height: jnp.ndarray
    seg_valid: jnp.ndarray
    box: jnp.ndarray
    box_material: jnp.ndarray
    box_height: jnp.ndarray
    box_valid: jnp.ndarray
    circ: jnp.ndarray
    circ_material: jnp.ndarray
    circ_height: jnp.ndarray
    circ_valid: jnp.ndarray


# The intersection tables below are laid out [surfaces, rays]: the rays (23 per robot) are the
# minor axis that XLA's CPU backend vectorises, and the nearest-surface reduction runs over the
# major axis as elementwise minima. The transposed layout runs slower (docs/performance.md).


def _ray_segments(o: jnp.ndarray, d: jnp.ndarray, seg: jnp.ndarray) -> jnp.ndarray:
    """Hit distance [S, R] of rays o + t d (o, d: [R, 2], |d| = 1) on segments; inf = miss."""
    ox, oy, dx, dy = o[:, 0], o[:, 1], d[:, 0], d[:, 1]
    ex, ey = (seg[:, 2] - seg[:, 0])[:, None], (seg[:, 3] - seg[:, 1])[:, None]
    wx, wy = seg[:, 0:1] - ox, seg[:, 1:2] - oy
    denom = dx * ey - dy * ex
    ok = jnp.abs(denom) > _EPS
    inv = 1.0 / jnp.where(ok, denom, 1.0)
    t = (wx * ey - wy * ex) * inv
    u = (wx * dy - wy * dx) * inv
    hit = ok & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
    return jnp.where(hit, t, INF)


def _ray_boxes(o: jnp.ndarray, inv_d: jnp.ndarray, box: jnp.ndarray) -> jnp.ndarray:
    """Hit distance [B, R] of rays on axis-aligned boxes (slab method); 0 if o is inside.

    ``inv_d`` [R, 2] is 1 / direction, computed once per ray rather than once per box.
    """
    ox, oy, ix, iy = o[:, 0], o[:, 1], inv_d[:, 0], inv_d[:, 1]
    tx1, tx2 = (box[:, 0:1] - ox) * ix, (box[:, 2:3] - ox) * ix
    ty1, ty2 = (box[:, 1:2] - oy) * iy, (box[:, 3:4] - oy) * iy
    tnear = jnp.maximum(jnp.minimum(tx1, tx2), jnp.minimum(ty1, ty2))
    tfar = jnp.minimum(jnp.maximum(tx1, tx2), jnp.maximum(ty1, ty2))
    tnear = jnp.maximum(tnear, 0.0)
    return jnp.where(tfar >= tnear, tnear, INF)


def _ray_circles(o: jnp.ndarray, d: jnp.ndarray, circ: jnp.ndarray) -> jnp.ndarray:
    """Hit distance [C, R] of rays on circles; 0 if o is inside."""
    wx, wy = circ[:, 0:1] - o[:, 0], circ[:, 1:2] - o[:, 1]
    b = wx * d[:, 0] + wy * d[:, 1]
    c2 = wx * wx + wy * wy - circ[:, 2:3] ** 2
    disc = b * b - c2
    t = b - jnp.sqrt(jnp.maximum(disc, 0.0))
    inside = c2 < 0.0
    hit = (disc >= 0.0) & ((t >= 0.0) | inside)
    return jnp.where(hit, jnp.where(inside, 0.0, t), INF)


def _per_kind_hits(origins: jnp.ndarray, dirs: jnp.ndarray, scene: Scene):
    """Hit distances per kind of surface: ([S, R], [B, R], [C, R]), inf where missed."""
    # Avoid 1/0 for axis-parallel rays: a tiny component gives huge, correctly signed slabs.
    safe = jnp.where(jnp.abs(dirs) < 1e-9, jnp.where(dirs < 0, -1e-9, 1e-9), dirs)
    return (
        jnp.where(scene.seg_valid[:, None], _ray_segments(origins, dirs, scene.seg), INF),
        jnp.where(scene.box_valid[:, None], _ray_boxes(origins, 1.0 / safe, scene.box), INF),
        jnp.where(scene.circ_valid[:, None], _ray_circles(origins, dirs, scene.circ), INF),
    )


_INDEX_BITS = 6
_INDEX_MASK = (1 << _INDEX_BITS) - 1
_RAY_LANES = 8


def ray_padding(n_rays: int) -> int:
    """How many rays :func:`cast_rays` adds to ``n_rays`` to fill the CPU's vector lanes."""
    return -n_rays % _RAY_LANES


def cast_rays(
    origins: jnp.ndarray, dirs: jnp.ndarray, scene: Scene
) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """First surface along each ray, with its material and height.

    Args:
        origins: [R, 2] ray origins. dirs: [R, 2] unit directions.
        scene: the surfaces (at most 64 in all).

    Returns:
        (t [R] distance, inf when nothing is hit; material [R] int (0 on a miss);
         height [R] of that surface).
    """
    n_s, n_b, n_c = scene.seg.shape[0], scene.box.shape[0], scene.circ.shape[0]
    assert n_s + n_b + n_c <= _INDEX_MASK + 1, "cast_rays handles at most 64 surfaces"
    # Rays are the minor axis of every table below, and XLA's CPU backend vectorises it in
    # 8-lane (AVX2) chunks: 23 rays leave a scalar remainder loop that halves the speed of the
    # whole cast, so the ray count is padded with copies of the last ray (dropped at the end).
    n_r = origins.shape[0]
    pad = ray_padding(n_r)
    if pad:
        origins = jnp.concatenate([origins, jnp.broadcast_to(origins[-1:], (pad, 2))])
        dirs = jnp.concatenate([dirs, jnp.broadcast_to(dirs[-1:], (pad, 2))])
    # Which surface is nearest is found with one integer min per kind: a non-negative float's bit
    # pattern orders like the float, so the surface's index goes into the low mantissa bits (a
    # relative error below 1e-5 on t). argmin + gather, or masked reductions, make XLA's CPU
    # backend recompute the intersection tests several times over (docs/performance.md).
    key = None
    for hits, offset in zip(_per_kind_hits(origins, dirs, scene), (0, n_s, n_s + n_b), strict=True):
        bits = jax.lax.bitcast_convert_type(hits, jnp.int32)
        index = offset + jnp.arange(hits.shape[0], dtype=jnp.int32)[:, None]
        k = jnp.min((bits & ~_INDEX_MASK) | index, axis=0)
        key = k if key is None else jnp.minimum(key, k)
    t = jax.lax.bitcast_convert_type(key & ~_INDEX_MASK, jnp.float32)
    index = key & _INDEX_MASK
    material = jnp.concatenate([scene.seg_material, scene.box_material, scene.circ_material])
    height = jnp.concatenate([scene.seg_height, scene.box_height, scene.circ_height])
    t, index = t[:n_r], index[:n_r]
    hit = jnp.isfinite(t)
    return t, jnp.where(hit, material[index], 0), jnp.where(hit, height[index], 0.0)


def reduce_pair(a, b, op_a, op_b, init_a, init_b) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Two reductions of two [N] vectors in one pass: (op_a over a, op_b over b), as scalars.

    XLA's CPU backend fuses a plain reduction into each consumer and evaluates it once per
    element of that consumer's output: a reduction feeding an (x, y) pair, or anything stacked
    with one, is computed once per component, and so are the per-surface terms it reads. A
    reduction with two outputs is not fused into its consumers (jax 0.10): it runs once, in a
    kernel of its own, computing those terms once. XLA compiles its arithmetic differently from
    a plain ``jnp.sum`` (e.g. where it fuses a multiply into an add), so a sum can differ in the
    last bit.

    Args:
        a, b: [N] arrays. op_a, op_b: associative binary ops (e.g. ``jnp.add``).
        init_a, init_b: their identities (e.g. 0.0, False).
    """
    init = (jnp.asarray(init_a, a.dtype), jnp.asarray(init_b, b.dtype))
    return jax.lax.reduce((a, b), init, lambda x, y: (op_a(x[0], y[0]), op_b(x[1], y[1])), (0,))


def kind_gaps(p: jnp.ndarray, radius: jnp.ndarray, scene: Scene):
    """Per kind of surface: (gap [P] = surface distance minus radius, inf where invalid;
    nx [P], ny [P]: the unit vector from the surface's closest point towards p).

    Written in x/y components: reductions over a length-2 axis are very slow on XLA's CPU backend.
    """
    px, py = p[0], p[1]
    # Segments: closest point on each.
    ax, ay = scene.seg[:, 0], scene.seg[:, 1]
    ex, ey = scene.seg[:, 2] - ax, scene.seg[:, 3] - ay
    u = jnp.clip(((px - ax) * ex + (py - ay) * ey) / jnp.maximum(ex * ex + ey * ey, _EPS), 0, 1)
    seg_v = (px - (ax + u * ex), py - (ay + u * ey))
    # Boxes: clamp into the rectangle.
    box_v = (
        px - jnp.clip(px, scene.box[:, 0], scene.box[:, 2]),
        py - jnp.clip(py, scene.box[:, 1], scene.box[:, 3]),
    )
    # Circles: centre to centre, less the circle's radius.
    circ_v = (px - scene.circ[:, 0], py - scene.circ[:, 1])
    out = []
    for (vx, vy), extra, valid in (
        (seg_v, 0.0, scene.seg_valid),
        (box_v, 0.0, scene.box_valid),
        (circ_v, scene.circ[:, 2], scene.circ_valid),
    ):
        dist = jnp.sqrt(vx * vx + vy * vy)
        # A centre exactly on a surface has no normal; use +x (resolve_disc then reverts).
        ok = dist > 1e-9
        inv = 1.0 / jnp.where(ok, dist, 1.0)
        gap = jnp.where(valid, dist - extra - radius, INF)
        out.append((gap, jnp.where(ok, vx * inv, 1.0), jnp.where(ok, vy * inv, 0.0)))
    return out


def disc_gaps(p: jnp.ndarray, radius: jnp.ndarray, scene: Scene):
    """Clearance between a disc and every surface, with the outward normals.

    Args:
        p: [2] disc centre. radius: disc radius.

    Returns:
        (gap [P] = surface distance minus radius, +inf for invalid entries;
         normal [P, 2] unit vector from the surface towards p), P = S + B + C in that order.
    """
    kinds = kind_gaps(p, radius, scene)
    return (
        jnp.concatenate([g for g, _, _ in kinds]),
        jnp.stack(
            [
                jnp.concatenate([nx for _, nx, _ in kinds]),
                jnp.concatenate([ny for _, _, ny in kinds]),
            ],
            axis=1,
        ),
    )


def min_gap(p: jnp.ndarray, radius: jnp.ndarray, scene: Scene) -> jnp.ndarray:
    """Smallest clearance (m) between a disc and the scene; negative means overlap."""
    gaps = [g.min() for g, _, _ in kind_gaps(p, radius, scene)]
    return jnp.minimum(jnp.minimum(gaps[0], gaps[1]), gaps[2])


def resolve_disc(
    p_old: jnp.ndarray,
    p_new: jnp.ndarray,
    radius: jnp.ndarray,
    scene: Scene,
    iters: int = 1,
    skin: float = 2e-5,
) -> jnp.ndarray:
    """Move a disc from ``p_old`` to ``p_new`` without overlapping anything.

    Each pass pushes the disc out of every surface it penetrates along that surface's normal,
    to ``skin`` metres of clearance, so a disc driven into a wall stays in contact and slides along
    it; in a corner the pushes from both walls add up. If overlap remains after ``iters`` passes
    (a tight pocket) the disc keeps ``p_old``, which was clear; so no overlap ever arises from a
    clear start. One pass suffices for the worlds' walls, boxes and pillars (a step moves at most
    4.5 mm); more passes cost compile and run time in every step.

    Each kind's pushes along x and y are summed in one two-output reduction
    (:func:`reduce_pair`): with two plain sums XLA's CPU backend computed every push twice
    (docs/performance.md).

    Returns:
        [2] the resolved centre.
    """
    p = p_new
    for _ in range(iters):
        dx = dy = 0.0
        for gap, nx, ny in kind_gaps(p, radius, scene):
            depth = jnp.where(gap < skin, skin - gap, 0.0)
            sx, sy = reduce_pair(depth * nx, depth * ny, jnp.add, jnp.add, 0.0, 0.0)
            dx, dy = dx + sx, dy + sy
        p = p + jnp.stack([dx, dy])
    return jnp.where(min_gap(p, radius, scene) >= 0.0, p, p_old)
