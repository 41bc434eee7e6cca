"""The five STL systems of the paper (SPEC 8) as :class:`~jaxais.controllers.System` data.

| code | sets | idiotypic | replacement |
|------|------|-----------|-------------|
| SIE  | LTL seed | yes | no |
| SRL  | LTL seed | no  | no |
| UIE  | random set R1 or R2 | yes | yes |
| URL  | random set R1 or R2 | no  | yes |
| HDC  | hand-designed, fixed, no learning | - | - |

The names (``SYSTEMS``, ``RANDOM_SETS``, ``LABELS``, :func:`label`, :func:`parse_label`) live in
:mod:`jaxais.labels`, which is free of JAX, and are re-exported here.
"""

from __future__ import annotations

import jax
import numpy as np

from jaxais.controllers import System
from jaxais.envs.struct import device_array
from jaxais.immune.antibodies import Antibodies, from_dicts, sample_antibodies
from jaxais.immune.network import NetworkParams, relative_fitness, seed_paratopes
from jaxais.immune.readings import DEFAULT, Readings
from jaxais.labels import LABELS, RANDOM_SETS, SYSTEMS, label, parse_label  # noqa: F401 (re-export)
from jaxais.seed import Seed

UNSEEDED_P = (0.25, 0.75)
"""Range of the unseeded systems' initial paratopes [paper]."""
N_SETS = 5

HAND_DESIGNED = [
    # [paper] The HDC "uses a simple random wander to search for the target, a backward turning
    # motion to escape collisions, and it steers the robot in the opposite direction of any
    # detected obstacles"; it names no tracking, so it wanders whether or not the target is seen
    # and finishes when the finish rule fires while it happens to face the target (SPEC 8).
    # Attributes [ours].
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


def random_sets(name: str, x: int = N_SETS) -> tuple[Antibodies, np.ndarray]:
    """A fixed random initial repertoire: [x, 8] antibodies and their initial P ~ U[0.25, 0.75]."""
    if name not in RANDOM_SETS:
        raise ValueError(f"unknown random set {name!r} (one of {', '.join(RANDOM_SETS)})")
    k_ab, k_p = jax.random.split(jax.random.key(RANDOM_SETS[name]))
    antibodies = sample_antibodies(k_ab, (x, 8))
    P = jax.random.uniform(k_p, (x * 8,), minval=UNSEEDED_P[0], maxval=UNSEEDED_P[1])
    return antibodies, np.asarray(P.reshape(x, 8))


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
    """Build one system.

    Args:
        name: SIE, SRL, UIE, URL or HDC (or a label such as ``UIE-R2``).
        seed: the LTL seed (needed by SIE and SRL).
        random_set: R1 or R2 (needed by UIE and URL).
        network: network constants (default: the paper's).
        readings: our readings of the paper's open points (default: ours,
            :data:`jaxais.immune.readings.DEFAULT`).
    """
    if "-" in name:
        name, random_set = parse_label(name)
    network = NetworkParams() if network is None else network
    if name in ("SIE", "SRL"):
        if seed is None:
            raise ValueError(f"{name} needs an LTL seed")
        antibodies = seed.antibodies
        P = _seeded_paratopes(seed.tau, seed.collisions, seed.L, network.rho, network.phi)
    elif name in ("UIE", "URL"):
        antibodies, P = random_sets(random_set or "")
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
