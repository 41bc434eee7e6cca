"""Reinforcement scores and the stuck penalties (SPEC 6, the paper's Table 2 and section 4.4).

For one robot, shared by the LTL (score L) and the STL (paratope P): the antibody that acted at
t-1 is scored from the antigens (m_{t-1}, m_t):

======  =====  =========================================================================
old     new    score
======  =====  =========================================================================
0       0      +0.05
1       0      -0.10
2-7     0      +0.10
0       1      +0.10
1       1      0.05 (1 - |x - 7| / 7), x the blue centroid column (0..14) [ours]
2-7     1      +0.20
0       2-7    -0.05
1       2-7    -0.05
2-7     2-7    0.25 (lev_old - lev_new) + 0.25 clip((V_old - V_new) / V_old, -1, 1)
               - 0.10 [same antigen and V_new >= V_old], clipped to [-0.40, 0.50] [ours]
======  =====  =========================================================================

lev is 1 for obstacle and 2 for collision antigens, V the maximum IR reading ``Vm``.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.antigens import TARGET_SEEN, TARGET_UNSEEN, is_obstacle_or_collision, severity

# Fixed rows of Table 2 [paper].
SCORE_UNSEEN_TO_UNSEEN = 0.05  # 0 -> 0: no obstacles encountered.
SCORE_LOST_MARKER = -0.10  # 1 -> 0: lost sight of the marker.
SCORE_AVOIDED = 0.10  # 2-7 -> 0: avoided the obstacle.
SCORE_FOUND_MARKER = 0.10  # 0 -> 1: found the marker.
SCORE_AVOIDED_AND_SEEN = 0.20  # 2-7 -> 1: avoided the obstacle, sees the marker.
SCORE_UNSEEN_TO_OBSTACLE = -0.05  # 0 -> 2-7: encountered an obstacle.
SCORE_SEEN_TO_OBSTACLE = -0.05  # 1 -> 2-7: encountered an obstacle.

# 1 -> 1, "0.00 to 0.05 depending on the marker's orientation" [paper: range; ours: formula].
SCORE_KEPT_MARKER_MAX = 0.05  # 1 -> 1 score with the marker dead ahead.
CENTRE_COLUMN = 7.0  # Camera column straight ahead (of 0..14).
CENTRE_HALF_WIDTH = 7.0  # Centroid offset where the 1 -> 1 score reaches 0 (the image edge).

# 2-7 -> 2-7, "-0.40 to 0.50, depending on several factors" [paper: range; ours: formula].
WEIGHT_SEVERITY = 0.25  # Per level of severity gained (collision -> obstacle) or lost.
WEIGHT_PROXIMITY = 0.25  # Times the relative fall of Vm, clipped to [-1, 1].
PENALTY_NO_PROGRESS = 0.10  # Subtracted when the antigen is unchanged and Vm did not fall.
SCORE_OBSTACLE_MIN = -0.40
SCORE_OBSTACLE_MAX = 0.50
V_PREV_FLOOR = 1e-6  # V_old = 0 gives no NaN (a real 2-7 antigen has Vm >= 250).

# Stuck penalties [paper].
UNSEEN_LIMIT = 250  # Penalise after more than this many consecutive iterations of antigen 0.
OBSTACLE_LIMIT = 15  # Penalise after more consecutive obstacle encounters (Readings).
PENALTY_IDIOTYPIC = 0.5  # Score a penalty removes from the acting antibody, idiotypic systems.
PENALTY_NON_IDIOTYPIC = 1.0  # ... and in non-idiotypic systems.

# [old group, new group] for the fixed rows; group 0 unseen, 1 seen, 2 obstacle/collision. The
# two ranged cells (1 -> 1, 2-7 -> 2-7) are computed and hold NaN here.
_TABLE = np.array(
    [
        [SCORE_UNSEEN_TO_UNSEEN, SCORE_FOUND_MARKER, SCORE_UNSEEN_TO_OBSTACLE],
        [SCORE_LOST_MARKER, np.nan, SCORE_SEEN_TO_OBSTACLE],
        [SCORE_AVOIDED, SCORE_AVOIDED_AND_SEEN, np.nan],
    ],
    dtype=np.float32,
)


def _group(m: jnp.ndarray) -> jnp.ndarray:
    return jnp.minimum(jnp.asarray(m, jnp.int32), 2)


def rl_score(
    m_prev: jnp.ndarray,
    m: jnp.ndarray,
    v_prev: jnp.ndarray,
    v: jnp.ndarray,
    centroid: jnp.ndarray,
) -> jnp.ndarray:
    """Table 2 score in [-0.40, 0.50] of the antibody that acted at t-1, from the antigens and
    Vm at t-1 and t and the blue centroid column at t (0..14)."""
    v_prev = jnp.asarray(v_prev, jnp.float32)
    v = jnp.asarray(v, jnp.float32)
    g_prev, g = _group(m_prev), _group(m)

    offset = jnp.abs(jnp.asarray(centroid, jnp.float32) - CENTRE_COLUMN) / CENTRE_HALF_WIDTH
    kept_marker = SCORE_KEPT_MARKER_MAX * jnp.clip(1.0 - offset, 0.0, 1.0)

    relative_fall = jnp.clip((v_prev - v) / jnp.maximum(v_prev, V_PREV_FLOOR), -1.0, 1.0)
    no_progress = (m == m_prev) & (v >= v_prev)
    obstacle = (
        WEIGHT_SEVERITY * (severity(m_prev) - severity(m)).astype(jnp.float32)
        + WEIGHT_PROXIMITY * relative_fall
        - PENALTY_NO_PROGRESS * no_progress.astype(jnp.float32)
    )
    obstacle = jnp.clip(obstacle, SCORE_OBSTACLE_MIN, SCORE_OBSTACLE_MAX)

    fixed = jnp.asarray(_TABLE)[g_prev, g]
    both_seen = (g_prev == TARGET_SEEN) & (g == TARGET_SEEN)
    both_obstacle = is_obstacle_or_collision(m_prev) & is_obstacle_or_collision(m)
    return jnp.where(both_seen, kept_marker, jnp.where(both_obstacle, obstacle, fixed))


@pytree_dataclass
class PenaltyCounters:
    """Lengths (int32) of the current runs of antigen 0 (``unseen_run``), of obstacle
    encounters (``obstacle_run``; both 0 after a penalty) and of antigens 0-1 (``clear_run``)."""

    unseen_run: jnp.ndarray
    obstacle_run: jnp.ndarray
    clear_run: jnp.ndarray


def init_counters() -> PenaltyCounters:
    """Counters at the start of a run (no antigen seen yet: clear)."""
    return PenaltyCounters(
        unseen_run=jnp.int32(0), obstacle_run=jnp.int32(0), clear_run=jnp.int32(1)
    )


def update_penalty(
    counters: PenaltyCounters,
    m: jnp.ndarray,
    count_encounters: bool | jnp.ndarray = False,
    encounter_gap: int | jnp.ndarray = 1,
) -> tuple[PenaltyCounters, jnp.ndarray]:
    """The runs with antigen ``m`` counted in, and whether a penalty fires now.

    A penalty fires when a run passes its limit (the 251st antigen 0 [paper], the 16th
    encounter) and restarts that run. ``count_encounters`` [ours]: an encounter is an entry into
    2-7 from 0-1, ended by ``encounter_gap`` clear iterations (catches a robot hovering at the
    threshold); else [paper, literal] every iteration of 2-7 counts and one clear one ends it.
    """
    obstacle_now = is_obstacle_or_collision(m)
    unseen = jnp.where(m == TARGET_UNSEEN, counters.unseen_run + 1, 0)
    clear = jnp.where(obstacle_now, 0, counters.clear_run + 1)
    entered = obstacle_now & (counters.clear_run > 0)
    encounters = jnp.where(
        clear >= encounter_gap, 0, counters.obstacle_run + entered.astype(jnp.int32)
    )
    iterations = jnp.where(obstacle_now, counters.obstacle_run + 1, 0)
    obstacle = jnp.where(count_encounters, encounters, iterations)
    fire_unseen = unseen > UNSEEN_LIMIT
    fire_obstacle = obstacle > OBSTACLE_LIMIT
    new = PenaltyCounters(
        unseen_run=jnp.where(fire_unseen, 0, unseen).astype(jnp.int32),
        obstacle_run=jnp.where(fire_obstacle, 0, obstacle).astype(jnp.int32),
        clear_run=clear.astype(jnp.int32),
    )
    return new, fire_unseen | fire_obstacle


def penalty_size(
    idiotypic: bool | jnp.ndarray,
    with_idiotypic: float | jnp.ndarray = PENALTY_IDIOTYPIC,
    without: float | jnp.ndarray = PENALTY_NON_IDIOTYPIC,
) -> jnp.ndarray:
    """Score removed by one penalty: 0.5 with idiotypic selection, 1.0 without [paper]."""
    return jnp.where(idiotypic, with_idiotypic, without).astype(jnp.float32)
