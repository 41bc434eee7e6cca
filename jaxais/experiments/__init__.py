"""The paper's experiments, each one library call (the scripts are thin wrappers over them):

- :func:`reproduce`: the paper end to end (``scripts/reproduce.py``);
- :func:`evolve`: the LTL genetic algorithm and its seed (``scripts/evolve.py``);
- :func:`trials`: n trials of one system in one world (``scripts/trials.py``);
- :func:`sweep`: parameter landscapes and the reality gap (``scripts/sweep.py``);
- :func:`ablate`: each of our readings switched (``scripts/ablate.py``);
- :func:`render`: a world with wandering robots drawn (``scripts/render.py``).

Submodules: ``protocol`` (the paper's worlds, systems, trial counts and comparisons, stated
once), ``records`` (what a run writes), ``stats`` (Tables 3-5, robustness tests, H1-H4),
``claims`` (the paper's 32 claims), ``report``, ``ablation``, ``sweeps`` and ``sweep_plots``,
``seeds`` (the protocol on N fresh LTL seeds), ``diversity``, ``plotting``, ``bench`` (the
benchmarks), ``schema`` (the formats' JSON Schemas) and the drivers' modules ``reproduction``,
``evolution``, ``one_system``, ``demo``.

This layer sits on top of the engine; nothing below imports from it. Importing the package does
not start JAX: each call loads what it needs.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "reproduce": "reproduction",
    "evolve": "evolution",
    "trials": "one_system",
    "sweep": "sweeps",
    "ablate": "ablation",
    "render": "demo",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"jaxais.experiments.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'jaxais.experiments' has no attribute {name!r}")
