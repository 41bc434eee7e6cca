"""The five STL systems (SPEC 8) as :class:`~jaxais.controllers.System` data: SIE and SRL from
the LTL seed, UIE and URL from random set R1 or R2 (with replacement), the idiotypic ones SIE
and UIE; HDC hand-designed, without learning. Names from :mod:`jaxais.labels` (re-exported).

A System's parameters by name (:data:`PARAMETERS`, :data:`USED_BY`, :data:`FIXED`) are read
from the declarations of :class:`NetworkParams`' and :class:`Readings`' fields
(:func:`jaxais.immune.network.param`): a new one is a field, never an entry here.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from jaxais.controllers import System
from jaxais.envs.struct import device_array
from jaxais.immune.antibodies import Antibodies, from_dicts, sample_antibodies
from jaxais.immune.network import NetworkParams, Param, declared, relative_fitness, seed_paratopes
from jaxais.immune.readings import DEFAULT, Readings
from jaxais.io import check_type as _check
from jaxais.labels import LABELS, RANDOM_SETS, SYSTEMS, label, parse_label  # noqa: F401 (re-export)
from jaxais.seed import Seed, load_seed

UNSEEDED_P = (0.25, 0.75)  # [paper] the unseeded systems' initial paratopes' range
N_SETS = 5

FLAGS: dict[str, dict[str, bool]] = {
    name: {
        "seeded": name in ("SIE", "SRL"),  # from the LTL seed, eqs (1)-(2)
        "learning": name != "HDC",  # RL, eq (4) and penalties
        "idiotypic": name in ("SIE", "UIE"),  # selection stages 2-3, eqs (5)-(10)
        "replacement": name in ("UIE", "URL"),  # weak antibodies replaced
    }
    for name in SYSTEMS
}
"""What each system has [paper, SPEC 8]: :func:`make_system` builds from it, and a parameter's
users (:data:`USED_BY`) follow from it."""

MECHANISMS: dict[str, Callable[[Mapping[str, bool]], bool]] = {
    "every": lambda flags: True,  # bouts and penalty counts: a penalty ends HDC's bout too
    "seeding": lambda flags: flags["seeded"],
    "learning": lambda flags: flags["learning"],
    "idiotypic": lambda flags: flags["idiotypic"],
    "non_idiotypic": lambda flags: flags["learning"] and not flags["idiotypic"],
}
"""A parameter's mechanism (its declaration's ``mechanism``) -> does a system with these
:data:`FLAGS` use it."""

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
    flags = FLAGS[name]
    return System(
        antibodies=antibodies,
        paratopes=device_array(P, np.float32),
        learning=device_array(flags["learning"]),
        idiotypic=device_array(flags["idiotypic"]),
        replacement=device_array(flags["replacement"]),
        network=network,
        readings=DEFAULT if readings is None else readings,
    )


@functools.cache
def _declarations(
    network: type = NetworkParams, readings: type = Readings
) -> dict[str, tuple[str, Param]]:
    """Every declared parameter of a System with these parts: name -> (its part, declaration),
    in field order; ValueError on a name in both parts or an unknown mechanism."""
    out: dict[str, tuple[str, Param]] = {}
    for part, cls in (("network", network), ("readings", readings)):
        for name, declaration in declared(cls).items():
            if name in out:
                raise ValueError(f"parameter {name!r} is declared in both network and readings")
            if declaration.mechanism not in MECHANISMS:
                raise ValueError(
                    f"{cls.__name__}.{name}: unknown mechanism {declaration.mechanism!r} "
                    f"(one of {', '.join(MECHANISMS)})"
                )
            out[name] = (part, declaration)
    return out


def parameters(
    network: type = NetworkParams, readings: type = Readings
) -> dict[str, tuple[str, type]]:
    """The sweepable parameters of a System with these parts (a subclass adds its fields):
    name -> (the System field that holds it, its type), in field order."""
    declarations = _declarations(network, readings).items()
    return {name: (part, p.kind) for name, (part, p) in declarations if p.fixed is None}


def users(mechanism: str) -> tuple[str, ...]:
    """The systems (in :data:`SYSTEMS` order) that have ``mechanism``."""
    return tuple(name for name in SYSTEMS if MECHANISMS[mechanism](FLAGS[name]))


def used_by(network: type = NetworkParams, readings: type = Readings) -> dict[str, tuple[str, ...]]:
    """name -> the systems that use it, for each sweepable parameter that not all systems use."""
    declarations = _declarations(network, readings).items()
    out = {name: users(p.mechanism) for name, (_, p) in declarations if p.fixed is None}
    return {name: names for name, names in out.items() if names != SYSTEMS}


def fixed(network: type = NetworkParams, readings: type = Readings) -> dict[str, str]:
    """name -> why it is not a sweep's or an optimiser's variable (compiled in, or used before
    the trials start), for the declared parameters that are not."""
    declarations = _declarations(network, readings).items()
    return {name: p.fixed for name, (_, p) in declarations if p.fixed is not None}


PARAMETERS: dict[str, tuple[str, type]] = parameters()
"""A System's traced parameters (grid axes, an optimiser's variables): name -> (field, type)."""
USED_BY: dict[str, tuple[str, ...]] = used_by()
"""The systems that use a parameter, where not all do (a penalty ends HDC's bout too)."""
FIXED: dict[str, str] = fixed()
"""Parameters that look sweepable but are compiled in or act before the trials, and why."""


def system_params(system: System, names: Sequence[str] | None = None) -> dict[str, Any]:
    """``system``'s parameters ``names`` (default: all of :data:`PARAMETERS`, and a subclassed
    part's own) as name -> value."""
    known = _parameters_of(system)
    names = known if names is None else names
    _unknown(names, known)
    return {name: getattr(getattr(system, known[name][0]), name) for name in names}


def with_params(system: System, params: Mapping[str, Any]) -> System:
    """``system`` with ``params`` (:data:`PARAMETERS` name -> value), jit-safe: each value takes
    its leaf's dtype (the same program) and the network is clipped into its valid ranges (an
    optimiser never runs a negative k1)."""
    known = _parameters_of(system)
    _unknown(params, known)
    parts = {"network": {}, "readings": {}}
    for name, value in params.items():
        part = known[name][0]
        dtype = getattr(getattr(getattr(system, part), name), "dtype", None)
        if dtype is not None:  # traced values stay traced, host values on the host
            traced = isinstance(value, jax.Array)
            value = value.astype(dtype) if traced else np.asarray(value, dtype)
        parts[part][name] = value
    network = system.network.replace(**parts["network"]).clip_valid()
    return system.replace(network=network, readings=system.readings.replace(**parts["readings"]))


def _parameters_of(system: System) -> dict[str, tuple[str, type]]:
    """:func:`parameters` of ``system``'s own part classes."""
    return parameters(type(system.network), type(system.readings))


def _unknown(names: Any, known: Mapping[str, Any]) -> None:
    """ValueError naming the first name that is not a parameter name."""
    unknown = [name for name in names if name not in known]
    if unknown:
        raise ValueError(f"unknown parameter {unknown[0]!r} (one of {', '.join(known)})")
