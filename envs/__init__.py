"""The e-puck simulator, a pure-JAX 2D ray-cast world (``jaxais.envs``; never imports jaxais).

Its gymnax face (``envs.gymnax``: ``make``, ``EpuckEnv``, ...) loads on first use: importing
gymnax takes seconds, which the simulator and the task loop skip.

Worlds by name: the built-ins are the files ``worlds/*.toml``; ``JAXAIS_WORLDS`` (folders, as
``PATH``) adds the user's, loaded by name too (``names``: the lookup, free of JAX).
"""

import importlib
from typing import Any

from . import names as names  # bound here: JAX-free callers may have loaded it by file first
from .geometry import Scene, cast_rays, min_gap
from .names import world_names
from .params import (
    CAMERA_COLUMNS,
    CAMERA_ROWS,
    GOAL,
    MARKER,
    N_IR,
    NONE,
    WALL,
    SimParams,
    default_params,
)
from .sim import (
    Observation,
    State,
    StepNoise,
    build_scene,
    observe,
    reset,
    sample_step_noise,
    step,
    step_with_noise,
)
from .world import BUILTIN_WORLDS, Capacity, World, WorldError, load_world, world_path

__all__ = [
    "BUILTIN_WORLDS",
    "CAMERA_COLUMNS",
    "CAMERA_ROWS",
    "GOAL",
    "MARKER",
    "N_IR",
    "NONE",
    "WALL",
    "Capacity",
    "EnvParams",
    "EnvState",
    "EpuckEnv",
    "Observation",
    "Scene",
    "SimParams",
    "State",
    "StepNoise",
    "World",
    "WorldError",
    "build_scene",
    "cast_rays",
    "default_params",
    "load_world",
    "make",
    "min_gap",
    "observe",
    "register_gymnax",
    "reset",
    "sample_step_noise",
    "step",
    "step_with_noise",
    "world_names",
    "world_path",
]

_GYMNAX = ("EnvParams", "EnvState", "EpuckEnv", "make", "register_gymnax")


def __getattr__(name: str) -> Any:
    if name in _GYMNAX:
        return getattr(importlib.import_module(".gymnax", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
