"""Our readings of what the paper leaves open in its controllers (SPEC 5-7), as one parameter set.

Each [ours] reading is argued in SPEC and tested at behaviour level (tests/test_behaviour_level.py);
:data:`LITERAL` keeps the earlier literal readings for ``scripts/ablate.py``. Fields are pytree
leaves: runs with different readings share one compiled program.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.network import Param, declared, param

HOLD = 31
"""Iterations a selected behaviour acts, about 1 s [ours]: a reverse turn then backs out of IR
range and a wander's F is its share of 1 s bouts spent turning; 1 is the literal reading, under
which robots end up trapped (SPEC 5)."""
ENCOUNTER_GAP = 70
"""Clear iterations (Vm < 250) that end a run of obstacle encounters, about 2.2 s: leaving IR
range at a mid-range speed [ours, SPEC 6]."""
SIGMA0_FLOOR = 0.05
"""Floor on eq (4)'s initial column means, Table 2's smallest positive score, so a column that
never earned reward stays learnable [ours, SPEC 7]; 0 is the literal equation."""
ALPHA_ON_SELF = False
"""Eqs (7)-(8) also sum alpha's own set: False is [paper, section 4.3] ("the other
antibodies"); True, the earlier reading, keeps the idiotypic difference rate near 5 % (SPEC 7)."""


@pytree_dataclass
class Readings:
    """The readings (scalars, or [n] under ``vmap``); build with :func:`readings`. Each field
    declares its default, range, help and mechanism (:func:`~jaxais.immune.network.param`).
    """

    # fmt: off
    hold: jnp.ndarray = param(HOLD, kind=int, bound=(1, np.inf), unit="iterations",
                              mechanism="every", help="iterations a selected behaviour acts "
                              "unless a new obstacle or collision interrupts it (HOLD)")
    count_encounters: jnp.ndarray = param(True, kind=bool, mechanism="every",
                                          help="the obstacle penalty counts encounters, not "
                                          "iterations (reinforcement.update_penalty)")
    encounter_gap: jnp.ndarray = param(ENCOUNTER_GAP, kind=int, bound=(1, np.inf),
                                       unit="iterations", mechanism="every",
                                       help="clear iterations that end a run of obstacle "
                                       "encounters (ENCOUNTER_GAP)")
    sigma0_floor: jnp.ndarray = param(SIGMA0_FLOOR, bound=(0.0, 1.0), mechanism="learning",
                                      help="floor on eq (4)'s initial column means "
                                      "(SIGMA0_FLOOR)")
    alpha_on_self: jnp.ndarray = param(ALPHA_ON_SELF, kind=bool, mechanism="idiotypic",
                                       help="eqs (7)-(8) also sum alpha's own set "
                                       "(ALPHA_ON_SELF)")
    # fmt: on


_DTYPES = {int: np.int32, bool: np.bool_, float: np.float32}  # a reading's leaf per kind


def _checked(name: str, value: Any, declaration: Param) -> np.ndarray:
    """``value`` as its leaf; ValueError (one line) when it is not of its kind and range."""
    kind, (low, high) = declaration.kind, declaration.bound or (-np.inf, np.inf)
    if kind is bool:
        if not isinstance(value, bool | np.bool_):
            raise ValueError(f"{name} must be True or False, got {value!r}")
    elif kind is int:
        whole = isinstance(value, int) and not isinstance(value, bool)
        if not whole or not low <= value <= high:
            rule = f">= {low}" if high == np.inf else f"in [{low}, {high}]"
            unit = f" ({declaration.unit})" if declaration.unit else ""
            raise ValueError(f"{name} must be an int {rule}{unit}, got {value!r}")
    elif isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name} must be a number, got {type(value).__name__}")
    elif not low <= value <= high:  # NaN fails too
        raise ValueError(f"{name} must lie in [{low:g}, {high:g}], got {value!r}")
    return np.asarray(value, _DTYPES[kind])


def readings(**overrides: Any) -> Readings:
    """A validated :class:`Readings`: the fields' defaults (ours) with ``overrides`` (e.g.
    ``hold=1``); ValueError names a bad value."""
    fields = {f.name: f.default for f in dataclasses.fields(Readings)}
    for name in overrides:
        if name not in fields:  # as Python says for a keyword argument
            raise TypeError(f"readings() got an unexpected keyword argument {name!r}")
    values = fields | overrides
    return Readings(
        **{name: _checked(name, values[name], p) for name, p in declared(Readings).items()}
    )


DEFAULT = readings()
LITERAL = readings(hold=1, count_encounters=False, sigma0_floor=0.0)
"""The literal readings the engine used before (SPEC 5-7); alpha acts on the others."""
