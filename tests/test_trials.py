"""The task loop (``jaxais.loop``), its driver (``jaxais.runner``) and the STL trials
(``jaxais.trials``), SPEC 9.

Every program here runs world1 with the STL controller, :data:`_stl_fixtures.CONFIG` and batches
of :data:`_stl_fixtures.BATCH` runs, so each distinct program compiles once per session: the
jitted ``start`` / ``iterate`` of the fixtures, and the runner's programs ``run_trials`` drives.

Rules of the loop are checked by driving one run with the jitted ``iterate`` and writing the
observation it reads (goal pixels, IR) before each iteration.
"""

from __future__ import annotations

import dataclasses
import functools
import zlib
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import _stl_fixtures as F
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _python import run_python, shipped_env

from jaxais import loop, runner
from jaxais import trials as trials_module
from jaxais.controllers import LTL, STL, stl_for
from jaxais.immune.antibodies import sample_antibodies
from jaxais.loop import FAILED_COLLISIONS, FAILED_TIME, FINISHED, RUNNING, outcome
from jaxais.trials import TrialSet, run_trials, summarise, trial_keys

DT = 0.032
MAX_IT = F.CONFIG.max_iterations(DT)  # 625

# IR vectors that present a given antigen (Vm at the sensor of that side).
IR = {
    0: [0.0] * 8,
    2: [1000.0, 0, 0, 0, 0, 0, 0, 0],
    3: [0, 0, 0, 1000.0, 0, 0, 0, 0],
    4: [0, 0, 0, 0, 0, 0, 1000.0, 0],
    5: [3000.0, 0, 0, 0, 0, 0, 0, 0],
    6: [0, 0, 0, 3000.0, 0, 0, 0, 0],
    7: [0, 0, 0, 0, 0, 0, 3000.0, 0],
}


def key_data(keys: jax.Array) -> np.ndarray:
    return np.asarray(jax.random.key_data(keys))


tree_equal = F.tree_equal


@functools.cache
def start_runs():
    """BATCH runs at t = 0: SIE trials 0-1 and HDC trials 0-1 of seed 0 (their trial keys)."""
    r_sie, k_sie = trial_keys(0, "SIE", 2)
    r_hdc, k_hdc = trial_keys(0, "HDC", 2)
    sys_ = F.systems()
    params = F.stack([sys_["SIE"], sys_["SIE"], sys_["HDC"], sys_["HDC"]])
    runs = F.start_runs(jnp.concatenate([r_sie, r_hdc]), jnp.concatenate([k_sie, k_hdc]), params)
    return runs, params


def one_run(i: int = 0):
    runs, params = start_runs()
    return F.unstack(runs, i), F.unstack(params, i)


def with_obs(run, antigen: int | None = None, goal: int | None = None):
    """The run with its last observation rewritten: IR presenting ``antigen``, goal pixels."""
    obs = run.obs
    if antigen is not None:
        ir = jnp.asarray(IR[0 if antigen == 1 else antigen], obs.ir.dtype)
        obs = obs.replace(ir=ir, vm=jnp.max(ir).astype(obs.vm.dtype))
        obs = obs.replace(blue_pixels=jnp.full_like(obs.blue_pixels, 3 * (antigen == 1)))
    if goal is not None:
        obs = obs.replace(
            goal_pixels=jnp.full_like(obs.goal_pixels, goal),
            blue_pixels=jnp.full_like(obs.blue_pixels, goal),
        )
    return run.replace(obs=obs)


def drive(run, params, steps: list[dict], config=F.CONFIG, seed: int = 0) -> list:
    """Apply ``iterate`` once per entry of ``steps`` (each rewrites the observation first)."""
    out = []
    for k, mods in enumerate(steps):
        run = with_obs(run, **mods)
        run = F.step_one(run, jax.random.key(1000 * seed + k), params, config=config)
        out.append(run)
    return out


def status(run) -> int:
    return int(run.status)


# ---------------------------------------------------------------------------------- the loop


def test_finish_rule_three_consecutive_iterations_over_40_goal_pixels():
    run, params = one_run()
    runs = drive(run, params, [{"antigen": 0, "goal": 41}] * 3)
    assert [status(r) for r in runs] == [RUNNING, RUNNING, FINISHED]
    assert [int(r.streak) for r in runs] == [1, 2, 3]
    # The iteration that detects the finish records it and moves nothing.
    assert int(runs[2].t) == int(runs[1].t) == 2
    assert tree_equal(runs[2].sim, runs[1].sim) and tree_equal(runs[2].ctrl, runs[1].ctrl)


def test_finish_rule_needs_more_than_40_pixels_without_a_gap():
    run, params = one_run()
    goals = [41, 41, 40, 41, 41, 0, 45, 45, 41]
    runs = drive(run, params, [{"antigen": 0, "goal": g} for g in goals])
    assert [int(r.streak) for r in runs] == [1, 2, 0, 1, 2, 0, 1, 2, 3]
    assert [status(r) for r in runs] == [RUNNING] * 8 + [FINISHED]


def test_time_cap_stops_at_exactly_max_iterations():
    run, params = one_run(1)
    run = run.replace(t=jnp.asarray(MAX_IT - 2, run.t.dtype))
    runs = drive(run, params, [{"antigen": 0, "goal": 0}] * 4)
    assert [int(r.t) for r in runs] == [MAX_IT - 1, MAX_IT, MAX_IT, MAX_IT]
    assert [status(r) for r in runs] == [RUNNING, RUNNING, FAILED_TIME, FAILED_TIME]
    res = outcome(jax.tree.map(lambda a: a[None], runs[-1]), F.CONFIG, DT)
    assert res["tau"][0] == pytest.approx(F.CONFIG.tau_cap)
    assert res["iterations"][0] == MAX_IT and res["status"][0] == FAILED_TIME


def test_collision_cap_stops_when_the_count_reaches_it():
    run, params = one_run(2)
    run = run.replace(collisions=jnp.asarray(F.CONFIG.collision_cap - 2, run.collisions.dtype))
    runs = drive(run, params, [{"antigen": a} for a in (5, 0, 7, 0)])
    assert [int(r.collisions) for r in runs] == [4, 4, 5, 5]
    assert [status(r) for r in runs] == [RUNNING, RUNNING, FAILED_COLLISIONS, FAILED_COLLISIONS]
    assert int(runs[2].t) == int(runs[1].t) == 2
    assert tree_equal(runs[2].sim, runs[1].sim)


COLLISION_SEQ = [5, 6, 7, 5, 2, 6, 0, 7, 7, 1, 3, 4, 6]


def test_collisions_count_one_per_contact_episode():
    """A collision counts when the antigen is in 5-7 and Vm has fallen under 250 since the last
    counted one (SPEC 9): the chatter 5-6-7-5-2-6 of one contact is one collision."""
    run, params = one_run(3)
    runs = drive(run, params, [{"antigen": a} for a in COLLISION_SEQ])
    assert [int(r.collisions) for r in runs] == [1, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2, 2, 3]
    assert [int(r.m_prev) for r in runs] == COLLISION_SEQ
    assert all(status(r) == RUNNING for r in runs)


def test_every_rule_is_counted_apart_and_never_stops_a_run():
    """Whatever ``collision_rule`` says, every run counts c per contact episode, per reading of a
    collision antigen (Vm >= 2400) and per entry into 5-7 (issue 41), each apart; the cap stops
    on the rule's count only."""
    readings = [1, 2, 3, 4, 4, 5, 5, 6, 7, 7, 7, 7, 8]  # COLLISION_SEQ's 8 collision readings
    for config in (F.CONFIG, NO_STOP_ENTRY):
        run, params = one_run(3)
        runs = drive(run, params, [{"antigen": a} for a in COLLISION_SEQ], config)
        assert [int(r.by_reading) for r in runs] == readings
        assert [int(r.by_episode) for r in runs] == [1, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2, 2, 3]
        assert [int(r.by_entry) for r in runs] == [1, 1, 1, 1, 1, 2, 2, 3, 3, 3, 3, 3, 4]
        assert all(status(r) == RUNNING for r in runs)  # 8 readings, past the cap of 5
        res = outcome(jax.tree.map(lambda a: a[None], runs[-1]), config, DT)
        assert [int(res[f"collisions_{k}"][0]) for k in ("episode", "reading", "entry")] == [
            3,
            8,
            4,
        ]


NO_STOP_ENTRY = dataclasses.replace(F.CONFIG, stop_at_collision_cap=False, collision_rule="entry")
"""The earlier collision count (every entry into 5-7), and runs that go on past the cap."""


def test_entry_rule_counts_every_entry_and_runs_go_on_past_the_cap():
    run, params = one_run(3)
    runs = drive(run, params, [{"antigen": a} for a in COLLISION_SEQ], NO_STOP_ENTRY)
    assert [int(r.collisions) for r in runs] == [1, 1, 1, 1, 1, 2, 2, 3, 3, 3, 3, 3, 4]
    run = run.replace(collisions=jnp.asarray(F.CONFIG.collision_cap, run.collisions.dtype))
    runs = drive(run, params, [{"antigen": a} for a in (5, 0, 7, 0)], NO_STOP_ENTRY)
    assert [int(r.collisions) for r in runs] == [6, 6, 7, 7]
    assert all(status(r) == RUNNING for r in runs) and int(runs[-1].t) == 4
    res = outcome(jax.tree.map(lambda a: a[None], runs[-1]), NO_STOP_ENTRY, DT)
    assert res["collisions"][0] == 7 and res["collisions_capped"][0] == 5
    assert res["failed_collisions"][0] and not res["failed_time"][0]


def test_an_ended_run_never_changes():
    run, params = one_run()
    done = drive(run, params, [{"antigen": 0, "goal": 41}] * 3)[-1]
    assert status(done) == FINISHED
    for k, mods in enumerate([{"antigen": 5}, {"goal": 45}, {"antigen": 0, "goal": 0}, {}]):
        before = with_obs(done, **mods)
        after = F.step_one(before, jax.random.key(77 + k), params)
        assert tree_equal(after, before)


def test_outcome_caps_and_fitness():
    runs = SimpleNamespace(
        status=np.array([FINISHED, FAILED_TIME, FAILED_COLLISIONS, FINISHED, FAILED_TIME]),
        t=np.array([100, 700, 300, 0, 625]),
        collisions=np.array([3, 2, 9, 0, 6]),
        trapped=np.array([0, 400, 0, 0, 10]),
        locked=np.array([0, 350, 0, 0, 0]),
    )
    res = outcome(runs, F.CONFIG, DT)
    np.testing.assert_allclose(res["tau"], [3.2, 20.0, 9.6, 0.0, 20.0])
    np.testing.assert_array_equal(res["collisions"], [3, 2, 9, 0, 6])
    np.testing.assert_array_equal(res["collisions_capped"], [3, 2, 5, 0, 5])
    np.testing.assert_allclose(res["fitness"], [13.6, 18.0, 24.8, 0.0, 30.0])
    np.testing.assert_array_equal(res["failed_collisions"], [False, False, True, False, True])
    np.testing.assert_array_equal(res["failed_time"], [False, True, False, False, True])
    np.testing.assert_allclose(res["trapped_s"], [0.0, 12.8, 0.0, 0.0, 0.32])
    np.testing.assert_allclose(res["locked_s"], [0.0, 11.2, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(res["iterations"], [100, 700, 300, 0, 625])
    assert loop.fitness(10.0, 2) == 13.0 and loop.RHO == 8.0


def test_vmapped_iterate_equals_a_loop_of_single_iterations():
    """jit(vmap(iterate)) over BATCH runs of different systems = jitted iterate run by run, for
    12 iterations crossing an idiotope redraw (tick 120), including a run that hits the time
    cap and one that hits the collision cap."""
    runs, _ = start_runs()
    params = F.batch_params()  # SIE, UIE-R1, URL-R1, HDC
    first_tick = 115
    runs = runs.replace(
        t=jnp.asarray([first_tick, first_tick, first_tick, MAX_IT - 4], runs.t.dtype),
        collisions=runs.collisions.at[2].set(F.CONFIG.collision_cap - 1),
    )
    ir = runs.obs.ir.at[2].set(jnp.asarray(IR[6], runs.obs.ir.dtype))
    runs = runs.replace(obs=runs.obs.replace(ir=ir))  # run 2 collides at once
    singles = [F.unstack(runs, i) for i in range(F.BATCH)]
    single_params = [F.unstack(params, i) for i in range(F.BATCH)]
    w, sp = F.world(), F.sim_params()
    idiotopes_before = np.asarray(runs.ctrl.I)
    for k in range(12):
        tick = jnp.int32(first_tick + k)
        keys = jax.random.split(jax.random.key(500 + k), F.BATCH)
        runs = F.iterate_batch_fn()(keys, runs, tick, w, sp, STL, params, F.CONFIG)
        for i in range(F.BATCH):
            singles[i] = F.iterate_fn()(
                keys[i], singles[i], tick, w, sp, STL, single_params[i], F.CONFIG
            )
    for i in range(F.BATCH):
        batched = F.unstack(runs, i)
        for path, a in jax.tree_util.tree_leaves_with_path(batched):
            b = functools.reduce(lambda x, p: getattr(x, p.name), path, singles[i])
            np.testing.assert_array_equal(
                F.leaf_array(a), F.leaf_array(b), err_msg=f"run {i} {jax.tree_util.keystr(path)}"
            )
    st = np.asarray(runs.status)
    assert st[2] == FAILED_COLLISIONS and st[3] == FAILED_TIME and st[0] == RUNNING
    assert int(runs.t[0]) == first_tick + 12 and int(runs.t[2]) == first_tick
    # The learning runs redrew their idiotope at tick 120; the run stopped at tick 115 did not.
    I = np.asarray(runs.ctrl.I)
    assert not np.array_equal(I[0], idiotopes_before[0])
    np.testing.assert_array_equal(I[2], idiotopes_before[2])


def test_task_loop_equals_iterate_with_folded_keys():
    """One chunk of ``advance`` (its iteration traced under jax.disable_jit) = ``iterate`` run
    chunk times, iteration t of each run with the key ``fold_in(run.key, t)``: the same runs,
    bit for bit."""
    chunk = 4
    config = dataclasses.replace(F.CONFIG, chunk=chunk, segment=chunk, record=False)
    runs, params = start_runs()
    w, sp = F.world(), F.sim_params()
    batch = runner.Batch(runs=runs, poses=jnp.zeros((F.BATCH, 1, 3)), chunks=jnp.int32(0))
    advanced = jax.jit(runner.advance, static_argnums=(3, 5))(batch, w, sp, STL, params, config)

    expected = runs
    for i in range(chunk):
        keys = jax.vmap(jax.random.fold_in)(runs.key, expected.t)
        # F.CONFIG has the same caps; passing it reuses the compiled iterate.
        expected = F.iterate_batch_fn()(keys, expected, jnp.int32(i), w, sp, STL, params, F.CONFIG)
    assert np.all(np.asarray(expected.t) == chunk)  # every run went on (keys of t = 0..3)
    assert tree_equal(advanced.runs, expected)
    assert int(advanced.chunks) == 1


def _hashes(jaxpr, loops: int = 0, counts: Counter | None = None) -> Counter:
    """Threefry hashes (draws, splits, fold-ins) of a jaxpr, counted by how many loops enclose
    them; those inside a branch (the idiotope's, once a period) count under "branch"."""
    counts = Counter() if counts is None else counts
    for eqn in jaxpr.eqns:
        name = eqn.primitive.name
        if name in ("random_bits", "random_split", "random_fold_in"):
            counts["branch" if loops < 0 else loops] += 1
        inner = -1 if name == "cond" else loops + (name in ("while", "scan"))
        for value in eqn.params.values():
            for sub in value if isinstance(value, tuple | list) else [value]:
                if hasattr(sub, "eqns") or hasattr(sub, "jaxpr"):
                    _hashes(getattr(sub, "jaxpr", sub), inner, counts)
    return counts


@pytest.mark.parametrize("ltl", [False, True])
def test_the_task_loop_hashes_once_or_twice_per_iteration(ltl):
    """On CPU every threefry hash is a loop of its own, so the count per iteration is what the
    task loop's speed depends on: the keys and the simulator's noise of a chunk are drawn
    together (three hashes a chunk), and in each iteration the act draws once (and an STL
    learn that replaces antibodies once); the idiotope's draw sits in its periodic branch."""
    controller, params = STL, F.batch_params()
    if ltl:
        controller, params = LTL, sample_antibodies(jax.random.key(0), (F.BATCH, 8))
    w, sp = F.world(), F.sim_params()
    keys = trial_keys(0, "SIE", F.BATCH)
    start = lambda p: runner.start_batch(*keys, w, sp, controller, p, F.CONFIG)
    advance = lambda b, p: runner.advance(b, w, sp, controller, p, F.CONFIG)
    jaxpr = jax.make_jaxpr(advance)(jax.eval_shape(start, params), params)
    # Loops: the map over lockstep groups, the segment's chunks, the chunk's iterations.
    expected = Counter({2: 3, 3: 1}) if ltl else Counter({2: 3, 3: 2, "branch": 1})
    assert _hashes(jaxpr.jaxpr) == expected


# ---------------------------------------------------------------------------------- trials


@functools.cache
def trials(counts: tuple[tuple[str, int], ...], seed: int) -> dict[str, TrialSet]:
    """``run_trials`` on BATCH runs in total (so one compiled program serves every call)."""
    assert sum(n for _, n in counts) == F.BATCH
    sys_ = F.systems()
    return run_trials(
        F.world(),
        {name: sys_[name] for name, _ in counts},
        dict(counts),
        seed,
        F.CONFIG,
        F.sim_params(),
    )


SIE_HDC = (("SIE", 2), ("HDC", 2))


def same_trials(a: TrialSet, b: TrialSet, n: int | None = None) -> bool:
    n = len(a.records) if n is None else n
    return a.records[:n] == b.records[:n] and all(
        np.array_equal(x, y) for x, y in zip(a.trajectories[:n], b.trajectories[:n], strict=True)
    )


@pytest.mark.slow
def test_trial_records_are_consistent():
    res = trials(SIE_HDC, 0)
    assert list(res) == ["SIE", "HDC"]
    for name, ts in res.items():
        assert len(ts.records) == 2 and len(ts.trajectories) == 2
        for rec, traj in zip(ts.records, ts.trajectories, strict=True):
            assert set(rec) >= {
                "tau", "collisions", "collisions_capped", "fitness", "failed",
                "failed_collisions", "failed_time", "failed_by", "trapped_s",
                "idiotypic_difference_rate", "iterations",
            }  # fmt: skip
            assert rec["tau"] == pytest.approx(min(rec["iterations"] * DT, F.CONFIG.tau_cap))
            capped = min(rec["collisions"], F.CONFIG.collision_cap)
            assert rec["collisions_capped"] == capped
            assert rec["fitness"] == pytest.approx((8 * capped + rec["tau"]) / 2)
            assert rec["failed"] == (rec["failed_collisions"] or rec["failed_time"])
            by = [k for k in ("collisions", "time") if rec[f"failed_{k}"]]
            assert rec["failed_by"] == by
            assert rec["failed_collisions"] == (rec["collisions"] > F.CONFIG.collision_cap)
            assert rec["failed_time"] == (rec["iterations"] == MAX_IT)
            assert 0 <= rec["trapped_s"] <= rec["tau"]
            assert 0 <= rec["collisions"] <= F.CONFIG.collision_cap  # CONFIG stops at the cap
            assert rec["iterations"] <= MAX_IT
            rate = rec["idiotypic_difference_rate"]
            if name == "SIE":
                assert 0.0 <= rate <= 1.0
            else:
                assert rate is None
            assert traj.ndim == 2 and traj.shape[1] == 3
            assert traj.shape[0] == rec["iterations"] // F.CONFIG.chunk + 2


def test_same_seed_gives_identical_trials():
    again = run_trials(
        F.world(), {k: F.systems()[k] for k in ("SIE", "HDC")}, 2, 0, F.CONFIG, F.sim_params()
    )
    first = trials(SIE_HDC, 0)
    for name in first:
        assert same_trials(first[name], again[name])


def test_different_seeds_give_different_trials():
    a, b = trials(SIE_HDC, 0), trials(SIE_HDC, 1)
    for name in a:
        for x, y in zip(a[name].trajectories, b[name].trajectories, strict=True):
            assert not np.array_equal(x[0], y[0])  # other start placements
            assert not np.array_equal(x, y)


def test_results_do_not_depend_on_batch_mates():
    """SIE with HDC, SIE alone (4 trials: its first 2 are the same trials) and SIE after HDC in
    the batch all give SIE identical trials; likewise HDC."""
    with_hdc = trials(SIE_HDC, 0)
    alone = trials((("SIE", 4),), 0)
    hdc_first = trials((("HDC", 2), ("SIE", 2)), 0)
    assert same_trials(with_hdc["SIE"], alone["SIE"], 2)
    assert same_trials(with_hdc["SIE"], hdc_first["SIE"])
    assert same_trials(with_hdc["HDC"], hdc_first["HDC"])
    # ... while the later trials of SIE alone are other trials.
    assert not np.array_equal(alone["SIE"].trajectories[2][0], alone["SIE"].trajectories[0][0])


class _Compiling(Exception):
    """Raised by the spy below instead of compiling: which controller, not its runs, is asked."""


def test_a_batch_compiles_only_the_parts_of_the_network_its_systems_use(monkeypatch):
    """SIE and HDC never replace antibodies; HDC and SRL are not idiotypic; HDC does not learn.
    Each batch runs the smallest controller for its systems (stl_for), the full one once UIE-R1
    is among them (that the trials come out the same: the next test)."""
    ran = set()

    def rollout(*args, **kw):
        ran.add(args[4])  # the controller the runner would compile
        raise _Compiling

    monkeypatch.setattr(trials_module, "rollout", rollout)
    batches = (("SIE", "HDC"), ("SIE", "UIE-R1", "HDC"), ("HDC", "SRL"), ("HDC",))
    sys_ = F.systems()
    for labels in batches:
        with pytest.raises(_Compiling):
            run_trials(F.world(), {k: sys_[k] for k in labels}, 1, 0, F.CONFIG, F.sim_params())
    expected = {stl_for(F.stack([sys_[k] for k in labels])) for labels in batches}
    assert len(expected) == 4 and STL in expected
    assert ran == expected


SMALLEST_AND_FULL = """
import sys
sys.path.insert(0, {tests!r})
from jaxais import _speed
_speed.setup(cache=False)  # the scripts' settings, before JAX starts
from test_trials import SIE_HDC, same_trials, trials

small, full = trials(SIE_HDC, 0), trials((("SIE", 2), ("UIE-R1", 1), ("HDC", 1)), 0)
print(same_trials(small["SIE"], full["SIE"]), same_trials(small["HDC"], full["HDC"], 1))
"""


@pytest.mark.slow
def test_the_smallest_controller_gives_the_full_ones_trials_bit_for_bit():
    """SIE and HDC without replacement (their batch's program) and beside UIE-R1 (the full
    controller) give the same trials bit for bit: with the scripts' settings, which the claim is
    about (the tests' unoptimised programs round a step of these apart)."""
    proc = run_python(SMALLEST_AND_FULL.format(tests=str(Path(__file__).parent)), shipped_env())
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.split() == ["True", "True"]


def test_all_systems_of_a_world_meet_the_same_start_placements():
    """Common random numbers: trial i's reset key (hence the world placement) is the same for
    every system; the dynamics keys differ."""
    r_sie, k_sie = trial_keys(0, "SIE", 2)
    r_hdc, k_hdc = trial_keys(0, "HDC", 2)
    r_uie, _ = trial_keys(0, "UIE-R2", 2)
    np.testing.assert_array_equal(key_data(r_sie), key_data(r_hdc))
    np.testing.assert_array_equal(key_data(r_sie), key_data(r_uie))
    assert not np.array_equal(key_data(k_sie), key_data(k_hdc))
    assert not np.array_equal(key_data(r_sie[0]), key_data(r_sie[1]))
    # The reset states from those keys: equal across systems, different across trials.
    runs, _ = start_runs()  # SIE trials 0, 1 then HDC trials 0, 1
    sims = [F.unstack(runs.sim, i) for i in range(F.BATCH)]
    assert tree_equal(sims[0], sims[2]) and tree_equal(sims[1], sims[3])
    assert not np.array_equal(np.asarray(sims[0].pose), np.asarray(sims[1].pose))
    # run_trials starts trial i of both systems from one state: those placements (to an ulp,
    # as the test's programs compile with other XLA options).
    res = trials(SIE_HDC, 0)
    for i in range(2):
        np.testing.assert_array_equal(res["SIE"].trajectories[i][0], res["HDC"].trajectories[i][0])
        np.testing.assert_allclose(res["SIE"].trajectories[i][0], sims[i].pose, rtol=1e-6)


def test_batch_keys_follow_the_documented_derivation_from_names():
    """Reset keys from (seed, i); run keys from (seed, a CRC-32 of the base label, i), written
    out here with plain ``jax.random`` calls; nothing depends on ``LABELS`` (its order, or a
    label added to it)."""
    plan = (("SIE", 3), ("HDC", 2), ("UIE-R2", 4), ("SIE@hold=1", 2))
    for seed in (0, 3, 2**32 - 1):
        k_worlds, k_systems = jax.random.split(jax.random.key(seed))
        resets, runs = [], []
        for label, n in plan:
            name = label.split("@")[0].encode()
            stream = jax.random.fold_in(k_systems, zlib.crc32(name) & 0x7FFFFFFF)
            resets += [jax.random.fold_in(k_worlds, i) for i in range(n)]
            runs += [jax.random.fold_in(stream, i) for i in range(n)]
        got = trials_module.batch_keys(seed, plan)
        for keys, want in zip(got, (resets, runs), strict=True):
            assert jax.random.key_impl(keys) == jax.random.key_impl(want[0])
            np.testing.assert_array_equal(key_data(keys), key_data(jnp.stack(want)))


def test_a_systems_trials_do_not_depend_on_the_list_of_systems(monkeypatch):
    """A new label, placed first in a reordered LABELS and run before SIE in the batch, leaves
    SIE's trials as they were; the new label, with HDC's data, gets trials of its own."""
    plan = (("SIE", 2), ("HDC", 2))
    before = trials_module.batch_keys(5, plan)
    monkeypatch.setattr(trials_module, "LABELS", ("NEW", *reversed(trials_module.LABELS)))
    after = trials_module.batch_keys(5, plan)
    for a, b in zip(before, after, strict=True):
        np.testing.assert_array_equal(key_data(a), key_data(b))
    sys_ = F.systems()
    res = run_trials(
        F.world(), {"NEW": sys_["HDC"], "SIE": sys_["SIE"]}, 2, 0, F.CONFIG, F.sim_params()
    )
    assert same_trials(res["SIE"], trials(SIE_HDC, 0)["SIE"])
    assert not same_trials(res["NEW"], trials(SIE_HDC, 0)["HDC"])


def test_trial_keys_do_not_depend_on_the_number_of_trials():
    for label in ("SIE", "URL-R2"):
        r4, k4 = trial_keys(3, label, 4)
        r2, k2 = trial_keys(3, label, 2)
        np.testing.assert_array_equal(key_data(r4[:2]), key_data(r2))
        np.testing.assert_array_equal(key_data(k4[:2]), key_data(k2))
        assert len({tuple(k) for k in key_data(k4)}) == 4


def test_run_trials_rejects_bad_arguments():
    sys_ = F.systems()
    with pytest.raises(ValueError, match="unknown system label"):
        run_trials(F.world(), {"XYZ": sys_["SIE"]}, 2, 0, F.CONFIG)
    with pytest.raises(ValueError, match="trials must be >= 1"):
        run_trials(F.world(), {"SIE": sys_["SIE"]}, 0, 0, F.CONFIG)


def test_summarise_by_hand():
    def rec(tau, c, by, rate, trapped=0.0, locked=0.0):
        capped = min(c, 100)
        return {
            "tau": tau,
            "collisions": c,
            "collisions_capped": capped,
            "fitness": (8 * capped + tau) / 2,
            "failed": bool(by),
            "failed_collisions": "collisions" in by,
            "failed_time": "time" in by,
            "failed_by": by,
            "trapped_s": trapped,
            "locked_s": locked,
            "idiotypic_difference_rate": rate,
            "iterations": int(tau / DT),
        }

    records = [
        rec(10.0, 2, [], 0.2),
        rec(20.0, 150, ["collisions"], 0.1, 8.0, 6.0),
        rec(4000.0, 1, ["time"], 0.3),
        rec(4000.0, 300, ["collisions", "time"], 0.0, 4.0),
    ]
    s = summarise(records)
    assert s == pytest.approx(
        {
            "n": 4,
            "tau": 2007.5,
            "collisions": 50.75,  # (2 + 100 + 1 + 100) / 4: capped
            "fitness": 1206.75,  # (13 + 410 + 2004 + 2400) / 4
            "failure_rate": 0.75,
            "failed_by_collisions": 0.5,
            "failed_by_time": 0.5,
            "trapped_s": 3.0,
            "locked_s": 1.5,
            "idiotypic_difference_rate": 0.15,
        }
    )
    records[0]["idiotypic_difference_rate"] = None
    del records[1]["locked_s"]  # a record written before lock-ups were measured
    assert summarise(records)["idiotypic_difference_rate"] is None
    assert summarise(records)["locked_s"] is None


def test_run_trials_rejects_seeds_outside_their_range():
    """batch_keys would wrap such a seed onto another one."""
    sie = {"SIE": F.systems()["SIE"]}
    for seed in (-1, 2**32, 2**40):
        with pytest.raises(ValueError, match=r"seed must be in \[0, 2\*\*32\), got"):
            run_trials(F.world(), sie, 2, seed, F.CONFIG)
    for seed in (1.5, "0", True):
        with pytest.raises(ValueError, match="seed must be an integer"):
            run_trials(F.world(), sie, 2, seed, F.CONFIG)


@pytest.mark.slow
def test_pooled_trials_equal_the_recorded_batch():
    """Without recording, run_trials goes through the refilling pool: with one slot, each run
    starts when the one before ended, and every record and placement is the batch's."""
    pooled = run_trials(
        F.world(),
        {k: F.systems()[k] for k in ("SIE", "HDC")},
        2,
        0,
        dataclasses.replace(F.CONFIG, record=False),
        F.sim_params(),
        slots=1,
    )
    batch = trials(SIE_HDC, 0)
    for name in batch:
        assert pooled[name].trajectories is None
        assert pooled[name].records == batch[name].records
        for a, b in zip(pooled[name].placements, batch[name].placements, strict=True):
            np.testing.assert_array_equal(a.goal, b.goal)
            np.testing.assert_array_equal(a.boxes, b.boxes)


def test_trial_sets_keep_where_each_trial_had_its_boxes_and_goal():
    """Placements: the boxes and goal of each trial's start state (reset places the goal and
    random boxes anew per trial), the same for every system's trial i."""
    res = trials(SIE_HDC, 0)
    runs, _ = start_runs()  # SIE trials 0, 1 then HDC trials 0, 1, from the same reset keys
    world = F.world()
    goal_region = np.asarray(world.goal_region)
    for ts in res.values():
        assert len(ts.placements) == len(ts.records) == 2
        for i, placement in enumerate(ts.placements):
            sim = F.unstack(runs.sim, i)
            assert placement.boxes.shape == (world.box_half.shape[0], 2)
            np.testing.assert_allclose(placement.goal, sim.goal, rtol=1e-6)
            np.testing.assert_allclose(placement.boxes, sim.boxes, rtol=1e-6)
            assert np.all(placement.goal >= goal_region[:2]) and np.all(
                placement.goal <= goal_region[2:]
            )
    assert not np.array_equal(res["SIE"].placements[0].goal, res["SIE"].placements[1].goal)
    for a, b in zip(res["SIE"].placements, res["HDC"].placements, strict=True):
        np.testing.assert_array_equal(a.goal, b.goal)
        np.testing.assert_array_equal(a.boxes, b.boxes)


def test_a_loop_is_one_kernel_unless_it_holds_what_that_form_cannot_emit():
    """The loop's call is tagged for XLA's one-kernel form; a loop with a sort or a scatter (a
    user's controller may hold one) is left untagged, and computes the same either way."""
    from jaxais.runner import _kernel_can_emit, one_kernel

    plain = lambda x: jax.lax.fori_loop(0, 5, lambda i, s: s * 0.5 + i, x)
    sorts = lambda x: jax.lax.fori_loop(0, 5, lambda i, s: jnp.sort(s) + s.at[i % 4].add(1.0), x)
    x = jnp.arange(4.0)
    for f, emits in ((plain, True), (sorts, False)):
        assert _kernel_can_emit(jax.make_jaxpr(f)(x).jaxpr) is emits
        program = jax.jit(lambda a, f=f: one_kernel(f)(a))
        assert ('xla_cpu_small_call = "true"' in program.lower(x).as_text()) is emits
        np.testing.assert_array_equal(program(x), jax.jit(f)(x))
