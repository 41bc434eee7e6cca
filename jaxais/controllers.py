"""Controllers: the protocol the task loop (:mod:`jaxais.loop`) runs, and the controllers.

A controller is a :class:`Controller`, a tuple of pure functions of one robot, key first, like
optax's ``(init, update)`` pairs: ``init`` makes its state, ``learn`` scores what acted last,
``act`` picks wheel speeds, ``stats`` (optional) reads what a run records from the final state.
Its ``params`` are a pytree of its own (antibodies, flags, constants), so a batch of robots can
differ in data under one compiled program. The loop hands it a :class:`Percept` and never looks
inside its state: a new controller plugs in without touching the loop
(``jaxais.trials.make_trials``, ``run_trials(..., controller=...)``).

- :func:`ltl_controller`: one antibody set acting alone with RL accumulating each antibody's
  score L (the GA's evaluation, SPEC 10).
- :func:`stl_controller`: the short-term learning network of SPEC 7 over five sets; a
  :class:`System` (its params) says whether it learns, whether selection is idiotypic and whether
  weak antibodies are replaced, so SIE, SRL, UIE, URL and HDC are one program with different data
  and can share one compiled batch; :func:`stl_for` leaves out the parts a batch does not use.
- :func:`braitenberg_controller`: a Braitenberg vehicle [ours, not in the paper], a reactive
  baseline of a dozen lines: the IR readings push the wheels away from obstacles, the blue
  centroid steers toward the target.

Every draw or split of a key is a threefry hash, which runs as a loop of its own on CPU, so the
task loop's time goes with the number of draws per iteration, not their size. Learn and act
therefore draw at most once per iteration each and slice the draw, relying on JAX's threefry
numbering a draw's values by their index (a draw's first k values are the k-value draw from the
same key). An act draws a new bout's two uniforms first, which are what
:func:`~jaxais.immune.behaviours.wheel_speeds` draws from that key, then the selection's
tie-breaks.
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
from jaxais.immune.antigens import is_collision, is_obstacle_or_collision
from jaxais.immune.behaviours import MAX_WHEEL_SPEED, wheel_speeds
from jaxais.immune.network import (
    NetworkParams,
    idiotopes,
    idiotypic_select,
    rescale_paratopes,
    select_alpha,
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

# ----------------------------------------------------------------------------- the protocol


@pytree_dataclass
class Percept:
    """What a controller sees at one iteration (scalars but ``ir``).

    Attributes:
        m, m_prev: antigen now and at the previous iteration (m_prev = 0 at t = 0).
        v, v_prev: Vm (maximum IR reading) now and before.
        ir: [8] the IR readings ps0..ps7 (0..4095, ``envs.params.IR_BEARINGS_DEG``).
        blue_pixels: number of blue pixels; centroid: their mean column (7 when none).
        t: iterations since the start of the run.
        tick: iterations since the batch started, the same for every run of a batch (it equals
            t while a run is going), so a periodic step can be a ``lax.cond`` that stays a
            branch under ``vmap`` instead of being computed every iteration and masked.
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
    """A controller as pure functions of one robot, key first.

    - ``init(key, params) -> state``
    - ``learn(key, state, percept, params) -> state``: learning from the last action's outcome
      (a controller that does not learn returns ``state``);
    - ``act(key, state, percept, params) -> (state, wheels [2])``: left and right wheel speeds;
    - ``stats(state, params) -> dict[str, scalar]`` (optional): what a finished run records
      beyond the loop's own counts, e.g. the STL's idiotypic difference rate (NaN where it
      does not apply).
    - ``choices(state) -> [k] int32`` (optional): what the controller has chosen for each
      situation it tells apart, -1 where it has not chosen yet (the STL: the set last selected
      for each antigen). The loop measures lock-ups with it (:class:`jaxais.loop.Run`'s
      ``locked``): a controller without it never counts as locked.

    ``params`` is the controller's own pytree; every key is a typed PRNG key of its own (the
    loop gives learn and act one each per iteration). Controllers are compared by identity when
    compiled programs are cached, so build each once (a module constant or a cached factory).
    """

    init: Callable[..., Any]
    learn: Callable[..., Any]
    act: Callable[..., Any]
    stats: Callable[..., dict[str, Any]] | None = None
    choices: Callable[..., jnp.ndarray] | None = None


# --------------------------------------------------------------- the immune controllers' bouts

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


def _level(m: jnp.ndarray) -> jnp.ndarray:
    """0 target unseen, 1 target seen, 2 obstacle, 3 collision."""
    return jnp.where(
        is_obstacle_or_collision(m), 2 + is_collision(m).astype(jnp.int32), jnp.minimum(m, 1)
    )


def interrupts(m: jnp.ndarray, held: jnp.ndarray) -> jnp.ndarray:
    """Does antigen ``m`` cut short the bout of the behaviour selected for antigen ``held``?

    [ours] A more urgent situation (target seen while wandering, an obstacle, a collision), or
    a new obstacle or collision on another side, gets a new selection at once; a calmer one
    (the obstacle left behind) lets the bout run on, so a reverse turn backs all the way out.
    """
    level, held_level = _level(m), _level(held)
    return (level > held_level) | ((level == held_level) & (level >= 2) & (m != held))


@pytree_dataclass
class Bout:
    """The behaviour acting now (SPEC 5): it acts for ``Readings.hold`` iterations.

    Attributes:
        antigen: [] int32 the antigen it was selected for (its antibody column).
        left: [] int32 iterations of the bout still to act after this one.
        u: [2] the behaviour's uniforms, what :func:`~jaxais.immune.behaviours.wheel_speeds` draws
            from the act key of the bout's selection: the behaviour acts on the same numbers all
            bout, so a wander's turn decision holds for the bout and F % is the share of bouts, i.e.
            of time, spent turning."""

    antigen: jnp.ndarray
    left: jnp.ndarray
    u: jnp.ndarray


def _init_bout() -> Bout:
    """A bout that has ended (the first act selects)."""
    return Bout(antigen=jnp.int32(0), left=jnp.int32(0), u=jnp.zeros(2))


def _end_if(bout: Bout, penalised: jnp.ndarray) -> Bout:
    """The bout ended by a penalty: the network selects again at once [ours]. Otherwise the
    penalised antibody would act on, and the rewards of the rest of its bout (0 -> 0 scores
    +0.05 per iteration) would undo the penalty before the next selection, which the paper's
    penalties exist to force ("to break out of repeated behaviour cycles", section 4.4)."""
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
    """A GA robot during its run: its set [8], the scores L [8], the penalty counters and the
    behaviour acting now."""

    antibodies: Antibodies
    L: jnp.ndarray
    counters: PenaltyCounters
    bout: Bout


def ltl_controller(readings: Readings = DEFAULT) -> Controller:
    """One set, no idiotypic selection: the antibody for the antigen acts; RL accumulates L.

    Params: an :class:`Antibodies` set [8]. The antibody selected for an antigen acts for a bout
    (``readings.hold``, :class:`Bout`). L_ij is the cumulative RL score of antibody j, clipped
    to [0, L_MAX] after every update; penalties subtract the non-idiotypic 1.0.

    Args:
        readings: our readings of the paper's open points (built in as constants).
    """

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
    """One STL system as data (see :mod:`jaxais.systems` for SIE, SRL, UIE, URL, HDC).

    Attributes:
        antibodies: [x, y] the initial sets.
        paratopes: [x, y] initial P.
        learning: RL, eq (4) and penalties on (off for the hand-designed controller).
        idiotypic: three-stage idiotypic selection (eqs 5-10) rather than stage 1 alone.
        replacement: replace antibodies with P < 0.1 (unseeded systems).
        network: the network constants.
        readings: our readings of the paper's open points (:mod:`jaxais.immune.readings`).
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
    """The network during a run.

    Attributes:
        antibodies: [x, y] current sets (replacement changes them).
        P: [x, y] paratopes. sigma0: [y] initial column means (eq 4). I: [x, y] idiotopes.
        N: [x, y] clone counts. counters: penalty runs.
        acting: set index of the antibody acting now (scored at the next iteration); its
            antigen column is ``bout.antigen``. bout: the behaviour acting now.
        differences: selections with alpha != beta. selections: selections made (one per bout).
        replaced: antibodies replaced so far.
        chosen: [y] the set last selected for each antigen (-1: never selected yet).
    """

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
    replacement: bool = True, idiotypic: bool = True, learning: bool = True
) -> Controller:
    """The STL network: per iteration RL on the antibody that acted last, eq (4), penalties,
    replacement (unseeded), the idiotope every ``idiotope_period`` iterations, then, when a bout
    ends or is interrupted (:class:`Bout`), selection (stage 1, or stages 1-3 when idiotypic);
    the selected antibody's behaviour acts for the bout.

    Replacement [ours on the detail]: at most one antibody per iteration, the first (in set,
    antigen order) whose P is below 0.1; any others follow on later iterations.

    Args:
        replacement, idiotypic, learning: build that part of the network in (default: all of
            them, which runs every system). A batch in which no run uses a part (its
            ``System`` flag False throughout) gives the same trials without it, from a smaller
            and faster program (docs/performance.md); :func:`stl_for` picks the smallest
            controller for a batch (tests/test_controllers.py checks that the trials are the
            same).
    """

    def init(key, system: System):
        P = jnp.asarray(system.paratopes, jnp.float32)
        return STLState(
            antibodies=system.antibodies,
            P=P,
            # Eq (4)'s targets, floored so that no column is pinned at 0 (jaxais.immune.readings).
            sigma0=jnp.maximum(jnp.mean(P, axis=0), system.readings.sigma0_floor),
            I=idiotopes(key, P),
            N=jnp.full(P.shape, system.network.initial_clones, jnp.float32),
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
                # One draw: past the x * y values that the idiotope's redraw below draws from
                # this key, the new antibody's seven values, then its paratope's.
                u = jax.random.uniform(key, (P.size + 1 + N_ATTRIBUTES + 1,))[P.size :]
                fresh = from_uniforms(u[:-1])
                antibodies = jax.tree.map(
                    lambda old, new: jnp.where(first, new, old), antibodies, fresh
                )
                lo, hi = REPLACEMENT_P
                P = jnp.where(first, lo + (hi - lo) * u[-1], P)
                replaced = replaced + jnp.any(weak).astype(jnp.int32)

        # The idiotope is redrawn every idiotope_period iterations of a run (not at t = 0). The
        # test is on the batch's tick (unbatched), so under vmap this stays a branch taken once
        # per period; a run that joins a batch at a tick that is a multiple of the period
        # (jaxais.runner.run_pool's refills) keeps the same schedule.
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
                u[2:], s.P, s.I, s.N, pc.m, system.network, system.readings.alpha_on_self
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


# ---------------------------------------------------------------------------- a baseline


@pytree_dataclass
class BraitenbergParams:
    """A Braitenberg vehicle's gains [ours; a baseline, not in the paper].

    Attributes:
        speed: cruising wheel speed, speed units (Table 1's behaviours run at 100-1000).
        avoid: turn per unit of proximity (the nearer side's, 0 far to 1 touching).
        steer: turn per unit of the blue centroid's offset from the image centre (-1..1).
    """

    speed: jnp.ndarray
    avoid: jnp.ndarray
    steer: jnp.ndarray


def braitenberg_params(speed: float = 500.0, avoid: float = 1.0, steer: float = 0.5):
    """:class:`BraitenbergParams` as float32 scalars (the defaults are ours, set by
    ``tests/test_controllers.py``'s behaviour tests: it turns away from the nearer wall and
    toward the blue, not by any STL result)."""
    f = lambda x: jnp.float32(x)
    return BraitenbergParams(speed=f(speed), avoid=f(avoid), steer=f(steer))


def _proximity(ir: jnp.ndarray) -> jnp.ndarray:
    """IR readings as proximity in [0, 1]: 0 beyond about 6 cm (reading 100), 1 from about
    1.5 cm (reading 600; ``envs.params.IR_TABLE_VALUE``)."""
    return jnp.clip((ir - 100.0) / 500.0, 0.0, 1.0)


def braitenberg_controller() -> Controller:
    """A reactive vehicle: no state, no learning, no randomness.

    The front sensors' proximity on each side (ps0-ps2 right, ps5-ps7 left, weighted toward
    the front) slows the robot and turns it away from the nearer side; with nothing near, a
    blue centroid left or right of the image centre turns it toward the blue.
    """
    weights = np.array([1.0, 0.7, 0.3, 0.0, 0.0, 0.3, 0.7, 1.0], np.float32)  # ps0..ps7
    right_side = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0], np.float32)

    def init(key, params):
        del key, params
        return jnp.int32(0)  # no state; a scalar keeps the loop's pytrees non-empty

    def learn(key, state, pc: Percept, params):
        del key, pc, params
        return state

    def act(key, state, pc: Percept, params: BraitenbergParams):
        del key
        p = _proximity(pc.ir) * weights
        right, left = jnp.max(p * right_side), jnp.max(p * (1.0 - right_side))
        near = jnp.maximum(left, right)
        away = jnp.where(left >= right, 1.0, -1.0)  # + turns right (left wheel faster)
        seen = pc.blue_pixels > 0
        toward = jnp.where(seen, (pc.centroid - 7.0) / 7.0, 0.0)  # + the blue is to the right
        turn = params.avoid * near * away + (1.0 - near) * params.steer * toward
        forward = params.speed * (1.0 - near)
        wheels = jnp.stack([forward + params.speed * turn, forward - params.speed * turn])
        return state, jnp.clip(wheels, -MAX_WHEEL_SPEED, MAX_WHEEL_SPEED)

    return Controller(init=init, learn=learn, act=act)


BRAITENBERG = braitenberg_controller()
"""The Braitenberg vehicle (one shared instance, so compiled programs are reused)."""
