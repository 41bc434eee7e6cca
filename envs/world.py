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
from .names import WorldError, find_world, is_plain_name, resolve
from .params import MATERIALS
from .struct import device_array, pytree_dataclass, static_field

MAX_SURFACES = geometry._INDEX_MASK + 1  # what the ray caster tells apart, padding included
MAX_ARENA_SIDE = 100.0  # m [ours]: float32 positions still resolve 8 um there
MAX_HEIGHT = 10.0  # of a wall, box, pillar or goal, m
MAX_HEADING = 2.0 * math.pi  # magnitude of a start heading bound, rad

MAX_NOISE_STD = 10.0  # of a relative noise (IR, wheels)


@dataclass(frozen=True)
class Field:
    """One key of the world format: its TOML kind (``str``, ``number``, ``vec2``, ``vec4``,
    ``table``, ``tables``: an array of tables), whether a file must give it, the range it keeps
    alone (a number's, or each of a list's; ``low`` exclusive when ``open_low``), the strings it
    takes, and what it is. The rules that involve other fields (regions inside the arena, sizes
    within half of it, a box's one of ``center`` or ``region``, the goal sized by its shape, the
    count of surfaces) are :func:`parse_world`'s."""

    kind: str
    doc: str
    required: bool = False
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    choices: tuple[str, ...] | None = None


_SIZE: dict[str, Any] = {"low": 0.0, "open_low": True}  # a length, m: > 0
_HEIGHT = Field("number", "m (default: the arena's wall_height)", **_SIZE, high=MAX_HEIGHT)
_MATERIAL = Field("str", "default wall", choices=tuple(m for m in MATERIALS if m != "none"))
_REGION = "[xmin, ymin, xmax, ymax], m, inside the arena"
FIELDS: dict[str, dict[str, Field]] = {
    "": {
        "name": Field("str", "the world's name (a world found by name carries its file's)", True),
        "arena": Field("table", "the arena and its 4 outer walls", True),
        "robot": Field("table", "where the robot starts", True),
        "goal": Field("table", "the blue goal", True),
        "walls": Field("tables", "inner walls"),
        "boxes": Field("tables", "boxes, fixed or placed at random each run"),
        "pillars": Field("tables", "round pillars"),
        "wanderers": Field("tables", "wandering e-pucks"),
        "noise": Field("table", "noise beyond the IR noise every world has"),
    },
    "arena": {
        "width": Field("number", "m", True, **_SIZE, high=MAX_ARENA_SIDE),
        "height": Field("number", "m", True, **_SIZE, high=MAX_ARENA_SIDE),
        "wall_height": Field("number", "m", True, **_SIZE, high=MAX_HEIGHT),
    },
    "robot": {
        "start_region": Field("vec4", f"where its centre is drawn: {_REGION}", True),
        "start_heading": Field("vec2", "[min, max] of the heading drawn, rad (default [-pi, pi])",
                               low=-MAX_HEADING, high=MAX_HEADING),
    },
    "goal": {
        "shape": Field("str", "box (sized by half_size) or ball (by radius)", True,
                       choices=("box", "ball")),
        "half_size": Field("vec2", "a box's [hx, hy], m", **_SIZE),
        "radius": Field("number", "a ball's radius, m", **_SIZE),
        "height": Field("number", "m", True, **_SIZE, high=MAX_HEIGHT),
        "region": Field("vec4", f"where its centre is drawn: {_REGION}", True),
    },
    "walls": {
        "from": Field("vec2", "one end [x, y], m", True),
        "to": Field("vec2", "the other end [x, y], m", True),
        "material": _MATERIAL,
        "height": _HEIGHT,
    },
    "boxes": {
        "half_size": Field("vec2", "[hx, hy], m", True, **_SIZE),
        "center": Field("vec2", "a fixed box's centre [x, y], m (or region)"),
        "region": Field("vec4", f"where a random box's centre is drawn: {_REGION}"),
        "material": _MATERIAL,
        "height": _HEIGHT,
    },
    "pillars": {
        "center": Field("vec2", "[x, y], m", True),
        "radius": Field("number", "m", True, **_SIZE),
        "material": _MATERIAL,
        "height": _HEIGHT,
    },
    "wanderers": {"region": Field("vec4", f"where it starts: {_REGION}", True)},
    "noise": {
        "ir_relative_std": Field("number", "relative (default 0)", low=0.0, high=MAX_NOISE_STD),
        "camera_miss_prob": Field("number", "chance per iteration that the camera misses what it "
                                  "sees (default 0)", low=0.0, high=1.0),
        "camera_shift_prob": Field("number", "chance per iteration that a detection shifts "
                                   "(default 0)", low=0.0, high=1.0),
        "wheel_relative_std": Field("number", "relative (default 0)", low=0.0,
                                    high=MAX_NOISE_STD),
    },
}  # fmt: skip
"""The world format by table path (``""`` the top level): what the loader reads, and what its
JSON Schema (:func:`jaxais.experiments.schema.world_schema`) is generated from."""
_KEYS: dict[str, tuple[str, ...]] = {path: tuple(keys) for path, keys in FIELDS.items()}


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

    def get(self, table: dict, key: str, path: str, default: Any = ..., kind: str = "") -> Any:
        """``table[key]`` of its kind in :data:`FIELDS` (or ``kind``), else ``default``."""
        field = f"{path}.{key}" if path else key
        kind = kind or FIELDS[path.split("[", 1)[0]][key].kind
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
        value = self.get(table, key, path, default)
        if not 0 < value <= hi:
            raise _fail(self.src, f"{path}.{key}", f"must lie in (0, {hi:g}] m{why}, got {value:g}")
        return value

    def half_size(self, table: dict, path: str, hi: float) -> list[float]:
        """A [hx, hy] pair, each in (0, hi] m."""
        half = self.get(table, "half_size", path)
        if not all(0 < h <= hi for h in half):
            raise _fail(
                self.src,
                f"{path}.half_size",
                f"each half size must lie in (0, {hi:g}] m{_HALF_ARENA}, got {half}",
            )
        return half

    def material(self, table: dict, path: str, default: str) -> int:
        name = self.get(table, "material", path, default)
        if name not in MATERIALS or name == "none":
            allowed = ", ".join(m for m in MATERIALS if m != "none")
            raise _fail(self.src, f"{path}.material", f"unknown material {name!r} ({allowed})")
        return MATERIALS[name]

    def region(self, table: dict, key: str, path: str, arena: list[float], margin: float):
        """A region [xmin, ymin, xmax, ymax] inside the arena, ``margin`` away from its walls."""
        r = self.get(table, key, path, kind="vec4")
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


def _goal_crowds(start, goal_region, half, shape, radius, n: int = 8) -> list[float] | None:
    """A goal centre on an n x n grid over ``goal_region`` that leaves no point of ``start``
    (:func:`_region_has_room`'s grid) ``radius`` clear of the goal, or None."""
    for gx in np.linspace(goal_region[0], goal_region[2], n):
        for gy in np.linspace(goal_region[1], goal_region[3], n):
            goal = [(gx, gy, half[0])] if shape == "ball" else []
            box = [(gx, gy, half)] if shape == "box" else []
            if not _region_has_room(start, radius, [], goal, box):
                return [round(float(gx), 4), round(float(gy), 4)]
    return None


def _segment_meets(seg: list[float], region: list[float]) -> bool:
    """Whether the segment (x1, y1, x2, y2) touches the closed region [xmin, ymin, xmax, ymax]
    (Liang-Barsky clipping)."""
    x1, y1, x2, y2 = seg
    lo, hi = 0.0, 1.0
    for p, q in ((x1 - x2, x1 - region[0]), (x2 - x1, region[2] - x1),
                 (y1 - y2, y1 - region[1]), (y2 - y1, region[3] - y1)):  # fmt: skip
        if p == 0.0:
            if q < 0.0:
                return False
        elif p < 0.0:
            lo = max(lo, q / p)
        else:
            hi = min(hi, q / p)
    return lo <= hi


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
    name = rd.get(doc, "name", "")
    if not is_plain_name(name):
        raise _fail(src, "name", f"{_show(name)} is not a plain name (letters, digits, _ and -)")
    arena_t = rd.get(doc, "arena", "")
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
    for k, w in enumerate(rd.get(doc, "walls", "", [])):
        path = f"walls[{k}]"
        rd.known(w, path)
        a = rd.get(w, "from", path)
        b = rd.get(w, "to", path)
        for p, key in ((a, "from"), (b, "to")):
            if not (0 <= p[0] <= width and 0 <= p[1] <= height):
                raise _fail(src, f"{path}.{key}", f"{p} is outside the arena")
        if a == b:
            raise _fail(src, path, "zero-length wall (from == to)")
        segs.append(a + b)
        seg_mat.append(rd.material(w, path, "wall"))
        seg_h.append(rd.positive(w, "height", path, wall_h))

    box_half, box_region, box_mat, box_h = [], [], [], []
    for k, bx in enumerate(rd.get(doc, "boxes", "", [])):
        path = f"boxes[{k}]"
        rd.known(bx, path)
        half = rd.half_size(bx, path, max_half)
        if ("center" in bx) == ("region" in bx):
            raise _fail(src, path, "give exactly one of 'center' (fixed) or 'region' (random)")
        margin = max(half)
        if "center" in bx:
            c = rd.get(bx, "center", path)
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
    for k, p in enumerate(rd.get(doc, "pillars", "", [])):
        path = f"pillars[{k}]"
        rd.known(p, path)
        c = rd.get(p, "center", path)
        r = rd.positive(p, "radius", path, hi=max_half, why=_HALF_ARENA)
        if not (0 <= c[0] <= width and 0 <= c[1] <= height):
            raise _fail(src, f"{path}.center", f"{c} is outside the arena")
        pillars.append(c + [r])
        pil_mat.append(rd.material(p, path, "wall"))
        pil_h.append(rd.positive(p, "height", path, wall_h))

    goal_t = rd.get(doc, "goal", "")
    rd.known(goal_t, "goal")
    goal_shape = rd.get(goal_t, "shape", "goal")
    if goal_shape not in FIELDS["goal"]["shape"].choices:
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

    robot_t = rd.get(doc, "robot", "")
    rd.known(robot_t, "robot")
    start_region = rd.region(robot_t, "start_region", "robot", arena, body_radius)
    # As a box is (below): the robot is placed clear of the goal, so wherever the goal lands
    # some start must keep the robot clear of it (a start region inside the goal's has none).
    crowded = _goal_crowds(start_region, goal_region, goal_half, goal_shape, body_radius)
    if crowded is not None:
        raise _fail(
            src, "robot.start_region", f"no point of {start_region} keeps {body_radius:g} m "
            f"clear of a goal at {crowded} (in goal.region {goal_region}): a robot would start "
            "on the goal; move or enlarge the start region",
        )  # fmt: skip
    heading = rd.get(robot_t, "start_heading", "robot", [-math.pi, math.pi])
    if heading[0] > heading[1]:
        raise _fail(src, "robot.start_heading", f"needs min <= max, got {heading}")
    if max(abs(h) for h in heading) > MAX_HEADING:
        raise _fail(
            src,
            "robot.start_heading",
            f"each bound must lie in [-{MAX_HEADING:.4f}, {MAX_HEADING:.4f}] rad, got {heading}",
        )

    wander_regions = []
    for k, wd in enumerate(rd.get(doc, "wanderers", "", [])):
        rd.known(wd, f"wanderers[{k}]")
        wander_regions.append(rd.region(wd, "region", f"wanderers[{k}]", arena, body_radius))

    noise_t = rd.get(doc, "noise", "", {})
    if "pixel_flip_prob" in noise_t:
        raise _fail(
            src,
            "noise.pixel_flip_prob",
            "per-pixel flips invent targets; use camera_miss_prob and camera_shift_prob",
        )
    rd.known(noise_t, "noise")
    noise = {key: rd.get(noise_t, key, "noise", 0.0) for key in _KEYS["noise"]}
    for key, value in noise.items():
        hi = FIELDS["noise"][key].high
        if not 0.0 <= value <= hi:
            raise _fail(src, f"noise.{key}", f"must lie in [0, {hi:g}], got {value}")

    n_s = max(len(segs), capacity.segments)
    n_b = max(len(box_half), capacity.boxes, 1)
    n_c = max(len(pillars), capacity.pillars, 1)
    _check_surface_count(src, name, segs, box_half, pillars, wander_regions, n_s + n_b + n_c)

    for k, seg in enumerate(segs[4:]):  # the outer walls keep the region's margin
        if _segment_meets(seg, goal_region):
            raise _fail(
                src, f"walls[{k}]", f"the wall {seg[:2]} -> {seg[2:]} crosses goal.region "
                f"{goal_region}: the goal would be placed on it; move the wall or the region",
            )  # fmt: skip

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
        doc = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a byte-order mark is read
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
