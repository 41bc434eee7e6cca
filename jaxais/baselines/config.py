"""The neural baseline's training settings (free of JAX: scripts check flags before JAX starts)."""

from __future__ import annotations

import dataclasses
import math

from jaxais.io import python_scalars
from jaxais.labels import world_names_module

NN_LABEL = "NN"  # the trained controller's label in records; it names its trials' random stream


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """What :func:`~jaxais.baselines.neural.make_train` compiles in (static). Defaults [ours]:
    156 M robot-steps, 5-10 min on a 2-core CPU (docs/baseline.md has the pilots).

    Attributes:
        world: the training world, a name (built-in or on ``JAXAIS_WORLDS``) or a file's path
            [ours: ga_maze, the paper's LTL world].
        generations: ES updates. pairs: antithetic pairs (population 2 x pairs).
        episodes: per member and generation (shared by all). steps: per episode (32 ms each).
        sigma: perturbation scale. learning_rate: adam's. hidden: the MLP's hidden units.
        weight_decay: adamw's decoupled decay. collision_penalty: reward per collision.
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
        python_scalars(self)
        try:
            world_names_module().resolve(self.world)
        except ValueError as err:  # WorldError, one line
            raise ValueError(f"world: {err}") from None
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
