"""The neural baseline's training settings (free of JAX: scripts check flags before JAX starts).

See :mod:`jaxais.baselines.neural` for what they drive.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

BUILTIN_WORLDS = ("ga_maze", "world1", "world2", "real")
"""The simulator's built-in worlds (``envs.BUILTIN_WORLDS``, named here without loading JAX)."""
NN_LABEL = "NN"
"""The trained controller's label in trial sets and reports (it names its trials' random
stream, :func:`jaxais.trials.batch_keys`)."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """What :func:`make_train` compiles in (static: it fixes shapes and loop lengths).

    Defaults [ours]: 156 M simulated robot-steps, 5-10 minutes on this project's shared 2-core
    CPU (284-580 s measured, docs/baseline.md). A pilot run with these settings was the only
    one evaluated in the test worlds before they were fixed; a second pilot with
    ``collision_penalty=4`` stalled in the training world (the robots learnt to stand still)
    and was stopped there.

    Attributes:
        world: the training world [ours: ga_maze, the paper's LTL world].
        generations: ES updates.
        pairs: antithetic pairs per generation (population 2 x pairs).
        episodes: episodes per member per generation (shared by all members).
        steps: steps per episode (32 ms each).
        sigma: perturbation scale in weight space.
        learning_rate: adam's step size.
        hidden: hidden units of the MLP.
        weight_decay: decoupled L2 decay of the weights per update (adamw).
        collision_penalty: the environment's reward per collision (``EnvParams``; its
            default is 1.0).
    """

    world: str = "ga_maze"
    generations: int = 200
    pairs: int = 32
    episodes: int = 4
    steps: int = 3000
    sigma: float = 0.1
    learning_rate: float = 0.03
    hidden: int = 16
    weight_decay: float = 0.0
    collision_penalty: float = 1.0

    def __post_init__(self):
        if self.world not in BUILTIN_WORLDS and not Path(self.world).is_file():
            raise ValueError(f"world: no built-in world or file {self.world!r}")
        for name in ("generations", "pairs", "episodes", "steps", "hidden"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        for name in ("sigma", "learning_rate"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        for name in ("weight_decay", "collision_penalty"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {value!r}")

    @property
    def population(self) -> int:
        return 2 * self.pairs
