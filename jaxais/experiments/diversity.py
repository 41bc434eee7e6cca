"""Diversity of evolved sets (SPEC 10 [ours]): P independent populations against one of P × R."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.ga import driver
from jaxais.ga.config import GAConfig
from jaxais.ga.core import GAState
from jaxais.immune.antibodies import Antibodies, antibody_distance
from jaxais.immune.antigens import N_ANTIGENS

__all__ = ["compare_diversity", "diversity"]


@jax.jit
def _set_distances(sets: Antibodies) -> jnp.ndarray:
    """[K, K, 8] antibody distances between every pair of sets, per antigen."""
    a = jax.tree.map(lambda x: jnp.asarray(x)[:, None, :], sets)
    b = jax.tree.map(lambda x: jnp.asarray(x)[None, :, :], sets)
    return antibody_distance(a, b)


def diversity(sets: Antibodies) -> float:
    """Mean pairwise distance between K >= 2 sets [K, 8], in [0, 1]: the mean over all pairs
    (i < k) and antigens j of :func:`jaxais.immune.antibodies.antibody_distance` (A_ij, A_kj)."""
    K = sets.shape[0]
    if len(sets.shape) != 2 or K < 2:
        raise ValueError(f"diversity needs [K >= 2, {N_ANTIGENS}] sets, got {sets.shape}")
    d = np.asarray(_set_distances(sets), np.float64).mean(axis=-1)  # [K, K]
    return float(d[np.triu_indices(K, k=1)].mean())


def compare_diversity(
    seeds: Sequence[int],
    config: GAConfig,
    world: envs.World,
    sim_params: envs.SimParams | None = None,
    done: Mapping[int, GAState] | None = None,
    on_run: Callable[[str, int], None] | None = None,
) -> dict[str, Any]:
    """Diversity of P populations of R (each one's final best) against one of P × R (its P best),
    one GA run each per seed (``jax.random.key(s)``), by two-sided Welch and Mann-Whitney tests.
    ``done``: finished multi-population states by seed, reused; ``on_run(arm, seed)`` after each
    run. Returns a JSON-able dict (statistics None where undefined)."""
    from scipy import stats

    if config.populations < 2:
        raise ValueError("compare_diversity: the multi-population arm needs populations >= 2")
    if len(set(seeds)) != len(seeds) or len(seeds) < 2:
        raise ValueError("compare_diversity: give at least 2 distinct seeds")
    sim_params = envs.default_params() if sim_params is None else sim_params
    single = dataclasses.replace(config, populations=1, robots=config.populations * config.robots)
    done = done or {}
    arms = {  # the GA config, the best sets kept per run (None: each population's best)
        "multi": (config, None, "best robot of each population, final generation"),
        "single": (
            single,
            config.populations,
            f"{config.populations} best robots of the final generation",
        ),
    }
    values: dict[str, list[float]] = {arm: [] for arm in arms}
    for s in seeds:
        for arm, (cfg, k, _) in arms.items():
            state = done.get(s) if arm == "multi" else None
            if state is None:
                state = driver.run(jax.random.key(s), cfg, world, sim_params)
                if on_run is not None:
                    on_run(arm, s)
            values[arm].append(diversity(driver.final_sets(state, k)))

    def finite(x: float) -> float | None:
        return float(x) if math.isfinite(float(x)) else None

    with np.errstate(all="ignore"):
        t = stats.ttest_ind(values["multi"], values["single"], equal_var=False)
    u = stats.mannwhitneyu(values["multi"], values["single"], alternative="two-sided")
    return {
        "seeds": [int(s) for s in seeds],
        **{
            arm: {
                "populations": cfg.populations,
                "robots": cfg.robots,
                "sets": sets,
                "diversity": values[arm],
                "mean": float(np.mean(values[arm])),
            }
            for arm, (cfg, _, sets) in arms.items()
        },
        "welch_t": {"statistic": finite(t.statistic), "p_value": finite(t.pvalue)},
        "mann_whitney_u": {"statistic": finite(u.statistic), "p_value": finite(u.pvalue)},
    }
