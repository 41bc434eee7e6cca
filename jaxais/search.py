"""Adapters for third-party search code: QDax's MAP-Elites over the GA's genome (antibody sets)
and evosax's algorithms over the network's parameters. Both run the library's own evaluation,
so a jitted search scores a candidate key for key as the library does.

QDax (``pip install '.[qdax]'``; its fitness is maximised, so it is told -f)::

    evaluate = make_evaluator("ga_maze", config=GAConfig(), grid=None)  # jaxais.ga
    scoring = qdax_scoring(evaluate, final_position(world))  # (fitness, descriptors, extra)
    emitter = MixingEmitter(qdax_mutation(), qdax_variation(), 0.5, batch_size=32)

evosax (minimises f; ``sample`` draws within ``ranges``, inside :data:`~jaxais.immune.network.
BOUNDS`; ``eval`` runs :func:`jaxais.trials.make_trials` on ``with_params`` of each candidate)::

    problem = network_problem(run, make_system("SIE", seed), {"k1": (0, 2), "k2": (0, 2)})
    population = jax.vmap(problem.sample)(jax.random.split(key, 16))  # SimpleGA's, DE's start
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import envs
from jaxais.ga.config import GAConfig
from jaxais.ga.core import Evaluation
from jaxais.ga.evaluation import Descriptors
from jaxais.ga.operators import Operators, default_operators
from jaxais.immune.antibodies import Antibodies
from jaxais.immune.antigens import N_ANTIGENS
from jaxais.io import ArgumentTypeError, check_type
from jaxais.systems import PARAMETERS, System, system_params, with_params

__all__ = [
    "final_position",
    "mean_position",
    "network_problem",
    "qdax_mutation",
    "qdax_scoring",
    "qdax_variation",
    "visit_grid",
]


def _operators(operators: Operators | None, config: GAConfig | None) -> Operators:
    if operators is not None:
        check_type(operators, Operators, "operators", "an Operators (jaxais.ga.operators)")
        return operators
    return default_operators(GAConfig() if config is None else config)


def qdax_mutation(
    operators: Operators | None = None, config: GAConfig | None = None
) -> Callable[[Antibodies, jax.Array], Antibodies]:
    """QDax's ``mutation_fn(genotypes, key)``: the GA's mutation (``operators.mutation``;
    default ``config``'s, Table 1's resampling at 5 %) of sets [B, 8], within Table 1's limits."""
    mutation = _operators(operators, config).mutation
    return lambda genotypes, key: mutation(key, genotypes)


def _unscored(sets: Antibodies) -> Evaluation:
    """A parent's evaluation where none is at hand: zeros (equal L: RL crossover ties, a coin)."""
    batch = sets.shape[:-1]  # sets [..., 8]
    zeros = jnp.zeros(batch, jnp.float32)
    L = jnp.zeros((*batch, N_ANTIGENS), jnp.float32)
    return Evaluation(zeros, zeros, zeros, L, jnp.zeros(batch, jnp.int32))


def qdax_variation(
    operators: Operators | None = None, config: GAConfig | None = None, mutate: bool = True
) -> Callable[[Antibodies, Antibodies, jax.Array], Antibodies]:
    """QDax's ``variation_fn(x1, x2, key)``: children [B, 8] of parents ``x1``, ``x2`` as the GA
    breeds them: ``operators.crossover``, then (``mutate``) ``operators.mutation``, keys split
    as :func:`jaxais.ga.core.next_generation` splits its. QDax passes no scores, so the
    parents' evaluations are zeros: RL-assisted crossover ties everywhere, a coin per antigen."""
    ops = _operators(operators, config)

    def variation_fn(x1: Antibodies, x2: Antibodies, key: jax.Array) -> Antibodies:
        k_cross, k_mut = jax.random.split(key)
        children = ops.crossover(k_cross, x1, _unscored(x1), x2, _unscored(x2))
        return ops.mutation(k_mut, children) if mutate else children

    return variation_fn


def final_position(world: envs.World | str) -> Callable[[Descriptors], jnp.ndarray]:
    """A descriptor: where the runs ended, (x, y) [..., 2] in [0, 1] across ``world``'s arena,
    mean over the starts."""
    world = envs.load_world(world) if isinstance(world, str) else world
    lo, hi = np.asarray(world.arena[:2]), np.asarray(world.arena[2:])

    def descriptor(d: Descriptors) -> jnp.ndarray:
        xy = jnp.mean(d.final_pose[..., :2], axis=-2)
        return jnp.clip((xy - lo) / (hi - lo), 0.0, 1.0)

    return descriptor


def mean_position(d: Descriptors) -> jnp.ndarray:
    """A descriptor: where the runs spent their time, the visit grid's centroid (x, y) [..., 2]
    in [0, 1] across the arena (an evaluator made with ``grid``; cells at their centres)."""
    visit_grid(d)  # the check: an evaluator with a grid
    rows, cols = d.visits.shape[-2:]
    x = (jnp.arange(cols) + 0.5) / cols
    y = (jnp.arange(rows) + 0.5) / rows
    return jnp.stack([jnp.sum(d.visits.sum(-2) * x, -1), jnp.sum(d.visits.sum(-1) * y, -1)], -1)


def visit_grid(d: Descriptors) -> jnp.ndarray:
    """A descriptor: the visit grid [..., rows · cols] (an evaluator made with ``grid``)."""
    if d.visits is None:
        raise ValueError("visit_grid: the evaluator has no grid: make_evaluator(..., grid=(r, c))")
    return d.visits.reshape(*d.visits.shape[:-2], -1)


def qdax_scoring(
    evaluate_sets: Callable[[jax.Array, Antibodies], tuple[Evaluation, Descriptors]],
    descriptor: Callable[[Descriptors], jnp.ndarray],
) -> Callable[[Antibodies, jax.Array], tuple[jnp.ndarray, jnp.ndarray, dict[str, Any]]]:
    """QDax's ``scoring_function(genotypes, key)``: (fitness [B] = -f, QDax maximising;
    ``descriptor`` [B, D]; extra scores τ, c, crossings [B] and L [B, 8]) of
    :func:`jaxais.ga.evaluation.make_evaluator`'s ``evaluate_sets``."""

    def scoring_fn(genotypes: Antibodies, key: jax.Array):
        evaluation, descriptors = evaluate_sets(key, genotypes)
        extra = {"tau": evaluation.tau, "collisions": evaluation.collisions}
        extra |= {"crossings": evaluation.crossings, "L": evaluation.L}
        return -evaluation.fitness, descriptor(descriptors), extra

    return scoring_fn


# ------------------------------------------------------------------------------- evosax


def _check_ranges(system: System, ranges: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
    """``ranges`` as name -> (low, high) floats, each finite and inside the parameter's bounds."""
    check_type(ranges, Mapping, "ranges", "a dict name -> (low, high)")
    if not ranges:
        raise ValueError("ranges must name at least one parameter, e.g. {'k1': (0, 2)}")
    known = system_params(system)
    out = {}
    for name, span in ranges.items():
        if name not in known:
            raise ValueError(f"ranges: unknown parameter {name!r}; known: {sorted(known)}")
        try:
            low, high = (float(v) for v in span)
        except (TypeError, ValueError):
            raise ValueError(f"ranges[{name!r}] must be (low, high), got {span!r}") from None
        field = PARAMETERS.get(name, (None,))[0]
        bound = _bound(system, name) if field == "network" else (-math.inf, math.inf)
        ok = math.isfinite(low) and math.isfinite(high) and low < high
        if not ok or low < bound[0] or high > bound[1]:
            raise ValueError(
                f"ranges[{name!r}] must be finite, low < high and within {bound}, got {span!r}"
            )
        out[name] = (low, high)
    return out


def _bound(system: System, name: str) -> tuple[float, float]:
    from jaxais.immune.network import bounds

    return bounds(system.network).get(name, (-math.inf, math.inf))


@functools.cache
def _problem_class() -> type:
    """evosax's ``Problem`` subclassed (evosax imported on first use: an optional extra)."""
    try:
        from evosax.problems.problem import Problem, State
    except ImportError:
        raise ImportError("network_problem needs evosax: pip install 'jaxais[evosax]'") from None

    class NetworkProblem(Problem):
        """Network parameters as an evosax problem: a solution is {name: float32}; ``eval``'s
        fitness [population] is each candidate's mean f over ``run``'s trials (lower is
        better, as evosax minimises), common random numbers (one key for all)."""

        def __init__(self, run, system, ranges):
            self.run, self.system, self.ranges = run, system, ranges

        @functools.partial(jax.jit, static_argnames=("self",))
        def eval(self, key, solutions, state):
            cost = lambda x: jnp.mean(self.run(key, with_params(self.system, x))["fitness"])
            fitness = jax.vmap(cost)(solutions)
            return fitness, state.replace(counter=state.counter + 1), {}

        @functools.partial(jax.jit, static_argnames=("self",))
        def sample(self, key):
            keys = jax.random.split(key, len(self.ranges))
            return {
                name: jax.random.uniform(k, (), jnp.float32, low, high)
                for k, (name, (low, high)) in zip(keys, self.ranges.items(), strict=True)
            }

    NetworkProblem.State = State
    return NetworkProblem


def network_problem(
    run: Callable[[jax.Array, System], dict[str, jnp.ndarray]],
    system: System,
    ranges: Mapping[str, tuple[float, float]],
):
    """An evosax ``Problem`` over ``system``'s parameters ``ranges`` (name -> (low, high),
    finite, within :data:`~jaxais.immune.network.BOUNDS`): ``sample(key)`` draws a solution
    {name: float32} uniformly in them (a population-based algorithm's start: ``jax.vmap`` it);
    ``eval(key, solutions, state)`` runs ``run`` (:func:`jaxais.trials.make_trials`' run) on
    ``with_params(system, x)`` of each, and ``with_params`` clips what an algorithm proposes
    into BOUNDS."""
    if not callable(run):
        raise ArgumentTypeError(f"run must be make_trials(config)'s function, got {run!r:.60}")
    check_type(system, System, "system", "a System (make_system)")
    return _problem_class()(run, system, _check_ranges(system, ranges))
