"""Worlds as data: TOML files loaded into fixed-shape padded arrays (SPEC section 3).

A world file (``worlds/world1.toml`` is a commented example) declares the arena, walls, boxes
(fixed or drawn each run) and pillars, the goal and its region, the start region, the wandering
e-pucks and the noise. A world by name is a file: the built-ins are ``worlds/*.toml``, the user's
are on the ``JAXAIS_WORLDS`` search path (:mod:`.names`, which states the precedence).
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax.numpy as jnp
import numpy as np

from . import geometry
from .names import BUILTIN_WORLDS as BUILTIN_WORLDS  # re-exported: envs.BUILTIN_WORLDS
from .names import WorldError, find_world, resolve
from .params import MATERIALS
from .struct import device_array, pytree_dataclass, static_field

MAX_SURFACES = geometry._INDEX_MASK + 1  # what the ray caster tells apart, padding included
MAX_ARENA_SIDE = 100.0  # m [ours]: float32 positions still resolve 8 um there
MAX_HEIGHT = 10.0  # of a wall, box, pillar or goal, m
MAX_HEADING = 2.0 * math.pi  # magnitude of a start heading bound, rad

_KEYS: dict[str, tuple[str, ...]] = {
    "": ("name", "arena", "robot", "goal", "walls", "boxes", "pillars", "wanderers", "noise"),
    "arena": ("width", "height", "wall_height"),
    "robot": ("start_region", "start_heading"),
    "goal": ("shape", "half_size", "radius", "height", "region"),
    "walls": ("from", "to", "material", "height"),
    "boxes": ("half_size", "center", "region", "material", "height"),
    "pillars": ("center", "radius", "material", "height"),
    "wanderers": ("region",),
    "noise": ("ir_relative_std", "camera_miss_prob", "camera_shift_prob", "wheel_relative_std"),
}
"""The world format's keys, by table path (``""`` the top level)."""


@pytree_dataclass
class World:
    """One world padded to S segments, B boxes, C pillars (>= 1 each; padding not valid).

    Attributes:
        arena: [4] (xmin, ymin, xmax, ymax), m. seg: [S, 4] (x1, y1, x2, y2).
        box_half: [B, 2]; box_region: [B, 4] where its centre is drawn (a point when fixed).
        pillar: [C, 3] (x, y, radius). Each kind has [S]/[B]/[C] material, height, valid.
        goal_half: [2] (a ball's: radius twice); goal_region, start_region: [4];
            start_heading: [2] (min, max) rad; wanderer_region: [W, 4].
        name, goal_shape ("box" or "ball"), and the static noise levels: ir_noise (relative,
            on top of the simulator's), camera_miss, camera_shift (probabilities per
            iteration), wheel_noise (relative).
    """

    arena: jnp.ndarray
    seg: jnp.ndarray
    seg_material: jnp.ndarray
    seg_height: jnp.ndarray
    seg_valid: jnp.ndarray
    box_half: jnp.ndarray
    box_region: jnp.ndarray
    box_material: jnp.ndarray
    box_height: jnp.ndarray
    box_valid: jnp.ndarray
    pillar: jnp.ndarray
    pillar_material: jnp.ndarray
    pillar_height: jnp.ndarray
    pillar_valid: jnp.ndarray
    goal_half: jnp.ndarray
    goal_height: jnp.ndarray
    goal_region: jnp.ndarray
    start_region: jnp.ndarray
    start_heading: jnp.ndarray
    wanderer_region: jnp.ndarray
    name: str = static_field(default="world")
    goal_shape: str = static_field(default="box")
    # Noise levels are static: a noiseless world draws no noise at all (it is a large share of a
    # step's cost on a CPU), at the price of one compilation per noise level.
    ir_noise: float = static_field(default=0.0)
    camera_miss: float = static_field(default=0.0)
    camera_shift: float = static_field(default=0.0)
    wheel_noise: float = static_field(default=0.0)

    @property
    def n_wanderers(self) -> int:
        return self.wanderer_region.shape[0]


@dataclass(frozen=True)
class Capacity:
    """Minimum padded sizes: worlds loaded with one Capacity share array shapes, so jitted
    functions taking the world share programs where the static fields match too."""

    segments: int = 1
    boxes: int = 1
    pillars: int = 1


_HALF_ARENA = " (half the arena's shorter side)"


def _fail(src: str, field: str, msg: str) -> WorldError:
    return WorldError(f"{src}: field '{field}': {msg}")


class _Reader:
    """Typed field access with one-line errors naming the file and field."""

    def __init__(self, src: str):
        self.src = src

    def get(self, table: dict, key: str, path: str, kind: str, default: Any = ...) -> Any:
        field = f"{path}.{key}" if path else key
        if key not in table:
            if default is ...:
                raise _fail(self.src, field, "missing")
            return default
        value = table[key]
        if kind == "number":
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise _fail(self.src, field, f"expected a number, got {_show(value)}")
            if not _finite(value):
                raise _fail(self.src, field, f"expected a finite number, got {_show(value)}")
            return float(value)
        if kind == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                raise _fail(self.src, field, f"expected an integer, got {_show(value)}")
            return value
        if kind == "str":
            if not isinstance(value, str):
                raise _fail(self.src, field, f"expected a string, got {_show(value)}")
            return value
        if kind.startswith("vec"):
            n = int(kind[3:])
            ok = isinstance(value, list) and len(value) == n
            ok = ok and all(
                isinstance(v, int | float) and not isinstance(v, bool) and _finite(v) for v in value
            )
            if not ok:
                raise _fail(self.src, field, f"expected a list of {n} numbers, got {_show(value)}")
            return [float(v) for v in value]
        if kind == "table":
            if not isinstance(value, dict):
                raise _fail(self.src, field, "expected a table")
            return value
        if kind == "tables":
            if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
                raise _fail(self.src, field, "expected an array of tables ([[...]])")
            return value
        raise AssertionError(kind)

    def known(self, table: dict, path: str) -> None:
        """Refuse keys the world format does not have (a misspelt ``[[pilars]]`` would
        otherwise drop its pillars without a word)."""
        allowed = _KEYS[path.split("[", 1)[0]]
        for key in table:
            if key not in allowed:
                kind = "table" if isinstance(table[key], dict | list) and not path else "key"
                close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.7)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise _fail(
                    self.src,
                    f"{path}.{key}" if path else key,
                    f"unknown {kind}{hint}; allowed: {', '.join(allowed)}",
                )

    def positive(
        self,
        table: dict,
        key: str,
        path: str,
        default: Any = ...,
        hi: float = MAX_HEIGHT,
        why: str = "",
    ) -> float:
        """A number in (0, hi] m (``why`` says where ``hi`` comes from)."""
        value = self.get(table, key, path, "number", default)
        if not 0 < value <= hi:
            raise _fail(self.src, f"{path}.{key}", f"must lie in (0, {hi:g}] m{why}, got {value:g}")
        return value

    def half_size(self, table: dict, path: str, hi: float) -> list[float]:
        """A [hx, hy] pair, each in (0, hi] m."""
        half = self.get(table, "half_size", path, "vec2")
        if not all(0 < h <= hi for h in half):
            raise _fail(
                self.src,
                f"{path}.half_size",
                f"each half size must lie in (0, {hi:g}] m{_HALF_ARENA}, got {half}",
            )
        return half

    def material(self, table: dict, path: str, default: str) -> int:
        name = self.get(table, "material", path, "str", default)
        if name not in MATERIALS or name == "none":
            allowed = ", ".join(m for m in MATERIALS if m != "none")
            raise _fail(self.src, f"{path}.material", f"unknown material {name!r} ({allowed})")
        return MATERIALS[name]

    def region(self, table: dict, key: str, path: str, arena: list[float], margin: float):
        """A region [xmin, ymin, xmax, ymax] inside the arena, ``margin`` away from its walls."""
        r = self.get(table, key, path, "vec4")
        field = f"{path}.{key}"
        if r[0] > r[2] or r[1] > r[3]:
            raise _fail(self.src, field, f"needs xmin <= xmax and ymin <= ymax, got {r}")
        lo_x, lo_y = arena[0] + margin, arena[1] + margin
        hi_x, hi_y = arena[2] - margin, arena[3] - margin
        if r[0] < lo_x - 1e-9 or r[1] < lo_y - 1e-9 or r[2] > hi_x + 1e-9 or r[3] > hi_y + 1e-9:
            raise _fail(
                self.src,
                field,
                f"{r} is outside the arena (must lie within [{lo_x:g}, {lo_y:g}, {hi_x:g}, "
                f"{hi_y:g}] to keep {margin:g} m from the walls)",
            )
        return r


def _show(value: Any, limit: int = 40) -> str:
    """``repr(value)``, cut short: a TOML integer may have hundreds of digits."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def _finite(value: int | float) -> bool:
    """Whether a TOML number is finite as a float (TOML integers have no size limit)."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _pad(rows: list, n: int, width: int | None, fill: float = 0.0) -> np.ndarray:
    shape = (n,) if width is None else (n, width)
    out = np.full(shape, fill, np.float64)
    if rows:
        out[: len(rows)] = np.asarray(rows, np.float64).reshape((len(rows),) + shape[1:])
    return out


def _region_has_room(region, radius, segs, pillars, boxes, n: int = 24) -> bool:
    """Whether a point of an n x n grid over ``region`` keeps ``radius`` from the static
    surfaces (boxes as (cx, cy, (hx, hy))): else reset would overlap without a word."""
    xs = np.linspace(region[0], region[2], n)
    ys = np.linspace(region[1], region[3], n)
    p = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    gap = np.full(len(p), np.inf)
    for x1, y1, x2, y2 in segs:
        a, e = np.array([x1, y1]), np.array([x2 - x1, y2 - y1])
        u = np.clip(((p - a) @ e) / max(e @ e, 1e-12), 0.0, 1.0)
        gap = np.minimum(gap, np.linalg.norm(p - (a + u[:, None] * e), axis=1))
    for cx, cy, r in pillars:
        gap = np.minimum(gap, np.linalg.norm(p - [cx, cy], axis=1) - r)
    for cx, cy, (hx, hy) in boxes:
        q = np.clip(p, [cx - hx, cy - hy], [cx + hx, cy + hy])
        gap = np.minimum(gap, np.linalg.norm(p - q, axis=1))
    return bool(np.any(gap >= radius))


def _check_surface_count(src, name, segs, boxes, pillars, wanderers, padded: int) -> None:
    """Refuse a world whose rays would meet more than :data:`MAX_SURFACES` surfaces: ``padded``
    segments, boxes and pillars, the goal and the wanderers."""
    total = padded + len(wanderers) + 1
    if total <= MAX_SURFACES:
        return
    count = lambda n, one, many: f"{n} {one if n == 1 else many}"
    parts = [
        count(len(segs), "wall", "walls") + " with the 4 outer ones",
        count(len(boxes), "box", "boxes"),
        count(len(pillars), "pillar", "pillars"),
        count(len(wanderers), "wanderer", "wanderers"),
        "the goal",
    ]
    padding = padded - len(segs) - len(boxes) - len(pillars)
    if padding:
        parts.append(count(padding, "padding slot", "padding slots"))
    raise WorldError(
        f"{src}: world {name!r} has {total} surfaces ({', '.join(parts)}); at most "
        f"{MAX_SURFACES} are supported (the ray caster's limit): remove at least "
        f"{total - MAX_SURFACES} walls, boxes, pillars or wanderers"
    )


def parse_world(doc: dict, src: str, capacity: Capacity = Capacity(), body_radius: float = 0.037):
    """A :class:`World` from a parsed TOML document; a WorldError names ``src`` and the field
    (missing, unknown or mistyped, out of range, off the arena, or too many surfaces)."""
    rd = _Reader(src)
    rd.known(doc, "")
    name = rd.get(doc, "name", "", "str")
    arena_t = rd.get(doc, "arena", "", "table")
    rd.known(arena_t, "arena")
    width = rd.positive(arena_t, "width", "arena", hi=MAX_ARENA_SIDE)
    height = rd.positive(arena_t, "height", "arena", hi=MAX_ARENA_SIDE)
    wall_h = rd.positive(arena_t, "wall_height", "arena")
    arena = [0.0, 0.0, width, height]
    max_half = 0.5 * min(width, height)

    # Outer walls first, then the file's own segments.
    segs = [[0, 0, width, 0], [width, 0, width, height], [width, height, 0, height]]
    segs.append([0, height, 0, 0])
    seg_mat = [MATERIALS["wall"]] * 4
    seg_h = [wall_h] * 4
    for k, w in enumerate(rd.get(doc, "walls", "", "tables", [])):
        path = f"walls[{k}]"
        rd.known(w, path)
        a = rd.get(w, "from", path, "vec2")
        b = rd.get(w, "to", path, "vec2")
        for p, key in ((a, "from"), (b, "to")):
            if not (0 <= p[0] <= width and 0 <= p[1] <= height):
                raise _fail(src, f"{path}.{key}", f"{p} is outside the arena")
        if a == b:
            raise _fail(src, path, "zero-length wall (from == to)")
        segs.append(a + b)
        seg_mat.append(rd.material(w, path, "wall"))
        seg_h.append(rd.positive(w, "height", path, wall_h))

    box_half, box_region, box_mat, box_h = [], [], [], []
    for k, bx in enumerate(rd.get(doc, "boxes", "", "tables", [])):
        path = f"boxes[{k}]"
        rd.known(bx, path)
        half = rd.half_size(bx, path, max_half)
        if ("center" in bx) == ("region" in bx):
            raise _fail(src, path, "give exactly one of 'center' (fixed) or 'region' (random)")
        margin = max(half)
        if "center" in bx:
            c = rd.get(bx, "center", path, "vec2")
            region = rd.region({"center": c + c}, "center", path, arena, 0.0)
            if not (half[0] <= c[0] <= width - half[0] and half[1] <= c[1] <= height - half[1]):
                raise _fail(src, f"{path}.center", f"box at {c} pokes out of the arena")
        else:
            region = rd.region(bx, "region", path, arena, margin)
        box_half.append(half)
        box_region.append(region)
        box_mat.append(rd.material(bx, path, "wall"))
        box_h.append(rd.positive(bx, "height", path, wall_h))

    pillars, pil_mat, pil_h = [], [], []
    for k, p in enumerate(rd.get(doc, "pillars", "", "tables", [])):
        path = f"pillars[{k}]"
        rd.known(p, path)
        c = rd.get(p, "center", path, "vec2")
        r = rd.positive(p, "radius", path, hi=max_half, why=_HALF_ARENA)
        if not (0 <= c[0] <= width and 0 <= c[1] <= height):
            raise _fail(src, f"{path}.center", f"{c} is outside the arena")
        pillars.append(c + [r])
        pil_mat.append(rd.material(p, path, "wall"))
        pil_h.append(rd.positive(p, "height", path, wall_h))

    goal_t = rd.get(doc, "goal", "", "table")
    rd.known(goal_t, "goal")
    goal_shape = rd.get(goal_t, "shape", "goal", "str")
    if goal_shape not in ("box", "ball"):
        raise _fail(src, "goal.shape", f"expected 'box' or 'ball', got {goal_shape!r}")
    size_key, other = ("half_size", "radius") if goal_shape == "box" else ("radius", "half_size")
    if other in goal_t:
        raise _fail(
            src, f"goal.{other}", f"a {goal_shape!r} goal is sized by {size_key}, not {other}"
        )
    if goal_shape == "box":
        goal_half = rd.half_size(goal_t, "goal", max_half)
    else:
        r = rd.positive(goal_t, "radius", "goal", hi=max_half, why=_HALF_ARENA)
        goal_half = [r, r]
    goal_h = rd.positive(goal_t, "height", "goal")
    goal_region = rd.region(goal_t, "region", "goal", arena, max(goal_half))

    robot_t = rd.get(doc, "robot", "", "table")
    rd.known(robot_t, "robot")
    start_region = rd.region(robot_t, "start_region", "robot", arena, body_radius)
    heading = rd.get(robot_t, "start_heading", "robot", "vec2", [-math.pi, math.pi])
    if heading[0] > heading[1]:
        raise _fail(src, "robot.start_heading", f"needs min <= max, got {heading}")
    if max(abs(h) for h in heading) > MAX_HEADING:
        raise _fail(
            src,
            "robot.start_heading",
            f"each bound must lie in [-{MAX_HEADING:.4f}, {MAX_HEADING:.4f}] rad, got {heading}",
        )

    wander_regions = []
    for k, wd in enumerate(rd.get(doc, "wanderers", "", "tables", [])):
        rd.known(wd, f"wanderers[{k}]")
        wander_regions.append(rd.region(wd, "region", f"wanderers[{k}]", arena, body_radius))

    noise_t = rd.get(doc, "noise", "", "table", {})
    if "pixel_flip_prob" in noise_t:
        raise _fail(
            src,
            "noise.pixel_flip_prob",
            "per-pixel flips invent targets; use camera_miss_prob and camera_shift_prob",
        )
    rd.known(noise_t, "noise")
    noise = {key: rd.get(noise_t, key, "noise", "number", 0.0) for key in _KEYS["noise"]}
    for key, value in noise.items():
        hi = 1.0 if key in ("camera_miss_prob", "camera_shift_prob") else 10.0
        if not 0.0 <= value <= hi:
            raise _fail(src, f"noise.{key}", f"must lie in [0, {hi:g}], got {value}")

    n_s = max(len(segs), capacity.segments)
    n_b = max(len(box_half), capacity.boxes, 1)
    n_c = max(len(pillars), capacity.pillars, 1)
    _check_surface_count(src, name, segs, box_half, pillars, wander_regions, n_s + n_b + n_c)

    fixed_boxes = [
        (r[0], r[1], h) for r, h in zip(box_region, box_half, strict=True) if r[:2] == r[2:]
    ]
    checks = [("robot.start_region", start_region, body_radius)]
    checks += [(f"wanderers[{k}].region", r, body_radius) for k, r in enumerate(wander_regions)]
    checks.append(("goal.region", goal_region, min(goal_half)))
    for field, region, radius in checks:
        if not _region_has_room(region, radius, segs, pillars, fixed_boxes):
            raise _fail(
                src,
                field,
                f"no point of {region} keeps {radius:g} m clear of the walls, pillars and fixed "
                "boxes; move or enlarge the region",
            )

    f32 = lambda a: device_array(a, np.float32)
    i32 = lambda a: device_array(a, np.int32)
    valid = lambda n_real, n: device_array(np.arange(n) < n_real)
    return World(
        arena=f32(arena),
        seg=f32(_pad(segs, n_s, 4)),
        seg_material=i32(_pad(seg_mat, n_s, None)),
        seg_height=f32(_pad(seg_h, n_s, None)),
        seg_valid=valid(len(segs), n_s),
        box_half=f32(_pad(box_half, n_b, 2, 0.01)),
        # Padding boxes sit far outside the arena so that even unmasked they touch nothing.
        box_region=f32(_pad(box_region, n_b, 4, -100.0)),
        box_material=i32(_pad(box_mat, n_b, None)),
        box_height=f32(_pad(box_h, n_b, None)),
        box_valid=valid(len(box_half), n_b),
        pillar=f32(_pad(pillars, n_c, 3, -100.0)),
        pillar_material=i32(_pad(pil_mat, n_c, None)),
        pillar_height=f32(_pad(pil_h, n_c, None)),
        pillar_valid=valid(len(pillars), n_c),
        goal_half=f32(goal_half),
        goal_height=f32(goal_h),
        goal_region=f32(goal_region),
        start_region=f32(start_region),
        start_heading=f32(heading),
        wanderer_region=f32(np.asarray(wander_regions, np.float64).reshape(-1, 4)),
        name=name,
        goal_shape=goal_shape,
        ir_noise=noise["ir_relative_std"],
        camera_miss=noise["camera_miss_prob"],
        camera_shift=noise["camera_shift_prob"],
        wheel_noise=noise["wheel_relative_std"],
    )


_SCALED: dict[str, tuple[str, ...]] = {
    "arena": ("width", "height"),
    "robot": ("start_region",),
    "goal": ("region",),
    "walls": ("from", "to"),
    "boxes": ("center", "region", "half_size"),
    "pillars": ("center", "radius"),
    "wanderers": ("region",),
}
"""What :func:`scale_document` multiplies, by table: every coordinate, region and obstacle size;
never a height, the goal's size or the robot (``SimParams``)."""


def scale_document(doc: dict, scale: float) -> dict:
    """A parsed world file with every field of :data:`_SCALED` times ``scale`` (a number, a
    list of numbers; anything else is left for the parser to refuse): the same world, larger.
    ``doc`` is not changed."""

    def times(value: Any) -> Any:
        if isinstance(value, bool) or not isinstance(value, int | float | list):
            return value
        if isinstance(value, list):
            return [times(v) for v in value]
        return value * scale

    out = dict(doc)
    for table, keys in _SCALED.items():
        part = doc.get(table)
        if isinstance(part, dict):
            out[table] = {k: times(v) if k in keys else v for k, v in part.items()}
        elif isinstance(part, list):
            out[table] = [
                {k: times(v) if k in keys else v for k, v in t.items()} if isinstance(t, dict)
                else t
                for t in part
            ]  # fmt: skip
    return out


def world_path(name: str) -> Path:
    """The file of the world called ``name``: a built-in (``worlds/NAME.toml``) or one on the
    ``JAXAIS_WORLDS`` search path (WorldError, one line, when there is none)."""
    return find_world(name)


def load_world(
    name_or_path: str | Path, capacity: Capacity = Capacity(), scale: float = 1.0
) -> World:
    """A world by name (``world1``; a built-in or one on ``JAXAIS_WORLDS``, see :mod:`.names`)
    or a world file by path (with a folder part or the ``.toml`` suffix), every coordinate,
    region and obstacle size times ``scale`` (:func:`scale_document`; 1: the file as it is).
    WorldError (one line) when there is no such world, the file is malformed (at that scale),
    or a file found by name has another ``name`` field (a world's name is its file's)."""
    if isinstance(scale, bool) or not isinstance(scale, int | float) or not 0 < scale < math.inf:
        raise WorldError(f"scale must be a finite number > 0, got {scale!r}")
    path, by_name = resolve(name_or_path)
    try:
        doc = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise WorldError(f"{path}: not valid TOML: {err}") from None
    except (OSError, UnicodeDecodeError) as err:
        raise WorldError(f"{path}: cannot read: {err}") from None
    if scale == 1:
        world = parse_world(doc, str(path), capacity)
    else:
        try:
            world = parse_world(scale_document(doc, scale), str(path), capacity)
        except WorldError as err:
            raise WorldError(f"{err} (at world scale {scale:g})") from None
    if by_name is not None and world.name != by_name:
        raise _fail(
            str(path),
            "name",
            f"{world.name!r} differs from the file's name {by_name!r}: a world found by name "
            f'must be named after its file (name = "{by_name}")',
        )
    return world
