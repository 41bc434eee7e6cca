"""The paper's experimental protocol, stated once [paper, sections 5-6]: worlds and systems in
table order, who runs where, trial counts, Table 4's comparisons, the significance level and the
caps. Free of JAX: the scripts check their flags against it before JAX starts."""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Sequence
from importlib import resources
from os import PathLike
from pathlib import Path

from jaxais.io import INTEGER, check_names, check_number, check_type
from jaxais.labels import LABELS, parse_label, world_names_module

__all__ = [
    "add_cap_arguments",
    "add_world_scale_argument",
    "check_caps",
    "check_seed",
    "check_world_scale",
    "check_worlds",
    "is_world_file",
    "load_paper_tables",
    "ALPHA",
    "COLLISION_CAP",
    "COMPARISONS",
    "COUNTING_RULES",
    "DEFAULT_RULE",
    "REAL_TRIALS",
    "REAL_WORLD",
    "RHO",
    "SEEDED",
    "SIMULATED_TRIALS",
    "SYSTEMS",
    "TAU_CAP",
    "UNSCALED_WORLDS",
    "UNSEEDED",
    "WORLDS",
    "WORLD_NAMES",
    "systems_for_world",
    "trials_for_world",
]

REAL_WORLD = "real"
"""The paper's real-world arena (here a simulated world with the real robot's noise)."""
WORLDS: tuple[str, ...] = ("world1", "world2", REAL_WORLD)
"""The paper's test worlds, in its table order: two simulated worlds and the real one."""
WORLD_NAMES: dict[str, str] = {
    "world1": "Simulated World 1",
    "world2": "Simulated World 2",
    REAL_WORLD: "the real world",
}
"""How the paper names its worlds."""

SYSTEMS: tuple[str, ...] = LABELS
"""The paper's systems, in its table order."""
SEEDED: tuple[str, ...] = ("SIE", "SRL")
"""The systems that start from the LTL seed."""
UNSEEDED: tuple[str, ...] = tuple(s for s in SYSTEMS if parse_label(s)[1] is not None)
"""The systems that start from a fixed random set (R1 or R2), in table order."""

SIMULATED_TRIALS = 30
"""Trials of each system in a simulated world [paper]."""
REAL_TRIALS = 20
"""Trials of each system in the real world [paper]."""

COMPARISONS: tuple[tuple[str, str], ...] = (
    ("SIE", "SRL"),
    ("SIE", "HDC"),
    ("SIE", "UIE-R1"),
    ("SIE", "URL-R1"),
    ("SIE", "UIE-R2"),
    ("SIE", "URL-R2"),
    ("SRL", "UIE-R1"),
    ("SRL", "URL-R1"),
    ("SRL", "UIE-R2"),
    ("SRL", "URL-R2"),
    ("UIE-R1", "URL-R1"),
    ("UIE-R2", "URL-R2"),
)
"""The 12 comparisons of the paper's Table 4, in its row order (written as the table has them)."""
ALPHA = 0.01
"""The paper accepts differences at the 99 % level only (two-tailed Student's t, p < ALPHA)."""
COLLISION_CAP = 100
"""c is capped at this count [paper, section 5: "τ and c are capped at 4000 s and 100"]; Table 3
averages the capped count."""
TAU_CAP = 4000.0
"""τ is capped at this many seconds [paper, section 5]."""
RHO = 8.0
"""The weight of a collision against a second in f = (ρc + τ)/2 [paper, eq 11]: jaxais.loop.RHO."""
COUNTING_RULES: tuple[str, ...] = ("episode", "reading")
"""How c is counted in the tables, each from every trial's record (the text never defines c):
one per contact episode [ours, the default], or every reading with Vm >= 2400, section 4.1's
"collision" antigen. Neither feeds the dynamics (jaxais.loop.COLLISION_RULES)."""
DEFAULT_RULE = COUNTING_RULES[0]


def systems_for_world(world: str) -> tuple[str, ...]:
    """The systems the paper runs in ``world``, in table order: all seven, but only R1's
    unseeded ones in the real world."""
    if world == REAL_WORLD:
        return tuple(s for s in SYSTEMS if parse_label(s)[1] in (None, "R1"))
    return SYSTEMS


def trials_for_world(world: str) -> int:
    """The paper's trials per system in ``world``: 20 in the real world, else 30."""
    return REAL_TRIALS if world == REAL_WORLD else SIMULATED_TRIALS


def add_cap_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--tau-cap`` and ``--collision-cap`` to a script's flags, defaulting to the caps."""
    parser.add_argument(
        "--tau-cap", type=float, default=TAU_CAP, help=f"time cap, s [paper: {TAU_CAP:g}]"
    )
    parser.add_argument(
        "--collision-cap",
        type=int,
        default=COLLISION_CAP,
        help=f"collision cap [paper: {COLLISION_CAP}]",
    )


UNSCALED_WORLDS: dict[str, str] = {
    REAL_WORLD: "the paper gives the real pen's size",
    "ga_maze": "the LTL's maze is the GA's, not a test world",
}
"""Worlds ``--world-scale`` never scales, and why."""


def check_world_scale(scale: object, worlds: Sequence[str] = (), flag: str = "--world-scale"):
    """``scale`` as a float: a finite number > 0 (one-line ValueError naming ``flag``
    otherwise), refused unless 1 for a world of :data:`UNSCALED_WORLDS` in ``worlds``."""
    if isinstance(scale, bool) or not isinstance(scale, int | float):
        raise ValueError(f"{flag} must be a number, got {scale!r}")
    if not 0 < scale < float("inf"):
        raise ValueError(f"{flag} must be a finite number > 0, got {scale!r}")
    for w in worlds if scale != 1 else ():
        if str(w) in UNSCALED_WORLDS:
            raise ValueError(f"{flag} does not apply to {w}: {UNSCALED_WORLDS[str(w)]}")
    return float(scale)


def add_world_scale_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--world-scale K`` (default 1) to a script's flags (:func:`check_world_scale`)."""
    parser.add_argument(
        "--world-scale", type=_number, default=1.0, metavar="K",
        help="scale every coordinate, region and obstacle size of the world, and the camera's "
        "range, by K (the robot and the target block as they are; not the real pen) [ours: 1]",
    )  # fmt: skip


def _number(text: str) -> float:
    """``--world-scale``'s value, checked where it is read (one line, not argparse's usage)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def check_seed(seed: int, flag: str = "--seed") -> None:
    """Refuse a PRNG seed that is no integer, or outside [0, 2**32) (``jax.random.key``
    truncates it), in one line."""
    check_type(seed, INTEGER, flag, "an integer")
    if not 0 <= seed < 2**32:
        raise ValueError(f"{flag} must be in [0, 2**32), got {seed}")


def check_caps(tau_cap: float | None, collision_cap: int | None) -> tuple[float, int]:
    """The two caps, the paper's where None, checked in one line naming the flags; τ's as a float
    (10 and 10.0 give one record). Iteration counters are int32, hence τ's 1e6 s. Types first:
    a cap of 1.5 collisions is refused, not read as 1."""
    tau_cap = TAU_CAP if tau_cap is None else check_number(tau_cap, "--tau-cap")
    if collision_cap is not None:
        check_type(collision_cap, INTEGER, "--collision-cap", "an integer")
    collision_cap = int(COLLISION_CAP if collision_cap is None else collision_cap)
    if not 0 < tau_cap <= 1e6 or collision_cap < 1:
        raise ValueError("--tau-cap must be in (0, 1e6] and --collision-cap >= 1")
    return tau_cap, collision_cap


def check_worlds(worlds: str | Sequence[str] | None) -> list[str]:
    """``--worlds`` (comma-separated or a sequence; None: all the paper's) as a list: the
    paper's worlds, other worlds by name (``envs.world_names()``: built-in or on
    ``JAXAIS_WORLDS``) or world files (``PATH.toml``), the others run with the simulated worlds'
    protocol; each named once (one-line ValueError otherwise)."""
    names = list(WORLDS) if worlds is None else check_names(worlds, "--worlds", str | PathLike)
    names = [os.fspath(w) for w in names]
    known = set(WORLDS) | set(world_names_module().world_names())
    unknown = sorted(w for w in names if w not in known and not is_world_file(w))
    if unknown or not names:
        raise ValueError(
            f"--worlds: unknown world(s) {unknown} (the paper's: {', '.join(WORLDS)}; or a world "
            "by name, envs.world_names(), or a world file PATH.toml)"
        )
    if len(set(names)) < len(names):
        raise ValueError(f"--worlds names a world twice: {','.join(names)}")
    return names


def is_world_file(name: str) -> bool:
    """Is ``name`` a world file's path (``.toml``, existing), not a world's name?"""
    return name.endswith(".toml") and Path(name).is_file()


def load_paper_tables() -> dict:
    """The paper's Tables 3-5 (``table3``: ``{world: {system: {"c", "tau", "f"}}}``, ``table4``
    by ``"A vs B"``, ``table5``), ``hypotheses``, ``protocol``, ``notes`` and ``source``."""
    text = resources.files("jaxais").joinpath("data/paper_tables.json").read_text("utf-8")
    return json.loads(text)
