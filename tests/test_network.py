"""Tests of the idiotypic network equations (1)-(10) in jaxais.immune.network.

Every equation is checked against hand-worked numbers and against a plain NumPy reference
written independently here (loops, float64). Jitted functions are built once at module level and
all inputs keep one shape per function, so hypothesis examples never trigger a recompile.
"""

# I is the paper's name for the idiotope matrix.
# ruff: noqa: E741

from __future__ import annotations

from collections import Counter
from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from jaxais.immune import network as nw

X, Y = 5, 8
PARAMS = nw.network_params()

relative_fitness = jax.jit(nw.relative_fitness)
seed_paratopes = jax.jit(nw.seed_paratopes)
idiotopes = jax.jit(nw.idiotopes)
idiotopes_many_keys = jax.jit(jax.vmap(nw.idiotopes, in_axes=(0, None)))
rescale_paratopes = jax.jit(nw.rescale_paratopes)
concentrations = jax.jit(nw.concentrations)
tiebreak_many_keys = jax.jit(
    jax.vmap(lambda key, v: nw.argmax_ties(v, jax.random.uniform(key, v.shape)), in_axes=(0, None))
)


def _uniforms(key, P, stages=2):
    """The selection's draw from ``key``: ``stages * x`` uniforms, as the controller makes."""
    return jax.random.uniform(key, (stages * np.shape(P)[0],))


select_alpha = jax.jit(lambda key, P, m: nw.select_alpha(_uniforms(key, P, 1), P, m))
stimulation_suppression = jax.jit(nw.stimulation_suppression)

# Traces of idiotypic_select per input shape, to prove new values never retrace it.
SELECT_TRACES: Counter[tuple[int, ...]] = Counter()


def _select_counting_traces(key, P, I, N, antigen, params):
    SELECT_TRACES[np.shape(P)] += 1
    return nw.idiotypic_select(_uniforms(key, P), P, I, N, antigen, params)


def _select(key, P, I, N, antigen, params, alpha_on_self=False):
    return nw.idiotypic_select(_uniforms(key, P), P, I, N, antigen, params, alpha_on_self)


idiotypic_select = jax.jit(_select_counting_traces)
idiotypic_select_reading = jax.jit(_select)
idiotypic_select_batch = jax.jit(jax.vmap(_select))

hyp = settings(max_examples=30, deadline=None)
# XLA on CPU flushes subnormal floats to zero, so they are left out of generated inputs.
unit_floats = st.floats(0, 1, width=32, allow_subnormal=False)
clone_counts = st.floats(0, 5000, width=32, allow_subnormal=False)
# Values on a coarse grid: many exact ties and entries equal to their column mean.
grid_values = st.sampled_from([0.0, 0.1, 0.25, 0.5, 0.75, 1.0])
paratope_matrices = arrays(np.float32, (X, Y), elements=grid_values)
seeds = st.integers(0, 2**31 - 1)


def keys(seed: int, n: int) -> jax.Array:
    return jax.random.split(jax.random.key(seed), n)


# ---------------------------------------------------------------- independent NumPy reference


def ref_relative_fitness(tau, c, rho):
    tau, c = np.asarray(tau, np.float64), np.asarray(c, np.float64)
    total = sum(1.0 / (tau[k] + rho * c[k]) for k in range(len(tau)))
    return np.array([1.0 / ((tau[i] + rho * c[i]) * total) for i in range(len(tau))])


def ref_seed_paratopes(L, mu, phi):
    return np.clip(np.asarray(L, np.float64) * np.asarray(mu, np.float64)[:, None] / phi, 0, 1)


def ref_candidates(P):
    """Exact rational test P_ij < sigma_j, i.e. x * P_ij < sum_i P_ij (no rounding at all)."""
    x, y = P.shape
    cand = np.zeros((x, y), bool)
    for j in range(y):
        column = [Fraction(float(v)) for v in P[:, j]]
        for i in range(x):
            cand[i, j] = x * column[i] < sum(column)
    return cand


def ref_rescale(P, sigma0):
    P = np.asarray(P, np.float64).copy()
    for j in range(P.shape[1]):
        mean = P[:, j].mean()
        if mean != 0:
            P[:, j] *= sigma0[j] / mean
    return P


def ref_concentrations(N, Phi):
    N = np.asarray(N, np.float64)
    return Phi * N / N.sum()


def ref_select(P, I, N, m, b, k1, k2, k3, Phi, alpha_on_self=False):
    """Eqs (5)-(10) with explicit loops; assumes no ties (continuous random inputs). Alpha acts
    on the other sets only (section 4.3) unless ``alpha_on_self``."""
    P, I, N = (np.asarray(a, np.float64) for a in (P, I, N))
    x, y = P.shape
    n = int(np.argmax(P[:, m]))
    C = ref_concentrations(N, Phi)
    eps, delta = np.zeros(x), np.zeros(x)
    for i in range(x):
        if i == n and not alpha_on_self:
            continue
        for j in range(y):
            eps[i] += k1 * (1 - P[i, j]) * I[n, j] * C[i, j] * C[n, j]
            delta[i] += k2 * P[n, j] * I[i, j] * C[i, j] * C[n, j]
    s2 = P[:, m] + eps - delta
    N_new = N.copy()
    N_new[:, m] = np.maximum(b * s2 + N[:, m] * (1 - k3), 0)
    activation = ref_concentrations(N_new, Phi)[:, m] * s2
    return n, int(np.argmax(activation)), N_new, eps, delta, s2


def random_network(rng: np.random.Generator, x: int = X, y: int = Y):
    P = rng.uniform(0, 1, (x, y)).astype(np.float32)
    I = np.zeros((x, y), np.float32)
    rows = rng.random(x) < 0.8
    I[np.arange(x)[rows], rng.integers(0, y, rows.sum())] = 1.0
    N = rng.uniform(0, 2000, (x, y)).astype(np.float32)
    return P, I, N


# ---------------------------------------------------------------- parameters


def test_defaults_match_spec():
    p = nw.network_params()
    assert (p.b, p.k1, p.k2, p.k3, p.Phi) == (100.0, 0.85, 1.10, 0.0, 25.0)
    assert (p.rho, p.phi, p.initial_clones, p.idiotope_period) == (8.0, 20.0, 1000.0, 120)
    # The penalties of SPEC 6 (Table 2's text): 0.5 with idiotypic selection, 1.0 without.
    assert (p.penalty_idiotypic, p.penalty_non_idiotypic) == (0.5, 1.0)
    # idiotope_period is static: every other field is a leaf, the period lives in the treedef.
    assert len(jax.tree_util.tree_leaves(p)) == len(nw.BOUNDS)
    assert jax.tree.structure(p) != jax.tree.structure(p.replace(idiotope_period=60))
    assert p.replace(k1=0.5).k1 == 0.5


@pytest.mark.parametrize(
    "overrides",
    [
        {"b": -1.0},
        {"k1": -0.1},
        {"k2": -0.1},
        {"k3": -0.01},
        {"k3": 1.5},
        {"Phi": 0.0},
        {"Phi": -2.0},
        {"phi": 0.0},
        {"rho": -8.0},
        {"penalty_idiotypic": -0.5},
        {"initial_clones": 0.0},
        {"k1": float("nan")},
        {"idiotope_period": 0},
        {"idiotope_period": 1.5},
        {"kappa": 1.0},
    ],
)
def test_bad_params_raise(overrides):
    with pytest.raises(ValueError, match="NetworkParams") as info:
        nw.network_params(**overrides)
    assert "\n" not in str(info.value)


def test_validate_checks_batched_leaves():
    batch = nw.NetworkParams(k3=jnp.array([0.0, 0.5, 1.0]))
    assert batch.validate() is batch
    with pytest.raises(ValueError, match="k3"):
        nw.NetworkParams(k3=jnp.array([0.0, 2.0])).validate()


# ---------------------------------------------------------------- eq (1) relative fitness


def test_relative_fitness_hand_worked():
    # cost = tau + 8c = [100, 200]; sum 1/cost = 0.015; mu = [1/(100*0.015), 1/(200*0.015)].
    mu = relative_fitness(jnp.array([100.0, 200.0]), jnp.array([0.0, 0.0]), 8.0)
    np.testing.assert_allclose(mu, [2 / 3, 1 / 3], rtol=1e-6)
    # cost = [100 + 8*0, 60 + 8*5] = [100, 100]: collisions weigh rho each, so equal fitness.
    mu = relative_fitness(jnp.array([100.0, 60.0]), jnp.array([0.0, 5.0]), 8.0)
    np.testing.assert_allclose(mu, [0.5, 0.5], rtol=1e-6)
    # rho is used in the sum too: rho = 0 ignores collisions entirely, cost = [100, 60].
    mu = relative_fitness(jnp.array([100.0, 60.0]), jnp.array([0.0, 5.0]), 0.0)
    np.testing.assert_allclose(mu, [0.375, 0.625], rtol=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_relative_fitness_reference_and_sum(seed):
    rng = np.random.default_rng(seed)
    tau = rng.uniform(20, 300, X).astype(np.float32)
    c = rng.integers(0, 30, X).astype(np.float32)
    mu = relative_fitness(tau, c, 8.0)
    assert mu.dtype == jnp.float32
    np.testing.assert_allclose(mu, ref_relative_fitness(tau, c, 8.0), rtol=1e-5)
    np.testing.assert_allclose(np.sum(mu), 1.0, rtol=1e-5)
    # Lower cost (faster, fewer collisions) is fitter.
    cost = tau + 8 * c
    assert np.all(np.diff(np.asarray(mu)[np.argsort(cost)]) <= 1e-7)


def test_relative_fitness_equal_sets_equal_mu():
    mu = relative_fitness(jnp.full(X, 120.0), jnp.full(X, 3.0), 8.0)
    np.testing.assert_allclose(mu, np.full(X, 1 / X), rtol=1e-6)


# ---------------------------------------------------------------- eq (2) seeded paratopes


def test_seed_paratopes_hand_worked_and_clipped():
    # L*mu/phi: 10*1/20 = 0.5; 40*1/20 = 2 -> 1; -5*1/20 = -0.25 -> 0; 12*0.5/20 = 0.3.
    L = jnp.array([[10.0, 40.0, -5.0], [12.0, 0.0, 80.0]])
    P = seed_paratopes(L, jnp.array([1.0, 0.5]), 20.0)
    np.testing.assert_allclose(P, [[0.5, 1.0, 0.0], [0.3, 0.0, 1.0]], rtol=1e-6)


@pytest.mark.parametrize("seed", range(3))
def test_seed_paratopes_reference(seed):
    rng = np.random.default_rng(seed)
    L = rng.uniform(-10, 60, (X, Y)).astype(np.float32)
    mu = rng.dirichlet(np.ones(X)).astype(np.float32) * 2
    P = seed_paratopes(L, mu, 20.0)
    np.testing.assert_allclose(P, ref_seed_paratopes(L, mu, 20.0), rtol=1e-5, atol=1e-7)
    assert float(P.min()) >= 0.0 and float(P.max()) <= 1.0


# ---------------------------------------------------------------- eq (3) idiotopes


def test_idiotopes_hand_worked_and_uniform():
    # Every column mean is (0.9 + 0.8 + 0.1) / 3 = 0.6. Set 0 (all 0.9) has no idiotope; set 1
    # is below 0.6 only in column 1; set 2 in columns 0, 2 and 3, so it picks one of them with
    # probability 1/3 each.
    P = jnp.array([[0.9, 0.9, 0.9, 0.9], [0.8, 0.1, 0.8, 0.8], [0.1, 0.8, 0.1, 0.1]])
    I = np.asarray(idiotopes_many_keys(keys(0, 6000), P))
    np.testing.assert_array_equal(I[:, 0], 0.0)
    np.testing.assert_array_equal(I[:, 1], np.tile([0.0, 1.0, 0.0, 0.0], (6000, 1)))
    np.testing.assert_array_equal(I[:, 2].sum(axis=1), 1.0)
    np.testing.assert_allclose(I[:, 2].mean(axis=0), [1 / 3, 0.0, 1 / 3, 1 / 3], atol=0.03)


@hyp
@given(P=paratope_matrices, seed=seeds)
def test_idiotopes_invariants(P, seed):
    I = np.asarray(idiotopes(jax.random.key(seed), P))
    cand = ref_candidates(P)
    assert I.dtype == np.float32 and set(np.unique(I)) <= {0.0, 1.0}
    assert np.all(I.sum(axis=1) <= 1)  # at most one idiotope per set
    assert not np.any((I == 1) & ~cand)  # only strictly below the column mean
    np.testing.assert_array_equal(I.sum(axis=1), cand.any(axis=1))  # one per set that can


def test_idiotopes_constant_column_has_no_candidates():
    # 0.1 is not exact in float32; a rounded mean must not make all of 0.1 "below the mean".
    I = idiotopes(jax.random.key(0), np.full((X, Y), 0.1, np.float32))
    np.testing.assert_array_equal(I, np.zeros((X, Y)))


# ---------------------------------------------------------------- eq (4) rescaling


def test_rescale_hand_worked():
    # Column 0 mean 0.25 -> sigma0 0.5: doubled (and 0.8 -> 1.6, not clipped).
    # Column 1 mean 0 -> guard, unchanged.  Column 2 mean 0.5 -> sigma0 0.25: halved.
    P = jnp.array([[0.8, 0.0, 0.2], [-0.3, 0.0, 0.8]])
    out = rescale_paratopes(P, jnp.array([0.5, 0.4, 0.25]))
    np.testing.assert_allclose(out, [[1.6, 0.0, 0.1], [-0.6, 0.0, 0.4]], rtol=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_rescale_reference_and_means_restored(seed):
    rng = np.random.default_rng(seed)
    P = rng.uniform(0, 1, (X, Y)).astype(np.float32)
    P[:, 3] = 0.0  # a dead column exercises the guard
    sigma0 = rng.uniform(0.2, 0.8, Y).astype(np.float32)
    out = np.asarray(rescale_paratopes(P, sigma0))
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out, ref_rescale(P, sigma0), rtol=1e-5, atol=1e-7)
    live = np.arange(Y) != 3
    np.testing.assert_allclose(out.mean(axis=0)[live], sigma0[live], rtol=1e-5)
    np.testing.assert_array_equal(out[:, 3], 0.0)


def test_rescale_zero_column_gradient_is_finite():
    grad_fn = jax.jit(jax.grad(lambda p: nw.rescale_paratopes(p, jnp.ones(Y)).sum()))
    grad = grad_fn(jnp.zeros((X, Y)))
    assert np.all(np.isfinite(grad))


# ---------------------------------------------------------------- eq (6) concentrations


def test_concentrations_hand_worked():
    # sum N = 1 + 3 + 0 + 4 = 8; C = 2 * N / 8 = N / 4.
    C = concentrations(jnp.array([[1.0, 3.0], [0.0, 4.0]]), 2.0)
    np.testing.assert_allclose(C, [[0.25, 0.75], [0.0, 1.0]], rtol=1e-6)
    # All clones dead: zeros, not NaN.
    np.testing.assert_array_equal(concentrations(jnp.zeros((2, 2)), 2.0), np.zeros((2, 2)))


@pytest.mark.parametrize("seed", range(3))
def test_concentrations_reference(seed):
    N = np.random.default_rng(seed).uniform(0, 2000, (X, Y)).astype(np.float32)
    C = concentrations(N, 25.0)
    np.testing.assert_allclose(C, ref_concentrations(N, 25.0), rtol=1e-5)
    np.testing.assert_allclose(np.sum(C), 25.0, rtol=1e-5)


def test_initial_clones():
    N = nw.initial_clones(3, 4, 1000.0)
    assert N.shape == (3, 4) and N.dtype == jnp.float32
    np.testing.assert_array_equal(N, 1000.0)


# ---------------------------------------------------------------- random tie-break


def test_tiebreak_uniform_over_exact_ties_only():
    values = jnp.array([0.3, 0.7, 0.1, 0.7, 0.7, 0.69999])
    picks = np.asarray(tiebreak_many_keys(keys(2, 6000), values))
    assert picks.dtype == np.int32
    freq = np.bincount(picks, minlength=6) / picks.size
    np.testing.assert_allclose(freq, [0, 1 / 3, 0, 1 / 3, 1 / 3, 0], atol=0.03)


def test_tiebreak_unique_max_is_argmax():
    values = jnp.array([0.3, 0.7, 0.1, 0.9, 0.5, 0.2])
    np.testing.assert_array_equal(tiebreak_many_keys(keys(3, 6000), values), 3)


# ---------------------------------------------------------------- eqs (5), (7)-(10) selection

# A 3 x 2 network worked by hand: every C is 1 (six antibodies, one clone each, Phi = 6).
HAND_P = jnp.array([[0.75, 0.875], [0.5, 0.625], [0.25, 0.125]])
HAND_I = jnp.array([[0.0, 1.0], [1.0, 0.0], [0.0, 1.0]])
HAND_N = jnp.ones((3, 2))
HAND_PARAMS = nw.network_params(b=10.0, k1=1.0, k2=1.0, k3=0.5, Phi=6.0)


# Antigen 0: P[:, 0] = [0.75, 0.5, 0.25] -> alpha = set 0, I_0 = [0, 1], P_0 = [0.75, 0.875].
# Summed over every set i (alpha's own included):
#   eps_i = sum_j (1 - P_ij) I_0j = 1 - P_i1 = [0.125, 0.375, 0.875]
#   delta_i = sum_j P_0j I_ij = [0.875 (I_0 = e1), 0.75 (I_1 = e0), 0.875 (I_2 = e1)]
HAND_EPS_ALL, HAND_DELTA_ALL = [0.125, 0.375, 0.875], [0.875, 0.75, 0.875]


def _check_hand_worked(alpha_on_self, eps_want, delta_want, s2_want, N0_want, beta_want):
    C = concentrations(HAND_N, 6.0)
    eps, delta = stimulation_suppression(HAND_P, HAND_I, C, 0, HAND_PARAMS, alpha_on_self)
    np.testing.assert_allclose(eps, eps_want, rtol=1e-6)
    np.testing.assert_allclose(delta, delta_want, rtol=1e-6)
    alpha, beta, N_new = idiotypic_select_reading(
        jax.random.key(0), HAND_P, HAND_I, HAND_N, 0, HAND_PARAMS, alpha_on_self
    )
    assert (int(alpha), int(beta)) == (0, beta_want)
    assert alpha.dtype == jnp.int32 and beta.dtype == jnp.int32
    N_want = np.stack([N0_want, np.ones(3)], axis=1)
    np.testing.assert_allclose(N_new, N_want, rtol=1e-6)
    n, p, N_ref, eps_ref, delta_ref, s2_ref = ref_select(
        HAND_P, HAND_I, HAND_N, 0, 10.0, 1.0, 1.0, 0.5, 6.0, alpha_on_self
    )
    # The NumPy reference agrees with the hand arithmetic too.
    assert (n, p) == (0, beta_want)
    np.testing.assert_allclose(eps_ref, eps_want, atol=1e-12)
    np.testing.assert_allclose(delta_ref, delta_want, atol=1e-12)
    np.testing.assert_allclose(s2_ref, s2_want, atol=1e-12)
    np.testing.assert_allclose(N_ref, N_want, atol=1e-12)


def test_select_hand_worked_alpha_acts_on_the_others():
    # The default (section 4.3): alpha's own eps and delta are 0, so its S2 is its P.
    # S2 = [0.75, 0.5 + 0.375 - 0.75, 0.25 + 0.875 - 0.875] = [0.75, 0.125, 0.25]
    # N_i0 = 10 * S2 + 1 * (1 - 0.5) = [8.0, 1.75, 3.0]; column 1 unchanged; sum N = 15.75
    # lambda = 6 / 15.75 * N_i0 * S2 = 6 / 15.75 * [6.0, 0.21875, 0.75] -> beta = alpha = 0.
    eps = [0.0, *HAND_EPS_ALL[1:]]
    delta = [0.0, *HAND_DELTA_ALL[1:]]
    _check_hand_worked(False, eps, delta, [0.75, 0.125, 0.25], [8.0, 1.75, 3.0], 0)


def test_select_hand_worked_alpha_on_self():
    # The engine's earlier reading: alpha's own set summed too.
    # S2 = [0.75 + 0.125 - 0.875, 0.125, 0.25] = [0, 0.125, 0.25]
    # N_i0 = 10 * S2 + 0.5 = [0.5, 1.75, 3.0]; sum N = 8.25
    # lambda = 6 / 8.25 * [0, 0.21875, 0.75] -> beta = set 2.
    _check_hand_worked(True, HAND_EPS_ALL, HAND_DELTA_ALL, [0.0, 0.125, 0.25], [0.5, 1.75, 3.0], 2)


def test_select_floors_clones_at_zero():
    # k2 = 10: delta = [0, 7.5, 8.75], S2 = [0.75, -6.625, -7.625], 10*S2 + 0.5 < 0 -> 0 but
    # alpha's (8.0).
    params = HAND_PARAMS.replace(k2=10.0)
    _, _, N_new = idiotypic_select(jax.random.key(0), HAND_P, HAND_I, HAND_N, 0, params)
    np.testing.assert_array_equal(N_new, [[8.0, 1.0], [0.0, 1.0], [0.0, 1.0]])


@hyp
@given(
    P=arrays(np.float32, (X, Y), elements=unit_floats),
    N=arrays(np.float32, (X, Y), elements=clone_counts),
    I=paratope_matrices.map(lambda a: (a > 0.5).astype(np.float32)),
    n=st.integers(0, X - 1),
)
def test_alpha_own_eps_and_delta_are_zero_by_default(P, N, I, n):
    C = concentrations(N, PARAMS.Phi)
    eps, delta = stimulation_suppression(P, I, C, n, PARAMS)
    eps_all, delta_all = stimulation_suppression(P, I, C, n, PARAMS, True)
    assert float(eps[n]) == 0.0 and float(delta[n]) == 0.0
    others = np.arange(X) != n
    np.testing.assert_array_equal(np.asarray(eps)[others], np.asarray(eps_all)[others])
    np.testing.assert_array_equal(np.asarray(delta)[others], np.asarray(delta_all)[others])


@pytest.mark.parametrize("alpha_on_self", [False, True])
@pytest.mark.parametrize("seed", range(6))
def test_select_reference(seed, alpha_on_self):
    rng = np.random.default_rng(seed)
    P, I, N = random_network(rng)
    m = int(rng.integers(0, Y))
    params = nw.network_params(k3=float(rng.uniform(0, 0.5)))
    key = jax.random.key(seed)
    alpha, beta, N_new = idiotypic_select_reading(key, P, I, N, m, params, alpha_on_self)
    n, p, N_ref, eps_ref, delta_ref, _ = ref_select(
        P, I, N, m, params.b, params.k1, params.k2, params.k3, params.Phi, alpha_on_self
    )
    C = concentrations(N, params.Phi)
    eps, delta = stimulation_suppression(P, I, C, n, params, alpha_on_self)
    np.testing.assert_allclose(eps, eps_ref, rtol=1e-4, atol=1e-7)
    np.testing.assert_allclose(delta, delta_ref, rtol=1e-4, atol=1e-7)
    assert (int(alpha), int(beta)) == (n, p)
    np.testing.assert_allclose(N_new, N_ref, rtol=1e-4, atol=1e-3)


@hyp
@given(
    P=arrays(np.float32, (X, Y), elements=unit_floats),
    N=arrays(np.float32, (X, Y), elements=clone_counts),
    I=paratope_matrices.map(lambda a: (a > 0.5).astype(np.float32)),
    m=st.integers(0, Y - 1),
    k2=st.floats(0, 20),
    seed=seeds,
)
def test_select_invariants(P, N, I, m, k2, seed):
    params = PARAMS.replace(k2=k2)
    alpha, beta, N_new = idiotypic_select(jax.random.key(seed), P, I, N, m, params)
    N_new = np.asarray(N_new)
    assert np.all(N_new >= 0) and np.all(np.isfinite(N_new))
    others = np.arange(Y) != m
    np.testing.assert_array_equal(N_new[:, others], N[:, others])
    assert P[int(alpha), m] == P[:, m].max()
    assert 0 <= int(beta) < X


def test_select_alpha_is_argmax_when_unique():
    rng = np.random.default_rng(7)
    for seed in range(5):
        P, I, N = random_network(rng)
        for m in range(Y):
            alpha, _, _ = idiotypic_select(jax.random.key(seed), P, I, N, m, PARAMS)
            assert int(alpha) == int(np.argmax(P[:, m]))
            assert int(select_alpha(jax.random.key(seed), P, m)) == int(alpha)


@hyp
@given(
    column=arrays(np.int32, X, elements=st.integers(0, 64), unique=True),
    P=arrays(np.float32, (X, Y), elements=unit_floats),
    clones=st.floats(0, 5000),
    k3=st.floats(0, 1),
    m=st.integers(0, Y - 1),
    seed=seeds,
)
def test_no_idiotypic_effect_gives_beta_alpha(column, P, clones, k3, m, seed):
    # With k1 = k2 = 0, S2 = P_im and lambda_i = Phi/sum(N') * (b P_im + N_im (1 - k3)) * P_im.
    # That is strictly increasing in P_im >= 0 when b > 0 and the column N_im is the same for
    # every set (as at the start), so beta = alpha; it need not hold for unequal clone counts.
    P = P.copy()
    P[:, m] = column / 64.0  # distinct values, so alpha is unique
    N = np.full((X, Y), 1000.0, np.float32)
    N[:, m] = clones
    params = PARAMS.replace(k1=0.0, k2=0.0, k3=k3)
    I = np.ones((X, Y), np.float32)  # idiotopes must not matter
    alpha, beta, N_new = idiotypic_select(jax.random.key(seed), P, I, N, m, params)
    assert int(alpha) == int(beta) == int(np.argmax(P[:, m]))
    np.testing.assert_allclose(
        np.asarray(N_new)[:, m], params.b * P[:, m] + N[:, m] * (1 - k3), rtol=1e-5, atol=1e-3
    )


def test_no_idiotypic_effect_unequal_clones_can_differ():
    # P[:, 0] = [0.75, 0.5, 0.25], N[:, 0] = [0, 1000, 1]: with k1 = k2 = 0, b = 10, k3 = 0.5,
    # lambda ∝ N'_i0 * P_i0 = [(7.5 + 0) 0.75, (5 + 500) 0.5, (2.5 + 0.5) 0.25]
    # = [5.625, 252.5, 0.75], so beta = 1 although alpha = 0: clones, not only P, drive stage 3.
    params = HAND_PARAMS.replace(k1=0.0, k2=0.0)
    N = jnp.array([[0.0, 1.0], [1000.0, 1.0], [1.0, 1.0]])
    alpha, beta, _ = idiotypic_select(jax.random.key(0), HAND_P, HAND_I, N, 0, params)
    assert (int(alpha), int(beta)) == (0, 1)


def test_select_ties_are_random_and_key_deterministic():
    # All sets identical: every stage is a full tie, so the key alone decides.
    P = np.full((X, Y), 0.5, np.float32)
    I = np.zeros((X, Y), np.float32)
    N = np.full((X, Y), 1000.0, np.float32)
    out = [idiotypic_select(jax.random.key(s), P, I, N, 2, PARAMS) for s in range(40)]
    assert {int(a) for a, _, _ in out} == set(range(X))
    assert {int(b) for _, b, _ in out} == set(range(X))
    # Stage 1 breaks its ties as select_alpha does from the same key (the controller relies on
    # it: a batch without idiotypic systems runs select_alpha alone, with the same alphas).
    for s, (a, _, _) in enumerate(out):
        assert int(select_alpha(jax.random.key(s), P, 2)) == int(a)
    again = idiotypic_select(jax.random.key(7), P, I, N, 2, PARAMS)
    for a, b in zip(out[7], again, strict=True):
        np.testing.assert_array_equal(a, b)


def test_vmap_equals_loop_including_batched_params():
    B = 6
    rng = np.random.default_rng(11)
    nets = [random_network(rng) for _ in range(B)]
    P, I, N = (np.stack(a) for a in zip(*nets, strict=True))
    m = rng.integers(0, Y, B).astype(np.int32)
    seeds = rng.integers(0, 2**31, B)
    k1, k2, k3 = rng.uniform(0, 2, B), rng.uniform(0, 2, B), rng.uniform(0, 1, B)
    # Every float leaf gets a batch axis; k1, k2, k3 differ per network.
    batch = jax.tree.map(lambda leaf: np.full(B, leaf, np.float32), PARAMS)
    batch = batch.replace(
        k1=k1.astype(np.float32), k2=k2.astype(np.float32), k3=k3.astype(np.float32)
    )
    key_batch = jax.vmap(jax.random.key)(seeds)
    alpha, beta, N_new = idiotypic_select_batch(key_batch, P, I, N, m, batch)
    for i in range(B):
        one = PARAMS.replace(k1=float(k1[i]), k2=float(k2[i]), k3=float(k3[i]))
        a, b, n = idiotypic_select(jax.random.key(seeds[i]), P[i], I[i], N[i], int(m[i]), one)
        assert (int(alpha[i]), int(beta[i])) == (int(a), int(b))
        np.testing.assert_allclose(N_new[i], n, rtol=1e-5)


def test_select_never_retraces_for_new_values():
    rng = np.random.default_rng(3)
    idiotypic_select(jax.random.key(0), *random_network(rng), 0, PARAMS)  # compiled at most here
    before = SELECT_TRACES[(X, Y)]
    for seed in range(1, 5):
        params = PARAMS.replace(k1=0.1 * seed, k3=0.2 * seed)
        idiotypic_select(jax.random.key(seed), *random_network(rng), seed, params)
    assert SELECT_TRACES[(X, Y)] == before


def test_runs_under_scan():
    # An STL-like loop under lax.scan: select, reward the acting antibody, rescale (eq 4).
    rng = np.random.default_rng(5)
    P0, I, _ = random_network(rng)
    sigma0 = P0.mean(axis=0)
    T = 300
    xs = (
        rng.integers(0, Y, T).astype(np.int32),
        rng.uniform(-0.1, 0.1, T).astype(np.float32),
        jax.random.split(jax.random.key(6), T),
    )

    def step(carry, inputs):
        P, N = carry
        m, reward, key = inputs
        alpha, beta, N = nw.idiotypic_select(_uniforms(key, P), P, I, N, m, PARAMS)
        P = P.at[beta, m].set(jnp.clip(P[beta, m] + reward, 0.0, 1.0))
        return (nw.rescale_paratopes(P, sigma0), N), alpha != beta

    init = (P0, np.full((X, Y), PARAMS.initial_clones, np.float32))
    (P, N), differ = jax.jit(lambda c, x: jax.lax.scan(step, c, x))(init, xs)
    assert np.all(np.isfinite(P)) and np.all(np.isfinite(N)) and np.all(np.asarray(N) >= 0)
    np.testing.assert_allclose(np.mean(P, axis=0), sigma0, rtol=1e-4)
    assert differ.shape == (T,) and differ.dtype == np.bool_
