"""The idiotypic immune network: equations (1)-(10) of Whitbrook et al. (SPEC section 7).

Each function is for one network of x sets by y antigens, pure and float32 with fixed shapes, so
callers vmap over robots, trials and grids. Readings decided here (SPEC 7 has the long form):

- Eq (1) uses ``rho`` where it prints 8 (the paper sets rho = 8).
- Eq (3): at most one idiotope per set, uniform among entries below their column mean.
- Eq (4) is not clipped; a column of mean 0 is left unchanged [ours: guard].
- Eqs (7)-(8) sum over the sets i != n of the stage-1 winner (section 4.3: alpha acts on "the
  other antibodies"); ``alpha_on_self=True`` keeps the earlier reading that also summed i = n.
- After eq (9), "using (1)" and "using (2)" are read as eqs (5) and (6); clones floored at 0 [ours].
- Ties in both selection stages are broken uniformly at random [ours].
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass, static_field


@pytree_dataclass
class NetworkParams:
    """Constants of the idiotypic network [paper, SPEC 7]: traced leaves (a batch of constants
    is one vmap) but for the static ``idiotope_period``. Build with :func:`network_params`, which
    validates (concrete values, outside jit); inside jit, :meth:`clip_valid` keeps proposed values
    in :data:`BOUNDS`.

    Attributes:
        b, k3: clone production and death rate of eq (5). k1, k2: eqs (7), (8).
        Phi: eq (6)'s scale. rho: eq (1)'s collision weight. phi: eq (2)'s scale.
        initial_clones: clones per antibody as the STL starts.
        penalty_idiotypic, penalty_non_idiotypic: paratope a penalty removes from the acting
            antibody, with and without idiotypic selection (SPEC 6).
        idiotope_period: iterations between idiotope redraws (eq 3).
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
        """``self`` once every range holds (elementwise; concrete values, not under jit).

        Raises:
            ValueError: one line naming the first bad field.
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
    """Paper constants with ``overrides``, validated (ValueError: unknown or bad field)."""
    unknown = sorted(set(overrides) - set(NetworkParams.__dataclass_fields__))
    if unknown:
        raise ValueError(f"unknown NetworkParams field(s): {', '.join(unknown)}")
    return NetworkParams(**overrides).validate()


def argmax_ties(values: jax.Array, u: jax.Array) -> jax.Array:
    """int32 index of the largest of ``values`` [x], exact ties won by the largest uniform of
    ``u`` [x], each equally likely [ours: ties]."""
    values = jnp.asarray(values)
    return jnp.argmax(jnp.where(values == jnp.max(values), u, -1.0)).astype(jnp.int32)


def relative_fitness(tau: jax.Array, collisions: jax.Array, rho: float = 8.0) -> jax.Array:
    """Eq (1): mu [x], each set's relative fitness from tau, collisions [x]; sums to 1.

    Every ``tau + rho * c`` must be positive.
    """
    cost = jnp.asarray(tau, jnp.float32) + rho * jnp.asarray(collisions, jnp.float32)
    # 1 / (cost_i * sum_k 1/cost_k), written as a normalised inverse cost.
    inverse = 1.0 / cost
    return inverse / jnp.sum(inverse)


def seed_paratopes(L: jax.Array, mu: jax.Array, phi: float = 20.0) -> jax.Array:
    """Eq (2): P [x, y] = L [x, y] (final RL scores) * mu [x] / phi, clipped to [0, 1]
    [ours: clip]."""
    L = jnp.asarray(L, jnp.float32)
    mu = jnp.asarray(mu, jnp.float32)
    return jnp.clip(L * mu[:, None] / phi, 0.0, 1.0)


def idiotopes(key: jax.Array, P: jax.Array) -> jax.Array:
    """Eq (3): I [x, y] of 0/1 from P [x, y]: each set one of its entries below their column
    mean, uniformly; a set without such entries none."""
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
    """Eq (4): P [x, y] with every column scaled back to its initial mean ``sigma0`` [y].

    Not clipped (the paper bounds only the scored antibody's P); a column of mean 0 is left
    unchanged [ours: guard].
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
    """Clone counts N [x, y] as the STL starts, all ``n0``."""
    return jnp.full((x, y), n0, jnp.float32)


def concentrations(N: jax.Array, Phi: float) -> jax.Array:
    """Eq (6): C [x, y] = Phi * N / sum(N); zeros when there are no clones (no NaN)."""
    N = jnp.asarray(N, jnp.float32)
    total = jnp.sum(N)
    return jnp.where(total > 0, Phi * N / jnp.where(total > 0, total, 1.0), 0.0)


def select_alpha(u: jax.Array, P: jax.Array, antigen: jax.Array | int) -> jax.Array:
    """Selection stage 1: alpha's set n (int32), the highest paratope P [x, y] for ``antigen``;
    ``u`` [x] breaks ties."""
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
    """Eqs (7)-(8): stimulation eps [x] and suppression delta [x] of each set by alpha's set n.

    eps_i = k1 * sum_j (1 - P_ij) I_nj C_ij C_nj and delta_i = k2 * sum_j P_nj I_ij C_ij C_nj
    for i != n, 0 for n unless ``alpha_on_self`` (traced). P, I, C [x, y]: C before the update.
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
    """Eq (9): S2 [x], S2_i = P_im + eps_i - delta_i, each set's stimulus for antigen m."""
    return jnp.asarray(P, jnp.float32)[:, antigen] + eps - delta


def update_clones(
    N: jax.Array, s2: jax.Array, antigen: jax.Array | int, b: float, k3: float
) -> jax.Array:
    """Eq (5) on column m of N [x, y]: N_im <- b * S2_i + N_im * (1 - k3), floored at 0 [ours:
    no negative clone counts for a suppressed antibody]."""
    N = jnp.asarray(N, jnp.float32)
    column = jnp.maximum(b * s2 + N[:, antigen] * (1.0 - k3), 0.0)
    # A one-hot column write, not a scatter: cheaper inside a batched loop.
    in_column = jnp.arange(N.shape[1]) == antigen
    return jnp.where(in_column[None, :], column[:, None], N)


def activation(N: jax.Array, s2: jax.Array, antigen: jax.Array | int, Phi: float) -> jax.Array:
    """Eq (10): lambda [x], lambda_i = C_im * S2_i with C (eq 6) of the updated clones."""
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
    """Three-stage idiotypic selection (eqs 5-10): alpha (stage 1), S2 and the antigen's clone
    column (eqs 5, 7-9), beta the highest activation (eq 10); alpha != beta is an idiotypic
    difference.

    Args:
        u: [2 * x] uniforms, stage 1's tie-breaks then stage 3's, sliced from the controller's
            one draw per iteration; ``u[:x]`` alone gives the same alphas as stage 1 alone.
        P, I, N: [x, y] paratopes, idiotopes, clone counts.

    Returns:
        alpha, beta (int32), and N [x, y] with column ``antigen`` updated.
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
