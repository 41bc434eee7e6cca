"""Our readings of what the paper leaves open in its controllers (SPEC 5-7), as one parameter set.

Each [ours] reading is argued in SPEC and tested at behaviour level (tests/test_behaviour_level.py);
:data:`LITERAL` keeps the earlier literal readings for ``scripts/ablate.py``. Fields are pytree
leaves: runs with different readings share one compiled program.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass

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
    """The readings (scalars, or [n] under ``vmap``).

    Attributes:
        hold: :data:`HOLD` (a new obstacle or collision interrupts it).
        count_encounters: the obstacle penalty counts encounters, not iterations
            (:func:`~jaxais.immune.reinforcement.update_penalty`).
        encounter_gap: :data:`ENCOUNTER_GAP`.
        sigma0_floor: :data:`SIGMA0_FLOOR`. alpha_on_self: :data:`ALPHA_ON_SELF`.
    """

    hold: jnp.ndarray
    count_encounters: jnp.ndarray
    encounter_gap: jnp.ndarray
    sigma0_floor: jnp.ndarray
    alpha_on_self: jnp.ndarray


def readings(
    hold: int = HOLD,
    count_encounters: bool = True,
    encounter_gap: int = ENCOUNTER_GAP,
    sigma0_floor: float = SIGMA0_FLOOR,
    alpha_on_self: bool = ALPHA_ON_SELF,
) -> Readings:
    """A validated :class:`Readings` (defaults: ours; ValueError names a bad value)."""
    for name, value in (("hold", hold), ("encounter_gap", encounter_gap)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name} must be an int >= 1 (iterations), got {value!r}")
    if not 0.0 <= sigma0_floor <= 1.0:
        raise ValueError(f"sigma0_floor must lie in [0, 1], got {sigma0_floor!r}")
    for name, flag in (("count_encounters", count_encounters), ("alpha_on_self", alpha_on_self)):
        if not isinstance(flag, bool | np.bool_):
            raise ValueError(f"{name} must be True or False, got {flag!r}")
    return Readings(
        hold=np.asarray(hold, np.int32),
        count_encounters=np.asarray(count_encounters, bool),
        encounter_gap=np.asarray(encounter_gap, np.int32),
        sigma0_floor=np.asarray(sigma0_floor, np.float32),
        alpha_on_self=np.asarray(alpha_on_self, bool),
    )


DEFAULT = readings()
LITERAL = readings(hold=1, count_encounters=False, sigma0_floor=0.0)
"""The literal readings the engine used before (SPEC 5-7); alpha acts on the others."""
