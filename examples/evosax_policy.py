"""OpenAI-ES (evosax) training a small MLP policy on ``gymnax.make("jaxais/world1")``.

evosax's own ``GymnaxProblem`` rolls the policies out (one episode each, its return the
fitness, summed until the episode ends); the whole search is one jitted ``lax.scan`` over the
generations. evosax minimises, so the fitness it is told is minus the return::

    python examples/evosax_policy.py          # CONFIG: 50 generations of 32
    python examples/evosax_policy.py --tiny   # TINY: 3 generations of 4, what the tests run
"""

from __future__ import annotations

import sys
from typing import Any

import jax
import numpy as np
import optax
from evosax.algorithms import Open_ES
from evosax.problems import GymnaxProblem
from evosax.problems.networks import MLP, tanh_output_fn

from jaxais import envs

CONFIG = {
    "generations": 50,
    "population": 32,
    "rollouts": 2,
    "episode_length": 500,
    "hidden": 16,
    "sigma": 0.1,
    "learning_rate": 0.05,
}
TINY = {"generations": 3, "population": 4, "rollouts": 1, "episode_length": 16, "hidden": 4}


def main(config: dict[str, Any], seed: int = 0) -> dict[str, float]:
    """Evolve with ``config``; returns and prints the first and last generations' mean return."""
    envs.register_gymnax()
    problem = GymnaxProblem(
        "jaxais/world1",
        policy=MLP(layer_sizes=(config["hidden"], 2), output_fn=tanh_output_fn),
        episode_length=config["episode_length"],
        num_rollouts=config["rollouts"],
        use_normalize_obs=False,
        # One episode per rollout: no auto-reset, so reset draws no pool of next starts.
        env_kwargs={"max_steps_in_episode": config["episode_length"], "auto_reset": False},
    )
    key = jax.random.key(seed)
    solution = problem.sample(key)
    es = Open_ES(
        population_size=config["population"],
        solution=solution,
        optimizer=optax.adam(config["learning_rate"]),
        std_schedule=optax.constant_schedule(config["sigma"]),
    )
    params = es.default_params

    def generation(carry, key):
        state, problem_state = carry
        k_ask, k_eval, k_tell = jax.random.split(key, 3)
        population, state = es.ask(k_ask, state, params)
        returns, problem_state, _ = problem.eval(k_eval, population, problem_state)
        state, _ = es.tell(k_tell, population, -returns, state, params)
        return (state, problem_state), returns.mean()

    @jax.jit
    def search(key):
        k_init, k_problem, k_run = jax.random.split(key, 3)
        carry = (es.init(k_init, solution, params), problem.init(k_problem))
        keys = jax.random.split(k_run, config["generations"])
        return jax.lax.scan(generation, carry, keys)[1]

    mean_returns = np.asarray(search(key))
    summary = {"first": float(mean_returns[0]), "last": float(mean_returns[-1])}
    print(
        f"OpenES on jaxais/world1: {len(mean_returns)} generations of {config['population']}, "
        f"mean return {summary['first']:.4g} -> {summary['last']:.4g}"
    )
    return summary


if __name__ == "__main__":
    main(CONFIG | TINY if "--tiny" in sys.argv[1:] else CONFIG)
