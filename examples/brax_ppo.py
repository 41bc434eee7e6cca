"""brax's PPO, unmodified, on a jaxais world (``pip install 'jaxais[brax]'``).

    python examples/brax_ppo.py            # a tiny run: about 3 CPU minutes, nearly all compiling
    python examples/brax_ppo.py 2000000    # a real one: more env steps

Prints one line per evaluation: the mean episode's reward, counted collisions and approach to
the goal (m), as brax's evaluator sums jaxais's per-step metrics.
"""

import functools
import sys

from brax.training.agents.ppo import networks
from brax.training.agents.ppo import train as ppo

from jaxais.envs.brax import BraxEnv


def report(step: int, metrics: dict) -> None:
    print(
        f"{step:>9} steps: reward {float(metrics['eval/episode_reward']):7.3f}  "
        f"collisions {float(metrics['eval/episode_collision']):5.2f}  "
        f"approach {float(metrics['eval/episode_progress']):6.3f} m"
    )


def main(num_timesteps: int = 4096) -> None:
    ppo.train(
        BraxEnv("world1"),
        num_timesteps=num_timesteps,
        episode_length=64 if num_timesteps < 100_000 else 2000,
        num_envs=8,
        batch_size=8,
        num_minibatches=4,
        unroll_length=16,
        num_updates_per_batch=2,
        # brax compiles its evaluator anew for each of the first three evaluations (the states'
        # shardings change): a tiny run evaluates at its start and end only.
        num_evals=2 if num_timesteps < 100_000 else 10,
        num_eval_envs=8,
        num_resets_per_eval=1,  # fresh placements (and placement pools) between evaluations
        network_factory=functools.partial(
            networks.make_ppo_networks,
            policy_hidden_layer_sizes=(32, 32),
            value_hidden_layer_sizes=(32, 32),
        ),
        seed=0,
        progress_fn=report,
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 4096)
