"""Pictures of worlds and runs: a world's map, trajectories and GIFs (matplotlib, Agg canvas, no
pyplot state, NumPy values outside jit). A figure shows in a notebook as a PNG (:class:`PngFigure`).

Boxes and the goal are drawn where a run had them: pass its ``State`` or a placement (any object
with ``boxes`` [B, 2] and ``goal`` [2], e.g. ``jaxais.trials.Placement``); without either they
sit at their regions' centres.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from io import BytesIO
from types import SimpleNamespace
from typing import Any

import numpy as np
from matplotlib import animation
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Rectangle

from jaxais.envs import GOAL, MARKER, WALL, World
from jaxais.io import atomic_write

__all__ = [
    "MATERIAL_COLOURS",
    "PngFigure",
    "animate",
    "draw_trajectory",
    "draw_world",
    "new_figure",
    "save_figure",
    "show",
    "world_figure",
]

MATERIAL_COLOURS = {WALL: "0.3", MARKER: "#5aa9e6", GOAL: "#1030c0"}
START_COLOUR = "tab:green"
WANDERER_COLOUR = "0.55"
BODY_RADIUS = 0.037  # m, ``default_params().body_radius``
ROBOT_COLOURS = ("tab:red", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")


def _np(x: Any) -> np.ndarray:
    return np.asarray(x, np.float64)


def _robot_colour(i: int) -> str:
    return ROBOT_COLOURS[i % len(ROBOT_COLOURS)]


def _material_colour(m: Any) -> str:
    return MATERIAL_COLOURS.get(int(m), "k")


def _region_rect(region: np.ndarray, **kw: Any) -> Rectangle:
    x0, y0, x1, y1 = region
    return Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, **kw)


Placed = Any
"""A ``State`` or a placement (``boxes`` [B, 2], ``goal`` [2]), with a robot axis if batched."""


def _is_placed(x: Any) -> bool:
    return hasattr(x, "boxes") and hasattr(x, "goal")


def _is_batched(state: Placed) -> bool:
    return np.ndim(state.goal) > 1


def _robots(states: Placed | Sequence[Placed] | None) -> list[Placed]:
    """``states`` (one, batched with a leading robot axis, or a list of either) as a list of one
    robot's boxes, goal and, a ``State``'s, wanderers (NumPy)."""
    if states is None:
        return []
    if not _is_placed(states):
        return [robot for s in states for robot in _robots(s)]
    if not _is_batched(states):
        return [states]
    keys = [k for k in ("boxes", "goal", "wanderers") if hasattr(states, k)]
    arrays = {k: np.asarray(getattr(states, k)) for k in keys}
    return [
        SimpleNamespace(**{k: a[i] for k, a in arrays.items()}) for i in range(len(arrays["goal"]))
    ]


def _draw_static(ax: Axes, world: World, show_regions: bool) -> None:
    """Walls, pillars and the regions: the parts of a world that no run changes."""
    seg = _np(world.seg)[np.asarray(world.seg_valid)]
    mats = np.asarray(world.seg_material)[np.asarray(world.seg_valid)]
    ax.add_collection(
        LineCollection(
            seg.reshape(-1, 2, 2),
            colors=[_material_colour(m) for m in mats],
            linewidths=[3.0 if m != WALL else 2.0 for m in mats],
            capstyle="butt",
            zorder=3,
        )
    )
    valid = np.asarray(world.pillar_valid)
    mats = np.asarray(world.pillar_material)[valid]
    for (x, y, r), m in zip(_np(world.pillar)[valid], mats, strict=True):
        colour = _material_colour(m)
        ax.add_patch(Circle((x, y), r, facecolor=colour, edgecolor="k", lw=0.5, zorder=3))
    if not show_regions:
        return
    regions = [(world.start_region, 1.2, START_COLOUR, "start region")]
    regions += [(world.goal_region, 1.2, MATERIAL_COLOURS[GOAL], "goal region")]
    regions += [(r, 1.0, WANDERER_COLOUR, "wanderer region" if k == 0 else None)
                for k, r in enumerate(_np(world.wanderer_region))]  # fmt: skip
    for region, lw, colour, label in regions:
        ax.add_patch(_region_rect(_np(region), ls="--", lw=lw, ec=colour, label=label, zorder=2))
    seen: set[tuple[float, ...]] = set()
    for region, ok in zip(_np(world.box_region), np.asarray(world.box_valid), strict=True):
        fixed = region[0] == region[2] and region[1] == region[3]
        if ok and not fixed and tuple(region) not in seen:
            label = "box region" if not seen else None
            seen.add(tuple(region))
            ax.add_patch(_region_rect(region, ls=":", lw=1.0, ec="0.6", label=label, zorder=2))


def _draw_objects(
    ax: Axes,
    world: World,
    state: Placed | None,
    *,
    alpha: float = 1.0,
    show_wanderers: bool = True,
    wanderer_label: str | None = None,
    edge: str = "k",
) -> None:
    """Boxes and the goal (at ``state``'s positions, else their regions' centres), outlined in
    ``edge``; a ``State``'s wanderers."""
    region_centre = lambda r: 0.5 * (r[..., :2] + r[..., 2:])
    boxes = _np(state.boxes) if state is not None else region_centre(_np(world.box_region))
    goal = _np(state.goal) if state is not None else region_centre(_np(world.goal_region))
    style = dict(edgecolor=edge, lw=0.5 if edge == "k" else 1.2, alpha=alpha, zorder=3)
    valid = np.asarray(world.box_valid)
    half, mats = _np(world.box_half)[valid], np.asarray(world.box_material)[valid]
    for (cx, cy), (hx, hy), m in zip(boxes[valid], half, mats, strict=True):
        colour = _material_colour(m)
        ax.add_patch(Rectangle((cx - hx, cy - hy), 2 * hx, 2 * hy, facecolor=colour, **style))
    gh = _np(world.goal_half)
    style = dict(facecolor=MATERIAL_COLOURS[GOAL], **style)
    if world.goal_shape == "ball":
        ax.add_patch(Circle(tuple(goal), gh[0], **style))
    else:
        ax.add_patch(Rectangle(tuple(goal - gh), 2 * gh[0], 2 * gh[1], **style))
    if state is not None and show_wanderers and hasattr(state, "wanderers"):
        for k, (x, y, _) in enumerate(_np(state.wanderers)):
            label = wanderer_label if k == 0 else None
            disc = Circle((x, y), BODY_RADIUS, facecolor=WANDERER_COLOUR, edgecolor="k", lw=0.5,
                          alpha=alpha, zorder=4, label=label)  # fmt: skip
            ax.add_patch(disc)


def _frame_axes(ax: Axes, world: World) -> None:
    x0, y0, x1, y1 = _np(world.arena)
    pad = 0.03 * max(x1 - x0, y1 - y0)
    ax.set_xlim(x0 - pad, x1 + pad)
    ax.set_ylim(y0 - pad, y1 + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def draw_world(ax: Axes, world: World, state: Placed | None = None) -> Axes:
    """Draw ``world`` and its start, goal, wanderer and random-box regions on ``ax`` (limits and
    aspect set to the arena) and return ``ax``; ``state`` is one robot's ``State`` (boxes, goal
    and wanderers where it has them) or a placement (boxes and goal)."""
    if state is not None and not _is_placed(state):
        raise TypeError(f"draw_world: state must have boxes and goal, got {type(state).__name__}")
    if state is not None and _is_batched(state):
        raise ValueError("draw_world takes one robot's State; index a batched State first")
    _draw_static(ax, world, show_regions=True)
    _draw_objects(ax, world, state)
    _frame_axes(ax, world)
    return ax


def draw_trajectory(ax: Axes, xy: Any, label: str | None = None, **kw: Any) -> Line2D:
    """Draw ``xy`` [T, 2+] as a line (``kw`` to ``ax.plot``), a hollow circle at its start and a
    filled square at its end; returns the line."""
    xy = _np(xy)
    if xy.ndim != 2 or xy.shape[1] < 2 or xy.shape[0] == 0:
        raise ValueError(f"draw_trajectory needs a [T, 2] array with T >= 1, got {xy.shape}")
    kw.setdefault("lw", 1.2)
    (line,) = ax.plot(xy[:, 0], xy[:, 1], label=label, zorder=5, **kw)
    colour = line.get_color()
    ax.plot(*xy[0, :2], "o", ms=6, mfc="white", mec=colour, mew=1.5, zorder=6)
    ax.plot(*xy[-1, :2], "s", ms=5, color=colour, zorder=6)
    return line


class PngFigure(Figure):
    """A ``Figure`` that IPython shows as a PNG: without pyplot (whose inline backend registers
    one for every figure) a notebook would print ``<Figure size ... with 1 Axes>``."""

    def _repr_png_(self) -> bytes:
        buffer = BytesIO()
        self.savefig(buffer, format="png")
        return buffer.getvalue()


def new_figure(figsize: tuple[float, float], layout: str | None = "constrained") -> PngFigure:
    """A :class:`PngFigure` on its own Agg canvas (no pyplot)."""
    fig = PngFigure(figsize=figsize, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def show(fig: Figure) -> None:
    """Display ``fig`` in the running IPython (a notebook's cell output); a one-line
    ``ValueError`` outside one."""
    ipython = sys.modules.get("IPython")  # not a dependency: the running one, if any
    if getattr(ipython, "get_ipython", lambda: None)() is None:
        raise ValueError("no notebook (IPython) runs here to show the figure: save it instead")
    ipython.display.display(fig)


def world_figure(
    world: World,
    states: Placed | Sequence[Placed] | None = None,
    trajectories: Any = None,
    title: str | None = None,
    *,
    labels: Sequence[str] | None = None,
) -> Figure:
    """A figure (Agg canvas) of ``world`` with robots and trajectories.

    Args:
        states: a ``State`` or placement, batched or not, or a list: the first robot's boxes,
            goal and wanderers solid, the others' faint and, with several, outlined in their
            trajectory's colour.
        trajectories: [T, 2+], [N, T, 2+] or a list of [T_i, 2+].
        title: default the world's name; ``labels``: default ``robot i``.
    """
    x0, y0, x1, y1 = _np(world.arena)
    w, h = 5.0 * (x1 - x0) / (y1 - y0), 5.0  # plot area in inches, the arena's shape
    if w > 9.0:
        w, h = 9.0, 45.0 / w
    fig = new_figure((w + 2.0, h + 0.7))  # room for the labels and the legend
    ax = fig.add_subplot()
    _draw_static(ax, world, show_regions=True)
    robots = _robots(states)
    for i, s in enumerate(robots or [None]):
        label = "wanderer (at start)" if i == 0 else None
        edge = _robot_colour(i) if len(robots) > 1 else "k"
        _draw_objects(ax, world, s, alpha=0.25 if i else 1.0, wanderer_label=label, edge=edge)
    if trajectories is not None and not isinstance(trajectories, list | tuple):
        arr = np.asarray(trajectories)  # one array (NumPy or JAX): [T, 2+] or [N, T, 2+]
        trajectories = [arr] if arr.ndim == 2 else list(arr)
    for i, xy in enumerate(trajectories or []):
        label = labels[i] if labels is not None else f"robot {i}"
        draw_trajectory(ax, xy, label=label, color=_robot_colour(i))
    _frame_axes(ax, world)
    ax.set_title(title if title is not None else world.name)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small", frameon=False)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike[str], dpi: float = 120) -> None:
    """Save ``fig`` atomically in its suffix's format (png without one)."""
    fmt = os.path.splitext(os.fspath(path))[1].lstrip(".").lower() or "png"
    atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt, dpi=dpi))


def animate(
    world: World,
    poses: Any,
    wanderers: Any,
    out_path: str | os.PathLike[str],
    fps: float = 25,
    *,
    state: Placed | None = None,
    dt: float | None = None,
) -> int:
    """Write a GIF of poses [T, 3] or [T, R, 3] (x, y, heading; R robots in copies of the world)
    and ``wanderers`` [T, (R,) W, 3] or None, one frame per row, atomically; returns the frame
    count.

    ``state``: the first robot's ``State`` or placement (boxes and goal do not move); ``dt``:
    seconds between frames, for a clock in the title. Each robot trails its path so far.
    """
    poses = _np(poses)
    if poses.ndim == 2:
        poses = poses[:, None]
    if poses.ndim != 3 or poses.shape[-1] != 3 or poses.shape[0] == 0:
        raise ValueError(f"animate needs poses [T, 3] or [T, R, 3], got {np.shape(poses)}")
    n_t, n_r = poses.shape[:2]
    wand = np.zeros((n_t, n_r, 0, 3)) if wanderers is None else _np(wanderers)  # [T, R, W, 3]
    if wand.ndim == 3:
        wand = wand[:, None]
    if wand.shape[:2] != (n_t, n_r) or wand.shape[-1] != 3:
        raise ValueError(f"wanderers {np.shape(wanderers)} do not match poses {poses.shape}")
    if state is not None and _is_batched(state):
        state = _robots(state)[0]
    if os.path.splitext(os.fspath(out_path))[1].lower() != ".gif":
        raise ValueError(f"{out_path}: an animation must be written to a .gif file")

    # A fixed layout: constrained layout would be re-solved for every frame (half the time).
    fig = new_figure((5.0, 5.0), layout=None)
    ax = fig.add_subplot()
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.02, top=0.93)
    _draw_static(ax, world, show_regions=False)
    _draw_objects(ax, world, state, show_wanderers=False)
    _frame_axes(ax, world)
    ax.set_axis_off()  # tick labels would take two thirds of each frame's drawing time
    robot_artists = []
    for r in range(n_r):
        colour = _robot_colour(r)
        style = dict(facecolor=colour, edgecolor="k", lw=0.8, zorder=7)
        body = ax.add_patch(Circle((0, 0), BODY_RADIUS, **style))
        (tick,) = ax.plot([], [], color="k", lw=1.5, zorder=8)
        (path,) = ax.plot([], [], color=colour, lw=1.0, alpha=0.7, zorder=5)
        disc = dict(facecolor=WANDERER_COLOUR, edgecolor=colour, lw=1.0, zorder=6)
        others = [ax.add_patch(Circle((0, 0), BODY_RADIUS, **disc)) for _ in range(wand.shape[2])]
        robot_artists.append((body, tick, path, others))

    def update(i: int) -> None:
        for r, (body, tick, path, others) in enumerate(robot_artists):
            x, y, th = poses[i, r]
            body.center = (x, y)
            tick.set_data([x, x + BODY_RADIUS * np.cos(th)], [y, y + BODY_RADIUS * np.sin(th)])
            path.set_data(poses[: i + 1, r, 0], poses[: i + 1, r, 1])
            for k, disc in enumerate(others):
                disc.center = tuple(wand[i, r, k, :2])
        clock = f"  t = {i * dt:.1f} s" if dt is not None else ""
        ax.set_title(f"{world.name}{clock}")

    def write(tmp: Any) -> None:
        writer = animation.PillowWriter(fps=fps)
        with writer.saving(fig, os.fspath(tmp), dpi=80):
            for i in range(n_t):
                update(i)
                writer.grab_frame()

    atomic_write(out_path, write)
    return n_t
