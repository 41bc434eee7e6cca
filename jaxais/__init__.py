"""jaxais: evolve and run idiotypic immune-network controllers for e-puck robots, in JAX.

The public face, importable from the package root (loaded on first use, so that ``jaxais.cli``
stays free of JAX and a script can still set ``XLA_FLAGS`` before JAX starts)::

    from jaxais import envs, make_system, run_trials, load_seed
    world = envs.load_world("world1")
    results = run_trials(world, {"SIE": make_system("SIE", load_seed()[0])}, 30, seed=0)

Submodules: ``envs`` (the simulator), ``immune`` (the paper's network, eqs 1-10), ``controllers``,
``perception`` (what a controller author reads: IR proximity, centroid offset, wheel limits),
``loop`` (the task loop), ``runner`` (its driver), ``ga`` (LTL), ``checkpointing``, ``seed``,
``labels``, ``systems``, ``trials``, and ``experiments`` (the paper's protocol, records, stats,
claims, report, ablation, plotting and drivers)."""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_EXPORTS = {
    "GAConfig": "ga.config",
    "NetworkParams": "immune.network",
    "Readings": "immune.readings",
    "EpisodeConfig": "loop",
    "System": "controllers",
    "LTL": "controllers",
    "STL": "controllers",
    "Controller": "controllers",
    "Percept": "controllers",
    "stl_controller": "controllers",
    "proximity": "perception",
    "centroid_offset": "perception",
    "clip_wheels": "perception",
    "Seed": "seed",
    "load_seed": "seed",
    "save_seed": "seed",
    "make_system": "systems",
    "system_params": "systems",
    "with_params": "systems",
    "TrialsConfig": "trials",
    "make_trials": "trials",
    "run_trials": "trials",
    "build_tables": "experiments.stats",
    "records_frame": "experiments.records",
}
__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"jaxais.{_EXPORTS[name]}"), name)
    try:  # submodules, e.g. jaxais.envs after `import jaxais`
        return importlib.import_module(f"jaxais.{name}")
    except ModuleNotFoundError:
        if name == "envs":  # envs/ is mapped into the package by the install, not by folders
            raise ImportError(
                "jaxais.envs not found: this checkout's jaxais/ folder shadows the installed "
                "package; install it editable (pip install -e .) or run outside the checkout"
            ) from None
        raise AttributeError(f"module 'jaxais' has no attribute {name!r}") from None
