"""The idiotypic immune network: equations (1)-(10) of Whitbrook et al. (SPEC section 7).

Every function is written for one network of ``x`` antibody sets by ``y`` antigens (5 x 8 in the
paper, never assumed here): pure, float32, fixed shapes, explicit PRNG keys (the selection stages
take the caller's uniforms), no Python branching on traced values, so callers batch robots,
trials and parameter grids with ``vmap``.

Readings of the paper decided here:

- Eq (1) prints ``8 c_k`` in the sum; ``rho`` is used in both places (the paper sets rho = 8).
- Eq (3): a set gets at most one idiotope, drawn uniformly among the entries strictly below their
  column mean; a set with no such entry gets none.
- Eq (4) is not clipped (the paper clips only the scored antibody's P, in RL), and a column whose
  current mean is 0 is left unchanged [ours: guard].
- Eqs (7)-(8) sum over the antigens j of every other set i != n against the stage-1 winner's
  set n, as section 4.3 says: "comparing the idiotope of alpha with the paratopes of the other
  antibodies ... and comparing the paratope of alpha with the idiotopes of the others";
  stimulation pairs the idiotope of alpha (I_nj) with each set's paratopes (1 - P_ij),
  suppression the paratope of alpha (P_nj) with each set's idiotopes (I_ij), and alpha's own
  eps and delta are 0, so its S2 is its P. ``alpha_on_self=True`` keeps the engine's earlier
  reading, which summed i = n too (:data:`jaxais.immune.readings.ALPHA_ON_SELF` says what it
  does). Concentrations are taken before the clone update.
- The text after eq (9) says clones are updated "using (1)" and concentrations "using (2)"; these
  are read as eqs (5) and (6). Eq (5) uses S2 and touches only the antigen's column; clone counts
  are floored at 0 [ours].
- Ties in both selection stages are broken uniformly at random [ours].
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass, static_field

__all__ = [
    "BOUNDS",
    "NetworkParams",
    "activation",
    "argmax_ties",
    "concentrations",
    "idiotopes",
    "idiotypic_select",
    "initial_clones",
    "network_params",
    "relative_fitness",
    "rescale_paratopes",
    "seed_paratopes",
    "select_alpha",
    "stage2_stimulus",
    "stimulation_suppression",
    "update_clones",
]


@pytree_dataclass
class NetworkParams:
    """Constants of the idiotypic network [paper, SPEC section 7].

    The float constants are pytree leaves, so a batch of networks with different constants is one
    ``vmap``. ``idiotope_period`` is static: it is a loop schedule, fixed at trace time.
    Build with :func:`network_params`, which validates; ``validate`` needs concrete values, so call
    it outside ``jit``; inside, ``clip_valid`` keeps proposed values in range.

    Attributes:
        b: clone-production scale of eq (5).
        k1: stimulation magnitude of eq (7).
        k2: suppression magnitude of eq (8).
        k3: death rate of eq (5), in [0, 1].
        Phi: concentration scale of eq (6), > 0.
        rho: weight of collisions against completion time in eq (1).
        phi: paratope scale of eq (2), > 0.
        initial_clones: clones per antibody at the start of the STL phase.
        penalty_idiotypic, penalty_non_idiotypic: paratope removed from the acting antibody by
            a penalty with and without idiotypic selection (SPEC 6).
        idiotope_period: iterations between idiotope recomputations (eq 3), >= 1.
    """

    b: float = 100.0
    k1: float = 0.85
    k2: float = 1.10
    k3: float = 0.0
    Phi: float = 25.0
    rho: float = 8.0
    phi: float = 20.0
    initial_clones: float = 1000.0
    penalty_idiotypic: float = 0.5
    penalty_non_idiotypic: float = 1.0
    idiotope_period: int = static_field(default=120)

    def validate(self) -> NetworkParams:
        """Check every constant's range (batched leaves are checked elementwise).

        Returns:
            ``self``, so construction can be chained.

        Raises:
            ValueError: a one-line message naming the first bad field.
        """
        for name, (low, high) in BOUNDS.items():
            try:
                value = np.asarray(getattr(self, name), dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(
                    f"NetworkParams.{name} must be a number, got {getattr(self, name)!r:.40}"
                ) from None
            if not np.all((value >= low) & (value <= high)):  # NaN fails too
                rule = "> 0" if low == _POSITIVE else f">= {low:g}"
                rule = f"in [{low:g}, {high:g}]" if high < np.inf else rule
                raise ValueError(f"NetworkParams.{name} must be {rule}, got {value}")
        period = self.idiotope_period
        if isinstance(period, bool) or not isinstance(period, int | np.integer) or period < 1:
            raise ValueError(f"NetworkParams.idiotope_period must be an int >= 1, got {period!r}")
        return self

    def clip_valid(self) -> NetworkParams:
        """A copy with each float constant clipped into :data:`BOUNDS`: jit-safe, for values an
        optimiser proposes (NaN stays NaN); host values stay on the host."""
        clip = lambda v, lo, hi: (jnp if isinstance(v, jax.Array) else np).clip(v, lo, hi)
        return self.replace(**{k: clip(getattr(self, k), *BOUNDS[k]) for k in BOUNDS})


_POSITIVE = float(np.finfo(np.float32).tiny)  # "> 0" as a closed bound
BOUNDS: dict[str, tuple[float, float]] = {
    "b": (0.0, np.inf),
    "k1": (0.0, np.inf),
    "k2": (0.0, np.inf),
    "k3": (0.0, 1.0),
    "Phi": (_POSITIVE, np.inf),
    "rho": (0.0, np.inf),
    "phi": (_POSITIVE, np.inf),
    "initial_clones": (_POSITIVE, np.inf),
    "penalty_idiotypic": (0.0, np.inf),
    "penalty_non_idiotypic": (0.0, np.inf),
}
"""Each float constant's valid range [low, high] (float32's smallest normal number for "> 0"):
what ``validate`` checks, ``clip_valid`` clips to, and an optimiser may read."""


def network_params(**overrides: float | int) -> NetworkParams:
    """Paper constants with ``overrides`` applied, validated.

    Raises:
        ValueError: an unknown field name or an out-of-range value.
    """
    unknown = sorted(set(overrides) - set(NetworkParams.__dataclass_fields__))
    if unknown:
        raise ValueError(f"unknown NetworkParams field(s): {', '.join(unknown)}")
    return NetworkParams(**overrides).validate()


def argmax_ties(values: jax.Array, u: jax.Array) -> jax.Array:
    """Index of the largest of ``values`` [x]; among exact ties, the one with the largest of the
    i.i.d. uniforms ``u`` [x], so each tied index is equally likely to win [ours: ties].

    Returns:
        int32 scalar index.
    """
    values = jnp.asarray(values)
    return jnp.argmax(jnp.where(values == jnp.max(values), u, -1.0)).astype(jnp.int32)


def relative_fitness(tau: jax.Array, collisions: jax.Array, rho: float = 8.0) -> jax.Array:
    """Eq (1): relative fitness of each evolved set; sums to 1, lower cost gives higher mu.

    Args:
        tau: [x] task completion times (must make every ``tau + rho * c`` positive).
        collisions: [x] collision counts.
        rho: collision weight.

    Returns:
        mu: [x] float32.
    """
    cost = jnp.asarray(tau, jnp.float32) + rho * jnp.asarray(collisions, jnp.float32)
    # 1 / (cost_i * sum_k 1/cost_k), written as a normalised inverse cost.
    inverse = 1.0 / cost
    return inverse / jnp.sum(inverse)


def seed_paratopes(L: jax.Array, mu: jax.Array, phi: float = 20.0) -> jax.Array:
    """Eq (2): seeded paratopes P = L * mu / phi, clipped to [0, 1] [ours: clip].

    Args:
        L: [x, y] final RL scores of the evolved antibodies.
        mu: [x] relative fitness of each set (eq 1).
        phi: scale (the largest L * mu is about 20).

    Returns:
        P: [x, y] float32.
    """
    L = jnp.asarray(L, jnp.float32)
    mu = jnp.asarray(mu, jnp.float32)
    return jnp.clip(L * mu[:, None] / phi, 0.0, 1.0)


def idiotopes(key: jax.Array, P: jax.Array) -> jax.Array:
    """Eq (3): idiotope matrix, at most one 1 per set.

    Entries strictly below their column (antigen) mean are candidates; each set keeps one of its
    candidates, chosen uniformly at random, and a set without candidates keeps none.

    Args:
        key: PRNG key.
        P: [x, y] paratopes.

    Returns:
        I: [x, y] float32 of 0.0 / 1.0.
    """
    P = jnp.asarray(P, jnp.float32)
    # Drawn flat and reshaped: same i.i.d. scores, and XLA compiles a 1-D threefry about twice
    # as fast as a 2-D one on CPU.
    u = jax.random.uniform(key, (P.size,))
    sigma = jnp.mean(P, axis=0)
    # No entry equal to its column's maximum is below the exact mean; this second test stops
    # float rounding of the mean from making every entry of a constant column a candidate.
    candidate = (sigma > P) & (jnp.max(P, axis=0) > P)
    scores = jnp.where(candidate, jnp.reshape(u, P.shape), -1.0)
    chosen = jax.nn.one_hot(jnp.argmax(scores, axis=1), P.shape[1], dtype=jnp.float32)
    return chosen * jnp.any(candidate, axis=1, keepdims=True)


def rescale_paratopes(P: jax.Array, sigma0: jax.Array) -> jax.Array:
    """Eq (4): scale every column back to its initial mean.

    Not clipped: the paper bounds only the scored antibody's P (in RL), so a rescaled value may
    leave [0, 1]. A column whose current mean is 0 cannot be rescaled and is returned unchanged
    [ours: guard].

    Args:
        P: [x, y] paratopes after RL.
        sigma0: [y] initial column means.

    Returns:
        P: [x, y] float32.
    """
    P = jnp.asarray(P, jnp.float32)
    sigma = jnp.mean(P, axis=0)
    positive = sigma > 0
    # The inner where keeps the division finite so neither the value nor its gradient is NaN.
    scale = jnp.where(
        positive, jnp.asarray(sigma0, jnp.float32) / jnp.where(positive, sigma, 1.0), 1.0
    )
    return P * scale


def initial_clones(x: int, y: int, n0: float = 1000.0) -> jax.Array:
    """Clone counts at the start of the STL phase.

    Args:
        x: number of sets (static). y: number of antigens (static). n0: clones per antibody.

    Returns:
        N: [x, y] float32, all ``n0``.
    """
    return jnp.full((x, y), n0, jnp.float32)


def concentrations(N: jax.Array, Phi: float) -> jax.Array:
    """Eq (6): C = Phi * N / sum(N); all zeros if there are no clones at all (no NaN).

    Args:
        N: [x, y] clone counts.
        Phi: scale; the concentrations sum to Phi.

    Returns:
        C: [x, y] float32.
    """
    N = jnp.asarray(N, jnp.float32)
    total = jnp.sum(N)
    return jnp.where(total > 0, Phi * N / jnp.where(total > 0, total, 1.0), 0.0)


def select_alpha(u: jax.Array, P: jax.Array, antigen: jax.Array | int) -> jax.Array:
    """Selection stage 1: the set whose antibody for ``antigen`` has the highest paratope.

    Args:
        u: [x] i.i.d. uniforms that break ties (the caller's draw, see :func:`idiotypic_select`).
        P: [x, y] paratopes.
        antigen: index m of the presenting antigen.

    Returns:
        n: int32 set index of alpha = A_nm.
    """
    return argmax_ties(jnp.asarray(P, jnp.float32)[:, antigen], u)


def stimulation_suppression(
    P: jax.Array,
    I: jax.Array,
    C: jax.Array,
    n: jax.Array | int,
    k1: float,
    k2: float,
    alpha_on_self: jax.Array | bool = False,
) -> tuple[jax.Array, jax.Array]:
    """Eqs (7)-(8): how much alpha's set ``n`` stimulates and suppresses each other set.

    eps_i = k1 * sum_j (1 - P_ij) I_nj C_ij C_nj   (idiotope of alpha vs paratopes of set i)
    delta_i = k2 * sum_j P_nj I_ij C_ij C_nj       (paratope of alpha vs idiotopes of set i)

    for i != n; eps_n = delta_n = 0 (section 4.3: alpha acts on "the other antibodies").

    Args:
        P: [x, y] paratopes. I: [x, y] idiotopes. C: [x, y] concentrations before the update.
        n: set index of the stage-1 winner alpha.
        k1: stimulation magnitude. k2: suppression magnitude.
        alpha_on_self: also sum i = n (the engine's earlier reading; traced, so a batch may mix).

    Returns:
        eps: [x] float32, delta: [x] float32.
    """
    P = jnp.asarray(P, jnp.float32)
    I = jnp.asarray(I, jnp.float32)
    C = jnp.asarray(C, jnp.float32)
    acted_on = (jnp.arange(P.shape[0]) != n) | alpha_on_self
    eps = k1 * jnp.sum((1.0 - P) * I[n] * C * C[n], axis=1)
    delta = k2 * jnp.sum(P[n] * I * C * C[n], axis=1)
    return jnp.where(acted_on, eps, 0.0), jnp.where(acted_on, delta, 0.0)


def stage2_stimulus(
    P: jax.Array, eps: jax.Array, delta: jax.Array, antigen: jax.Array | int
) -> jax.Array:
    """Eq (9): S2_i = P_im + eps_i - delta_i, each set's stimulus for antigen m.

    Returns:
        S2: [x] float32.
    """
    return jnp.asarray(P, jnp.float32)[:, antigen] + eps - delta


def update_clones(
    N: jax.Array, s2: jax.Array, antigen: jax.Array | int, b: float, k3: float
) -> jax.Array:
    """Eq (5) for the presenting antigen's column: N_im <- b * S2_i + N_im * (1 - k3), floored
    at 0 [ours: a strongly suppressed antibody would otherwise get a negative clone count].

    Args:
        N: [x, y] clone counts. s2: [x] stimuli (eq 9). antigen: column m.
        b: stimulus-to-clones scale. k3: death rate.

    Returns:
        N: [x, y] float32; only column ``antigen`` differs.
    """
    N = jnp.asarray(N, jnp.float32)
    column = jnp.maximum(b * s2 + N[:, antigen] * (1.0 - k3), 0.0)
    # A one-hot column write, not a scatter: cheaper inside a batched loop.
    in_column = jnp.arange(N.shape[1]) == antigen
    return jnp.where(in_column[None, :], column[:, None], N)


def activation(N: jax.Array, s2: jax.Array, antigen: jax.Array | int, Phi: float) -> jax.Array:
    """Eq (10): lambda_i = C_im * S2_i, with C the concentrations (eq 6) of the updated clones.

    Returns:
        lambda: [x] float32.
    """
    return concentrations(N, Phi)[:, antigen] * s2


def idiotypic_select(
    u: jax.Array,
    P: jax.Array,
    I: jax.Array,
    N: jax.Array,
    antigen: jax.Array | int,
    params: NetworkParams,
    alpha_on_self: jax.Array | bool = False,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Three-stage idiotypic selection (eqs 5-10) for the presenting antigen.

    Stage 1 picks alpha (:func:`select_alpha`). Stage 2 computes every set's stimulus S2 (eq 9,
    with eqs 7-8; alpha's own S2 = P_nm) and updates the antigen's column of clones (eq 5).
    Stage 3 picks beta, the set with the highest activation (eq 10). An idiotypic difference is
    alpha != beta.

    Args:
        u: [2 * x] i.i.d. uniforms: stage 1's tie-breaks, then stage 3's. The controller slices
            them from the one draw it makes per iteration (a key per function would change every
            random stream); ``u[:x]`` is :func:`select_alpha`'s, so a batch without idiotypic
            systems, which runs stage 1 alone, picks the same alphas.
        P: [x, y] paratopes. I: [x, y] idiotopes. N: [x, y] clone counts.
        antigen: index m of the presenting antigen.
        params: network constants (b, k1, k2, k3, Phi are used).
        alpha_on_self: eqs (7)-(8) also sum alpha's own set (:func:`stimulation_suppression`).

    Returns:
        alpha: int32 set index of the stage-1 winner.
        beta: int32 set index of the stage-3 winner, the antibody that acts.
        N_new: [x, y] float32 clone counts; only column ``antigen`` differs from ``N``.
    """
    P = jnp.asarray(P, jnp.float32)
    N = jnp.asarray(N, jnp.float32)
    x = P.shape[0]
    alpha = select_alpha(u[:x], P, antigen)
    eps, delta = stimulation_suppression(
        P, I, concentrations(N, params.Phi), alpha, params.k1, params.k2, alpha_on_self
    )
    s2 = stage2_stimulus(P, eps, delta, antigen)
    N_new = update_clones(N, s2, antigen, params.b, params.k3)
    beta = argmax_ties(activation(N_new, s2, antigen, params.Phi), u[x:])
    return alpha, beta, N_new
