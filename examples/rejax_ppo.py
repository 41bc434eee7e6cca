"""rejax's PPO trained on jaxais's gymnax environment, rejax's code as it ships.

rejax makes an environment from a name only for gymnax's own names and its ``brax/``,
``navix/``... prefixes, so ours is made by ``gymnax.make("jaxais/world1")`` and handed to rejax as
an object with its parameters (rejax's documented alternative). rejax 0.1.3 steps environments
through the five-value ``step`` that gymnax 1.0 replaced, so the env is made with
``legacy_step=True`` (gymnax's ``LegacyStepAPIWrapper`` cannot be deep-copied, which rejax does).
Training and rejax's periodic evaluations (128 episodes each) are one jitted program::

    python examples/rejax_ppo.py          # CONFIG: 2^17 steps of 16 envs
    python examples/rejax_ppo.py --tiny   # TINY: 128 steps of 4 envs, what the tests run
"""

from __future__ import annotations

import sys
from typing import Any

import gymnax
import jax
import numpy as np
from rejax import PPO

from jaxais import envs

CONFIG = {
    "total_timesteps": 2**17,
    "eval_freq": 2**14,
    "num_envs": 16,
    "num_steps": 128,
    "num_epochs": 4,
    "num_minibatches": 8,
    "episode_length": 500,
    "hidden": (64, 64),
}
TINY = {
    "total_timesteps": 128,
    "eval_freq": 64,
    "num_envs": 4,
    "num_steps": 16,
    "num_epochs": 1,
    "num_minibatches": 2,
    "episode_length": 16,
    "hidden": (8,),
}


def main(config: dict[str, Any], seed: int = 0) -> dict[str, float]:
    """Train with ``config``; returns and prints the evaluations' first and last mean return."""
    envs.register_gymnax()
    env, params = gymnax.make(
        "jaxais/world1", legacy_step=True, max_steps_in_episode=config["episode_length"]
    )
    algo = PPO.create(
        env=env,
        env_params=params,
        agent_kwargs={"hidden_layer_sizes": config["hidden"]},
        **{k: config[k] for k in CONFIG if k not in ("episode_length", "hidden")},
    )
    _, (lengths, returns) = jax.jit(PPO.train)(algo, jax.random.key(seed))
    mean_returns = np.asarray(returns).mean(axis=-1)  # [evaluations]
    summary = {"first": float(mean_returns[0]), "last": float(mean_returns[-1])}
    print(
        f"rejax PPO on world1: {len(mean_returns)} evaluations, mean return "
        f"{summary['first']:.4g} -> {summary['last']:.4g}"
    )
    return summary


if __name__ == "__main__":
    main(CONFIG | TINY if "--tiny" in sys.argv[1:] else CONFIG)
