"""A variant of the network's eqs (7)-(8), run as a contender beside the paper's systems.

    python examples/network_variant.py --tiny          # a few short trials, seconds
    python examples/network_variant.py --trials 30     # world1, the paper's 4000 s cap

The variant: saturating interactions. The paper's stimulation and suppression are bilinear in
the two concentrations, so one antibody whose clones dominate (C of several units, against a
mean of Phi / 40 = 0.625) can stimulate or suppress the others without limit. Here each product
``z = C_ij * C_nj`` passes through ``z / (1 + z / K)``: within 10 % of ``z`` for typical pairs
(z about 0.4, K = 4), never above K for a dominant one. Everything else is the paper's:

    eps_i   = k1 * sum_j (1 - P_ij) I_nj s(C_ij C_nj)      s(z) = z / (1 + z / K)
    delta_i = k2 * sum_j P_nj I_ij s(C_ij C_nj)

K is the variant's own constant: a field of a :class:`NetworkParams` subclass, declared with
``param`` (range, help, mechanism), so the system validates, clips and sweeps it like k1.
Nothing in the library changes; ``contender()`` is what ``reproduce.py --contender
examples/network_variant.py:contender`` runs.
"""

from __future__ import annotations

import argparse

import jax.numpy as jnp
import numpy as np

from jaxais import (
    EpisodeConfig,
    NetworkParams,
    envs,
    load_seed,
    make_system,
    run_trials,
    stl_controller,
)
from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.network import acted_on, param


@pytree_dataclass
class SaturatingParams(NetworkParams):
    """The paper's constants and the variant's saturation scale K."""

    K: float = param(4.0, bound=(1e-6, np.inf), mechanism="idiotypic",
                     help="the concentration product at which s(z) is half of z")  # fmt: skip


def saturating(P, I, C, n, params, alpha_on_self=False):
    """Eqs (7)-(8) with saturating products: (eps [x], delta [x]) of alpha's set n on each set
    (P, I, C [x, y]; C before eq 5's update), 0 for the sets alpha does not act on."""
    z = C * C[n]  # [x, y] the paper's concentration products
    s = z / (1.0 + z / params.K)
    eps = params.k1 * jnp.sum((1.0 - P) * I[n] * s, axis=1)
    delta = params.k2 * jnp.sum(P[n] * I * s, axis=1)
    on = acted_on(P.shape[0], n, alpha_on_self)
    return jnp.where(on, eps, 0.0), jnp.where(on, delta, 0.0)


CONTROLLER = stl_controller(interaction=saturating)  # built once: compiled programs are cached


def contender(seed=None):
    """(controller, params): SIE's seeded network, selecting with the saturating eqs (7)-(8).
    ``seed``: an LTL seed or its directory (default: the shipped one)."""
    seed = load_seed()[0] if seed is None else seed
    return CONTROLLER, make_system("SIE", seed, network=SaturatingParams())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tiny", action="store_true", help="2 trials capped at 10 s (a check)")
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--world", default="world1")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    n, config = args.trials, EpisodeConfig()
    if args.tiny:
        n, config = 2, EpisodeConfig(tau_cap=10.0, segment=500)
    controller, system = contender()
    world = envs.load_world(args.world)
    trials = run_trials(world, {"SIEV": system}, n, args.seed, config, controller=controller)
    records = trials["SIEV"].records
    tau = np.mean([r["tau"] for r in records])
    rate = np.nanmean([r["idiotypic_difference_rate"] for r in records])
    print(f"SIEV (saturating eqs 7-8, K = {system.network.K}): {n} trials in {args.world}, "
          f"mean tau {tau:.1f} s, idiotypic difference rate {100 * rate:.1f} %")  # fmt: skip


if __name__ == "__main__":
    main()
