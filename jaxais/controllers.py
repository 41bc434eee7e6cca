"""Controllers: the protocol the task loop (:mod:`jaxais.loop`) runs, and the controllers.

A :class:`Controller` is a tuple of pure functions of one robot, key first (like optax's
``(init, update)``); its params are its own pytree, so a batch of robots differs in data under one
compiled program, and a new controller plugs in without touching the loop.

- :func:`ltl_controller`: one set acting alone, RL accumulating each antibody's L (SPEC 10).
- :func:`stl_controller`: the STL network of SPEC 7 over five sets; a :class:`System` says what
  learns, so SIE, SRL, UIE, URL and HDC share one compiled batch.
- :func:`braitenberg_controller`: a Braitenberg vehicle, a reactive baseline [ours], written
  with :mod:`jaxais.perception`'s helpers as a new controller would be.

On CPU each threefry draw is a loop of its own, so learn and act draw at most once per iteration
and slice the draw (a draw's first k values are the k-value draw from the same key).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxais.envs.struct import pytree_dataclass
from jaxais.immune.antibodies import N_ATTRIBUTES, Antibodies, from_uniforms, take
from jaxais.immune.antigens import severity
from jaxais.immune.behaviours import wheel_speeds
from jaxais.immune.network import (
    Interaction,
    NetworkParams,
    idiotopes,
    idiotypic_select,
    initial_clones,
    rescale_paratopes,
    select_alpha,
    stimulation_suppression,
)
from jaxais.immune.readings import DEFAULT, Readings
from jaxais.immune.reinforcement import (
    PENALTY_NON_IDIOTYPIC,
    PenaltyCounters,
    init_counters,
    penalty_size,
    rl_score,
    update_penalty,
)
from jaxais.perception import RIGHT, SENSOR_SIDE, centroid_offset, clip_wheels, proximity

# ----------------------------------------------------------------------------- the protocol


@pytree_dataclass
class Percept:
    """What a controller sees at one iteration (scalars but ``ir`` [8]).

    Attributes:
        m, m_prev, v, v_prev: antigen and Vm now and before (m_prev = 0 at t = 0).
        blue_pixels, centroid: blue pixels and their mean column (7 when none).
        t: iterations of the run. tick: the batch's clock, one for all its runs, so a
            periodic step is a ``lax.cond`` that stays a branch under ``vmap``; in a pool
            (:func:`jaxais.runner.run_pool`) it may jump between segments, and a run starts on
            a multiple of the pool's align, so ``tick - t`` stays that multiple throughout a run.
    """

    m: jnp.ndarray
    m_prev: jnp.ndarray
    v: jnp.ndarray
    v_prev: jnp.ndarray
    ir: jnp.ndarray
    blue_pixels: jnp.ndarray
    centroid: jnp.ndarray
    t: jnp.ndarray
    tick: jnp.ndarray


class Controller(NamedTuple):
    """A controller as pure functions of one robot, key first; build each once (compiled
    programs are cached by identity).

    - ``init(key, params) -> state``; ``learn(key, state, percept, params) -> state``;
      ``act(key, state, percept, params) -> (state, wheels [2])``;
    - ``stats(state, params) -> dict`` (optional): what a run records beyond the loop's counts;
    - ``choices(state) -> [k] int32`` (optional): the choice per situation, -1 before any; the
      loop measures lock-ups with it.
    """

    init: Callable[..., Any]
    learn: Callable[..., Any]
    act: Callable[..., Any]
    stats: Callable[..., dict[str, Any]] | None = None
    choices: Callable[..., jnp.ndarray] | None = None


def no_state(key, params):
    """A stateless controller's ``init``: a scalar keeps the loop's pytrees non-empty."""
    del key, params
    return jnp.int32(0)


def no_learning(key, state, percept, params):
    """A controller's ``learn`` that learns nothing."""
    del key, percept, params
    return state


# --------------------------------------------------------------- the immune controllers' bouts

L_MAX = 100.0  # upper clip of the LTL's cumulative score L [ours, consistent with φ = 20]
REPLACE_BELOW = 0.1  # unseeded systems replace antibodies with a lower P [paper]
REPLACEMENT_P = (0.25, 0.75)  # a replacement's P range [ours, as the unseeded initial P]


def _scored(shape: tuple[int, ...], index: tuple[jnp.ndarray, ...]) -> jnp.ndarray:
    """Boolean mask of one entry: a one-hot compare, cheaper than a scatter in a batched loop."""
    grids = jnp.meshgrid(*[jnp.arange(n) for n in shape], indexing="ij")
    mask = jnp.ones(shape, bool)
    for g, i in zip(grids, index, strict=True):
        mask = mask & (g == i)
    return mask


def _level(m: jnp.ndarray) -> jnp.ndarray:
    """0 target unseen, 1 target seen, 2 obstacle, 3 collision: SPEC 6's lev, seen above unseen."""
    return severity(m) + jnp.minimum(m, 1)


def interrupts(m: jnp.ndarray, held: jnp.ndarray) -> jnp.ndarray:
    """Does antigen ``m`` cut short the bout selected for antigen ``held``? [ours] A more urgent
    level or an obstacle on another side does; a calmer one lets a reverse turn back out."""
    level, held_level = _level(m), _level(held)
    return (level > held_level) | ((level == held_level) & (level >= 2) & (m != held))


@pytree_dataclass
class Bout:
    """The behaviour acting now, for ``Readings.hold`` iterations (SPEC 5): selected for
    ``antigen``, ``left`` iterations to go, its uniforms ``u`` [2] kept all bout (a wander's
    turn decision holds)."""

    antigen: jnp.ndarray
    left: jnp.ndarray
    u: jnp.ndarray


def _init_bout() -> Bout:
    """A bout that has ended (the first act selects)."""
    return Bout(antigen=jnp.int32(0), left=jnp.int32(0), u=jnp.zeros(2))


def _end_if(bout: Bout, penalised: jnp.ndarray) -> Bout:
    """The bout ended by a penalty, so the network selects again at once [ours]: the rest of the
    bout's rewards would undo it (the penalties "break out of repeated behaviour cycles", 4.4)."""
    return bout.replace(left=jnp.where(penalised, 0, bout.left).astype(jnp.int32))


def _next_bout(bout: Bout, pc: Percept, u: jnp.ndarray, hold: jnp.ndarray):
    """(select now?, the bout after this iteration's choice: a new one keeps ``u`` [2])."""
    select = (bout.left <= 0) | interrupts(pc.m, bout.antigen)
    new = Bout(
        antigen=jnp.where(select, pc.m, bout.antigen).astype(jnp.int32),
        left=jnp.where(select, hold - 1, bout.left - 1).astype(jnp.int32),
        u=jnp.where(select, u, bout.u),
    )
    return select, new


# ---------------------------------------------------------------------------------- LTL


@pytree_dataclass
class LTLState:
    """A GA robot during its run: its set [8], scores L [8], penalty counters, bout."""

    antibodies: Antibodies
    L: jnp.ndarray
    counters: PenaltyCounters
    bout: Bout


def ltl_controller(readings: Readings = DEFAULT) -> Controller:
    """The LTL: params a set [8], whose antibody for the antigen acts for a bout; L is the
    cumulative RL score clipped to [0, L_MAX], penalties subtract 1.0. ``readings`` are
    compiled in."""

    def init(key, antibodies):
        del key  # the first act selects, from its own key
        n = antibodies.type.shape[0]
        return LTLState(
            antibodies=antibodies, L=jnp.zeros(n), counters=init_counters(), bout=_init_bout()
        )

    def learn(key, state: LTLState, pc: Percept, antibodies):
        del key, antibodies  # RL draws nothing
        scored = _scored(state.L.shape, (state.bout.antigen,)) & (pc.t > 0)
        counters, fire = update_penalty(
            state.counters, pc.m, readings.count_encounters, readings.encounter_gap
        )
        r = rl_score(pc.m_prev, pc.m, pc.v_prev, pc.v, pc.centroid)
        r = r - jnp.where(fire, PENALTY_NON_IDIOTYPIC, 0.0)
        L = jnp.where(scored, jnp.clip(state.L + r, 0.0, L_MAX), state.L)
        return state.replace(L=L, counters=counters, bout=_end_if(state.bout, fire))

    def act(key, state: LTLState, pc: Percept, antibodies):
        del antibodies
        _, bout = _next_bout(state.bout, pc, jax.random.uniform(key, (2,)), readings.hold)
        ab = take(state.antibodies, bout.antigen)
        wheels = wheel_speeds(bout.u, ab, pc.blue_pixels, pc.centroid)
        return state.replace(bout=bout), wheels

    return Controller(init=init, learn=learn, act=act)


# ---------------------------------------------------------------------------------- STL


@pytree_dataclass
class System:
    """One STL system as data (:mod:`jaxais.systems`: SIE, SRL, UIE, URL, HDC).

    Attributes:
        antibodies, paratopes: [x, y] the initial sets and P.
        learning: RL, eq (4) and penalties (off for HDC). idiotypic: stages 1-3 (eqs 5-10),
            else stage 1 alone. replacement: replace antibodies with P < 0.1 (unseeded).
    """

    antibodies: Antibodies
    paratopes: jnp.ndarray
    learning: jnp.ndarray
    idiotypic: jnp.ndarray
    replacement: jnp.ndarray
    network: NetworkParams
    readings: Readings


@pytree_dataclass
class STLState:
    """The network during a run: antibodies, P, I, N [x, y]; sigma0 [y] (eq 4); ``acting``,
    the set acting now in column ``bout.antigen``; counts of ``differences`` (alpha != beta),
    ``selections`` and ``replaced``; ``chosen`` [y], each antigen's last set (-1: none)."""

    antibodies: Antibodies
    P: jnp.ndarray
    sigma0: jnp.ndarray
    I: jnp.ndarray
    N: jnp.ndarray
    counters: PenaltyCounters
    acting: jnp.ndarray
    bout: Bout
    differences: jnp.ndarray
    selections: jnp.ndarray
    replaced: jnp.ndarray
    chosen: jnp.ndarray


def stl_controller(
    replacement: bool = True,
    idiotypic: bool = True,
    learning: bool = True,
    interaction: Interaction = stimulation_suppression,
) -> Controller:
    """The STL network: per iteration RL on the antibody that acted last, eq (4), penalties,
    replacement, the idiotope every period, and at a bout's end selection (stage 1, or 1-3).

    Replacement [ours]: at most one per iteration, the first weak one in (set, antigen) order.
    A part left out (``False``) gives the same trials for a batch that never uses it, from a
    smaller program (:func:`stl_for`). ``interaction``: eqs (7)-(8) of the idiotypic systems'
    selection (:data:`~jaxais.immune.network.Interaction`), the paper's by default; a variant
    with its systems is a contender, ``(stl_controller(interaction=f), make_system("SIE", ...))``
    (``examples/network_variant.py``).
    """
    # One instance per variant however it is asked for (compiled programs are cached by
    # controller): stl_controller() is STL.
    return _stl_controller(bool(replacement), bool(idiotypic), bool(learning), interaction)


@functools.cache
def _stl_controller(
    replacement: bool, idiotypic: bool, learning: bool, interaction: Interaction
) -> Controller:
    """:func:`stl_controller`, built once per distinct variant."""

    def init(key, system: System):
        P = jnp.asarray(system.paratopes, jnp.float32)
        return STLState(
            antibodies=system.antibodies,
            P=P,
            # Eq (4)'s targets, floored so that no column is pinned at 0 (jaxais.immune.readings).
            sigma0=jnp.maximum(jnp.mean(P, axis=0), system.readings.sigma0_floor),
            I=idiotopes(key, P),
            N=initial_clones(*P.shape, system.network.initial_clones),
            counters=init_counters(),
            acting=jnp.int32(0),
            bout=_init_bout(),
            differences=jnp.int32(0),
            selections=jnp.int32(0),
            replaced=jnp.int32(0),
            chosen=jnp.full(P.shape[1], -1, jnp.int32),
        )

    def learn(key, s: STLState, pc: Percept, system: System):
        P, antibodies, replaced = s.P, s.antibodies, s.replaced
        rd = system.readings
        counters, fire = update_penalty(s.counters, pc.m, rd.count_encounters, rd.encounter_gap)
        if learning:  # else no run in the batch learns: only the penalty counters move
            on = system.learning
            scored = _scored(s.P.shape, (s.acting, s.bout.antigen)) & (pc.t > 0) & on
            r = rl_score(pc.m_prev, pc.m, pc.v_prev, pc.v, pc.centroid)
            P = jnp.where(scored, jnp.clip(s.P + r, 0.0, 1.0), s.P)
            # Eq (4), then the paper's bounds: "the maximum P allowed is 1.00, the minimum 0.00"
            # (the rescale alone can lift an entry above 1; column means then fall a little short
            # of sigma0, and only while the bound binds).
            P = jnp.where(on, jnp.clip(rescale_paratopes(P, s.sigma0), 0.0, 1.0), P)
            net = system.network
            size = penalty_size(system.idiotypic, net.penalty_idiotypic, net.penalty_non_idiotypic)
            P = jnp.where(scored & fire, jnp.clip(P - size, 0.0, 1.0), P)
            if replacement:  # only a learning run replaces
                weak = (P < REPLACE_BELOW) & system.replacement & on
                first = _scored(P.shape, jnp.unravel_index(jnp.argmax(weak), P.shape))
                first = first & jnp.any(weak)
                # One draw: past the idiotope's x * y values, the antibody's seven and its P.
                u = jax.random.uniform(key, (P.size + 1 + N_ATTRIBUTES + 1,))[P.size :]
                fresh = from_uniforms(u[:-1])
                antibodies = jax.tree.map(
                    lambda old, new: jnp.where(first, new, old), antibodies, fresh
                )
                lo, hi = REPLACEMENT_P
                P = jnp.where(first, lo + (hi - lo) * u[-1], P)
                replaced = replaced + jnp.any(weak).astype(jnp.int32)

        # The idiotope's redraw every period (not at t = 0) tests the batch's tick, so under vmap
        # it stays a branch (the pool's refills keep runs in phase).
        due = pc.tick % system.network.idiotope_period == 0
        I = jax.lax.cond(due, lambda: jnp.where(pc.t > 0, idiotopes(key, P), s.I), lambda: s.I)
        return s.replace(
            antibodies=antibodies,
            P=P,
            I=I,
            counters=counters,
            replaced=replaced,
            bout=_end_if(s.bout, fire),
        )

    def act(key, s: STLState, pc: Percept, system: System):
        x = s.P.shape[0]
        u = jax.random.uniform(key, (2 + 2 * x,))  # a new bout's, then the tie-breaks
        select, bout = _next_bout(s.bout, pc, u[:2], system.readings.hold)
        if idiotypic:
            alpha, beta, N = idiotypic_select(
                u[2:],
                s.P,
                s.I,
                s.N,
                pc.m,
                system.network,
                system.readings.alpha_on_self,
                interaction,
            )
            idio = system.idiotypic
            chosen = jnp.where(idio, beta, alpha)
            differ = idio & (alpha != beta) & select
            s = s.replace(
                N=jnp.where(idio & select, N, s.N),
                differences=s.differences + differ.astype(jnp.int32),
            )
        else:  # no run in the batch is idiotypic: stage 1 alone, the clones never change
            chosen = select_alpha(u[2 : 2 + x], s.P, pc.m)  # the alpha of the stages above
        acting = jnp.where(select, chosen, s.acting).astype(jnp.int32)
        column = select & (jnp.arange(s.chosen.shape[0]) == pc.m)
        s = s.replace(
            acting=acting,
            bout=bout,
            selections=s.selections + select.astype(jnp.int32),
            chosen=jnp.where(column, acting, s.chosen),
        )
        ab = take(s.antibodies, (acting, bout.antigen))
        return s, wheel_speeds(bout.u, ab, pc.blue_pixels, pc.centroid)

    def stats(s: STLState, system: System):
        rate = s.differences / jnp.maximum(s.selections, 1)
        return {
            "idiotypic_difference_rate": jnp.where(system.idiotypic, rate, jnp.nan),
            "replaced": s.replaced,
        }

    def choices(s: STLState):
        return s.chosen

    return Controller(init=init, learn=learn, act=act, stats=stats, choices=choices)


LTL = ltl_controller()  # the GA's controller


def stl_for(systems: System) -> Controller:
    """The smallest (shared) STL controller that runs every system of a batch [n]."""
    parts = (systems.replacement, systems.idiotypic, systems.learning)
    return stl_controller(*(bool(np.any(f)) for f in parts))


STL = stl_controller(True, True, True)  # every part built in (stl_for's arguments are positional)


# ---------------------------------------------------------------------------- a baseline


@pytree_dataclass
class BraitenbergParams:
    """A Braitenberg vehicle's gains [ours]: cruising ``speed`` (speed units), turn per unit of
    the nearer side's proximity (``avoid``) and of the blue centroid's offset (``steer``)."""

    speed: jnp.ndarray
    avoid: jnp.ndarray
    steer: jnp.ndarray


def braitenberg_params(speed: float = 500.0, avoid: float = 1.0, steer: float = 0.5):
    """:class:`BraitenbergParams` as float32 (defaults [ours], from its behaviour tests)."""
    f = jnp.float32
    return BraitenbergParams(speed=f(speed), avoid=f(avoid), steer=f(steer))


def braitenberg_controller() -> Controller:
    """A reactive vehicle (no state, learning or randomness): the nearer side's proximity slows
    it and turns it away; with nothing near, it turns toward the blue centroid."""
    weights = np.array([1.0, 0.7, 0.3, 0.0, 0.0, 0.3, 0.7, 1.0], np.float32)  # ps0..ps7
    right_side = (SENSOR_SIDE == RIGHT).astype(np.float32)  # ps0-ps2

    def act(key, state, pc: Percept, params: BraitenbergParams):
        del key
        p = proximity(pc.ir) * weights  # front sensors weigh most
        right, left = jnp.max(p * right_side), jnp.max(p * (1.0 - right_side))
        near = jnp.maximum(left, right)
        away = jnp.where(left >= right, 1.0, -1.0)  # + turns right (left wheel faster)
        toward = centroid_offset(pc.centroid, pc.blue_pixels)  # + the blue is to the right
        turn = params.avoid * near * away + (1.0 - near) * params.steer * toward
        forward = params.speed * (1.0 - near)
        wheels = jnp.stack([forward + params.speed * turn, forward - params.speed * turn])
        return state, clip_wheels(wheels)

    return Controller(init=no_state, learn=no_learning, act=act)


BRAITENBERG = braitenberg_controller()
