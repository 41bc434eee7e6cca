"""jaxais: evolve and run idiotypic immune-network controllers for e-puck robots, in JAX.

The public face, importable from the package root (loaded on first use, so that ``jaxais.cli``
stays free of JAX and a script can still set ``XLA_FLAGS`` before JAX starts)::

    from jaxais import envs, make_system, run_trials, load_seed
    world = envs.load_world("world1")
    results = run_trials(world, {"SIE": make_system("SIE", load_seed()[0])}, 30, seed=0)

Submodules: ``envs`` (the simulator), ``antigens``, ``antibodies``, ``behaviours``,
``reinforcement``, ``network`` (eqs 1-10), ``readings`` (our readings of the paper's open points),
``controllers``, ``episode`` (the task loop), ``ga`` (LTL), ``checkpointing``, ``seed``,
``labels`` (the systems' names), ``systems``, ``trials``; and ``experiments``, the paper's
experiments on top of them: ``experiments.protocol`` (its worlds, systems, trial counts and
comparisons), ``experiments.records``, ``experiments.stats``, ``experiments.claims`` (the paper's
32 claims), ``experiments.report``, ``experiments.ablation``, ``experiments.plotting``.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

__version__ = "0.1.0"

# In a source checkout the simulator lives in ../envs (installed as jaxais.envs by pip); make
# ``import jaxais.envs`` work there too, e.g. for ``python -c`` run from the repository root.
_checkout_envs = Path(__file__).resolve().parent.parent / "envs"
if (_checkout_envs / "worlds").is_dir() and not (Path(__file__).parent / "envs").is_dir():
    __path__.append(str(_checkout_envs.parent))  # noqa: F821 (module __path__)

_EXPORTS = {
    "GAConfig": "ga",
    "NetworkParams": "network",
    "Readings": "readings",
    "EpisodeConfig": "episode",
    "System": "controllers",
    "LTL": "controllers",
    "STL": "controllers",
    "Seed": "seed",
    "load_seed": "seed",
    "save_seed": "seed",
    "make_system": "systems",
    "run_trials": "trials",
    "build_tables": "experiments.stats",
}
__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"jaxais.{_EXPORTS[name]}"), name)
    try:  # submodules, e.g. jaxais.envs after `import jaxais`
        return importlib.import_module(f"jaxais.{name}")
    except ModuleNotFoundError:
        raise AttributeError(f"module 'jaxais' has no attribute {name!r}") from None
