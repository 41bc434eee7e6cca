"""Controllers built on the shared task loop (:mod:`jaxais.episode`).

- :func:`ltl_controller`: one antibody set acting alone with RL accumulating each antibody's
  score L (the GA's evaluation, SPEC 10).
- :func:`stl_controller`: the short-term learning network of SPEC 7 over five sets; a
  :class:`System` (its params) says whether it learns, whether selection is idiotypic and whether
  weak antibodies are replaced, so SIE, SRL, UIE, URL and HDC are one program with different data
  and can share one compiled batch; :func:`stl_for` leaves out the parts a batch does not use.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxais import prng
from jaxais.antibodies import Antibodies, antibodies_from_uniform, take
from jaxais.behaviours import wheel_speeds_from_uniform
from jaxais.envs.struct import pytree_dataclass
from jaxais.episode import Controller, Percept
from jaxais.network import (
    NetworkParams,
    idiotopes,
    idiotypic_select_from_uniform,
    rescale_paratopes,
    select_alpha_from_uniform,
)
from jaxais.reinforcement import (
    PENALTY_NON_IDIOTYPIC,
    PenaltyCounters,
    init_counters,
    penalty_size,
    rl_score,
    update_penalty,
)

L_MAX = 100.0
"""Upper clip of an antibody's cumulative RL score L in the LTL [ours, consistent with φ = 20]."""
REPLACE_BELOW = 0.1
"""Unseeded systems replace antibodies whose paratope falls below this [paper]."""
REPLACEMENT_P = (0.25, 0.75)
"""Range of a replacement antibody's paratope [ours, as the unseeded initial P]."""


def _scored(shape: tuple[int, ...], index: tuple[jnp.ndarray, ...]) -> jnp.ndarray:
    """Boolean mask of one entry: a one-hot compare, cheaper than a scatter in a batched loop."""
    grids = jnp.meshgrid(*[jnp.arange(n) for n in shape], indexing="ij")
    mask = jnp.ones(shape, bool)
    for g, i in zip(grids, index, strict=True):
        mask = mask & (g == i)
    return mask


# ---------------------------------------------------------------------------------- LTL


@pytree_dataclass
class LTLState:
    """A GA robot during its run: its set [8], the scores L [8] and the penalty counters."""

    antibodies: Antibodies
    L: jnp.ndarray
    counters: PenaltyCounters


def ltl_controller() -> Controller:
    """One set, no idiotypic selection: the antibody for the antigen acts; RL accumulates L.

    Params: an :class:`Antibodies` set [8]. L_ij is the cumulative RL score of antibody j,
    clipped to [0, L_MAX] after every update; penalties subtract the non-idiotypic 1.0.
    """

    def init(key, antibodies):
        del key
        n = antibodies.type.shape[0]
        return LTLState(antibodies=antibodies, L=jnp.zeros(n), counters=init_counters())

    def learn(u, state: LTLState, pc: Percept, antibodies):
        del u, antibodies
        scored = _scored(state.L.shape, (pc.m_prev,)) & (pc.t > 0)
        counters, fire = update_penalty(state.counters, pc.m)
        r = rl_score(pc.m_prev, pc.m, pc.v_prev, pc.v, pc.centroid)
        r = r - jnp.where(fire, PENALTY_NON_IDIOTYPIC, 0.0)
        L = jnp.where(scored, jnp.clip(state.L + r, 0.0, L_MAX), state.L)
        return state.replace(L=L, counters=counters)

    def act(u, state: LTLState, pc: Percept, antibodies):
        del antibodies
        ab = take(state.antibodies, pc.m)
        return state, wheel_speeds_from_uniform(u, ab, pc.blue_pixels, pc.centroid)

    return Controller(init=init, learn=learn, act=act, n_uniform=lambda params: 2)


# ---------------------------------------------------------------------------------- STL


@pytree_dataclass
class System:
    """One STL system as data (see :mod:`jaxais.systems` for SIE, SRL, UIE, URL, HDC).

    Attributes:
        antibodies: [x, y] the initial sets.
        paratopes: [x, y] initial P.
        learning: RL, eq (4) and penalties on (off for the hand-designed controller).
        idiotypic: three-stage idiotypic selection (eqs 5-10) rather than stage 1 alone.
        replacement: replace antibodies with P < 0.1 (unseeded systems).
        network: the network constants.
    """

    antibodies: Antibodies
    paratopes: jnp.ndarray
    learning: jnp.ndarray
    idiotypic: jnp.ndarray
    replacement: jnp.ndarray
    network: NetworkParams


@pytree_dataclass
class STLState:
    """The network during a run.

    Attributes:
        antibodies: [x, y] current sets (replacement changes them).
        P: [x, y] paratopes. sigma0: [y] initial column means (eq 4). I: [x, y] idiotopes.
        N: [x, y] clone counts. counters: penalty runs.
        acting: set index of the antibody that acted last (scored at the next iteration).
        differences: iterations with alpha != beta. selections: iterations selected.
        replaced: antibodies replaced so far.
        key: PRNG key of the periodic idiotope draws.
    """

    antibodies: Antibodies
    P: jnp.ndarray
    sigma0: jnp.ndarray
    I: jnp.ndarray
    N: jnp.ndarray
    counters: PenaltyCounters
    acting: jnp.ndarray
    differences: jnp.ndarray
    selections: jnp.ndarray
    replaced: jnp.ndarray
    key: jax.Array


def stl_controller(
    replacement: bool = True, idiotypic: bool = True, learning: bool = True
) -> Controller:
    """The STL network: per iteration RL on the antibody that acted last, eq (4), penalties,
    replacement (unseeded), the idiotope every ``idiotope_period`` iterations, then selection
    (stage 1, or stages 1-3 when idiotypic) and the winner's behaviour.

    Replacement [ours on the detail]: at most one antibody per iteration, the first (in set,
    antigen order) whose P is below 0.1; any others follow on later iterations.

    Args:
        replacement, idiotypic, learning: build that part of the network in (default: all of
            them, which runs every system). A batch in which no run uses a part (its
            ``System`` flag False throughout) gives the same trials without it, from a smaller
            and faster program; :func:`stl_for` picks the smallest controller for a batch.
            Measured for 30 SIE trials in world1 on a 2-core CPU, without replacement:
            11.0-11.6 s -> 9.7-10.8 s to compile, about 15 % less time per iteration. Checked:
            30 trials of each system in world1 alone give the very means (and SIE the very
            trials) of a run with the full controller.
    """

    def init(key, system: System):
        P = jnp.asarray(system.paratopes, jnp.float32)
        k_idiotope, key = jax.random.split(key)
        return STLState(
            antibodies=system.antibodies,
            P=P,
            sigma0=jnp.mean(P, axis=0),
            I=idiotopes(k_idiotope, P),
            N=jnp.full(P.shape, system.network.initial_clones, jnp.float32),
            counters=init_counters(),
            acting=jnp.int32(0),
            differences=jnp.int32(0),
            selections=jnp.int32(0),
            replaced=jnp.int32(0),
            key=key,
        )

    def draws(system: System):
        """Layout of one iteration's uniforms: (name, size) in order."""
        x = system.paratopes.shape[-2]
        return (("new", 7), ("new_p", 1), ("select", 2 * x), ("behave", 2))

    def n_uniform(system: System) -> int:
        return sum(n for _, n in draws(system))

    def split(u, system: System) -> dict:
        out, start = {}, 0
        for name, n in draws(system):
            out[name], start = u[start : start + n], start + n
        return out

    def learn(u, s: STLState, pc: Percept, system: System):
        u = split(u, system)
        P, antibodies, replaced = s.P, s.antibodies, s.replaced
        if not learning:  # no run in the batch learns: only the penalty counters move
            counters, _ = update_penalty(s.counters, pc.m)
        else:
            on = system.learning
            scored = _scored(s.P.shape, (s.acting, pc.m_prev)) & (pc.t > 0) & on
            r = rl_score(pc.m_prev, pc.m, pc.v_prev, pc.v, pc.centroid)
            P = jnp.where(scored, jnp.clip(s.P + r, 0.0, 1.0), s.P)
            # Eq (4), then the paper's bounds: "the maximum P allowed is 1.00, the minimum 0.00"
            # (the rescale alone can lift an entry above 1; column means then fall a little short
            # of sigma0, and only while the bound binds).
            P = jnp.where(on, jnp.clip(rescale_paratopes(P, s.sigma0), 0.0, 1.0), P)
            counters, fire = update_penalty(s.counters, pc.m)
            P = jnp.where(scored & fire, jnp.clip(P - penalty_size(system.idiotypic), 0.0, 1.0), P)
            if replacement:  # only a learning run replaces
                weak = (P < REPLACE_BELOW) & system.replacement & on
                first = _scored(P.shape, jnp.unravel_index(jnp.argmax(weak), P.shape))
                first = first & jnp.any(weak)
                fresh = antibodies_from_uniform(u["new"])
                antibodies = jax.tree.map(
                    lambda old, new: jnp.where(first, new, old), antibodies, fresh
                )
                lo, hi = REPLACEMENT_P
                P = jnp.where(first, lo + (hi - lo) * u["new_p"][0], P)
                replaced = replaced + jnp.any(weak).astype(jnp.int32)

        # The idiotope is redrawn every idiotope_period iterations. The test is on the batch's
        # tick (unbatched), so under vmap this stays a branch taken once per period. Its draw
        # uses the unrolled hash: the same numbers, without rolled loops in the branch.
        due = (pc.tick % system.network.idiotope_period == 0) & (pc.tick > 0)
        I = jax.lax.cond(
            due,
            lambda: idiotopes(jax.random.fold_in(prng.unrolled(s.key), pc.tick), P),
            lambda: s.I,
        )
        return s.replace(
            antibodies=antibodies,
            P=P,
            I=I,
            counters=counters,
            replaced=replaced,
        )

    def act(u, s: STLState, pc: Percept, system: System):
        u = split(u, system)
        tiebreaks = u["select"].reshape(2, -1)
        if idiotypic:
            alpha, beta, N = idiotypic_select_from_uniform(
                tiebreaks, s.P, s.I, s.N, pc.m, system.network
            )
            idio = system.idiotypic
            acting = jnp.where(idio, beta, alpha)
            ab = take(s.antibodies, (acting, pc.m))
            s = s.replace(
                N=jnp.where(idio, N, s.N),
                acting=acting,
                differences=s.differences + (idio & (alpha != beta)).astype(jnp.int32),
                selections=s.selections + 1,
            )
        else:  # no run in the batch is idiotypic: stage 1 alone, the clones never change
            acting = select_alpha_from_uniform(tiebreaks[0], s.P, pc.m)
            ab = take(s.antibodies, (acting, pc.m))
            s = s.replace(acting=acting, selections=s.selections + 1)
        return s, wheel_speeds_from_uniform(u["behave"], ab, pc.blue_pixels, pc.centroid)

    return Controller(init=init, learn=learn, act=act, n_uniform=n_uniform)


LTL = ltl_controller()
"""The GA's controller (one shared instance, so compiled programs are reused)."""


@functools.cache
def _stl(replacement: bool, idiotypic: bool, learning: bool) -> Controller:
    # One instance per variant: compiled programs are cached by controller.
    return stl_controller(replacement, idiotypic, learning)


def stl_for(systems: System) -> Controller:
    """The smallest STL controller that runs every system of a batch (flags [n]), shared."""
    return _stl(
        *(bool(np.any(f)) for f in (systems.replacement, systems.idiotypic, systems.learning))
    )


STL = _stl(True, True, True)
"""The STL network controller, every part built in (one shared instance)."""
