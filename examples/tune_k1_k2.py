"""CMA-ES (evosax) tunes the network's k1 and k2 for SIE: the whole search one jitted program.

    pip install -e '.[test]'   # evosax
    python examples/tune_k1_k2.py

Each candidate (k1, k2) plays the same trials (``make_trials``: one key per generation, common
random numbers across the population); its cost is the mean fitness f (lower is better, as
evosax minimises). ``with_params`` clips what CMA-ES proposes into the network's valid ranges
(``NetworkParams.clip_valid``), so a negative k1 runs as 0, never as a negative constant.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from evosax.algorithms import CMA_ES

from jaxais import (
    EpisodeConfig,
    TrialsConfig,
    load_seed,
    make_system,
    make_trials,
    system_params,
    with_params,
)


def tune(generations: int = 20, population: int = 8, trials: int = 8, tau_cap: float = 500.0):
    """(the network with the tuned k1 and k2, the best cost per generation [generations])."""
    base = make_system("SIE", load_seed()[0])
    episode = EpisodeConfig(tau_cap=tau_cap)
    run = make_trials(TrialsConfig(world="world1", n_trials=trials, label="SIE", episode=episode))
    start = jax.tree.map(jnp.float32, system_params(base, ["k1", "k2"]))  # the paper's point
    es = CMA_ES(population_size=population, solution=start)
    params = es.default_params

    def cost(x, key):  # one candidate {"k1", "k2"}: its mean fitness over the trials
        return run(key, with_params(base, x))["fitness"].mean()

    def generation(state, key):
        k_ask, k_run, k_tell = jax.random.split(key, 3)
        xs, state = es.ask(k_ask, state, params)
        fitness = jax.vmap(cost, in_axes=(0, None))(xs, k_run)
        state, _ = es.tell(k_tell, xs, fitness, state, params)
        return state, fitness.min()

    @jax.jit
    def search(key):
        k_init, k_gens = jax.random.split(key)
        state = es.init(k_init, start, params)
        state, best = jax.lax.scan(generation, state, jax.random.split(k_gens, generations))
        return es.get_mean(state), best  # CMA-ES's estimate: its distribution's mean

    mean, history = search(jax.random.key(0))
    return with_params(base, mean).network, history


if __name__ == "__main__":
    network, history = tune()
    print(f"k1 {float(network.k1):.3f}, k2 {float(network.k2):.3f}; best f per generation:")
    print(jnp.round(history, 1))
