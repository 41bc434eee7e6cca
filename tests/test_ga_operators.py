"""The GA's breeding operators, passed in (jaxais.ga.operators): the defaults breed bit for bit as
the GA did before they were arguments (so the shipped seed stays what it is), a user's operators
breed without a library edit (examples/tournament_ga.py's tournament selection, checked against
NumPy), and checkpoints record the operators' names: a resume with others is refused in one line.

Shapes are tiny and fixed: each jitted program compiles once. The example itself runs as a user
runs it, once (slow: the GA's and the STL's rollouts compile in it).
"""

from __future__ import annotations

import functools
import json
import os
import re
import runpy
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _python import call_main
from test_ga import TINY, evaluation

from jaxais import ga
from jaxais.checkpointing import CheckpointError, GACheckpointer
from jaxais.experiments import evolution
from jaxais.immune.antibodies import mutate, sample_antibodies

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "tournament_ga.py"


@functools.cache
def example() -> dict:
    """examples/tournament_ga.py's names, imported as a user's module (main not run)."""
    return runpy.run_path(str(EXAMPLE))


def old_next_generation(key, population, evaluation, config):
    """``jaxais.ga.core.next_generation`` as it was before the operators were passed in (its
    roulette, crossover and mutation rate chosen by config), kept here verbatim with the
    selection and crossover it called: the reference of the shipped seed's breeding."""

    def selection_weights(tau, collisions, rho=8.0):
        cost = jnp.asarray(tau, jnp.float32) + rho * jnp.asarray(collisions, jnp.float32)
        return 1.0 / jnp.maximum(cost, 1e-6)

    def roulette(key, weights, n):
        cdf = jnp.cumsum(weights)
        u = jax.random.uniform(key, (n,))
        idx = jnp.searchsorted(cdf, u * cdf[-1], side="right")
        return jnp.minimum(idx, weights.shape[0] - 1).astype(jnp.int32)

    def crossover(key, a, La, b, Lb, rl_assisted=True):
        coin = jax.random.uniform(key, La.shape) < 0.5
        from_a = (La > Lb) | ((La == Lb) & coin) if rl_assisted else coin
        return jax.tree.map(lambda x, y: jnp.where(from_a, x, y), a, b)

    P, R = population.shape[:2]
    n_elite, n_child = config.elitism, R - config.elitism
    k_parents, k_ties, k_mut = jax.random.split(key, 3)
    rows = jnp.arange(P)[:, None]
    order = jnp.argsort(evaluation.fitness, axis=1, stable=True)[:, :n_elite]
    elites = jax.tree.map(lambda x: x[rows, order], population)
    weights = selection_weights(evaluation.tau, evaluation.collisions)
    spin = lambda k, w: roulette(k, w, 2 * n_child).reshape(2, n_child)
    parents = jax.vmap(spin)(jax.random.split(k_parents, P), weights)
    pa, pb = parents[:, 0], parents[:, 1]
    children = crossover(
        k_ties,
        jax.tree.map(lambda x: x[rows, pa], population),
        evaluation.L[rows, pa],
        jax.tree.map(lambda x: x[rows, pb], population),
        evaluation.L[rows, pb],
        rl_assisted=config.crossover == "rl",
    )
    children = mutate(k_mut, children, config.mutation)
    return jax.tree.map(lambda e, ch: jnp.concatenate([e, ch], axis=1), elites, children)


def random_case(seed: int, P: int = 3, R: int = 6):
    """A population [P, R, 8] and an evaluation of it, with ties in f and L."""
    rng = np.random.default_rng(seed)
    population = jax.tree.map(np.asarray, _sample(jax.random.key(seed)))
    tau = rng.choice([40.0, 150.0, 500.0], (P, R)).astype(np.float32)
    c = rng.integers(0, 4, (P, R)).astype(np.float32)
    L = rng.integers(0, 3, (P, R, 8)).astype(np.float32)  # many ties between parents
    return population, evaluation((8 * c + tau) / 2, tau, c, L)


_sample = jax.jit(functools.partial(sample_antibodies, shape=(3, 6, 8)))
_old = jax.jit(old_next_generation, static_argnames="config")
_new = jax.jit(ga.next_generation, static_argnames=("config", "operators"))
UNIFORM = ga.GAConfig(populations=3, robots=6)  # the shipped seed's: uniform, 0.05, 1 elite
RL = ga.GAConfig(populations=3, robots=6, crossover="rl", mutation=0.3, elitism=2)


@pytest.mark.parametrize("config", [UNIFORM, RL], ids=["uniform", "rl"])
def test_default_operators_breed_bit_for_bit_as_before(config):
    before = _new._cache_size()
    for seed in range(3):
        population, ev = random_case(seed)
        key = jax.random.key(100 + seed)
        want = _old(key, population, ev, config)
        # The config's defaults, implicit or built again each time (equal: one compile).
        for ops in (None, ga.default_operators(config)):
            got = _new(key, population, ev, config, ops)
            for a, b in zip(jax.tree.leaves(want), jax.tree.leaves(got), strict=True):
                assert a.dtype == b.dtype
                np.testing.assert_array_equal(np.asarray(b), np.asarray(a))
    assert _new._cache_size() - before == 2


def test_default_operator_names():
    names = ga.default_operators(ga.GAConfig()).names()
    assert names == {"selection": "roulette", "crossover": "uniform", "mutation": "resample(0.05)"}
    rl = ga.default_operators(ga.GAConfig(crossover="rl", mutation=1))
    assert rl.names() == {"selection": "roulette", "crossover": "rl", "mutation": "resample(1.0)"}
    assert ga.resample_mutation(0.05) is ga.resample_mutation(0.05)  # cached: one compile


@functools.cache
def _tournament(size: int):
    return jax.jit(example()["tournament_selection"](size), static_argnums=2)


def test_tournament_selection_picks_per_its_definition():
    """The lowest f of 3 robots drawn with replacement, the first drawn on ties: each draw as
    NumPy picks it from the same contestants, and the frequencies NumPy's exact probabilities."""
    size, n = 3, 60_000
    f = np.array([5.0, 1.0, 3.0, 3.0, 9.0], np.float32)  # robots 2 and 3 tie
    one = evaluation(f)  # one population's evaluation [R]
    key = jax.random.key(0)
    got = np.asarray(_tournament(size)(key, one, n))
    assert got.shape == (n,) and got.dtype == np.int32
    drawn = np.asarray(jax.random.randint(key, (n, size), 0, f.size))  # the contestants
    np.testing.assert_array_equal(got, drawn[np.arange(n), np.argmin(f[drawn], axis=1)])
    # P(the best drawn has f = v) = P(all >= v) - P(all > v), shared by the robots with f = v.
    R = f.size
    p = np.array([((f >= v).sum() / R) ** size - ((f > v).sum() / R) ** size for v in f])
    p /= np.array([(f == v).sum() for v in f])
    assert p.sum() == pytest.approx(1.0)
    freq = np.bincount(got, minlength=R) / n
    np.testing.assert_allclose(freq, p, atol=5 * np.sqrt(0.25 / n))


def test_user_operators_breed_without_a_library_edit():
    """Operators written here, as a user writes them: every child is the whole set of the fitter
    of robots 0 and 1 (so crossover saw each parent's evaluation), unmutated; the elite stays."""
    first_two = lambda key, ev, n: jnp.repeat(jnp.arange(2, dtype=jnp.int32), n // 2)
    fitter = lambda key, a, ea, b, eb: jax.tree.map(
        lambda x, y: jnp.where((ea.fitness < eb.fitness)[..., None], x, y), a, b
    )
    ops = ga.Operators(
        selection=ga.Operator("first-two", first_two),
        crossover=ga.Operator("fitter-parent", fitter),
        mutation=ga.Operator("none", lambda key, children: children),
    )
    state = ga.init(jax.random.key(1), TINY)
    f = np.array([[4.0, 2.0, 1.0, 9.0], [3.0, 7.0, 8.0, 9.0]])
    new = ga.tell(jax.random.key(2), state.population, evaluation(f), state, TINY, ops)
    leaves = zip(jax.tree.leaves(state.population), jax.tree.leaves(new.population), strict=True)
    for old, bred in leaves:
        old, bred = np.asarray(old), np.asarray(bred)
        np.testing.assert_array_equal(bred[0, 0], old[0, 2])  # elites: the best robots
        np.testing.assert_array_equal(bred[1, 0], old[1, 0])
        np.testing.assert_array_equal(bred[0, 1:], np.broadcast_to(old[0, 1], (3, 8)))
        np.testing.assert_array_equal(bred[1, 1:], np.broadcast_to(old[1, 0], (3, 8)))


def test_a_wrong_operator_is_one_line():
    state = ga.init(jax.random.key(1), TINY)
    ev = evaluation(np.ones((2, 4)))
    bad = ga.default_operators(TINY).replace(
        selection=ga.Operator("short", lambda key, ev, n: jnp.zeros(n - 1, jnp.int32))
    )
    with pytest.raises(ValueError, match=r"^selection 'short' returned shape \(5,\), expected"):
        ga.tell(jax.random.key(2), state.population, ev, state, TINY, bad)
    ops = ga.default_operators(TINY)
    with pytest.raises(TypeError, match="^Operators.selection must be an Operator"):
        ga.Operators(lambda key, ev, n: None, ops.crossover, ops.mutation)
    with pytest.raises(ValueError, match="must not be empty"):
        ga.Operator(" ", lambda key, children: children)


def _hand_made_checkpoint(out: Path, extra: dict) -> None:
    """Generation 0 of a run as evolve.py checkpoints it (its run.json), with ``extra``."""
    info = evolution._run_info("ga_maze", 0, TINY)
    with GACheckpointer(out / "checkpoints", info, resume=False) as ck:
        ck.save(ga.init(jax.random.key(0), TINY), TINY, extra)


def test_resume_with_other_operators_is_refused_in_one_line(tmp_path):
    tournament = ga.default_operators(TINY).replace(selection=example()["tournament_selection"](3))
    _hand_made_checkpoint(tmp_path / "new", {"operators": tournament.names()})
    with pytest.raises(CheckpointError) as info:
        evolution.evolve(tmp_path / "new", 0, TINY, resume=True)
    assert str(info.value) == "--resume: this run used selection 'tournament3', not 'roulette'"
    # A checkpoint from before the record ran its config's defaults.
    _hand_made_checkpoint(tmp_path / "old", {"history": []})
    with pytest.raises(CheckpointError) as info:
        evolution.evolve(tmp_path / "old", 0, TINY, resume=True, operators=tournament)
    assert str(info.value) == "--resume: this run used selection 'roulette', not 'tournament3'"
    with pytest.raises(CheckpointError, match="crossover 'uniform', not 'rl'"):
        rl = ga.default_operators(TINY).replace(crossover=ga.rl_crossover())
        evolution.evolve(tmp_path / "old", 0, TINY, resume=True, operators=rl)
    # The diversity comparison's other runs take the config's operators: refused up front.
    with pytest.raises(ga.ConfigError, match="default operators only"):
        evolution.evolve(tmp_path / "div", 0, TINY, diversity_seeds=2, operators=tournament)


@pytest.mark.slow
def test_tournament_example_runs_as_a_user_runs_it(tmp_path, capsys):
    out = tmp_path / "run"
    env = os.environ | {"JAX_PLATFORMS": "cpu"}
    env["JAX_COMPILATION_CACHE_DIR"] = os.environ["JAXAIS_TESTS_CACHE"]  # the tests' programs
    proc = subprocess.run(
        [sys.executable, str(EXAMPLE), "--tiny", "--out", str(out)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    ga_line = r"^GA with tournament3 selection: 2 generations of 2 x 4, best f per population \["
    assert re.search(ga_line, proc.stdout, re.MULTILINE), proc.stdout
    found = re.search(r"^SIE with the tournament seed in world1: 2 trials, mean f (\S+)$",
                      proc.stdout, re.MULTILINE)  # fmt: skip
    assert found and np.isfinite(float(found[1])), proc.stdout
    # The operators' names in the summary, the seed and every checkpoint.
    names = {"selection": "tournament3", "crossover": "uniform", "mutation": "resample(0.05)"}
    assert json.loads((out / "summary.json").read_text())["operators"] == names
    assert json.loads((out / "seed" / "seed.json").read_text())["operators"] == names
    info = json.loads((out / "checkpoints" / "run.json").read_text())
    info.pop("format")
    config = ga.GAConfig(populations=2, robots=4, generations=2, tau_cap=2.0, success_starts=4)
    with GACheckpointer(out / "checkpoints", info, resume=True) as ck:
        for generation in (1, 2):
            assert ck.restore(config, generation)[1]["operators"] == names
    # evolve.py (the defaults) refuses to continue it, in one line.
    flags = ["--populations", "2", "--robots", "4", "--tau-cap", "2", "--success-starts", "4"]
    proc = call_main("evolve.py", *flags, "--generations", "3", "--out", out, "--resume")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        "evolve.py: error: --resume: this run used selection 'tournament3', not 'roulette'"
    )
