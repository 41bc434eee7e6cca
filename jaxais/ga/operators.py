"""The GA's breeding operators, passed in (evosax-style): selection, crossover and mutation are
functions on arrays, each wrapped in a named :class:`Operator`, and an :class:`Operators` holds
the three. :func:`jaxais.ga.core.next_generation` calls them (elitism stays the core's); the
defaults, :func:`default_operators`, are SPEC 10's roulette, the config's crossover (uniform
[ours] or RL-assisted) and its mutation rate (the paper's 5 %).

The three signatures (keys are typed ``jax.random.key``; write them with jnp, they run under
jit; LOWER fitness is better)::

    selection(key, evaluation, n) -> [n] int32 parent indices in [0, R)
        ``evaluation``: ONE population's :class:`jaxais.ga.core.Evaluation` (fitness, tau,
        collisions, crossings [R], L [R, 8]); the core vmaps it over the populations, with a
        key each, and draws n = 2 (R - elitism): the first half are the children's first
        parents, the second half their second.
    crossover(key, a, a_eval, b, b_eval) -> Antibodies [..., 8]
        the children of parents ``a``, ``b`` (Antibodies [..., 8]), whose evaluations are
        ``a_eval``, ``b_eval`` (Evaluation [...]: f, τ, c, crossings; L [..., 8]); called once
        for every child of every population ([P, R - elitism]), with one key.
    mutation(key, children) -> Antibodies [..., 8]
        ``children`` mutated, within Table 1's limits; called once for all children.

A user's operator is one function in one file of theirs, e.g. (examples/tournament_ga.py)::

    def tournament(key, evaluation, n):  # n times the lowest f of 3 robots drawn at random
        drawn = jax.random.randint(key, (n, 3), 0, evaluation.fitness.shape[0])
        return drawn[jnp.arange(n), jnp.argmin(evaluation.fitness[drawn], axis=1)]

    ops = ga.default_operators(config).replace(selection=ga.Operator("tournament3", tournament))
    evolution.evolve(out, config=config, operators=ops)

An operator's ``name`` is recorded in checkpoints and summaries (a resume with another is
refused). Operators are static arguments of the jitted core: build one once and reuse it (one
compile per operator object; the factories here are cached, so equal arguments give the same).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp

from jaxais.immune.antibodies import Antibodies, mutate
from jaxais.io import ArgumentTypeError, check_type
from jaxais.loop import RHO

if TYPE_CHECKING:
    from jaxais.ga.config import GAConfig
    from jaxais.ga.core import Evaluation

__all__ = [
    "Operator",
    "Operators",
    "crossover",
    "default_operators",
    "resample_mutation",
    "rl_crossover",
    "roulette",
    "roulette_selection",
    "selection_weights",
    "uniform_crossover",
]

ROLES = ("selection", "crossover", "mutation")


@dataclasses.dataclass(frozen=True)
class Operator:
    """A GA operator: ``fn`` (one of the module docstring's three signatures) and the ``name``
    checkpoints record. Calling it calls ``fn``. Hashable, a static jit argument: two are equal
    when their names are and their ``fn`` is the same function."""

    name: str
    fn: Callable[..., Any]

    def __post_init__(self):
        check_type(self.name, str, "an Operator's name", "a string")
        if not self.name.strip():
            raise ValueError("an Operator's name must not be empty (checkpoints record it)")
        if not callable(self.fn):
            raise ArgumentTypeError(
                f"Operator {self.name!r}: fn must be a function, got {self.fn!r:.60}"
            )

    def __call__(self, *args: Any) -> Any:
        return self.fn(*args)


@dataclasses.dataclass(frozen=True)
class Operators:
    """The three breeding operators a GA runs (:func:`default_operators`: SPEC 10's)."""

    selection: Operator
    crossover: Operator
    mutation: Operator

    def __post_init__(self):
        for role in ROLES:
            check_type(getattr(self, role), Operator, f"Operators.{role}", "an Operator(name, fn)")

    def names(self) -> dict[str, str]:
        """{"selection": name, "crossover": name, "mutation": name}: what checkpoints record."""
        return {role: getattr(self, role).name for role in ROLES}

    def replace(self, **changes: Operator) -> Operators:
        """A copy with the operators given by role replaced."""
        return dataclasses.replace(self, **changes)


# ------------------------------------------------------------------------------- selection


def selection_weights(tau: jnp.ndarray, collisions: jnp.ndarray, rho: float = RHO) -> jnp.ndarray:
    """[...] float32 roulette weights 1/(τ + ρc) (SPEC 10), unnormalised (the floor only guards
    a zero cost)."""
    cost = jnp.asarray(tau, jnp.float32) + rho * jnp.asarray(collisions, jnp.float32)
    return 1.0 / jnp.maximum(cost, 1e-6)


def roulette(key: jax.Array, weights: jnp.ndarray, n: int) -> jnp.ndarray:
    """[n] int32 indices drawn with replacement, with probability proportional to ``weights``
    [R] (non-negative, not all 0)."""
    cdf = jnp.cumsum(weights)
    u = jax.random.uniform(key, (n,))
    # side="right": u falls in [cdf[i-1], cdf[i]) -> i, so a zero-weight robot is never drawn.
    idx = jnp.searchsorted(cdf, u * cdf[-1], side="right")
    return jnp.minimum(idx, weights.shape[0] - 1).astype(jnp.int32)


def _roulette_selection(key: jax.Array, evaluation: Evaluation, n: int) -> jnp.ndarray:
    return roulette(key, selection_weights(evaluation.tau, evaluation.collisions), n)


@functools.cache
def roulette_selection() -> Operator:
    """ "roulette": n draws with replacement, robot r with probability ∝ 1/(τ_r + ρc_r)
    (SPEC 10)."""
    return Operator("roulette", _roulette_selection)


# ------------------------------------------------------------------------------- crossover


def crossover(
    key: jax.Array,
    a: Antibodies,
    La: jnp.ndarray,
    b: Antibodies,
    Lb: jnp.ndarray,
    rl_assisted: bool = True,
) -> Antibodies:
    """Children [..., 8] of parents ``a``, ``b`` [..., 8], antigen by antigen (SPEC 10).

    RL-assisted (SPEC 10's rule): the antibody of the parent with the higher L_j (``La``, ``Lb``
    [..., 8]), either on a tie; uniform (``rl_assisted=False``, static): either, 1/2 each.
    """
    coin = jax.random.uniform(key, La.shape) < 0.5
    from_a = (La > Lb) | ((La == Lb) & coin) if rl_assisted else coin
    return jax.tree.map(lambda x, y: jnp.where(from_a, x, y), a, b)


def _uniform(key, a, a_eval, b, b_eval):
    return crossover(key, a, a_eval.L, b, b_eval.L, rl_assisted=False)


def _rl(key, a, a_eval, b, b_eval):
    return crossover(key, a, a_eval.L, b, b_eval.L, rl_assisted=True)


@functools.cache
def uniform_crossover() -> Operator:
    """ "uniform": each antigen's antibody from either parent, 1/2 each [ours: the default]."""
    return Operator("uniform", _uniform)


@functools.cache
def rl_crossover() -> Operator:
    """ "rl": each antigen's antibody from the parent with the higher L_j, either on a tie
    (SPEC 10's RL-assisted crossover)."""
    return Operator("rl", _rl)


# ------------------------------------------------------------------------------- mutation


@functools.cache
def resample_mutation(rate: float = 0.05) -> Operator:
    """ "resample(rate)": each gene redrawn within Table 1's limits with probability ``rate``
    (:func:`jaxais.immune.antibodies.mutate`; SPEC 10: 0.05)."""
    if isinstance(rate, bool) or not (isinstance(rate, int | float) and 0 <= rate <= 1):
        raise ValueError(f"resample_mutation: rate must be a probability in [0, 1], got {rate!r}")
    rate = float(rate)
    return Operator(f"resample({rate!r})", lambda key, children: mutate(key, children, rate))


def default_operators(config: GAConfig) -> Operators:
    """SPEC 10's operators as ``config`` chooses them: roulette selection, its ``crossover``
    ("uniform" or "rl") and resampling with probability ``mutation``."""
    cross = rl_crossover() if config.crossover == "rl" else uniform_crossover()
    return Operators(roulette_selection(), cross, resample_mutation(float(config.mutation)))
