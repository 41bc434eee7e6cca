"""The five STL systems (SPEC 8) as :class:`~jaxais.controllers.System` data: SIE and SRL from
the LTL seed, UIE and URL from random set R1 or R2 (with replacement), the idiotypic ones SIE
and UIE; HDC hand-designed, without learning. Names from :mod:`jaxais.labels` (re-exported)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from jaxais.controllers import System
from jaxais.envs.struct import device_array
from jaxais.immune.antibodies import Antibodies, from_dicts, sample_antibodies
from jaxais.immune.network import NetworkParams, relative_fitness, seed_paratopes
from jaxais.immune.readings import DEFAULT, Readings
from jaxais.io import check_type as _check
from jaxais.labels import LABELS, RANDOM_SETS, SYSTEMS, label, parse_label  # noqa: F401 (re-export)
from jaxais.seed import Seed, load_seed

UNSEEDED_P = (0.25, 0.75)  # [paper] the unseeded systems' initial paratopes' range
N_SETS = 5

HAND_DESIGNED = [
    # [paper] random wander, backward turn on collision, steer away from obstacles; no tracking:
    # it finishes when the finish rule fires while it faces the target (SPEC 8). Values [ours].

    {"antigen": "target unseen", "type": "wander both", "S": 350, "F": 15, "A": 60, "Rf": 18,
     "Ra": 60},
    {"antigen": "target seen", "type": "wander both", "S": 350, "F": 15, "A": 60, "Rf": 18,
     "Ra": 60},
    {"antigen": "obstacle right", "type": "forward turn", "S": 250, "A": 90, "D": "left"},
    {"antigen": "obstacle rear", "type": "forward turn", "S": 300, "A": 20, "D": "left"},
    {"antigen": "obstacle left", "type": "forward turn", "S": 250, "A": 90, "D": "right"},
    # Reversing with the right wheel slowed swings the front left, away from a right-hand hit.
    {"antigen": "collision right", "type": "reverse turn", "S": 300, "A": 60, "D": "right"},
    {"antigen": "collision rear", "type": "forward turn", "S": 300, "A": 40, "D": "left"},
    {"antigen": "collision left", "type": "reverse turn", "S": 300, "A": 60, "D": "left"},
]  # fmt: skip


def random_sets(name: str) -> tuple[Antibodies, np.ndarray]:
    """A fixed random initial repertoire: [5, 8] antibodies and their initial P ~ U[0.25, 0.75]."""
    if name not in RANDOM_SETS:
        raise ValueError(f"unknown random set {name!r} (one of {', '.join(RANDOM_SETS)})")
    k_ab, k_p = jax.random.split(jax.random.key(RANDOM_SETS[name]))
    antibodies = sample_antibodies(k_ab, (N_SETS, 8))
    P = jax.random.uniform(k_p, (N_SETS * 8,), minval=UNSEEDED_P[0], maxval=UNSEEDED_P[1])
    return antibodies, np.asarray(P.reshape(N_SETS, 8))


def hand_designed_sets(
    x: int = N_SETS, behaviours: list[dict] = HAND_DESIGNED
) -> tuple[Antibodies, np.ndarray]:
    """HDC as a network: every set holds ``behaviours``; set 0 alone has P = 1."""
    one = from_dicts(behaviours)
    antibodies = jax.tree.map(lambda a: np.stack([np.asarray(a)] * x), one)
    P = np.zeros((x, 8), np.float32)
    P[0] = 1.0
    return antibodies, P


@jax.jit
def _seeded_paratopes(tau, collisions, L, rho, phi):
    """Eqs (1)-(2) as one compiled program (rather than op by op at every script's start)."""
    return seed_paratopes(L, relative_fitness(tau, collisions, rho), phi)


def make_system(
    name: str,
    seed: Seed | None = None,
    random_set: str | None = None,
    network: NetworkParams | None = None,
    readings: Readings | None = None,
) -> System:
    """One system by ``name`` (or a label, ``UIE-R2``): SIE and SRL need ``seed`` (a Seed or
    its directory), UIE and URL ``random_set``; ``network``, ``readings``: default the paper's
    and ours. A bad argument: a one-line ValueError."""
    _check(name, str, "make_system's name", f"one of {', '.join(LABELS)}")
    if "-" in name:
        name, random_set = parse_label(name)
    if isinstance(seed, str | Path):
        seed = load_seed(seed)[0]
    _check(seed, Seed | None, "seed", "a Seed (load_seed()[0]), a seed directory or None")
    _check(network, NetworkParams | None, "network", "a NetworkParams or None")
    _check(readings, Readings | None, "readings", "a Readings (immune.readings.readings())")
    network = NetworkParams() if network is None else network.validate()
    if name in ("SIE", "SRL"):
        if seed is None:
            raise ValueError(f"{name} needs an LTL seed: make_system({name!r}, load_seed()[0])")
        antibodies = seed.antibodies
        P = _seeded_paratopes(seed.tau, seed.collisions, seed.L, network.rho, network.phi)
    elif name in ("UIE", "URL"):
        if random_set is None:
            raise ValueError(f"{name} needs a random set: make_system({name + '-R1'!r}) or R2")
        antibodies, P = random_sets(random_set)
    elif name == "HDC":
        antibodies, P = hand_designed_sets()
    else:
        raise ValueError(f"unknown system {name!r} (one of {', '.join(SYSTEMS)})")
    antibodies = jax.tree.map(device_array, antibodies)
    return System(
        antibodies=antibodies,
        paratopes=device_array(P, np.float32),
        learning=device_array(name != "HDC"),
        idiotypic=device_array(name in ("SIE", "UIE")),
        replacement=device_array(name in ("UIE", "URL")),
        network=network,
        readings=DEFAULT if readings is None else readings,
    )


# A System's traced parameters (grid axes, an optimiser's variables): name -> (field, type).
PARAMETERS: dict[str, tuple[str, type]] = {
    **dict.fromkeys(("k1", "k2", "k3", "b", "Phi", "initial_clones", "penalty_idiotypic",
                     "penalty_non_idiotypic"), ("network", float)),
    "hold": ("readings", int), "encounter_gap": ("readings", int),
    "sigma0_floor": ("readings", float), "alpha_on_self": ("readings", bool),
}  # fmt: skip


def system_params(system: System, names: Sequence[str] | None = None) -> dict[str, Any]:
    """``system``'s parameters ``names`` (default: all of :data:`PARAMETERS`) as name -> value."""
    names = PARAMETERS if names is None else names
    _unknown(names)
    return {name: getattr(getattr(system, PARAMETERS[name][0]), name) for name in names}


def with_params(system: System, params: Mapping[str, Any]) -> System:
    """``system`` with ``params`` (:data:`PARAMETERS` name -> value), jit-safe: each value takes
    its leaf's dtype (the same program) and the network is clipped into its valid ranges (an
    optimiser never runs a negative k1)."""
    _unknown(params)
    parts = {"network": {}, "readings": {}}
    for name, value in params.items():
        part = PARAMETERS[name][0]
        dtype = getattr(getattr(getattr(system, part), name), "dtype", None)
        if dtype is not None:  # traced values stay traced, host values on the host
            traced = isinstance(value, jax.Array)
            value = value.astype(dtype) if traced else np.asarray(value, dtype)
        parts[part][name] = value
    network = system.network.replace(**parts["network"]).clip_valid()
    return system.replace(network=network, readings=system.readings.replace(**parts["readings"]))


def _unknown(names: Any) -> None:
    """ValueError naming the first name that is not a :data:`PARAMETERS` name."""
    unknown = [name for name in names if name not in PARAMETERS]
    if unknown:
        raise ValueError(f"unknown parameter {unknown[0]!r} (one of {', '.join(PARAMETERS)})")
