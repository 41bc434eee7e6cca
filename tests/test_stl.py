"""Unit tests of the STL controller (``jaxais.controllers.STL``), SPEC 6-8, hand-worked.

``STL.learn`` and ``STL.act`` are each jitted once (``_stl_fixtures``) and called on hand-made
:class:`STLState` / :class:`Percept` values of one shape and dtype, so no case (hypothesis
examples included) compiles again. The NumPy references below are written from the SPEC, not
from the code under test.
"""

# I is the paper's name for the idiotope matrix.
# ruff: noqa: E741

from __future__ import annotations

import _stl_fixtures as F
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxais.controllers import STL, interrupts
from jaxais.immune.antibodies import from_uniforms, take, within_limits
from jaxais.immune.behaviours import wheel_speeds
from jaxais.immune.network import idiotopes
from jaxais.immune.readings import LITERAL, readings
from jaxais.immune.reinforcement import rl_score

hyp = settings(max_examples=25, deadline=None)
seeds = st.integers(0, 2**31 - 1)
antigens = st.integers(0, 7)


def learn(s, pc, sys_, key_seed: int = 0):
    """``STL.learn`` with ``jax.random.key(key_seed)`` on ``s`` whose acting antibody was
    selected for ``pc.m_prev`` (as under the literal per-iteration reading that ``F.system``
    uses)."""
    s = s.replace(bout=s.bout.replace(antigen=pc.m_prev))
    return F.learn_fn()(jax.random.key(key_seed), s, pc, sys_)


def act(s, pc, sys_, key_seed: int = 0):
    return F.act_fn()(jax.random.key(key_seed), s, pc, sys_)


def P_of(s) -> np.ndarray:
    return np.asarray(s.P, np.float64)


tree_equal = F.tree_equal


def tree_close(a, b) -> bool:
    return all(
        np.allclose(np.asarray(x), np.asarray(y), rtol=1e-6)
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    )


def reference_learn(P, sigma0, acting, m_prev, r, clip=True):
    """SPEC 6-7 without penalty or replacement: score A[acting, m_prev], clip, eq (4), and the
    paper's bounds P in [0, 1] (``clip=False``: eq (4) alone)."""
    P = np.array(P, np.float64)
    P[acting, m_prev] = np.clip(P[acting, m_prev] + r, 0.0, 1.0)
    mean = P.mean(axis=0)
    scale = np.where(mean > 0, np.asarray(sigma0, np.float64) / np.where(mean > 0, mean, 1), 1)
    return np.clip(P * scale, 0.0, 1.0) if clip else P * scale


def column_P(col: int, values, rest: float = 0.5) -> np.ndarray:
    P = np.full((F.X, F.Y), rest)
    P[:, col] = values
    return P


# ---------------------------------------------------------------------------------- RL


def test_rl_scores_the_antibody_that_acted_last_and_only_it():
    # 0 -> 0 scores +0.05 on A[acting=2, m_prev=0]; eq (4) then rescales column 0 to 0.4.
    sys_ = F.system()
    P = column_P(0, [0.2, 0.4, 0.6, 0.3, 0.5])
    out = learn(F.state(sys_, P, acting=2), F.percept(m=0, m_prev=0, t=5), sys_)
    expected = P.copy()
    expected[:, 0] = np.array([0.2, 0.4, 0.65, 0.3, 0.5]) * (0.4 / 0.41)
    np.testing.assert_allclose(P_of(out), expected, rtol=1e-6)

    # Another acting set gets the score instead.
    out3 = learn(F.state(sys_, P, acting=3), F.percept(m=0, m_prev=0, t=5), sys_)
    expected[:, 0] = np.array([0.2, 0.4, 0.6, 0.35, 0.5]) * (0.4 / 0.41)
    np.testing.assert_allclose(P_of(out3), expected, rtol=1e-6)

    # The column scored is the previous antigen's (m_prev = 4, m = 0: 2-7 -> 0 scores +0.10).
    P4 = column_P(4, [0.2, 0.4, 0.6, 0.3, 0.5])
    out4 = learn(F.state(sys_, P4, acting=1), F.percept(m=0, m_prev=4, v=0, v_prev=900, t=5), sys_)
    expected4 = P4.copy()
    expected4[:, 4] = np.array([0.2, 0.5, 0.6, 0.3, 0.5]) * (0.4 / 0.42)
    np.testing.assert_allclose(P_of(out4), expected4, rtol=1e-6)


def test_nothing_is_scored_at_the_first_iteration_or_without_learning():
    P = column_P(0, [0.2, 0.4, 0.6, 0.3, 0.5])
    sys_ = F.system()
    out = learn(F.state(sys_, P, acting=2), F.percept(m=0, m_prev=0, t=0), sys_)
    np.testing.assert_allclose(P_of(out), P, rtol=1e-6)
    off = F.system(learning=False)
    out = learn(F.state(off, P, acting=2), F.percept(m=0, m_prev=0, t=5), off)
    np.testing.assert_array_equal(P_of(out), np.asarray(jnp.float32(P)))


def test_scored_paratope_is_clipped_to_unit_interval_before_rescaling():
    sys_ = F.system()
    # 2 -> 1 scores +0.20; A[0, 2] = 1 stays 1 (unclipped: 1.2, rescaled 1.125).
    P = column_P(2, [1.0, 0.5, 0.5, 0.5, 0.5])
    out = learn(F.state(sys_, P, acting=0), F.percept(m=1, m_prev=2, blue_pixels=3, t=3), sys_)
    np.testing.assert_allclose(P_of(out)[:, 2], [1.0, 0.5, 0.5, 0.5, 0.5], rtol=1e-6)
    # 1 -> 0 scores -0.10; A[0, 1] = 0.05 becomes 0 (unclipped: -0.05, rescaled -0.0526).
    P = column_P(1, [0.05, 0.5, 0.5, 0.5, 0.5])
    out = learn(F.state(sys_, P, acting=0), F.percept(m=0, m_prev=1, t=3), sys_)
    np.testing.assert_allclose(
        P_of(out)[:, 1], [0.0, 0.5125, 0.5125, 0.5125, 0.5125], rtol=1e-6, atol=1e-7
    )


def test_rescale_leaves_an_all_zero_column_alone():
    sys_ = F.system()
    P = column_P(6, 0.0, rest=0.4)
    sigma0 = np.full(F.Y, 0.4)  # column 6 started at 0.4 but is now all 0
    out = learn(F.state(sys_, P, sigma0=sigma0, acting=1), F.percept(m=6, m_prev=6, t=3), sys_)
    assert np.all(np.isfinite(P_of(out)))
    np.testing.assert_array_equal(P_of(out)[:, 6], 0.0)


@hyp
@given(
    seed=seeds,
    acting=st.integers(0, F.X - 1),
    m_prev=antigens,
    m=antigens,
    v_prev=st.floats(0, 4095, width=32),
    v=st.floats(0, 4095, width=32),
    centroid=st.floats(0, 14, width=32),
    t=st.integers(1, 119),
    idiotypic=st.booleans(),
)
def test_learn_matches_reference_and_restores_column_means(
    seed, acting, m_prev, m, v_prev, v, centroid, t, idiotypic
):
    """RL on A[acting, m_prev] only, every P in [0, 1], and every column mean back at sigma0
    where eq (4) alone keeps the column within the bounds."""
    rng = np.random.default_rng(seed)
    P = rng.random((F.X, F.Y)).astype(np.float32)
    P[rng.random((F.X, F.Y)) < 0.15] = rng.choice([0.0, 1.0])  # some entries at the bounds
    sys_ = F.system(idiotypic=idiotypic)
    s = F.state(sys_, P, acting=acting)
    blue = 3 if m == 1 else 0
    pc = F.percept(m=m, m_prev=m_prev, v=v, v_prev=v_prev, blue_pixels=blue, centroid=centroid, t=t)
    out = learn(s, pc, sys_, seed % 97)
    r = float(rl_score(m_prev, m, v_prev, v, centroid))
    sigma0 = P.astype(np.float64).mean(axis=0)
    np.testing.assert_allclose(
        P_of(out), reference_learn(P, sigma0, acting, m_prev, r), rtol=2e-5, atol=1e-6
    )
    assert np.all(P_of(out) >= 0.0) and np.all(P_of(out) <= 1.0)
    within = (reference_learn(P, sigma0, acting, m_prev, r, clip=False) <= 1.0).all(axis=0)
    keep = (sigma0 > 0) & within
    means = P_of(out).mean(axis=0)
    np.testing.assert_allclose(means[keep], sigma0[keep], rtol=2e-5, atol=1e-7)
    # Nothing else learned: no penalty (short runs), no replacement, no new idiotope (t < 120).
    assert tree_equal(out.antibodies, s.antibodies)
    np.testing.assert_array_equal(out.I, s.I)
    assert int(out.replaced) == 0


# ---------------------------------------------------------------------------------- penalties


def _fire_steps(antigen_seq, v=0.0, v_prev=0.0, idiotypic=False) -> list[int]:
    """1-based positions in the run of antigens at which a penalty hit the acting antibody.

    Each iteration is learned twice from the same state: as is, and with the penalty counters
    zeroed (so no penalty can fire); they differ exactly when a penalty fired.
    """
    sys_ = F.system(idiotypic=idiotypic)
    s = F.state(sys_, np.full((F.X, F.Y), 0.5), acting=1)
    fired, m_prev = [], antigen_seq[0]
    for k, m in enumerate(antigen_seq, start=1):
        pc = F.percept(m=m, m_prev=m_prev, v=v, v_prev=v_prev, t=k)
        out = learn(s, pc, sys_)
        calm = learn(s.replace(counters=F.state(sys_, s.P).counters), pc, sys_)
        if not np.allclose(P_of(out), P_of(calm), atol=1e-6):
            fired.append(k)
        s, m_prev = out, m
    return fired


def test_penalty_fires_on_the_251st_consecutive_antigen_0():
    assert _fire_steps([0] * 260) == [251]
    # A "target seen" in between restarts the count.
    assert _fire_steps([0] * 200 + [1] + [0] * 255) == [201 + 251]


def test_penalty_fires_on_the_16th_consecutive_obstacle_antigen_and_repeats():
    # Vm falling (900 < 1000), so the scores within a level are positive and the penalised
    # paratope is well above 0 (the 4 -> 5 step at k = 16 scores -0.225).
    seq = [2, 3, 4] * 5 + [5, 6, 7] * 6
    assert _fire_steps(seq, v=900, v_prev=1000) == [16, 32]
    # Antigen 0 or 1 in between restarts the count.
    seq = [3] * 10 + [1] + [3] * 20
    assert _fire_steps(seq, v=900, v_prev=1000) == [11 + 16]


@pytest.mark.parametrize(
    ("idiotypic", "counters", "m_prev", "m"),
    [
        (True, {"unseen_run": 250}, 0, 0),
        (False, {"unseen_run": 250}, 0, 0),
        (True, {"obstacle_run": 15}, 3, 3),
        (False, {"obstacle_run": 15}, 3, 3),
    ],
)
def test_penalty_size(idiotypic, counters, m_prev, m):
    """0.5 off the scored antibody in idiotypic systems, 1.0 otherwise (clipped at 0), applied
    after eq (4) (the controller's documented order), and the run then restarts."""
    sys_ = F.system(idiotypic=idiotypic)
    P = column_P(m_prev, [0.5, 0.9, 0.5, 0.5, 0.5])
    pc = F.percept(m=m, m_prev=m_prev, v=900, v_prev=1000, t=10)
    fire = learn(F.state(sys_, P, acting=1, **counters), pc, sys_)
    calm = learn(F.state(sys_, P, acting=1), pc, sys_)
    penalty = 0.5 if idiotypic else 1.0
    expected = P_of(calm).copy()
    expected[1, m_prev] = max(expected[1, m_prev] - penalty, 0.0)
    np.testing.assert_allclose(P_of(fire), expected, rtol=1e-6, atol=1e-7)
    assert P_of(calm)[1, m_prev] > 0.9  # the penalty is visible, not hidden by the clip
    assert int(fire.counters.unseen_run) == 0 and int(fire.counters.obstacle_run) == 0


@pytest.mark.parametrize("idiotypic", [True, False])
def test_penalty_sizes_are_the_networks_traced_constants(idiotypic):
    # A sweep sets them per run: the same compiled learn, other numbers.
    sys_ = F.system(idiotypic=idiotypic)
    sys_ = sys_.replace(
        network=sys_.network.replace(penalty_idiotypic=0.25, penalty_non_idiotypic=0.75)
    )
    P = column_P(0, [0.5, 0.9, 0.5, 0.5, 0.5])
    pc = F.percept(m=0, m_prev=0, v=900, v_prev=1000, t=10)
    fire = learn(F.state(sys_, P, acting=1, unseen_run=250), pc, sys_)
    calm = learn(F.state(sys_, P, acting=1), pc, sys_)
    drop = P_of(calm)[1, 0] - P_of(fire)[1, 0]
    assert drop == pytest.approx(0.25 if idiotypic else 0.75, abs=1e-6)


def test_no_penalty_one_iteration_before_the_limit():
    sys_ = F.system()
    P = np.full((F.X, F.Y), 0.5)
    for counters, mp, m in (({"unseen_run": 249}, 0, 0), ({"obstacle_run": 14}, 3, 3)):
        pc = F.percept(m=m, m_prev=mp, v=900, v_prev=1000, t=10)
        near = learn(F.state(sys_, P, acting=1, **counters), pc, sys_)
        calm = learn(F.state(sys_, P, acting=1), pc, sys_)
        np.testing.assert_array_equal(P_of(near), P_of(calm))
        runs = (int(near.counters.unseen_run), int(near.counters.obstacle_run))
        assert runs == ((250, 0) if m == 0 else (0, 15))


# ---------------------------------------------------------------------------------- replacement


def _weak_state(sys_):
    P = np.full((F.X, F.Y), 0.5)
    P[1, 3], P[4, 6] = 0.05, 0.02
    return F.state(sys_, P, acting=0), P


def _changed(a, b) -> np.ndarray:
    """[x, y] bool: antibodies that differ in any field."""
    out = np.zeros(np.shape(a.type), bool)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        out |= np.asarray(x) != np.asarray(y)
    return out


def test_replacement_one_weak_antibody_per_iteration():
    sys_ = F.system(replacement=True)
    s, P = _weak_state(sys_)
    pc = F.percept(m=0, m_prev=0, t=7)  # scores A[0, 0]; columns 3 and 6 untouched
    seen = []
    for step, key_seed in enumerate((11, 12, 13)):
        # learn's one draw from its key: the idiotope's x * y values, then the new antibody's
        # type and six attributes, then its P's uniform.
        u = jax.random.uniform(jax.random.key(key_seed), (F.X * F.Y + 8,))[F.X * F.Y :]
        out = learn(s, pc, sys_, key_seed)
        changed = _changed(out.antibodies, s.antibodies)
        seen.append(np.argwhere(changed).tolist())
        if step < 2:
            (i, j) = [(1, 3), (4, 6)][step]
            assert changed.sum() == 1 and changed[i, j]
            new = take(out.antibodies, (i, j))
            assert bool(within_limits(new))
            assert tree_close(new, from_uniforms(u[:7]))
            assert 0.25 <= P_of(out)[i, j] <= 0.75
            np.testing.assert_allclose(P_of(out)[i, j], 0.25 + 0.5 * float(u[7]), rtol=1e-6)
        assert int(out.replaced) == min(step + 1, 2)
        s = out
    assert seen == [[[1, 3]], [[4, 6]], []]
    assert np.all(P_of(s) >= 0.1)


@pytest.mark.parametrize(
    "switches", [{"replacement": False}, {"replacement": True, "learning": False}]
)
def test_no_replacement_without_the_flag_or_without_learning(switches):
    sys_ = F.system(**switches)
    s, P = _weak_state(sys_)
    out = learn(s, F.percept(m=0, m_prev=0, t=7), sys_, 11)
    assert tree_equal(out.antibodies, s.antibodies)
    assert P_of(out)[1, 3] < 0.1 and P_of(out)[4, 6] < 0.1
    assert int(out.replaced) == 0


@hyp
@given(seed=seeds, row=st.integers(0, F.X - 1), col=antigens)
def test_replacement_is_a_valid_antibody_with_p_in_range(seed, row, col):
    sys_ = F.system(replacement=True)
    P = np.full((F.X, F.Y), 0.5)
    P[row, col] = 0.0
    out = learn(F.state(sys_, P, acting=row), F.percept(m=0, m_prev=0, t=3), sys_, seed)
    assert bool(within_limits(take(out.antibodies, (row, col))))
    assert 0.25 <= P_of(out)[row, col] <= 0.75
    assert _changed(out.antibodies, sys_.antibodies).sum() <= 1


# ---------------------------------------------------------------------------------- HDC


def test_hdc_never_learns_and_always_acts_with_set_0():
    hdc = F.systems()["HDC"].replace(readings=jax.tree.map(jnp.asarray, LITERAL))
    s0 = F.state(hdc, hdc.paratopes)
    rng = np.random.default_rng(5)
    # Long runs of 0 and of obstacles (penalties would fire) then random antigens; t crosses
    # the idiotope period twice.
    seq = [0] * 260 + [3] * 20 + rng.integers(0, 8, 40).tolist()
    s, m_prev = s0, 0
    for k, m in enumerate(seq, start=1):
        pc = F.percept(m=m, m_prev=m_prev, v=500.0 * (m > 1), v_prev=500.0 * (m_prev > 1), t=k)
        s = learn(s, pc, hdc, k)
        s, _ = act(s, pc, hdc, k)
        assert int(s.acting) == 0
        m_prev = m
    np.testing.assert_array_equal(s.P, s0.P)
    assert tree_equal(s.antibodies, s0.antibodies)
    np.testing.assert_array_equal(s.N, s0.N)
    assert int(s.differences) == 0 and int(s.replaced) == 0 and int(s.selections) == len(seq)


# ---------------------------------------------------------------------------------- selection


@hyp
@given(seed=seeds, m=antigens, blue=st.integers(0, 45), centroid=st.floats(0, 14, width=32))
def test_non_idiotypic_selection_acts_with_alpha(seed, m, blue, centroid):
    sys_ = F.system(idiotypic=False)
    rng = np.random.default_rng(seed)
    s = F.state(sys_, rng.random((F.X, F.Y)), I=np.eye(F.X, F.Y), bout_key=101)
    pc = F.percept(m=m, blue_pixels=blue, centroid=centroid)
    out, wheels = act(s, pc, sys_, seed % 101)
    alpha = int(np.argmax(np.asarray(s.P)[:, m]))
    assert int(out.acting) == alpha
    np.testing.assert_array_equal(out.N, s.N)
    assert int(out.differences) == 0 and int(out.selections) == 1
    # The winner's behaviour drives the wheels with fresh numbers: what wheel_speeds draws from
    # the act's key.
    assert not tree_equal(out.bout.u, s.bout.u)
    ab = take(sys_.antibodies, (alpha, m))
    expected = wheel_speeds(
        jax.random.uniform(jax.random.key(seed % 101), (2,)), ab, blue, centroid
    )
    np.testing.assert_allclose(np.asarray(wheels), np.asarray(expected), rtol=1e-6)


def test_ties_in_stage_1_are_broken_at_random():
    sys_ = F.system(idiotypic=False)
    s = F.state(sys_, np.full((F.X, F.Y), 0.5))
    chosen = {int(act(s, F.percept(m=2), sys_, k)[0].acting) for k in range(40)}
    assert chosen == set(range(F.X))


@pytest.mark.parametrize("idiotypic", [False, True])
def test_the_selections_tie_breaks_are_not_the_new_bouts_numbers(idiotypic):
    """One draw per act serves the new bout's behaviour and the selection's tie-breaks, from
    separate values: with every set tied, the set chosen says nothing about the bout's numbers.
    (Were they shared, set n would win only when its value is the largest of X: a mean of
    X / (X + 1), not 1/2.)"""
    sys_ = F.system(idiotypic=idiotypic)
    s = F.state(sys_, np.full((F.X, F.Y), 0.5))
    outs = [act(s, F.percept(m=2), sys_, k)[0] for k in range(200)]
    chosen = np.array([int(o.acting) for o in outs])
    u = np.array([np.asarray(o.bout.u) for o in outs])
    for n in range(2):
        assert np.sum(chosen == n) > 20
        assert abs(u[chosen == n, n].mean() - 0.5) < 0.15


def reference_select(P, I, N, m, k1=0.85, k2=1.10, b=100.0, k3=0.0, Phi=25.0):
    """Eqs (5)-(10) for one antigen m (float64, no ties assumed); alpha acts on the other sets
    only (section 4.3), so its own eps and delta are 0."""
    P, I, N = (np.asarray(a, np.float64) for a in (P, I, N))
    C = Phi * N / N.sum() if N.sum() > 0 else np.zeros_like(N)
    n = int(np.argmax(P[:, m]))
    others = np.arange(P.shape[0]) != n
    eps = others * k1 * np.sum((1 - P) * I[n] * C * C[n], axis=1)
    delta = others * k2 * np.sum(P[n] * I * C * C[n], axis=1)
    s2 = P[:, m] + eps - delta
    N2 = N.copy()
    N2[:, m] = np.maximum(b * s2 + N[:, m] * (1 - k3), 0.0)
    C2 = Phi * N2 / N2.sum() if N2.sum() > 0 else np.zeros_like(N2)
    activation = C2[:, m] * s2
    return n, int(np.argmax(activation)), N2, activation


@hyp
@given(seed=seeds, m=antigens)
def test_idiotypic_selection_matches_reference_and_counts_differences(seed, m):
    sys_ = F.system(idiotypic=True)
    rng = np.random.default_rng(seed)
    P = rng.random((F.X, F.Y))
    I = np.zeros((F.X, F.Y))
    has = rng.random(F.X) < 0.8
    I[np.arange(F.X)[has], rng.integers(0, F.Y, F.X)[has]] = 1.0
    N = rng.uniform(0, 3000, (F.X, F.Y))
    s = F.state(sys_, P, I=I, N=N)
    out, _ = act(s, F.percept(m=m), sys_, seed % 89)
    alpha, beta, N2, activation = reference_select(np.float32(P), I, np.float32(N), m)
    top2 = np.sort(activation)[-2:]
    if top2[1] - top2[0] > 1e-4 * max(abs(top2[1]), 1e-3):  # no near-tie in eq (10)
        assert int(out.acting) == beta
    assert int(out.differences) == int(alpha != int(out.acting))
    np.testing.assert_allclose(np.asarray(out.N), N2, rtol=1e-4, atol=1e-2)
    assert np.all(np.asarray(out.N) >= 0)
    np.testing.assert_array_equal(np.delete(np.asarray(out.N), m, 1), np.delete(s.N, m, 1))


def test_idiotypic_stimulation_can_overturn_alpha():
    """Hand-worked: alpha = set 0 (P 0.6) has its idiotope on antigen 5, where set 1's paratope
    is 0: set 1 is stimulated (eps_1 = 0.85 * 0.625^2 = 0.332) past alpha, whose own S2 stays
    its P (alpha acts on the others only), so beta = set 1 (S2 0.83 vs 0.6)."""
    P = np.full((F.X, F.Y), 0.2)
    P[0, 2], P[1, 2] = 0.6, 0.5
    P[0, 5], P[1, 5] = 1.0, 0.0
    I = np.zeros((F.X, F.Y))
    I[0, 5] = 1.0
    for idiotypic, acting, differences in ((True, 1, 1), (False, 0, 0)):
        sys_ = F.system(idiotypic=idiotypic)
        out, _ = act(F.state(sys_, P, I=I), F.percept(m=2), sys_)
        assert (int(out.acting), int(out.differences)) == (acting, differences)
    out, _ = act(
        F.state(F.system(idiotypic=True), P, I=I), F.percept(m=2), F.system(idiotypic=True)
    )
    np.testing.assert_allclose(float(out.N[1, 2]), 1000 + 100 * (0.5 + 0.85 * 0.625**2), rtol=1e-5)
    np.testing.assert_allclose(float(out.N[0, 2]), 1000 + 100 * 0.6, rtol=1e-5)


def test_clone_counts_are_floored_at_zero_under_sustained_suppression():
    """Sets 1-4 are suppressed by alpha (S2 = 0.05 - 0.43 < 0) every iteration; unfloored their
    clones for antigen 2 would go below 0 after about 27 iterations."""
    sys_ = F.system(idiotypic=True)
    P = np.full((F.X, F.Y), 1.0)
    P[:, 2] = [0.9, 0.05, 0.05, 0.05, 0.05]
    I = np.zeros((F.X, F.Y))
    I[1:, 5] = 1.0
    s = F.state(sys_, P, I=I)
    for k in range(40):
        s, _ = act(s, F.percept(m=2), sys_, k)
        assert np.all(np.asarray(s.N) >= 0)
    np.testing.assert_array_equal(np.asarray(s.N)[1:, 2], 0.0)
    assert float(s.N[0, 2]) > 1000


# ---------------------------------------------------------------------------------- idiotope


def test_idiotope_is_recomputed_only_every_period():
    """Eq (3) is redrawn when the batch tick is a positive multiple of the period, from
    learn's key, on the paratopes after this iteration's learning."""
    sys_ = F.system()
    period = sys_.network.idiotope_period
    assert period == 120
    rng = np.random.default_rng(3)
    P = rng.random((F.X, F.Y))
    stale = np.ones((F.X, F.Y))  # not an eq (3) idiotope: recomputation is visible
    for t in (0, 1, 60, 119, 121, 239, 241, 359):
        out = learn(F.state(sys_, P, I=stale), F.percept(m=0, m_prev=0, t=t), sys_, t)
        np.testing.assert_array_equal(out.I, stale, err_msg=f"t={t}")
    draws = set()
    for t in (120, 240, 360):
        out = learn(F.state(sys_, P, I=stale), F.percept(m=0, m_prev=0, t=t), sys_, t)
        I = np.asarray(out.I)
        assert np.all(I.sum(axis=1) <= 1), t
        np.testing.assert_array_equal(I, idiotopes(jax.random.key(t), out.P))
        draws.add(I.tobytes())
    assert len(draws) > 1  # a fresh draw each period


def test_idiotope_follows_the_batch_tick():
    sys_ = F.system()
    P = np.random.default_rng(4).random((F.X, F.Y))
    stale = np.ones((F.X, F.Y))
    due = learn(F.state(sys_, P, I=stale), F.percept(m=0, m_prev=0, t=7, tick=240), sys_)
    assert not np.array_equal(due.I, stale)
    not_due = learn(F.state(sys_, P, I=stale), F.percept(m=0, m_prev=0, t=240, tick=7), sys_)
    np.testing.assert_array_equal(not_due.I, stale)


@hyp
@given(seed=seeds, k=st.integers(1, 5))
def test_recomputed_idiotope_has_at_most_one_per_set_below_the_column_mean(seed, k):
    sys_ = F.system()
    rng = np.random.default_rng(seed)
    P = rng.choice([0.0, 0.25, 0.5, 1.0], (F.X, F.Y)) * rng.random()
    out = learn(F.state(sys_, P), F.percept(m=1, m_prev=1, t=120 * k), sys_, seed % 83)
    I, Pn = np.asarray(out.I), np.asarray(out.P)
    assert set(np.unique(I)) <= {0.0, 1.0}
    assert np.all(I.sum(axis=1) <= 1)
    # Candidates lie below their column mean (a relative ulp of slack for the float mean).
    assert np.all(Pn[I == 1] < Pn.mean(axis=0)[np.nonzero(I)[1]] * (1 + 1e-6))


# ---------------------------------------------------------------------------------- our readings


def _bout_system(hold: int = 4):
    return F.system(readings=readings(hold=hold))


def test_a_selected_behaviour_acts_for_its_bout_then_is_selected_again():
    """With hold h the antibody selected for an antigen keeps acting, with the behaviour
    numbers of its selection (what wheel_speeds draws from that act's key), for h iterations
    (SPEC 5 [ours]); calmer antigens do not cut it short."""
    sys_ = _bout_system(hold=4)
    P = np.full((F.X, F.Y), 0.5)
    P[3, 5] = 0.9  # set 3 wins antigen 5 (collision right), set 1 antigen 0
    P[1, 0] = 0.9
    s = F.state(sys_, P)
    wheels = []
    # A collision selects A[3, 5]; the robot then backs away: 2 (obstacle) and 0 (clear) follow.
    for k, m in enumerate([5, 2, 0, 0, 0, 0], start=1):
        s, w = act(s, F.percept(m=m, t=k), sys_, key_seed=k)
        wheels.append(np.asarray(w))
        assert int(s.acting) == (3 if k <= 4 else 1)
        assert int(s.bout.antigen) == (5 if k <= 4 else 0)
        if k == 1:
            bout_u = s.bout.u
        assert tree_equal(s.bout.u, bout_u) == (k <= 4)
    assert int(s.selections) == 2
    expected = wheel_speeds(
        jax.random.uniform(jax.random.key(1), (2,)), take(sys_.antibodies, (3, 5)), 0, 7.0
    )
    for w in wheels[:4]:  # the behaviour acts on the numbers of its selection's key
        np.testing.assert_allclose(w, expected, rtol=1e-6)


@pytest.mark.parametrize(
    ("held", "m", "cut"),
    [(0, 1, True), (0, 3, True), (1, 0, False), (2, 6, True), (2, 4, True), (6, 2, False),
     (6, 6, False), (6, 7, True), (5, 0, False), (3, 3, False)],
)  # fmt: skip
def test_urgent_antigens_interrupt_a_bout(held, m, cut):
    assert bool(interrupts(jnp.int32(m), jnp.int32(held))) == cut


def test_rl_scores_the_held_antibody_after_the_antigen_changed():
    """During a bout selected for antigen 5, the scored entry is A[acting, 5], whatever the
    previous antigen was."""
    sys_ = _bout_system()
    P = column_P(5, [0.2, 0.4, 0.6, 0.3, 0.5])
    s = F.state(sys_, P, acting=2, held=5, left=2)
    out = F.learn_fn()(jax.random.key(0), s, F.percept(m=0, m_prev=2, v=0, v_prev=900, t=5), sys_)
    expected = P.copy()
    expected[:, 5] = np.array([0.2, 0.4, 0.7, 0.3, 0.5]) * (0.4 / 0.42)  # 2-7 -> 0: +0.10
    np.testing.assert_allclose(P_of(out), expected, rtol=1e-6)


def test_sigma0_floor_keeps_a_zero_column_learnable():
    """A column whose initial mean is 0 is pinned at 0 by the literal eq (4); with the floor
    its scored antibody keeps a positive P (SPEC 7 [ours])."""
    seeded = F.systems()["SIE"]
    P0 = np.asarray(seeded.paratopes).copy()
    P0[:, 1] = 0.0
    runs = {}
    for floor in (0.0, 0.05):
        sys_ = seeded.replace(paratopes=jnp.asarray(P0), readings=readings(sigma0_floor=floor))
        s = F.init_fn()(jax.random.key(0), sys_)
        assert float(s.sigma0[1]) == pytest.approx(floor)
        s = s.replace(acting=jnp.int32(2), bout=s.bout.replace(antigen=jnp.int32(1)))
        pc = F.percept(m=1, m_prev=0, t=3)  # 0 -> 1 scores +0.10 on A[2, 1]
        runs[floor] = P_of(F.learn_fn()(jax.random.key(0), s, pc, sys_))[:, 1]
    np.testing.assert_array_equal(runs[0.0], 0.0)
    np.testing.assert_allclose(runs[0.05], [0, 0, 0.25, 0, 0], atol=1e-6)


def test_encounter_penalty_catches_a_robot_hovering_at_a_wall():
    """Antigen 2 every other iteration (a robot at the threshold): 16 encounters penalise the
    acting antibody under our reading; the literal count never does (SPEC 6)."""
    P = np.full((F.X, F.Y), 0.5)
    fired = {}
    for count in (True, False):
        sys_ = F.system(readings=readings(hold=1, count_encounters=count))
        s, m_prev, hits = F.state(sys_, P, acting=1), 0, []
        for k, m in enumerate([2, 0] * 20, start=1):
            pc = F.percept(m=m, m_prev=m_prev, v=300.0 * (m > 1), v_prev=300.0 * (m_prev > 1), t=k)
            s = learn(s, pc, sys_)
            if k > 1 and int(s.counters.obstacle_run) == 0 and m == 2:
                hits.append(k)
            m_prev = m
        fired[count] = hits
    assert fired[True] == [31] and fired[False] == []


def test_a_penalty_ends_the_bout_so_the_network_selects_again():
    """After 250 iterations of antigen 0 the acting antibody is penalised and its bout ends: the
    next act selects again (another set), instead of letting the rest of the bout's rewards
    undo the penalty (SPEC 6-7 [ours])."""
    sys_ = _bout_system(hold=31)
    P = np.full((F.X, F.Y), 0.5)
    P[0, 0], P[1, 0] = 1.0, 0.9  # set 0 wins antigen 0, set 1 is next
    s = F.state(sys_, P, acting=0, held=0, left=20, unseen_run=250)
    s = F.learn_fn()(jax.random.key(0), s, F.percept(m=0, m_prev=0, t=300), sys_)
    assert int(s.bout.left) == 0 and float(s.P[0, 0]) < float(s.P[1, 0])
    s, _ = act(s, F.percept(m=0, t=300), sys_)
    assert int(s.acting) == 1 and int(s.bout.left) == 30
    # Without a penalty the bout runs on.
    calm = F.state(sys_, P, acting=0, held=0, left=20, unseen_run=10)
    calm = F.learn_fn()(jax.random.key(0), calm, F.percept(m=0, m_prev=0, t=300), sys_)
    calm, _ = act(calm, F.percept(m=0, t=300), sys_)
    assert int(calm.acting) == 0 and int(calm.bout.left) == 19


def test_choices_record_the_set_last_selected_for_each_antigen():
    # Non-idiotypic, literal readings: each act selects; alpha is the set with the highest P
    # for the antigen presented, and choices() holds it in that antigen's entry only.
    sys_ = F.system(base="UIE-R1")
    P = np.full((F.X, F.Y), 0.5, np.float32)
    P[3, 5], P[1, 0] = 0.9, 0.8
    s = F.state(sys_, P)
    np.testing.assert_array_equal(STL.choices(s), np.full(F.Y, -1))
    s, _ = act(s, F.percept(5), sys_)
    want = np.full(F.Y, -1)
    want[5] = 3
    np.testing.assert_array_equal(STL.choices(s), want)
    s, _ = act(s, F.percept(0, m_prev=5), sys_)
    want[0] = 1
    np.testing.assert_array_equal(STL.choices(s), want)
    assert int(s.acting) == 1
