"""The GA's settings (:class:`GAConfig`) and their validation; imports no JAX, so a script can
check its flags before JAX starts."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Final

import numpy as np

__all__ = ["CROSSING_STARTS", "MAX_SEED", "ConfigError", "GAConfig"]

CROSSING_STARTS: Final = 50  # fresh starts per set measuring a seed's crossing rates [ours]
MAX_SEED: Final = 2**31 - 1  # the largest PRNG seed of a GA run


class ConfigError(ValueError):
    """A GA setting is out of range (one-line message; ``field`` names the setting)."""

    def __init__(self, field: str, message: str):
        super().__init__(f"{field} {message}")
        self.field = field
        self.reason = message


def _is_int(value: Any) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def _is_real(value: Any) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _setting(default: Any, help: str) -> Any:
    return field(default=default, metadata={"help": help})


@dataclass(frozen=True)
class GAConfig:
    """Static settings of a GA run (hashable: a static argument of the jitted core); each field's
    ``metadata["help"]`` is its flag's help.

    Defaults [ours] (SPEC 10, docs/seeds/seeds.md): ``generations`` 200, since 30 do not leave the
    start pocket; ``tau_cap`` 500 s, tracking sets cross in 35-200 s; ``starts`` 1, robustness
    coming from the checks; ``success_rate`` 0.95, at 0.9 sets crossing 75-85 % passed;
    ``crossover`` uniform, since the RL rule favours the parent that searched longer.

    ``crossover`` and ``mutation`` choose the default breeding operators
    (:func:`jaxais.ga.operators.default_operators`); operators passed in (``operators=`` of
    :func:`jaxais.ga.driver.run` and :func:`jaxais.experiments.evolution.evolve`) replace them.
    """

    populations: int = _setting(5, "independent populations P [paper: 5]")
    robots: int = _setting(10, "robots (antibody sets) per population R [paper: 10]")
    generations: int = _setting(200, "generation cap [ours: 200]")
    mutation: float = _setting(0.05, "per-gene probability of the default mutation [paper: 0.05]")
    elitism: int = _setting(1, "elite robots per population, copied unchanged [ours: 1]")
    target_f: float | None = _setting(None, "stop when every population's best f <= this")
    tau_cap: float = _setting(500.0, "time cap of one run, simulated s [ours: 500]")
    collision_cap: int = _setting(100, "collision cap of one run; reaching it ends the run [100]")
    starts: int = _setting(1, "random starts per robot and generation (f, τ, c, L: means) [1]")
    success_starts: int = _setting(10, "fresh starts checking each best, per generation [10]")
    success_rate: float | None = _setting(0.95, "stop when every best crosses this often (none)")
    crossover: str = _setting("uniform", "default crossover: uniform, or (rl) by the higher L_j")

    def __post_init__(self):
        def count(x: Any, low: int) -> bool:
            return _is_int(x) and x >= low

        def finite(x: Any, low: float, high: float) -> bool:
            return _is_real(x) and math.isfinite(x) and low <= x <= high

        R, f, r = self.robots, self.target_f, self.success_rate
        top = R - 1 if count(R, 2) else "robots - 1"
        checks = (
            ("populations", count(self.populations, 1), "an integer >= 1"),
            ("robots", count(R, 2), "an integer >= 2"),
            ("generations", count(self.generations, 1), "an integer >= 1"),
            ("mutation", finite(self.mutation, 0, 1), "a probability in [0, 1]"),
            ("elitism", count(self.elitism, 0) and count(R, 2) and self.elitism < R,
             f"an integer in [0, robots - 1] = [0, {top}]"),
            ("target_f", f is None or finite(f, 0, math.inf), "None or a finite number >= 0"),
            ("tau_cap", finite(self.tau_cap, 0, 1e6) and self.tau_cap > 0,
             "a finite number in (0, 1e6]"),
            ("collision_cap", count(self.collision_cap, 1), "an integer >= 1"),
            ("starts", count(self.starts, 1), "an integer >= 1"),
            ("success_starts", count(self.success_starts, 0), "an integer >= 0"),
            ("success_rate", r is None or (_is_real(r) and 0 < r <= 1),
             "None or a fraction in (0, 1]"),
            ("crossover", self.crossover in ("uniform", "rl"), "'uniform' or 'rl'"),
            ("success_starts", r is None or self.success_starts >= 1,
             ">= 1 when success_rate is set"),
        )  # fmt: skip
        for name, ok, what in checks:
            if not ok:
                raise ConfigError(name, f"must be {what}, got {getattr(self, name)!r}")

    def episode_config(self):
        """The task loop's :class:`jaxais.loop.EpisodeConfig` with the LTL caps."""
        from jaxais.loop import EpisodeConfig

        return EpisodeConfig(
            tau_cap=float(self.tau_cap),
            collision_cap=int(self.collision_cap),
            stop_at_collision_cap=True,  # the LTL caps (SPEC 10) end a run
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able values."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GAConfig:
        """Inverse of :meth:`to_dict` (unknown keys are an error)."""
        unknown = set(d) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f"unknown GA setting {sorted(unknown)[0]!r}")
        return cls(**d)
