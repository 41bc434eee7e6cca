"""Ray casting and disc collision for one robot against a 2D scene of segments, axis-aligned
boxes and circles (pillars, robots, the goal ball); batch with ``vmap``. The CPU-speed choices
here are measured in docs/performance.md."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .struct import pytree_dataclass

INF = jnp.inf
_EPS = 1e-12


@pytree_dataclass
class Scene:
    """Every surface one robot can see or touch: seg [S, 4] (x1, y1, x2, y2), box [B, 4]
    (xmin, ymin, xmax, ymax), circ [C, 3] (x, y, r), each with [S]/[B]/[C] material, height and
    valid."""

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


# Tables are [surfaces, rays]: XLA's CPU backend vectorises the rays, the minor axis, and the
# nearest-surface reduction is elementwise minima over the major one (faster than transposed).


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
    """Hit distance [B, R] of rays (``inv_d`` [R, 2] = 1 / direction) on boxes; 0 inside."""
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
    """The first of <= 64 surfaces along rays ``origins``, ``dirs`` [R, 2]: distance [R] (inf on
    a miss), its material [R] (0 on a miss) and height [R]."""
    n_s, n_b, n_c = scene.seg.shape[0], scene.box.shape[0], scene.circ.shape[0]
    assert n_s + n_b + n_c <= _INDEX_MASK + 1, "cast_rays handles at most 64 surfaces"
    # XLA vectorises the rays in 8-lane (AVX2) chunks: 23 rays would leave a scalar remainder
    # loop that halves the cast's speed, so copies of the last ray pad them (dropped at the end).
    n_r = origins.shape[0]
    pad = ray_padding(n_r)
    if pad:
        origins = jnp.concatenate([origins, jnp.broadcast_to(origins[-1:], (pad, 2))])
        dirs = jnp.concatenate([dirs, jnp.broadcast_to(dirs[-1:], (pad, 2))])
    # The nearest surface is one integer min per kind: a non-negative float's bits order like the
    # float, so the index goes into the low mantissa bits (relative error < 1e-5 on t); argmin +
    # gather made XLA recompute the intersection tests several times over.
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
    """(op_a over a, op_b over b) of two [N] vectors in one two-output reduction (identities
    ``init_a``, ``init_b``): XLA's CPU backend fuses a plain reduction into each consumer, so one
    feeding an (x, y) pair ran once per component; this runs once (a sum may differ in the last
    bit from ``jnp.sum``)."""
    init = (jnp.asarray(init_a, a.dtype), jnp.asarray(init_b, b.dtype))
    return jax.lax.reduce((a, b), init, lambda x, y: (op_a(x[0], y[0]), op_b(x[1], y[1])), (0,))


def kind_gaps(p: jnp.ndarray, radius: jnp.ndarray, scene: Scene):
    """Per kind of surface: gap [P] (distance less radius, inf where invalid) and the unit
    vector nx, ny [P] towards p, in x/y components (a length-2 axis is slow on XLA's CPU)."""
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
    """The centre [2] of a disc moved from ``p_old`` to ``p_new`` without overlap.

    Each pass pushes it out of every surface it penetrates, along the normal to ``skin`` m of
    clearance, so it slides along walls; overlap left after ``iters`` passes keeps the clear
    ``p_old``. One pass suffices for a step of at most 4.5 mm.
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
