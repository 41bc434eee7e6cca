"""The LTL genetic algorithm (SPEC 10). **LOWER fitness is better**: a robot's fitness is the
paper's f = (ρc + τ)/2 (eq 11); selection, elitism and every "best" minimise it.

Modules (their names are importable from here, loaded on first use): ``config`` (GAConfig, no
JAX), ``core`` (pure, jitted, shaped like evosax: ``init`` / ``ask`` / ``tell``) and ``driver``
(evaluation in the maze, generations, stop rules, the seed).

Each generation every robot (P × R antibody sets) runs ``ga_maze`` from ``starts`` random starts
with the LTL controller (RL on, no idiotypic selection): τ, c, L, f are means over them and
``crossings`` counts the starts in which it crossed the maze (reached the goal within the time
cap). ``tell`` keeps the ``elitism`` best robots and breeds the rest from two parents drawn by
roulette on 1/(τ + ρc), each antigen's antibody from either parent (uniform) or the one with the
higher L (``"rl"``), then mutated. [ours] One run is a noisy measure of a set (with one start the
best of 50 robots was mostly the luckiest), so with ``success_starts`` > 0 each population's
best of the generation is checked from fresh starts, checks pooled while a set stays best, and
the checked best is the elite; a set meeting ``success_rate`` outranks one that does not, then
f decides. The run stops when every best meets ``success_rate`` in two checks, at ``target_f``,
or at ``generations``. The seed holds each best's measured τ, c and L (eq (1) needs them).
"""

from __future__ import annotations

import importlib
from typing import Any

_SUBMODULES = ("config", "core", "driver")


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"jaxais.ga.{name}")
    for sub in _SUBMODULES:
        module = importlib.import_module(f"jaxais.ga.{sub}")
        if name in module.__all__:
            return getattr(module, name)
    raise AttributeError(f"module 'jaxais.ga' has no attribute {name!r}")
