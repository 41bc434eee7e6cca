"""Our readings of what the paper leaves open in its controllers, as one traced parameter set.

The paper does not say how long a selected behaviour acts, what a "consecutive obstacle
encounter" is, or how eq (4) treats a column whose initial mean is 0 (SPEC 5-7). Each reading
below is [ours], chosen from the paper's text or a behaviour-level test that never looks at the
STL results (``tests/test_behaviour_level.py``), and the earlier literal reading is kept as
:data:`LITERAL`, so ``scripts/ablate.py`` can show what each choice does. One field is the
paper's own rule with our earlier misreading kept beside it (``alpha_on_self``, section 4.3).
Every field is a pytree leaf: runs with different readings share one compiled program
(``vmap`` over them).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass

__all__ = ["ALPHA_ON_SELF", "DEFAULT", "LITERAL", "Readings", "readings"]

HOLD = 31
"""Iterations a selected behaviour acts (about 1 s at 32 ms) [ours]. A reverse turn at Table 1's
slowest reverse speed (300 units: 4.2 cm/s) with a small reduction A then backs about 4 cm
(about 3 cm at A = 60), beyond the 2.9 cm at which the IR reading falls under the obstacle
threshold 250, so it frees a robot in contact; a wander's "F % of time" is the share of its 1 s
bouts spent turning, so it drives a random walk instead of a fixed circle. Measured by
``tests/test_behaviour_level.py`` (empty and cluttered arenas): from contact with a wall, 99 % of
reverse turns never touch it again and all get clear within 5 s, against a median of 15
re-contacts per start with 1; a wander single at Table 1's midpoints visits about 1.7x the
5 cm cells in 120 s. (A reverse turn with A near 200 spins on the spot, for a whole bout.)
1 is the literal per-iteration reading, under which robots end up trapped (SPEC 5)."""

ENCOUNTER_GAP = 70
"""Iterations clear of obstacles (Vm < 250) that end a run of "consecutive obstacle encounters"
[ours]: about 2.2 s, the time a robot at the middle of Table 1's speed range (225 units,
3.2 cm/s) takes to leave the IR range (7 cm), i.e. to move well away (SPEC 6)."""

SIGMA0_FLOOR = 0.05
"""Floor on eq (4)'s initial column means, so a column whose seeded antibodies never earned
reward stays learnable [ours]: 0.05 is Table 2's smallest positive score, as if one antibody of
the column had earned it (SPEC 7). 0 is the literal equation, which pins such a column at 0."""


ALPHA_ON_SELF = False
"""Whether eqs (7)-(8) also sum alpha's effect on its own set (i = n). [paper, section 4.3]: the
network works by "comparing the idiotope of alpha with the paratopes of the other antibodies to
determine how much each is stimulated, and comparing the paratope of alpha with the idiotopes of
the others to calculate how much each should be suppressed", so alpha acts on the others only and
its own S2 is its P (False, the default). True is the engine's earlier reading: alpha's idiotope
sits where alpha is weak, so alpha then stimulates itself more and suppresses itself less than
the others, the network defends alpha, and the idiotypic difference rate stays near 5 % where
section 5 calibrated k1 and k2 to give about 20 % (SPEC 7)."""


@pytree_dataclass
class Readings:
    """The [ours] readings of the controllers (scalars, or [n] under ``vmap``).

    Attributes:
        hold: iterations a selected behaviour acts before the next selection, unless a new
            obstacle or collision interrupts it (see :func:`jaxais.controllers.interrupts`).
            The wander types draw their turn decision once per selection. 1 = every iteration.
        count_encounters: count the "more than 15 consecutive obstacle encounters" penalty in
            encounters (entries into antigens 2-7), a run broken only after ``encounter_gap``
            clear iterations; False counts consecutive iterations of antigens 2-7, broken by
            one clear iteration (the literal reading).
        encounter_gap: clear iterations that end a run of encounters.
        sigma0_floor: floor on eq (4)'s initial column means (0: the literal equation).
        alpha_on_self: eqs (7)-(8) include alpha's effect on its own set (:data:`ALPHA_ON_SELF`;
            False is the paper's "the other antibodies").
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
    """A validated :class:`Readings` (defaults: ours).

    Raises:
        ValueError: a one-line message naming the bad value.
    """
    if isinstance(hold, bool) or not isinstance(hold, int) or hold < 1:
        raise ValueError(f"hold must be an int >= 1 (iterations), got {hold!r}")
    if isinstance(encounter_gap, bool) or not isinstance(encounter_gap, int) or encounter_gap < 1:
        raise ValueError(f"encounter_gap must be an int >= 1 (iterations), got {encounter_gap!r}")
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
"""Our readings."""
LITERAL = readings(hold=1, count_encounters=False, sigma0_floor=0.0)
"""The literal per-iteration readings the engine used before (SPEC 5-7's "old readings"); alpha
acts on the others, as the paper's text says (the literal reading of section 4.3)."""
