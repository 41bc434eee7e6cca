"""The LTL genetic algorithm (SPEC 10). **LOWER fitness is better**: a robot's fitness is the
paper's f = (ρc + τ)/2 (eq 11); selection, elitism and every "best" minimise it.

``config`` (GAConfig, no JAX), ``core`` (pure and jitted, evosax's ``init`` / ``ask`` / ``tell``),
``operators`` (selection, crossover and mutation: named functions passed in, SPEC 10's by
default) and ``driver`` (evaluation in the maze, generations, stop rules, the seed); their names
are importable from here. Each generation every robot (P × R sets) runs ``ga_maze`` from
``starts`` starts with the LTL controller; ``tell`` keeps the elites and breeds the rest with the
operators (default: roulette on 1/(τ + ρc), uniform or RL crossover, 5 % mutation). [ours] One
run is a noisy measure, so each population's best is checked from ``success_starts`` fresh starts
and the checked best is the elite; the run stops when every best meets ``success_rate`` in two
checks, at ``target_f``, or at ``generations``.
"""

from __future__ import annotations

import importlib
from typing import Any

_SUBMODULES = ("config", "core", "operators", "evaluation", "driver")


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"jaxais.ga.{name}")
    for sub in _SUBMODULES:
        module = importlib.import_module(f"jaxais.ga.{sub}")
        if name in module.__all__:
            return getattr(module, name)
    raise AttributeError(f"module 'jaxais.ga' has no attribute {name!r}")
