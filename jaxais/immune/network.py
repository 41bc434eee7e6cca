"""The idiotypic immune network: equations (1)-(10) of Whitbrook et al. (SPEC section 7).

Each function is for one network of x sets by y antigens, pure and float32 with fixed shapes, so
callers vmap over robots, trials and grids. Readings decided here (SPEC 7 has the long form):

- Eq (1) uses ``rho`` where it prints 8 (the paper sets rho = 8).
- Eq (3): at most one idiotope per set, uniform among entries below their column mean.
- Eq (4) is not clipped; a column of mean 0 is left unchanged [ours: guard].
- Eqs (7)-(8) sum over the sets i != n of the stage-1 winner (section 4.3: alpha acts on "the
  other antibodies"); ``alpha_on_self=True`` keeps the earlier reading that also summed i = n.
  They are one replaceable function (:data:`Interaction`), the paper's by default.
- After eq (9), "using (1)" and "using (2)" are read as eqs (5) and (6); clones floored at 0 [ours].
- Ties in both selection stages are broken uniformly at random [ours].
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass


@dataclasses.dataclass(frozen=True)
class Param:
    """A parameter field's declaration (its ``metadata["param"]``, made by :func:`param`).

    Attributes:
        help: what it is, with the equation or SPEC section.
        mechanism: the part of the network that reads it; :data:`jaxais.systems.MECHANISMS`
            maps each to the systems that have that part (e.g. ``"idiotypic"``: SIE, UIE).
        kind: float, int or bool: a sweep's values are of this type.
        bound: the valid [low, high] (None: a switch); float32's smallest normal for "> 0".
        unit: what an int counts (error messages), or None.
        fixed: why it is not a sweep's or an optimiser's variable (None: it is one).
        static: not a pytree leaf but part of the compiled program (a loop schedule).
    """

    help: str
    mechanism: str
    kind: type = float
    bound: tuple[float, float] | None = None
    unit: str | None = None
    fixed: str | None = None
    static: bool = False


def param(
    default: Any,
    *,
    help: str,
    mechanism: str,
    kind: type = float,
    bound: tuple[float, float] | None = None,
    unit: str | None = None,
    fixed: str | None = None,
    static: bool = False,
) -> Any:
    """A parameter field with ``default`` and its :class:`Param` declaration (the arguments).

    The bounds, the sweepable parameters and the systems that use each (:data:`BOUNDS`,
    :data:`jaxais.systems.PARAMETERS`, :data:`jaxais.systems.USED_BY`) are read from these.
    """
    if static and fixed is None:
        raise ValueError("a static parameter is compiled in: say why in fixed=")
    declaration = Param(help, mechanism, kind, bound, unit, fixed, static)
    # "static" is pytree_dataclass's marker for a field kept out of the leaves.
    return dataclasses.field(default=default, metadata={"param": declaration, "static": static})


def declared(cls: Any) -> dict[str, Param]:
    """The :func:`param` fields of a dataclass (or of an instance's class), in field order."""
    return {f.name: f.metadata["param"] for f in dataclasses.fields(cls) if "param" in f.metadata}


def bounds(cls: Any) -> dict[str, tuple[float, float]]:
    """Each bounded traced field's valid [low, high], in field order (:data:`BOUNDS` for
    :class:`NetworkParams`; a subclass's own fields too)."""
    return {n: p.bound for n, p in declared(cls).items() if p.bound and not p.static}


_POSITIVE = float(np.finfo(np.float32).tiny)  # "> 0" as a closed bound
_SEEDING = (
    "rho and phi set the seeded paratopes (eqs 1-2) before the trials start; build the system "
    "with other NetworkParams instead"
)


@pytree_dataclass
class NetworkParams:
    """Constants of the idiotypic network [paper, SPEC 7]: traced leaves (a batch of constants
    is one vmap) but for the static ``idiotope_period``. Build with :func:`network_params`, which
    validates (concrete values, outside jit); inside jit, :meth:`clip_valid` keeps proposed values
    in :data:`BOUNDS`. Each field declares its range, help and mechanism (:func:`param`); a new
    constant is one such field (or a subclass's) and the equation that reads it.
    """

    # fmt: off
    b: float = param(100.0, bound=(0.0, np.inf), mechanism="idiotypic",
                     help="clone production rate, eq (5)")
    k1: float = param(0.85, bound=(0.0, np.inf), mechanism="idiotypic",
                      help="stimulation rate, eq (7)")
    k2: float = param(1.10, bound=(0.0, np.inf), mechanism="idiotypic",
                      help="suppression rate, eq (8)")
    k3: float = param(0.0, bound=(0.0, 1.0), mechanism="idiotypic",
                      help="clone death rate, eq (5)")
    Phi: float = param(25.0, bound=(_POSITIVE, np.inf), mechanism="idiotypic",
                       help="concentration scale, eq (6)")
    rho: float = param(8.0, bound=(0.0, np.inf), mechanism="seeding", fixed=_SEEDING,
                       help="collision weight in the relative fitness, eq (1)")
    phi: float = param(20.0, bound=(_POSITIVE, np.inf), mechanism="seeding", fixed=_SEEDING,
                       help="scale of the seeded paratopes, eq (2)")
    initial_clones: float = param(1000.0, bound=(_POSITIVE, np.inf), mechanism="idiotypic",
                                  help="clones per antibody as the STL starts")
    penalty_idiotypic: float = param(0.5, bound=(0.0, np.inf), mechanism="idiotypic",
                                     help="paratope a penalty removes from the acting "
                                     "antibody with idiotypic selection (SPEC 6)")
    penalty_non_idiotypic: float = param(1.0, bound=(0.0, np.inf), mechanism="non_idiotypic",
                                         help="paratope a penalty removes from the acting "
                                         "antibody with stage 1 alone (SPEC 6)")
    idiotope_period: int = param(120, kind=int, bound=(1, np.inf), mechanism="idiotypic",
                                 help="iterations between idiotope redraws, eq (3)",
                                 static=True, fixed="NetworkParams.idiotope_period is a loop "
                                 "schedule, fixed when the program is compiled; run one sweep "
                                 "per value")
    # fmt: on

    def validate(self) -> NetworkParams:
        """``self`` once every range holds (elementwise; concrete values, not under jit).

        Raises:
            ValueError: one line naming the first bad field.
        """
        cls = type(self).__name__
        for name, (low, high) in bounds(self).items():
            try:
                value = np.asarray(getattr(self, name), dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(
                    f"{cls}.{name} must be a number, got {getattr(self, name)!r:.40}"
                ) from None
            if not np.all((value >= low) & (value <= high)):  # NaN fails too
                rule = "> 0" if low == _POSITIVE else f">= {low:g}"
                rule = f"in [{low:g}, {high:g}]" if high < np.inf else rule
                raise ValueError(f"{cls}.{name} must be {rule}, got {value}")
        for name, declaration in declared(self).items():
            if declaration.static:  # a schedule: a Python int (it fixes the program)
                value, low = getattr(self, name), declaration.bound[0]
                whole = isinstance(value, int | np.integer) and not isinstance(value, bool)
                if not whole or value < low:
                    raise ValueError(f"{cls}.{name} must be an int >= {low}, got {value!r}")
        return self

    def clip_valid(self) -> NetworkParams:
        """A copy with each float constant clipped into :data:`BOUNDS`: jit-safe, for values an
        optimiser proposes (NaN stays NaN); host values stay on the host."""
        clip = lambda v, lo, hi: (jnp if isinstance(v, jax.Array) else np).clip(v, lo, hi)
        valid = bounds(self)
        return self.replace(**{k: clip(getattr(self, k), *valid[k]) for k in valid})


BOUNDS: dict[str, tuple[float, float]] = bounds(NetworkParams)
"""Each float constant's valid range [low, high] (float32's smallest normal number for "> 0"),
read from the fields: what ``validate`` checks, ``clip_valid`` clips to, and an optimiser may
read."""


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


def acted_on(x: int, n: jax.Array | int, alpha_on_self: jax.Array | bool = False) -> jax.Array:
    """[x] bool: the sets alpha's set ``n`` stimulates and suppresses in eqs (7)-(8), every set
    but n (section 4.3, "the other antibodies"), or all of them with ``alpha_on_self``."""
    return (jnp.arange(x) != n) | alpha_on_self


def stimulation_suppression(
    P: jax.Array,
    I: jax.Array,
    C: jax.Array,
    n: jax.Array | int,
    params: NetworkParams,
    alpha_on_self: jax.Array | bool = False,
) -> tuple[jax.Array, jax.Array]:
    """Eqs (7)-(8), the paper's :data:`Interaction`: stimulation eps [x] and suppression
    delta [x] of each set by alpha's set n.

    eps_i = k1 * sum_j (1 - P_ij) I_nj C_ij C_nj and delta_i = k2 * sum_j P_nj I_ij C_ij C_nj
    for the sets :func:`acted_on` (0 for the others). P, I, C [x, y]: C before the update.
    """
    P = jnp.asarray(P, jnp.float32)
    I = jnp.asarray(I, jnp.float32)
    C = jnp.asarray(C, jnp.float32)
    on = acted_on(P.shape[0], n, alpha_on_self)
    eps = params.k1 * jnp.sum((1.0 - P) * I[n] * C * C[n], axis=1)
    delta = params.k2 * jnp.sum(P[n] * I * C * C[n], axis=1)
    return jnp.where(on, eps, 0.0), jnp.where(on, delta, 0.0)


Interaction = Callable[
    [jax.Array, jax.Array, jax.Array, jax.Array, NetworkParams, jax.Array | bool],
    tuple[jax.Array, jax.Array],
]
"""Eqs (7)-(8) as a replaceable function (an argument of :func:`idiotypic_select` and
:func:`jaxais.controllers.stl_controller`; the paper's is :func:`stimulation_suppression`):
``interaction(P, I, C, n, params, alpha_on_self) -> (eps [x], delta [x])`` with P, I, C [x, y]
float32 (C of the clones before eq 5), n alpha's set (int32), ``params`` the system's
:class:`NetworkParams` (traced; a subclass carries a variant's own constants) and
``alpha_on_self`` a traced bool (:func:`acted_on`). Pure and shape-preserving: it runs inside
the trials' compiled loop, once per selection."""


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
    interaction: Interaction = stimulation_suppression,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Three-stage idiotypic selection (eqs 5-10): alpha (stage 1), S2 and the antigen's clone
    column (eqs 5, 7-9), beta the highest activation (eq 10); alpha != beta is an idiotypic
    difference.

    Args:
        u: [2 * x] uniforms, stage 1's tie-breaks then stage 3's, sliced from the controller's
            one draw per iteration; ``u[:x]`` alone gives the same alphas as stage 1 alone.
        P, I, N: [x, y] paratopes, idiotopes, clone counts.
        interaction: eqs (7)-(8), an :data:`Interaction` (default the paper's).

    Returns:
        alpha, beta (int32), and N [x, y] with column ``antigen`` updated.
    """
    P = jnp.asarray(P, jnp.float32)
    N = jnp.asarray(N, jnp.float32)
    x = P.shape[0]
    alpha = select_alpha(u[:x], P, antigen)
    eps, delta = interaction(P, I, concentrations(N, params.Phi), alpha, params, alpha_on_self)
    s2 = stage2_stimulus(P, eps, delta, antigen)
    N_new = update_clones(N, s2, antigen, params.b, params.k3)
    beta = argmax_ties(activation(N_new, s2, antigen, params.Phi), u[x:])
    return alpha, beta, N_new
